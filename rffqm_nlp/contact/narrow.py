"""Narrow phase of the contact checks: exact distances and overlaps between panels.

* Exact distances, vectorised over pairs of triangles (each panel is two,
  :mod:`~rffqm_nlp.contact.panels`): an exact intersection test by separating axes (the
  two normals, the nine edge-edge cross products and the six in-plane edge normals, so
  the coplanar case is included), and for disjoint triangles the exact distance (the
  smallest of the nine segment-segment distances and the six vertex-face distances whose
  foot lies inside the face). The distance between two panels is the smallest of their
  four triangle pairs.
* Cheap lower bounds on those distances (:func:`lower_bound`): the bounding spheres' gap,
  how far one panel lies on one side of the other's plane, and the gap between the two
  panels' projections on the line through their centres.
* Flat overlaps: at omega = 0 every panel is a convex quadrilateral in the plane; two
  panels overlap when their interiors do (a separating-axis test on the eight edge
  normals, touching along an edge or at a corner is not an overlap).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InputError
from ..files import Key, check_value, describe_value
from ..model.backend import finite_array, finite_result
from ..model.pattern import Pattern
from .panels import Geometry, PanelPair, States
from .vectors import column_norm, cross, dot, least, least_of, most, most_of, norm

#: Separating-axis gaps below this times the pattern's scale count as touching.
REL_EPS = 1e-12

#: Triangle pairs per vectorised batch of the narrow phase (bounds its memory).
CHUNK = 4096

#: Corners (a, b, c, d) -> the triangles (a, c, d) and (a, d, b).
_TRIANGLES = np.array([[0, 2, 3], [0, 3, 1]])
#: Triangle index pairs (4, 2) of a panel pair.
_TRI_PAIRS = np.array([[0, 0], [0, 1], [1, 0], [1, 1]])


# --------------------------------------------------------------------------- panels

def panel_distance(geo: Geometry, S: np.ndarray, s: np.ndarray, p: np.ndarray,
                   q: np.ndarray) -> np.ndarray:
    """Distances (n,) between panels p and q (n,) in states S[s] (S: (K, V, 3)), 0 on
    contact. ``geo`` is the pattern (or the panel bookkeeping :func:`collisions` made of
    it), S holds states of its V vertices; every argument is checked
    (:class:`~rffqm_nlp.errors.InputError`)."""
    if isinstance(geo, Pattern):
        geo = Geometry(geo)
    if not isinstance(geo, Geometry):
        raise InputError(f"geo must be the crease pattern (rffqm_nlp.Pattern) of the "
                         f"states, got {describe_value(geo)}")
    V, P = (geo.N + 1) * (geo.M + 1), geo.N * geo.M
    S = finite_array(S, "S", shape=(None, V, 3), allowed=f"states (K, {V}, 3) of finite "
                     "numbers")
    s, p, q = (_indices(x, name, high) for x, name, high in
               ((s, "s", len(S)), (p, "p", P), (q, "q", P)))
    if not len(s) == len(p) == len(q):
        raise InputError(f"s, p and q must have one length, got {len(s)}, {len(p)} and "
                         f"{len(q)}")
    return finite_result(quad_distance(geo.quads(S, s, p), geo.quads(S, s, q), geo.scale),
                         "the panel distances are not finite (degenerate panels or "
                         "coordinates too large)")


def _indices(x: Any, name: str, high: int) -> np.ndarray:
    """A 1-D array of whole numbers in [0, high)."""
    arr = finite_array(x, name, ndim=1, allowed=f"a 1-D array of whole numbers in [0, {high})")
    if np.any(arr != np.round(arr)) or np.any(arr < 0) or np.any(arr >= high):
        raise InputError(f"{name} must be a 1-D array of whole numbers in [0, {high}), got "
                         f"values from {arr.min():g} to {arr.max():g}")
    return arr.astype(np.int64)


def quad_distance(P: np.ndarray, Q: np.ndarray, scale: float) -> np.ndarray:
    """Distances (n,) between the panels with corners P and Q (n, 4, 3) (a, b, c, d), 0 on
    contact: the smallest of their four triangle pairs; ``scale`` the pattern's extent
    (for :data:`REL_EPS`)."""
    TP = P[:, _TRIANGLES][:, _TRI_PAIRS[:, 0]]                      # (n, 4, 3, 3)
    TQ = Q[:, _TRIANGLES][:, _TRI_PAIRS[:, 1]]
    TP, TQ = TP.reshape(-1, 3, 3), TQ.reshape(-1, 3, 3)
    d = np.concatenate([_triangle_distance(TP[k:k + CHUNK], TQ[k:k + CHUNK], scale)
                        for k in range(0, len(TP), CHUNK)] or [np.zeros(0)])
    return least(d.reshape(-1, 4))


def distance(st: States, s: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Exact distances (n,) of panels p and q in states s (all (n,)) of ``st``."""
    return quad_distance(st.quads(s, p), st.quads(s, q), st.geo.scale)


def lower_bound(st: States, s: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Cheap lower bounds (n,) on the distances of panels p and q in states s (all (n,)):
    the largest of the bounding spheres' gap, the plane gap (how far one panel lies
    wholly on one side of the other's plane) and the gap between the panels' projections
    on the line through their centroids (a separating axis that certifies most pairs of
    nearly flat or nearly parallel neighbours). Computed row by row on the panel tables."""
    A, B = st.columns(s, p), st.columns(s, q)                        # fields (..., n)
    u = B.centre - A.centre
    dist = column_norm(u)
    lb = dist - A.radius - B.radius
    for F, G in ((A, B), (B, A)):                # G's corners over F's plane, from F's a
        n, a, c = F.normal, F.corners[:, 0], G.corners
        h = [n[0] * (c[0, k] - a[0]) + n[1] * (c[1, k] - a[1]) + n[2] * (c[2, k] - a[2])
             for k in range(4)]
        lb = np.maximum(lb, np.maximum(least_of(h), -most_of(h)))
    with np.errstate(divide="ignore", invalid="ignore"):
        u /= dist
    along = [[u[0] * F.corners[0, k] + u[1] * F.corners[1, k] + u[2] * F.corners[2, k]
              for k in range(4)] for F in (A, B)]
    gap = least_of(along[1]) - most_of(along[0])                   # along the centres
    return np.maximum(lb, np.where(dist > 0, gap, -np.inf))


# --------------------------------------------------------------------------- triangles

def _triangles(A: Any, B: Any, scale: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """The arguments of :func:`triangles_intersect` and :func:`triangle_distance` checked:
    triangles (n, 3, 3) of finite numbers, as many of each, and a scale > 0."""
    A = finite_array(A, "A", shape=(None, 3, 3), allowed="triangles (n, 3, 3) of finite "
                     "numbers")
    B = finite_array(B, "B", shape=(len(A), 3, 3), allowed=f"triangles ({len(A)}, 3, 3) of "
                     "finite numbers, as many as A")
    scale = check_value(scale, Key("number", low=0.0, low_open=True, hint="(a length)"),
                           "scale")
    return A, B, scale


def triangles_intersect(A: np.ndarray, B: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Whether closed triangles A and B (n, 3, 3) intersect, (n,) bool (separating axes).

    Tested axes (17): both normals, the nine edge-edge cross products and the in-plane
    normals of all six edges; gaps below REL_EPS * scale * |axis| count as touching.
    Raises :class:`~rffqm_nlp.errors.InputError` for arguments of other kinds or shapes.
    """
    with np.errstate(all="ignore"):
        return _triangles_intersect(*_triangles(A, B, scale))


def _triangles_intersect(A: np.ndarray, B: np.ndarray, scale: float) -> np.ndarray:
    eA = np.roll(A, -1, axis=1) - A
    eB = np.roll(B, -1, axis=1) - B
    nA = cross(eA[:, 0], eA[:, 1])
    nB = cross(eB[:, 0], eB[:, 1])
    hit = ~_separated(np.stack([nA, nB], axis=1), A, B, scale).any(axis=1)
    k = np.flatnonzero(hit)                  # the normals do not separate: the other 15
    if k.size:
        eA, eB, nA, nB = eA[k], eB[k], nA[k], nB[k]
        axes = np.concatenate([cross(eA[:, :, None], eB[:, None, :]).reshape(-1, 9, 3),
                               cross(nA[:, None], eA), cross(nB[:, None], eB)], axis=1)
        hit[k] = ~_separated(axes, A[k], B[k], scale).any(axis=1)
    return hit


def _separated(axes: np.ndarray, A: np.ndarray, B: np.ndarray, scale: float) -> np.ndarray:
    """Whether each axis (n, k, 3) separates triangles A and B (n, 3, 3) by more than
    REL_EPS * scale * |axis|: (n, k) bool."""
    pA = dot(axes[:, :, None], A[:, None])                           # (n, k, 3)
    pB = dot(axes[:, :, None], B[:, None])
    eps = REL_EPS * scale * norm(axes)
    gap = np.maximum(least(pB) - most(pA), least(pA) - most(pB))
    return gap > eps


def triangle_distance(A: np.ndarray, B: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Euclidean distances (n,) between closed triangles A and B (n, 3, 3), 0 if they meet.

    Raises :class:`~rffqm_nlp.errors.InputError` for arguments of other kinds or shapes, and
    for degenerate triangles (corners on a line) or coordinates too large for floating
    point, where the distances computed here are not finite."""
    A, B, scale = _triangles(A, B, scale)
    with np.errstate(all="ignore"):
        d = _triangle_distance(A, B, scale)
    return finite_result(d, "triangle_distance has no finite value: a triangle is degenerate "
                            "(its corners on a line) or its coordinates are too large")


def _triangle_distance(A: np.ndarray, B: np.ndarray, scale: float) -> np.ndarray:
    if len(A) == 0:
        return np.zeros(0)
    eA = np.roll(A, -1, axis=1)
    eB = np.roll(B, -1, axis=1)
    seg = _segment_distance(A[:, :, None], eA[:, :, None], B[:, None, :], eB[:, None, :])
    d = least(seg.reshape(-1, 9))
    d = np.minimum(d, least(_vertex_face_distance(A, B)))
    d = np.minimum(d, least(_vertex_face_distance(B, A)))
    return np.where(_triangles_intersect(A, B, scale), 0.0, d)


def _segment_distance(P1, Q1, P2, Q2) -> np.ndarray:
    """Distances between segments [P1, Q1] and [P2, Q2] (broadcast (..., 3)) (Ericson 5.1.9)."""
    d1, d2, r = Q1 - P1, Q2 - P2, P1 - P2
    a = dot(d1, d1)
    e = dot(d2, d2)
    b = dot(d1, d2)
    c = dot(d1, r)
    f = dot(d2, r)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-14 * a * e, np.clip((b * f - c * e) / denom, 0, 1), 0.0)
        t = (b * s + f) / e
        s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    return norm(r + d1 * s[..., None] - d2 * t[..., None])


def _vertex_face_distance(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Distances (n, 3) from the vertices of A to the plane of B where the foot lies in B,
    inf elsewhere (the other closest features are covered by segment distances)."""
    n = cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    nn = norm(n)
    inside = np.ones(A.shape[:2], dtype=bool)
    for k in range(3):
        edge = B[:, (k + 1) % 3] - B[:, k]
        inside &= dot(cross(edge[:, None], A - B[:, k, None]), n[:, None]) >= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.abs(dot(A - B[:, 0, None], n[:, None])) / nn[:, None]
    return np.where(inside & (nn[:, None] > 0), h, np.inf)


# --------------------------------------------------------------------------- flat state

def flat_overlaps(geo: Geometry) -> list[PanelPair]:
    """Pairs of panels whose interiors overlap in the flat pattern (omega = 0): a
    separating-axis test on the eight edge normals of the pairs whose circumscribed discs
    overlap, row by row on a table (2, 4, P) of the corners' x and y (a, c, d, b around)."""
    X = geo.pat.X.reshape(-1, 3)
    R = np.ascontiguousarray(X[geo.corners[:, [0, 2, 3, 1]], :2].transpose(2, 1, 0))
    C = np.stack([R[0].sum(axis=0), R[1].sum(axis=0)], axis=1) / 4
    pq = cKDTree(C).query_pairs(2 * geo.radius.max(), output_type="ndarray").reshape(-1, 2)
    d = C[pq[:, 0]] - C[pq[:, 1]]                                   # circumscribed discs
    pq = pq[np.hypot(d[:, 0], d[:, 1]) <= geo.radius[pq[:, 0]] + geo.radius[pq[:, 1]]]
    (Ax, Ay), (Bx, By) = R.take(pq[:, 0], axis=2), R.take(pq[:, 1], axis=2)   # (4, n) each
    hit = np.ones(len(pq), dtype=bool)
    for Fx, Fy in ((Ax, Ay), (Bx, By)):
        for k in range(4):
            ax, ay = Fy[k] - Fy[(k + 1) % 4], Fx[(k + 1) % 4] - Fx[k]         # edge normal
            pA = [ax * Ax[i] + ay * Ay[i] for i in range(4)]
            pB = [ax * Bx[i] + ay * By[i] for i in range(4)]
            gap = np.maximum(least_of(pB) - most_of(pA), least_of(pA) - most_of(pB))
            hit &= gap <= -1e-9 * geo.scale * np.hypot(ax, ay)
    return sorted(geo.label(p, q) for p, q in pq[hit])
