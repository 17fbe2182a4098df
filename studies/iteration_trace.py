"""Where the default solve's iterations go: one solve traced step by step.

A bundled target (``--target``, default the sphere cap) at n x n panels (``--n``, default 20),
solved with its file's options to the optimality conditions (Levenberg-Marquardt on the
marching manifold, :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`), each accepted step in a
row: the loss and its
gap to the final loss (relative), the damping lam of the step taken, the rows of the step's
QP (working: the rows it was given; active: those with a nonzero multiplier), the trial
steps taken (a step that broke a constraint and was corrected, or failed and raised lam,
counts as one more; corrected: the steps taken with rows shifted by a correction), whether
the step used the secant term, and the optimality error at the point (scaled, as the
stopping test). Then a summary: iterations, trials, the step from which the active rows
no longer changed, and the mean contraction of the loss gap between two given steps
(``--from``, ``--to``).

The trace wraps the solver's internals (the step, the optimality test and the
linearisation of :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`) and changes nothing in the
solve.

    .venv/bin/python studies/iteration_trace.py [--target sphere_cap] [--n 20] [--from 10]
        [--to 30] [--out studies/results]
    .venv/bin/python studies/iteration_trace.py --smoke   (4 x 4 panels, temporary output)
"""

from __future__ import annotations

import argparse
from dataclasses import replace
from pathlib import Path

import numpy as np

from common import RESULTS, TARGETS, Run, add_smoke, fmt, smoke_dir, target_problem, write_table
from rffqm_nlp.design.solvers import levenberg_marquardt as reduced
from rffqm_nlp.design.results import DesignResult


class Trace:
    """The steps of one solve, grouped by the point they were taken from (one group per
    linearisation): for each step its lam, working and active rows, shift and model."""

    def __init__(self):
        self.points: list[dict] = []
        #: the stopping test's scale of the optimality error (reduced.levenberg_marquardt):
        #: max(1, |J' r at the start| / 100)
        self.scale: float | None = None

    def linearized(self, objective: float) -> None:
        self.points.append({"objective": objective, "steps": [], "error": None})

    def step(self, lam: float, shifted: bool, step, augmented: bool) -> None:
        active = (set() if step is None or not step.which.size else
                  set(step.which[np.abs(step.multipliers) > 0].tolist()))
        self.points[-1]["steps"].append({
            "lam": lam, "shifted": shifted, "augmented": augmented,
            "working": 0 if step is None else int(step.which.size), "active": active})

    def tested(self, error: float, gradient: np.ndarray) -> None:
        if self.scale is None:
            self.scale = max(1.0, float(np.max(np.abs(gradient))) / 100)
        self.points[-1]["error"] = error / self.scale


def traced_solve(target: str, n: int) -> tuple[Trace, DesignResult]:
    """Solve the target with its file's options (no stop_rms), the solver's internals
    wrapped to record the trace; restores them after."""
    trace = Trace()
    originals = (reduced.Manifold.linearize, reduced._Steps.__call__, reduced._kkt_error)

    def linearize(self, p, metric=True):
        trace.linearized(p.objective)
        return originals[0](self, p, metric)

    def steps(self, m, lam, shift):
        out = originals[1](self, m, lam, shift)
        trace.step(lam, bool(np.any(shift > 0)), out, m.H is not m.JtJ)
        return out

    def kkt_error(m, steps_, step):
        error = originals[2](m, steps_, step)
        trace.tested(error, m.grad)
        return error

    reduced.Manifold.linearize, reduced._Steps.__call__ = linearize, steps
    reduced._kkt_error = kkt_error
    try:
        problem, options = target_problem(target, n)
        result = problem.solve(replace(options, stop_rms=None))
    finally:
        reduced.Manifold.linearize, reduced._Steps.__call__, reduced._kkt_error = originals
    return trace, result


def table(trace: Trace, final: float) -> list[str]:
    lines = ["| step | loss | gap / final loss | lam | QP rows: working, active | trials "
             "(corrected) | secant term | optimality error |", "|---|---|---|---|---|---|---|---|"]
    for k, point in enumerate(trace.points):
        steps = point["steps"]
        last = steps[-1] if steps else None
        lines.append(
            f"| {k} | {point['objective']:.7g} | {(point['objective'] - final) / final:.2e} "
            f"| {fmt(None if last is None else last['lam'], '.2g')} "
            f"| {'-' if last is None else last['working']}, "
            f"{'-' if last is None else len(last['active'])} "
            f"| {len(steps)} ({sum(s['shifted'] for s in steps)}) "
            f"| {'-' if last is None else ('yes' if last['augmented'] else 'no')} "
            f"| {fmt(point['error'], '.2e')} |")
    return lines


def summary(trace: Trace, final: float, first: int, last: int) -> list[str]:
    active = [p["steps"][-1]["active"] if p["steps"] else set() for p in trace.points]
    settled = len(active) - 1
    while settled > 0 and active[settled - 1] == active[-1]:
        settled -= 1
    gaps = [(p["objective"] - final) / final for p in trace.points]
    last = min(last, len(gaps) - 1)
    ratio = None
    if 0 <= first < last and gaps[first] > 0 and gaps[last] > 0:
        ratio = (gaps[last] / gaps[first]) ** (1 / (last - first))
    trials = sum(len(p["steps"]) for p in trace.points)
    return [f"- iterations {len(trace.points) - 1}, trial steps {trials}",
            f"- the active rows are the same from step {settled} on "
            f"({len(active[-1])} row{'s' if len(active[-1]) != 1 else ''})",
            f"- mean contraction of the loss gap from step {first} to {last}: {fmt(ratio, '.2f')}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--target", default="sphere_cap", choices=TARGETS)
    parser.add_argument("--n", type=int, default=20)
    parser.add_argument("--from", dest="first", type=int, default=10)
    parser.add_argument("--to", dest="last", type=int, default=30)
    parser.add_argument("--out", type=Path, default=RESULTS)
    add_smoke(parser)
    args = parser.parse_args()
    if args.smoke:
        args.n, args.first, args.last = 4, 0, 3
        args.out = smoke_dir("iteration_trace")
    run = Run()
    trace, result = traced_solve(args.target, args.n)
    final = result.stats.objective
    lines = [f"# The default solve step by step: {args.target}, {args.n} x {args.n} panels", "",
             f"- {run.header()}", f"- status {result.stats.status}, final loss {final:.10g}, "
             f"fit RMS / diameter {result.fit.rms:.4f}; {result.stats.marched_iterations} of "
             f"{result.stats.iterations} iterations by Levenberg-Marquardt (the trace covers "
             "those; the rest, if any, IPOPT's after a stall)",
             *summary(trace, final, args.first, args.last), "",
             *table(trace, final)]
    write_table(args.out / f"iteration_trace_{args.target}_{args.n}.md", "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
