"""Multistart: solve a design problem from several starting Miuras and keep the best fit
(``SolveOptions.multistart``)."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from ..errors import InfeasibleDesign, InputError, SolverFailed, one_line
from ..files import check_value
from ..targets.curvature_target import Curvature
from .options import SOLVE_KEYS, SolveOptions
from .results import DesignResult

if TYPE_CHECKING:  # for type hints only: the problem's solve calls this module
    from .problem import DesignProblem

#: Half-widths (radians) of the uniform perturbations of alpha0 and omega0 of the starts
#: 1, 2, ... of a multistart; the perturbed values are clipped into their valid ranges.
MULTISTART_SPREAD = {"alpha0": 0.3, "omega0": 0.6}


def multistart_starts(problem: DesignProblem, starts: int, seed: int) -> list[tuple[float, float]]:
    """(alpha0, omega0) of each start of a multistart: the problem's own first, then
    ``starts - 1`` seeded uniform perturbations by :data:`MULTISTART_SPREAD`, clipped to
    alpha0 in [min_angle + 0.05, pi/2 - 0.05] and omega0 inside ``omega_bounds`` (5% of
    their width away from each end)."""
    starts = check_value(starts, SOLVE_KEYS["multistart"], "[solve] multistart")
    seed = check_value(seed, SOLVE_KEYS["seed"], "[solve] seed")
    rng = np.random.default_rng(seed)
    lo, hi = problem.omega_bounds
    margin = 0.05 * (hi - lo)
    alpha = np.clip(problem.alpha0 + rng.uniform(-1, 1, starts - 1) * MULTISTART_SPREAD["alpha0"],
                    problem.min_angle + 0.05, np.pi / 2 - 0.05)
    omega = np.clip(problem.omega0 + rng.uniform(-1, 1, starts - 1) * MULTISTART_SPREAD["omega0"],
                    lo + margin, hi - margin)
    return [(problem.alpha0, problem.omega0)] + [(float(a), float(w)) for a, w in zip(alpha, omega)]


def solve_multistart(problem: DesignProblem, options: SolveOptions, *,
                     callback: Callable[[dict], None] | None = None,
                     warm_start: DesignResult | None = None,
                     verbose: bool = False) -> DesignResult:
    """Solve ``problem`` from each of the ``options.multistart`` starts of
    :func:`multistart_starts` (seeded by ``options.seed``); keep the best.

    A start that ends in :class:`InfeasibleDesign` or :class:`SolverFailed` is recorded and
    skipped; the result is the successful start with the smallest fit.rms, with the
    problem and options as asked (``result.problem``) and ``result.stats.multistart`` =
    {"starts", "seed", "chosen" (index of the kept start), "time" (all starts, s), "runs":
    one entry per start with alpha0, omega0, status, rms (None when it failed), iterations,
    time and reason}. When every start fails, raises :class:`InfeasibleDesign` if all were
    infeasible, else :class:`SolverFailed` with the status of the first failed solve.
    """
    if warm_start is not None:
        raise InputError("multistart and warm_start exclude each other: a warm start replaces "
                         "the starting Miuras that multistart varies")
    t0 = time.perf_counter()
    single = replace(options, multistart=1)
    runs: list[dict[str, Any]] = []
    errors: list[InfeasibleDesign | SolverFailed] = []
    best: tuple[int, DesignResult] | None = None
    for k, (alpha0, omega0) in enumerate(multistart_starts(problem, options.multistart,
                                                           options.seed)):
        t1 = time.perf_counter()
        run: dict[str, Any] = {"start": k, "alpha0": alpha0, "omega0": omega0}
        try:
            res = replace(problem, alpha0=alpha0, omega0=omega0).solve(
                single, callback=callback, verbose=verbose)
        except (InfeasibleDesign, SolverFailed) as exc:
            errors.append(exc)
            run.update(status=getattr(exc, "status", "") or "Infeasible_Problem_Detected",
                       rms=None, iterations=None, reason=one_line(exc))
        else:
            run.update(status=res.stats.status, rms=res.fit.rms,
                       iterations=res.stats.iterations, reason="")
            if best is None or _error(problem, res) < _error(problem, best[1]):
                best = (k, res)
        run["time"] = time.perf_counter() - t1
        runs.append(run)
    if best is None:
        statuses = ", ".join(sorted({r["status"] for r in runs}))
        message = (f"all {options.multistart} starts of the multistart failed ({statuses}); "
                   f"the problem's own start: {one_line(errors[0])}")
        failed = [e for e in errors if isinstance(e, SolverFailed)]
        if not failed:
            raise InfeasibleDesign(message) from errors[0]
        raise SolverFailed(message, status=failed[0].status, stats=failed[0].stats,
                           last_iterate=failed[0].last_iterate,
                           best_iterate=failed[0].best_iterate) from failed[0]
    chosen, res = best
    stats = replace(res.stats, multistart={
        "starts": options.multistart, "seed": options.seed, "chosen": chosen,
        "time": time.perf_counter() - t0, "runs": runs})
    return replace(res, stats=stats, problem=problem.config(options))



def _error(problem: DesignProblem, result: DesignResult) -> float:
    """What a multistart keeps the smallest of: the fit's RMS distance, or for a curvature
    target (whose design is its own lattice: fit.rms is 0) the curvature error."""
    if isinstance(problem.target, Curvature):
        return result.fit.curvature_rms
    return result.fit.rms
