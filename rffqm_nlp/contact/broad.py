"""Broad phase of the contact checks: the panel pairs a step of the motion must look at.

:func:`coarse_rows` gives, for a step [w0, w1] (:class:`Step`), every pair that the step's sphere
gaps g(w0), g(w1) (centre distance minus both radii) and its cheapest motion bound m do
not certify clear, (g(w0) + g(w1) - m) / 2 <= clearance, however far apart, by
:class:`scipy.spatial.cKDTree` queries on the panel centres at w0.

* Reaches: with an affine fit of the centres' displacements over the step,
  D_p = A C_p + t + e_p (least squares on the centres' leading principal directions), and
  L the spectral norm of A, |D_p - D_q| <= L |C_p - C_q| + |e_p| + |e_q|, so every such
  pair has g(w0) <= G_p + G_q with a reach per panel G_p = (clearance + (SAFETY + 1)
  (L r_p + |e_p|) + SAFETY s_p) / (2 - (SAFETY + 1) L) (r its radius, s its spin: its
  largest vertex displacement about its centre; :func:`reach`). The tree queries find
  the centres within r_p + G_p + r_q + G_q (one query with twice the largest, or blocks
  of panels queried against the panels from the block on: in the grid's order when
  r + G is nearly the same for all, else by decreasing r + G in blocks of similar
  r + G, so that very unequal reaches do not make every query large). A
  folding sheet's centres move nearly affinely over a short step, so the reaches are a
  fraction of a panel. Every gap is lowered, every bound raised, by a small slack (a
  bound on the rounding).
* Tiles: near flat, though, a large sheet bends: one affine map misfits its
  displacements by about the same length whatever the panels' size, so the reaches grow
  to many panels (docs/collisions.md). The motion halves such steps
  (:func:`~rffqm_nlp.contact.motion.steps`) down to ``tol``; in one still left (the
  median reach above
  ``TILE_REACH`` panel radii), from ``MIN_TILES`` tiles of ``TILE`` x ``TILE`` panels on,
  each tile gets its own fit (:func:`local_pairs`): the bound above holds for any affine
  map, so a pair (p, q) with p in a tile and both residuals measured against that tile's
  fit needs g(w0) <= G_p + G_q with the tile's reaches too; a pair is a candidate when
  both the tile's and the global reaches allow it (a subset of the global candidates
  that keeps every pair they must give).
* Memory: no step's pairs are held at once. The tree queries give their pairs in chunks
  of about ``ROWS`` (the first block's count bounds it, each next block is sized from the
  last one's pairs per panel).

The broad phase adds no assumption to the motion's (:mod:`~rffqm_nlp.contact.motion`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from .panels import Geometry, States
from .vectors import column_norm, most_of, norm

#: Factor on a step's relative vertex displacement (chord) bounding its path: the
#: motion's one assumption (:mod:`~rffqm_nlp.contact.motion`), which the reaches share.
SAFETY = 2.0

#: Most panel pairs the broad phase and the refinement hold at once (tree query results,
#: candidate rows of a step, rows of a refinement level), so that the check's memory
#: grows like the pattern, not like its pairs.
ROWS = 2 ** 18

#: The broad phase takes the panels in the grid's order (blocks of nearby panels) when
#: their largest radius plus reach is at most this times the smallest, else by decreasing
#: radius plus reach (blocks of big panels queried with a big radius, the rest small).
SPREAD = 1.5
#: ... and then in blocks of panels whose radius plus reach is within this factor of the
#: block's largest (each block's query radius is twice its largest), unless the pattern
#: has at most ONE_QUERY pairs: then one query a step costs less than the blocks' trees.
CLASS = 1.3
ONE_QUERY = 2 ** 17

#: Panels a side of the grid's tiles, each with its own affine fit of a coarse step's
#: displacements in the broad phase (:func:`local_pairs`), used from MIN_TILES tiles on
#: (below, one query over the whole sheet costs less than a query per tile).
TILE = 24
MIN_TILES = 4
#: ... and only in a coarse step whose global reaches are large: their median above
#: TILE_REACH times the panels' median radius (a sheet folding nearly uniformly keeps them
#: a fraction of a panel, and there the tiles' fits cost more than they save).
TILE_REACH = 2.0


@dataclass(frozen=True, eq=False)
class Step:
    """A step of the motion from state ``a`` to state ``b`` of a :class:`States`, with what
    its broad phase reads: the panels' centres ``C`` (3, P) at a, their displacements ``D``
    (3, P) to b, their ``spin`` (P,) (largest vertex displacement about the centre), their
    reaches ``G`` (P,) (:func:`reach`), the ``clearance`` and ``eps``, a bound on the
    rounding of the gaps and displacements (:func:`_slack`); ``spread`` the median reach
    over the median panel radius (:meth:`far` reads it once a step for the halving and
    once for the tiles)."""

    a: int
    b: int
    C: np.ndarray
    D: np.ndarray
    spin: np.ndarray
    G: np.ndarray
    clearance: float
    eps: float
    spread: float

    def far(self, times: float) -> bool:
        """Whether the median reach exceeds ``times`` the median panel radius: how far the
        step's motion is from one affine map, in panels."""
        return self.spread > times


def step(geo: Geometry, st: States, a: int, b: int, clearance: float) -> Step:
    """The :class:`Step` from state ``a`` to state ``b`` of ``st``."""
    start, end = st.panels(a), st.panels(b)
    C, D = start.centre, end.centre - start.centre                  # (3, P)
    dQ = (end.corners - start.corners) - D[:, None]                 # (3, 4, P)
    spin = most_of(list(np.sqrt(dQ[0] ** 2 + dQ[1] ** 2 + dQ[2] ** 2)))   # (P,)
    G = reach(C, D, spin, geo.radius, clearance)
    eps = _slack(geo, np.stack([C, end.centre])) + 1e-5 * float(G.max())
    return Step(a, b, C, D, spin, G, clearance, eps,
                float(np.median(G)) / geo.median_radius)


def coarse_rows(geo: Geometry, st: States, s: Step):
    """The rows (n, 4) = (a, b, p, q) of the step ``s`` from state a to b of ``st``: every
    pair that the sphere gaps g(a), g(b) and the rows' motion bound m do not certify clear,
    (g(a) + g(b) - m) / 2 <= clearance; with those bounds m (n,), SAFETY times the
    centres' relative displacement plus each panel's largest vertex displacement about its
    centre (at least :func:`~rffqm_nlp.contact.motion.pair_bound`'s). In chunks (rows, m)
    of at most ROWS pairs, from the tree queries of :func:`_close_pairs` with the panels'
    reaches of :func:`reach`, or, where those are far (TILE_REACH) and from MIN_TILES tiles
    on, of :func:`local_pairs`."""
    end = st.panels(s.b).centre
    C, D, spin, r, eps, clearance = s.C, s.D, s.spin, geo.radius, s.eps, s.clearance
    grid = tiles(geo) if s.far(TILE_REACH) else None
    pairs = (local_pairs(geo, grid, C, D, spin, r + s.G, clearance, eps)
             if grid is not None and len(grid[2]) >= MIN_TILES
             else _close_pairs(geo, C.T, r + s.G, 2 * eps))
    for p, q, dist in pairs:
        rp, rq = r.take(p), r.take(q)
        m = SAFETY * (column_norm(D.take(p, axis=1) - D.take(q, axis=1))
                      + spin.take(p) + spin.take(q))
        g0 = dist - rp - rq
        g1 = column_norm(end.take(p, axis=1) - end.take(q, axis=1)) - rp - rq
        kept = np.flatnonzero((g0 + g1 - m) / 2 <= clearance + 2 * eps)
        rows = np.stack([np.full(len(kept), s.a), np.full(len(kept), s.b), p[kept], q[kept]],
                        axis=1)
        yield rows, m[kept] + eps


def pairs_within(geo: Geometry, C: np.ndarray, reach: float) -> np.ndarray:
    """Pairs (n, 2), p < q, sharing no vertex, whose bounding spheres about the centres
    C (P, 3) grown by ``reach`` overlap."""
    R = geo.radius + reach / 2
    chunks = [np.stack([p, q], axis=1)
              for p, q, _ in _close_pairs(geo, C, R, 2 * _slack(geo, C))]
    return np.concatenate(chunks or [np.zeros((0, 2), dtype=np.int64)])


# --------------------------------------------------------------------------- reaches

def _fit_reach(L, r: np.ndarray, e: np.ndarray, spin: np.ndarray,
               clearance: float) -> np.ndarray:
    """The reaches G of panels with radii r, residuals e and spins (each (n,)) against an
    affine fit of spectral norm L (a float, or (n,) per panel): :func:`reach`'s bound."""
    return (clearance + (SAFETY + 1) * (L * r + e) + SAFETY * spin) / (2 - (SAFETY + 1) * L)


def reach(C: np.ndarray, D: np.ndarray, spin: np.ndarray, r: np.ndarray,
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
    A = np.stack([(EX @ U[:, :k] / np.where(lam[:k] > 0, lam[:k], np.inf)) @ U[:, :k].T
                  for k in range(4)])                # A = E X^T U_k diag(1 / lam_k) U_k^T
    L = np.linalg.norm(A, 2, axis=(1, 2))
    ok = (SAFETY + 1) * L < 2                        # k = 0 (A = 0) always is
    V = E - A[ok] @ X                                # (k, 3, P)
    e = np.sqrt(V[:, 0] * V[:, 0] + V[:, 1] * V[:, 1] + V[:, 2] * V[:, 2])
    G = _fit_reach(L[ok, None], r, e, spin, clearance)
    return G[int(np.argmin((r + G).max(axis=1)))]


def _slack(geo: Geometry, C: np.ndarray) -> float:
    """A bound on the float32 rounding error of a sphere gap or a relative displacement
    computed from centroids C (any shape) and the radii: 1e-5 (over a hundred units in
    the last place) times the largest coordinate plus the largest radius."""
    return 1e-5 * (float(np.abs(C).max(initial=0.0)) + float(geo.radius.max()))


# --------------------------------------------------------------------------- tree queries

def _close_pairs(geo: Geometry, C: np.ndarray, R: np.ndarray, slack: float):
    """The pairs p < q sharing no vertex whose centres C (P, 3) are at most R_p + R_q +
    ``slack`` apart (R (P,) >= 0), with those distances, in chunks (p, q, dist) (n,) of at
    most ROWS pairs. When R varies by at most SPREAD, the panels in the grid's order. One
    query with twice the largest R when R varies by at most SPREAD or the pattern has at
    most ONE_QUERY pairs, and the first 64 (or fewer, halved until the tree counts at most
    ROWS pairs within twice the largest R of them) let it expect at most 0.7 ROWS pairs
    (all pairs fit in ROWS: no count). Otherwise each pair is found once, from the panel
    with the larger R: panels by decreasing R, a block of them queried (a tree of its own)
    against a tree on the panels from the block on, with twice the block's largest R; a
    block holds panels whose R is within CLASS of its first's (so that a few large panels
    do not make every query large), as many as the pairs per panel of the last query (or
    the first 64's) allow for 0.7 ROWS pairs."""
    uniform = R.max() <= SPREAD * R.min()
    order = np.arange(len(R)) if uniform else np.argsort(-R, kind="stable")
    X, R, ij = C[order], R[order], geo.ij[order]
    top = np.maximum.accumulate(R[::-1])[::-1]          # the largest R from each on
    P, c0, base = len(X), 0, 0
    rest = cKDTree(X)
    found, size = _first_block(rest, X, 2 * float(top[0]) + slack)
    one = uniform or P * (P - 1) // 2 <= ONE_QUERY
    if one and found * P / min(size, P) <= 1.4 * ROWS:   # ordered pairs, self included
        i, j = rest.query_pairs(2 * float(top[0]) + slack, output_type="ndarray").T
        yield from _kept(order, R, ij, i, j, norm(X[i] - X[j]), slack)
        return
    while c0 < P:
        if 2 * (c0 - base) > P - base:          # a smaller tree on the panels still to come
            base, rest = c0, cKDTree(X[c0:])
        c1 = min(P, c0 + size)
        if not uniform:                         # R decreasing: the panels within CLASS
            c1 = min(c1, max(c0 + 1, int(np.searchsorted(-R, -R[c0] / CLASS, "right"))))
        head = cKDTree(X[c0:c1])
        hits = head.sparse_distance_matrix(rest, float(R[c0:c1].max() + top[c0]) + slack,
                                           output_type="ndarray")
        i, j, dist = hits["i"] + c0, hits["j"] + base, hits["v"]
        size = max(1, int(0.7 * (c1 - c0) * ROWS / max(len(hits), 1)))
        del hits
        yield from _kept(order, R, ij, i, j, dist, slack)
        c0 = c1


def _first_block(tree: cKDTree, X: np.ndarray, radius: float) -> tuple[int, int]:
    """(found, size): the first ``size`` of the points X (P, 3) (64, or fewer, halved until
    at most ROWS) have ``found`` ordered pairs (self included) within ``radius`` among the
    points of ``tree`` (on X). Without a count when all pairs fit in ROWS: (P^2, P)."""
    P, size = len(X), 64
    if P * (P - 1) // 2 <= ROWS:
        return P * P, P
    while True:
        found = cKDTree(X[:size]).count_neighbors(tree, radius)
        if size == 1 or found <= ROWS:
            return found, size
        size //= 2


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


# --------------------------------------------------------------------------- tiles

def tiles(geo: Geometry) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The grid's tiles of TILE x TILE panels: the tile of each panel (P,), the panels in
    tile order (P,) and where each tile starts in that order (T,)."""
    nj = -(-geo.M // TILE)
    tile = (geo.ij[:, 0] // TILE) * nj + geo.ij[:, 1] // TILE
    perm = np.argsort(tile, kind="stable")
    starts = np.flatnonzero(np.r_[True, tile[perm][1:] != tile[perm][:-1]])
    return tile, perm, starts


def _tile_fits(C: np.ndarray, D: np.ndarray, spin: np.ndarray, r: np.ndarray,
               clearance: float, tile: np.ndarray, perm: np.ndarray, starts: np.ndarray):
    """:func:`reach`'s fit on each tile's panels alone, all tiles at once: L (T,), A
    (T, 3, 3), the mean centre and displacement (T, 3) and whether a fit with
    (SAFETY + 1) L < 2 exists (T,). C, D (3, P), spin and r (P,) as :func:`reach`'s."""
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
            e = norm(E - np.einsum("pij,pj->pi", A[t], X))
            G = _fit_reach(L[t], rs, e, ss, clearance)
            top = np.maximum.reduceat(rs + G, starts)
            ok = np.isfinite(L) & ((SAFETY + 1) * L < 2) & np.isfinite(top) & (top < best)
            best[ok], bestL[ok], bestA[ok] = top[ok], L[ok], A[ok]
    return bestL, bestA, mc, md, np.isfinite(best)


def local_pairs(geo: Geometry, grid: tuple[np.ndarray, np.ndarray, np.ndarray],
                C: np.ndarray, D: np.ndarray, spin: np.ndarray, Rg: np.ndarray,
                clearance: float, eps: float):
    """The pairs of :func:`_close_pairs` (C.T, Rg, 2 eps) that are also within the reaches
    of the affine fit of p's grid tile (:func:`_tile_fits`; both panels' residuals against
    that one fit, which bounds |D_p - D_q| as the global fit does): a superset of the pairs
    the step's filter keeps, found with far smaller queries where the sheet bends (one
    affine map fits a tile's displacements far better than the whole sheet's). C, D (3, P),
    spin (P,) as :func:`reach`'s, Rg (P,) the radii plus the global reaches, ``grid``
    the tiles of :func:`tiles`. In chunks (p, q, dist) of at most ROWS pairs."""
    r = geo.radius
    tile, perm, starts = grid
    L, A, mc, md, ok = _tile_fits(C, D, spin, r, clearance, tile, perm, starts)
    Ct = np.ascontiguousarray(C.T)
    e = norm(D.T - md[tile] - np.einsum("pij,pj->pi", A[tile], Ct - mc[tile]))
    own = np.where(ok[tile], r + _fit_reach(L[tile], r, e, spin, clearance), Rg)
    slack = np.where(ok, 4 * eps / (2 - (SAFETY + 1) * L) + 2 * eps, 2 * eps)
    groups = np.split(perm, starts[1:])
    centre = np.stack([Ct[g].mean(axis=0) for g in groups])
    rho = np.array([float(norm(Ct[g] - c).max()) for g, c in zip(groups, centre)])
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
            eq = norm(D.T[cand] - md[T] - (Ct[cand] - mc[T]) @ A[T].T)
            Rq = r[cand] + _fit_reach(L[T], r[cand], eq, spin[cand], clearance)
        else:
            Rq = Rg[cand]
        Rgq = Rg[cand]  # a pair must pass both: the tile's reaches and the global ones
        near = norm(Ct[cand] - centre[T]) <= rho[T] + np.minimum(
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
