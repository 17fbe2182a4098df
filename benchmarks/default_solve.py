"""Benchmark of the default solve to optimality on the bundled targets and user surfaces.

For each bundled target (targets/*.toml, its ``stop_rms`` dropped: the solve runs to the
optimality conditions at ``tol``) at N x N panels (default 20) it solves, each in a fresh
process with the given numbers of OpenBLAS threads (default 1 and 2):

* ``default``: ``problem.solve(options)`` with the file's options, i.e. Levenberg-Marquardt
  on the marching manifold alone (:mod:`rffqm_nlp.design.solvers.levenberg_marquardt`);
* ``ipopt``: the same with ``solver="ipopt"`` (exact Hessian);
* ``baseline``: the default solve of the code at ``--baseline`` (a git revision, exported
  to a temporary folder with ``git archive``; default: the commit before this solver),
  whose Levenberg-Marquardt stopped when a step gained less than 0.01% and handed over to
  IPOPT;
* ``previous`` (with ``--previous REV``): the default solve of the code at that git
  revision, to compare a change of the default solve with the code before it in one run.

Then the surfaces a user brings (:data:`USER_SURFACES`), each solved as a user would,
``DesignProblem(target=surface, panels=(N, N)).solve()`` with the default options, in a
fresh process per solve: every built-in surface without a target file, and two callables
(``surfaces.Custom``: the README's lambda, and a bump written with CasADi's exp).

The yardstick, measured in this run: one forward evaluation of the NumPy model
(``numpy_model.march`` of the problem's starting Miura + ``numpy_model.fold`` at omega0),
best of ``--repeat`` x 10 calls; "solve / forward" is the solve's wall time over it.
Times: "build" the transcription and its derivatives, "solve" the rest (wall, from the
result's statistics), "cpu" the CPU time of the whole solve call.

Then one default solve per target runs under cProfile (in a child, ``--threads`` first
value), and so does the baseline's: the time spent in the solver's parts.

Each solve runs ``--repeat`` times (default 1); a table gives the default path's fastest and
median solve per target (or user surface) and thread count against the goal.

Usage: ``python studies/bench_default_solve.py [--n 20] [--threads 1,2] [--repeat 1]
[--baseline REV] [--previous REV] [--out studies/results/bench_default_solve.md]``;
``--smoke``: 4 x 4 panels, one thread, no baseline, of the user surfaces the two callables,
output to a temporary folder.
"""

from __future__ import annotations

import argparse
import cProfile
import functools
import json
import os
import pstats
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:  # a child given the package to measure keeps it
    sys.path.insert(0, str(ROOT))

from common import (RESULTS, TARGETS, Run, add_smoke, export_package, fmt,  # noqa: E402
                    run_child, smoke_dir, solve_in_child, solve_problem, target_problem,
                    write_table)
from rffqm_nlp import DesignProblem, SolveOptions  # noqa: E402
from rffqm_nlp.model import numpy_model
from rffqm_nlp.targets import surfaces
from rffqm_nlp.targets.surfaces import Surface  # noqa: E402

#: the commit before Levenberg-Marquardt ran to the optimality conditions by itself
BASELINE = "0f9ad8d"
GOAL = 0.5  # seconds of solve time at 20 x 20 panels (issue 21)
#: (label, file, function) of the profile's rows: cumulative time in that function (or in
#: the first of several names found: a function renamed since the baseline)
PARTS = [("whole solve", "design.py", "solve"),
         ("  transcription", "design.py", "transcribe"),
         ("  derivatives' build (Manifold)", "reduced.py", "__init__"),
         ("Levenberg-Marquardt", "reduced.py", "levenberg_marquardt"),
         ("  trial marches (march + NLP point)", "transcription.py", ("project", "__call__")),
         ("  r, g (and before: J, G) at trial points", "reduced.py", "point"),
         ("  J, G and S at accepted points", "reduced.py", "linearize"),
         ("  sensitivity S", "reduced.py", "sensitivity"),
         ("  model (Jr, J'J, metric)", "reduced.py", "_model"),
         ("  optimality test", "reduced.py", "_kkt_error"),
         ("  secant update", "reduced.py", "_secant"),
         ("IPOPT handover", "design.py", "_solve_ipopt")]


#: the surfaces a user brings (name -> a maker): the built-in ones without a target file,
#: and two callables
USER_SURFACES: dict[str, Callable[[], Surface]] = {
    **{name: functools.partial(surfaces.get, name) for name in surfaces.names()
       if not (ROOT / "targets" / f"{name}.toml").exists()},
    "custom_readme": lambda: surfaces.Custom(lambda u, v: (u, v, 0.1 * u * v),
                                             ((-1, 1), (-1, 1))),
    "custom_bump": lambda: surfaces.Custom(
        lambda u, v: (u, v, 0.3 * ca.exp(-(u * u + v * v))), ((-1.5, 1.5), (-1.5, 1.5))),
}


def problem_of(name: str, n: int) -> DesignProblem:
    """The problem of a bundled target (its file's) or of a user surface at n x n panels."""
    if name in USER_SURFACES:
        return DesignProblem(target=USER_SURFACES[name](), panels=(n, n))
    return target_problem(name, n)[0]


def forward_time(name: str, n: int, repeat: int) -> float:
    """Best wall time (s) of one NumPy march + fold of the problem's starting Miura."""
    start = problem_of(name, n).start()
    best = np.inf
    for _ in range(10 * repeat):
        t0 = time.perf_counter()
        numpy_model.fold(numpy_model.march(start.boundary), start.omega)
        best = min(best, time.perf_counter() - t0)
    return best


def solve_row(name: str, n: int, path: str, threads: int, package: Path) -> dict:
    """One solve in a fresh process importing the package from ``package``."""
    env = {"PYTHONPATH": str(package), "OPENBLAS_NUM_THREADS": str(threads)}
    if name in USER_SURFACES:
        row = run_child(__file__, "--surface-child", name, str(n), env=env)
    else:
        solve = {"stop_rms": None, **({"solver": "ipopt"} if path == "ipopt" else {})}
        row = solve_in_child(name, n, solve=solve, env=env)
    row.update(path=path, threads=threads)
    return row


def solve_surface(name: str, n: int) -> dict:
    """A user surface's default solve at n x n panels (:func:`common.solve_problem`'s row)."""
    return solve_problem(problem_of(name, n), SolveOptions(), {"n": n, "target": name})


def report(row: dict) -> dict:
    """Print a solve's row in short (the run's progress) and return it."""
    print(json.dumps({k: row.get(k) for k in ("target", "path", "threads", "status",
                                               "iterations", "build_time", "solve_time")}),
          flush=True)
    return row


def profile(name: str, n: int) -> dict[str, float | None]:
    """Seconds in each of :data:`PARTS` in one default solve of the target."""
    problem, options = target_problem(name, n)
    profiler = cProfile.Profile()
    profiler.enable()
    problem.solve(replace(options, stop_rms=None))
    profiler.disable()
    stats = pstats.Stats(profiler).stats  # (file, line, function) -> (.., .., .., cum, ..)
    out: dict[str, float | None] = {}
    for label, file, function in PARTS:
        names = (function,) if isinstance(function, str) else function
        times = [v[3] for (f, _, fn), v in stats.items()
                 if fn in names and Path(f).name == file and "rffqm_nlp" in f]
        out[label] = max(times) if times else None
    return out


def profile_in_child(name: str, n: int, threads: int, package: Path) -> dict:
    return run_child(__file__, "--profile-child", name, str(n),
                     env={"PYTHONPATH": str(package), "OPENBLAS_NUM_THREADS": str(threads)})


def table(rows: list[dict], forward: dict[str, float]) -> list[str]:
    lines = ["| target | path | threads | status | iterations (LM) | build (s) | solve (s) "
             "| cpu (s) | solve / forward | fit RMS / diameter |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        fit = (r.get("fit") or {}).get("rms")
        solve = r.get("solve_time")
        ratio = None if solve is None else solve / forward[r["target"]]
        lines.append(
            f"| {r['target']} | {r['path']} | {r['threads']} | {r.get('status', '-')} "
            f"| {r.get('iterations', '-')} ({r.get('marched_iterations', '-')}) "
            f"| {fmt(r.get('build_time'), '.2f')} | {fmt(solve, '.2f')} "
            f"| {fmt(r.get('cpu'), '.2f')} | {fmt(ratio, '.0f')} | {fmt(fit, '.4f')} |")
    return lines


def goal_table(rows: list[dict]) -> list[str]:
    """The default solve against :data:`GOAL`: per target and thread count, the fastest
    and the median of the repeats that succeeded (the machine's speed varies between runs);
    a failed run fails the goal."""
    lines = ["| target | threads | runs | failed | solve, fastest (s) | solve, median (s) "
             "| fastest within the goal |", "|---|---|---|---|---|---|---|"]
    groups: dict[tuple[str, int], list[float | None]] = {}
    for r in rows:
        if r["path"] == "default":
            time_ = r.get("solve_time") if r.get("success") else None
            groups.setdefault((r["target"], r["threads"]), []).append(time_)
    for (target, threads), runs in groups.items():
        times = [t for t in runs if t is not None]
        failed = len(runs) - len(times)
        within = bool(times) and not failed and min(times) <= GOAL
        lines.append(f"| {target} | {threads} | {len(runs)} | {failed} "
                     f"| {fmt(min(times, default=None), '.2f')} "
                     f"| {fmt(float(np.median(times)) if times else None, '.2f')} "
                     f"| {'yes' if within else 'no'} |")
    return lines


def profile_table(profiles: dict[tuple[str, str], dict]) -> list[str]:
    keys = list(profiles)
    lines = ["| part | " + " | ".join(f"{t} ({p})" for t, p in keys) + " |",
             "|---|" + "---|" * len(keys)]
    for label, _, _ in PARTS:
        cells = [fmt(profiles[k].get(label), ".2f") for k in keys]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--baseline", default=BASELINE)
    parser.add_argument("--previous", default=None)
    parser.add_argument("--out", type=Path, default=RESULTS / "bench_default_solve.md")
    add_smoke(parser)
    args = parser.parse_args()
    if args.smoke:
        args.n, args.threads, args.baseline, args.previous = 4, "1", None, None
        args.out = smoke_dir("bench_default_solve") / "bench_default_solve.md"
    threads = [int(t) for t in args.threads.split(",")]
    run = Run()
    users = [k for k in USER_SURFACES if k.startswith("custom_") or not args.smoke]
    forward = {name: forward_time(name, args.n, args.repeat) for name in (*TARGETS, *users)}
    packages = {"default": ROOT}
    if args.previous:  # right after the default: the two rows see the same load
        packages["previous"] = export_package(args.previous)
    packages["ipopt"] = ROOT
    if args.baseline:
        packages["baseline"] = export_package(args.baseline)
    rows = []
    for t in threads:
        for name in TARGETS:
            for path, package in packages.items():
                for _ in range(args.repeat):
                    rows.append(report(solve_row(name, args.n, path, t, package)))
        for name in users:
            for _ in range(args.repeat):
                rows.append(report(solve_row(name, args.n, "default", t, ROOT)))
    profiles = {}
    for name in TARGETS:
        for path in ("default", "baseline"):
            if path in packages:
                profiles[(name, path)] = profile_in_child(name, args.n, threads[0],
                                                          packages[path])
    lines = [f"# The default solve to optimality at {args.n} x {args.n} panels", "",
             run.header(), "",
             "Command: `" + " ".join(["python studies/bench_default_solve.py", *sys.argv[1:]])
             + "`", "",
             "Yardstick, one NumPy forward evaluation (march + fold), best wall time (ms): "
             + ", ".join(f"{k} {1e3 * v:.1f}" for k, v in forward.items()) + ".", "",
             *table(rows, forward), "",
             f"Goal: solve <= {GOAL} s at 20 x 20 panels (the default path; the user surfaces "
             "with the default options):", "",
             *goal_table(rows), "",
             f"Profile (cumulative seconds, {threads[0]} thread(s), one solve each; cProfile "
             "inflates them):", "", *profile_table(profiles), ""]
    text = "\n".join(lines)
    write_table(args.out, text)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--profile-child":
        print(json.dumps(profile(sys.argv[2], int(sys.argv[3]))))
    elif len(sys.argv) == 4 and sys.argv[1] == "--surface-child":
        print(json.dumps(solve_surface(sys.argv[2], int(sys.argv[3]))))
    else:
        main()
