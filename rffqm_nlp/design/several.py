"""One sheet designed for several targets (docs/several_states.md): the start of every state,
the NLP of all of them (:func:`rffqm_nlp.design.transcription.several_states`), its solve
(Levenberg-Marquardt handing over to IPOPT, or IPOPT alone, as for one state) and the
result with one :class:`~rffqm_nlp.design.results.State` per target."""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Callable

import numpy as np

from ..errors import InputError
from ..model import numpy_model
from ..model.boundary import BoundaryData
from ..targets import shape, surfaces
from ..targets.curvature_target import Curvature
from . import measure, transcription
from .options import CLOSED_FORM, SolveOptions
from .results import DesignResult, SolveStats
from .solvers import handover
from .solvers.context import Outcome, Run, raise_failure
from .transcription import ORIENTATIONS, oriented

if TYPE_CHECKING:  # for type hints only: the problem calls this module
    from .problem import DesignProblem, Start

#: The folds a free omega_k's start is chosen among (within omega_bounds): the one whose
#: folded start best fits target k after a rigid alignment (:func:`fold_scans`, :func:`plan`).
START_FOLDS = 41
#: Iterations of each screening solve of a mesh's orientation (:func:`screened`).
SCREEN_ITERATIONS = 10
#: Largest constraint violation of a screening solve's last point that still counts.
SCREEN_FEASIBLE = 1e-6
#: Panels along the longer side of the coarse pattern on which a larger pattern's
#: candidate orientations are screened first (:func:`screened`, :func:`coarse_problem`).
SCREEN_PANELS = 8
#: The candidates, best first on the coarse pattern, screened again at the pattern's own
#: panels (docs/several_states.md, "Which way a mesh runs").
SCREEN_KEEP = 3
#: Controls a side of each state's free correspondence: more than one state's
#: (:data:`~rffqm_nlp.design.transcription.GRID_CONTROLS`), since one pattern no longer
#: bends to each mesh's parametrization (docs/several_states.md, "Which way a mesh runs").
STATE_GRID_CONTROLS = 6


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


@dataclass(frozen=True)
class Plan:
    """How a solve of several states starts: the first target's start (the Miura-ori or
    the closed form), which the Tikhonov term regularizes toward (``reference``); every
    state's start (``states``: that start's boundary data, shared, and the state's omega,
    target lattice laid onto the pattern's indices, spacing and alignment); how each
    state's target lattice is laid on (``orientations``,
    :data:`rffqm_nlp.design.transcription.ORIENTATIONS`)."""

    reference: Start
    states: tuple[Start, ...]
    orientations: tuple[tuple[bool, bool, bool], ...]


def first_problem(problem: DesignProblem) -> DesignProblem:
    """The problem of the first target alone, folded at its fixed omega where given: its
    start (the Miura-ori or the closed form, :func:`rffqm_nlp.design.solve.starting_design`)
    is the start of the pattern of every state and the reference of the Tikhonov term."""
    omega, _ = problem.state_options(0)
    single = replace(problem, other_targets=(), omega=None, state_weights=None)
    return single if omega is None else replace(single, omega0=omega)


def solve_states(problem: DesignProblem, options: SolveOptions, first: Start, *,
                 callback: Callable[[dict], None] | None = None,
                 verbose: bool = False) -> DesignResult:
    """Solve ``problem`` (several targets) with ``options`` from ``first``, the start of
    :func:`first_problem`: the plan of :func:`plan` (each mesh's orientation screened,
    :func:`screened`), every continuation stage's NLP of all states solved by
    ``options.solver`` (:func:`.solvers.handover.solve`), the answer re-marched, checked
    and measured state by state (:func:`result`). Iterations count the screening solves
    too."""
    problem.check_reachable()
    run = Run(options, callback=callback, verbose=verbose)
    chosen, notes = screened(problem, first, run)
    nlp, outcome = _solve_plan(problem, chosen, run)
    stats = run.stats(outcome)
    if not outcome.success:
        raise_failure(nlp, outcome, stats, run.iterations)
    return result(problem, nlp, chosen, outcome.x, stats, run.options, notes)


def _solve_plan(problem: DesignProblem, plan: Plan, run: Run,
                stages: tuple[float, ...] | None = None) -> tuple[transcription.NLP, Outcome]:
    """The continuation ``stages`` (default ``run.options``') of one plan, each from the
    last one's answer."""
    x = None
    for factor in run.options.continuation if stages is None else stages:
        t1 = time.perf_counter()
        nlp = transcribe_states(problem, plan, problem.stage_weights(factor))
        run.build_time += time.perf_counter() - t1
        outcome = handover.solve(nlp, nlp.x0 if x is None else x, run, panels=problem.panels,
                                 warm=x is not None)
        x = outcome.x
        if not outcome.success:
            break
    return nlp, outcome


def fold_scans(problem: DesignProblem, first: Start
               ) -> dict[int, tuple[np.ndarray, list[np.ndarray]]]:
    """For each further state k: the folds its start is chosen among (its fixed omega, or
    :data:`START_FOLDS` folds within omega_bounds) and the coarse lattice of ``first``'s
    pattern at each."""
    pattern = numpy_model.march(first.boundary)
    scans = {}
    for k in range(1, len(problem.targets)):
        omega, _ = problem.state_options(k)
        folds = (np.array([omega]) if omega is not None
                 else np.linspace(*problem.omega_bounds, START_FOLDS))
        scans[k] = folds, [shape.coarse_grain(numpy_model.fold(pattern, w)) for w in folds]
    return scans


def plan(problem: DesignProblem, first: Start,
         orientations: dict[int, tuple[bool, bool, bool]] | None = None,
         scans: dict[int, tuple[np.ndarray, list[np.ndarray]]] | None = None) -> Plan:
    """The start of every state, its target lattice laid on in ``orientations[k]``
    (default the identity): ``first`` (the start of :func:`first_problem`) for the
    pattern and the first state (its lattice, where laid on otherwise, aligned onto at
    its fold); each further state at whichever of its folds (:func:`fold_scans`, given as
    ``scans`` or computed) brings the start's coarse lattice closest to its target lattice
    after a rigid alignment (Kabsch), aligned onto it."""
    orientations = orientations or {}
    scans = scans or fold_scans(problem, first)
    states, laid = [], []
    for k, target in enumerate(problem.targets):
        o = orientations.get(k, ORIENTATIONS[0])
        laid.append(o)
        if k == 0 and o == ORIENTATIONS[0]:
            states.append(first)
            continue
        lattice = oriented(target.lattice(problem.M, problem.N) if o[0]
                           else target.lattice(problem.N, problem.M), o)
        folds, coarse = scans[k] if k else (np.array([first.omega]), [shape.coarse_grain(
            numpy_model.fold(numpy_model.march(first.boundary), first.omega))])
        best = int(np.argmin([shape.kabsch(c, lattice)[2] for c in coarse]))
        R, t, _ = shape.kabsch(coarse[best], lattice)
        s_i, s_j = surfaces.mean_neighbour_distances(lattice)
        states.append(replace(first, omega=float(folds[best]), target_points=lattice,
                              spacing=0.5 * (s_i + s_j), rotation=R, translation=t))
    return Plan(reference=first, states=tuple(states), orientations=tuple(laid))


def screened(problem: DesignProblem, first: Start, run: Run) -> tuple[Plan, tuple[str, ...]]:
    """:func:`plan` from ``first`` with the orientation of every state whose target is a
    mesh or a point cloud (:class:`~rffqm_nlp.targets.meshes.Mesh`: its parametrization
    is computed, so which way its lattice runs along the pattern is unknown) chosen among
    the eight :data:`ORIENTATIONS`: the first state's jointly with the next mesh state's
    (64 pairs; the pattern's Miura start has a direction, so the first state's matters
    too), every later one's given those chosen before it. The orientation that wins is
    the one whose first continuation stage, at most :data:`SCREEN_ITERATIONS` iterations
    (counted in ``run`` and toward its ``max_iter``, within its time limit), ends with the
    least loss at a point that holds the constraints (the identity where none does, or
    where no iteration or time was left). A pattern of more than
    :data:`SCREEN_PANELS` panels a side screens every candidate on the coarse pattern of
    :func:`coarse_problem` first, from its Miura-ori start, and only the
    :data:`SCREEN_KEEP` best there at its own panels. A surface given by its
    parametrization is laid on as parametrized. Returns the plan and notes on what was
    chosen."""
    meshes = [k for k, target in enumerate(problem.targets)
              if isinstance(target, surfaces.Mesh)]
    if not meshes:
        return plan(problem, first), ()
    groups = [(k,) for k in meshes]
    if 0 in meshes:  # the first state's orientation, jointly with the next mesh state's
        groups = [tuple(meshes[:2])] + groups[2:]
    chosen: dict[int, tuple[bool, bool, bool]] = {}
    coarse = coarse_problem(problem)
    levels = [(problem, first)] if coarse is None else [
        (coarse, first_problem(coarse).start()), (problem, first)]
    levels = [(at, start, fold_scans(at, start)) for at, start in levels]
    for group in groups:
        candidates = list(itertools.product(ORIENTATIONS, repeat=len(group)))
        for at, start, scans in levels:
            scores = [_screen(at, plan(at, start, {**chosen, **dict(zip(group, c))}, scans),
                              run) for c in candidates]
            if np.isinf(scores).all():  # none holds the constraints, or no time was left
                candidates = [(ORIENTATIONS[0],) * len(group)]
                break
            best = np.argsort(scores, kind="stable")[:1 if at is problem else SCREEN_KEEP]
            candidates = [candidates[i] for i in best]
        chosen.update(zip(group, candidates[0]))
    notes = tuple(f"state {k + 1}'s mesh lattice is laid on {_orientation_text(chosen[k])}, "
                  f"the least loss of the orientations screened" for k in meshes)
    return plan(problem, first, chosen, levels[-1][2]), notes


def coarse_problem(problem: DesignProblem) -> DesignProblem | None:
    """``problem`` at :data:`SCREEN_PANELS` panels along its longer side (the other side in
    proportion, even, at least 4 as every pattern), where it has more; None otherwise."""
    longest = max(problem.panels)
    if longest <= SCREEN_PANELS:
        return None
    panels = tuple(max(4, 2 * round(p * SCREEN_PANELS / longest / 2)) for p in problem.panels)
    return replace(problem, panels=panels)


def _screen(problem: DesignProblem, trial_plan: Plan, run: Run) -> float:
    """The loss of ``trial_plan``'s first continuation stage cut at
    :data:`SCREEN_ITERATIONS` iterations (counted in ``run``, within what its ``max_iter``
    and time limit leave); inf where its last point breaks a constraint, and without a
    solve where ``run`` has no iteration or no time left."""
    left = None if run.deadline is None else run.deadline - time.perf_counter()
    if run.iterations_left <= 0 or (left is not None and left <= 0):
        return np.inf
    trial = Run(replace(run.options, max_iter=min(SCREEN_ITERATIONS, run.iterations_left),
                        time_limit=left))
    nlp, outcome = _solve_plan(problem, trial_plan, trial, run.options.continuation[:1])
    run.iterations += trial.iterations
    run.gauss_newton_iterations += trial.gauss_newton_iterations
    run.marched_iterations += trial.marched_iterations
    run.restoration_iterations += trial.restoration_iterations
    run.build_time += trial.build_time
    admissible = (outcome.objective is not None if outcome.g is None  # marched
                  else float(np.max(np.maximum(nlp.lbg - outcome.g,
                                               outcome.g - nlp.ubg))) <= SCREEN_FEASIBLE)
    return outcome.objective if admissible else np.inf


def _orientation_text(orientation: tuple[bool, bool, bool]) -> str:
    """How an orientation lays a lattice on, in words."""
    swap, flip_i, flip_j = orientation
    words = [w for w, on in (("transposed", swap), ("reversed along i", flip_i),
                             ("reversed along j", flip_j)) if on]
    return " and ".join(words) if words else "as its target parametrizes it"


def transcribe_states(problem: DesignProblem, plan: Plan,
                      weights: dict[str, float]) -> transcription.NLP:
    """The NLP of every state (:func:`rffqm_nlp.design.transcription.several_states`) of
    ``plan``; ``weights``: the loss weights of the first target's kind (each state's are
    :meth:`DesignProblem.weights_of` them)."""
    setups, state_weights = [], []
    reference = plan.reference
    for k, (target, start, o) in enumerate(zip(problem.targets, plan.states,
                                               plan.orientations)):
        omega, weight = problem.state_options(k)
        own = problem.weights_of(target, weights)
        setups.append(transcription.Setup(
            boundary=start.boundary, omega=start.omega, rotation=start.rotation,
            translation=start.translation, target=start.target_points, spacing=start.spacing,
            weights=own, min_angle=problem.min_angle, min_length=problem.min_length,
            mu_margin=problem.mu_margin,
            omega_bounds=problem.omega_bounds if omega is None else (omega, omega),
            fixed=problem.fix, reference=reference.boundary,
            reference_omega=reference.omega,
            correspondence=problem.correspondence_of(target, swap=o[0],
                                                     controls=STATE_GRID_CONTROLS),
            curvature=(transcription.CurvatureLoss.of(target, problem.N, problem.M, own)
                       if isinstance(target, Curvature) else None)))
        state_weights.append(weight)
    return transcription.several_states(setups, state_weights, plan.orientations)


def result(problem: DesignProblem, nlp: transcription.NLP, plan: Plan,
           x: np.ndarray, stats: SolveStats, options: SolveOptions,
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
    bd = BoundaryData.from_vector(vec, plan.reference.boundary.sigma, *problem.panels)
    pattern = measure.remarched(bd, stats, x)
    measure.check_constraints(problem, pattern, stats, x)
    config = problem.config(options)
    states, said = [], list(notes)
    for k, (target, start, functions) in enumerate(zip(problem.targets, plan.states,
                                                       nlp.states)):
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
