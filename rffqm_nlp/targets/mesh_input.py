"""What a :class:`~rffqm_nlp.targets.meshes.Mesh` takes in (step 1 of :mod:`.meshes`): a
file of the :data:`FORMATS`, a ``trimesh`` object, a ``(V, F)`` pair or a point array, read
from its bytes alone, bounded before any work on it, moved into its unit frame
(:func:`_frame`) and cleaned; trimesh's own messages and log records never reach the user."""

from __future__ import annotations

import contextlib
import io
import logging
import math
import stat
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..errors import RffqmError, SurfaceError

#: Fewest points of a point cloud.
MIN_POINTS = 20
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


def is_mesh_file(path: str | Path) -> bool:
    """Whether ``path``'s suffix names a format trimesh reads (OBJ, STL, PLY, OFF, GLB,
    XYZ, ...), case-insensitively. Of those, a :class:`Mesh` reads the :data:`FORMATS`
    and refuses the others (archives, drawings) in one line."""
    return Path(path).suffix.lower().lstrip(".") in trimesh.available_formats()


@contextlib.contextmanager
def quiet_trimesh() -> Iterator[None]:
    """trimesh's log records (which may quote a file's content) silenced for the block."""
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


@contextlib.contextmanager
def trimesh_step(what: str, step: str) -> Iterator[None]:
    """trimesh's work on the shape, quiet; any failure inside becomes one SurfaceError line
    naming the step, never trimesh's own text (it may quote the file)."""
    with quiet_trimesh():
        try:
            yield
        except (RffqmError, MemoryError):
            raise
        except Exception:
            raise SurfaceError(f"{what} could not be processed (trimesh failed while {step}); "
                               f"repair the mesh (e.g. in MeshLab or Blender) or export it "
                               f"again") from None


def load(source: Any, what: str) -> tuple[trimesh.Trimesh | np.ndarray, np.ndarray, float]:
    """(the cleaned mesh or the cloud's points (n, 3), in the unit frame; the frame's centre
    (3,) and scale (:func:`_frame`)) from any accepted source, its size bounded
    (:func:`_check_size`) before any work on it."""
    if isinstance(source, (str, Path)):
        source = _read(Path(source))
    if isinstance(source, trimesh.Scene):
        _check_scene_size(source, what)
        with trimesh_step(what, "joining the file's pieces"):
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
    with quiet_trimesh():
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
    with trimesh_step(what, "reading the file's pieces"):
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
    """(the :func:`clean` mesh in the unit frame of its used vertices, the frame's centre,
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
    return clean((pts - centre) / scale, tri, what), centre, scale


def clean(vertices: Any, faces: Any, what: str) -> trimesh.Trimesh:
    """The mesh with vertices merged (within trimesh's 1e-8: give it in the unit frame),
    degenerate and duplicate faces and unused vertices removed."""
    pts = _finite_points(vertices, what)
    tri = _triangles(faces, len(pts), what)
    with trimesh_step(what, "merging its vertices"):
        mesh = trimesh.Trimesh(vertices=pts, faces=tri, process=False)
        mesh.merge_vertices(merge_tex=True, merge_norm=True)
        mesh.update_faces(mesh.nondegenerate_faces())
        mesh.update_faces(mesh.unique_faces())
        mesh.remove_unreferenced_vertices()
    if len(mesh.faces) == 0:
        raise SurfaceError(f"{what} has no non-degenerate triangles; give a triangle mesh of "
                           f"the surface")
    return mesh
