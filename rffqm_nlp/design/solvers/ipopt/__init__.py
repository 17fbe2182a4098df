"""IPOPT on the design NLP, either transcription.

:func:`solve` runs IPOPT from a point of the NLP: one run per phase of :func:`phases` (the
damped Gauss-Newton Hessian first where asked, then the exact one from the last iterate and
its multipliers), each built with the options of :func:`ipopt_options` and the iteration
callback :class:`.iteration_log.IterationLog`, which keeps the best admissible iterate and
stops IPOPT once ``run.stop`` holds. The Hessians are in :mod:`.hessians`.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import Any

import casadi as ca
import numpy as np

from ....ipopt_options import NO_OPTION_FILE
from ...options import SolveOptions
from ...transcription import NLP
from ..context import Outcome, Run
from .hessians import gauss_newton_hessian, lagrangian_hessian
from .iteration_log import IterationLog

#: Largest sequential pattern (panels) whose NLP is expanded to SX; see :func:`expand`.
SX_MAX_PANELS = 144
#: IPOPT's barrier from a cold start. The loss is small against the many log-barrier terms,
#: so IPOPT's default (monotone from mu = 0.1) first solves a different problem (angles near
#: pi/2, long sides): the simultaneous transcription loses feasibility there and never
#: recovers, the sequential one needs more iterations. "adaptive" suits the simultaneous
#: NLP; for the sequential one it found a worse local minimum of a small sphere cap, which
#: a small mu_init does not (docs/decisions/ipopt.md).
COLD_BARRIER = {"sequential": {"ipopt.mu_init": 1e-3},
                "simultaneous": {"ipopt.mu_strategy": "adaptive"}}
#: Most iterations of the damped Gauss-Newton Hessian before the exact one takes over (see
#: :func:`phases`).
GAUSS_NEWTON_ITERATIONS = 30
#: IPOPT statuses after which the exact Hessian does not take over from Gauss-Newton (nor
#: does it after stop_rms is reached).
HANDOVER_STOP_STATUSES = ("Solve_Succeeded", "Maximum_WallTime_Exceeded")


def phases(options: SolveOptions, done: int) -> list[tuple[str, int]]:
    """(Hessian, iteration limit) of each IPOPT run of one solve stage, ``done``
    iterations having been spent already.

    With ``hessian = "gauss-newton"`` the damped Gauss-Newton runs first, for at most
    :data:`GAUSS_NEWTON_ITERATIONS`; unless it reaches stop_rms or converges, the exact
    Hessian takes over from its last iterate and multipliers. On its own it converges
    only linearly, and its last iterates may fail the re-march check.
    """
    left = options.max_iter - done
    if options.hessian != "gauss-newton":
        return [(options.hessian, left)]
    first = min(GAUSS_NEWTON_ITERATIONS, left)
    return [("gauss-newton", first)] + ([("exact", left - first)] if left > first else [])


def expand(options: SolveOptions, panels: tuple[int, int]) -> bool:
    """Expand the NLP to SX (fast evaluation, costly derivative build) or keep MX.

    The sequential NLP is dense: its SX Hessian's build grows fast with the pattern, so
    only patterns up to :data:`SX_MAX_PANELS` panels are expanded. The simultaneous
    NLP's time goes to the linear solver, not to evaluations, so it stays MX
    (docs/decisions/ipopt.md).
    """
    return options.transcription == "sequential" and panels[0] * panels[1] <= SX_MAX_PANELS


def solve(nlp: NLP, x: np.ndarray, run: Run, *, panels: tuple[int, int], warm: bool = False,
          best: np.ndarray | None = None) -> Outcome:
    """IPOPT from ``x`` (n,) on the NLP of a pattern of ``panels``: one run per phase of
    :func:`phases`, each later run handed the last one's iterate and multipliers.
    ``warm``: ``x`` is near an optimum (a small barrier keeps IPOPT there); ``best``: the
    best admissible point met before, kept where IPOPT meets none better."""
    multipliers: dict[str, Any] = {}
    log = None
    for hessian, max_iter in phases(run.options, run.iterations):
        outcome, log = _run(nlp, x, run, hessian, max_iter, panels,
                            warm=warm or bool(multipliers), multipliers=multipliers,
                            previous=log)
        if outcome.best is None:
            outcome = replace(outcome, best=best)
        x, best = outcome.x, outcome.best
        if outcome.status == "Fit_Reached" or outcome.status in HANDOVER_STOP_STATUSES:
            break
        multipliers = outcome.multipliers
    return outcome


def _run(nlp: NLP, x: np.ndarray, run: Run, hessian: str, max_iter: int,
         panels: tuple[int, int], warm: bool, multipliers: dict[str, Any],
         previous: IterationLog | None) -> tuple[Outcome, IterationLog]:
    """One IPOPT run with ``hessian`` for at most ``max_iter`` iterations."""
    t1 = time.perf_counter()
    elapsed = t1 - run.t0
    opts = ipopt_options(run.options, hessian, max_iter, elapsed, panels, verbose=run.verbose,
                         warm=warm, multipliers=bool(multipliers))
    if hessian == "gauss-newton":
        opts["hess_lag"] = gauss_newton_hessian(nlp, run.options.damping)
    elif hessian == "exact" and nlp.parts is not None:
        opts["hess_lag"] = lagrangian_hessian(nlp)
    log = IterationLog(nlp, run.history, run.callback, run.stop,
                       previous if multipliers else None, t0=time.perf_counter() - elapsed)
    opts["iteration_callback"] = log
    solver = ca.nlpsol("design", "ipopt", {"x": nlp.x, "f": nlp.objective, "g": nlp.g}, opts)
    run.build_time += time.perf_counter() - t1
    sol = solver(x0=x, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg, **multipliers)
    stats = dict(solver.stats())
    run.iterations += int(stats["iter_count"])
    if hessian == "gauss-newton":
        run.gauss_newton_iterations += int(stats["iter_count"])
    found = {"multipliers": {"lam_g0": sol["lam_g"], "lam_x0": sol["lam_x"]},
             "g": sol["g"].full().ravel(), "best": log.best}
    if log.reached:
        return Outcome(x=log.reached_x, status="Fit_Reached", success=True,
                       objective=log.reached_objective, **found), log
    return Outcome(x=sol["x"].full().ravel(), status=stats["return_status"],
                   success=bool(stats["success"]), objective=float(sol["f"]), **found), log


def ipopt_options(options: SolveOptions, hessian: str, max_iter: int, elapsed: float,
                  panels: tuple[int, int], verbose: bool = False, warm: bool = False,
                  multipliers: bool = False) -> dict[str, Any]:
    """CasADi's nlpsol options of one IPOPT run: ``options``' limits (the time limit less
    ``elapsed`` seconds), the barrier of a cold or a ``warm`` start, the warm start from
    ``multipliers``, the user's ``ipopt_options`` and the ``hessian``'s approximation (the
    Hessian functions themselves are added by the caller). IPOPT reads no option file."""
    opts: dict[str, Any] = {
        "ipopt.max_iter": max_iter, "ipopt.tol": options.tol,
        "ipopt.constr_viol_tol": 1e-9, "ipopt.print_level": 5 if verbose else 0,
        "print_time": verbose, "ipopt.sb": "yes",
        "expand": expand(options, panels), **NO_OPTION_FILE}
    if options.time_limit is not None:
        opts["ipopt.max_wall_time"] = max(options.time_limit - elapsed, 1e-3)
    if warm or options.barrier_init is not None:
        # near an optimum a small barrier keeps IPOPT from wandering off
        mu_init = 1e-6 if options.barrier_init is None else options.barrier_init
        opts.update({"ipopt.mu_init": mu_init, "ipopt.bound_push": 1e-9,
                     "ipopt.bound_frac": 1e-9})
    else:
        opts.update(COLD_BARRIER[options.transcription])
    if multipliers:
        opts["ipopt.warm_start_init_point"] = "yes"
    opts.update({f"ipopt.{name}": value for name, value in options.ipopt_options.items()})
    if hessian == "limited-memory":
        opts["ipopt.hessian_approximation"] = "limited-memory"
    return opts
