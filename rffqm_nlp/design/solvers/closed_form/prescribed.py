"""The closed form for a curvature target (:class:`~rffqm_nlp.targets.curvature_target.Curvature`,
docs/curvature_targets.md): the alternating perturbation for the best separable
approximation of its principal curvatures, folded where it meets the prescription best."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from ....errors import InfeasibleDesign, InputError
from ....files import describe_value
from ....model import numpy_model
from ....targets import shape
from ....targets.curvature_target import Curvature
from ...transcription.curvature_loss import CurvatureLoss, loss_value
from .alternating import ClosedForm, closed_form_boundary
from .separable import separable_curvatures

if TYPE_CHECKING:
    from ...problem import DesignProblem, Start

#: The folds at which the closed form of a curvature target is tried besides omega0 (those
#: within omega_bounds): it bends with smaller perturbations, and meets the prescription
#: closer, the more it is folded (docs/benchmarks/curvature_targets.md).
FOLDS = (1.6, 1.8, 2.0, 2.2, 2.4, 2.6, 2.8, 3.0)


def prescribed_design(problem: "DesignProblem", omega: float) -> ClosedForm:
    """The closed form of ``problem``'s curvature target folded at ``omega``: the best
    separable approximation (:func:`.separable_curvatures`) of the principal curvatures
    (:meth:`Curvature.principal`) at the points of its (N+1) x (M+1) lattice, over its
    footprint, with the problem's panels, Miura-ori and min_angle. Raises
    :class:`InfeasibleDesign` where no alternating perturbation bends so far."""
    target = _target_of(problem)
    x, y = target.lattice_xy(problem.N, problem.M)
    separable = separable_curvatures(*target.principal(x[:, None], y[None, :]))
    return closed_form_boundary(separable.kx, separable.ky, panels=problem.panels,
                                size=target.size, alpha0=problem.alpha0,
                                layout=problem.layout, omega=omega,
                                min_angle=problem.min_angle)


def prescribed_start(problem: "DesignProblem", admissible: bool = False) -> "Start":
    """:meth:`DesignProblem.start` with the closed form of its curvature target in place of
    the Miura-ori: of omega0 and the :data:`FOLDS` within omega_bounds, the fold whose
    closed form has the least curvature loss (:func:`.curvature_loss.loss_value`, with the
    problem's weights) among those that keep the problem's min_length (all of them where
    none does, unless ``admissible``), aligned (Kabsch) to the footprint lattice. Raises
    :class:`InfeasibleDesign` when no fold gives a closed form (that keeps min_length,
    with ``admissible``)."""
    target = _target_of(problem)
    miura = problem.start()
    loss = CurvatureLoss.of(target, problem.N, problem.M, problem.weights)
    lo, hi = problem.omega_bounds
    found, reasons = [], []
    for omega in dict.fromkeys([problem.omega0, *(w for w in FOLDS if lo <= w <= hi)]):
        try:
            design = prescribed_design(problem, omega)
        except InfeasibleDesign as exc:
            reasons.append(str(exc))
            continue
        pattern = numpy_model.march(design.boundary)
        coarse = shape.coarse_grain(numpy_model.fold(pattern, design.omega))
        sides = pattern.side_lengths
        keeps = bool(sides.min() >= problem.min_length * sides.mean())
        found.append((not keeps, loss_value(coarse, loss), design, coarse))
    if not found or (admissible and found and min(found, key=lambda f: f[:2])[0]):
        why = (reasons[0] if not found else f"every fold's closed form has a side below "
               f"min_length = {problem.min_length:g} times the mean side; lower min_length")
        raise InfeasibleDesign(f"no closed form for this curvature target: {why}")
    _, _, design, coarse = min(found, key=lambda f: f[:2])
    rotation, translation, _ = shape.kabsch(coarse, miura.target_points)
    return replace(miura, boundary=design.boundary, omega=design.omega, rotation=rotation,
                   translation=translation)


def _target_of(problem: "DesignProblem") -> Curvature:
    """The curvature target of ``problem``, else :class:`InputError`."""
    target = getattr(problem, "target", None)
    if not isinstance(target, Curvature) or not hasattr(problem, "start"):
        raise InputError("problem must be a design problem whose target is a curvature "
                         f"field (rq.surfaces.Curvature), got {describe_value(problem)}")
    return target
