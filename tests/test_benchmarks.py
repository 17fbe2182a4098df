"""Every benchmark script runs: its ``--smoke`` run (tiny sizes, one repetition, output to a
temporary folder) ends with exit status 0, prints its Markdown table and leaves the pages of
docs/benchmarks alone."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BENCHMARKS = ROOT / "benchmarks"
PAGES = ROOT / "docs" / "benchmarks"
#: the benchmark scripts: every benchmarks/*.py but the shared module
SCRIPTS = sorted(p.name for p in BENCHMARKS.glob("*.py") if p.name != "common.py")
#: a Markdown table: a header row followed by its |---| separator
TABLE = re.compile(r"^\|.*\|\n\|(-+\|)+\s*$", re.MULTILINE)


def pages_snapshot() -> dict[str, float]:
    return {p.name: p.stat().st_mtime for p in PAGES.iterdir()}


def test_every_benchmark_has_its_page_and_is_listed():
    """Its page under docs/benchmarks, a row in that folder's index and in
    benchmarks/README.md."""
    pages = {p.stem for p in PAGES.glob("*.md")}
    assert SCRIPTS and {Path(s).stem for s in SCRIPTS} <= pages
    index, readme = (PAGES / "index.md").read_text(), (BENCHMARKS / "README.md").read_text()
    for script in SCRIPTS:
        assert f"]({Path(script).stem}.md)" in index, script
        assert f"[{script}]({script})" in readme, script


@pytest.mark.parametrize("script", SCRIPTS)
def test_smoke_run(script, tmp_path):
    before = pages_snapshot()
    env = {**os.environ, "TMPDIR": str(tmp_path), "OMP_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(BENCHMARKS / script), "--smoke"], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert TABLE.search(proc.stdout), f"no table printed:\n{proc.stdout[-2000:]}"
    assert pages_snapshot() == before, "a smoke run wrote to docs/benchmarks"
