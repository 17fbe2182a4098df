"""Point sets on and off a surface: the triangles of a parameter grid, the mean spacing of a
lattice, the diameter of a point set, and the memory bound on how many points one
evaluation may take (shapes in each function's docstring)."""

from __future__ import annotations

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from .. import memory
from ..errors import InputError, SurfaceError
from ..files import Key, check_value
from ..model.backend import finite_array, finite_result

#: Most parameter values along one direction of a grid or lattice (:meth:`Surface.grid_uv`,
#: :meth:`Surface.lattice_uv`, :func:`grid_faces`); how many points one evaluation may
#: take is bounded by the memory this machine has left (:func:`refuse_points`).
MAX_GRID = 100_000
#: Bytes per point and output row of an evaluation (the result, its copies), and the
#: size from which it is checked against the memory left (smaller ones do not read /proc).
_BYTES_PER_ENTRY, _MEMORY_CHECK_FROM = 32.0, 1e8
#: The count of a grid's parameter values along one direction.
GRID = Key("whole", low=2, high=MAX_GRID)


def refuse_points(count: float, rows: int, what: str) -> None:
    """Refuse (:class:`InputError`) an evaluation of ``rows`` numbers at each of ``count``
    points (``what``) that this machine cannot hold."""
    count = check_value(count, Key("number", low=0.0), "count")
    rows = check_value(rows, Key("whole", low=0, high=2**31), "rows")
    what = check_value(what, Key("string"), "what")
    need = _BYTES_PER_ENTRY * count * rows
    if need > _MEMORY_CHECK_FROM:
        memory.refuse_beyond(need, what, "use fewer points")


def grid_faces(n_u: int, n_v: int) -> np.ndarray:
    """Triangles of an (n_u, n_v) vertex grid (vertex (a, b) = a*n_v + b), two per cell:
    (a,b)-(a+1,b)-(a+1,b+1) and (a,b)-(a+1,b+1)-(a,b+1), both oriented like r_u x r_v.
    n_u, n_v are whole numbers in [2, :data:`MAX_GRID`]."""
    n_u, n_v = (check_value(n, GRID, k, SurfaceError) for n, k in ((n_u, "n_u"), (n_v, "n_v")))
    refuse_points(n_u * n_v, 12, f"the faces of a {n_u} x {n_v} grid")
    idx = np.arange(n_u * n_v).reshape(n_u, n_v)
    p, q, r, s = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tri = np.stack([np.stack([p, q, r], -1), np.stack([p, r, s], -1)], axis=2)
    return tri.reshape(-1, 3)


def mean_neighbour_distances(points: np.ndarray) -> tuple[float, float]:
    """Mean distance between lattice neighbours of (n, m, 3) points along i and along j."""
    points = finite_array(points, "points", shape=(None, None, 3))
    if min(points.shape[:2]) < 2:
        raise InputError(f"points must be a lattice of at least 2 x 2 points, got shape "
                         f"{points.shape}")
    with np.errstate(all="ignore"):
        d_i = np.linalg.norm(np.diff(points, axis=0), axis=-1)
        d_j = np.linalg.norm(np.diff(points, axis=1), axis=-1)
        means = float(d_i.mean()), float(d_j.mean())
    return finite_result(means, "the neighbour distances overflow: the points are too large "
                                "for floating point")


def point_set_diameter(points: np.ndarray) -> float:
    """Largest distance between two of the points (any shape (..., 3)).

    Only convex-hull vertices can realise it. A pair of farthest-point steps gives a lower
    bound d; with c the bounding-box centre and R the largest |p - c|, a point p can only be
    in a pair longer than d if |p - c| + R >= d, and the pairs of those points are compared
    in blocks. On a convex cap every sampled point is a hull vertex, so the pruning is what
    keeps it fast (measured against all pairs: docs/decisions/smaller.md).
    Raises :class:`InputError` unless the points are finite numbers of shape (..., 3).
    """
    pts = finite_array(points, "points", allowed="a finite array of shape (..., 3)")
    if pts.shape[-1:] != (3,):
        raise InputError(f"points must be a finite array of shape (..., 3), got shape "
                         f"{pts.shape}")
    with np.errstate(all="ignore"):
        return finite_result(_diameter_of(pts.reshape(-1, 3)), "the diameter overflows: the "
                             "points are too large for floating point")


def _diameter_of(pts: np.ndarray) -> float:
    if len(pts) > 50:
        try:
            pts = pts[ConvexHull(pts, qhull_options="QJ").vertices]
        except QhullError:    # degenerate (e.g. every point the same): compare them all
            pts = np.unique(pts, axis=0)
    if len(pts) < 2:
        return 0.0
    a = int(np.argmax(((pts - pts[0]) ** 2).sum(axis=1)))
    b = int(np.argmax(((pts - pts[a]) ** 2).sum(axis=1)))
    best = float(((pts[a] - pts[b]) ** 2).sum())
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    radius = np.linalg.norm(pts - centre, axis=1)
    cand = pts[radius + radius.max() >= np.sqrt(best) * (1 - 1e-12)]
    block = max(1, 1_000_000 // len(cand))
    for k in range(0, len(cand), block):
        sq = ((cand[k:k + block, None, :] - cand[None, :, :]) ** 2).sum(axis=-1)
        best = max(best, float(sq.max()))
    return float(np.sqrt(best))
