"""Target shapes from triangle meshes and point clouds: :class:`Mesh` (``rq.surfaces.Mesh``).

A designer's shape becomes a smooth parametric surface r(u, v) in four steps
(``docs/meshes.md`` has the measurements behind the choices):

1. **Load.** A file of the :data:`FORMATS` (OBJ, STL, PLY, OFF, GLB, glTF with embedded
   buffers, XYZ; at most :data:`MAX_FILE_BYTES`, read from its bytes alone: no file it names
   is opened, no material or texture decoded, nothing of it quoted in an error), a
   ``trimesh.Trimesh``, a ``(V, F)`` pair of arrays, or a point cloud (an (n, 3) array, a
   ``trimesh.PointCloud`` or a file with vertices and no faces). At most :data:`MAX_FACES`
   triangles or :data:`MAX_POINTS` points, checked before any work on them. The shape is
   then moved into its unit frame (:mod:`.mesh_input`: centred, divided by a power of two near
   its bounding box's diagonal), where every later step works, so its units do not
   matter; the results are scaled back. Vertices are merged; degenerate and duplicate
   faces dropped. A mesh must be one connected patch of disk topology (one component,
   manifold, exactly one boundary loop, Euler characteristic 1).
2. **Parametrize.** A patch with four corners (:func:`corners`: exactly four places where
   the boundary turns left by at least pi - :data:`CORNER_ANGLE`) is mapped conformally
   onto a rectangle (:func:`conformal_rectangle`): u harmonic (cotangent weights) with u = 0
   and 1 on two opposite sides and no flux through the other two, v likewise on the other
   pair, the rectangle's aspect ratio sqrt(E_u / E_v) from their Dirichlet energies, its
   area the mesh's; used when no triangle flips and the map stretches areas by at most
   :data:`MAX_AREA_SPREAD` (corners far from right angles stretch them more). Otherwise, if
   the mesh is a graph over its best-fit plane (every face normal within
   :data:`GRAPH_ANGLE` of the plane's normal and no triangle flipped in the projection),
   (u, v) are the in-plane coordinates; faces covering at most :data:`SLIVER_AREA` of the
   area may break these two rules (slivers). Otherwise a least-squares conformal map (LSCM,
   sparse least squares, two boundary vertices pinned), or where that flips a triangle,
   Tutte's uniform-weight map onto a circle (injective by construction); then scaled to the
   mesh's area. A point cloud is projected onto its best-fit plane and a first spline fitted
   there (step 4, with ``smoothing``); its points, moved onto that smooth surface and
   triangulated in the plane (Delaunay, the long triangles of
   :func:`~.mesh_domain.cloud_faces` that reach the outside dropped), take the conformal
   rectangle when that triangulation is a disk with four corners that uses every point
   (its boundary is ragged: corners with the reach :data:`CLOUD_CORNER_WINDOW`, flipped
   slivers up to :data:`CLOUD_SLIVER_AREA`), else the projection. A boundary's corners
   need a reach of at least :data:`CORNER_REACH` vertices, and of more than four runs the
   four sharpest count where the fifth is :data:`CORNER_GAP` blunter.
   Either way the parameter image is rotated so that its smallest bounding rectangle is
   axis-aligned (:func:`align`).
3. **Domain.** The rectangle itself for a conformal rectangle (a point cloud's inset by
   :data:`CLOUD_INSET` point spacings, where the spline would follow the noise of the
   boundary points); otherwise the largest
   axis-aligned rectangle whose raster nodes (a :data:`RASTER` x :data:`RASTER` grid over the
   parameter image's bounding box, eroded by one node) all lie inside the parameter image,
   so the mesh covers the whole domain.
4. **Spline.** A tensor-product cubic B-spline on uniform knots over the parameter image's
   bounding box, fitted to the parametrized vertices (a point cloud with a conformal
   rectangle: its points on the first, denoised spline, fitted like a mesh's vertices, with
   MESH_SMOOTHING and the mesh's knots) by penalised least squares
   (P-spline): minimise sum_k |s(u_k, v_k) - p_k|^2 + lambda (n / n_c) (|D_u c|^2 + |D_v c|^2)
   over the control points c, with D_u, D_v the second differences of c along u and v,
   n the number of vertices and n_c the number of control points. lambda is
   :data:`MESH_SMOOTHING` for meshes (exact vertices: the penalty only fills cells without
   data) and :data:`CLOUD_SMOOTHING` for point clouds (noisy points: the penalty smooths).
   The fitted spline is sampled on a grid of two points per knot span and handed to
   ``casadi.interpolant(..., "bspline", ...)``, which works on SX symbols, so the AD
   derivatives, curvatures, the loss and both solvers work unchanged.

The spline's deviation from the vertices inside the domain, and for a mesh also the distance
of r on a :data:`DEVIATION_GRID` grid of the domain to the mesh (max and RMS over both, over
the diameter), is kept in :attr:`Mesh.deviation_max` and :attr:`Mesh.deviation_rms`; above
:data:`MAX_DEVIATION` (the max for a mesh, the RMS for a point cloud, whose points carry
noise) the Mesh is refused.

Distances to the shape: :meth:`Mesh.closest_points` gives exact closest points on the mesh
(:func:`closest_on_mesh`: trimesh's candidate faces, the nearest taken);
:func:`rffqm_nlp.targets.shape.relative_fit` the RMS and maximum distance of points to any target,
over its diameter.

Each step has a module of its own: :mod:`.mesh_input` (1), :mod:`.mesh_topology` and
:mod:`.parametrization` (2), :mod:`.mesh_domain` (3), :mod:`.splines` (4); this one holds
:class:`Mesh`, which runs them, and the distances to the shape, and gives ``rq.meshes`` the
constants and functions of every step.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import trimesh

from ..errors import SurfaceError
from ..files import Key, check_value
from .mesh_domain import RASTER, cloud_mask, inscribed_rectangle, polygon_mask
from .mesh_input import (FORMATS, MAX_FACES, MAX_FILE_BYTES, MAX_PIECES, MAX_POINTS,
                         MIN_POINTS, is_mesh_file, load, quiet_trimesh)
from .mesh_topology import boundary_loop, check_disk
from .parametric import Surface
from .parametrization import (CLOUD_CORNER_WINDOW, CLOUD_SLIVER_AREA, CORNER_ANGLE,
                              CORNER_GAP, CORNER_REACH, CORNER_WINDOW, GRAPH_ANGLE,
                              MAX_AREA_SPREAD, SLIVER_AREA, TIE, align, cloud_rectangle,
                              conformal_rectangle, corners, parametrize, project)
from .splines import KNOT_SPANS, fit_spline, in_units, knot_spans, smoothed

__all__ = ["CLOUD_CORNER_WINDOW", "CLOUD_INSET", "CLOUD_POINTS_PER_CELL", "CLOUD_SLIVER_AREA",
           "CLOUD_SMOOTHING", "CORNER_ANGLE", "CORNER_GAP", "CORNER_REACH", "CORNER_WINDOW", "DEVIATION_GRID", "FORMATS", "GRAPH_ANGLE", "KNOT_SPANS",
           "MAX_AREA_SPREAD", "MAX_DEVIATION", "MAX_FACES", "MAX_FILE_BYTES", "MAX_PIECES",
           "MAX_POINTS", "MESH_POINTS_PER_CELL", "MESH_SMOOTHING", "MIN_POINTS", "Mesh",
           "RASTER", "SLIVER_AREA", "TIE", "align", "closest_on_mesh", "conformal_rectangle",
           "corners", "inscribed_rectangle", "is_mesh_file", "parametrize"]

#: Largest spline deviation from the vertices, over the diameter (max for meshes, RMS for
#: point clouds).
MAX_DEVIATION = 0.01
#: Grid (per direction) over the domain on which r is compared with the mesh, and on which
#: a point cloud's fitted normals are checked.
DEVIATION_GRID = 41
#: P-spline penalty weight lambda for meshes and for point clouds (module docstring).
MESH_SMOOTHING = 1e-4
CLOUD_SMOOTHING = 0.01
#: A point cloud's rectangle domain stays this many point spacings (sqrt(area / points))
#: inside the rectangle, off the noisy boundary points.
CLOUD_INSET = 1.0
#: Vertices (meshes) or points (clouds) per knot cell when choosing the number of knots.
MESH_POINTS_PER_CELL = 4
CLOUD_POINTS_PER_CELL = 16
_KNOTS = Key("list", length=2, item=Key("whole", low=KNOT_SPANS[0], high=KNOT_SPANS[1]),
             hint="(n_u, n_v)")


class Mesh(Surface):
    """A target shape given as a triangle mesh or a point cloud, as a smooth r(u, v).

    ``source`` is a path (a file of the :data:`FORMATS`), a ``trimesh.Trimesh``, a
    ``trimesh.PointCloud``, a ``(V (n, 3), F (m, 3))`` pair or an (n, 3) point array.
    ``knots`` optionally gives the number of knot spans (n_u, n_v) of the spline, and
    ``smoothing`` the penalty weight lambda (module docstring); by default both are chosen
    from the number of points.

    Attributes: ``path`` (or None), ``mesh`` (the cleaned ``trimesh.Trimesh``, None for a
    point cloud), ``points`` (n, 3) the vertices or cloud points, ``uv`` (n, 2) their
    parameters, ``parametrization`` ("rectangle", "projection", "lscm", "tutte"), ``knots``
    (n_u, n_v) of r's spline, ``smoothing`` (of the cloud's denoising fit for a point cloud
    with a conformal rectangle), ``deviation_max`` and ``deviation_rms`` (over the diameter).
    """

    def __init__(self, source: Any, *, name: str | None = None,
                 knots: tuple[int, int] | None = None, smoothing: float | None = None):
        self.path = Path(source) if isinstance(source, (str, Path)) else None
        if smoothing is not None:
            smoothing = check_value(smoothing, Key("number", low=0, low_open=True), "smoothing",
                                    SurfaceError)
        if knots is not None:
            knots = check_value(knots, _KNOTS, "knots", SurfaceError)
        what = str(self.path) if self.path is not None else "the mesh"
        # every step works on the shape moved and scaled into its unit frame (:mod:`.mesh_input`):
        # trimesh's tolerances are absolute
        loaded, centre, scale = load(source, what)
        cloud = not isinstance(loaded, trimesh.Trimesh)
        self._unit_mesh = mesh = None if cloud else loaded
        self.smoothing = fit_smoothing = smoothing or (CLOUD_SMOOTHING if cloud
                                                       else MESH_SMOOTHING)
        if not cloud:
            check_disk(mesh, what)
            points = fitted = np.asarray(mesh.vertices, dtype=float)
            uv, self.parametrization = parametrize(mesh)
            self.knots = knots or knot_spans(uv, MESH_POINTS_PER_CELL)
        else:
            what = what if self.path is not None else "the point cloud"
            points = fitted = loaded
            uv, self._plane_normal = project(points)
            self.knots = knots or knot_spans(uv, CLOUD_POINTS_PER_CELL)
            on_surface = smoothed(uv, points, self.knots, self.smoothing)[0]
            rectangle = cloud_rectangle(on_surface, uv)
            if rectangle is None:
                uv, self.parametrization = align(uv), "projection"
                inside = cloud_mask(uv)
            else:  # the denoised surface in the new parameters: fitted like a mesh
                uv, self.parametrization = align(rectangle), "rectangle"
                fitted, fit_smoothing = on_surface, MESH_SMOOTHING
                self.knots = knots or knot_spans(uv, MESH_POINTS_PER_CELL)
        if self.parametrization == "rectangle":
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            if cloud:  # the noisy boundary points' spacings stay outside
                inset = CLOUD_INSET * math.sqrt(np.prod(hi - lo) / len(uv))
                lo, hi = lo + inset, hi - inset
            domain = ((lo[0], hi[0]), (lo[1], hi[1]))
        elif cloud:
            domain = inscribed_rectangle(uv, inside)
        else:
            domain = inscribed_rectangle(uv, polygon_mask(uv[boundary_loop(mesh)]))
        spline = fit_spline(uv, fitted, self.knots, fit_smoothing)
        # back in the shape's own units: lengths times scale, points moved back to centre
        self._centre, self._scale = centre, scale
        self.mesh = None if cloud else trimesh.Trimesh(
            centre + scale * np.asarray(mesh.vertices), mesh.faces, process=False)
        self.points, self.uv = centre + scale * points, scale * uv
        self._spline = in_units(spline, centre, scale)
        domain = tuple((float(scale * a), float(scale * b)) for a, b in domain)
        super().__init__(name or (self.path.stem if self.path else "mesh"), {}, domain)
        self._check_deviation(what, cloud)
        if cloud:
            self._check_graph(what)

    def __repr__(self) -> str:
        source = f"{self.path}" if self.path else f"{len(self.points)} points"
        return f"<Mesh {self.name} ({source}, {self.parametrization}) on {self.domain}>"

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        r = self._spline(ca.vertcat(u, v))
        return r[0], r[1], r[2]

    # -- checks after the fit -----------------------------------------------------------
    def _inside_domain(self) -> np.ndarray:
        """Mask (n,) of the points whose parameters lie in the domain."""
        (u0, u1), (v0, v1) = self.domain
        u, v = self.uv[:, 0], self.uv[:, 1]
        return (u >= u0) & (u <= u1) & (v >= v0) & (v <= v1)

    def _check_deviation(self, what: str, cloud: bool) -> None:
        """Deviations over the diameter: of r(u_k, v_k) from the points inside the domain,
        and for a mesh also of r on a DEVIATION_GRID x DEVIATION_GRID grid of the domain
        from the mesh (exact closest points); refused above MAX_DEVIATION."""
        inside = self._inside_domain()
        uv, pts = self.uv[inside], self.points[inside]
        dev = np.linalg.norm(self.point(uv[:, 0], uv[:, 1]) - pts, axis=1) / self.diameter()
        if not cloud:
            grid = self.sample(DEVIATION_GRID, DEVIATION_GRID).reshape(-1, 3)
            dev = np.r_[dev, self.distance(grid) / self.diameter()]
        if dev.size == 0:
            raise SurfaceError(f"no point of {what} lies in the fitted domain {self.domain}; "
                               f"give a denser point cloud")
        self.deviation_max = float(dev.max())
        self.deviation_rms = float(np.sqrt(np.mean(dev ** 2)))
        worst, which = (self.deviation_rms, "RMS") if cloud else (self.deviation_max, "maximum")
        if worst > MAX_DEVIATION:
            raise SurfaceError(
                f"the smooth surface fitted to {what} deviates from its "
                f"{'points' if cloud else 'vertices'} by {worst:.3%} of the diameter ({which}, "
                f"allowed {MAX_DEVIATION:.0%}); pass more knots=(n_u, n_v) (now {self.knots}), "
                f"a smaller smoothing, or a smoother {'cloud' if cloud else 'mesh'}")

    def _check_graph(self, what: str) -> None:
        """A point cloud must be a graph over its plane: fitted normals within GRAPH_ANGLE."""
        u, v = self.grid_uv(DEVIATION_GRID, DEVIATION_GRID)
        cos = np.abs(self.normal(u[:, None], v[None, :]) @ self._plane_normal)
        if cos.min() < math.cos(GRAPH_ANGLE):
            raise SurfaceError(
                f"the point cloud {what} is not a graph over its best-fit plane (the fitted "
                f"surface tilts by {math.degrees(math.acos(cos.min())):.0f} deg > "
                f"{math.degrees(GRAPH_ANGLE):.0f} deg); mesh it first, or crop it")

    # -- distances to the shape ---------------------------------------------------------
    def closest_points(self, points: Any, resolution: int = 101
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact closest points on the mesh (all of it, not only the domain) to ``points``
        (..., 3): returns (uv (..., 2) the barycentric interpolation of the vertex
        parameters, which may lie outside the domain; closest (..., 3); distances (...)).
        For a point cloud, the closest points on r(u, v) over the domain
        (:meth:`Surface.closest_points` with ``resolution``)."""
        if self.mesh is None:
            return super().closest_points(points, resolution)
        pts = np.asarray(points, dtype=float)
        if pts.shape[-1:] != (3,) or not np.all(np.isfinite(pts)):
            raise SurfaceError(f"points must be a finite array of shape (..., 3), got shape "
                               f"{pts.shape}")
        shape, flat = pts.shape[:-1], pts.reshape(-1, 3)
        if len(flat) == 0:
            return np.zeros(shape + (2,)), np.zeros(shape + (3,)), np.zeros(shape)
        unit = self._unit_mesh  # in the unit frame: the same answer at any size
        with quiet_trimesh():
            closest, dist, tri = closest_on_mesh(unit, (flat - self._centre) / self._scale)
            bary = trimesh.triangles.points_to_barycentric(unit.triangles[tri], closest)
        uv = np.einsum("nk,nkd->nd", bary, self.uv[unit.faces[tri]])
        closest = self._centre + self._scale * closest
        return (uv.reshape(shape + (2,)), closest.reshape(shape + (3,)),
                (self._scale * dist).reshape(shape))

    def distance(self, points: Any) -> np.ndarray:
        """Distance (...) from ``points`` (..., 3) to the shape (:meth:`closest_points`)."""
        return self.closest_points(points)[2]

    def to_config(self) -> dict:
        """``{"mesh": "<path>"}`` (the path as given); a Mesh made from arrays has none."""
        if self.path is None:
            raise SurfaceError("a Mesh made from arrays or a trimesh object cannot be saved as "
                               "config; write it to a file (e.g. mesh.export('part.ply')) and "
                               "use Mesh('part.ply') or [target] mesh = \"part.ply\"")
        return {"mesh": str(self.path)}


def closest_on_mesh(mesh: trimesh.Trimesh, points: np.ndarray, block: int = 256
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact closest points on the triangles of ``mesh`` to ``points`` (n, 3): (closest
    (n, 3), distances (n,), triangle indices (n,)). trimesh's ``nearby_faces`` gives each
    point's candidates (the faces whose bounding boxes meet the box around the point out to
    its nearest vertex, among which is the closest face) and the nearest of them is taken;
    ``block`` points at a time, to bound the memory. (``trimesh.proximity.closest_point``
    swaps the nearest candidate for a farther one whose squared distance differs by less
    than its absolute 1e-8 and whose normal faces the point better: at a mesh's own size
    its distances were up to 21% too long, docs/meshes.md.)"""
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    closest, dist = np.zeros((len(points), 3)), np.zeros(len(points))
    face = np.zeros(len(points), dtype=np.int64)
    triangles = mesh.triangles
    for start in range(0, len(points), block):
        part = points[start:start + block]
        candidates = trimesh.proximity.nearby_faces(mesh, part)
        counts = np.fromiter(map(len, candidates), dtype=np.int64, count=len(part))
        flat = np.concatenate(candidates).astype(np.int64)
        owner = np.repeat(np.arange(len(part)), counts)
        near = trimesh.triangles.closest_point(triangles[flat], part[owner])
        square = np.einsum("kd,kd->k", near - part[owner], near - part[owner])
        best = np.lexsort((square, owner))[np.r_[0, np.cumsum(counts)[:-1]]]
        stop = start + len(part)
        closest[start:stop], dist[start:stop] = near[best], np.sqrt(square[best])
        face[start:stop] = flat[best]
    return closest, dist, face
