"""Self-contact of a folding pattern: flat overlaps and the first contact along the motion.

RFFQM guarantees a rigid folding motion, not that the sheet stays clear of itself.
:func:`collisions` checks the motion omega in [0, omega_max] of a marched
:class:`~rffqm_nlp.model.pattern.Pattern` for two panels that share no vertex touching,
intersecting or coming closer than a ``clearance``.

Method.

* Geometry: panels are rigid and planar, so panel (i, j) with corners a = (i, j),
  b = (i+1, j), c = (i, j+1), d = (i+1, j+1) is exactly the two triangles (a, c, d) and
  (a, d, b); folded states come from :func:`rffqm_nlp.model.numpy_model.fold` (batched).
* Narrow phase, vectorised over pairs of triangles: an exact intersection test by
  separating axes (the two normals, the nine edge-edge cross products and the six in-plane
  edge normals, so the coplanar case is included), and for disjoint triangles the exact
  distance (the smallest of the nine segment-segment distances and the six vertex-face
  distances whose foot lies inside the face). The distance between two panels is the
  smallest of their four triangle pairs.
* Broad phase, :class:`scipy.spatial.cKDTree` queries per coarse step [w0, w1], on the
  panel centres at w0. They must give every pair that the step's sphere gaps g(w0),
  g(w1) (centre distance minus both radii) and its cheapest motion bound m (below) do
  not certify clear, (g(w0) + g(w1) - m) / 2 <= clearance, however far apart. With an
  affine fit of the centres' displacements over the step, D_p = A C_p + t + e_p (least
  squares on the centres' leading principal directions), and L the spectral norm of A,
  |D_p - D_q| <= L |C_p - C_q| + |e_p| + |e_q|, so every such pair has g(w0) <= G_p + G_q
  with a reach per panel G_p = (clearance + (SAFETY + 1) (L r_p + |e_p|) + SAFETY s_p) /
  (2 - (SAFETY + 1) L) (r its radius, s its spin: its largest vertex displacement about
  its centre); the tree queries find the centres within r_p + G_p + r_q + G_q (blocks of
  panels queried against the panels from the block on: in the grid's order when r + G is
  nearly the same for all, else by decreasing r + G, so that very unequal reaches do not
  make every query large). A folding sheet's centres move
  nearly affinely over a short step, so the reaches are a fraction of a panel. Every gap
  is lowered, every bound raised, by a small slack (a bound on the rounding).
  Near flat, though, a large sheet bends: one affine map misfits its displacements by
  about the same length whatever the panels' size, so the reaches grow to many panels
  (docs/collisions.md). In such a step (the median reach above ``TILE_REACH`` panel
  radii), from ``MIN_TILES`` tiles of ``TILE`` x ``TILE`` panels on, each tile gets its
  own fit (:func:`_local_pairs`): the bound above holds for any affine map, so a pair
  (p, q) with p in a tile and both residuals measured against that tile's fit needs
  g(w0) <= G_p + G_q with the tile's reaches too; a pair is a candidate when both the
  tile's and the global reaches allow it (a subset of the global candidates
  that keeps every pair they must give).
* Memory: no step's pairs are held at once. The tree queries give their pairs in chunks
  of about ``ROWS`` (the first block's count bounds it, each next block is sized from the
  last one's pairs per panel), a step's rows are refined along the motion as they come
  (in batches of at most ``ROWS`` rows, the coarse steps in order), and no step that
  starts after the earliest contact found is looked at. The report does not depend on
  the order or the batches: a pair in contact at a sample is found by every row that has
  that sample, and only rows that start after the earliest contact found are dropped.
* Along the motion: omega is sampled on a coarse grid (steps of at most ``MAX_STEP``); on
  a step [w0, w1] a candidate pair is certified clear when
  (d(w0) + d(w1) - m) / 2 > clearance, where d is the panel distance and m bounds how far
  the pair's distance can change over the step: SAFETY times the largest relative
  displacement of a vertex of one panel against a vertex of the other between w0 and w1
  (a rigid motion's displacement is affine on a panel, so its extreme is at a vertex;
  the 16 vertex pairs are compared, after a coarser bound, the centres' relative
  displacement plus each panel's largest vertex displacement about its centre, has
  failed to certify the step), or SAFETY times the largest displacement of a vertex of
  one panel in the frame of the other (origin at its corner a, axes along its edge
  a -> b and its normal), whichever is smaller: in its own frame a panel is still and
  the other moves rigidly, so the distance changes by at most that. The frame bound is
  the one that certifies panels hinged across a very thin panel (side-length LP
  patterns): they stay close while their far corners move a lot, but in one another's
  frame they hardly move. Distances are first bounded from below cheaply (centre
  distance minus radii, how far one panel lies on one side of the other's plane, and the
  gap between the two panels' projections on the line through their centres); the exact
  distance is computed only where that bound does not certify the step, and only an
  exact distance reports a contact.
  Uncertified pairs are followed into the halves of the step (one batched fold per
  level) until they are certified, touch at a sample (d <= clearance), or the step is
  shorter than ``tol``; contacts after the earliest one found are dropped on the way.
  ``first_omega`` is the earliest sample in contact, so it lies within ``tol`` after the
  true first contact.
* Guarantee and its assumptions: no contact is missed provided that within one step the
  path of every vertex relative to another, and of every vertex in the frame of another
  panel, is at most SAFETY times its chord (smooth motion on short steps; the second,
  added with the frame bound, is of the same kind as the first); the broad phase adds no
  assumption. A pair whose distance dips below the clearance only between two samples
  less than ``tol`` apart may be missed (a near miss shorter than ``tol`` in omega).
* Flat overlaps: at omega = 0 every panel is a convex quadrilateral in the plane; two
  panels overlap when their interiors do (a separating-axis test on the eight edge
  normals, touching along an edge or at a corner is not an overlap).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..model.backend import finite_array, finite_result
from ..errors import InputError
from ..files import Key, check_value, describe_value
from ..model.numpy_model import fold
from ..model.pattern import Pattern, check_fold_angle, check_pattern

#: Largest coarse step in omega.
MAX_STEP = 0.1
#: Factor on a step's relative vertex displacement (chord) bounding its path.
SAFETY = 2.0
#: Separating-axis gaps below this times the pattern's scale count as touching.
REL_EPS = 1e-12

#: Rows of a state's panel table (:class:`_States`).
_ROWS = 19

#: Panel pairs per batch of the bounds and distances along the motion.
BATCH = 2048

#: Most panel pairs the broad phase and the refinement hold at once (tree query results,
#: candidate rows of a step, rows of a refinement level), so that the check's memory
#: grows like the pattern, not like its pairs.
ROWS = 2 ** 18

#: The broad phase takes the panels in the grid's order (blocks of nearby panels) when
#: their largest radius plus reach is at most this times the smallest, else by decreasing
#: radius plus reach (blocks of big panels queried with a big radius, the rest small).
SPREAD = 1.5

#: Triangle pairs per vectorised batch of the narrow phase (bounds its memory).
CHUNK = 4096

#: Panels a side of the grid's tiles, each with its own affine fit of a coarse step's
#: displacements in the broad phase (:func:`_local_pairs`), used from MIN_TILES tiles on
#: (below, one query over the whole sheet costs less than a query per tile).
TILE = 24
MIN_TILES = 4
#: ... and only in a coarse step whose global reaches are large: their median above
#: TILE_REACH times the panels' median radius (a sheet folding nearly uniformly keeps them
#: a fraction of a panel, and there the tiles' fits cost more than they save).
TILE_REACH = 2.0

PanelPair = tuple[tuple[int, int], tuple[int, int]]

#: Corners (a, b, c, d) -> the triangles (a, c, d) and (a, d, b).
_TRIANGLES = np.array([[0, 2, 3], [0, 3, 1]])
#: Triangle index pairs (4, 2) of a panel pair.
_TRI_PAIRS = np.array([[0, 0], [0, 1], [1, 0], [1, 1]])


@dataclass(frozen=True)
class CollisionReport:
    """Result of :func:`collisions`.

    ``free``: no flat overlap and no contact on the motion. ``first_omega``: the smallest
    |omega| in [0, |omega_max|] at which two panels that share no vertex touch or come
    closer than ``clearance``, signed like ``omega_max`` (0.0 when the flat state is
    already in contact), or None. ``pairs``: the panel pairs in contact there, 1-based
    ((i, j), (k, l)) with (i, j) < (k, l). ``flat_overlaps``: pairs whose interiors overlap
    in the flat pattern (any two panels, neighbours included).
    """

    free: bool
    first_omega: float | None
    pairs: list[PanelPair] = field(default_factory=list)
    flat_overlaps: list[PanelPair] = field(default_factory=list)
    omega_max: float = 0.0
    clearance: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dictionary (pairs as nested lists)."""
        return {"free": self.free, "first_omega": self.first_omega,
                "pairs": [[list(p), list(q)] for p, q in self.pairs],
                "flat_overlaps": [[list(p), list(q)] for p, q in self.flat_overlaps],
                "omega_max": self.omega_max, "clearance": self.clearance}


def collisions(pattern: Pattern, omega_max: float, *, clearance: float = 0.0,
               tol: float = 1e-4) -> CollisionReport:
    """Flat overlaps and the first self-contact of ``pattern`` folding from 0 to ``omega_max``.

    ``omega_max`` in [-pi, pi] (negative: the other folding branch); ``clearance`` >= 0 a
    distance (a sheet thickness) that panels sharing no vertex must keep; ``tol`` > 0 the
    accuracy of ``first_omega`` in omega. See the module docstring for the method. Raises
    :class:`~rffqm_nlp.errors.InputError` for arguments of other kinds (``pattern`` not a
    :class:`~rffqm_nlp.model.pattern.Pattern`, ``omega_max`` not one number in [-pi, pi], ...).
    """
    check_pattern(pattern, "pattern")
    w_max = check_fold_angle(omega_max, "omega_max")
    clearance = check_value(clearance, Key("number", low=0, hint="(a distance)"),
                               "clearance")
    tol = check_value(tol, Key("number", low=0, low_open=True, hint="(a step in omega)"),
                         "tol")
    geo = _Geometry(pattern)
    flat = _flat_overlaps(geo)
    first, pairs = _first_contact(geo, w_max, float(clearance), float(tol))
    return CollisionReport(free=not flat and first is None, first_omega=first, pairs=pairs,
                           flat_overlaps=flat, omega_max=w_max, clearance=float(clearance))


# --------------------------------------------------------------------------- panels

class _Geometry:
    """Panel bookkeeping of a pattern: corner indices, sizes, the folded states.

    Panels are numbered p = (i-1) M + (j-1); ``corners`` (P, 4) holds the flat vertex
    indices of a, b, c, d; ``radius`` (P,) the distance from a panel's centroid to its
    farthest corner (constant: panels are rigid).
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
        self.scale = float(np.ptp(X, axis=0).max()) or 1.0

    def states(self, omegas: np.ndarray) -> np.ndarray:
        """Folded vertex positions (K, (N+1)(M+1), 3) at the omegas (K,)."""
        return fold(self.pat, omegas).reshape(len(omegas), -1, 3)

    def centres(self, Y: np.ndarray) -> np.ndarray:
        """Panel centroids (..., P, 3) of states Y (..., V, 3)."""
        return _centroid(Y[..., self.corners, :])

    def label(self, p: int, q: int) -> PanelPair:
        """1-based panel pair, smaller panel first."""
        a, b = sorted((int(p), int(q)))
        return ((a // self.M + 1, a % self.M + 1), (b // self.M + 1, b % self.M + 1))


def _near_pairs(geo: _Geometry, C: np.ndarray, reach: float) -> np.ndarray:
    """Pairs (n, 2), p < q, sharing no vertex, whose spheres grown by ``reach`` overlap."""
    R = geo.radius + reach / 2
    chunks = [np.stack([p, q], axis=1)
              for p, q, _ in _close_pairs(geo, C, R, 2 * _slack(geo, C))]
    return np.concatenate(chunks or [np.zeros((0, 2), dtype=np.int64)])


def _close_pairs(geo: _Geometry, C: np.ndarray, R: np.ndarray, slack: float):
    """The pairs p < q sharing no vertex whose centres C (P, 3) are at most R_p + R_q +
    ``slack`` apart (R (P,) >= 0), with those distances, in chunks (p, q, dist) (n,) of at
    most ROWS pairs. Panels by decreasing R; the first 64 (or fewer, halved until the
    tree counts at most ROWS pairs within twice the largest R of them) estimate the pairs
    per panel. When one query with twice the largest R is expected to give at most
    0.7 ROWS pairs, that query; otherwise each pair is found once, from the panel with the
    larger R: a block of panels queried (a tree of its own) against a tree on the panels
    from the block on, with twice the block's largest R, each block sized from the pairs
    per panel of the last query for 0.7 ROWS (the query radius only shrinks)."""
    order = (np.arange(len(R)) if R.max() <= SPREAD * R.min()
             else np.argsort(-R, kind="stable"))
    X, R, ij = C[order], R[order], geo.ij[order]
    top = np.maximum.accumulate(R[::-1])[::-1]          # the largest R from each on
    P, c0, base, size = len(X), 0, 0, 64
    rest = cKDTree(X)
    while True:
        head = cKDTree(X[:size])
        found = head.count_neighbors(rest, 2 * float(top[0]) + slack)
        if size == 1 or found <= ROWS:
            break
        size //= 2
    if found * P / min(size, P) <= 1.4 * ROWS:   # ordered pairs, self included: one query
        i, j = rest.query_pairs(2 * float(top[0]) + slack, output_type="ndarray").T
        yield from _kept(order, R, ij, i, j, _norm(X[i] - X[j]), slack)
        return
    while c0 < P:
        if 2 * (c0 - base) > P - base:          # a smaller tree on the panels still to come
            base, rest = c0, cKDTree(X[c0:])
        c1 = min(P, c0 + size)
        head = cKDTree(X[c0:c1])
        hits = head.sparse_distance_matrix(rest, float(R[c0:c1].max() + top[c0]) + slack,
                                           output_type="ndarray")
        i, j, dist = hits["i"] + c0, hits["j"] + base, hits["v"]
        size = max(1, int(0.7 * (c1 - c0) * ROWS / max(len(hits), 1)))
        del hits
        yield from _kept(order, R, ij, i, j, dist, slack)
        c0 = c1


def _kept(order: np.ndarray, R: np.ndarray, ij: np.ndarray, i: np.ndarray, j: np.ndarray,
          dist: np.ndarray, slack: float):
    """Of the pairs i, j (n,) of panels by rank (``order`` (P,) the panels, R (P,) and ij
    (P, 2) by rank) at distances ``dist`` (n,), those with j > i, at most R_i + R_j +
    ``slack`` apart and sharing no vertex, as (p, q, dist) with p < q, in chunks of at
    most ROWS."""
    k = np.flatnonzero(j > i)                            # each test on the pairs left
    i, j, dist = i[k], j[k], dist[k]
    k = np.flatnonzero(dist <= R[i] + R[j] + slack)
    i, j, dist = i[k], j[k], dist[k]
    k = np.flatnonzero(np.maximum(np.abs(ij[i, 0] - ij[j, 0]), np.abs(ij[i, 1] - ij[j, 1])) >= 2)
    p, q, dist = order[i[k]], order[j[k]], dist[k]
    for k in range(0, len(p), ROWS):
        a, b = p[k:k + ROWS], q[k:k + ROWS]
        yield np.minimum(a, b), np.maximum(a, b), dist[k:k + ROWS]


def _tiles(geo: _Geometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid's tiles of TILE x TILE panels: the tile of each panel (P,), the panels in
    tile order (P,) and where each tile starts in that order (T,)."""
    nj = -(-geo.M // TILE)
    tile = (geo.ij[:, 0] // TILE) * nj + geo.ij[:, 1] // TILE
    perm = np.argsort(tile, kind="stable")
    starts = np.flatnonzero(np.r_[True, tile[perm][1:] != tile[perm][:-1]])
    return tile, perm, starts


def _tile_fits(C: np.ndarray, D: np.ndarray, spin: np.ndarray, r: np.ndarray,
               clearance: float, tile: np.ndarray, perm: np.ndarray, starts: np.ndarray):
    """:func:`_reach`'s fit on each tile's panels alone, all tiles at once: L (T,), A
    (T, 3, 3), the mean centre and displacement (T, 3) and whether a fit with
    (SAFETY + 1) L < 2 exists (T,). C, D (3, P), spin and r (P,) as :func:`_reach`'s."""
    Cs, Ds = C.T[perm], D.T[perm]                                   # (P, 3) by tile
    count = np.diff(np.r_[starts, len(perm)])
    mc = np.add.reduceat(Cs, starts, axis=0) / count[:, None]
    md = np.add.reduceat(Ds, starts, axis=0) / count[:, None]
    t = tile[perm]
    X, E = Cs - mc[t], Ds - md[t]
    XX = np.add.reduceat(X[:, :, None] * X[:, None, :], starts, axis=0)   # (T, 3, 3)
    EX = np.add.reduceat(E[:, :, None] * X[:, None, :], starts, axis=0)
    lam, U = np.linalg.eigh(XX)
    U, lam = U[:, :, ::-1], lam[:, ::-1]                            # largest first
    rs, ss = r[perm], spin[perm]
    bestA, bestL = np.zeros((len(starts), 3, 3)), np.zeros(len(starts))
    best = np.full(len(starts), np.inf)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for k in range(4):
            Uk = U[:, :, :k]
            A = (EX @ Uk / np.where(lam[:, None, :k] > 0, lam[:, None, :k], np.inf)) \
                @ Uk.transpose(0, 2, 1)
            L = np.linalg.norm(A, 2, axis=(1, 2)) if k else np.zeros(len(starts))
            e = _norm(E - np.einsum("pij,pj->pi", A[t], X))
            G = _fit_reach(L[t], rs, e, ss, clearance)
            top = np.maximum.reduceat(rs + G, starts)
            ok = np.isfinite(L) & ((SAFETY + 1) * L < 2) & np.isfinite(top) & (top < best)
            best[ok], bestL[ok], bestA[ok] = top[ok], L[ok], A[ok]
    return bestL, bestA, mc, md, np.isfinite(best)


def _local_pairs(geo: _Geometry, tiles: tuple[np.ndarray, np.ndarray, np.ndarray],
                 C: np.ndarray, D: np.ndarray, spin: np.ndarray, Rg: np.ndarray,
                 clearance: float, eps: float):
    """The pairs of :func:`_close_pairs` (C.T, Rg, 2 eps) that are also within the reaches
    of the affine fit of p's grid tile (:func:`_tile_fits`; both panels' residuals against
    that one fit, which bounds |D_p - D_q| as the global fit does): a superset of the pairs
    the step's filter keeps, found with far smaller queries where the sheet bends (one
    affine map fits a tile's displacements far better than the whole sheet's). C, D (3, P),
    spin (P,) as :func:`_reach`'s, Rg (P,) the radii plus the global reaches, ``tiles``
    those of :func:`_tiles`. In chunks (p, q, dist) of at most ROWS pairs."""
    r = geo.radius
    tile, perm, starts = tiles
    L, A, mc, md, ok = _tile_fits(C, D, spin, r, clearance, tile, perm, starts)
    Ct = np.ascontiguousarray(C.T)
    e = _norm(D.T - md[tile] - np.einsum("pij,pj->pi", A[tile], Ct - mc[tile]))
    own = np.where(ok[tile], r + _fit_reach(L[tile], r, e, spin, clearance), Rg)
    slack = np.where(ok, 4 * eps / (2 - (SAFETY + 1) * L) + 2 * eps, 2 * eps)
    groups = np.split(perm, starts[1:])
    centre = np.stack([Ct[g].mean(axis=0) for g in groups])
    rho = np.array([float(_norm(Ct[g] - c).max()) for g, c in zip(groups, centre)])
    Rmax = np.array([float(Rg[g].max()) for g in groups])
    lists = cKDTree(Ct).query_ball_point(centre, rho + Rmax + float(Rg.max()) + 4 * eps,
                                         return_sorted=False)
    out, held = [], 0
    for T, g in enumerate(groups):
        cand = np.asarray(lists[T], dtype=np.int64)
        cand = cand[cand > g.min()]
        if not cand.size:
            continue
        Rp = own[g]
        if ok[T]:
            eq = _norm(D.T[cand] - md[T] - (Ct[cand] - mc[T]) @ A[T].T)
            Rq = r[cand] + _fit_reach(L[T], r[cand], eq, spin[cand], clearance)
        else:
            Rq = Rg[cand]
        Rgq = Rg[cand]  # a pair must pass both: the tile's reaches and the global ones
        near = _norm(Ct[cand] - centre[T]) <= rho[T] + np.minimum(
            float(Rp.max()) + Rq + slack[T], Rmax[T] + Rgq + 2 * eps)
        cand, Rq, Rgq = cand[near], Rq[near], Rgq[near]
        if not cand.size:
            continue
        hits = cKDTree(Ct[g]).sparse_distance_matrix(
            cKDTree(Ct[cand]), min(float(Rp.max() + Rq.max() + slack[T]),
                                   float(Rmax[T] + Rgq.max() + 2 * eps)), output_type="ndarray")
        i, j, dist = hits["i"], hits["j"], hits["v"]
        p, q = g[i], cand[j]
        k = np.flatnonzero((q > p) & (dist <= Rp[i] + Rq[j] + slack[T])
                           & (dist <= Rg[p] + Rg[q] + 2 * eps))
        p, q, dist = p[k], q[k], dist[k]
        k = np.flatnonzero(np.maximum(np.abs(geo.ij[p, 0] - geo.ij[q, 0]),
                                      np.abs(geo.ij[p, 1] - geo.ij[q, 1])) >= 2)
        out.append((p[k], q[k], dist[k]))
        held += len(k)
        if held >= ROWS:
            yield from _in_chunks(out)
            out, held = [], 0
    yield from _in_chunks(out)


def _in_chunks(found: list[tuple[np.ndarray, np.ndarray, np.ndarray]]):
    """The pairs (p, q, dist) of ``found`` joined and cut into chunks of at most ROWS."""
    if not found:
        return
    p, q, dist = (np.concatenate(x) for x in zip(*found))
    for k in range(0, len(p), ROWS):
        yield p[k:k + ROWS], q[k:k + ROWS], dist[k:k + ROWS]


def _slack(geo: _Geometry, C: np.ndarray) -> float:
    """A bound on the float32 rounding error of a sphere gap or a relative displacement
    computed from centroids C (any shape) and the radii: 1e-5 (over a hundred units in
    the last place) times the largest coordinate plus the largest radius."""
    return 1e-5 * (float(np.abs(C).max(initial=0.0)) + float(geo.radius.max()))


def _gap(A: np.ndarray, B: np.ndarray, at: int = 0) -> np.ndarray:
    """Sphere gaps (n,): centre distance minus both radii, a lower bound on the distance of
    two panels, from the columns A, B (w, n) of a panel table with a centre in rows
    at..at+2 and the radius in row 3."""
    d = [A[at + k] - B[at + k] for k in range(3)]
    return np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]) - A[3] - B[3]


def _shift(A: np.ndarray, B: np.ndarray, at: int) -> np.ndarray:
    """Relative displacement (n,) of two panels' centres, |D_p - D_q|, from the columns
    A, B (w, n) of a panel table with the centres' displacements in rows at..at+2."""
    d = [A[at + k] - B[at + k] for k in range(3)]
    return np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])


def panel_distance(geo: _Geometry, S: np.ndarray, s: np.ndarray, p: np.ndarray,
                   q: np.ndarray) -> np.ndarray:
    """Distances (n,) between panels p and q (n,) in states S[s] (S: (K, V, 3)), 0 on
    contact. ``geo`` is the pattern (or the panel bookkeeping :func:`collisions` made of
    it), S holds states of its V vertices; every argument is checked
    (:class:`~rffqm_nlp.errors.InputError`)."""
    if isinstance(geo, Pattern):
        geo = _Geometry(geo)
    if not isinstance(geo, _Geometry):
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
    return finite_result(_panel_distance(geo, S, s, p, q), "the panel distances are not "
                         "finite (degenerate panels or coordinates too large)")


def _indices(x: Any, name: str, high: int) -> np.ndarray:
    """A 1-D array of whole numbers in [0, high)."""
    arr = finite_array(x, name, ndim=1, allowed=f"a 1-D array of whole numbers in [0, {high})")
    if np.any(arr != np.round(arr)) or np.any(arr < 0) or np.any(arr >= high):
        raise InputError(f"{name} must be a 1-D array of whole numbers in [0, {high}), got "
                         f"values from {arr.min():g} to {arr.max():g}")
    return arr.astype(np.int64)


def _panel_distance(geo: _Geometry, S: np.ndarray, s: np.ndarray, p: np.ndarray,
                    q: np.ndarray) -> np.ndarray:
    return _quad_distance(S[s[:, None], geo.corners[p]], S[s[:, None], geo.corners[q]],
                          geo.scale)


def _quad_distance(P: np.ndarray, Q: np.ndarray, scale: float) -> np.ndarray:
    """Distances (n,) between the panels with corners P and Q (n, 4, 3) (a, b, c, d), 0 on
    contact: the smallest of their four triangle pairs."""
    TP = P[:, _TRIANGLES][:, _TRI_PAIRS[:, 0]]                      # (n, 4, 3, 3)
    TQ = Q[:, _TRIANGLES][:, _TRI_PAIRS[:, 1]]
    TP, TQ = TP.reshape(-1, 3, 3), TQ.reshape(-1, 3, 3)
    d = np.concatenate([_triangle_distance(TP[k:k + CHUNK], TQ[k:k + CHUNK], scale)
                        for k in range(0, len(TP), CHUNK)] or [np.zeros(0)])
    return _least(d.reshape(-1, 4))


def _centroid(Q: np.ndarray) -> np.ndarray:
    """Centroids (..., 3) of the panel corners Q (..., 4, 3)."""
    return (Q[..., 0, :] + Q[..., 1, :] + Q[..., 2, :] + Q[..., 3, :]) / 4


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
    nA = _cross(eA[:, 0], eA[:, 1])
    nB = _cross(eB[:, 0], eB[:, 1])
    hit = ~_separated(np.stack([nA, nB], axis=1), A, B, scale).any(axis=1)
    k = np.flatnonzero(hit)                  # the normals do not separate: the other 15
    if k.size:
        eA, eB, nA, nB = eA[k], eB[k], nA[k], nB[k]
        axes = np.concatenate([_cross(eA[:, :, None], eB[:, None, :]).reshape(-1, 9, 3),
                               _cross(nA[:, None], eA), _cross(nB[:, None], eB)], axis=1)
        hit[k] = ~_separated(axes, A[k], B[k], scale).any(axis=1)
    return hit


def _separated(axes: np.ndarray, A: np.ndarray, B: np.ndarray, scale: float) -> np.ndarray:
    """Whether each axis (n, k, 3) separates triangles A and B (n, 3, 3) by more than
    REL_EPS * scale * |axis|: (n, k) bool."""
    pA = _dot(axes[:, :, None], A[:, None])                          # (n, k, 3)
    pB = _dot(axes[:, :, None], B[:, None])
    eps = REL_EPS * scale * _norm(axes)
    gap = np.maximum(_least(pB) - _most(pA), _least(pA) - _most(pB))
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
    d = _least(seg.reshape(-1, 9))
    d = np.minimum(d, _least(_vertex_face_distance(A, B)))
    d = np.minimum(d, _least(_vertex_face_distance(B, A)))
    return np.where(_triangles_intersect(A, B, scale), 0.0, d)


def _segment_distance(P1, Q1, P2, Q2) -> np.ndarray:
    """Distances between segments [P1, Q1] and [P2, Q2] (broadcast (..., 3)) (Ericson 5.1.9)."""
    d1, d2, r = Q1 - P1, Q2 - P2, P1 - P2
    a = _dot(d1, d1)
    e = _dot(d2, d2)
    b = _dot(d1, d2)
    c = _dot(d1, r)
    f = _dot(d2, r)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-14 * a * e, np.clip((b * f - c * e) / denom, 0, 1), 0.0)
        t = (b * s + f) / e
        s = np.where(t < 0, np.clip(-c / a, 0, 1), np.where(t > 1, np.clip((b - c) / a, 0, 1), s))
    t = np.clip(t, 0, 1)
    return _norm(r + d1 * s[..., None] - d2 * t[..., None])


def _vertex_face_distance(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Distances (n, 3) from the vertices of A to the plane of B where the foot lies in B,
    inf elsewhere (the other closest features are covered by segment distances)."""
    n = _cross(B[:, 1] - B[:, 0], B[:, 2] - B[:, 0])
    nn = _norm(n)
    inside = np.ones(A.shape[:2], dtype=bool)
    for k in range(3):
        edge = B[:, (k + 1) % 3] - B[:, k]
        inside &= _dot(_cross(edge[:, None], A - B[:, k, None]), n[:, None]) >= 0
    with np.errstate(divide="ignore", invalid="ignore"):
        h = np.abs(_dot(A - B[:, 0, None], n[:, None])) / nn[:, None]
    return np.where(inside & (nn[:, None] > 0), h, np.inf)


# --------------------------------------------------------------------------- flat state

def _flat_overlaps(geo: _Geometry) -> list[PanelPair]:
    """Pairs of panels whose interiors overlap in the flat pattern (omega = 0): a
    separating-axis test on the eight edge normals of the pairs whose circumscribed discs
    overlap, row by row on a table (8, P) of the corners' x then y (a, c, d, b around)."""
    X = geo.pat.X.reshape(-1, 3)
    R = X[geo.corners[:, [0, 2, 3, 1]], :2].transpose(2, 1, 0).reshape(8, -1)
    C = np.stack([R[:4].sum(axis=0), R[4:].sum(axis=0)], axis=1) / 4
    pq = cKDTree(C).query_pairs(2 * geo.radius.max(), output_type="ndarray").reshape(-1, 2)
    d = C[pq[:, 0]] - C[pq[:, 1]]                                   # circumscribed discs
    pq = pq[np.hypot(d[:, 0], d[:, 1]) <= geo.radius[pq[:, 0]] + geo.radius[pq[:, 1]]]
    A, B = R.take(pq[:, 0], axis=1), R.take(pq[:, 1], axis=1)       # (8, n)
    hit = np.ones(len(pq), dtype=bool)
    for F in (A, B):
        for k in range(4):
            ax, ay = F[4 + k] - F[4 + (k + 1) % 4], F[(k + 1) % 4] - F[k]   # edge normal
            pA = [ax * A[i] + ay * A[4 + i] for i in range(4)]
            pB = [ax * B[i] + ay * B[4 + i] for i in range(4)]
            gap = np.maximum(_least_of(pB) - _most_of(pA), _least_of(pA) - _most_of(pB))
            hit &= gap <= -1e-9 * geo.scale * np.hypot(ax, ay)
    return sorted(geo.label(p, q) for p, q in pq[hit])


# --------------------------------------------------------------------------- motion

def _first_contact(geo: _Geometry, w_max: float, clearance: float,
                   tol: float) -> tuple[float | None, list[PanelPair]]:
    """The earliest |omega| in [0, |w_max|] with two panels within ``clearance``, signed.
    The coarse steps in order, their rows refined as the broad phase gives them, once at
    least ROWS are held (or at the end); no step that starts after the earliest contact
    found is looked at."""
    sign = -1.0 if w_max < 0 else 1.0
    W = abs(w_max)
    n_steps = max(1, int(np.ceil(W / MAX_STEP)))
    st = _States(geo, sign, np.linspace(0.0, W, n_steps + 1))
    found, held = _Contact(geo), []
    for a in range(n_steps):
        if st.omegas[a] > found.best:
            break
        for chunk in _coarse_rows(geo, st, a, clearance):
            held.append(chunk)
            if sum(len(rows) for rows, _ in held) >= ROWS:
                _refine(st, *_joined(held), clearance, tol, found)
                held = []
    if held:
        _refine(st, *_joined(held), clearance, tol, found)
    if not np.isfinite(found.best):
        return None, []
    return sign * float(found.best) if found.best > 0 else 0.0, found.pairs


def _joined(chunks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Chunks (rows (n, 4), bounds (n,)) put together."""
    return np.concatenate([r for r, _ in chunks]), np.concatenate([m for _, m in chunks])


class _Contact:
    """The earliest contact found so far: its |omega| ``best`` (inf: none) and the panel
    pairs in contact there (1-based labels, sorted)."""

    def __init__(self, geo: _Geometry):
        self.geo, self.best, self.pairs = geo, np.inf, []

    def record(self, w: np.ndarray, hit: np.ndarray, p: np.ndarray, q: np.ndarray) -> None:
        """Take the pairs p, q (n,) in contact (``hit`` (n,) bool) at the |omega| w (n,)
        into account."""
        if not hit.any() or w[hit].min() > self.best:
            return
        w_hit = w[hit].min()
        at = hit & (w == w_hit)
        new = [self.geo.label(a, b) for a, b in zip(p[at], q[at])]
        self.pairs = sorted(set(new + (self.pairs if w_hit == self.best else [])))
        self.best = w_hit


def _refine(st: _States, rows: np.ndarray, m: np.ndarray, clearance: float, tol: float,
            found: _Contact) -> None:
    """Follow the rows (n, 4) = (state a, state b, p, q), with upper bounds m (n,) on the
    change of their distance (inf: none yet), into the halves of their steps until each
    is certified clear, in contact at a sample, or shorter than ``tol``; contacts go to
    ``found``, rows that start after its earliest contact are dropped. In batches of at
    most ROWS rows (a stack of the halves still to follow)."""
    stack = [(rows, m)]
    while stack:
        rows, m = stack.pop()
        if len(rows) > ROWS:
            stack.append((rows[ROWS:], m[ROWS:]))
            rows, m = rows[:ROWS], m[:ROWS]
        omegas = np.asarray(st.omegas)
        keep = omegas[rows[:, 0]] <= found.best
        rows, m = rows[keep], m[keep]
        if not rows.size:
            continue
        ia, ib, p, q = rows.T
        wa, wb, n = omegas[ia], omegas[ib], len(rows)
        d = _per_state(_lower_bound, st, np.concatenate([ia, ib]), np.tile(p, 2),
                       np.tile(q, 2))
        da, db = d[:n], d[n:]
        loose = (da + db - m) / 2 <= clearance      # m so far an upper bound (inf: none)
        m[loose] = SAFETY * _in_batches(_motion, st, ia[loose], ib[loose], p[loose], q[loose])
        exact = (da + db - m) / 2 <= clearance
        k = int(exact.sum())
        d = _per_state(_distance, st, np.concatenate([ia[exact], ib[exact]]),
                       np.tile(p[exact], 2), np.tile(q[exact], 2))
        da[exact], db[exact] = d[:k], d[k:]
        for w_s, d_s in ((wa, da), (wb, db)):
            found.record(w_s, exact & (d_s <= clearance), p, q)
        open_ = ((da + db - m) / 2 <= clearance) & (da > clearance) & (wb - wa > tol)
        if open_.any():
            halves = _split(rows[open_], st)
            stack.append((halves, np.full(len(halves), np.inf)))


class _States:
    """The folded states visited along the motion, grown as steps are halved.

    ``omegas``: their |omega| (a list, K entries); ``T`` (K, 19, P): each state's panel
    table, one row per quantity (gathers by column are several times faster than by
    panel): row 4 c + k the coordinate c of corner k (a, b, c, d), rows 12-14 the
    centroid, 15-17 the unit normal, 18 the radius. Its storage doubles as states are
    added (halving steps adds a few states at a time).
    """

    def __init__(self, geo: _Geometry, sign: float, omegas: np.ndarray):
        self.geo, self.sign, self.omegas, self._at = geo, sign, [], {}
        self._T = np.zeros((0, _ROWS, geo.N * geo.M))
        self.add(omegas)

    @property
    def T(self) -> np.ndarray:
        """The panel tables (K, 19, P) of the states so far (a contiguous view)."""
        return self._T[:len(self.omegas)]

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
            grown = np.empty((max(2 * len(self._T), K + k), *self._T.shape[1:]))
            grown[:K] = self._T[:K]
            self._T = grown
        Y = np.ascontiguousarray(self.geo.states(self.sign * omegas).transpose(0, 2, 1))
        T = self._T[K:K + k]                                             # Y: (k, 3, V)
        T[:, :12] = Y.take(self.geo.corners.T, axis=2).reshape(k, 12, -1)
        X = T[:, :12].reshape(k, 3, 4, -1)                               # (k, 3, 4, P)
        T[:, 12:15] = (X[:, :, 0] + X[:, :, 1] + X[:, :, 2] + X[:, :, 3]) / 4
        u, v = X[:, :, 3] - X[:, :, 0], X[:, :, 2] - X[:, :, 1]          # (k, 3, P)
        n = np.stack([u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                      u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]], axis=1)
        T[:, 15:18] = n / np.sqrt(n[:, 0] ** 2 + n[:, 1] ** 2 + n[:, 2] ** 2)[:, None]
        T[:, 18] = self.geo.radius
        self._at.update((w, K + i) for i, w in enumerate(omegas.tolist()))
        self.omegas.extend(omegas.tolist())


def _columns(st: _States, s: np.ndarray, p: np.ndarray, rows: slice = slice(0, 19)) -> np.ndarray:
    """The table rows ``rows`` (r, n) of panels p in states s (both (n,)): one np.take on
    the flattened tables."""
    T = st.T
    R, P = T.shape[1:]
    at = np.arange(R)[rows] * P
    return T.reshape(-1).take((s * (R * P) + p)[None] + at[:, None], mode="clip")


def _quads(st: _States, s: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Corners (n, 4, 3) of panels p in states s (both (n,))."""
    return np.ascontiguousarray(_columns(st, s, p, slice(0, 12)).reshape(3, 4, -1).T)


def _normals(st: _States, s: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Unit normals (n, 3) of panels p in states s (both (n,))."""
    return np.ascontiguousarray(_columns(st, s, p, slice(15, 18)).T)


def _motion(st: _States, ia, ib, p, q) -> np.ndarray:
    """Bounds (n,) on how far the distance of panels p and q can change from state ia to
    state ib (all (n,)): the smallest of the largest displacement of a vertex of q
    relative to a vertex of p (16 vertex pairs) and the largest displacement of a vertex
    of one panel in the frame of the other (4 vertices, both ways)."""
    Pa, Pb, Qa, Qb = (_quads(st, s, x) for s, x in ((ia, p), (ib, p), (ia, q), (ib, q)))
    dP, dQ = Pb - Pa, Qb - Qa                                        # (n, 4, 3)
    m = _most(_norm(dQ[:, None] - dP[:, :, None]).reshape(-1, 16))
    for A, B, C, D, x in ((Pa, Pb, Qa, Qb, p), (Qa, Qb, Pa, Pb, q)):   # C, D in A's frame
        La, Lb = _local(A, _normals(st, ia, x), C), _local(B, _normals(st, ib, x), D)
        m = np.minimum(m, _most(_norm(Lb - La)))
    return m


def _local(A: np.ndarray, n: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Coordinates (n, 4, 3) of the points B (n, 4, 3) in the frame of the panel with
    corners A (n, 4, 3) and unit normal n (n, 3): origin at corner a, axes along a -> b,
    the normal's cross product with it, and the normal."""
    e1 = A[:, 1] - A[:, 0]
    e1 = e1 - _dot(e1, n)[:, None] * n
    e1 = e1 / _norm(e1)[:, None]
    e2 = _cross(n, e1)
    r = B - A[:, :1]
    return np.stack([_dot(r, e1[:, None]), _dot(r, e2[:, None]), _dot(r, n[:, None])], axis=-1)


def _lower_bound(st: _States, s, p, q) -> np.ndarray:
    """Cheap lower bounds (n,) on the distances of panels p and q in states s (all (n,)):
    the largest of the bounding spheres' gap, the plane gap (how far one panel lies
    wholly on one side of the other's plane) and the gap between the panels' projections
    on the line through their centroids (a separating axis that certifies most pairs of
    nearly flat or nearly parallel neighbours). Computed row by row on the panel tables."""
    A, B = _columns(st, s, p), _columns(st, s, q)                   # (19, n)
    u = B[12:15] - A[12:15]
    dist = np.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    lb = dist - A[18] - B[18]
    for F, G in ((A, B), (B, A)):                # G's corners over F's plane, from F's a
        h = [F[15] * (G[k] - F[0]) + F[16] * (G[4 + k] - F[4]) + F[17] * (G[8 + k] - F[8])
             for k in range(4)]
        lb = np.maximum(lb, np.maximum(_least_of(h), -_most_of(h)))
    with np.errstate(divide="ignore", invalid="ignore"):
        u /= dist
    along = [[u[0] * F[k] + u[1] * F[4 + k] + u[2] * F[8 + k] for k in range(4)] for F in (A, B)]
    gap = _least_of(along[1]) - _most_of(along[0])                 # along the centres
    return np.maximum(lb, np.where(dist > 0, gap, -np.inf))


def _distance(st: _States, s, p, q) -> np.ndarray:
    """Exact distances (n,) of panels p and q in states s (all (n,))."""
    return _quad_distance(_quads(st, s, p), _quads(st, s, q), st.geo.scale)


def _per_state(f, st: _States, s, p, q) -> np.ndarray:
    """f(st, s, p, q) (n,) computed once for each distinct (state, pair) among the n, in
    batches of ``BATCH`` (their temporaries stay in cache)."""
    P = st.geo.N * st.geo.M
    first, inv = _distinct((s * P + p) * P + q)
    s, p, q = s[first], p[first], q[first]
    out = [f(st, s[k:k + BATCH], p[k:k + BATCH], q[k:k + BATCH])
           for k in range(0, len(s), BATCH)]
    return np.concatenate(out or [np.zeros(0)])[inv]


def _in_batches(f, st: _States, *index: np.ndarray) -> np.ndarray:
    """f(st, *index) (n,) for the index arrays (all (n,)), in batches of ``BATCH``."""
    n = len(index[0])
    out = [f(st, *(x[k:k + BATCH] for x in index)) for k in range(0, n, BATCH)]
    return np.concatenate(out or [np.zeros(0)])


def _distinct(code: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (u,) of one occurrence of each distinct value of ``code`` (n,) and the
    index (n,) of every entry's value among them (by sorting)."""
    order = np.argsort(code, kind="stable")
    c = code[order]
    new = np.ones(len(c), dtype=bool)
    new[1:] = c[1:] != c[:-1]
    inv = np.empty(len(c), dtype=np.int64)
    inv[order] = np.cumsum(new) - 1
    return order[new], inv


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (length 3), broadcast; written out by component
    (NumPy's reductions over a short last axis are several times slower)."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross products over the last axis (length 3), broadcast."""
    u0, u1, u2, v0, v1, v2 = u[..., 0], u[..., 1], u[..., 2], v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], axis=-1)


def _norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis (length 3)."""
    return np.sqrt(_dot(v, v))


def _least(x: np.ndarray) -> np.ndarray:
    """Minimum over the (short) last axis, elementwise over its entries."""
    out = x[..., 0]
    for k in range(1, x.shape[-1]):
        out = np.minimum(out, x[..., k])
    return out


def _most(x: np.ndarray) -> np.ndarray:
    """Maximum over the (short) last axis, elementwise over its entries."""
    out = x[..., 0]
    for k in range(1, x.shape[-1]):
        out = np.maximum(out, x[..., k])
    return out


def _least_of(xs: list[np.ndarray]) -> np.ndarray:
    """Elementwise minimum of the arrays xs (all (n,))."""
    out = xs[0]
    for x in xs[1:]:
        out = np.minimum(out, x)
    return out


def _most_of(xs: list[np.ndarray]) -> np.ndarray:
    """Elementwise maximum of the arrays xs (all (n,))."""
    out = xs[0]
    for x in xs[1:]:
        out = np.maximum(out, x)
    return out


def _coarse_rows(geo: _Geometry, st: _States, a: int, clearance: float):
    """The rows (n, 4) = (a, a + 1, p, q) of the coarse step from state a to a + 1 of
    ``st``: every pair that the sphere gaps g(a), g(a + 1) and the rows' motion bound m do
    not certify clear, (g(a) + g(a + 1) - m) / 2 <= clearance; with those bounds m (n,),
    SAFETY times the centres' relative displacement plus each panel's largest vertex
    displacement about its centre (at least :func:`_motion`'s). In chunks (rows, m) of at
    most ROWS pairs, from the tree queries of :func:`_close_pairs` with the panels'
    reaches of :func:`_reach`, or, where those are far (TILE_REACH) and from MIN_TILES
    tiles on, of :func:`_local_pairs`."""
    Ta, Tb = st.T[a], st.T[a + 1]
    P = geo.N * geo.M
    C, D = Ta[12:15], Tb[12:15] - Ta[12:15]                          # (3, P)
    dQ = (Tb[:12] - Ta[:12]).reshape(3, 4, P) - D[:, None]
    spin = _most_of(list(np.sqrt(dQ[0] ** 2 + dQ[1] ** 2 + dQ[2] ** 2)))   # (P,)
    G = _reach(C, D, spin, geo.radius, clearance)
    eps = _slack(geo, np.stack([C, Tb[12:15]])) + 1e-5 * float(G.max())
    Y = np.concatenate([Tb[12:15], geo.radius[None], D, spin[None]])  # (8, P)
    far = np.median(G) > TILE_REACH * np.median(geo.radius)
    tiles = _tiles(geo) if far else None
    pairs = (_local_pairs(geo, tiles, C, D, spin, geo.radius + G, clearance, eps)
             if tiles is not None and len(tiles[2]) >= MIN_TILES
             else _close_pairs(geo, C.T, geo.radius + G, 2 * eps))
    for p, q, dist in pairs:
        A, B = Y.take(p, axis=1), Y.take(q, axis=1)                  # (8, n)
        m = SAFETY * (_shift(A, B, 4) + A[7] + B[7])
        g0 = dist - A[3] - B[3]
        kept = np.flatnonzero((g0 + _gap(A, B) - m) / 2 <= clearance + 2 * eps)
        rows = np.stack([np.full(len(kept), a), np.full(len(kept), a + 1), p[kept], q[kept]],
                        axis=1)
        yield rows, m[kept] + eps


def _fit_reach(L, r: np.ndarray, e: np.ndarray, spin: np.ndarray,
               clearance: float) -> np.ndarray:
    """The reaches G of panels with radii r, residuals e and spins (each (n,)) against an
    affine fit of spectral norm L (a float, or (n,) per panel): :func:`_reach`'s bound."""
    return (clearance + (SAFETY + 1) * (L * r + e) + SAFETY * spin) / (2 - (SAFETY + 1) * L)


def _reach(C: np.ndarray, D: np.ndarray, spin: np.ndarray, r: np.ndarray,
           clearance: float) -> np.ndarray:
    """The panels' reaches G (P,) over a step: every pair whose sphere gaps g(a), g(b) at
    its start and end and motion bound m = SAFETY (|D_p - D_q| + spin_p + spin_q) leave
    (g(a) + g(b) - m) / 2 <= clearance has g(a) <= G_p + G_q. From the centres C (3, P)
    at the start, their displacements D (3, P), the spins (P,) and radii r (P,).

    With an affine fit D_p = A C_p + t + e_p and L = |A| (spectral norm),
    |D_p - D_q| <= L |C_p - C_q| + |e_p| + |e_q|, |C_p - C_q| = g(a) + r_p + r_q and g(b) >=
    g(a) - |D_p - D_q|; so such a pair has g(a) (2 - (SAFETY + 1) L) <= 2 clearance + h_p +
    h_q, h = (SAFETY + 1) (L r + |e|) + SAFETY spin. The fit: least squares on the k
    leading principal directions of the centres (k = 0: A = 0, a translation; a sheet
    still nearly flat makes the third direction ill-conditioned), the k of the smallest
    largest reach among those with (SAFETY + 1) L < 2."""
    X = C - C.mean(axis=1, keepdims=True)
    E = D - D.mean(axis=1, keepdims=True)                           # t = mean(D) - A mean(C)
    lam, U = np.linalg.eigh(X @ X.T)                                # X's principal directions
    U, lam, EX = U[:, ::-1], lam[::-1], E @ X.T                     # largest first
    best = None
    for k in range(4):                           # A = E X^T U_k diag(1 / lam_k) U_k^T
        A = (EX @ U[:, :k] / np.where(lam[:k] > 0, lam[:k], np.inf)) @ U[:, :k].T
        L = float(np.linalg.norm(A, 2))
        if (SAFETY + 1) * L >= 2:
            continue
        G = _fit_reach(L, r, _norm((E - A @ X).T), spin, clearance)
        if best is None or (r + G).max() < (r + best).max():
            best = G
    return best


def _split(rows: np.ndarray, st: _States) -> np.ndarray:
    """Halve the steps of ``rows`` (n, 4): the child rows (2n, 4), the midpoint states
    not yet in ``st`` added to it."""
    first, inv = _distinct(rows[:, 0] * len(st.omegas) + rows[:, 1])
    w = np.asarray(st.omegas)
    mid = st.index((w[rows[first, 0]] + w[rows[first, 1]]) / 2)[inv]
    left = np.stack([rows[:, 0], mid, rows[:, 2], rows[:, 3]], axis=1)
    right = np.stack([mid, rows[:, 1], rows[:, 2], rows[:, 3]], axis=1)
    return np.concatenate([left, right])


def near_pairs(pattern: Pattern, Y: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of panels that share no vertex within ``reach`` in one state, for
    :mod:`rffqm_nlp.design.clearance`: the pairs (n, 2) (0-based panel indices p = (i-1) M +
    (j-1), p < q) whose bounding spheres in the folded vertices Y ((N+1, M+1, 3)) come
    within ``reach`` (the broad phase), and their exact distances (n,). Raises
    :class:`~rffqm_nlp.errors.InputError` for arguments of other kinds or shapes."""
    check_pattern(pattern, "pattern")
    Y = finite_array(Y, "Y", shape=(pattern.N + 1, pattern.M + 1, 3))
    reach = check_value(reach, Key("number", low=0.0, hint="(a distance)"), "reach")
    geo = _Geometry(pattern)
    S = Y.reshape(1, -1, 3)
    pq = _near_pairs(geo, geo.centres(S)[0], float(reach))
    s = np.zeros(len(pq), dtype=np.int64)
    return pq, finite_result(_panel_distance(geo, S, s, pq[:, 0], pq[:, 1]),
                             "the panel distances are not finite (degenerate panels or "
                             "coordinates too large)")
