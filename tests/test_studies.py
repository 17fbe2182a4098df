"""Every study script runs: its ``--smoke`` run (tiny sizes, one repetition, output to a
temporary folder) ends with exit status 0, prints a Markdown table and leaves
studies/results alone."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
STUDIES = ROOT / "studies"
#: the study scripts: every studies/*.py with a main guard, but the shared module
SCRIPTS = sorted(p.name for p in STUDIES.glob("*.py")
                 if p.name != "common.py" and 'if __name__ == "__main__":' in p.read_text())
#: a Markdown table: a header row followed by its |---| separator
TABLE = re.compile(r"^\|.*\|\n\|(-+\|)+\s*$", re.MULTILINE)


def results_snapshot() -> dict[str, float]:
    return {p.name: p.stat().st_mtime for p in (STUDIES / "results").iterdir()}


def test_the_study_scripts_are_found():
    assert len(SCRIPTS) >= 10 and "bench_inverse.py" in SCRIPTS


@pytest.mark.parametrize("script", SCRIPTS)
def test_smoke_run(script, tmp_path):
    before = results_snapshot()
    env = {**os.environ, "TMPDIR": str(tmp_path), "OMP_NUM_THREADS": "1",
           "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    proc = subprocess.run([sys.executable, str(STUDIES / script), "--smoke"], cwd=ROOT,
                          env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    assert TABLE.search(proc.stdout), f"no table printed:\n{proc.stdout[-2000:]}"
    assert results_snapshot() == before, "a smoke run wrote to studies/results"
