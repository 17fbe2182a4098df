"""The rectangle domain of a :class:`~rffqm_nlp.targets.meshes.Mesh` (step 3 of
:mod:`.meshes`): the largest axis-aligned rectangle inside the parameter image, found on a
raster over its bounding box; the region a point cloud samples (its triangulation)."""

from __future__ import annotations

import numpy as np
from matplotlib.path import Path as PolygonPath
from scipy.ndimage import binary_erosion
from scipy.spatial import Delaunay

from ..errors import SurfaceError

#: Raster nodes per direction for the inscribed rectangle.
RASTER = 200


def _raster(uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raster node coordinates (RASTER,) along u and along v over the bounding box of uv."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    return np.linspace(lo[0], hi[0], RASTER), np.linspace(lo[1], hi[1], RASTER)


def polygon_mask(polygon: np.ndarray) -> np.ndarray:
    """(RASTER, RASTER) mask of the raster nodes inside the polygon (b, 2)."""
    gu, gv = _raster(polygon)
    nodes = np.stack(np.meshgrid(gu, gv, indexing="ij"), -1).reshape(-1, 2)
    return PolygonPath(polygon).contains_points(nodes).reshape(RASTER, RASTER)


def cloud_faces(uv: np.ndarray) -> tuple[Delaunay, np.ndarray]:
    """The Delaunay triangulation of uv (n, 2) and the mask (m,) of the triangles kept: all
    but the long ones (longest edge above three times the median longest edge) that reach
    the outside through long ones, peeled from the convex hull inwards. That drops the
    long triangles spanning concave bays and gaps open to the outside, and keeps a long
    one inside, where a random sample left a sparse spot (dropped, it was a hole, and the
    cloud no disk)."""
    tri = Delaunay(uv)
    vertices = uv[tri.simplices]
    longest = np.linalg.norm(vertices - np.roll(vertices, 1, axis=1), axis=2).max(axis=1)
    long = longest > 3 * np.median(longest)
    dropped = np.zeros(len(long), dtype=bool)
    front = np.flatnonzero(long & (tri.neighbors == -1).any(axis=1))
    while front.size:
        dropped[front] = True
        near = tri.neighbors[front].ravel()
        near = np.unique(near[near >= 0])
        front = near[long[near] & ~dropped[near]]
    return tri, ~dropped


def cloud_mask(uv: np.ndarray) -> np.ndarray:
    """(RASTER, RASTER) mask of the raster nodes inside the region the cloud samples: in
    the triangles of :func:`cloud_faces`."""
    gu, gv = _raster(uv)
    tri, keep = cloud_faces(uv)
    keep = np.r_[keep, False]  # index -1 (outside) -> False
    nodes = np.stack(np.meshgrid(gu, gv, indexing="ij"), -1).reshape(-1, 2)
    return keep[tri.find_simplex(nodes)].reshape(RASTER, RASTER)


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
