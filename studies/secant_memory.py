"""How many accepted steps the secant term B should remember: iterations and trial points of
the default solve (Levenberg-Marquardt on the marching manifold, run to the optimality
conditions) against ``reduced.SECANT_PAIRS``.

B is NL2SOL's structured secant update (:mod:`rffqm_nlp.design.solvers.levenberg_marquardt`)
applied, from zero at
every iteration, to the last ``SECANT_PAIRS`` accepted steps; "all" keeps every step, which
is the update applied once per step to the running B (the solver before 2026-12-03). The
problems: the bundled targets (targets/*.toml, ``stop_rms`` dropped) at ``--sizes`` panels a
side, and the built-in surfaces below at ``--surface-sizes`` (default options, the bundled
files' layout zigzag_i). Iterations and trials are deterministic; a trial is a marched point
evaluated (a counter around ``Manifold.point``, the start's included), so it counts the
failed steps too. The solves run in two worker processes; no times are reported.

    python studies/secant_memory.py [--pairs 2 3 4 6 all] [--sizes 10 12 ... 30]
        [--surface-sizes 12 16 20]
    python studies/secant_memory.py --smoke   (4 x 4, two memories, temporary output)

Writes studies/results/secant_memory.md.
"""

from __future__ import annotations

import argparse
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

from common import RESULTS, TARGETS, Run, add_smoke, smoke_dir, target_problem, write_table
from rffqm_nlp.design.solvers import levenberg_marquardt as reduced
from rffqm_nlp.design.problem import from_config

SURFACES = ("saddle", "cylinder", "paraboloid", "ellipsoid_cap", "torus_patch",
            "gaussian_bump")
ALL = 10 ** 9  # every accepted step kept


def solve(memory: int, kind: str, name: str, n: int) -> dict:
    """One default solve with ``SECANT_PAIRS = memory``: its status, iterations, trials and
    loss."""
    reduced.SECANT_PAIRS = memory
    trials = [0]
    point = reduced.Manifold.point

    def counted(self, x):
        trials[0] += 1
        return point(self, x)

    reduced.Manifold.point = counted
    try:
        if kind == "target":
            problem, options = target_problem(name, n)
        else:
            problem, options = from_config({"target": {"name": name},
                                            "design": {"panels": [n, n], "layout": "zigzag_i"}})
        stats = problem.solve(replace(options, stop_rms=None)).stats
    finally:
        reduced.Manifold.point = point
    return {"status": stats.status, "iterations": stats.iterations, "trials": trials[0],
            "objective": stats.objective}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", nargs="+", default=["2", "3", "4", "6", "all"])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(range(10, 31, 2)))
    ap.add_argument("--surface-sizes", type=int, nargs="+", default=[12, 16, 20])
    ap.add_argument("--out", type=Path, default=RESULTS / "secant_memory.md")
    add_smoke(ap)
    args = ap.parse_args()
    surfaces = SURFACES
    if args.smoke:
        args.pairs, args.sizes, args.surface_sizes = ["3", "all"], [4], [4]
        surfaces = SURFACES[:1]
        args.out = smoke_dir("secant_memory") / "secant_memory.md"
    run = Run()
    memories = [ALL if p == "all" else int(p) for p in args.pairs]
    problems = ([("target", t, n) for n in args.sizes for t in TARGETS]
                + [("surface", s, n) for n in args.surface_sizes for s in surfaces])
    with ProcessPoolExecutor(2) as pool:
        futures = {(m, p): pool.submit(solve, m, *p) for m in memories for p in problems}
        out = {key: f.result() for key, f in futures.items()}
    label = ["all" if m == ALL else str(m) for m in memories]
    lines = ["# The secant term's memory: iterations / trials of the default solve\n",
             run.header() + "\n",
             "Command: `python studies/secant_memory.py "
             f"--pairs {' '.join(args.pairs)} --sizes {' '.join(map(str, args.sizes))} "
             f"--surface-sizes {' '.join(map(str, args.surface_sizes))}`\n",
             "Each cell: iterations / trials (marched points evaluated, the failed steps "
             "and the start included); * marks a status other than Solve_Succeeded. "
             "\"all\": every accepted step kept (the solver before 2026-12-03). "
             "Largest relative spread of the final loss across the memories: "
             f"{spread(out, memories, problems):.1e}.\n",
             "| problem | panels | " + " | ".join(f"pairs {m}" for m in label) + " |",
             "|---|---|" + "---|" * len(memories)]
    for kind, name, n in problems:
        cells = []
        for m in memories:
            r = out[(m, (kind, name, n))]
            flag = "" if r["status"] == "Solve_Succeeded" else "*"
            cells.append(f"{r['iterations']} / {r['trials']}{flag}")
        lines.append(f"| {name} | {n} x {n} | " + " | ".join(cells) + " |")
    for title, keep in (("bundled targets", "target"), ("built-in surfaces", "surface"),
                        ("all", None)):
        cells = []
        for m in memories:
            rows = [out[(m, p)] for p in problems if keep is None or p[0] == keep]
            cells.append(f"**{sum(r['iterations'] for r in rows)} / "
                         f"{sum(r['trials'] for r in rows)}**")
        lines.append(f"| total, {title} | | " + " | ".join(cells) + " |")
    lines.append(f"\nwhole run {run.elapsed():.0f} s (two worker processes)\n")
    write_table(args.out, "\n".join(lines))


def spread(out: dict, memories: list[int], problems: list[tuple]) -> float:
    """The largest relative difference of the final loss between memories, over the
    problems."""
    worst = 0.0
    for p in problems:
        values = [out[(m, p)]["objective"] for m in memories]
        worst = max(worst, (max(values) - min(values)) / max(abs(min(values)), 1e-300))
    return worst


if __name__ == "__main__":
    main()
