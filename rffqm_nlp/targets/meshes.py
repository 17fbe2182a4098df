"""Target shapes from triangle meshes and point clouds: :class:`Mesh` (``rq.surfaces.Mesh``).

A designer's shape becomes a smooth parametric surface r(u, v) in four steps
(``docs/meshes.md`` has the measurements behind the choices):

1. **Load.** A file of the :data:`FORMATS` (OBJ, STL, PLY, OFF, GLB, glTF with embedded
   buffers, XYZ; at most :data:`MAX_FILE_BYTES`, read from its bytes alone: no file it names
   is opened, no material or texture decoded, nothing of it quoted in an error), a
   ``trimesh.Trimesh``, a ``(V, F)`` pair of arrays, or a point cloud (an (n, 3) array, a
   ``trimesh.PointCloud`` or a file with vertices and no faces). At most :data:`MAX_FACES`
   triangles or :data:`MAX_POINTS` points, checked before any work on them. The shape is
   then moved into its unit frame (:func:`_frame`: centred, divided by a power of two near
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
(:func:`closest_on_mesh`: trimesh's candidate faces, the nearest taken);
:func:`rffqm_nlp.targets.shape.relative_fit` the RMS and maximum distance of points to any target,
over its diameter.
"""

from __future__ import annotations

import contextlib
import io
import logging
import math
import stat
from collections.abc import Iterator
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
from scipy.sparse.linalg import splu, spsolve
from scipy.spatial import ConvexHull, Delaunay

from ..errors import RffqmError, SurfaceError
from ..files import Key, check_value
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
#: The file formats read, by suffix: trimesh's readers of triangle meshes and point clouds.
#: Archives (zip, tar, bz2), whose unpacked size no file size bounds, and 2D drawings (dxf)
#: are refused.
FORMATS = ("obj", "stl", "ply", "off", "glb", "gltf", "xyz")
_KINDS = {"obj": "an OBJ", "stl": "an STL", "ply": "a PLY", "off": "an OFF",
          "glb": "a GLB (binary glTF)", "gltf": "a glTF", "xyz": "an XYZ point"}
_FORMAT_LIST = "an OBJ, STL, PLY, OFF, GLB, glTF or XYZ file"
#: Most triangles of a mesh (and three vertices each) and most points of a point cloud:
#: a larger one is refused before any work on it (the time and memory at the limit:
#: docs/meshes.md).
MAX_FACES = 100_000
MAX_POINTS = 50_000
#: Largest file read (bytes), checked before reading it: a mesh of MAX_FACES triangles
#: takes 29 MB as ASCII STL, 5 MB as binary STL.
MAX_FILE_BYTES = 50_000_000
#: Most pieces (placements of a geometry) of a scene file (GLB, glTF).
MAX_PIECES = 1000
#: Relative tolerance under which two candidates of :func:`align` (areas, sides) and of
#: :func:`_knot_spans` (a count on a half) tie: a tie is broken by a fixed rule rather than
#: by round-off, so the same shape at another size or position gives the same Mesh.
TIE = 1e-9


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
        # every step works on the shape moved and scaled into its unit frame (:func:`_frame`):
        # trimesh's tolerances are absolute
        loaded, centre, scale = _load(source, what)
        cloud = not isinstance(loaded, trimesh.Trimesh)
        self._unit_mesh = mesh = None if cloud else loaded
        self.smoothing = fit_smoothing = smoothing or (CLOUD_SMOOTHING if cloud
                                                       else MESH_SMOOTHING)
        if not cloud:
            _check_disk(mesh, what)
            points = fitted = np.asarray(mesh.vertices, dtype=float)
            uv, self.parametrization = parametrize(mesh)
            self.knots = knots or _knot_spans(uv, MESH_POINTS_PER_CELL)
        else:
            what = what if self.path is not None else "the point cloud"
            points = fitted = loaded
            uv, self._plane_normal = _project(points)
            self.knots = knots or _knot_spans(uv, CLOUD_POINTS_PER_CELL)
            on_surface = _smoothed(uv, points, self.knots, self.smoothing)[0]
            rectangle = _cloud_rectangle(on_surface, uv)
            if rectangle is None:
                uv, self.parametrization = align(uv), "projection"
                inside = _cloud_mask(uv)
            else:  # the denoised surface in the new parameters: fitted like a mesh
                uv, self.parametrization = align(rectangle), "rectangle"
                fitted, fit_smoothing = on_surface, MESH_SMOOTHING
                self.knots = knots or _knot_spans(uv, MESH_POINTS_PER_CELL)
        if self.parametrization == "rectangle":
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            if cloud:  # the noisy boundary points' spacings stay outside
                inset = CLOUD_INSET * math.sqrt(np.prod(hi - lo) / len(uv))
                lo, hi = lo + inset, hi - inset
            domain = ((lo[0], hi[0]), (lo[1], hi[1]))
        elif cloud:
            domain = inscribed_rectangle(uv, inside)
        else:
            domain = inscribed_rectangle(uv, _polygon_mask(uv[_boundary_loop(mesh)]))
        spline = _fit_spline(uv, fitted, self.knots, fit_smoothing)
        # back in the shape's own units: lengths times scale, points moved back to centre
        self._centre, self._scale = centre, scale
        self.mesh = None if cloud else trimesh.Trimesh(
            centre + scale * np.asarray(mesh.vertices), mesh.faces, process=False)
        self.points, self.uv = centre + scale * points, scale * uv
        self._spline = _in_units(spline, centre, scale)
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
        with _quiet_trimesh():
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


# -- loading -------------------------------------------------------------------------------


def is_mesh_file(path: str | Path) -> bool:
    """Whether ``path``'s suffix names a format trimesh reads (OBJ, STL, PLY, OFF, GLB,
    XYZ, ...), case-insensitively. Of those, a :class:`Mesh` reads the :data:`FORMATS`
    and refuses the others (archives, drawings) in one line."""
    return Path(path).suffix.lower().lstrip(".") in trimesh.available_formats()


@contextlib.contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """trimesh's log records (which may quote a file's content) silenced for the block."""
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


@contextlib.contextmanager
def _trimesh_step(what: str, step: str) -> Iterator[None]:
    """trimesh's work on the shape, quiet; any failure inside becomes one SurfaceError line
    naming the step, never trimesh's own text (it may quote the file)."""
    with _quiet_trimesh():
        try:
            yield
        except (RffqmError, MemoryError):
            raise
        except Exception:
            raise SurfaceError(f"{what} could not be processed (trimesh failed while {step}); "
                               f"repair the mesh (e.g. in MeshLab or Blender) or export it "
                               f"again") from None


def _load(source: Any, what: str) -> tuple[trimesh.Trimesh | np.ndarray, np.ndarray, float]:
    """(the cleaned mesh or the cloud's points (n, 3), in the unit frame; the frame's centre
    (3,) and scale (:func:`_frame`)) from any accepted source, its size bounded
    (:func:`_check_size`) before any work on it."""
    if isinstance(source, (str, Path)):
        source = _read(Path(source))
    if isinstance(source, trimesh.Scene):
        _check_scene_size(source, what)
        with _trimesh_step(what, "joining the file's pieces"):
            geoms = list(source.dump()) if source.geometry else []
            meshes = [g for g in geoms if isinstance(g, trimesh.Trimesh) and len(g.faces)]
            clouds = [g for g in geoms if isinstance(g, trimesh.PointCloud)]
            if meshes:
                source = trimesh.util.concatenate(meshes)
            elif clouds:
                source = np.concatenate([c.vertices for c in clouds])
            else:
                source = None
        if source is None:
            raise SurfaceError(f"cannot read {what} as a mesh: it holds no triangles and no "
                               f"points; export the surface as a triangle mesh or point cloud")
    if isinstance(source, trimesh.PointCloud):
        source = np.asarray(source.vertices)
    if isinstance(source, trimesh.Trimesh):
        if len(source.faces) == 0:
            return _cloud(source.vertices, what)
        return _unit_mesh(source.vertices, source.faces, what)
    if isinstance(source, (tuple, list)) and len(source) == 2:
        return _unit_mesh(*source, what)
    if isinstance(source, np.ndarray) and source.ndim == 2 and source.shape[1] == 3:
        return _cloud(source, what)
    raise SurfaceError(f"Mesh needs a file path, a trimesh.Trimesh, a (vertices, faces) pair or "
                       f"an (n, 3) point array, got {type(source).__name__}")


def _read(path: Path) -> Any:
    """trimesh's reading of a file of one of the :data:`FORMATS` of at most
    :data:`MAX_FILE_BYTES`, from its bytes alone (no file it names is opened: no resolver,
    no materials or textures); every failure becomes one SurfaceError line that quotes
    nothing of the file."""
    if "\x00" in str(path):
        raise SurfaceError(f"cannot read {path} as a mesh: its name holds a NUL character; "
                           f"give the mesh file's path")
    try:
        info = path.stat()
    except (FileNotFoundError, NotADirectoryError):
        raise SurfaceError(f"cannot read {path} as a mesh: no such file") from None
    except (OSError, ValueError) as err:
        reason = getattr(err, "strerror", None) or "the system refused to look it up"
        raise SurfaceError(f"cannot read {path} as a mesh: {reason}; give a readable mesh "
                           f"file") from None
    if stat.S_ISDIR(info.st_mode):
        raise SurfaceError(f"cannot read {path} as a mesh: it is a folder; give a mesh file")
    if not stat.S_ISREG(info.st_mode):
        raise SurfaceError(f"cannot read {path} as a mesh: it is no regular file (a device, "
                           f"a pipe or a socket); give a mesh file")
    kind = path.suffix.lower().lstrip(".")
    if kind not in FORMATS:
        raise SurfaceError(f"cannot read {path} as a mesh: its suffix names no format read "
                           f"here (archives are not unpacked); give {_FORMAT_LIST}")
    if info.st_size > MAX_FILE_BYTES:
        raise SurfaceError(f"cannot read {path} as a mesh: it is {_megabytes(info.st_size)}, "
                           f"more than the {_megabytes(MAX_FILE_BYTES)} read; decimate the "
                           f"mesh to at most {MAX_FACES} triangles (under 5 MB as binary "
                           f"STL or PLY)")
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise SurfaceError(f"cannot read {path} as a mesh: "
                           f"{err.strerror or 'the system refused to read it'}; give a "
                           f"readable mesh file") from None
    if len(data) > MAX_FILE_BYTES:  # it grew since stat
        raise SurfaceError(f"cannot read {path} as a mesh: it is more than the "
                           f"{_megabytes(MAX_FILE_BYTES)} read; decimate the mesh")
    with _quiet_trimesh():
        try:
            loaded = trimesh.load(io.BytesIO(data), file_type=kind, process=False,
                                  skip_materials=True)
        except MemoryError:
            raise
        except Exception:  # trimesh's readers raise anything on a bad file
            loaded = None
    if loaded is None:
        raise SurfaceError(f"cannot read {path} as a mesh: it could not be parsed as "
                           f"{_KINDS[kind]} file; give {_FORMAT_LIST}"
                           + ("" if kind != "gltf" else
                              " (a glTF must embed its buffers: no file it names is read)"))
    if isinstance(loaded, (trimesh.Trimesh, trimesh.PointCloud, trimesh.Scene)):
        return loaded
    raise SurfaceError(f"cannot read {path} as a mesh: trimesh gave a "
                       f"{type(loaded).__name__}; give a triangle mesh or a point cloud")


def _megabytes(size: int) -> str:
    return f"{size / 1e6:.3g} MB"


def _check_size(what: str, faces: int, vertices: int) -> None:
    """Raise SurfaceError above :data:`MAX_FACES` triangles (with faces) or
    :data:`MAX_POINTS` points (without), before any work on them."""
    if faces > MAX_FACES or (faces and vertices > 3 * MAX_FACES):
        many = f"{faces} triangles" if faces > MAX_FACES else f"{vertices} vertices"
        raise SurfaceError(f"{what} has {many}, more than a Mesh takes ({MAX_FACES} triangles "
                           f"and {3 * MAX_FACES} vertices); decimate it to at most "
                           f"{MAX_FACES} triangles (e.g. Blender's Decimate modifier, "
                           f"MeshLab's quadric edge collapse) or crop it")
    if not faces and vertices > MAX_POINTS:
        raise SurfaceError(f"{what} has {vertices} points, more than a Mesh takes "
                           f"({MAX_POINTS}); subsample it to at most {MAX_POINTS} points "
                           f"(e.g. every k-th point) or crop it")


def _check_scene_size(scene: trimesh.Scene, what: str) -> None:
    """:func:`_check_size` of everything a scene's pieces (each placement of a geometry
    counts) would give, before they are joined; at most :data:`MAX_PIECES` pieces."""
    with _trimesh_step(what, "reading the file's pieces"):
        nodes = list(scene.graph.nodes_geometry)
        if len(nodes) > MAX_PIECES:
            raise SurfaceError(f"{what} has {len(nodes)} pieces, more than a Mesh joins "
                               f"({MAX_PIECES}); export the surface as one mesh")
        faces = vertices = points = 0
        for node in nodes:
            geometry = scene.geometry.get(scene.graph[node][1])
            if isinstance(geometry, trimesh.Trimesh) and len(geometry.faces):
                faces += len(geometry.faces)
                vertices += len(geometry.vertices)
            elif isinstance(geometry, (trimesh.Trimesh, trimesh.PointCloud)):
                points += len(geometry.vertices)
    _check_size(what, faces, vertices if faces else points)


def _frame(points: np.ndarray, what: str) -> tuple[np.ndarray, float]:
    """(centre (3,), scale) of the unit frame of points (n, 3): the centre of their bounding
    box, and the power of two in (diagonal, 2 diagonal] of it (1 for coinciding points), so
    that scaling by it is exact. Every step of a Mesh works on (points - centre) / scale,
    so the same shape in micrometres, metres or light years gives the same Mesh up to that
    scale (trimesh's tolerances are absolute: vertex merging at 1e-8, closest points)."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre, half = 0.5 * lo + 0.5 * hi, 0.5 * hi - 0.5 * lo  # no overflow near 1e308
    largest = float(half.max())
    if largest == 0.0:
        return centre, 1.0
    diagonal = 2.0 * largest * float(np.linalg.norm(half / largest))
    if not diagonal < 2.0 ** 1022:
        raise SurfaceError(f"the coordinates of {what} span more than 1e307; give them in "
                           f"a larger unit")
    return centre, math.ldexp(1.0, math.frexp(diagonal)[1])


def _finite_points(vertices: Any, what: str) -> np.ndarray:
    try:
        pts = np.asarray(vertices, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise SurfaceError(f"the vertices of {what} must be numbers, shape (n, 3)") from None
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SurfaceError(f"the vertices of {what} must have shape (n, 3), got {pts.shape}")
    bad = int((~np.isfinite(pts).all(axis=1)).sum())
    if bad:
        raise SurfaceError(f"{what} has {bad} vertices with non-finite coordinates (NaN or "
                           f"inf); remove them")
    return pts


def _triangles(faces: Any, vertices: int, what: str) -> np.ndarray:
    """The faces as an (m, 3) integer array of indices into ``vertices`` vertices."""
    try:
        tri = np.asarray(faces)
        ok = tri.ndim == 2 and tri.shape[1] == 3 and np.issubdtype(tri.dtype, np.integer)
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok or (tri.size and (tri.min() < 0 or tri.max() >= vertices)):
        raise SurfaceError(f"the faces of {what} must be an (m, 3) integer array of vertex "
                           f"indices in [0, {vertices})")
    return tri


def _cloud(vertices: Any, what: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(the distinct points (n, 3) in the unit frame, its centre, its scale)."""
    pts = _finite_points(vertices, what)
    _check_size(what, 0, len(pts))
    centre, scale = _frame(pts, what) if len(pts) else (np.zeros(3), 1.0)
    pts = np.unique((pts - centre) / scale, axis=0)
    if len(pts) < MIN_POINTS:
        raise SurfaceError(f"{what} has no faces and only {len(pts)} distinct points; give a "
                           f"triangle mesh or a point cloud of at least {MIN_POINTS} points")
    extent = np.linalg.svd(pts - pts.mean(axis=0), compute_uv=False)
    if extent[1] <= 1e-9 * extent[0]:
        raise SurfaceError(f"the points of {what} lie on a line; give a point cloud that "
                           f"covers a surface patch")
    return pts, centre, scale


def _unit_mesh(vertices: Any, faces: Any, what: str) -> tuple[trimesh.Trimesh, np.ndarray,
                                                               float]:
    """(the :func:`_clean` mesh in the unit frame of its used vertices, the frame's centre,
    its scale), its size checked first."""
    pts = _finite_points(vertices, what)
    tri = _triangles(faces, len(pts), what)
    _check_size(what, len(tri), len(pts))
    if len(tri) == 0:
        raise SurfaceError(f"{what} has no non-degenerate triangles; give a triangle mesh of "
                           f"the surface")
    used = np.zeros(len(pts), dtype=bool)
    used[tri.ravel()] = True
    centre, scale = _frame(pts[used], what)
    return _clean((pts - centre) / scale, tri, what), centre, scale


def _clean(vertices: Any, faces: Any, what: str) -> trimesh.Trimesh:
    """The mesh with vertices merged (within trimesh's 1e-8: give it in the unit frame),
    degenerate and duplicate faces and unused vertices removed."""
    pts = _finite_points(vertices, what)
    tri = _triangles(faces, len(pts), what)
    with _trimesh_step(what, "merging its vertices"):
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
    with _trimesh_step(what, "finding its edges"):
        keys, counts = np.unique(_edge_keys(mesh), return_counts=True)
        adjacency = mesh.face_adjacency
    edges = np.c_[keys // len(mesh.vertices), keys % len(mesh.vertices)]
    if (counts > 2).any():
        raise SurfaceError(f"{what} has {int((counts > 2).sum())} non-manifold edges (shared by "
                           f"more than two triangles); repair the mesh or crop it to one sheet")
    n_comp, _ = connected_components(
        sparse.coo_matrix((np.ones(len(adjacency)), adjacency.T),
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
    with _trimesh_step(what, "making its triangles' winding consistent"):
        if not mesh.is_winding_consistent:  # a disk is orientable: one flip per bad face
            trimesh.repair.fix_winding(mesh)
        consistent = mesh.is_winding_consistent
    if not consistent:
        raise SurfaceError(f"the triangles of {what} could not be oriented consistently; "
                           f"repair the mesh (e.g. in MeshLab or Blender) or export it again")


def _edge_keys(mesh: trimesh.Trimesh) -> np.ndarray:
    """One int64 per edge of every face (3 m,), the same for both directions: a n + b for
    the edge between vertices a < b of the n (a sort of rows, 10 x faster)."""
    edges = np.sort(mesh.edges, axis=1).astype(np.int64)
    return edges[:, 0] * len(mesh.vertices) + edges[:, 1]


def _boundary_loop(mesh: trimesh.Trimesh) -> np.ndarray:
    """Vertex indices (b,) of the single boundary loop, in the faces' winding direction."""
    directed = mesh.edges
    _, inverse, counts = np.unique(_edge_keys(mesh), return_inverse=True, return_counts=True)
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


def _solve_spd(a: sparse.spmatrix, b: np.ndarray) -> np.ndarray:
    """x with a x = b, a sparse symmetric positive definite (a Laplacian restricted to the
    free vertices, normal equations): SuperLU with a minimum degree ordering of a + a' and
    diagonal pivots, as a Cholesky factorization would (faster than spsolve's defaults:
    docs/meshes.md); spsolve's partial pivoting where that fails."""
    a = sparse.csc_matrix(a)
    b = np.asarray(b, dtype=float)
    try:
        x = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                 options={"SymmetricMode": True}).solve(b)
    except RuntimeError:  # a zero pivot
        x = None
    if x is None or not np.all(np.isfinite(x)):
        x = spsolve(a, b)
    return np.asarray(x).reshape(b.shape)


def _harmonic(lap: sparse.csr_matrix, zero: np.ndarray, one: np.ndarray
              ) -> tuple[np.ndarray, float]:
    """(x (n,), its Dirichlet energy x' L x): L x = 0 but on the vertices ``zero`` (x = 0)
    and ``one`` (x = 1); the other boundary vertices get no flux (the natural condition)."""
    x = np.zeros(lap.shape[0])
    known = np.zeros(lap.shape[0], dtype=bool)
    known[zero] = known[one] = True
    x[one] = 1.0
    free = ~known
    x[free] = _solve_spd(lap[free][:, free], -(lap[free][:, known] @ x[known]))
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
    x[free] = _solve_spd(af.T @ af, -(af.T @ (a[:, known] @ fixed[known])))
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
    uv[interior] = _solve_spd(lap[interior][:, interior], rhs).reshape(-1, 2)
    return uv


def align(uv: np.ndarray) -> np.ndarray:
    """uv (n, 2) rotated (orientation kept) so that its smallest-area bounding rectangle is
    axis-aligned, u along the rectangle's longer side, and centred at the origin. Rectangles
    whose areas tie (within :data:`TIE`; a conformal rectangle's four sides) take the
    smallest rotation, and a square keeps its u."""
    corners = uv[ConvexHull(uv).vertices]
    edges = np.diff(np.r_[corners, corners[:1]], axis=0)
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    rotations = [np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) for a in angles]
    extents = np.array([np.ptp(corners @ rot.T, axis=0) for rot in rotations])
    areas = extents.prod(axis=1)
    tied = np.flatnonzero(areas <= areas.min() * (1 + TIE))
    best = min(tied, key=lambda k: (round(abs(float(angles[k])), 9), -float(angles[k])))
    rot, ext = rotations[best], extents[best]
    if ext[1] > ext[0] * (1 + TIE):
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

    def spans(x: float) -> int:
        """x rounded half to even, x a round-off (TIE) off a half counting as on it."""
        if abs(2 * x - round(2 * x)) <= TIE * x:
            x = round(2 * x) / 2
        return int(np.clip(round(x), lo, hi))

    return spans(math.sqrt(cells * aspect)), spans(math.sqrt(cells / aspect))


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
    coef = _solve_spd(lhs, a.T @ points)
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


def _in_units(spline: ca.Function, centre: np.ndarray, scale: float) -> ca.Function:
    """r (u, v) -> centre + scale * spline(u / scale, v / scale): a spline fitted in the unit
    frame (:func:`_frame`) in the shape's own units, its parameters lengths there too."""
    uv = ca.SX.sym("uv", 2)
    return ca.Function("mesh_r", [uv], [ca.DM(centre) + scale * spline(uv / scale)])
