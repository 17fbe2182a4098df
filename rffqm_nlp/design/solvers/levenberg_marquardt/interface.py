"""Levenberg-Marquardt as a solver of a design (:mod:`rffqm_nlp.design.solvers.context`):
the run's options, limits and counts around :func:`.loop.levenberg_marquardt`."""

from __future__ import annotations

import time
from typing import Callable

import numpy as np

from ...transcription import NLP
from ..context import Outcome, Run
from .loop import levenberg_marquardt
from .manifold import Manifold


def solve(nlp: NLP, x: np.ndarray, run: Run, *,
          reference: Callable[[], np.ndarray] | None = None) -> Outcome | None:
    """Levenberg-Marquardt on the marching manifold from ``x`` (n,) (or, where ``x``
    breaks a constraint, ``x`` moved toward ``reference()``, or restored), every step
    logged in ``run``. The status "Stalled" asks IPOPT to finish (from ``outcome.x``).
    None when it reached no admissible point (its restoration steps, if any, counted) and
    IPOPT should start from ``x``; a failure with its status when the iterations or the
    time ran out during that restoration (then no admissible point exists to report)."""
    options = run.options
    t1 = time.perf_counter()
    manifold = Manifold(nlp, options.boundary_knots or None)  # like IPOPT's build
    run.build_time += time.perf_counter() - t1
    out = levenberg_marquardt(
        nlp, x, options.damping, run.iterations_left, deadline=run.deadline, stop=run.stop,
        callback=run.log, tol=options.tol, manifold=manifold, reference=reference)
    run.iterations += out.iterations
    run.marched_iterations += out.iterations
    run.restoration_iterations += out.restored
    if out.status == "Inadmissible_Start":
        return _restoration_cut_short(run, x)
    run.start_moved = out.moved or run.start_moved  # later stages start admissible
    status = out.status
    if status == "Stalled" and run.iterations_left <= 0:
        status = "Maximum_Iterations_Exceeded"
    return Outcome(x=out.x, status=status, success=out.success, objective=out.objective,
                   best=out.x)


def _restoration_cut_short(run: Run, x: np.ndarray) -> Outcome | None:
    """Where Levenberg-Marquardt reached no admissible point: a failure with its status
    when ``max_iter`` or ``time_limit`` ran out during its restoration, else None."""
    if run.iterations_left <= 0:
        status = "Maximum_Iterations_Exceeded"
    elif run.deadline is not None and time.perf_counter() > run.deadline:
        status = "Maximum_WallTime_Exceeded"
    else:
        return None
    return Outcome(x=x, status=status, success=False, objective=None, best=None)
