"""What the benchmarks share: the bundled target problems, one design solved in a child
process (its time and peak memory its own), an earlier revision's package, the machine/date
line of the tables, Markdown tables and their cells, the page a full run writes to
(docs/benchmarks/<name>.md) and the ``--smoke`` run (tiny sizes, output to a temporary
folder).

A benchmark imports it as ``from common import ...`` (the benchmarks folder is the script's
path). ``python benchmarks/common.py --child '<json>'`` solves one design and prints its row
as JSON (:func:`solve_in_child` runs it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from rffqm_nlp import (DesignProblem, RffqmError, SolveOptions, SolverFailed, SolveStats,
                       load_design)

ROOT = Path(__file__).resolve().parent.parent
#: the pages a full run writes its table to, docs/benchmarks/<name>.md
PAGES = ROOT / "docs" / "benchmarks"
#: the bundled target files, targets/<name>.toml
TARGETS = ("sphere_cap", "hyperboloid", "quarter_vase")
#: "to 0.9%": the ``stop_rms`` (RMS distance / diameter) a benchmark passes when it solves to
#: that fit; it was the bundled target files' own value until 2026-12-01
STOP_RMS = 0.009
#: the lines between which a full run writes its table into its page; the rest of the page
#: (its question, earlier runs) is kept
BEGIN, END = "<!-- latest run -->", "<!-- end of the latest run -->"


# ------------------------------------------------------------------ problems
def target_problem(name: str, n: int, **design: Any) -> tuple[DesignProblem, SolveOptions]:
    """targets/<name>.toml at n x n panels, its [design] keys overridden by ``design``: the
    problem and the file's solve options."""
    problem, options = load_design(ROOT / "targets" / f"{name}.toml")
    return replace(problem, panels=(n, n), **design), options


# ------------------------------------------------------------------ child processes
def peak_rss_mb() -> float:
    """Peak resident set size of this process in MB (VmHWM; unlike ru_maxrss it is not
    inherited from the forking parent)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_child(script: str | Path, *argv: str, env: dict[str, str] | None = None) -> dict:
    """Run ``python script *argv`` from the repository root and return the JSON of its last
    line of output; RuntimeError with the end of its stderr when it fails."""
    cmd = [sys.executable, str(script), *argv]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT,
                          env=None if env is None else {**os.environ, **env})
    if proc.returncode:
        raise RuntimeError(f"child {cmd} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def solve_design(target: str, n: int, design: dict | None = None,
                 solve: dict | None = None) -> dict:
    """Solve targets/<target>.toml at n x n panels with its [design] and [solve] tables
    overridden by ``design`` and ``solve``: :func:`solve_problem`'s row."""
    rss0 = peak_rss_mb()
    problem, options = target_problem(target, n, **(design or {}))
    return solve_problem(problem, replace(options, **(solve or {})),
                         {"n": n, "target": target}, rss0)


def solve_problem(problem: DesignProblem, options: SolveOptions, row: dict[str, Any],
                  rss0: float | None = None) -> dict:
    """``problem.solve(options)`` as a JSON-ready row, ``row`` (what names the problem) and:
    the options' solver, the statistics (``history``: the iteration log), ``fit`` (None
    when the solve failed), ``x`` (the answer, or the last iterate of a failed solve, or
    None), ``wall``/``cpu`` seconds of the solve, and peak memory (``rss0_mb``, given or
    now, after the imports; ``peak_rss_mb`` at the end)."""
    rss0 = peak_rss_mb() if rss0 is None else rss0
    row = {**row, "transcription": options.transcription, "solver": options.solver,
           "hessian": options.hessian, "fit": None, "x": None, "error": None}
    t0, c0 = time.perf_counter(), time.process_time()
    stats = None
    try:
        res = problem.solve(options)
        stats, x = res.stats, res.x
        row.update(fit=res.fit.to_dict())
    except SolverFailed as exc:
        stats = exc.stats if isinstance(exc.stats, SolveStats) else None
        x = exc.last_iterate
        row.update(error=str(exc), status=exc.status)
    except RffqmError as exc:  # a failed run is a result here
        x = None
        row.update(error=str(exc), status=type(exc).__name__)
    row["wall"] = time.perf_counter() - t0
    row["cpu"] = time.process_time() - c0
    usage = resource.getrusage(resource.RUSAGE_SELF)
    row.update(cpu_user=usage.ru_utime, cpu_sys=usage.ru_stime, rss0_mb=rss0,
               peak_rss_mb=peak_rss_mb(), success=row["fit"] is not None)
    if stats is not None:
        row.update({k: v for k, v in stats.to_dict().items() if k != "multistart"})
    row.setdefault("iterations", None)
    row.setdefault("history", {"iter": [], "objective": [], "inf_pr": [], "elapsed": []})
    row["x"] = None if x is None else np.asarray(x, dtype=float).tolist()
    return row


def export_package(rev: str) -> Path:
    """The package at git revision ``rev``, exported to a temporary folder (put it on
    PYTHONPATH to run that revision's code, e.g. in :func:`solve_in_child`'s ``env``)."""
    folder = Path(tempfile.mkdtemp(prefix="rffqm-baseline-"))
    archive = subprocess.run(["git", "archive", rev, "rffqm_nlp"], cwd=ROOT, check=True,
                             capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
    return folder


def solve_in_child(target: str, n: int, design: dict | None = None, solve: dict | None = None,
                   env: dict[str, str] | None = None) -> dict:
    """:func:`solve_design` in a fresh Python process (``env``: extra environment)."""
    args = json.dumps({"target": target, "n": n, "design": design, "solve": solve})
    return run_child(__file__, "--child", args, env=env)


# ------------------------------------------------------------------ tables and pages
def machine() -> str:
    """The machine: architecture, CPUs and their model, memory, operating system, versions."""
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.exists() else []
    model = next((line.split(":", 1)[1].strip() for line in lines
                  if line.startswith("model name")), "?")
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return (f"{platform.machine()}, {os.cpu_count()} CPUs ({model}), {memory:.0f} GB; "
            f"{platform.platform()}; Python {platform.python_version()}, NumPy "
            f"{np.__version__}, CasADi {ca.__version__}")


@dataclass
class Run:
    """A benchmark run's clock and load, for the date/machine line of its table."""

    t0: float = field(default_factory=time.perf_counter)
    load0: float = field(default_factory=lambda: os.getloadavg()[0])

    def elapsed(self) -> float:
        return time.perf_counter() - self.t0

    def header(self) -> str:
        """date; machine; load at start and now; seconds since the start."""
        return (f"date {time.strftime('%Y-%m-%dT%H:%M')}; {machine()}; load average (1 min) "
                f"{self.load0:.1f} at start, {os.getloadavg()[0]:.1f} at end; whole run "
                f"{self.elapsed():.0f} s")

    def preamble(self, script: str) -> list[str]:
        """The lines a table starts with: :meth:`header` and the command that made it."""
        return [f"- {self.header()}",
                "- command: `" + " ".join([f"python benchmarks/{script}", *sys.argv[1:]])
                + "`"]


def fmt(value: float | None, spec: str = ".3g", none: str = "-") -> str:
    """A table cell: ``value`` formatted with ``spec``, or ``none`` for None."""
    return none if value is None else format(value, spec)


def ratio(value: float | None, baseline: float | None, spec: str = ".2f") -> str:
    """A table cell: ``value / baseline`` (``-`` without either)."""
    return "-" if value is None or not baseline else format(value / baseline, spec)


def markdown_table(columns: list[str] | tuple[str, ...], rows: list[list[str]]) -> list[str]:
    """The lines of a Markdown table: the header, its separator, one line per row."""
    return ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns),
            *("| " + " | ".join(row) + " |" for row in rows)]


def write_page(path: Path, title: str, text: str) -> None:
    """Print ``text`` (a run's table and notes) and write it into the page ``path``: between
    :data:`BEGIN` and :data:`END` where the page has them (the rest of the page kept), else
    as a new page with ``title``."""
    print(text)
    block = f"{BEGIN}\n{text.strip()}\n{END}"
    page = path.read_text() if path.exists() else ""
    if BEGIN in page and END in page:
        head, rest = page.split(BEGIN, 1)
        page = head + block + rest.split(END, 1)[1]
    else:
        page = f"# {title}\n\n{block}\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(page)
    print(f"wrote {path}")


# ------------------------------------------------------------------ output and smoke runs
def add_output(parser: argparse.ArgumentParser, name: str) -> None:
    """The ``--out`` option (default docs/benchmarks/<name>.md) and the ``--smoke`` flag."""
    parser.add_argument("--out", type=Path, default=PAGES / f"{name}.md",
                        help="the page the table goes to (default: %(default)s)")
    parser.add_argument("--smoke", action="store_true",
                        help="a quick check that the benchmark runs: smallest sizes, one "
                             "repetition, output to a temporary folder (docs/benchmarks is "
                             "left alone)")


def smoke_dir(name: str) -> Path:
    """A fresh temporary folder for a smoke run's output."""
    return Path(tempfile.mkdtemp(prefix=f"rffqm-smoke-{name}-"))


def output(args: argparse.Namespace, name: str) -> Path:
    """The page a run writes: ``args.out``, or a temporary one for a smoke run."""
    return smoke_dir(name) / f"{name}.md" if args.smoke else args.out


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        print(json.dumps(solve_design(**json.loads(sys.argv[2]))))
    else:
        sys.exit("usage: python benchmarks/common.py --child '<json>' (see solve_in_child)")
