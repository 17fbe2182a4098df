"""The closed form as the start of a design problem's solve (docs/closed_form.md s.7)."""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from ....errors import InputError
from ....files import Key, check_value, describe_value
from ....model import numpy_model
from ....targets import shape
from .alternating import ClosedForm, closed_form_boundary
from .separable import curvatures_along_lattice, lattice_steps, separable_curvatures

if TYPE_CHECKING:
    from ...problem import DesignProblem, Start


def closed_form_design(problem: "DesignProblem", omega: float | None = None) -> ClosedForm:
    """The closed form for ``problem``'s target: the best separable approximation of its
    curvatures along the lattice's directions (:func:`.separable_curvatures`) and of its
    steps (:func:`.lattice_steps`) on the target lattice of :meth:`DesignProblem.start`,
    with the problem's panels, Miura-ori (alpha0, layout) and min_angle, folded at ``omega``
    (default the problem's omega0). Raises :class:`InfeasibleDesign` (see
    :func:`.closed_form_boundary`) when no alternating perturbation of that Miura-ori at
    that fold bends so far."""
    _check_problem(problem)
    lattice = problem.target.lattice(problem.N, problem.M)
    return _design(problem, lattice, omega)


def closed_form_start(problem: "DesignProblem", omega: float | None = None) -> "Start":
    """:meth:`DesignProblem.start` with the closed form (:func:`closed_form_design`) in
    place of the Miura-ori: the same target lattice and spacing, the closed form's boundary
    data and omega, and the rigid motion (Kabsch) that aligns its folded coarse lattice to
    the target lattice. Raises :class:`InfeasibleDesign` as :func:`closed_form_design`."""
    _check_problem(problem)
    miura = problem.start()
    design = _design(problem, miura.target_points, omega)
    coarse = shape.coarse_grain(numpy_model.fold(numpy_model.march(design.boundary),
                                                 design.omega))
    rotation, translation, _ = shape.kabsch(coarse, miura.target_points)
    return replace(miura, boundary=design.boundary, omega=design.omega, rotation=rotation,
                   translation=translation)


def _check_problem(problem: "DesignProblem") -> None:
    """An :class:`InputError` unless ``problem`` is a design problem (known by its fields and
    its start: this package does not import the problem's module, which may import it)."""
    names = ("target", "panels", "alpha0", "layout", "omega0", "min_angle", "start", "N", "M")
    if not all(hasattr(problem, name) for name in names):
        raise InputError("problem must be a design problem (rffqm_nlp.DesignProblem), got "
                         f"{describe_value(problem)}")


def _design(problem: "DesignProblem", lattice, omega: float | None) -> ClosedForm:
    """The closed form of ``problem`` on its target lattice (N+1, M+1, 3)."""
    omega = problem.omega0 if omega is None else check_value(omega, Key("number"), "omega")
    separable = separable_curvatures(*curvatures_along_lattice(problem.target, problem.N,
                                                               problem.M))
    steps = lattice_steps(lattice)
    return closed_form_boundary(separable.kx, separable.ky, panels=problem.panels,
                                size=(float(steps[0].sum()), float(steps[1].sum())),
                                alpha0=problem.alpha0, layout=problem.layout, omega=omega,
                                steps=steps, min_angle=problem.min_angle)
