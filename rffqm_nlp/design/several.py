"""One sheet designed for several targets (docs/several_states.md): the start of every state,
the NLP of all of them (:func:`rffqm_nlp.design.transcription.several_states`), its solve
by IPOPT and the result with one :class:`~rffqm_nlp.design.results.State` per target."""

from __future__ import annotations

import time
from dataclasses import replace
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import InputError
from ..model import numpy_model
from ..model.boundary import BoundaryData
from ..targets import shape, surfaces
from ..targets.curvature_target import Curvature
from . import measure, transcription
from .options import CLOSED_FORM, LM, SolveOptions
from .results import DesignResult
from .solvers import ipopt
from .solvers.context import Run, raise_failure

if TYPE_CHECKING:  # for type hints only: the problem calls this module
    from .problem import DesignProblem, Start

#: The folds a free omega_k's start is chosen among (within omega_bounds): the one whose
#: folded start best fits target k after a rigid alignment (:func:`state_starts`).
START_FOLDS = 41
#: What a solve of several states says of its solver in the result's notes.
SOLVER_NOTE = ("several states are solved by IPOPT on the simultaneous transcription of "
               "every state (Levenberg-Marquardt designs one state)")


def refuse_options(problem: DesignProblem, options: SolveOptions,
                   warm_start: DesignResult | None) -> None:
    """Refuse, in one :class:`InputError` line each, what a design of several states does
    not take: solver "closed-form", the sequential transcription, a multistart, stop_rms,
    min_clearance and a warm start."""
    refused = [(options.solver == CLOSED_FORM, "[solve] solver = 'closed-form' designs one "
                "state; use 'levenberg-marquardt' or 'ipopt'"),
               (options.transcription != "simultaneous", "[solve] transcription must be "
                "'simultaneous' (the NLP of several states is simultaneous)"),
               (options.multistart != 1, "[solve] multistart must be 1"),
               (options.stop_rms is not None, "[solve] stop_rms is a distance to one "
                "target; leave it out"),
               (problem.min_clearance > 0, "[design] min_clearance must be 0"),
               (warm_start is not None, "a warm start is a design of one state; leave it out")]
    for refuse, why in refused:
        if refuse:
            raise InputError(f"a design of several targets: {why}")


def solve_states(problem: DesignProblem, options: SolveOptions, *,
                 callback: Callable[[dict], None] | None = None,
                 verbose: bool = False) -> DesignResult:
    """Solve ``problem`` (several targets) with ``options``: the starts of
    :func:`state_starts`, each continuation stage's NLP of every state solved by IPOPT
    (the solver named by ``options`` is recorded as "ipopt", :data:`SOLVER_NOTE`), the
    answer re-marched, checked and measured state by state (:func:`result`)."""
    problem.check_reachable()
    run = Run(replace(options, solver="ipopt"), callback=callback, verbose=verbose)
    t1 = time.perf_counter()
    starts = state_starts(problem)
    run.build_time += time.perf_counter() - t1
    x = None
    for factor in options.continuation:
        t1 = time.perf_counter()
        nlp = transcribe_states(problem, starts, problem.stage_weights(factor))
        run.build_time += time.perf_counter() - t1
        outcome = ipopt.solve(nlp, nlp.x0 if x is None else x, run, panels=problem.panels,
                              warm=x is not None)
        x = outcome.x
        if not outcome.success:
            break
    stats = run.stats(outcome)
    if not outcome.success:
        raise_failure(nlp, outcome, stats, run.iterations)
    notes = (SOLVER_NOTE,) if options.solver == LM else ()
    return result(problem, nlp, starts, x, stats, run.options, notes)


def state_starts(problem: DesignProblem) -> list[Start]:
    """The start of every state: the first target's Miura start (:meth:`DesignProblem.start`,
    at its fixed omega where given), and for each further target that pattern folded at
    its fixed omega or, where omega is designed, at the one of :data:`START_FOLDS` folds
    within omega_bounds whose coarse lattice best fits the target lattice after a rigid
    alignment (Kabsch), aligned onto it."""
    fixed, _ = problem.state_options(0)
    first = replace(problem, omega0=fixed).start() if fixed is not None else problem.start()
    pattern = numpy_model.march(first.boundary)
    starts = [first]
    for k, target in enumerate(problem.other_targets, start=1):
        omega, _ = problem.state_options(k)
        lattice = target.lattice(problem.N, problem.M)
        folds = [omega] if omega is not None else np.linspace(*problem.omega_bounds,
                                                              START_FOLDS)
        coarse = [shape.coarse_grain(numpy_model.fold(pattern, w)) for w in folds]
        errors = [shape.kabsch(c, lattice)[2] for c in coarse]
        best = int(np.argmin(errors))
        R, t, _ = shape.kabsch(coarse[best], lattice)
        s_i, s_j = surfaces.mean_neighbour_distances(lattice)
        starts.append(replace(first, omega=float(folds[best]), target_points=lattice,
                              spacing=0.5 * (s_i + s_j), rotation=R, translation=t))
    return starts


def transcribe_states(problem: DesignProblem, starts: list[Start],
                      weights: dict[str, float]) -> transcription.NLP:
    """The NLP of every state (:func:`rffqm_nlp.design.transcription.several_states`) from
    their starts; ``weights``: the loss weights of the first target's kind (each state's
    are :meth:`DesignProblem.weights_of` them)."""
    setups, state_weights = [], []
    first = starts[0]
    for k, (target, start) in enumerate(zip(problem.targets, starts)):
        omega, weight = problem.state_options(k)
        own = problem.weights_of(target, weights)
        setups.append(transcription.Setup(
            boundary=first.boundary, omega=start.omega, rotation=start.rotation,
            translation=start.translation, target=start.target_points, spacing=start.spacing,
            weights=own, min_angle=problem.min_angle, min_length=problem.min_length,
            mu_margin=problem.mu_margin,
            omega_bounds=problem.omega_bounds if omega is None else (omega, omega),
            fixed=problem.fix, reference=first.boundary, reference_omega=first.omega,
            correspondence=problem.correspondence_of(target),
            curvature=(transcription.CurvatureLoss.of(target, problem.N, problem.M, own)
                       if isinstance(target, Curvature) else None)))
        state_weights.append(weight)
    return transcription.several_states(setups, state_weights)


def result(problem: DesignProblem, nlp: transcription.NLP, starts: list[Start],
           x: np.ndarray, stats, options: SolveOptions,
           notes: tuple[str, ...] = ()) -> DesignResult:
    """The result of a solve of several states at the NLP's point ``x``: the pattern
    re-marched and checked (:func:`.measure.remarched`, :func:`.measure.check_constraints`),
    every state measured (:func:`.measure.measured_state`), whether the motion is free of
    self-contact from flat to each state's omega (one check a side of the flat state, up
    to its farthest state), the
    notes of each state prefixed with its number."""
    measure.require_finite({"the design vector": x, "the objective": stats.objective},
                           stats, x)
    vec = np.asarray(nlp.unpack(x)[0].full()).ravel()
    bd = BoundaryData.from_vector(vec, starts[0].boundary.sigma, *problem.panels)
    pattern = measure.remarched(bd, stats, x)
    measure.check_constraints(problem, pattern, stats, x)
    config = problem.config(options)
    states, said = [], list(notes)
    for k, (target, start, functions) in enumerate(zip(problem.targets, starts, nlp.states)):
        state, state_notes = measure.measured_state(
            target, pattern, functions.omega_value(x), functions.folded_array(x),
            functions.target_array(x, start.target_points), stats, x)
        states.append(replace(state, target_grid=measure.target_grid(target,
                                                                     config["target"][k])))
        said += [f"state {k + 1}: {note}" for note in state_notes]
    contacts = {}  # one check a side of the flat state, up to its farthest state
    for side in {np.sign(state.omega) for state in states}:
        reach = max((s.omega for s in states if np.sign(s.omega) == side), key=abs)
        contacts[side] = measure.collision_fields(pattern, reach)["first_contact_omega"]
    states = [replace(state, fit=replace(state.fit, **_free_up_to(
        state.omega, contacts[np.sign(state.omega)]))) for state in states]
    first = states[0]
    return DesignResult(boundary=bd, omega=first.omega, pattern=pattern, folded=first.folded,
                        target_points=first.target_points, rotation=first.rotation,
                        translation=first.translation, fit=first.fit, stats=stats,
                        problem=config, x=x, curvature=first.curvature,
                        target_grid=first.target_grid, notes=tuple(said),
                        other_states=tuple(states[1:]))


def _free_up_to(omega: float, contact: float | None) -> dict[str, object]:
    """A state's collision fields from the first contact of the motion on its side of the
    flat state (None: none up to the farthest state): free where the contact lies beyond
    omega."""
    if contact is not None and abs(contact) <= abs(omega):
        return {"collision_free": False, "first_contact_omega": contact}
    return {"collision_free": True, "first_contact_omega": None}
