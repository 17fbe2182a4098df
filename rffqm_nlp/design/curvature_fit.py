"""How well a design meets curvatures (docs/curvature_targets.md): the Gaussian curvature
error of every design, cell by cell, against its target's K (a surface's at the target
lattice's parameters, or a curvature target's prescription); a curvature target's maps and
fit; and the notes that say whether a surface realises a prescription and where the error
sits.

A cell is an interior point of the coarse lattice, where the discrete forms of
:func:`rffqm_nlp.targets.shape.fundamental_forms` (the finite differences of curvature.png)
are taken; its error is (K_design - K_target) over the largest |K_target|, or over
1 / diameter^2 where that is smaller (a target of K = 0 everywhere).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import trimesh

from ..errors import InputError
from ..files import Key, check_value, describe_value
from ..model.backend import finite_array, finite_result
from ..targets import shape
from ..targets.curvature import Curvature as Maps
from ..targets.curvature import curvature_maps, lattice_curvatures
from ..targets.curvature_target import Curvature
from ..targets.meshes import closest_on_mesh
from ..targets.parametric import Surface
from ..targets.point_sets import grid_faces

#: The outer share of the cells along each direction that counts as "near an edge" in the
#: notes (:func:`_where_error_sits`).
EDGE_SHARE = 0.2
#: The largest coordinate of a folded state measured, in target diameters (beyond, its
#: squares overflow).
MAX_EXTENT = 1e100


def _target_maps(coarse: np.ndarray, target_points: np.ndarray,
                target: Surface | Curvature) -> Maps:
    """The curvature maps of an aligned coarse lattice (N+1, M+1, 3): against a surface
    :func:`rffqm_nlp.targets.curvature.curvature_maps` (the target lattice (N+1, M+1, 3)),
    against a curvature target :func:`prescribed_maps`."""
    if isinstance(target, Curvature):
        return prescribed_maps(coarse, target)
    return curvature_maps(coarse, target_points, target)


def prescribed_maps(coarse: np.ndarray, target: Curvature) -> Maps:
    """The maps of a coarse lattice (N+1, M+1, 3) against a curvature target, each
    (N-1, M-1): the lattice's own K and H (its normal r_u x r_v), and as both the target's
    and the surface's maps the prescription at the footprint's points of the interior
    lattice points (where only K is prescribed, H is the design's own)."""
    if not isinstance(target, Curvature):
        raise InputError(f"target must be a curvature target (rq.surfaces.Curvature), got "
                         f"{describe_value(target)}")
    coarse = finite_array(coarse, "coarse", shape=(None, None, 3))
    design_K, design_H = lattice_curvatures(coarse)
    x, y = target.lattice_xy(coarse.shape[0] - 1, coarse.shape[1] - 1)
    xx, yy = x[1:-1, None], y[None, 1:-1]
    K = np.broadcast_to(target.gaussian(xx, yy), design_K.shape).copy()
    H = target.mean(xx, yy)
    H = design_H.copy() if H is None else np.broadcast_to(H, design_H.shape).copy()
    return Maps(design_K=design_K, design_H=design_H, target_K=K, target_H=H, surface_K=K,
                surface_H=H)


def cell_errors(maps: Maps, diameter: float) -> np.ndarray:
    """The Gaussian curvature error of every cell (N-1, M-1): (design K - surface K) over
    max(max |surface K|, 1 / ``diameter``^2) (no units)."""
    if not isinstance(maps, Maps):
        raise InputError(f"maps must be curvature maps (rffqm_nlp.targets.curvature."
                         f"Curvature), got {describe_value(maps)}")
    diameter = check_value(diameter, Key("number", low=0.0, low_open=True), "diameter")
    design = finite_array(maps.design_K, "maps.design_K", ndim=2, least=1)
    surface = finite_array(maps.surface_K, "maps.surface_K", shape=design.shape)
    with np.errstate(all="ignore"):
        reference = max(float(np.abs(surface).max()), float(np.float64(diameter) ** -2.0))
        errors = (design - surface) / reference
    return finite_result(errors, "the curvature errors overflow: the maps or the diameter "
                                 "are too large or small for floating point")


def curvature_errors(maps: Maps, diameter: float) -> dict[str, float]:
    """Fit's ``curvature_rms`` and ``curvature_max``: the root mean square and the largest
    absolute :func:`cell_errors`."""
    errors = cell_errors(maps, diameter)
    return {"curvature_rms": float(np.sqrt(np.mean(errors ** 2))),
            "curvature_max": float(np.abs(errors).max())}


def curvature_target_fit(folded: np.ndarray, target: Curvature) -> dict[str, float]:
    """The position fields of :class:`~rffqm_nlp.design.results.Fit` for a curvature
    target, which prescribes no positions, so the design's own coarse lattice (two
    triangles per cell) is its target: ``rms``, ``rms_surface`` and ``hausdorff`` 0,
    ``rms_surface_vertices`` and ``hausdorff_vertices`` the RMS and largest distance of
    every folded vertex (2N+1, 2M+1, 3) to it (the fold's corrugation), ``plane_rms`` the
    RMS distance of the coarse lattice to its best plane (how far it bends), all over the
    footprint's diagonal; ``coverage`` the coarse lattice's area over the footprint's."""
    if not isinstance(target, Curvature):
        raise InputError(f"target must be a curvature target (rq.surfaces.Curvature), got "
                         f"{describe_value(target)}")
    diameter = target.diameter()
    folded = _bounded(folded, diameter)
    coarse = shape.coarse_grain(folded)
    if min(coarse.shape[:2]) < 2:
        raise InputError(f"folded must be a (2N+1, 2M+1, 3) state with N, M >= 1, got "
                         f"shape {folded.shape}")
    pts = coarse.reshape(-1, 3)
    plane = np.linalg.svd(pts - pts.mean(0), compute_uv=False)[-1] / np.sqrt(len(pts))
    lattice = trimesh.Trimesh(vertices=pts / diameter, faces=grid_faces(*coarse.shape[:2]),
                              process=False)
    dist = closest_on_mesh(lattice, folded.reshape(-1, 3) / diameter)[1]
    return {"rms": 0.0, "rms_surface": 0.0, "hausdorff": 0.0,
            "rms_surface_vertices": float(np.sqrt(np.mean(dist ** 2))),
            "hausdorff_vertices": float(dist.max()), "plane_rms": float(plane / diameter),
            "coverage": shape.lattice_area(coarse) / target.area()}


def _where_error_sits(errors: np.ndarray) -> str:
    """Where the largest of the cell errors (n, m) sits, in words: its lattice point, near
    a corner, an edge or in the interior (the outer :data:`EDGE_SHARE` of the cells along a
    direction), and the share of the squared error on the outermost ring of cells."""
    errors = finite_array(errors, "errors", ndim=2, least=1)
    n, m = errors.shape
    i, j = np.unravel_index(int(np.argmax(np.abs(errors))), errors.shape)
    near = [f"{name} = {0 if k < count / 2 else 'N' if name == 'i' else 'M'}"
            for name, k, count in (("i", i, n), ("j", j, m))
            if min(k + 1, count - k) <= max(1.0, EDGE_SHARE * count)]
    region = ("near the corner " + ", ".join(near) if len(near) == 2 else
              f"near the edge {near[0]}" if near else "in the interior")
    ring = np.ones_like(errors, dtype=bool)
    ring[1:-1, 1:-1] = False
    total = float(np.sum(errors ** 2))
    share = float(np.sum(errors[ring] ** 2)) / total if total > 0 else 0.0
    return (f"largest {_percent(abs(errors[i, j]))} at lattice point ({i + 1}, {j + 1}), "
            f"{region}; the outermost ring of cells holds {share:.0%} of the squared error")


def _curvature_notes(target: Curvature, maps: Maps) -> tuple[str, ...]:
    """The notes of a design of a curvature target: whether a surface realises the
    prescription (:meth:`Curvature.realisable`), the design's K error and where it sits."""
    verdict = target.realisable()
    errors = cell_errors(maps, target.diameter())
    rms = float(np.sqrt(np.mean(errors ** 2)))
    measured = f"K error {_percent(rms)} RMS of max |K|, {_where_error_sits(errors)}"
    if verdict.verdict is False:
        return (f"No surface realises this prescription: {verdict.reason}. The design is "
                f"the best compromise the loss finds: {measured}.",)
    if verdict.verdict is None:
        return (f"Whether a surface realises this prescription is not decided by it "
                f"({verdict.reason}); the design meets it to {measured}.",)
    return (f"A surface realises this prescription ({verdict.reason}); the design meets it "
            f"to {measured}.",)


def measured(folded: np.ndarray, target_points: np.ndarray,
             target: Surface | Curvature) -> dict[str, Any]:
    """The curvature part of a result: {"maps", "errors" (Fit's curvature fields),
    "notes"} of an aligned folded state (2N+1, 2M+1, 3) against the target lattice
    (N+1, M+1, 3) (for a curvature target, the design's own coarse lattice)."""
    if not isinstance(target, (Surface, Curvature)):
        raise InputError(f"target must be a surface or a curvature target, got "
                         f"{describe_value(target)}")
    coarse = shape.coarse_grain(_bounded(folded, target.diameter()))
    maps = _target_maps(coarse, target_points, target)
    notes = _curvature_notes(target, maps) if isinstance(target, Curvature) else ()
    return {"maps": maps, "errors": curvature_errors(maps, target.diameter()),
            "notes": notes}


def _percent(value: float) -> str:
    """``value`` as a percentage of two significant digits ("6.7%", "0.0034%")."""
    return f"{100 * value:.2g}%"


def _bounded(folded: Any, diameter: float) -> np.ndarray:
    """``folded`` as a finite (n, m, 3) array within :data:`MAX_EXTENT` diameters of the
    origin, else :class:`InputError`."""
    folded = finite_array(folded, "folded", shape=(None, None, 3))
    if folded.size and np.abs(folded).max() > MAX_EXTENT * diameter:
        raise InputError(f"folded must lie within {MAX_EXTENT:g} target diameters of the "
                         "origin")
    return folded
