"""How a :class:`~rffqm_nlp.design.problem.DesignProblem` is solved: its continuation stages,
the solvers of each stage, the clearance rounds, and the memory it needs.

Each stage transcribes the problem (:meth:`DesignProblem.transcribe`) and runs
Levenberg-Marquardt on the marching manifold (:mod:`.solvers.levenberg_marquardt`), handing
over to IPOPT (:mod:`.solvers.ipopt`) only where it stalls or reaches no admissible point
(:func:`.solvers.handover.solve`); with solver "ipopt" IPOPT runs alone. The solvers share
one :class:`.solvers.context.Run`.
The answer is re-marched, checked and measured by :func:`.measure.result`.
"""

from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING, Callable

import casadi as ca
import numpy as np

from .. import memory
from ..errors import InfeasibleDesign, InputError, SolverFailed
from ..targets import shape
from ..targets.curvature_target import Curvature
from . import clearance, measure, several, transcription
from .multistart import solve_multistart
from .options import CLOSED_FORM, LM, SolveOptions
from .results import DesignResult, SolveStats
from .solvers import handover
from .solvers.closed_form import closed_form_start
from .solvers.closed_form.prescribed import prescribed_start
from .solvers.context import Outcome, Run, raise_failure

if TYPE_CHECKING:  # for type hints only: the problem calls this module
    from .problem import DesignProblem, Start


def solve(problem: DesignProblem, options: SolveOptions, *,
          callback: Callable[[dict], None] | None = None,
          warm_start: DesignResult | None = None, verbose: bool = False) -> DesignResult:
    """:meth:`DesignProblem.solve` (its docstring tells what each argument does)."""
    check_memory(problem, options)
    if isinstance(problem.target, Curvature) and options.stop_rms is not None:
        raise InputError("[solve] stop_rms is a distance to the target lattice, which a "
                         "curvature target does not have; leave it out")
    if problem.several:
        several.refuse_options(problem, options, warm_start)
        return several.solve_states(
            problem, options, starting_design(several.first_problem(problem), options),
            callback=callback, verbose=verbose)
    if options.solver == CLOSED_FORM:
        return closed_form_result(problem, options)
    if options.multistart != 1:
        return solve_multistart(problem, options, callback=callback, warm_start=warm_start,
                                verbose=verbose)
    problem.check_reachable()
    start = starting_design(problem, options)
    run = Run(options, callback=callback, verbose=verbose)
    x = None
    for stage, factor in enumerate(options.continuation):
        t1 = time.perf_counter()
        nlp = problem.transcribe(start, problem.stage_weights(factor),
                                 warm_start if x is None else None, options)
        run.build_time += time.perf_counter() - t1
        reference = (reference_point(problem, start, run)
                     if warm_start is not None and x is None else None)
        outcome = _solve_stage(problem, nlp, start, run, nlp.x0 if x is None else x,
                               warm=warm_start is not None or stage > 0, reference=reference)
        x = outcome.x
        if not outcome.success or outcome.status == "Fit_Reached":
            break
    stats = run.stats(outcome)
    if not outcome.success:
        raise_failure(nlp, outcome, stats, run.iterations)
    if problem.min_clearance > 0:
        nlp, outcome = _keep_clearance(problem, nlp, start, run, outcome)
        stats = run.stats(outcome)
    return measure.result(problem, nlp, start, outcome.x, stats, options)


def starting_design(problem: DesignProblem, options: SolveOptions) -> Start:
    """The design a solve starts from and regularizes toward (``options.start``): the
    problem's Miura-ori, or the closed form for its target's curvatures, the Miura where
    those curvatures ask more than the closed form can give (:class:`InfeasibleDesign`).
    A curvature target starts from its closed form (:func:`prescribed_start`) whatever
    ``options.start``."""
    if options.start == "closed-form" or isinstance(problem.target, Curvature):
        try:
            return closed_form_of(problem)
        except InfeasibleDesign:
            pass
    return problem.start()


def closed_form_of(problem: DesignProblem, admissible: bool = False) -> Start:
    """The closed form of ``problem``'s target as a start: :func:`prescribed_start` for a
    curvature target (with ``admissible``: only a fold whose closed form keeps min_length),
    else :func:`closed_form_start` (folded at omega0). Raises :class:`InfeasibleDesign`
    where the closed form asks too much."""
    if isinstance(problem.target, Curvature):
        return prescribed_start(problem, admissible)
    return closed_form_start(problem)


def closed_form_result(problem: DesignProblem, options: SolveOptions) -> DesignResult:
    """Solver "closed-form": the closed form (:func:`closed_form_of`) as the result, its
    NLP transcribed only to measure it (:func:`.measure.result`), no iteration. Raises
    :class:`InfeasibleDesign` where the closed form asks too much."""
    t0 = time.perf_counter()
    start = closed_form_of(problem, admissible=True)
    t1 = time.perf_counter()
    nlp = problem.transcribe(start, options=options)
    t2 = time.perf_counter()
    residuals = ca.Function("residuals", [nlp.x], [nlp.residuals])(nlp.x0)
    stats = SolveStats(status="Closed_Form", success=True, iterations=0, build_time=t2 - t1,
                       solve_time=t1 - t0 + time.perf_counter() - t2,
                       objective=0.5 * float(ca.sumsqr(residuals)), solver=CLOSED_FORM,
                       transcription=options.transcription, hessian=options.hessian)
    return measure.result(problem, nlp, start, nlp.x0, stats, options)


def _solve_stage(problem: DesignProblem, nlp: transcription.NLP, start: Start, run: Run,
                 x: np.ndarray, warm: bool,
                 reference: Callable[[], np.ndarray] | None = None) -> Outcome:
    """One continuation stage from x: Levenberg-Marquardt (with that solver), then IPOPT
    when it stalls or reaches no admissible point (from a start that breaks a constraint:
    moved toward ``reference()`` where given, else restored)."""
    run.stop = fit_reached(problem, nlp, start, run.options)
    return handover.solve(nlp, x, run, panels=problem.panels, warm=warm, reference=reference)


def _keep_clearance(problem: DesignProblem, nlp: transcription.NLP, start: Start, run: Run,
                    outcome: Outcome) -> tuple[transcription.NLP, Outcome]:
    """Re-solve, warm-started, with clearance rows on the pairs of panels closer than
    about min_clearance (:mod:`rffqm_nlp.design.clearance`), refreshed each round, until the
    re-marched design keeps min_clearance. Raises SolverFailed (status
    "clearance_not_met") when a round fails or brings the closest pair no farther."""
    gap, rows, cols = problem.min_clearance, 2 * problem.N, 2 * problem.M
    pairs = np.zeros((0, 2), dtype=np.int64)
    reached, stage_nlp, options = -np.inf, nlp, run.options
    for _ in range(clearance.ROUNDS):
        state = measure.marched(nlp, start, outcome.x, rows, cols)
        if state is None:
            break
        near, worst = clearance.closest(*state, gap)
        if worst.distance >= gap:
            return stage_nlp, outcome
        if worst.distance <= reached:
            break
        reached = worst.distance
        pairs = np.unique(np.concatenate([pairs, near]), axis=0)
        stage_nlp = clearance.constrain(nlp, *state, pairs, gap)
        run.options = replace(options, max_iter=min(  # each round's iterations are few
            options.max_iter, run.iterations + clearance.ROUND_ITERATIONS))
        try:
            trial = _solve_stage(problem, stage_nlp, start, run, outcome.x, warm=True)
        finally:
            run.options = options
        if not trial.success:
            break
        outcome = trial
    state = measure.marched(nlp, start, outcome.x, rows, cols)
    worst = (clearance.closest(*state, gap)[1] if state is not None
             else clearance.Closest(None, float("nan")))
    where = ("" if worst.pair is None else
             f": in the last design solved, panels {worst.pair[0]} and {worst.pair[1]} "
             f"are {worst.distance:.4g} apart")
    raise SolverFailed(
        f"min_clearance = {gap:g} is not met at the designed state{where}; "
        "lower min_clearance, or lower omega_bounds[1] (a design folded less keeps its "
        "layers farther apart)", status="clearance_not_met",
        stats=run.stats(outcome), last_iterate=outcome.x)


def reference_point(problem: DesignProblem, start: Start, run: Run
                    ) -> Callable[[], np.ndarray]:
    """The starting design's point (n,) of the NLP (the Miura-ori or the closed form),
    transcribed when first asked for (its time counted as build time): where a warm start
    breaks a constraint, Levenberg-Marquardt moves its boundary data toward it."""

    def point() -> np.ndarray:
        t1 = time.perf_counter()
        x = problem.transcribe(start, options=run.options).x0
        run.build_time += time.perf_counter() - t1
        return x

    return point


def fit_reached(problem: DesignProblem, nlp: transcription.NLP, start: Start,
                options: SolveOptions) -> Callable[[np.ndarray], bool] | None:
    """For ``stop_rms``: does the aligned coarse lattice at x (n,) fit the target well
    enough? None without ``stop_rms``."""
    if options.stop_rms is None:
        return None
    limit = options.stop_rms * problem.target.diameter()

    def reached(x: np.ndarray) -> bool:
        coarse = shape.coarse_grain(nlp.folded_array(x))
        return shape.kabsch(coarse, nlp.target_array(x, start.target_points))[2] <= limit

    return reached


def memory_estimate(problem: DesignProblem, options: SolveOptions | None = None) -> int:
    """Bytes that solving ``problem`` with ``options`` needs at its peak
    (:func:`rffqm_nlp.memory.design_estimate`; a multistart solves one start at a time).

    Levenberg-Marquardt's design variables n_d are the 3 (P + Q) boundary data of P x Q
    panels, or with ``stop_rms`` and ``boundary_knots`` k the coarse basis' 6 (min(k, P / 2)
    + min(k, Q / 2)) coordinates (a run that does not reach stop_rms in the coarse basis
    goes on in the whole design: then n_d's memory), plus a free correspondence's 2 Ku Kv
    controls (at most 2 GRID_CONTROLS^2,
    :class:`rffqm_nlp.design.transcription.Correspondence`). A design of several targets
    (the simultaneous NLP of every state, :mod:`rffqm_nlp.design.several`) counts one
    simultaneous NLP per target, as IPOPT solves it (what Levenberg-Marquardt needs on it
    is not measured)."""
    options = options or SolveOptions()
    P, Q = (float(p) for p in problem.panels)
    if problem.several:  # the simultaneous NLP, one state's kinematics per target
        need = len(problem.targets) * memory.design_estimate(problem.panels, "simultaneous")
        return int(min(need, 2.0 ** 62))
    if options.solver != LM:
        need = memory.design_estimate(problem.panels, options.transcription)
        return int(min(need, 2.0 ** 62))
    design = 3.0 * (P + Q)
    if options.stop_rms is not None and options.boundary_knots:
        knots = options.boundary_knots
        design = min(design, 6.0 * (min(knots, P / 2) + min(knots, Q / 2)))
    free = problem.correspondence == "free"
    if free:
        k = transcription.GRID_CONTROLS
        design += 2.0 * min(k, P / 2 + 1) * min(k, Q / 2 + 1)
    return int(min(memory.design_estimate(problem.panels, LM, design, free), 2.0 ** 62))


def check_memory(problem: DesignProblem, options: SolveOptions | None = None) -> None:
    """Refuse, before any work, a solve that needs more memory (:func:`memory_estimate`)
    than this machine has available (:func:`rffqm_nlp.memory.available`): one
    :class:`InputError` line with the estimate and the limit."""
    options = options or SolveOptions()
    P, Q = problem.panels
    memory.refuse_beyond(memory_estimate(problem, options),
                         f"[design] panels = [{P}, {Q}] with solver {options.solver}",
                         "choose fewer panels")
