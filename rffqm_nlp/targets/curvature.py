"""Curvature maps: the discrete Gaussian and mean curvature of a folded coarse lattice, side
by side with its target's (docs/paper.md s.8).

At every interior point of an (n, m) lattice the discrete first and second fundamental
forms are those of the loss (:func:`rffqm_nlp.targets.shape.fundamental_forms`: central
differences, unit spacings); from them K = det(II) / det(I) = (L N - M^2) / (E G - F^2) and
H = tr(I^-1 II) / 2 = (E N - 2 F M + G L) / (2 (E G - F^2)), the formulas of
:mod:`rffqm_nlp.targets.surfaces` (neither depends on the spacings). H takes the sign of the
target's
normal: the design's discrete normal r_u x r_v is turned, point by point, to agree with the
target lattice's, which is the target surface's r_u x r_v up to the differences.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from . import shape
from ..model.backend import finite_array, finite_result
from ..errors import InputError
from .parametric import Surface, check_surface


@dataclass(frozen=True)
class Curvature:
    """Curvature maps at the interior points of the coarse lattice, each (N-1, M-1) for an
    (N+1, M+1) lattice:

    * ``design_K``, ``design_H``: of the folded coarse lattice (aligned to the target);
    * ``target_K``, ``target_H``: of the target lattice, with the same differences;
    * ``surface_K``, ``surface_H``: the target surface's own (analytic) curvatures at the
      target lattice's parameters, for reference.
    """

    design_K: np.ndarray
    design_H: np.ndarray
    target_K: np.ndarray
    target_H: np.ndarray
    surface_K: np.ndarray
    surface_H: np.ndarray

    def to_dict(self) -> dict[str, list]:
        """{field: nested list}, JSON-ready."""
        return {f.name: np.asarray(getattr(self, f.name)).tolist() for f in fields(self)}


def _normals(P: np.ndarray) -> np.ndarray:
    """Discrete unit normals r_u x r_v / |r_u x r_v| at the interior points of P (n, m, 3)
    with the central differences of :func:`rffqm_nlp.targets.shape.fundamental_forms`,
    (n-2, m-2, 3)."""
    r_u = P[2:, 1:-1] - P[:-2, 1:-1]
    r_v = P[1:-1, 2:] - P[1:-1, :-2]
    cross = np.cross(r_u, r_v)
    return cross / np.linalg.norm(cross, axis=-1, keepdims=True)


def lattice_curvatures(P: np.ndarray, orient: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray]:
    """(K, H) of the lattice P (n, m, 3) at its interior points, each (n-2, m-2).

    ``orient``: unit normals (n-2, m-2, 3) that H's normal is turned to agree with (default:
    the lattice's own r_u x r_v). Raises :class:`InputError` for arguments that are not
    finite numbers of these shapes (n, m >= 3) and for a degenerate lattice (no finite
    curvature)."""
    P = finite_array(P, "P", shape=(None, None, 3))
    if min(P.shape[:2]) < 3:
        raise InputError(f"P must be a lattice of at least 3 x 3 points, got shape {P.shape}")
    if orient is not None:
        orient = finite_array(orient, "orient", shape=(P.shape[0] - 2, P.shape[1] - 2, 3))
    E, F, G, L, M, N = shape.fundamental_forms(P)
    with np.errstate(all="ignore"):
        det = E * G - F ** 2
        K = (L * N - M ** 2) / det
        H = (E * N - 2 * F * M + G * L) / (2 * det)
        if orient is not None:
            H = H * np.where(np.sum(_normals(P) * orient, axis=-1) < 0, -1.0, 1.0)
    return finite_result((K, H), "the lattice has no finite curvature: it is degenerate "
                                 "(E G - F^2 = 0 at an interior point) or too large for "
                                 "floating point")


def curvature_maps(coarse: np.ndarray, target_points: np.ndarray,
                   target: Surface) -> Curvature:
    """The :class:`Curvature` of an aligned coarse lattice (N+1, M+1, 3) against the target
    lattice (N+1, M+1, 3), which is ``target``'s :meth:`~rffqm_nlp.targets.surfaces.Surface.lattice`
    (uniform in parameters over the whole domain). Raises :class:`InputError` for
    arguments of other kinds or shapes and for degenerate lattices (no finite curvature)."""
    check_surface(target, "target")
    coarse = finite_array(coarse, "coarse", ndim=3, allowed="an (n, m, 3) lattice of finite "
                          "numbers")
    T = finite_array(target_points, "target_points", ndim=3, allowed="an (n, m, 3) lattice "
                     "of finite numbers")
    if coarse.shape != T.shape or T.shape[2] != 3 or min(T.shape[:2]) < 3:
        raise InputError("curvature maps need a coarse lattice and a target lattice of one "
                         f"shape (n, m, 3) with n, m >= 3, got {coarse.shape} and {T.shape}")
    target_K, target_H = lattice_curvatures(T)
    design_K, design_H = lattice_curvatures(coarse, orient=_normals(T))
    u, v = target.lattice_uv(T.shape[0] - 1, T.shape[1] - 1)
    uu, vv = np.meshgrid(u[1:-1], v[1:-1], indexing="ij")
    return Curvature(design_K=design_K, design_H=design_H, target_K=target_K,
                     target_H=target_H, surface_K=target.gaussian_curvature(uu, vv),
                     surface_H=target.mean_curvature(uu, vv))
