"""Coarse-to-fine: a design carried over from a coarser pattern against the Miura start.

A bundled target (``--target``, default the sphere cap) at n x n panels for each of
``--sizes``, solved to ``--stop-rms`` (default 0.9% RMS/diameter) with the target file's
options, twice in the same process: from the Miura-ori, and from the design of n / ``--ratio``
panels a side (itself solved from its Miura first) carried to n x n
(``DesignProblem.solve(warm_start=coarser result)``, :func:`rffqm_nlp.model.boundary.refine`).
The table gives each run's iterations, its first and last loss, its fit and wall time, and
the carried run's time, alone and with the coarse solve, over the Miura start's.

    python studies/coarse_start.py [--sizes 40 100 200] [--ratio 2] [--target sphere_cap]
        [--stop-rms 0.009] [--out studies/results/coarse_start.md]
    python studies/coarse_start.py --smoke   (8 panels from 4, temporary output)
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

from common import (RESULTS, STOP_RMS, TARGETS, Run, add_smoke, fmt, smoke_dir,
                    target_problem, write_table)
from rffqm_nlp.design.results import DesignResult


def timed(problem, options, warm_start: DesignResult | None = None
          ) -> tuple[DesignResult, float]:
    """The result of one solve and its wall time (s)."""
    t0 = time.perf_counter()
    result = problem.solve(options, warm_start=warm_start)
    return result, time.perf_counter() - t0


def row(label: str, n: int, result: DesignResult, wall: float) -> dict:
    """A table row of one solve."""
    return {"start": label, "n": n, "status": result.stats.status,
            "iterations": result.stats.iterations,
            "first": result.stats.history["objective"][0], "last": result.stats.objective,
            "rms": result.fit.rms, "wall": wall}


def sizes_run(target: str, n: int, ratio: int, stop_rms: float) -> list[dict]:
    """The Miura start, the coarse design and the carried start at n (one process)."""
    coarse_n = 2 * max(2, round(n / ratio / 2))
    problem, options = target_problem(target, n)
    coarse_problem, _ = target_problem(target, coarse_n)
    options = replace(options, stop_rms=stop_rms)
    miura = row("Miura", n, *timed(problem, options))
    coarse_result, coarse_wall = timed(coarse_problem, options)
    coarse = row("Miura", coarse_n, coarse_result, coarse_wall)
    carried = row(f"carried from {coarse_n}", n, *timed(problem, options, coarse_result))
    carried["ratio"] = carried["wall"] / miura["wall"]
    carried["ratio_with_coarse"] = (carried["wall"] + coarse_wall) / miura["wall"]
    return [miura, coarse, carried]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[40, 100, 200])
    ap.add_argument("--ratio", type=int, default=2)
    ap.add_argument("--target", default="sphere_cap", choices=TARGETS)
    ap.add_argument("--stop-rms", type=float, default=STOP_RMS)
    ap.add_argument("--out", type=Path, default=RESULTS / "coarse_start.md")
    add_smoke(ap)
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.out = [8], smoke_dir("coarse_start") / "coarse_start.md"
    clock = Run()
    rows = []
    for n in args.sizes:
        for r in sizes_run(args.target, n, args.ratio, args.stop_rms):
            rows.append(r)
            print(r, flush=True)
    lines = ["| panels | start | status | iterations | first loss | last loss | RMS/diam | "
             "wall [s] | / Miura's | with the coarse solve, / Miura's |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['n']} x {r['n']} | {r['start']} | {r['status']} | {r['iterations']} | "
            f"{r['first']:.4g} | {r['last']:.4g} | {100 * r['rms']:.2f}% | {r['wall']:.1f} | "
            f"{fmt(r.get('ratio'), '.2f')} | {fmt(r.get('ratio_with_coarse'), '.2f')} |")
    text = "\n".join([
        f"# Coarse-to-fine: {args.target} to {100 * args.stop_rms:.1f}% RMS/diameter from a "
        f"design of 1/{args.ratio} the panels a side against the Miura start", "",
        clock.header(), "",
        "Command: `" + " ".join(["python studies/coarse_start.py", *sys.argv[1:]]) + "`", "",
        "One process, the solves one after the other; wall: seconds of `prob.solve()` "
        "(transcription, derivative build, solve, re-march and fit).", "", *lines, ""])
    write_table(args.out, text)


if __name__ == "__main__":
    main()
