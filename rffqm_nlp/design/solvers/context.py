"""What every solver of a design is handed and hands back: the :class:`Run` of one solve and
the :class:`Outcome` of one solver's part of it.

A solver is a module with ``solve(nlp, x, run, ...) -> Outcome`` (:mod:`.ipopt`,
:mod:`.levenberg_marquardt`): it starts from the point ``x`` (n,) of the NLP, reads its own
options from ``run.options``, stops at ``run.deadline`` and once ``run.stop`` holds, and
counts its iterations and build time in ``run``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ...errors import SolverFailed, raise_for_ipopt
from ..options import SolveOptions
from ..results import SolveStats
from ..transcription import NLP


@dataclass
class Run:
    """One solve, over its stages and solvers: its options, who listens (``callback``
    receives {"iter", "objective", "inf_pr", "elapsed"} every iteration; ``verbose``: IPOPT
    prints its own), when it stops (``stop(x)``: the fit asked for is reached at the
    admissible point x, None: run to the tolerance), and what it has done so far: the
    iteration history (lists "iter", "objective", "inf_pr", "elapsed"), the counts and the
    build time (s)."""

    options: SolveOptions
    callback: Callable[[dict], None] | None = None
    verbose: bool = False
    stop: Callable[[np.ndarray], bool] | None = None
    t0: float = field(default_factory=time.perf_counter)
    history: dict[str, list] = field(
        default_factory=lambda: {"iter": [], "objective": [], "inf_pr": [], "elapsed": []})
    iterations: int = 0
    gauss_newton_iterations: int = 0
    marched_iterations: int = 0
    build_time: float = 0.0
    start_moved: float = 0.0
    restoration_iterations: int = 0

    @property
    def deadline(self) -> float | None:
        """The ``time.perf_counter()`` at which ``options.time_limit`` runs out (None: no
        limit)."""
        limit = self.options.time_limit
        return None if limit is None else self.t0 + limit

    @property
    def iterations_left(self) -> int:
        """Iterations ``options.max_iter`` leaves to the solvers still to run."""
        return self.options.max_iter - self.iterations

    def log(self, objective: float, violation: float) -> None:
        """Record one iteration's objective and largest constraint violation and pass it
        to the callback."""
        entry = {"iter": len(self.history["iter"]), "objective": objective,
                 "inf_pr": violation, "elapsed": time.perf_counter() - self.t0}
        for key, value in entry.items():
            self.history[key].append(value)
        if self.callback is not None:
            self.callback(entry)

    def stats(self, outcome: Outcome) -> SolveStats:
        """The statistics of a solve that ended with ``outcome``."""
        options = self.options
        objective = np.nan if outcome.objective is None else float(outcome.objective)
        return SolveStats(
            status=outcome.status, success=outcome.success, iterations=self.iterations,
            build_time=self.build_time,
            solve_time=time.perf_counter() - self.t0 - self.build_time, objective=objective,
            solver=options.solver, transcription=options.transcription,
            hessian=options.hessian, gauss_newton_iterations=self.gauss_newton_iterations,
            marched_iterations=self.marched_iterations, start_moved=self.start_moved,
            restoration_iterations=self.restoration_iterations, history=self.history)


@dataclass(frozen=True)
class Outcome:
    """How a solver's part of a solve ended: its last point ``x`` (n,), status, success,
    objective (None when no admissible point was reached), the best admissible point met
    (``best``, (n,) or None) and, from IPOPT, the multipliers at ``x`` (``multipliers``:
    {"lam_g0", "lam_x0"} for a warm start) and the constraints' values there (``g``);
    None when only Levenberg-Marquardt ran."""

    x: np.ndarray
    status: str
    success: bool
    objective: float | None
    best: np.ndarray | None
    multipliers: dict[str, np.ndarray] | None = None
    g: np.ndarray | None = None


def raise_failure(nlp: NLP, outcome: Outcome, stats: SolveStats, iterations: int) -> None:
    """Raise the named error of an unsuccessful solve (:class:`SolverFailed`, or IPOPT's
    statuses as :func:`rffqm_nlp.errors.raise_for_ipopt` names them)."""
    if outcome.g is None:
        raise SolverFailed(
            f"the marched Levenberg-Marquardt solve did not finish the design: status "
            f"{outcome.status} after {iterations} iterations; raise max_iter or time_limit",
            status=outcome.status, stats=stats, last_iterate=outcome.x,
            best_iterate=outcome.best)
    viol = np.maximum(nlp.lbg - outcome.g, outcome.g - nlp.ubg)
    report = f"largest constraint violation {viol.max():.3g} at constraint {int(viol.argmax())}"
    raise_for_ipopt(
        outcome.status, iterations, "the design",
        f"{report}; relax min_length, min_angle or mu_margin",
        "raise max_iter or time_limit, or relax tol", stats, outcome.x, outcome.best)
