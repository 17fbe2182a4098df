"""FOLD 1.2 files: the numbering of vertices, edges and faces, writing, reading, validating.

Numbering (shared with the crease and mesh writers of :mod:`rffqm_nlp.io.export`): vertex
(i, j) (1-based) is FOLD vertex ``(i-1)(M+1) + (j-1)``; the edges are the horizontal edges
(i, j) -> (i, j+1) row by row, then the vertical edges (i, j) -> (i+1, j) row by row; the
faces are the panels (i, j) row by row, counter-clockwise a, c, d, b in the flat pattern.
Boundary edges are "B"; a crease is a valley "V" when its fold angle at the designed state
is positive, else a mountain "M" (at omega = 0 the signs of the positive folding branch are
used).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._version import __version__
from ..errors import InputError
from ..files import describe_value, jsonable, read_json, write_json
from ..model.marching import fold, fold_angles
from ..model.pattern import Pattern, check_fold_angle, check_omega, motion_omegas
from ..design.checks import PATTERN_KEYS, REMARCH_RTOL, check_numbers, checked_pattern

CREATOR = "rffqm-nlp"
PREFIX = "rffqm:"
ASSIGNMENTS = frozenset("BMVFU")
_RESERVED = ("omega", "pattern", "version")
_ANGLE_TOL = 1e-9
#: Largest size of a coordinate in a file of 64-bit floats (FOLD, SVG, PDF, DXF, OBJ) and
#: in one of 32-bit floats (PLY, GLB).
FLOAT64_MAX = float(np.finfo(np.float64).max)
FLOAT32_MAX = float(np.finfo(np.float32).max)


# --------------------------------------------------------------------------- finite output
def finite_pattern(pat: Any) -> Pattern:
    """``pat`` when it is a :class:`Pattern` whose every array is finite, else
    :class:`InputError` (one line): nothing is drawn or written from NaN or infinity."""
    if not isinstance(pat, Pattern):
        raise InputError(f"expected a Pattern, got {type(pat).__name__}")
    for name in PATTERN_KEYS:
        if not np.all(np.isfinite(getattr(pat, name))):
            raise InputError(f"the pattern's {name} holds NaN or inf; only a finite pattern "
                             "is drawn or written")
    return pat


def check_coordinates(values: Any, what: str, limit: float = FLOAT64_MAX,
                      number: str = "a 64-bit float") -> np.ndarray:
    """``values`` as a float array when every value is finite and at most ``limit`` in size
    (the largest ``number``, the file's number type, holds: :data:`FLOAT64_MAX`,
    :data:`FLOAT32_MAX`), else :class:`InputError` (one line) naming ``what``."""
    with np.errstate(all="ignore"):
        arr = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{what} hold NaN or inf (an overflow, or a pattern that is not "
                         "finite); scale the pattern's side lengths down")
    largest = float(np.abs(arr).max(initial=0.0))
    if largest > limit:
        raise InputError(f"{what} reach {largest:.3g}, more than {number} holds "
                         f"({limit:.3g}); scale the pattern's side lengths down")
    return arr


# --------------------------------------------------------------------------- numbering
def vertex_index(N: int, M: int) -> np.ndarray:
    """FOLD index of every vertex, (N+1, M+1)."""
    return np.arange((N + 1) * (M + 1)).reshape(N + 1, M + 1)


def edges_vertices(N: int, M: int) -> np.ndarray:
    """Vertex pairs of the horizontal then the vertical edges, ((N+1)M + N(M+1), 2)."""
    v = vertex_index(N, M)
    horizontal = np.stack([v[:, :-1], v[:, 1:]], axis=-1).reshape(-1, 2)
    vertical = np.stack([v[:-1, :], v[1:, :]], axis=-1).reshape(-1, 2)
    return np.concatenate([horizontal, vertical])


def faces_vertices(N: int, M: int) -> np.ndarray:
    """Corners a, c, d, b of every panel (counter-clockwise in the flat pattern), (NM, 4)."""
    v = vertex_index(N, M)
    return np.stack([v[:-1, :-1], v[:-1, 1:], v[1:, 1:], v[1:, :-1]], axis=-1).reshape(-1, 4)


def _boundary_mask(N: int, M: int) -> np.ndarray:
    """True for the boundary edges, in the edge order of :func:`edges_vertices`."""
    h = np.zeros((N + 1, M), bool)
    h[[0, -1], :] = True
    v = np.zeros((N, M + 1), bool)
    v[:, [0, -1]] = True
    return np.concatenate([h.ravel(), v.ravel()])


def edge_fold_angles(pat: Pattern, omega: float) -> np.ndarray:
    """Fold angle (radians, gamma > 0 valley, 0 on boundary edges) of every edge at ``omega``;
    :class:`InputError` for a pattern or angles that are not finite."""
    gh, gv = fold_angles(finite_pattern(pat), omega)
    return check_coordinates(np.concatenate([gh.ravel(), gv.ravel()]),
                             f"the fold angles at omega {float(omega):g}")


def edge_assignments(pat: Pattern, omega: float) -> np.ndarray:
    """Assignment "B", "M" or "V" of every edge: the sign of its fold angle at ``omega``.

    At omega = 0 every crease is flat; the signs at omega = pi/2 (the same on the whole
    positive branch, tan(gamma/2) = k tan(omega/2)) are used instead.
    """
    om = check_fold_angle(omega)
    gamma = edge_fold_angles(pat, om if om != 0.0 else np.pi / 2)
    kinds = np.where(gamma > 0, "V", "M")
    kinds[_boundary_mask(pat.N, pat.M)] = "B"
    return kinds


# --------------------------------------------------------------------------- FOLD
def frame_omegas(omega: float, frames: int | np.ndarray | None) -> np.ndarray:
    """The omegas of the folding frames: none, ``frames`` values from 0 to ``omega``
    (:func:`~rffqm_nlp.model.pattern.motion_omegas`) or the explicit omegas ``frames``."""
    if frames is None:
        return np.zeros(0)
    if isinstance(frames, (int, np.integer)):
        return motion_omegas(omega, frames)
    return np.atleast_1d(check_omega(frames))


def fold_dict(pat: Pattern, omega: float, frames: int | np.ndarray | None = None,
              metadata: Mapping[str, Any] | None = None) -> dict:
    """The FOLD 1.2 dictionary of ``pat`` designed to be folded to ``omega``.

    The key frame is the flat crease pattern (2-D coordinates, assignments and fold angles
    in degrees at ``omega``, FOLD's signs: valley positive). ``frames`` (a count K of
    states from 0 to omega, or an array of omegas) adds ``file_frames``: each state's folded
    3-D coordinates, assignments and fold angles, and its ``rffqm:omega``. The design data are
    stored under the ``rffqm:`` prefix: ``rffqm:omega``, ``rffqm:pattern``
    (:meth:`Pattern.to_dict`) and every key of ``metadata`` as ``rffqm:<key>``.
    """
    if not isinstance(pat, Pattern):
        raise InputError(f"fold_dict expects a Pattern, got {type(pat).__name__}")
    finite_pattern(pat)
    om = check_fold_angle(omega)
    d: dict[str, Any] = {
        "file_spec": 1.2,
        "file_creator": CREATOR,
        "file_classes": ["singleModel"],
        "frame_title": f"RFFQM crease pattern, {pat.N} x {pat.M} panels",
        "frame_classes": ["creasePattern"],
        "frame_attributes": ["2D"],
        "vertices_coords": pat.X[..., :2].reshape(-1, 2).tolist(),
        "edges_vertices": edges_vertices(pat.N, pat.M).tolist(),
        "edges_assignment": edge_assignments(pat, om).tolist(),
        "edges_foldAngle": np.degrees(edge_fold_angles(pat, om)).tolist(),
        "faces_vertices": faces_vertices(pat.N, pat.M).tolist(),
    }
    omegas = frame_omegas(om, frames)
    if omegas.size:
        Y = check_coordinates(fold(pat, omegas), "the folded coordinates of the frames")
        d["file_frames"] = [{
            "frame_classes": ["foldedForm"],
            "frame_attributes": ["3D"],
            "frame_parent": 0,
            "frame_inherit": True,
            "vertices_coords": y.reshape(-1, 3).tolist(),
            "edges_assignment": edge_assignments(pat, w).tolist(),
            "edges_foldAngle": np.degrees(edge_fold_angles(pat, w)).tolist(),
            PREFIX + "omega": float(w),
        } for w, y in zip(omegas, Y)]
    d[PREFIX + "version"] = __version__
    d[PREFIX + "omega"] = om
    d[PREFIX + "pattern"] = pat.to_dict()
    for key, value in (metadata or {}).items():
        if key in _RESERVED:
            raise InputError(f"metadata key {key!r} is reserved; choose another name")
        d[PREFIX + str(key)] = jsonable(value)
    check_numbers({k: v for k, v in d.items() if k.startswith(PREFIX)}, "the FOLD metadata")
    return d


def write_fold(path: str | os.PathLike, pat: Pattern, omega: float,
               frames: int | np.ndarray | None = None,
               metadata: Mapping[str, Any] | None = None) -> Path:
    """Write :func:`fold_dict` as a ``.fold`` JSON file (atomically); returns the path.
    A pattern, coordinates, fold angles or metadata that are not finite (or an integer too
    large for a float) are refused in one :class:`InputError` line, and nothing is
    written."""
    try:
        d = fold_dict(pat, omega, frames, metadata)
    except InputError as exc:
        raise InputError(f"cannot write {path}: {exc}") from None
    return write_json(path, d, indent=1)


def _array(d: Mapping, key: str, problems: list[str], dtype=float) -> np.ndarray | None:
    """``d[key]`` as a rectangular array of numbers (of whole numbers for ``dtype`` int), or
    None (with a problem) when it is not one: strings, booleans and integers too large for
    the type are never converted."""
    whole = dtype is int
    try:
        arr = np.array(d[key])
    except (TypeError, ValueError, OverflowError):
        arr = None
    if arr is None or arr.dtype.kind not in ("iu" if whole else "iuf"):
        problems.append(f"{key} is not a rectangular array of "
                        f"{'whole numbers' if whole else 'numbers'}")
        return None
    return arr.astype(dtype)


def _signed_areas(xy: np.ndarray, faces: list) -> np.ndarray:
    """Shoelace signed area of every face polygon."""
    out = []
    for f in faces:
        p = xy[np.asarray(f)]
        q = np.roll(p, -1, axis=0)
        out.append(0.5 * np.sum(p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]))
    return np.array(out)


def _check_edges(d: Mapping, nv: int, problems: list[str]) -> tuple[int, np.ndarray | None]:
    """Check edges_vertices and the per-edge data; (edge count, assignments or None)."""
    ev = _array(d, "edges_vertices", problems, dtype=int)
    if ev is None:
        return 0, None
    if ev.ndim != 2 or ev.shape[1] != 2:
        problems.append(f"edges_vertices must be a list of vertex pairs, got shape {ev.shape}")
        return 0, None
    if ev.size and (ev.min() < 0 or ev.max() >= nv):
        problems.append(f"edges_vertices has indices outside [0, {nv})")
    if np.any(ev[:, 0] == ev[:, 1]):
        problems.append("edges_vertices has an edge from a vertex to itself")
    return len(ev), _check_edge_data(d, len(ev), None, "", problems)


def _check_edge_data(d: Mapping, ne: int, inherited: np.ndarray | None, where: str,
                     problems: list[str]) -> np.ndarray | None:
    """Check edges_assignment and edges_foldAngle of the key frame or of a frame (``where``
    prefixes the messages); returns the assignments in force (own or ``inherited``)."""
    asg = inherited
    if "edges_assignment" in d:
        own = d["edges_assignment"]
        asg = None
        if not isinstance(own, list) or len(own) != ne:
            problems.append(f"{where}edges_assignment must list one assignment per edge ({ne})")
        elif bad := [k for k, a in enumerate(own)
                     if not (isinstance(a, str) and a in ASSIGNMENTS)]:
            problems.append(f"{where}edges_assignment has values outside "
                            f"{sorted(ASSIGNMENTS)}: edge {bad[0]} holds "
                            f"{describe_value(own[bad[0]])} ({len(bad)} edges)")
        else:
            asg = np.array(own)
    if "edges_foldAngle" in d:
        ang = _array(d, "edges_foldAngle", problems)
        if ang is not None and ang.shape != (ne,):
            problems.append(f"{where}edges_foldAngle must list one angle per edge ({ne})")
        elif ang is not None:
            if not np.all(np.isfinite(ang)):
                problems.append(f"{where}edges_foldAngle has non-finite angles")
                return asg
            if not np.all(np.abs(ang) <= 180):
                problems.append(f"{where}edges_foldAngle has angles outside [-180, 180] degrees")
            if asg is not None:
                _check_angle_signs(asg, ang, where, problems)
    return asg


def _check_angle_signs(asg: np.ndarray, ang: np.ndarray, where: str,
                       problems: list[str]) -> None:
    """FOLD's convention: valley >= 0, mountain <= 0, boundary and flat exactly 0."""
    rules = {"V": ang < -_ANGLE_TOL, "M": ang > _ANGLE_TOL, "B": np.abs(ang) > _ANGLE_TOL,
             "F": np.abs(ang) > _ANGLE_TOL}
    for kind, bad in rules.items():
        idx = np.flatnonzero((asg == kind) & bad)
        if idx.size:
            problems.append(f"{where}edges_foldAngle disagrees with assignment {kind!r} at edge "
                            f"{int(idx[0])} ({idx.size} edges)")


def _check_faces(d: Mapping, coords: np.ndarray, problems: list[str]) -> None:
    faces = d["faces_vertices"]
    nv = len(coords)
    if not isinstance(faces, list) or not all(isinstance(f, list) for f in faces):
        problems.append("faces_vertices must be a list of vertex lists")
        return
    if any(len(f) < 3 or not all(isinstance(k, int) and not isinstance(k, bool) for k in f)
           for f in faces):
        problems.append("faces_vertices must list at least three integer vertex indices per face")
        return
    if any(k < 0 or k >= nv for f in faces for k in f):
        problems.append(f"faces_vertices has indices outside [0, {nv})")
        return
    area = _signed_areas(coords[:, :2], faces)
    cw = np.flatnonzero(area <= 0)
    if cw.size:
        problems.append(f"faces_vertices: face {int(cw[0])} is not counter-clockwise "
                        f"({cw.size} faces)")


def _check_frames(d: Mapping, nv: int, ne: int, asg: np.ndarray | None,
                  problems: list[str]) -> None:
    """Check every frame's parent, vertex count and per-edge data (assignments inherited)."""
    frames = d["file_frames"]
    if not isinstance(frames, list) or not all(isinstance(f, dict) for f in frames):
        problems.append("file_frames must be a list of frame objects")
        return
    for k, frame in enumerate(frames, start=1):
        where = f"file_frames[{k - 1}]: "
        parent = frame.get("frame_parent", 0)
        if (not isinstance(parent, int) or isinstance(parent, bool)
                or not 0 <= parent <= len(frames) or parent == k):
            problems.append(f"{where}frame_parent ({describe_value(parent)}) is not another "
                            "frame")
        if "vertices_coords" in frame:
            xyz = _array(frame, "vertices_coords", [])
            if xyz is None:
                problems.append(f"{where}vertices_coords is not a rectangular array of numbers")
            elif xyz.ndim != 2 or xyz.shape[0] != nv:
                problems.append(f"{where}vertices_coords has shape {xyz.shape}, the key "
                                f"frame {nv} vertices")
            elif not np.all(np.isfinite(xyz)):
                problems.append(f"{where}vertices_coords has non-finite coordinates")
        if ne:
            _check_edge_data(frame, ne, asg, where, problems)


def validate_fold(d: Any) -> list[str]:
    """Structural problems of a FOLD dictionary ([] when none).

    Checks the required keys, vertex coordinates (2-D or 3-D, finite), edge and face index
    ranges, per-edge list lengths, assignments in {B, M, V, F, U}, fold angles agreeing with
    the assignments (valley >= 0, mountain <= 0, boundary and flat 0), faces
    counter-clockwise by the signed area of the flat coordinates, and every frame's parent,
    vertex count and per-edge data (assignments inherited from the key frame).
    """
    if not isinstance(d, Mapping):
        return [f"a FOLD file holds a JSON object, got {type(d).__name__}"]
    required = ("file_spec", "vertices_coords", "edges_vertices", "edges_assignment",
                "faces_vertices")
    problems = [f"missing key {k!r}" for k in required if k not in d]
    if "vertices_coords" not in d:
        return problems
    coords = _array(d, "vertices_coords", problems)
    if coords is None:
        return problems
    if coords.ndim != 2 or coords.shape[1] not in (2, 3) or len(coords) == 0:
        problems.append(f"vertices_coords must be a list of 2-D or 3-D points, "
                        f"got shape {coords.shape}")
        return problems
    if not np.all(np.isfinite(coords)):
        problems.append("vertices_coords has non-finite coordinates")
    ne, asg = _check_edges(d, len(coords), problems) if "edges_vertices" in d else (0, None)
    if "faces_vertices" in d:
        _check_faces(d, coords, problems)
    if "file_frames" in d:
        _check_frames(d, len(coords), ne, asg, problems)
    return problems


def read_fold(path: str | os.PathLike) -> tuple[Pattern, float, dict]:
    """Read a FOLD file written by :func:`write_fold`: (pattern, omega, metadata).

    ``metadata`` holds the ``rffqm:`` keys of the file other than omega, pattern and
    version, without the prefix. The design data are checked as a saved result's are:
    no number anywhere NaN, infinite or too large for a float
    (:func:`rffqm_nlp.design.checks.check_numbers`), ``rffqm:pattern`` admissible and equal to
    its boundary data re-marched with the NumPy model
    (:func:`rffqm_nlp.design.checks.checked_pattern`), ``rffqm:omega`` in [-pi, pi], and the
    flat coordinates those of the pattern. Raises :class:`InputError` (one line, never
    quoting the file's content) for a file that is not valid JSON (or no regular file: a
    folder, a FIFO, a device), not a FOLD file, not written by this package, or whose
    design data fail these checks.
    """
    path = Path(path)
    d = read_json(path, "FOLD file")
    if isinstance(d, Mapping):
        check_numbers(d, str(path))
    problems = validate_fold(d)
    if problems:
        raise InputError(f"{path} is not a valid FOLD file: " + "; ".join(problems))
    if d.get("file_creator") != CREATOR or PREFIX + "pattern" not in d:
        raise InputError(f"{path} is a FOLD file but not one written by {CREATOR} "
                         f"(file_creator {describe_value(d.get('file_creator'))}, no "
                         "'rffqm:pattern'); "
                         "only files from write_fold carry the design data")
    pat = checked_pattern(d[PREFIX + "pattern"], str(path), where=PREFIX + "pattern")
    if PREFIX + "omega" not in d:
        raise InputError(f"{path}: the key 'rffqm:omega' is missing")
    try:
        omega = check_omega(d[PREFIX + "omega"], PREFIX + "omega")
    except InputError as exc:
        raise InputError(f"{path}: {exc}") from None
    if omega.ndim:
        raise InputError(f"{path}: rffqm:omega must be one number in [-pi, pi], got a list")
    omega = float(omega)
    xy = np.asarray(d["vertices_coords"], dtype=float)
    flat = pat.X[..., :2].reshape(-1, 2)
    scale = max(float(np.abs(flat).max(initial=0.0)), 1e-300)
    if (xy.shape != flat.shape
            or float(np.abs(xy - flat).max(initial=0.0)) > REMARCH_RTOL * scale):
        raise InputError(f"{path}: vertices_coords do not match 'rffqm:pattern'; the file "
                         "was edited after it was written")
    meta = {k[len(PREFIX):]: v for k, v in d.items()
            if k.startswith(PREFIX) and k[len(PREFIX):] not in _RESERVED}
    return pat, omega, meta
