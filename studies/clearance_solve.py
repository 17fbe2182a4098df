"""The cost of ``min_clearance``: the sphere cap designed with a sheet thickness kept.

The bundled sphere cap (targets/sphere_cap.toml, its ``stop_rms`` dropped) at N x N panels
(default 20) is solved once without clearance; the closest pair of its panels that share no
vertex, at distance d, sets the clearances asked: ``--factors`` times d (default 1.2 and 2).
Each is designed in a fresh process by the code here (``default``: each clearance round's
start, which its new rows break, restored by Levenberg-Marquardt) and by the code at
``--previous`` (default :data:`PREVIOUS`, the commit before that restoration, whose rounds
re-solved with IPOPT), ``--repeat`` times. The table gives the status, the iterations (those
of Levenberg-Marquardt, and of them the restoration steps), the solve's wall time (the
result's statistics), the fit, and the result's closest pair over the clearance asked (at
least 1 where the design keeps it).

Usage: ``python studies/clearance_solve.py [--n 20] [--factors 1.2,2] [--repeat 1]
[--previous REV] [--out studies/results/clearance_solve.md]``; ``--smoke``: 6 x 6 panels,
the first factor, no previous, output to a temporary folder.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:  # a child given the package to measure keeps it
    sys.path.insert(0, str(ROOT))

from common import (RESULTS, Run, add_smoke, export_package, fmt,  # noqa: E402
                    run_child, smoke_dir, target_problem, write_table)
from rffqm_nlp.design.clearance import closest  # noqa: E402
from rffqm_nlp.errors import SolverFailed  # noqa: E402

#: the commit before Levenberg-Marquardt restored a start that breaks a constraint
PREVIOUS = "a371ad2"
TARGET = "sphere_cap"


def closest_distance(pattern, omega: float, reach: float) -> float:
    """The distance of the closest pair of panels that share no vertex (inf beyond about
    ``reach``)."""
    return closest(pattern, omega, reach)[1].distance


def design(n: int, clearance: float) -> dict:
    """One design with ``min_clearance`` = clearance: its statistics, fit and closest pair
    (a failed one: its status and error)."""
    problem, options = target_problem(TARGET, n, min_clearance=clearance)
    try:
        res = problem.solve(replace(options, stop_rms=None))
    except SolverFailed as exc:
        return {"status": exc.status, "error": str(exc)}
    stats = res.stats.to_dict()
    return {"status": stats["status"], "iterations": stats["iterations"],
            "marched": stats["marched_iterations"],
            "restoration": stats.get("restoration_iterations"),
            "solve_time": stats["solve_time"], "rms": res.fit.rms,
            "closest": closest_distance(res.pattern, res.omega, 2 * clearance)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--factors", default="1.2,2")
    parser.add_argument("--repeat", type=int, default=1)
    parser.add_argument("--previous", default=PREVIOUS)
    parser.add_argument("--out", type=Path, default=RESULTS / "clearance_solve.md")
    add_smoke(parser)
    args = parser.parse_args()
    factors = [float(f) for f in args.factors.split(",")]
    if args.smoke:
        args.n, factors, args.previous = 6, factors[:1], None
        args.out = smoke_dir("clearance_solve") / "clearance_solve.md"
    run = Run()
    problem, options = target_problem(TARGET, args.n)
    free = problem.solve(replace(options, stop_rms=None))
    d = closest_distance(free.pattern, free.omega, 1.0)
    packages = {"default": ROOT}
    if args.previous:
        packages["previous"] = export_package(args.previous)
    rows = []
    for factor in factors:
        for path, package in packages.items():
            for _ in range(args.repeat):
                row = run_child(__file__, "--child", str(args.n), repr(factor * d),
                                env={"PYTHONPATH": str(package), "OPENBLAS_NUM_THREADS": "1"})
                rows.append({"factor": factor, "path": path, **row})
                print(json.dumps(rows[-1]), flush=True)
    lines = [f"# min_clearance on the {TARGET} at {args.n} x {args.n} panels", "",
             run.header(), "",
             "Command: `" + " ".join(["python studies/clearance_solve.py", *sys.argv[1:]])
             + "`", "",
             f"Without clearance: {free.stats.status}, {free.stats.iterations} iterations, "
             f"solve {free.stats.solve_time:.2f} s, fit RMS / diameter {free.fit.rms:.5f}; "
             f"closest pair d = {d:.5g}. One OpenBLAS thread, each design a fresh process.", "",
             "| clearance / d | path | status | iterations | by LM | restoration "
             "| solve (s) | fit RMS / diameter | closest / clearance |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        kept = None if r.get("closest") is None else r["closest"] / (r["factor"] * d)
        lines.append(
            f"| {r['factor']:g} | {r['path']} | {r['status']} | {r.get('iterations', '-')} "
            f"| {r.get('marched', '-')} | {fmt(r.get('restoration'), 'd')} "
            f"| {fmt(r.get('solve_time'), '.2f')} | {fmt(r.get('rms'), '.5f')} "
            f"| {fmt(kept, '.4f')} |")
    write_table(args.out, "\n".join(lines + [""]))


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        print(json.dumps(design(int(sys.argv[2]), float(sys.argv[3]))))
    else:
        main()
