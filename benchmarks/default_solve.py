"""The default solve: to optimality on the bundled targets and the surfaces a user brings,
against IPOPT alone and an earlier revision.

For each bundled target (targets/*.toml, its ``stop_rms`` dropped: the solve runs to the
optimality conditions at ``tol``) at each of ``--sizes`` N x N panels (default 20; issue 43
asks for 20, 32, 40, 100 and 200) it solves, each in a fresh process with the given numbers
of OpenBLAS threads (default 1 and 2):

* ``default``: ``problem.solve(options)`` with the file's options, i.e. Levenberg-Marquardt
  on the marching manifold alone (docs/solvers.md);
* ``ipopt``: the same with ``solver="ipopt"`` (exact Hessian): the baseline of the column
  "solve / IPOPT";
* ``baseline``: the default solve of the code at ``--baseline`` (a git revision, exported
  to a temporary folder with ``git archive``; default: the commit before Levenberg-Marquardt
  ran to the optimality conditions by itself, whose Levenberg-Marquardt stopped when a step
  gained less than 0.01% and handed over to IPOPT; ``none`` for no such rows);
* ``previous`` (with ``--previous REV``): the default solve of the code at that git
  revision, to compare a change of the default solve with the code before it in one run.

Then the surfaces a user brings (:data:`USER_SURFACES`), each solved as a user would,
``DesignProblem(target=surface, panels=(N, N)).solve()`` with the default options, in a
fresh process per solve: every built-in surface without a target file, and two callables
(``surfaces.Custom``: the README's lambda, and a bump written with CasADi's exp).

The yardstick, measured in this run: one forward evaluation of the NumPy model
(``numpy_model.march`` of the problem's starting Miura + ``numpy_model.fold`` at omega0),
best of ``--repeat`` x 10 calls; "solve / forward" is the solve's wall time over it, and
"call / forward" that of the whole ``solve()`` call (build, solve and the result: the
re-march, the fit, the collision check and the curvature maps; issue 43's goal at 20 x 20:
at most 70). Times: "build" the transcription and its derivatives, "solve" the solvers'
(wall, from the result's statistics), "call" the whole call (wall), "cpu" its CPU time. Each solve runs
``--repeat`` times (default 1); "goal" says whether a default solve took at most
:data:`GOAL` seconds.

    python benchmarks/default_solve.py [--sizes 20,32,40] [--threads 1,2] [--repeat 1]
        [--baseline REV|none] [--previous REV] [--users all|none]
        [--out docs/benchmarks/default_solve.md]
    python benchmarks/default_solve.py --smoke   (the sphere cap and the two callables at
        4 x 4 panels, one thread, no baseline, temporary output)
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:  # a child given the package to measure keeps it
    sys.path.insert(0, str(ROOT))

import rffqm_nlp as rq  # noqa: E402
from common import (TARGETS, Run, add_output, export_package, fmt,  # noqa: E402
                    markdown_table, output, ratio, run_child, solve_in_child, solve_problem,
                    target_problem, write_page)

#: the commit before Levenberg-Marquardt ran to the optimality conditions by itself
BASELINE = "0f9ad8d"
GOAL = 0.5  # seconds of solve time at 20 x 20 panels (issue 21)
COLUMNS = ("target", "panels", "path", "threads", "status", "iterations (LM)", "build (s)",
           "solve (s)", "call (s)", "cpu (s)", "solve / forward", "call / forward",
           "solve / IPOPT", "goal", "fit RMS / diameter")

#: the surfaces a user brings (name -> a maker): the built-in ones without a target file,
#: and two callables
USER_SURFACES: dict[str, Callable[[], rq.surfaces.Surface]] = {
    **{name: functools.partial(rq.surfaces.get, name) for name in rq.surfaces.names()
       if not (ROOT / "targets" / f"{name}.toml").exists()},
    "custom_readme": lambda: rq.surfaces.Custom(lambda u, v: (u, v, 0.1 * u * v),
                                                ((-1, 1), (-1, 1))),
    "custom_bump": lambda: rq.surfaces.Custom(
        lambda u, v: (u, v, 0.3 * ca.exp(-(u * u + v * v))), ((-1.5, 1.5), (-1.5, 1.5))),
}


def problem_of(name: str, n: int) -> rq.DesignProblem:
    """The problem of a bundled target (its file's) or of a user surface at n x n panels."""
    if name in USER_SURFACES:
        return rq.DesignProblem(target=USER_SURFACES[name](), panels=(n, n))
    return target_problem(name, n)[0]


def forward_time(name: str, n: int, repeat: int) -> float:
    """Best wall time (s) of one NumPy march + fold of the problem's starting Miura."""
    start = problem_of(name, n).start()
    best = np.inf
    for _ in range(10 * repeat):
        t0 = time.perf_counter()
        rq.numpy_model.fold(rq.numpy_model.march(start.boundary), start.omega)
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
    return solve_problem(problem_of(name, n), rq.SolveOptions(), {"n": n, "target": name})


def report(row: dict) -> dict:
    """Print a solve's row in short (the run's progress) and return it."""
    print(json.dumps({k: row.get(k) for k in ("target", "path", "threads", "status",
                                               "iterations", "build_time", "solve_time")}),
          flush=True)
    return row


def ipopt_solves(rows: list[dict]) -> dict[tuple[str, int, int], float]:
    """The median solve time of the ``ipopt`` rows per (target, panels, threads): the
    baseline."""
    groups: dict[tuple[str, int, int], list[float]] = {}
    for r in rows:
        if r["path"] == "ipopt" and r.get("solve_time") is not None:
            groups.setdefault((r["target"], r["n"], r["threads"]), []).append(r["solve_time"])
    return {k: float(np.median(v)) for k, v in groups.items()}


def table(rows: list[dict], forward: dict[tuple[str, int], float]) -> list[str]:
    """The results table: one row per solve, its time against the yardstick and against
    IPOPT's solve of the same target in this run."""
    ipopt = ipopt_solves(rows)
    cells = []
    for r in rows:
        solve, n, yardstick = r.get("solve_time"), r["n"], forward[(r["target"], r["n"])]
        goal = "-" if r["path"] != "default" or n != 20 else (
            "yes" if r.get("success") and solve is not None and solve <= GOAL else "no")
        cells.append([
            r["target"], f"{n} x {n}", r["path"], str(r["threads"]), r.get("status", "-"),
            f"{r.get('iterations', '-')} ({r.get('marched_iterations', '-')})",
            fmt(r.get("build_time"), ".2f"), fmt(solve, ".2f"), fmt(r.get("wall"), ".2f"),
            fmt(r.get("cpu"), ".2f"), ratio(solve, yardstick, ".0f"),
            ratio(r.get("wall"), yardstick, ".0f"),
            ratio(solve, ipopt.get((r["target"], n, r["threads"]))), goal,
            fmt((r.get("fit") or {}).get("rms"), ".4f")])
    return markdown_table(COLUMNS, cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="20", help="panels a side, comma-separated")
    parser.add_argument("--users", choices=("all", "none"), default="all",
                        help="the surfaces a user brings too, or not")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--baseline", default=BASELINE, help="a git revision, or none")
    parser.add_argument("--previous", default=None)
    add_output(parser, "default_solve")
    args = parser.parse_args()
    targets = TARGETS
    if args.smoke:
        args.sizes, args.threads, args.baseline, args.previous = "4", "1", "none", None
        targets = TARGETS[:1]
    threads = [int(t) for t in args.threads.split(",")]
    sizes = [int(n) for n in args.sizes.split(",")]
    run = Run()
    users = ([] if args.users == "none" else
             [k for k in USER_SURFACES if k.startswith("custom_") or not args.smoke])
    forward = {(name, n): forward_time(name, n, args.repeat)
               for name in (*targets, *users) for n in sizes}
    packages = {"default": ROOT}
    if args.previous:  # right after the default: the two rows see the same load
        packages["previous"] = export_package(args.previous)
    packages["ipopt"] = ROOT
    if args.baseline != "none":
        packages["baseline"] = export_package(args.baseline)
    rows = []
    for n in sizes:
        for t in threads:
            for name in targets:
                for path, package in packages.items():
                    for _ in range(args.repeat):
                        rows.append(report(solve_row(name, n, path, t, package)))
            for name in users:
                for _ in range(args.repeat):
                    rows.append(report(solve_row(name, n, "default", t, ROOT)))
    at_20 = [r for r in rows if r["path"] == "default" and r["n"] == 20]
    within = sum(bool(r.get("success")) and r.get("solve_time") is not None
                 and r["solve_time"] <= GOAL for r in at_20)
    lines = [*run.preamble("default_solve.py"),
             "- panels a side: " + ", ".join(map(str, sizes)) + "; yardstick, one NumPy "
             "forward evaluation (march + fold), best wall time (ms): "
             + ", ".join(f"{k} {n} {1e3 * v:.1f}" for (k, n), v in forward.items()),
             "- baseline: IPOPT alone (exact Hessian), the median of its runs of the same "
             "target and threads" + ("" if args.baseline == "none" else
                                     f"; `baseline` rows: the code at {args.baseline}"), "",
             *table(rows, forward), "",
             f"Goal: solve <= {GOAL} s at 20 x 20 panels (the default path; the user surfaces "
             f"with the default options): {within} of {len(at_20)} default solves at "
             "20 x 20 within it."]
    write_page(output(args, "default_solve"), "The default solve", "\n".join(lines))


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--surface-child":
        print(json.dumps(solve_surface(sys.argv[2], int(sys.argv[3]))))
    else:
        main()
