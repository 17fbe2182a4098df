"""A solver's answer made a :class:`~rffqm_nlp.design.results.DesignResult`: re-marched by the
independent NumPy model, checked against its graph and its constraints, and measured (the
fit, the collision report, the curvature maps)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..contact.collisions import collisions
from ..errors import InputError, MarchingError, SolverFailed
from ..model import numpy_model
from ..model.boundary import BoundaryData
from ..model.pattern import Pattern
from ..targets import shape, surfaces
from ..targets.curvature_target import Curvature
from . import curvature_fit, transcription
from .options import SolveOptions
from .results import DesignResult, Fit, SolveStats, State

if TYPE_CHECKING:  # for type hints only: the problem calls this module
    from .problem import DesignProblem, Start

#: Samples per direction of the target kept in a result whose target config cannot rebuild
#: it (DesignResult.target_grid), for its pictures.
TARGET_GRID = 41
#: Relative agreement asked of the NumPy re-march and the CasADi graph's folded state.
REMARCH_AGREEMENT = 1e-8
#: Slack of the constraint check on re-marching (radians; relative for the sides).
CONSTRAINT_SLACK = 1e-6


def result(problem: DesignProblem, nlp: transcription.NLP, start: Start, x: np.ndarray,
           stats: SolveStats, options: SolveOptions) -> DesignResult:
    """The result of ``problem`` at the NLP's point ``x`` (n,): re-march it with the NumPy
    model, check it, measure the fit (for a curvature target:
    :func:`.curvature_fit.curvature_target_fit`) and the curvature
    (:func:`.curvature_fit.measured`). Raises :class:`SolverFailed` (with ``stats`` and
    ``x``) when it does not re-march ("remarch_failed"), when the re-march disagrees with
    the graph ("remarch_mismatch"), breaks a constraint ("constraint_violation") or holds
    NaN or inf ("non_finite")."""
    require_finite({"the design vector": x, "the objective": stats.objective}, stats, x)
    vec, omega = (np.asarray(v.full()).ravel() for v in nlp.unpack(x))
    bd = BoundaryData.from_vector(vec, start.boundary.sigma, 2 * problem.N, 2 * problem.M)
    pattern = remarched(bd, stats, x)
    check_constraints(problem, pattern, stats, x)
    state, notes = measured_state(problem.target, pattern, float(omega[0]),
                                  nlp.folded_array(x), nlp.target_array(x, start.target_points),
                                  stats, x)
    state = replace(state, fit=replace(state.fit, **collision_fields(pattern, state.omega)))
    config = problem.config(options)
    return DesignResult(boundary=bd, omega=state.omega, pattern=pattern, folded=state.folded,
                        target_points=state.target_points, rotation=state.rotation,
                        translation=state.translation, fit=state.fit, stats=stats,
                        problem=config, x=x, curvature=state.curvature,
                        target_grid=target_grid(problem.target, config["target"]),
                        notes=notes)


def remarched(bd: BoundaryData, stats: SolveStats, x: np.ndarray) -> Pattern:
    """The pattern of a solver's boundary data re-marched with the NumPy model; raises
    :class:`SolverFailed` ("remarch_failed", with ``stats`` and ``x``) where it fails."""
    try:
        return numpy_model.march(bd)
    except MarchingError as exc:
        raise SolverFailed(f"the solution fails re-marching with the NumPy model: {exc}",
                           status="remarch_failed", stats=stats, last_iterate=x) from exc


def measured_state(target: surfaces.Surface | Curvature, pattern: Pattern, omega: float,
                   graph: np.ndarray, target_points: np.ndarray, stats: SolveStats,
                   x: np.ndarray) -> tuple[State, tuple[str, ...]]:
    """One state of a solved design and its notes: ``pattern`` (re-marched) folded at
    ``omega`` by the NumPy model, checked against the graph's folded state ``graph``
    (2N+1, 2M+1, 3), aligned onto ``target_points`` (N+1, M+1, 3; a curvature target's
    lattice is its own), its fit (for a curvature target:
    :func:`.curvature_fit.curvature_target_fit`) and curvature (:func:`.curvature_fit.measured`),
    its collision fields not yet measured (:func:`collision_fields`). Raises
    :class:`SolverFailed` ("remarch_mismatch", "non_finite")."""
    Y = numpy_model.fold(pattern, omega)
    gap = np.abs(Y - graph).max()
    if gap > REMARCH_AGREEMENT * np.abs(Y).max():
        raise SolverFailed(f"the NumPy re-march disagrees with the CasADi graph by {gap:.3g}",
                           status="remarch_mismatch", stats=stats, last_iterate=x)
    R, t, _ = shape.kabsch(shape.coarse_grain(Y), target_points)
    folded = Y @ R.T + t
    if isinstance(target, Curvature):  # no positions: the lattice is its own target
        target_points = shape.coarse_grain(folded)
        fields = curvature_fit.curvature_target_fit(folded, target)
    else:
        fields = design_fit(folded, target_points, target)
    curvature = curvature_fit.measured(folded, target_points, target)
    fit = Fit(**fields, **curvature["errors"],
              min_side_over_mean=float(pattern.side_lengths.min()
                                       / pattern.side_lengths.mean()),
              min_sector_angle=float(pattern.sector_angles.min()))
    require_finite({"the folded state": folded,
                    "the fit": [v for v in fit.to_dict().values() if v is not None]},
                   stats, x)
    return State(omega=omega, folded=folded, target_points=target_points, rotation=R,
                 translation=t, fit=fit, curvature=curvature["maps"]), curvature["notes"]


def target_grid(target: surfaces.Surface | Curvature, config: dict) -> np.ndarray | None:
    """Samples of ``target`` kept in a result when its ``config`` cannot rebuild it
    (:data:`TARGET_GRID` a side), else None."""
    return (None if surfaces.rebuildable(config)
            else target.sample(TARGET_GRID, TARGET_GRID))


def check_constraints(problem: DesignProblem, pattern: Pattern, stats: SolveStats,
                      x: np.ndarray) -> None:
    """Raise :class:`SolverFailed` ("constraint_violation") when the re-marched ``pattern``
    breaks ``problem``'s min_angle or min_length by more than :data:`CONSTRAINT_SLACK`."""
    tol = CONSTRAINT_SLACK
    sides = pattern.side_lengths
    worst_angle = float(np.min(np.concatenate([pattern.alpha.ravel(), pattern.beta.ravel(),
                                               np.pi - pattern.alpha.ravel(),
                                               np.pi - pattern.beta.ravel()])))
    problems = []
    if worst_angle < problem.min_angle - tol:
        problems.append(f"a sector angle of {worst_angle:.6g} < min_angle")
    if sides.min() < problem.min_length * sides.mean() * (1 - tol):
        problems.append(f"a side of {sides.min() / sides.mean():.6g} x mean < min_length")
    if problems:
        raise SolverFailed("the solution violates its constraints on re-marching: "
                           + "; ".join(problems), status="constraint_violation",
                           stats=stats, last_iterate=x)


def collision_fields(pattern: Pattern, omega: float) -> dict[str, Any]:
    """Fit's ``collision_free`` and ``first_contact_omega`` of ``pattern`` folding from 0 to
    ``omega`` (:func:`rffqm_nlp.contact.collisions.collisions`)."""
    report = collisions(pattern, omega)
    return {"collision_free": report.free, "first_contact_omega": report.first_omega}


def marched(nlp: transcription.NLP, start: Start, x: np.ndarray, rows: int,
            cols: int) -> tuple[Pattern, float] | None:
    """The pattern and omega of x's boundary data re-marched with the NumPy model, or None
    when they do not march."""
    vec, omega = (np.asarray(v.full()).ravel() for v in nlp.unpack(x))
    try:
        bd = BoundaryData.from_vector(vec, start.boundary.sigma, rows, cols)
        return numpy_model.march(bd), float(omega[0])
    except (InputError, MarchingError):
        return None


def design_fit(folded: np.ndarray, target_points: np.ndarray,
               target: surfaces.Surface) -> dict[str, float]:
    """Fit measures of an aligned folded state (2N+1, 2M+1, 3) against the target lattice
    (N+1, M+1, 3) and the target's shape (:func:`rffqm_nlp.targets.shape.shape_fit`),
    relative to the target's diameter, as :class:`~rffqm_nlp.design.results.Fit` defines
    them (all but the pattern's side and angle measures)."""
    diameter = target.diameter()
    coarse = shape.coarse_grain(folded)
    rms = float(np.sqrt(np.mean(np.sum((coarse - target_points) ** 2, axis=-1))))
    pts = target_points.reshape(-1, 3)
    plane = np.linalg.svd(pts - pts.mean(0), compute_uv=False)[-1] / np.sqrt(len(pts))
    return {"rms": rms / diameter, "plane_rms": float(plane / diameter),
            **shape.shape_fit(folded, target)}


def require_finite(values: dict[str, Any], stats: SolveStats, x: np.ndarray) -> None:
    """Raise SolverFailed (status "non_finite") when any of ``values`` holds NaN or inf."""
    bad = [name for name, value in values.items()
           if not np.all(np.isfinite(np.asarray(value, dtype=float)))]
    if bad:
        raise SolverFailed(f"the solve ended with NaN or inf in {' and '.join(bad)}; no design "
                           "is returned (check the weights and the target)",
                           status="non_finite", stats=stats, last_iterate=x)
