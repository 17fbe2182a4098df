"""Target shapes from triangle meshes and point clouds: :class:`Mesh` (``rq.surfaces.Mesh``).

A designer's shape becomes a smooth parametric surface r(u, v) in four steps
(``docs/meshes.md`` has the measurements behind the choices):

1. **Load.** Any format trimesh reads (OBJ, STL, PLY, OFF, GLB, ...), a ``trimesh.Trimesh``,
   a ``(V, F)`` pair of arrays, or a point cloud (an (n, 3) array, a ``trimesh.PointCloud``
   or a file with vertices and no faces). Vertices are merged; degenerate and duplicate
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
   triangulated in the plane (Delaunay, the long triangles of :func:`_cloud_faces` dropped),
   take the conformal rectangle when that triangulation is a disk with four corners that
   uses every point, else the projection. Either way the parameter image is rotated so that
   its smallest bounding rectangle is axis-aligned (:func:`align`).
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
(trimesh's proximity query); :func:`rffqm_nlp.shape.relative_fit` the RMS and maximum
distance of points to any target, over its diameter.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np
import trimesh
from matplotlib.path import Path as PolygonPath
from scipy import sparse
from scipy.interpolate import BSpline
from scipy.ndimage import binary_erosion
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import spsolve
from scipy.spatial import ConvexHull, Delaunay

from .errors import SurfaceError
from .files import Key, check_value
from .surfaces import Surface

#: Largest angle between a face normal and the best-fit plane's normal for a projection.
GRAPH_ANGLE = math.radians(80.0)
#: Largest area fraction of a mesh's faces that may be steep or flipped in a projection or
#: a conformal map (slivers that CAD exports and Delaunay triangulations carry).
SLIVER_AREA = 1e-4
#: Largest angle (radians) between a boundary vertex's chords to its neighbours
#: :data:`CORNER_WINDOW` away for a corner of the patch (a rectangle's corner: pi / 2, a
#: straight side: pi, a circle: pi - 2 pi CORNER_WINDOW).
CORNER_ANGLE = math.radians(155.0)
#: The chords' reach, as a share of the boundary's vertices (:func:`corners`; a side of
#: fewer than about two reaches merges its corners, and the map falls back).
CORNER_WINDOW = 0.02
#: Largest ratio of the 99th to the 1st percentile (by area) of the conformal rectangle's
#: area scale (parameter area over mesh area per face): a flat parallelogram with 75 deg
#: corners gives 3.3, with 60 deg 12; the bundled targets' meshes 1.4-2.8.
MAX_AREA_SPREAD = 10.0
#: Largest spline deviation from the vertices, over the diameter (max for meshes, RMS for
#: point clouds).
MAX_DEVIATION = 0.01
#: Grid (per direction) over the domain on which r is compared with the mesh, and on which
#: a point cloud's fitted normals are checked.
DEVIATION_GRID = 41
#: Fewest points of a point cloud.
MIN_POINTS = 20
#: P-spline penalty weight lambda for meshes and for point clouds (module docstring).
MESH_SMOOTHING = 1e-4
CLOUD_SMOOTHING = 0.01
#: A point cloud's rectangle domain stays this many point spacings (sqrt(area / points))
#: inside the rectangle, off the noisy boundary points.
CLOUD_INSET = 1.0
#: Vertices (meshes) or points (clouds) per knot cell when choosing the number of knots.
MESH_POINTS_PER_CELL = 4
CLOUD_POINTS_PER_CELL = 16
#: Fewest and most knot spans per direction.
KNOT_SPANS = (4, 60)
_KNOTS = Key("list", length=2, item=Key("whole", low=KNOT_SPANS[0], high=KNOT_SPANS[1]),
             hint="(n_u, n_v)")
#: Raster nodes per direction for the inscribed rectangle.
RASTER = 200


class Mesh(Surface):
    """A target shape given as a triangle mesh or a point cloud, as a smooth r(u, v).

    ``source`` is a path (any format trimesh reads), a ``trimesh.Trimesh``, a
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
        self.mesh, points = _load(source, what)
        cloud = self.mesh is None
        self.smoothing = fit_smoothing = smoothing or (CLOUD_SMOOTHING if cloud
                                                       else MESH_SMOOTHING)
        if not cloud:
            _check_disk(self.mesh, what)
            self.points = fitted = np.asarray(self.mesh.vertices, dtype=float)
            self.uv, self.parametrization = parametrize(self.mesh)
            self.knots = knots or _knot_spans(self.uv, MESH_POINTS_PER_CELL)
        else:
            what = what if self.path is not None else "the point cloud"
            self.points = fitted = points
            uv, self._plane_normal = _project(points)
            self.knots = knots or _knot_spans(uv, CLOUD_POINTS_PER_CELL)
            on_surface = _smoothed(uv, points, self.knots, self.smoothing)[0]
            rectangle = _cloud_rectangle(on_surface, uv)
            if rectangle is None:
                self.uv, self.parametrization = align(uv), "projection"
                inside = _cloud_mask(self.uv)
            else:  # the denoised surface in the new parameters: fitted like a mesh
                self.uv, self.parametrization = align(rectangle), "rectangle"
                fitted, fit_smoothing = on_surface, MESH_SMOOTHING
                self.knots = knots or _knot_spans(self.uv, MESH_POINTS_PER_CELL)
        if self.parametrization == "rectangle":
            lo, hi = self.uv.min(axis=0), self.uv.max(axis=0)
            if cloud:  # the noisy boundary points' spacings stay outside
                inset = CLOUD_INSET * math.sqrt(np.prod(hi - lo) / len(self.uv))
                lo, hi = lo + inset, hi - inset
            domain = ((float(lo[0]), float(hi[0])), (float(lo[1]), float(hi[1])))
        elif cloud:
            domain = inscribed_rectangle(self.uv, inside)
        else:
            domain = inscribed_rectangle(
                self.uv, _polygon_mask(self.uv[_boundary_loop(self.mesh)]))
        self._spline = _fit_spline(self.uv, fitted, self.knots, fit_smoothing)
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
        closest, dist, tri = trimesh.proximity.closest_point(self.mesh, flat)
        bary = trimesh.triangles.points_to_barycentric(self.mesh.triangles[tri], closest)
        uv = np.einsum("nk,nkd->nd", bary, self.uv[self.mesh.faces[tri]])
        return uv.reshape(shape + (2,)), closest.reshape(shape + (3,)), dist.reshape(shape)

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


# -- loading -------------------------------------------------------------------------------


def is_mesh_file(path: str | Path) -> bool:
    """Whether ``path``'s suffix names a format trimesh reads (OBJ, STL, PLY, OFF, GLB,
    XYZ, ...), case-insensitively."""
    return Path(path).suffix.lower().lstrip(".") in trimesh.available_formats()


def _load(source: Any, what: str) -> tuple[trimesh.Trimesh | None, np.ndarray | None]:
    """(cleaned mesh, None) or (None, cloud points (n, 3)) from any accepted source."""
    if isinstance(source, (str, Path)):
        source = _read(Path(source))
    if isinstance(source, trimesh.Scene):
        geoms = list(source.dump()) if source.geometry else []
        meshes = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        clouds = [g for g in geoms if isinstance(g, trimesh.PointCloud)]
        if meshes:
            source = trimesh.util.concatenate(meshes)
        elif clouds:
            source = np.concatenate([c.vertices for c in clouds])
        else:
            raise SurfaceError(f"cannot read {what} as a mesh: it holds no triangles and no "
                               f"points; export the surface as a triangle mesh or point cloud")
    if isinstance(source, trimesh.PointCloud):
        source = np.asarray(source.vertices)
    if isinstance(source, trimesh.Trimesh):
        if len(source.faces) == 0:
            return None, _cloud(source.vertices, what)
        return _clean(source.vertices, source.faces, what), None
    if isinstance(source, (tuple, list)) and len(source) == 2:
        return _clean(*source, what), None
    if isinstance(source, np.ndarray) and source.ndim == 2 and source.shape[1] == 3:
        return None, _cloud(source, what)
    raise SurfaceError(f"Mesh needs a file path, a trimesh.Trimesh, a (vertices, faces) pair or "
                       f"an (n, 3) point array, got {type(source).__name__}")


def _read(path: Path) -> Any:
    """trimesh's reading of a file; every failure becomes one SurfaceError line."""
    if path.is_dir():
        raise SurfaceError(f"cannot read {path} as a mesh: it is a folder; give a mesh file")
    if not path.is_file():
        raise SurfaceError(f"cannot read {path} as a mesh: no such file")
    try:
        loaded = trimesh.load(str(path), process=False)
    except BaseException as err:  # trimesh's readers raise anything on a bad file
        if isinstance(err, (KeyboardInterrupt, SystemExit)):
            raise
        detail = " ".join(str(err).split())[:160] or type(err).__name__
        raise SurfaceError(f"cannot read {path} as a mesh: {detail}; give a mesh or point "
                           f"cloud file trimesh reads (OBJ, STL, PLY, OFF, GLB, XYZ)") from None
    if isinstance(loaded, (trimesh.Trimesh, trimesh.PointCloud, trimesh.Scene)):
        return loaded
    raise SurfaceError(f"cannot read {path} as a mesh: trimesh gave a "
                       f"{type(loaded).__name__}; give a triangle mesh or a point cloud")


def _finite_points(vertices: Any, what: str) -> np.ndarray:
    try:
        pts = np.asarray(vertices, dtype=float)
    except (TypeError, ValueError):
        raise SurfaceError(f"the vertices of {what} must be numbers, shape (n, 3)") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SurfaceError(f"the vertices of {what} must have shape (n, 3), got {pts.shape}")
    bad = int((~np.isfinite(pts).all(axis=1)).sum())
    if bad:
        raise SurfaceError(f"{what} has {bad} vertices with non-finite coordinates (NaN or "
                           f"inf); remove them")
    return pts


def _cloud(vertices: Any, what: str) -> np.ndarray:
    pts = np.unique(_finite_points(vertices, what), axis=0)
    if len(pts) < MIN_POINTS:
        raise SurfaceError(f"{what} has no faces and only {len(pts)} distinct points; give a "
                           f"triangle mesh or a point cloud of at least {MIN_POINTS} points")
    extent = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    if extent[1] <= 1e-9 * extent[0]:
        raise SurfaceError(f"the points of {what} lie on a line; give a point cloud that "
                           f"covers a surface patch")
    return pts


def _clean(vertices: Any, faces: Any, what: str) -> trimesh.Trimesh:
    """The mesh with vertices merged, degenerate and duplicate faces and unused vertices
    removed, and a consistent winding."""
    pts = _finite_points(vertices, what)
    try:
        tri = np.asarray(faces)
        ok = tri.ndim == 2 and tri.shape[1] == 3 and np.issubdtype(tri.dtype, np.integer)
    except (TypeError, ValueError):
        ok = False
    if not ok or (tri.size and (tri.min() < 0 or tri.max() >= len(pts))):
        raise SurfaceError(f"the faces of {what} must be an (m, 3) integer array of vertex "
                           f"indices in [0, {len(pts)})")
    mesh = trimesh.Trimesh(vertices=pts, faces=tri, process=False)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    mesh.update_faces(mesh.nondegenerate_faces())
    mesh.update_faces(mesh.unique_faces())
    mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise SurfaceError(f"{what} has no non-degenerate triangles; give a triangle mesh of "
                           f"the surface")
    return mesh


# -- topology ------------------------------------------------------------------------------


def _check_disk(mesh: trimesh.Trimesh, what: str) -> None:
    """Raise SurfaceError unless the mesh is one manifold patch of disk topology; fix its
    winding when it is one."""
    edges, counts = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
    if (counts > 2).any():
        raise SurfaceError(f"{what} has {int((counts > 2).sum())} non-manifold edges (shared by "
                           f"more than two triangles); repair the mesh or crop it to one sheet")
    n_comp, _ = connected_components(
        sparse.coo_matrix((np.ones(len(mesh.face_adjacency)), mesh.face_adjacency.T),
                          shape=(len(mesh.faces),) * 2), directed=False)
    if n_comp > 1:
        raise SurfaceError(f"{what} has {n_comp} separate pieces (connected components); "
                           f"keep one, e.g. crop it or delete the others")
    boundary = edges[counts == 1]
    if len(boundary) == 0:
        raise SurfaceError(f"{what} is a closed surface (no boundary); cut it open or crop it "
                           f"to one patch that is a deformed disk")
    degree = np.bincount(boundary.ravel(), minlength=len(mesh.vertices))
    if (degree > 2).any():
        raise SurfaceError(f"{what} has {int((degree > 2).sum())} non-manifold vertices (two "
                           f"boundary loops touch); repair the mesh or crop it")
    n_vertices = len(mesh.vertices)
    n_loops = connected_components(
        sparse.coo_matrix((np.ones(len(boundary)), boundary.T), shape=(n_vertices,) * 2),
        directed=False)[0] - int((degree == 0).sum())
    if n_loops > 1:
        raise SurfaceError(f"{what} has {n_loops} boundary loops, i.e. {n_loops - 1} hole(s); "
                           f"fill the holes or crop it to a patch without holes")
    euler = n_vertices - len(edges) + len(mesh.faces)
    if euler != 1:
        raise SurfaceError(f"{what} has one boundary loop but Euler characteristic {euler} (a "
                           f"disk has 1): it has handles or is not orientable; crop it to a "
                           f"patch that is a deformed disk")
    if not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)


def _boundary_loop(mesh: trimesh.Trimesh) -> np.ndarray:
    """Vertex indices (b,) of the single boundary loop, in the faces' winding direction."""
    directed = mesh.edges
    _, inverse, counts = np.unique(mesh.edges_sorted, axis=0, return_inverse=True,
                                   return_counts=True)
    succ = dict(directed[counts[inverse.ravel()] == 1].tolist())
    start = next(iter(succ))
    loop = [start]
    while (nxt := succ[loop[-1]]) != start:
        loop.append(nxt)
    return np.asarray(loop)


# -- parametrization -----------------------------------------------------------------------


def _plane_axes(points: np.ndarray) -> np.ndarray:
    """Principal axes (3, 3) of the points: rows e1, e2 (in-plane, decreasing extent) and
    the normal e3 = e1 x e2."""
    centred = points - points.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]
    return np.stack([axes[0], axes[1], np.cross(axes[0], axes[1])])


def _project(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(in-plane coordinates (n, 2) along the principal axes, the plane's normal (3,))."""
    axes = _plane_axes(points)
    return (points - points.mean(axis=0)) @ axes[:2].T, axes[2]


def parametrize(mesh: trimesh.Trimesh) -> tuple[np.ndarray, str]:
    """(uv (n, 2), method) for a disk-topology mesh with consistent winding: the conformal
    map onto a rectangle if the patch has four corners, else the projection onto the
    best-fit plane if the mesh is a graph over it, else LSCM, else Tutte's map (module
    docstring). Orientation: r_u x r_v agrees with the faces' normals."""
    rectangle = conformal_rectangle(mesh)
    if rectangle is not None:
        return align(rectangle), "rectangle"
    pts = np.asarray(mesh.vertices, dtype=float)
    axes = _plane_axes(pts)
    normals = mesh.face_normals
    if normals @ axes[2] @ mesh.area_faces < 0:
        axes = axes * np.array([[1.0], [-1.0], [-1.0]])
    uv = (pts - pts.mean(axis=0)) @ axes[:2].T
    steep = (normals @ axes[2]) < math.cos(GRAPH_ANGLE)
    if _injective(mesh, uv, steep):
        return align(uv), "projection"
    uv = _lscm(mesh)
    method = "lscm"
    if not _injective(mesh, uv, np.zeros(len(mesh.faces), dtype=bool)):
        uv, method = _tutte(mesh), "tutte"
    uv = align(uv)
    return uv * math.sqrt(mesh.area / _signed_areas(mesh.faces, uv).sum()), method


def corners(points: np.ndarray, normals: np.ndarray, loop: np.ndarray) -> np.ndarray | None:
    """Positions in the boundary ``loop`` (b,) of the patch's four corners, increasing, or
    None unless there are exactly four. At every boundary vertex p_k (of ``points`` (n, 3),
    with unit ``normals`` (n, 3); the loop counter-clockwise about them), the angle between
    the chords to p_{k-w} and p_{k+w} (w = :data:`CORNER_WINDOW` of the loop, at least one
    vertex, so a noisy boundary's zigzag averages out); the runs of vertices where the
    boundary turns left (a convex corner) and that angle is at most CORNER_ANGLE are the
    corners, each at its smallest angle."""
    b = len(loop)
    w = max(1, round(CORNER_WINDOW * b))
    p = points[loop]
    back, ahead = np.roll(p, w, axis=0) - p, np.roll(p, -w, axis=0) - p
    cos = np.einsum("kd,kd->k", back, ahead) / (np.linalg.norm(back, axis=1)
                                                * np.linalg.norm(ahead, axis=1))
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    left = np.einsum("kd,kd->k", np.cross(-back, ahead), normals[loop]) > 0
    sharp = (angle <= CORNER_ANGLE) & left
    if sharp.all() or not sharp.any():
        return None
    start = int(np.flatnonzero(~sharp)[0])  # runs, the loop rolled to start outside one
    order = (start + np.arange(b)) % b
    runs = np.split(order, np.flatnonzero(np.diff(sharp[order].astype(int)) != 0) + 1)
    found = sorted(int(run[np.argmin(angle[run])]) for run in runs if sharp[run[0]])
    return np.asarray(found) if len(found) == 4 else None


def _cotangent_laplacian(mesh: trimesh.Trimesh) -> sparse.csr_matrix:
    """L (n, n) with u' L u the Dirichlet energy of the piecewise linear u: the weight of
    an edge is half the sum of the cotangents of the angles opposite it."""
    n, f = len(mesh.vertices), mesh.faces
    half_cot = 0.5 / np.tan(mesh.face_angles)  # at vertex k of a face: opposite its edge
    i = np.r_[f[:, 1], f[:, 2], f[:, 0]]
    j = np.r_[f[:, 2], f[:, 0], f[:, 1]]
    w = half_cot.T.ravel()
    weights = sparse.coo_matrix((np.r_[w, w], (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
    return (sparse.diags(np.asarray(weights.sum(axis=1)).ravel()) - weights).tocsr()


def _harmonic(lap: sparse.csr_matrix, zero: np.ndarray, one: np.ndarray
              ) -> tuple[np.ndarray, float]:
    """(x (n,), its Dirichlet energy x' L x): L x = 0 but on the vertices ``zero`` (x = 0)
    and ``one`` (x = 1); the other boundary vertices get no flux (the natural condition)."""
    x = np.zeros(lap.shape[0])
    known = np.zeros(lap.shape[0], dtype=bool)
    known[zero] = known[one] = True
    x[one] = 1.0
    free = ~known
    x[free] = spsolve(lap[free][:, free].tocsc(), -(lap[free][:, known] @ x[known]))
    return x, float(x @ (lap @ x))


def conformal_rectangle(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """The conformal map (n, 2) of a patch with four :func:`corners` onto a rectangle of the
    mesh's area (module docstring), the sides in the boundary's order: bottom, right, top,
    left; None without four corners, where a triangle flips or where the map stretches
    areas by more than MAX_AREA_SPREAD."""
    loop = _boundary_loop(mesh)
    at = corners(np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals), loop)
    if at is None:
        return None
    ends = np.r_[at, at[0] + len(loop)]
    sides = [loop[np.arange(a, b + 1) % len(loop)] for a, b in zip(ends[:-1], ends[1:])]
    lap = _cotangent_laplacian(mesh)
    u, energy_u = _harmonic(lap, sides[3], sides[1])
    v, energy_v = _harmonic(lap, sides[0], sides[2])
    if not (energy_u > 0 and energy_v > 0):
        return None
    aspect = math.sqrt(energy_u / energy_v)  # height over width
    uv = np.c_[u / math.sqrt(aspect), v * math.sqrt(aspect)] * math.sqrt(mesh.area)
    if not _injective(mesh, uv, np.zeros(len(mesh.faces), dtype=bool)):
        return None
    return uv if _area_spread(mesh, uv) <= MAX_AREA_SPREAD else None


def _area_spread(mesh: trimesh.Trimesh, uv: np.ndarray) -> float:
    """The ratio of the 99th to the 1st percentile, weighted by the faces' areas, of the
    map's area scale (the faces' parameter area over their area)."""
    scale = _signed_areas(mesh.faces, uv) / np.maximum(mesh.area_faces, 1e-300)
    order = np.argsort(scale)
    share = np.cumsum(mesh.area_faces[order]) / mesh.area
    low, high = scale[order][np.searchsorted(share, [0.01, 0.99]).clip(0, len(scale) - 1)]
    return float(high / low) if low > 0 else math.inf


def _signed_areas(faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                  - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def _injective(mesh: trimesh.Trimesh, uv: np.ndarray, bad: np.ndarray) -> bool:
    """Whether the map uv (n, 2) of the disk is injective up to slivers: the faces that are
    ``bad`` (m,) or not positively oriented in the plane cover at most SLIVER_AREA of the
    mesh's area, and the boundary is a simple polygon."""
    bad = bad | (_signed_areas(mesh.faces, uv) <= 0)
    if mesh.area_faces[bad].sum() > SLIVER_AREA * mesh.area:
        return False
    return not _self_intersecting(uv[_boundary_loop(mesh)])


def _self_intersecting(polygon: np.ndarray) -> bool:
    """Whether two non-adjacent edges of the closed polygon (b, 2) cross."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    n = len(a)
    idx = np.arange(n)

    def orient(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    block = max(1, 2_000_000 // n)
    for k in range(0, n, block):
        i = idx[k:k + block, None]
        p, q = a[k:k + block, None], b[k:k + block, None]
        r, s = a[None], b[None]
        cross = ((orient(p, q, r) * orient(p, q, s) < 0)
                 & (orient(r, s, p) * orient(r, s, q) < 0))
        gap = (idx[None] - i) % n
        if (cross & (gap > 1) & (gap < n - 1)).any():
            return True
    return False


def _local_gradients(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Per face, the gradients (m, 3, 2) of the three barycentric coordinates in a local
    orthonormal frame of the face (counter-clockwise about its normal) and the areas (m,)."""
    tri = mesh.triangles
    e1 = tri[:, 1] - tri[:, 0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(mesh.face_normals, e1)
    rel = tri - tri[:, :1]
    q = np.stack([np.einsum("mkd,md->mk", rel, e1), np.einsum("mkd,md->mk", rel, e2)], -1)
    area = mesh.area_faces
    opposite = np.roll(q, 1, axis=1) - np.roll(q, -1, axis=1)  # q_{j+2} - q_{j+1}
    grad = np.stack([-opposite[..., 1], opposite[..., 0]], -1) / (2 * area[:, None, None])
    return grad, area


def _lscm(mesh: trimesh.Trimesh) -> np.ndarray:
    """Least-squares conformal map (n, 2): Cauchy-Riemann residuals u_x - v_y, u_y + v_x per
    face weighted by sqrt(area), the two farthest-apart boundary vertices pinned."""
    n = len(mesh.vertices)
    grad, area = _local_gradients(mesh)
    w = np.sqrt(area)[:, None] * np.ones((1, 3))
    faces = mesh.faces
    m = len(faces)
    rows = np.repeat(np.arange(2 * m), 6).reshape(2 * m, 6)
    cols = np.concatenate([np.c_[faces, faces + n], np.c_[faces, faces + n]])
    vals = np.concatenate([np.c_[w * grad[..., 0], -w * grad[..., 1]],
                           np.c_[w * grad[..., 1], w * grad[..., 0]]])
    a = sparse.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * m, 2 * n))
    loop = _boundary_loop(mesh)
    pts = mesh.vertices[loop]
    i = int(np.argmax(np.linalg.norm(pts - pts[0], axis=1)))
    j = int(np.argmax(np.linalg.norm(pts - pts[i], axis=1)))
    pinned = np.array([loop[i], loop[j]])
    length = float(np.linalg.norm(pts[i] - pts[j]))
    fixed = np.zeros(2 * n)
    fixed[pinned[1]] = length
    known = np.zeros(2 * n, dtype=bool)
    known[np.r_[pinned, pinned + n]] = True
    free = ~known
    af = a[:, free]
    x = fixed.copy()
    x[free] = spsolve((af.T @ af).tocsc(), -(af.T @ (a[:, known] @ fixed[known])))
    return np.c_[x[:n], x[n:]]


def _tutte(mesh: trimesh.Trimesh) -> np.ndarray:
    """Tutte's embedding (n, 2): boundary on the unit circle by arc length, every interior
    vertex the average of its neighbours (injective for a disk)."""
    n = len(mesh.vertices)
    loop = _boundary_loop(mesh)
    seg = np.linalg.norm(np.diff(mesh.vertices[np.r_[loop, loop[:1]]], axis=0), axis=1)
    angle = 2 * np.pi * np.r_[0.0, np.cumsum(seg)[:-1]] / seg.sum()
    uv = np.zeros((n, 2))
    uv[loop] = np.c_[np.cos(angle), np.sin(angle)]
    edges = mesh.edges_unique
    adj = sparse.coo_matrix((np.ones(2 * len(edges)), (edges.ravel(), edges[:, ::-1].ravel())),
                            shape=(n, n)).tocsr()
    lap = sparse.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    interior = np.ones(n, dtype=bool)
    interior[loop] = False
    rhs = -(lap[interior][:, loop] @ uv[loop])
    uv[interior] = np.asarray(spsolve(lap[interior][:, interior].tocsc(), rhs)).reshape(-1, 2)
    return uv


def align(uv: np.ndarray) -> np.ndarray:
    """uv (n, 2) rotated (orientation kept) so that its smallest-area bounding rectangle is
    axis-aligned, u along the rectangle's longer side, and centred at the origin."""
    corners = uv[ConvexHull(uv).vertices]
    edges = np.diff(np.r_[corners, corners[:1]], axis=0)
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    best = None
    for a in angles:
        rot = np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
        q = corners @ rot.T
        ext = np.ptp(q, axis=0)
        if best is None or ext.prod() < best[0]:
            best = (ext.prod(), rot, ext)
    _, rot, ext = best
    if ext[1] > ext[0]:
        rot = np.array([[0.0, 1.0], [-1.0, 0.0]]) @ rot
    out = uv @ rot.T
    return out - 0.5 * (out.min(axis=0) + out.max(axis=0))


# -- the domain ----------------------------------------------------------------------------


def _raster(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raster node coordinates (RASTER,) along u and along v over the bounding box of uv."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return np.linspace(lo[0], hi[0], RASTER), np.linspace(lo[1], hi[1], RASTER)


def _polygon_mask(polygon: np.ndarray) -> np.ndarray:
    """(RASTER, RASTER) mask of the raster nodes inside the polygon (b, 2)."""
    gu, gv = _raster(polygon)
    nodes = np.stack(np.meshgrid(gu, gv, indexing="ij"), -1).reshape(-1, 2)
    return PolygonPath(polygon).contains_points(nodes).reshape(RASTER, RASTER)


def _cloud_faces(uv: np.ndarray) -> tuple[Delaunay, np.ndarray]:
    """The Delaunay triangulation of uv (n, 2) and the mask (m,) of its triangles whose
    longest edge is at most three times the median longest edge (which drops the long
    triangles spanning gaps and concave bays)."""
    tri = Delaunay(uv)
    vertices = uv[tri.simplices]
    longest = np.linalg.norm(vertices - np.roll(vertices, 1, axis=1), axis=2).max(axis=1)
    return tri, longest <= 3 * np.median(longest)


def _cloud_mask(uv: np.ndarray) -> np.ndarray:
    """(RASTER, RASTER) mask of the raster nodes inside the region the cloud samples: in
    the triangles of :func:`_cloud_faces`."""
    gu, gv = _raster(uv)
    tri, keep = _cloud_faces(uv)
    keep = np.r_[keep, False]  # index -1 (outside) -> False
    nodes = np.stack(np.meshgrid(gu, gv, indexing="ij"), -1).reshape(-1, 2)
    return keep[tri.find_simplex(nodes)].reshape(RASTER, RASTER)


def _cloud_rectangle(points: np.ndarray, uv: np.ndarray) -> np.ndarray | None:
    """The :func:`conformal_rectangle` (n, 2) of a cloud's points (n, 3) (on its smoothed
    surface) triangulated by :func:`_cloud_faces` of their projections uv (n, 2), if that
    mesh is one disk with four corners that uses every point; else None."""
    tri, keep = _cloud_faces(uv)
    faces = tri.simplices[keep]
    if len(np.unique(faces)) != len(points):
        return None
    flip = _signed_areas(faces, uv) < 0
    faces[flip] = faces[flip][:, ::-1]  # counter-clockwise in the plane
    mesh = trimesh.Trimesh(points, faces, process=False)
    try:
        _check_disk(mesh, "the point cloud")
    except SurfaceError:
        return None
    return conformal_rectangle(mesh)


def inscribed_rectangle(uv: np.ndarray, inside: np.ndarray) -> tuple[tuple[float, float],
                                                                       tuple[float, float]]:
    """The largest axis-aligned rectangle ((u0, u1), (v0, v1)) of raster nodes that are all
    inside (``inside``: (RASTER, RASTER) over the bounding box of uv (n, 2)), after eroding
    the mask by one node so the rectangle stays within the parameter image between nodes."""
    mask = binary_erosion(inside)
    if not mask.any():
        raise SurfaceError("the parameter image of the shape is too thin for a rectangle; "
                           "give a mesh or cloud that covers a two-dimensional patch")
    gu, gv = _raster(uv)
    best, rect = 0, (0, 0, 0, 0)
    heights = np.zeros(RASTER, dtype=int)
    for i in range(RASTER):
        heights = np.where(mask[i], heights + 1, 0)
        stack: list[int] = []
        for j in range(RASTER + 1):
            h = heights[j] if j < RASTER else 0
            while stack and heights[stack[-1]] >= h:
                top = stack.pop()
                left = stack[-1] + 1 if stack else 0
                # nodes rows i-heights+1..i, columns left..j-1; area in node gaps
                area = (heights[top] - 1) * (j - 1 - left)
                if area > best:
                    best, rect = area, (i - heights[top] + 1, i, left, j - 1)
            stack.append(j)
    if best == 0:
        raise SurfaceError("the parameter image of the shape is too thin for a rectangle; "
                           "give a mesh or cloud that covers a two-dimensional patch")
    a, b, c, d = rect
    return (float(gu[a]), float(gu[b])), (float(gv[c]), float(gv[d]))


# -- the spline ----------------------------------------------------------------------------


def _knot_spans(uv: np.ndarray, per_cell: int) -> tuple[int, int]:
    """Knot spans (n_u, n_v): about per_cell points per cell, cells about square."""
    extent = np.ptp(uv, axis=0)
    cells = len(uv) / per_cell
    aspect = extent[0] / extent[1]
    lo, hi = KNOT_SPANS
    return (int(np.clip(round(math.sqrt(cells * aspect)), lo, hi)),
            int(np.clip(round(math.sqrt(cells / aspect)), lo, hi)))


def _uniform_knots(lo: float, hi: float, spans: int) -> np.ndarray:
    """Uniform cubic knots (spans + 7,) whose basis is a partition of unity on [lo, hi]."""
    h = (hi - lo) / spans
    return np.r_[lo + h * np.arange(-3, 0), np.linspace(lo, hi, spans + 1),
                 hi + h * np.arange(1, 4)]


def _second_differences(n: int) -> sparse.csr_matrix:
    return sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n)).tocsr()


def _basis(uv: np.ndarray, lo: np.ndarray, hi: np.ndarray, spans: tuple[int, int]
           ) -> sparse.csr_matrix:
    """The tensor-product cubic B-spline basis (n, (spans_u + 3) (spans_v + 3)) on uniform
    knots over [lo, hi] at uv (n, 2) (clipped to it)."""
    t_u, t_v = (_uniform_knots(lo[k], hi[k], spans[k]) for k in range(2))
    n_v = spans[1] + 3
    b_u = BSpline.design_matrix(np.clip(uv[:, 0], lo[0], hi[0]), t_u, 3).tocsr()
    b_v = BSpline.design_matrix(np.clip(uv[:, 1], lo[1], hi[1]), t_v, 3).tocsr()
    n = len(uv)
    iu, iv = b_u.indices.reshape(n, 4), b_v.indices.reshape(n, 4)
    wu, wv = b_u.data.reshape(n, 4), b_v.data.reshape(n, 4)
    cols = (iu[:, :, None] * n_v + iv[:, None, :]).reshape(n, 16)
    vals = (wu[:, :, None] * wv[:, None, :]).reshape(n, 16)
    return sparse.csr_matrix((vals.ravel(), (np.repeat(np.arange(n), 16), cols.ravel())),
                             shape=(n, (spans[0] + 3) * n_v))


def _smoothed(uv: np.ndarray, points: np.ndarray, spans: tuple[int, int],
              smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """The P-spline fit (module docstring) over the bounding box of uv (n, 2): its values
    (n, 3) at uv and its control points ((spans_u + 3) (spans_v + 3), 3)."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    n_u, n_v = spans[0] + 3, spans[1] + 3
    a = _basis(uv, lo, hi, spans)
    d_u = sparse.kron(_second_differences(n_u), sparse.identity(n_v))
    d_v = sparse.kron(sparse.identity(n_u), _second_differences(n_v))
    weight = smoothing * len(uv) / (n_u * n_v)
    lhs = (a.T @ a + weight * (d_u.T @ d_u + d_v.T @ d_v)).tocsc()
    coef = np.asarray(spsolve(lhs, a.T @ points))
    return a @ coef, coef


def _fit_spline(uv: np.ndarray, points: np.ndarray, spans: tuple[int, int],
                smoothing: float) -> ca.Function:
    """The P-spline fit (module docstring), as a CasADi bspline interpolant (u, v) -> r (3)."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    coef = _smoothed(uv, points, spans, smoothing)[1]
    g_u, g_v = (np.linspace(lo[k], hi[k], 2 * spans[k] + 1) for k in range(2))
    grid = np.stack(np.meshgrid(g_u, g_v, indexing="ij"), -1).reshape(-1, 2)
    values = (_basis(grid, lo, hi, spans) @ coef).reshape(len(g_u), len(g_v), 3)
    spline = ca.interpolant("mesh_r", "bspline", [g_u, g_v],
                            values.transpose(2, 0, 1).ravel(order="F"))
    # CasADi's bspline is 0 outside its grid: a parameter a round-off outside (a free
    # correspondence's grid on the domain's edge) is put back on it, with the identity's
    # derivative on the edge itself
    uv_sym = ca.SX.sym("uv", 2)
    on_grid = ca.vertcat(*(ca.if_else(uv_sym[k] < lo[k], lo[k],
                                      ca.if_else(uv_sym[k] > hi[k], hi[k], uv_sym[k]))
                           for k in range(2)))
    return ca.Function("mesh_r", [uv_sym], [spline(on_grid)])
