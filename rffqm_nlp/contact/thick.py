"""Thick panels along the motion: tapered panels (after Tachi) and their collision check.

A sheet of thickness t is made of one convex solid per panel, rigid with its panel, whose
hinge axes are the zero-thickness creases: the panel's zero-thickness quadrilateral is one
face of the solid (the "top"), and the material lies on one side of it, ``side`` = -1 (the
back, -e3 in the flat pattern) or +1 (the front). In the panel's flat frame the solid is
the intersection of the half-spaces h . x >= o (:class:`ThickPanels`):

* the slab 0 <= side z <= t and the four vertical planes through the panel's sides;
* at every interior crease, the plane through the crease that bisects the angle between
  the two panels at the designed state (normal (u_A - u_B) / |u_A - u_B|, u the unit
  vectors in each panel perpendicular to the crease, pointing into it). Where the fold
  opens the material's side the plane removes nothing; where it closes it, it bevels both
  panels so that their bevels meet exactly at the designed state.

Neighbours across a crease never overlap from flat to the designed state: in the frame of
one, the other turns about the crease by the fold angle gamma, and their material lies in
the wedges [0, (pi - |gamma*|)/2] and [(pi + |gamma*|)/2 - |gamma|, pi - |gamma|] of the
angle around the crease (measured through the material's side), disjoint for
|gamma| <= |gamma*| (fold angles are monotone along the motion: tan(gamma/2) =
k tan(omega/2), docs/paper.md s.2).

:func:`thick_collisions` checks the rest of the motion from flat to ``omega``:

* panels that share no vertex: every point of a solid lies within t of its
  zero-thickness panel, so the solids cannot meet while their panels keep 2 t apart: the
  zero-thickness check of :func:`~rffqm_nlp.contact.collisions.collisions` with a
  clearance of 2 t (sufficient, conservative where the panels face with bare sides);
* panels that share only a vertex v (two pairs at each interior vertex): near v each solid
  is its cone at v (the half-spaces through v), and each solid lies inside its cone
  (convex), so the interiors are disjoint exactly when the cones' are. Two cones are
  separated with an angular margin delta (:func:`cone_gap`: the best plane through v among
  the candidates of the separating axis test); in the frame of one panel the other turns
  about v, so a step over which it turns by less than the sum of the margins at the ends
  (SAFETY times the relative rotation's chord, the assumption of
  :mod:`~rffqm_nlp.contact.motion`) is certified, and other steps are halved down to
  ``tol`` in omega, where a pair still not certified (or one with a negative margin at a
  sample) is reported in contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..files import Key, check_value
from ..model.backend import finite_array
from ..model.numpy_model import fold
from ..model.pattern import Pattern, check_fold_angle, check_pattern
from .broad import SAFETY
from .collisions import CollisionReport, collisions
from .panels import PanelPair
from .vectors import cross, dot, norm

__all__ = ["SIDES", "ThickPanels", "ThickReport", "choose_side", "cone_gap",
           "panel_frames", "thick_collisions"]

#: The material's side of the zero-thickness surface, by name.
SIDES = {"back": -1, "front": 1}
#: Coarse samples of the motion of the vertex-sharing pairs.
SAMPLES = 33
#: A cone gap at or below this (radians) is a contact of the vertex-sharing solids.
OVERLAP = 0.0


def panel_frames(pat: Pattern, Y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rigid motions of every panel from the flat pattern to the states Y (..., N+1, M+1,
    3): rotations R (..., N, M, 3, 3) and translations T (..., N, M, 3), y = R x + T
    for every point x of the panel in the flat frame (exact for rigid panels: the frame of
    the sides a->c, a->b and their normal)."""
    check_pattern(pat, "pattern")
    Y = finite_array(Y, "Y", allowed=f"folded states of shape (..., {pat.N + 1}, "
                     f"{pat.M + 1}, 3)")
    if Y.shape[-3:] != (pat.N + 1, pat.M + 1, 3):
        raise InputError(f"Y must be folded states of shape (..., {pat.N + 1}, "
                         f"{pat.M + 1}, 3), got shape {Y.shape}")

    def frame(P):
        e1, e2 = P[..., :-1, 1:, :] - P[..., :-1, :-1, :], P[..., 1:, :-1, :] - P[..., :-1, :-1, :]
        return np.stack([e1, e2, cross(e1, e2)], axis=-1)

    X = pat.X
    with np.errstate(all="ignore"):
        R = np.swapaxes(np.linalg.solve(np.swapaxes(frame(X), -1, -2),
                                        np.swapaxes(frame(Y), -1, -2)), -1, -2)
        T = Y[..., :-1, :-1, :] - np.einsum("...ij,...j->...i", R, X[:-1, :-1])
    if not (np.all(np.isfinite(R)) and np.all(np.isfinite(T))):
        raise InputError("the panels' motions overflow: the states Y are too large for "
                         "floating point")
    return R, T


def _inward(X: np.ndarray) -> np.ndarray:
    """In-plane unit normals (N, M, 4, 3) of each panel's sides a->c, c->d, d->b, b->a
    (counter-clockwise), pointing into the panel."""
    a, b, c, d = X[:-1, :-1], X[1:, :-1], X[:-1, 1:], X[1:, 1:]
    ring = np.stack([a, c, d, b], axis=2)
    edge = np.roll(ring, -1, axis=2) - ring
    n = np.stack([-edge[..., 1], edge[..., 0], np.zeros_like(edge[..., 0])], axis=-1)
    return n / norm(n)[..., None]


#: For each side k (a->c, c->d, d->b, b->a) of panel (i, j): the neighbour's offset
#: (di, dj) and the neighbour's own side index for the same crease.
_ACROSS = ((-1, 0, 2), (0, 1, 3), (1, 0, 0), (0, -1, 1))


def _neighbour_normals(u: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each panel side: the inward normal of the panel across it at the rotations R
    (N, M, 3, 3), in the panel's own flat frame (N, M, 4, 3), and whether the side is an
    interior crease (N, M, 4)."""
    N, M = u.shape[:2]
    across = np.zeros_like(u)
    interior = np.zeros((N, M, 4), bool)
    for k, (di, dj, kk) in enumerate(_ACROSS):
        i0, i1 = max(0, -di), N - max(0, di)
        j0, j1 = max(0, -dj), M - max(0, dj)
        mine = (slice(i0, i1), slice(j0, j1))
        theirs = (slice(i0 + di, i1 + di), slice(j0 + dj, j1 + dj))
        Q = np.swapaxes(R[mine], -1, -2) @ R[theirs]
        across[mine + (k,)] = np.einsum("...ij,...j->...i", Q, u[theirs + (kk,)])
        interior[mine + (k,)] = True
    return across, interior


@dataclass(frozen=True)
class ThickPanels:
    """Tapered panels of a pattern (see the module), each the intersection of 8 half-spaces
    h . x >= o in its flat frame (units of the pattern).

    ``normals`` (N, M, 8, 3) and ``offsets`` (N, M, 8): the slab's two faces (the top,
    the zero-thickness panel, first), the four sides a->c, c->d, d->b, b->a, then the
    bevels of the creases that close on the material's side (a bevel that removes nothing,
    or a boundary side, repeats its side's half-space). ``bevelled`` (N, M, 4): which sides
    carry a bevel; ``side`` -1 (back) or +1 (front); ``thickness``; ``omega`` the designed
    state the bevels meet at.
    """

    normals: np.ndarray
    offsets: np.ndarray
    bevelled: np.ndarray
    side: int
    thickness: float
    omega: float

    @classmethod
    def build(cls, pat: Pattern, omega: float, thickness: float,
              side: str | int = "auto") -> ThickPanels:
        """The tapered panels of ``pat`` bevelled for the state ``omega`` (in [-pi, pi]),
        ``thickness`` > 0 in the pattern's units, the material on ``side`` ("back",
        "front", or "auto": :func:`choose_side`)."""
        check_pattern(pat, "pattern")
        omega = check_fold_angle(omega, "omega")
        thickness = check_value(thickness, Key("number", low=0, low_open=True,
                                               hint="(a length)"), "thickness")
        s = _side(pat, omega, side)
        X = pat.X
        u = _inward(X)
        R, _ = panel_frames(pat, fold(pat, omega))
        across, interior = _neighbour_normals(u, R)
        ring = np.stack([X[:-1, :-1], X[:-1, 1:], X[1:, 1:], X[1:, :-1]], axis=2)
        m = u - across
        closing = interior & (s * across[..., 2] > 0)
        length = norm(m)
        m = np.where(closing[..., None], m / np.where(length > 0, length, 1)[..., None], u)
        N, M = pat.N, pat.M
        top = np.broadcast_to([0.0, 0.0, float(s)], (N, M, 1, 3))
        normals = np.concatenate([top, -top, u, m], axis=2)
        offsets = np.concatenate([np.zeros((N, M, 1)), np.full((N, M, 1), -thickness),
                                  dot(u, ring), dot(m, ring)], axis=2)
        return cls(normals, offsets, closing, int(s), float(thickness), float(omega))

    def cones(self) -> tuple[np.ndarray, np.ndarray]:
        """The cone of every panel at each of its corners a, c, d, b: the normals (N, M, 4,
        5, 3) of the half-spaces through the corner (the top, the two sides and the two
        bevels at it), the cone's unit extreme rays (N, M, 4, 5, 3) (slots without one
        repeat the first) and which slots hold one (N, M, 4, 5)."""
        k = np.arange(4)
        prev = (k - 1) % 4                  # corner k lies on sides k - 1 and k
        h = np.stack([np.broadcast_to(self.normals[:, :, :1], self.normals[:, :, 2:6].shape),
                      self.normals[:, :, 2 + prev], self.normals[:, :, 2 + k],
                      self.normals[:, :, 6 + prev], self.normals[:, :, 6 + k]], axis=3)
        rays, valid = _extreme_rays(h)
        return h, rays, valid


def _extreme_rays(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit extreme rays (..., 5, 3) of the pointed cones {d: h_k . d >= 0} (h: (..., 5,
    3)), at most 5 (one per face), and which of the 5 slots hold one (the others repeat
    a ray): the cross products of two normals that meet every half-space, without
    repeats."""
    i, j = np.triu_indices(h.shape[-2], 1)
    c = cross(h[..., i, :], h[..., j, :])
    length = norm(c)
    ok = length > 1e-12
    c = c / np.where(ok, length, 1.0)[..., None]
    signs = np.einsum("...rk,...nk->...rn", c, h)
    c = c * np.where(np.all(signs >= -1e-12, axis=-1), 1.0, -1.0)[..., None]
    valid = ok & np.all(np.einsum("...rk,...nk->...rn", c, h) >= -1e-12, axis=-1)
    same = np.einsum("...rk,...qk->...rq", c, c) > 1 - 1e-12
    earlier = np.tril(np.ones((len(i), len(i)), bool), -1)
    valid &= ~np.any(same & earlier & valid[..., None, :], axis=-1)
    order = np.argsort(~valid, axis=-1, kind="stable")[..., :h.shape[-2]]
    rays = np.take_along_axis(c, order[..., None], axis=-2)
    valid = np.take_along_axis(valid, order, axis=-1)
    return np.where(valid[..., None], rays, rays[..., :1, :]), valid


def _side(pat: Pattern, omega: float, side: str | int) -> int:
    if isinstance(side, str) and side == "auto":
        return choose_side(pat, omega)
    if isinstance(side, str) and side in SIDES:
        return SIDES[side]
    if side in (-1, 1) and not isinstance(side, bool):
        return int(side)
    check_value(side, Key("choice", choices=("auto", *SIDES)), "side")
    raise AssertionError("unreachable: check_value refuses every other side")


def choose_side(pat: Pattern, omega: float) -> int:
    """The material's side, -1 (back) or +1 (front), that bevels less: the smaller sum,
    over the creases that close on that side, of the crease length times tan(|gamma|/2)
    (a bevel removes t^2 tan(|gamma|/2) / 2 of each panel's cross-section per unit length
    of crease, gamma the fold angle at ``omega``); the back on a tie."""
    check_pattern(pat, "pattern")
    omega = check_fold_angle(omega, "omega")
    u = _inward(pat.X)
    R, _ = panel_frames(pat, fold(pat, omega))
    across, interior = _neighbour_normals(u, R)
    X = pat.X
    ring = np.stack([X[:-1, :-1], X[:-1, 1:], X[1:, 1:], X[1:, :-1]], axis=2)
    length = norm(np.roll(ring, -1, axis=2) - ring)
    cos_g = np.clip(-dot(u, across), -1.0, 1.0)
    half = np.tan(np.minimum(np.arccos(cos_g), math.pi * (1 - 1e-9)) / 2)
    cost = {s: float(np.sum((length * half)[interior & (s * across[..., 2] > 0)]))
            for s in (-1, 1)}
    return -1 if cost[-1] <= cost[1] else 1


# --------------------------------------------------------------------------- cones
def cone_gap(h_a: np.ndarray, rays_a: np.ndarray, h_b: np.ndarray,
             rays_b: np.ndarray) -> np.ndarray:
    """Angular distance (radians) between pairs of pointed convex cones with a common apex,
    (n,): the least angle between a ray of one and the other (its spherical polygon),
    when their interiors are disjoint; -1 when they overlap. Disjoint when a candidate of
    the separating axis test (either cone's face normals, the cross products of a ray of
    each) leaves the cones on its two sides (touching allowed): exact for polyhedral
    cones. ``h_*`` (n, F, 3) face normals, ``rays_*`` (n, R, 3) extreme rays (repeats
    allowed; all scaled to unit length here). A cone turned by less than this angle about
    the apex stays clear."""
    h_a, rays_a, h_b, rays_b = (
        finite_array(v, name, allowed="an array of shape (n, k, 3), n and k >= 1")
        for v, name in ((h_a, "h_a"), (rays_a, "rays_a"), (h_b, "h_b"), (rays_b, "rays_b")))
    shapes = [v.shape for v in (h_a, rays_a, h_b, rays_b)]
    if any(len(sh) != 3 or sh[2] != 3 or sh[1] < 1 or sh[0] != shapes[0][0]
           for sh in shapes):
        raise InputError(f"h_a, rays_a, h_b, rays_b must be arrays of shape (n, k, 3) for "
                         f"one n, got shapes {', '.join(map(str, shapes))}")
    h_a, rays_a, h_b, rays_b = (_unit(v, name) for v, name in (
        (h_a, "h_a"), (rays_a, "rays_a"), (h_b, "h_b"), (rays_b, "rays_b")))
    pairs = cross(rays_a[:, :, None, :], rays_b[:, None, :, :]).reshape(len(rays_a), -1, 3)
    m = np.concatenate([h_a, -h_b, pairs, -pairs], axis=1)        # (n, C, 3)
    length = norm(m)
    on_a = np.einsum("nck,nrk->ncr", m, rays_a).min(axis=2)
    on_b = np.einsum("nck,nrk->ncr", m, rays_b).max(axis=2)
    eps = 1e-12 * np.maximum(length, 1e-300)
    apart = np.any((length > 1e-12) & (on_a >= -eps) & (on_b <= eps), axis=1)
    gap = np.minimum(_to_polygon(rays_a, rays_b), _to_polygon(rays_b, rays_a))
    return np.where(apart, gap, -1.0)


def _unit(v: np.ndarray, name: str) -> np.ndarray:
    """The vectors v (..., 3) scaled to unit length; :class:`InputError` for a zero one."""
    with np.errstate(all="ignore"):
        size = np.sqrt(np.sum((v / np.max(np.abs(v), axis=-1, keepdims=True)) ** 2, axis=-1))
        size = size * np.max(np.abs(v), axis=-1)
    if not np.all(np.isfinite(size) & (size > 0)):
        raise InputError(f"{name} must hold nonzero vectors")
    return v / size[..., None]


def _to_polygon(points: np.ndarray, rays: np.ndarray) -> np.ndarray:
    """The least angle (n,) from the unit vectors ``points`` (n, P, 3) to the arcs between
    any two of ``rays`` (n, R, 3): the angular distance to their spherical polygon from
    outside it (its edges are among those arcs, the other arcs lie inside it)."""
    i, j = np.triu_indices(rays.shape[1], 1)
    r1, r2 = rays[:, None, i, :], rays[:, None, j, :]              # (n, 1, A, 3)
    p = points[:, :, None, :]                                      # (n, P, 1, 3)
    c = cross(r1, r2)
    size = norm(c)
    n_hat = c / np.maximum(size, 1e-300)[..., None]
    along = dot(p, n_hat)
    q = p - along[..., None] * n_hat
    inside = ((size > 1e-12) & (dot(cross(r1, q), n_hat) >= 0)
              & (dot(cross(q, r2), n_hat) >= 0))
    to_arc = np.arcsin(np.clip(np.abs(along), 0.0, 1.0))
    ends = np.minimum(_angle(p, r1), _angle(p, r2))
    return np.where(inside, np.minimum(to_arc, ends), ends).min(axis=(1, 2))


def _angle(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Angles between unit vectors (..., 3), accurate near 0."""
    return np.arctan2(norm(cross(u, v)), dot(u, v))


def _vertex_pairs(N: int, M: int) -> np.ndarray:
    """The panel pairs that share only a vertex, with the corner each has there: rows
    (i_a, j_a, corner_a, i_b, j_b, corner_b), 0-based panels, corners 0..3 = a, c, d, b.
    At the interior vertex (i, j): panels (i-1, j-1) and (i, j) (its d and its a corner),
    panels (i-1, j) and (i, j-1) (its b and its c corner), 1-based."""
    i, j = np.meshgrid(np.arange(1, N), np.arange(1, M), indexing="ij")
    i, j = i.ravel(), j.ravel()
    one = np.ones_like(i)
    first = np.stack([i - 1, j - 1, 2 * one, i, j, 0 * one], axis=1)
    second = np.stack([i - 1, j, 3 * one, i, j - 1, 1 * one], axis=1)
    return np.concatenate([first, second])


def _rotation_angle(Q: np.ndarray) -> np.ndarray:
    """Angles (...) of rotations Q (..., 3, 3)."""
    trace = Q[..., 0, 0] + Q[..., 1, 1] + Q[..., 2, 2]
    return np.arccos(np.clip((trace - 1) / 2, -1.0, 1.0))


class _VertexPairs:
    """The cones of the vertex-sharing pairs and their margins at any omega."""

    def __init__(self, pat: Pattern, panels: ThickPanels):
        self.pat, self.sign = pat, 1.0 if panels.omega >= 0 else -1.0
        h, rays, _ = panels.cones()
        rows = _vertex_pairs(pat.N, pat.M)
        self.rows = rows
        self.h_a, self.r_a = h[rows[:, 0], rows[:, 1], rows[:, 2]], rays[rows[:, 0], rows[:, 1], rows[:, 2]]
        self.h_b, self.r_b = h[rows[:, 3], rows[:, 4], rows[:, 5]], rays[rows[:, 3], rows[:, 4], rows[:, 5]]

    def relative(self, omegas: np.ndarray) -> np.ndarray:
        """R_a^T R_b (K, n, 3, 3) at the |omega| values (K,) on the designed branch."""
        w = self.sign * np.asarray(omegas, dtype=float)
        R, _ = panel_frames(self.pat, fold(self.pat, w))
        r = self.rows
        return np.swapaxes(R[:, r[:, 0], r[:, 1]], -1, -2) @ R[:, r[:, 3], r[:, 4]]

    def gaps(self, Q: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Margins (n,) of the pairs k (n,) with relative rotations Q (n, 3, 3)."""
        h_b = np.einsum("nij,nrj->nri", Q, self.h_b[k])
        r_b = np.einsum("nij,nrj->nri", Q, self.r_b[k])
        return cone_gap(self.h_a[k], self.r_a[k], h_b, r_b)


def _first_vertex_contact(pairs: _VertexPairs, omega: float, tol: float
                          ) -> tuple[float | None, np.ndarray]:
    """The first |omega| in [0, |omega|] at which a vertex-sharing pair is not certified
    free (signed like ``omega``), or None; and the pairs (their row indices) there."""
    w = np.linspace(0.0, abs(omega), SAMPLES)
    sign = pairs.sign
    Q = pairs.relative(w)                                         # (K, n, 3, 3)
    n = len(pairs.rows)
    gap = np.stack([pairs.gaps(Q[s], np.arange(n)) for s in range(len(w))])
    bad = gap < OVERLAP
    if bad.any():
        first = int(np.argmax(bad.any(axis=1)))
        w = w[:first + 1]
        Q, gap = Q[:first + 1], gap[:first + 1]
    else:
        first = None
    hits: list[tuple[float, int]] = []
    for s in range(len(w) - 1):
        k = np.arange(n)
        _refine(pairs, w[s], w[s + 1], Q[s], Q[s + 1], gap[s], gap[s + 1], k, tol, hits)
    if first is not None:
        hits += [(float(w[first]), int(k)) for k in np.flatnonzero(bad[first])]
    if not hits:
        return None, np.zeros(0, int)
    at = min(h[0] for h in hits)
    return sign * at, np.array(sorted({k for x, k in hits if x == at}))


def _refine(pairs, w0, w1, Q0, Q1, g0, g1, k, tol, hits) -> None:
    """Certify the pairs k over [w0, w1] (rotations Q and margins g at both ends, each
    (len(k), ...)), halving the step where needed; contacts go to ``hits`` (omega, pair)."""
    turn = _rotation_angle(np.swapaxes(Q0, -1, -2) @ Q1)
    open_ = g0 + g1 <= SAFETY * turn
    if not open_.any():
        return
    k, Q0, Q1, g0, g1 = k[open_], Q0[open_], Q1[open_], g0[open_], g1[open_]
    if w1 - w0 < tol:
        hits.extend((float(w1), int(x)) for x in k)
        return
    wm = (w0 + w1) / 2
    Qm = pairs.relative(np.array([wm]))[0][k]
    gm = pairs.gaps(Qm, k)
    bad = gm < OVERLAP
    hits.extend((float(wm), int(x)) for x in k[bad])
    ok = ~bad
    _refine(pairs, w0, wm, Q0[ok], Qm[ok], g0[ok], gm[ok], k[ok], tol, hits)
    _refine(pairs, wm, w1, Qm[ok], Q1[ok], gm[ok], g1[ok], k[ok], tol, hits)



# --------------------------------------------------------------------------- the check
@dataclass(frozen=True)
class ThickReport:
    """Result of :func:`thick_collisions`.

    ``free``: no flat overlap, no two solids that share no vertex within reach (their
    panels kept 2 ``thickness`` apart) and every vertex-sharing pair certified apart, from
    flat to ``omega_max``. ``first_omega``: the first omega where one of these fails
    (signed like ``omega_max``), or None; ``pairs``: the 1-based panel pairs there.
    ``far``: the zero-thickness report with clearance 2 ``thickness``;
    ``vertex_first_omega``, ``vertex_pairs``: the first omega of a vertex-sharing pair and
    its pairs; ``vertex_pairs_checked``: how many such pairs were followed; ``side``: the
    material's side (-1 back, +1 front).
    """

    free: bool
    first_omega: float | None
    pairs: list[PanelPair]
    far: CollisionReport
    vertex_first_omega: float | None
    vertex_pairs: list[PanelPair] = field(default_factory=list)
    vertex_pairs_checked: int = 0
    thickness: float = 0.0
    side: int = -1
    omega_max: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dictionary (pairs as nested lists)."""
        pairs = lambda ps: [[list(p), list(q)] for p, q in ps]      # noqa: E731
        return {"free": self.free, "first_omega": self.first_omega,
                "pairs": pairs(self.pairs), "far": self.far.to_dict(),
                "vertex_first_omega": self.vertex_first_omega,
                "vertex_pairs": pairs(self.vertex_pairs),
                "vertex_pairs_checked": self.vertex_pairs_checked,
                "thickness": self.thickness, "side": self.side, "omega_max": self.omega_max}


def thick_collisions(pattern: Pattern, omega_max: float, thickness: float, *,
                     side: str | int = "auto", tol: float = 1e-4) -> ThickReport:
    """Whether the tapered panels of ``pattern`` (:class:`ThickPanels`, bevelled for
    ``omega_max``, ``thickness`` > 0 in the pattern's units, the material on ``side``)
    stay apart from flat to ``omega_max`` (see the module). ``tol`` > 0: the accuracy of
    a first contact in omega. :class:`~rffqm_nlp.errors.InputError` for arguments of other
    kinds."""
    check_pattern(pattern, "pattern")
    omega_max = check_fold_angle(omega_max, "omega_max")
    tol = check_value(tol, Key("number", low=0, low_open=True, hint="(a step in omega)"),
                      "tol")
    panels = ThickPanels.build(pattern, omega_max, thickness, side)
    far = collisions(pattern, omega_max, clearance=2 * panels.thickness, tol=tol)
    vertex_first, vertex_pairs, checked = None, [], 0
    if pattern.N > 1 and pattern.M > 1 and omega_max != 0.0:
        pairs = _VertexPairs(pattern, panels)
        checked = len(pairs.rows)
        vertex_first, rows = _first_vertex_contact(pairs, omega_max, tol)
        vertex_pairs = [((int(r[0]) + 1, int(r[1]) + 1), (int(r[3]) + 1, int(r[4]) + 1))
                        for r in pairs.rows[rows]]
        vertex_pairs = sorted({tuple(sorted(p)) for p in vertex_pairs})
    first, pairs_at = _earliest(far, vertex_first, vertex_pairs)
    return ThickReport(free=far.free and vertex_first is None, first_omega=first,
                       pairs=pairs_at, far=far, vertex_first_omega=vertex_first,
                       vertex_pairs=vertex_pairs, vertex_pairs_checked=checked,
                       thickness=panels.thickness, side=panels.side, omega_max=omega_max)


def _earliest(far: CollisionReport, vertex_first: float | None,
              vertex_pairs: list[PanelPair]) -> tuple[float | None, list[PanelPair]]:
    """The earlier of the two first contacts and its pairs (both on a tie)."""
    found = [(abs(w), w, p) for w, p in ((far.first_omega, far.pairs),
                                        (vertex_first, vertex_pairs)) if w is not None]
    if far.flat_overlaps:
        found.append((0.0, 0.0, far.flat_overlaps))
    if not found:
        return None, []
    at = min(f[0] for f in found)
    first = next(f[1] for f in found if f[0] == at)
    return first, sorted({p for f in found if f[0] == at for p in f[2]})
