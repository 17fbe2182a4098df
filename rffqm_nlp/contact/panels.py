"""The panels of a pattern for the contact checks, and their table along the motion.

Panels are rigid and planar: panel (i, j) with corners a = (i, j), b = (i+1, j),
c = (i, j+1), d = (i+1, j+1) is exactly the two triangles (a, c, d) and (a, d, b). They are
numbered p = (i-1) M + (j-1). :class:`Geometry` holds what does not change as the pattern
folds (corner indices, radii, the scale); :class:`States` the folded states visited along
the motion, each as a table of its panels read through the named fields of
:class:`Panels` (corners, centroid, unit normal, radius).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..model.numpy_model import fold
from ..model.pattern import Pattern

PanelPair = tuple[tuple[int, int], tuple[int, int]]

#: The fields of a panel's table, in its row order, and the shape of each per panel:
#: ``corners[c, k]`` the coordinate c of corner k (a, b, c, d), the centroid, the unit
#: normal, the radius (the distance from the centroid to the farthest corner).
FIELDS = {"corners": (3, 4), "centre": (3,), "normal": (3,), "radius": ()}


def _spans() -> dict[str, slice]:
    """The rows of each of :data:`FIELDS` in a table."""
    spans, at = {}, 0
    for name, shape in FIELDS.items():
        size = int(np.prod(shape))
        spans[name], at = slice(at, at + size), at + size
    return spans


_SPANS = _spans()
#: Rows of a panel table (19).
WIDTH = _SPANS["radius"].stop


@dataclass(frozen=True, eq=False)
class Panels:
    """The named fields of panel tables (..., WIDTH, n), n panels: ``corners``
    (..., 3, 4, n), ``centre`` and ``normal`` (..., 3, n), ``radius`` (..., n)
    (:data:`FIELDS`). Made by :meth:`of` as views of the table, so writing a field writes
    the table."""

    corners: np.ndarray
    centre: np.ndarray
    normal: np.ndarray
    radius: np.ndarray

    @classmethod
    def of(cls, table: np.ndarray) -> Panels:
        """The fields of ``table`` (..., WIDTH, n), as views (no copy)."""
        lead, n = table.shape[:-2], table.shape[-1]
        return cls(**{name: table[..., _SPANS[name], :].reshape(*lead, *shape, n)
                      for name, shape in FIELDS.items()})


class Geometry:
    """Panel bookkeeping of a pattern: corner indices, sizes, the folded states.

    ``ij`` (P, 2) the 0-based (i - 1, j - 1) of each panel; ``corners`` (P, 4) the flat
    vertex indices of a, b, c, d; ``radius`` (P,) the distance from a panel's centroid to
    its farthest corner (constant: panels are rigid), ``median_radius`` their median;
    ``scale`` the flat pattern's largest extent.
    """

    def __init__(self, pat: Pattern):
        self.pat, self.N, self.M = pat, pat.N, pat.M
        i, j = np.divmod(np.arange(self.N * self.M), self.M)
        a = i * (self.M + 1) + j
        self.ij = np.stack([i, j], axis=1)
        self.corners = np.stack([a, a + self.M + 1, a + 1, a + self.M + 2], axis=1)
        X = pat.X.reshape(-1, 3)
        Q = X[self.corners]
        self.radius = np.linalg.norm(Q - Q.mean(axis=1, keepdims=True), axis=2).max(axis=1)
        self.median_radius = float(np.median(self.radius))
        self.scale = float(np.ptp(X, axis=0).max()) or 1.0

    def states(self, omegas: np.ndarray) -> np.ndarray:
        """Folded vertex positions (K, (N+1)(M+1), 3) at the omegas (K,)."""
        return fold(self.pat, omegas).reshape(len(omegas), -1, 3)

    def centres(self, Y: np.ndarray) -> np.ndarray:
        """Panel centroids (..., P, 3) of states Y (..., V, 3)."""
        Q = Y[..., self.corners, :]
        return (Q[..., 0, :] + Q[..., 1, :] + Q[..., 2, :] + Q[..., 3, :]) / 4

    def quads(self, S: np.ndarray, s: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Corners (n, 4, 3) of panels p in states S[s] (S: (K, V, 3); s, p: (n,))."""
        return S[s[:, None], self.corners[p]]

    def label(self, p: int, q: int) -> PanelPair:
        """1-based panel pair, smaller panel first."""
        a, b = sorted((int(p), int(q)))
        return ((a // self.M + 1, a % self.M + 1), (b // self.M + 1, b % self.M + 1))


class States:
    """The folded states visited along the motion, grown as steps are halved.

    ``omegas``: their |omega| (a list, K entries). Each state's panel table holds one row
    per quantity and one column per panel (gathers by row are several times faster than
    by panel), read by field (:class:`Panels`): :meth:`panels` for one state,
    :meth:`columns` and :meth:`field` for panels of several states; beside it a table of
    the panels' frames (:meth:`frames`). The storage doubles as states are added (halving
    steps adds a few states at a time).
    """

    def __init__(self, geo: Geometry, sign: float, omegas: np.ndarray):
        self.geo, self.sign, self.omegas, self._at = geo, sign, [], {}
        self._T = np.zeros((0, WIDTH, geo.N * geo.M))
        self._F = np.zeros((0, 9, geo.N * geo.M))
        self.add(omegas)

    def panels(self, k: int) -> Panels:
        """The fields (each (..., P)) of every panel in state k."""
        return Panels.of(self._T[k])

    def index(self, omegas: np.ndarray) -> np.ndarray:
        """The states' indices (k,) at the |omega| values (k,), those not held yet folded
        and added."""
        new = [w for w in dict.fromkeys(np.asarray(omegas, dtype=float).tolist())
               if w not in self._at]
        if new:
            self.add(np.array(new))
        return np.array([self._at[w] for w in np.asarray(omegas, dtype=float).tolist()],
                        dtype=np.int64)

    def add(self, omegas: np.ndarray) -> None:
        """Fold the pattern at the |omega| values (k,) and append those states."""
        omegas = np.asarray(omegas, dtype=float)
        K, k = len(self.omegas), len(omegas)
        if K + k > len(self._T):
            self._T, self._F = (_grown(T, K, K + k) for T in (self._T, self._F))
        Y = np.ascontiguousarray(self.geo.states(self.sign * omegas).transpose(0, 2, 1))
        T = Panels.of(self._T[K:K + k])                                  # Y: (k, 3, V)
        T.corners[...] = Y.take(self.geo.corners.T, axis=2)              # (k, 3, 4, P)
        X = T.corners
        T.centre[...] = (X[:, :, 0] + X[:, :, 1] + X[:, :, 2] + X[:, :, 3]) / 4
        u, v = X[:, :, 3] - X[:, :, 0], X[:, :, 2] - X[:, :, 1]          # (k, 3, P)
        n = np.stack([u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                      u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]], axis=1)
        T.normal[...] = n / np.sqrt(n[:, 0] ** 2 + n[:, 1] ** 2 + n[:, 2] ** 2)[:, None]
        T.radius[...] = self.geo.radius
        self._F[K:K + k] = frames(X, T.normal).reshape(k, 9, -1)
        self._at.update((w, K + i) for i, w in enumerate(omegas.tolist()))
        self.omegas.extend(omegas.tolist())

    def _gather(self, s: np.ndarray, p: np.ndarray, rows: slice,
                table: np.ndarray | None = None) -> np.ndarray:
        """The rows ``rows`` (r, n) of the panel table (or ``table``, of the same layout)
        of panels p in states s (both (n,)): one np.take on the flattened tables."""
        T = (self._T if table is None else table)[:len(self.omegas)]
        R, P = T.shape[1:]
        at = np.arange(R)[rows] * P
        return T.reshape(-1).take((s * (R * P) + p)[None] + at[:, None], mode="clip")

    def columns(self, s: np.ndarray, p: np.ndarray) -> Panels:
        """Every field (each (..., n)) of panels p in states s (both (n,))."""
        return Panels.of(self._gather(s, p, slice(0, WIDTH)))

    def field(self, s: np.ndarray, p: np.ndarray, name: str) -> np.ndarray:
        """The field ``name`` (its shape, then n) of panels p in states s (both (n,))."""
        return self._gather(s, p, _SPANS[name]).reshape(*FIELDS[name], -1)

    def quads(self, s: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Corners (n, 4, 3) of panels p in states s (both (n,))."""
        return np.ascontiguousarray(self.field(s, p, "corners").T)

    def normals(self, s: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Unit normals (n, 3) of panels p in states s (both (n,))."""
        return np.ascontiguousarray(self.field(s, p, "normal").T)

    def frames(self, s: np.ndarray, p: np.ndarray) -> np.ndarray:
        """The frames (n, 3, 3) of panels p in states s (both (n,)), as :func:`frames`
        gives them."""
        F = self._gather(s, p, slice(0, 9), self._F)
        return np.ascontiguousarray(F.reshape(3, 3, -1).transpose(2, 0, 1))


def frames(X: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The panels' frames (k, 3, 3, P) from their corners X (k, 3, 4, P) and unit normals
    n (k, 3, P): indexed [state, axis, coordinate, panel], the axes along a -> b (made
    normal to n), the normal's cross product with it, and n; origin at corner a. The frame
    in which :func:`~rffqm_nlp.contact.motion.frame_bound` measures the other panel's
    motion."""
    e1 = X[:, :, 1] - X[:, :, 0]
    e1 = e1 - (e1[:, 0] * n[:, 0] + e1[:, 1] * n[:, 1] + e1[:, 2] * n[:, 2])[:, None] * n
    e1 = e1 / np.sqrt(e1[:, 0] * e1[:, 0] + e1[:, 1] * e1[:, 1]
                      + e1[:, 2] * e1[:, 2])[:, None]
    e2 = np.stack([n[:, 1] * e1[:, 2] - n[:, 2] * e1[:, 1],
                   n[:, 2] * e1[:, 0] - n[:, 0] * e1[:, 2],
                   n[:, 0] * e1[:, 1] - n[:, 1] * e1[:, 0]], axis=1)
    return np.stack([e1, e2, n], axis=1)


def _grown(T: np.ndarray, kept: int, size: int) -> np.ndarray:
    """A table (K, ...) with room for ``size`` states: T if it has, else a copy of its
    first ``kept`` with twice the room (or ``size``)."""
    if size <= len(T):
        return T
    grown = np.empty((max(2 * len(T), size), *T.shape[1:]))
    grown[:kept] = T[:kept]
    return grown
