"""Self-contact checks: narrow phase against a brute-force reference, the Miura-ori free,
a z-fold contact computed by hand, refinement, clearance, the paper's random recipe
(checked against a dense brute-force scan of every pair)."""

from __future__ import annotations

import importlib

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

import rffqm_nlp as rq
from rffqm_nlp.model import numpy_model as nm
from rffqm_nlp.contact import broad, motion
from rffqm_nlp.contact.collisions import (CollisionReport, collisions, near_pairs,
                                          panel_distance, triangle_distance,
                                          triangles_intersect)
from rffqm_nlp.contact.motion import frame_bound, pair_bound
from rffqm_nlp.contact.narrow import distance, lower_bound
from rffqm_nlp.contact.panels import Geometry, States
from rffqm_nlp.errors import InputError, MarchingError
from rffqm_nlp.model.lengths import side_length_lp


def non_adjacent(geo: Geometry, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Mask of the panel pairs p, q (n,) that share no vertex (row or column apart by 2 or
    more)."""
    i, j = geo.ij[:, 0], geo.ij[:, 1]
    return np.maximum(np.abs(i[p] - i[q]), np.abs(j[p] - j[q])) >= 2


def miura(n: int, m: int, alpha0: float = 1.2, layout: str = "zigzag_j") -> rq.Pattern:
    return nm.march(rq.miura_boundary(n, m, alpha0=alpha0, layout=layout))


def reference_distance(A: np.ndarray, B: np.ndarray) -> float:
    """Triangle distance as a small QP over barycentric coordinates (SLSQP, several starts)."""
    def f(x):
        return np.sum((x[:3] @ A - x[3:] @ B) ** 2)

    cons = [{"type": "eq", "fun": lambda x: x[:3].sum() - 1},
            {"type": "eq", "fun": lambda x: x[3:].sum() - 1}]
    best = np.inf
    for start in (np.full(6, 1 / 3), np.r_[1, 0, 0, 0, 1, 0], np.r_[0, 0, 1, 1, 0, 0]):
        res = minimize(f, start.astype(float), method="SLSQP", bounds=[(0, 1)] * 6,
                       constraints=cons, options={"ftol": 1e-14, "maxiter": 500})
        best = min(best, f(np.clip(res.x, 0, 1)))
    return float(np.sqrt(max(best, 0.0)))


def all_pair_distances(pat: rq.Pattern, omega: float) -> dict:
    """Every pair of panels sharing no vertex -> their distance (O(n^2) reference)."""
    geo = Geometry(pat)
    P = pat.N * pat.M
    p, q = np.triu_indices(P, 1)
    keep = non_adjacent(geo, p, q)
    p, q = p[keep], q[keep]
    Y = geo.states(np.array([omega]))
    d = panel_distance(geo, Y, np.zeros(len(p), dtype=int), p, q)
    return {geo.label(a, b): float(x) for a, b, x in zip(p, q, d)}


coord = st.floats(-2, 2, allow_nan=False, allow_infinity=False)
triangle = st.lists(coord, min_size=9, max_size=9).map(lambda v: np.reshape(v, (3, 3)))


def well_shaped(T: np.ndarray) -> bool:
    e = np.roll(T, -1, axis=0) - T
    area = np.linalg.norm(np.cross(e[0], e[1]))
    return area > 0.05 * max(np.sum(e * e, axis=1).max(), 1e-12)


# --------------------------------------------------------------------------- narrow phase

@settings(max_examples=150, deadline=None)
@given(triangle, triangle)
def test_triangle_distance_matches_reference(A, B):
    if not (well_shaped(A) and well_shaped(B)):
        return
    d = triangle_distance(A[None], B[None])[0]
    ref = reference_distance(A, B)
    assert d == pytest.approx(ref, abs=2e-5)
    hit = triangles_intersect(A[None], B[None])[0]
    assert hit == (d == 0.0)
    if ref > 1e-4:
        assert not hit


@settings(max_examples=60, deadline=None)
@given(triangle, st.floats(-1, 1), st.floats(0.0, 0.6), st.floats(0.0, 0.6))
def test_coplanar_triangles(A, shift, u, v):
    """A triangle and a copy moved within its plane by barycentric steps: they meet iff
    the reference distance is zero."""
    if not well_shaped(A):
        return
    B = A + shift * (u * (A[1] - A[0]) + v * (A[2] - A[0]))
    d = triangle_distance(A[None], B[None])[0]
    assert d == pytest.approx(reference_distance(A, B), abs=2e-5)


def test_piercing_triangles_intersect():
    A = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0]], dtype=float)
    B = np.array([[1, 1, -1], [1, 1, 1], [5, 5, 3]], dtype=float)   # an edge through A
    assert triangles_intersect(A[None], B[None])[0]
    assert triangle_distance(A[None], B[None])[0] == 0.0


# --------------------------------------------------------------------------- the motion

@pytest.mark.parametrize("n, m, alpha0, layout", [(3, 3, 1.2, "zigzag_j"),
                                                  (5, 4, 0.7, "zigzag_j"),
                                                  (4, 6, 1.0, "zigzag_i")])
def test_miura_free_up_to_folded_flat(n, m, alpha0, layout):
    pat = miura(n, m, alpha0, layout)
    for omega in (np.pi - 1e-3, -(np.pi - 1e-3)):
        rep = collisions(pat, omega)
        assert rep.free and rep.first_omega is None and rep.pairs == []
        assert rep.flat_overlaps == []


def zfold_contact(clearance: float, alpha0: float = 1.1, b: float = 1.0):
    """A 1 x 3 Miura row is a z-fold: panels (1, 1) and (1, 3) are parallel translates.
    Past a crease angle of pi/2 their distance is the plane gap w sin|gamma| with
    w = b sin(alpha0) the width of panel (1, 2); contact at sin|gamma| = clearance / w."""
    pat = nm.march(rq.miura_boundary(1, 3, a=3.0, b=b, alpha0=alpha0))
    w = b * np.sin(alpha0)
    gamma = np.pi - np.arcsin(clearance / w)
    _, gv = nm.fold_angles(pat, 1.0)
    k = np.tan(gv[0, 1] / 2) / np.tan(0.5)                            # tan(g/2) = k tan(w/2)
    omega = 2 * np.arctan(np.tan(gamma / 2) / abs(k))
    return pat, omega, w


def test_zfold_contact_by_hand():
    pat, omega_star, w = zfold_contact(0.3)
    dist = all_pair_distances(pat, omega_star)
    assert dist[((1, 1), (1, 3))] == pytest.approx(0.3, abs=1e-9)    # the formula holds
    rep = collisions(pat, np.pi, clearance=0.3)
    assert not rep.free and rep.pairs == [((1, 1), (1, 3))]
    assert omega_star <= rep.first_omega <= omega_star + 1e-4
    neg = collisions(pat, -np.pi, clearance=0.3)
    assert neg.first_omega == pytest.approx(-rep.first_omega, abs=1e-4)


def test_zfold_touches_only_when_folded_flat():
    pat, _, _ = zfold_contact(0.3)
    assert collisions(pat, np.pi - 1e-3).free
    rep = collisions(pat, np.pi)
    assert rep.pairs == [((1, 1), (1, 3))]
    assert rep.first_omega == pytest.approx(np.pi, abs=1e-4)


def test_first_omega_stable_under_refinement():
    pat, _, _ = zfold_contact(0.2, alpha0=0.8)
    coarse = collisions(pat, 3.0, clearance=0.2, tol=1e-4).first_omega
    fine = collisions(pat, 3.0, clearance=0.2, tol=1e-6).first_omega
    assert coarse is not None and abs(coarse - fine) <= 1e-4


def test_clearance_is_kept_until_first_contact():
    pat = miura(3, 4, alpha0=0.9)
    c = 0.2
    rep = collisions(pat, np.pi - 1e-3, clearance=c, tol=1e-6)
    assert rep.first_omega is not None and rep.pairs
    at = all_pair_distances(pat, rep.first_omega)
    for pair in rep.pairs:
        assert at[pair] == pytest.approx(c, abs=1e-4)
    before = all_pair_distances(pat, rep.first_omega - 1e-5)
    assert min(before.values()) >= c - 1e-9
    dense = np.linspace(0, rep.first_omega - 1e-5, 200)
    assert min(min(all_pair_distances(pat, w).values()) for w in dense) >= c - 1e-9


def test_flat_overlaps_of_a_fabricated_pattern():
    """Panel (1, 3) moved onto panel (1, 1) in the flat pattern overlaps it (and (1, 2))."""
    pat = miura(1, 4)
    X = np.array(pat.X)
    X[:, 2:4] = X[:, 0:2]
    fake = rq.Pattern(alpha=pat.alpha, beta=pat.beta, sigma=pat.sigma, lh=pat.lh,
                      lv=pat.lv, mu=pat.mu, X=X)
    rep = collisions(fake, 0.0)
    assert ((1, 1), (1, 3)) in rep.flat_overlaps and not rep.free
    assert collisions(pat, 0.0).flat_overlaps == []


def cross2(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def clipped_area(P: np.ndarray, Q: np.ndarray) -> float:
    """Area of the intersection of two convex polygons P, Q (k, 2), counterclockwise
    (Sutherland-Hodgman clipping of P by each edge of Q, then the shoelace formula)."""
    out = list(P)
    for a, b in zip(Q, np.roll(Q, -1, axis=0)):
        pts, out = out, []
        side = [cross2(b - a, x - a) for x in pts]
        for k, x in enumerate(pts):
            y, sx, sy = pts[(k + 1) % len(pts)], side[k], side[(k + 1) % len(pts)]
            if sx >= 0:
                out.append(x)
            if sx * sy < 0:
                out.append(x + (y - x) * sx / (sx - sy))
        if len(out) < 3:
            return 0.0
    x, y = np.array(out).T
    return 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


@pytest.mark.parametrize("seed", [0, 2, 3, 5])            # seeds whose panels stay convex
def test_flat_overlaps_match_clipped_areas(seed):
    """Fabricated flat patterns (the columns from j on slid back over the left part by a
    fraction t of a zigzag period, the rows from i on by t/2, vertices jittered; panels
    stay convex): the reported overlaps are the pairs whose quadrilaterals (a, c, d, b
    around) intersect in a positive area (clipping, every pair)."""
    rng = np.random.default_rng(seed)
    pat = miura(4, 6, alpha0=1.1)
    X = np.array(pat.X)
    j, i, t = rng.integers(2, 6), rng.integers(2, 4), rng.uniform(0.55, 0.95)
    X[:, j:] -= t * (X[:, j] - X[:, j - 2])[:, None]
    X[i:, :] -= t / 2 * (X[i] - X[i - 2])[None]
    X[..., :2] += rng.normal(0, 0.03, X[..., :2].shape)
    fake = rq.Pattern(alpha=pat.alpha, beta=pat.beta, sigma=pat.sigma, lh=pat.lh,
                      lv=pat.lv, mu=pat.mu, X=X)
    geo = Geometry(fake)
    quads = []
    for r in X.reshape(-1, 3)[geo.corners[:, [0, 2, 3, 1]], :2]:     # (4, 2) each
        turns = [cross2(r[(k + 1) % 4] - r[k], r[(k + 2) % 4] - r[(k + 1) % 4]) for k in range(4)]
        assert min(turns) > 0 or max(turns) < 0                      # convex
        quads.append(r if turns[0] > 0 else r[::-1])
    expected = sorted(geo.label(p, q) for p, q in zip(*np.triu_indices(len(quads), 1))
                      if clipped_area(quads[p], quads[q]) > 1e-9)
    assert expected and collisions(fake, 0.0).flat_overlaps == expected


def test_report_to_dict_and_inputs():
    rep = collisions(miura(2, 2), 1.0)
    assert isinstance(rep, CollisionReport)
    assert rep.to_dict() == {"free": True, "first_omega": None, "pairs": [],
                             "flat_overlaps": [], "omega_max": 1.0, "clearance": 0.0}
    for kw in ({"omega_max": 4.0}, {"omega_max": 1.0, "clearance": -1.0},
               {"omega_max": 1.0, "tol": 0.0}, {"omega_max": 1.0, "tol": "small"}):
        with pytest.raises(InputError, match=f"^{list(kw)[-1]} must "):
            collisions(miura(2, 2), **kw)


# --------------------------------------------------------------------------- paper's recipe

def random_recipe(seed: int) -> rq.Pattern:
    """The paper's Fig. Random recipe at 10 x 10: Miura angles +-0.1 pi, LP side lengths."""
    bd = rq.perturb_angles(rq.miura_boundary(10, 10), 0.1 * np.pi, seed)
    return nm.march(side_length_lp(bd))


def dense_min(pat: rq.Pattern, omegas: np.ndarray) -> float:
    """Smallest distance over every pair sharing no vertex and every omega (brute force)."""
    return min(min(all_pair_distances(pat, w).values()) for w in omegas)


@pytest.mark.parametrize("seed, clearance, omega_max", [(29, 0.003, 2.5), (22, 0.0015, 3.0)])
def test_random_recipe_contact_agrees_with_dense_scan(seed, clearance, omega_max):
    pat = random_recipe(seed)
    rep = collisions(pat, omega_max, clearance=clearance)
    assert not rep.free and rep.first_omega is not None and rep.pairs
    at = all_pair_distances(pat, rep.first_omega)
    for pair in rep.pairs:
        assert clearance - 1e-4 <= at[pair] <= clearance
    dense = np.linspace(0, rep.first_omega - 1e-4, 40)
    assert dense_min(pat, dense) > clearance


def test_random_recipe_free_agrees_with_dense_scan():
    pat = random_recipe(22)
    assert collisions(pat, 2.0).free
    assert dense_min(pat, np.linspace(0, 2.0, 40)) > 0


# --------------------------------------------------------------------------- the bounds

def test_cheap_bounds_hold_on_the_random_recipe():
    """Every pair sharing no vertex, at every coarse state of a random-recipe pattern: the
    cheap lower bound never exceeds the exact distance; between two states, the motion
    bounds (the frame bound and the vertex pairs') are each at least the change of the
    exact distance, the vertex pairs' is the largest relative displacement over the 16
    vertex pairs (brute force), and the frame bound is often far smaller."""
    pat = random_recipe(22)
    geo = Geometry(pat)
    states = States(geo, 1.0, np.linspace(0.0, 2.5, 11))
    p, q = np.triu_indices(pat.N * pat.M, 1)
    keep = non_adjacent(geo, p, q)
    p, q = p[keep], q[keep]
    tight = 0
    for k in range(11):
        s = np.full(len(p), k)
        lb, d = lower_bound(states, s, p, q), distance(states, s, p, q)
        assert np.all(lb <= d + 1e-12)
        tight += np.sum(lb > 0.5 * d)
    assert tight > 0.5 * 11 * len(p)              # and it is not a trivial bound
    a, b = np.full(len(p), 3), np.full(len(p), 4)
    Q = geo.states(np.array(states.omegas))[:, geo.corners]          # (11, P, 4, 3)
    dP = Q[4, p] - Q[3, p]
    dQ = Q[4, q] - Q[3, q]
    brute = np.linalg.norm(dQ[:, None, :, :] - dP[:, :, None, :], axis=3).max(axis=(1, 2))
    framed, paired = frame_bound(states, a, b, p, q), pair_bound(states, a, b, p, q)
    change = np.abs(distance(states, b, p, q) - distance(states, a, p, q))
    assert np.all(change <= framed + 1e-12) and np.all(change <= paired + 1e-12)
    np.testing.assert_allclose(paired, brute, rtol=1e-12)
    assert np.mean(framed < 0.5 * brute) > 0.1     # the panel frames do better for some


def coarse_rows(geo: Geometry, states: States, K: int, clearance: float):
    """The broad phase's rows (n, 4) and bounds (n,) of every step between the first K
    states, its chunks put together."""
    steps = [broad.step(geo, states, a, a + 1, clearance) for a in range(K - 1)]
    chunks = [c for s in steps for c in broad.coarse_rows(geo, states, s)]
    return np.concatenate([r for r, _ in chunks]), np.concatenate([m for _, m in chunks])


@pytest.mark.parametrize("make, seed, clearance, rows_at_once", [
    ("random", 29, 0.0, None), ("random", 29, 0.05, None),                  # one query a step
    ("random", 16, 0.0, None), ("random", 16, 0.05, None),
    ("random", 29, 0.0, 64), ("random", 16, 0.05, 64),       # blocks by decreasing reach
    ("miura", 0, 0.2, 64)])                                  # blocks in the grid's order
def test_coarse_rows_cover_every_pair_the_bounds_do_not_clear(make, seed, clearance,
                                                             rows_at_once, monkeypatch):
    """The broad phase (per coarse step, the panels' reaches; one tree query, or with few
    pairs allowed at once, blocks of panels queried against the panels from the block
    on) keeps every pair that a float64 scan of all pairs finds not cleared by its sphere
    gaps and motion bound over a coarse step, however far apart, with a motion bound at
    least as large, and each pair once a step."""
    pat = {"random": random_recipe, "miura": perturbed_miura}[make](seed)
    geo = Geometry(pat)
    K = 25
    states = States(geo, 1.0, np.linspace(0.0, 2.4, K))
    if rows_at_once:
        monkeypatch.setattr(broad, "ROWS", rows_at_once)
        chunks = [len(r) for a in range(K - 1) for r, _ in
                  broad.coarse_rows(geo, states, broad.step(geo, states, a, a + 1, clearance))]
        assert len(chunks) > 2 * (K - 1) and max(chunks) <= rows_at_once
    rows, m = coarse_rows(geo, states, K, clearance)
    got = {tuple(r): b for r, b in zip(rows.tolist(), m)}
    assert len(got) == len(rows)
    p, q = np.triu_indices(pat.N * pat.M, 1)
    keep = non_adjacent(geo, p, q)
    p, q = p[keep], q[keep]
    Q = geo.states(np.array(states.omegas))[:, geo.corners]          # (K, P, 4, 3)
    C, r = Q.mean(axis=2), geo.radius
    expected = 0
    for k in range(K - 1):
        g0 = np.linalg.norm(C[k, p] - C[k, q], axis=1) - r[p] - r[q]
        g1 = np.linalg.norm(C[k + 1, p] - C[k + 1, q], axis=1) - r[p] - r[q]
        dC = C[k + 1] - C[k]
        spin = np.linalg.norm(Q[k + 1] - Q[k] - dC[:, None], axis=2).max(axis=1)
        mk = 2.0 * (np.linalg.norm(dC[p] - dC[q], axis=1) + spin[p] + spin[q])
        need = (g0 + g1 - mk) / 2 <= clearance
        for a, b, bound in zip(p[need], q[need], mk[need]):
            assert got[(k, k + 1, a, b)] >= bound
        expected += need.sum()
    assert expected > 0 and len(rows) >= expected


@settings(max_examples=80, deadline=None)
@given(st.integers(0, 2 ** 32 - 1), st.floats(0.0, 0.3), st.floats(0.0, 0.5),
       st.floats(0.0, 0.3), st.sampled_from([0, 1, 2]))
def test_reaches_bound_every_pair_the_spheres_do_not_clear(seed, strain, noise, clearance, flat):
    """Random centres (flat in 0-2 directions), displacements an affine map plus noise,
    random radii and spins: every pair whose sphere gaps at both ends and motion bound
    leave (g(a) + g(b) - m) / 2 <= clearance has g(a) <= G_p + G_q (the reaches)."""
    rng = np.random.default_rng(seed)
    P = 40
    C = rng.normal(0, 3, (3, P))
    C[3 - flat:] *= 1e-9                                # a sheet (nearly) flat in some axes
    D = strain * rng.normal(0, 1, (3, 3)) @ C + rng.normal(0, 1, (3, 1)) \
        + noise * rng.normal(0, 1, (3, P))
    r, spin = rng.uniform(0.1, 1.0, P), rng.uniform(0.0, 0.2, P)
    G = broad.reach(C, D, spin, r, clearance)
    p, q = np.triu_indices(P, 1)
    g0 = np.linalg.norm(C[:, p] - C[:, q], axis=0) - r[p] - r[q]
    g1 = np.linalg.norm((C + D)[:, p] - (C + D)[:, q], axis=0) - r[p] - r[q]
    m = 2.0 * (np.linalg.norm(D[:, p] - D[:, q], axis=0) + spin[p] + spin[q])
    need = (g0 + g1 - m) / 2 <= clearance
    assert np.all(g0[need] <= (G[p] + G[q])[need] + 1e-9)


def perturbed_miura(seed: int) -> rq.Pattern:
    """A 6 x 6 Miura-ori (alpha0 = 1.2) with boundary angles perturbed by 0.02 pi."""
    return nm.march(rq.perturb_angles(rq.miura_boundary(6, 6, alpha0=1.2), 0.02 * np.pi, seed))


@pytest.mark.parametrize("make, seed, clearance, omega_max", [
    (perturbed_miura, 0, 0.4, 3.0), (perturbed_miura, 1, 0.2, 3.0),     # similar panels
    (random_recipe, 11, 0.03, 2.4), (random_recipe, 16, 0.03, 2.4)])    # very unequal
def test_coarse_rows_hold_every_contact_of_a_fine_scan(make, seed, clearance, omega_max):
    """Ground truth for the whole broad phase (trees, reaches, sphere gaps, float32 slack,
    motion bounds): every pair sharing no vertex that an all-pairs scan finds within the
    clearance at some omega of a coarse step (5 samples a step, its ends included) is a
    row of that step; and the reported first contact is no later than the scan's. The
    coarse steps are longer than the library's (more motion within one, larger
    reaches)."""
    pat = make(seed)
    geo = Geometry(pat)
    K = 4
    omegas = np.linspace(0.0, omega_max, K)
    rows, _ = coarse_rows(geo, States(geo, 1.0, omegas), K, clearance)
    got = {(a, geo.label(p, q)) for a, _, p, q in rows.tolist()}
    found, first = 0, np.inf
    for k in range(K - 1):
        for x in np.linspace(omegas[k], omegas[k + 1], 5):
            close = [pair for pair, d in all_pair_distances(pat, x).items() if d <= clearance]
            assert all((k, pair) in got for pair in close)
            found += len(close)
            first = min(first, x) if close else first
    assert found > 0
    rep = collisions(pat, omega_max, clearance=clearance)
    assert rep.first_omega is not None and rep.first_omega <= first


@pytest.mark.parametrize("make, seed, clearance, omega_max", [
    (random_recipe, 29, 0.003, 2.5), (random_recipe, 22, 0.0015, 3.0),
    (perturbed_miura, 0, 0.4, 3.0)])
def test_pairs_held_at_once_are_bounded_by_the_chunk_size(make, seed, clearance, omega_max,
                                                          monkeypatch):
    """With a small ROWS, every chunk of broad-phase rows and every batch the refinement
    evaluates (bounds at one state per row, exact distances at two) holds at most ROWS
    pairs (2 ROWS for the distances), there are many of them, and the report is the one
    of a single chunk."""
    pat = make(seed)
    whole = collisions(pat, omega_max, clearance=clearance)
    chunks, batches, per_row = [], [], []
    coarse, per_state, in_batches = broad.coarse_rows, motion.per_state, motion.in_batches

    def counted_rows(*args):
        for rows, m in coarse(*args):
            chunks.append(len(rows))
            yield rows, m

    def counted_per_state(f, st, s, p, q):
        batches.append(len(s))
        return per_state(f, st, s, p, q)

    def counted_in_batches(f, st, *index):
        per_row.append(len(index[0]))
        return in_batches(f, st, *index)

    monkeypatch.setattr(broad, "ROWS", 8)
    monkeypatch.setattr(broad, "coarse_rows", counted_rows)
    monkeypatch.setattr(motion, "per_state", counted_per_state)
    monkeypatch.setattr(motion, "in_batches", counted_in_batches)
    chunked = collisions(pat, omega_max, clearance=clearance)
    assert chunked == whole and not whole.free
    assert max(chunks) <= 8 and max(batches) <= 2 * 8 and max(per_row) <= 8
    assert len(chunks) > 3 * int(np.ceil(omega_max / motion.MAX_STEP))


@pytest.mark.parametrize("make, seed, clearance, omega_max, tile", [
    (random_recipe, 29, 0.0, 2.5, 3), (random_recipe, 16, 0.05, 2.4, 2),   # very unequal
    (perturbed_miura, 0, 0.4, 3.0, 2), (perturbed_miura, 1, 0.2, 3.0, 5)])  # similar panels
def test_tile_fits_give_the_rows_of_the_global_fit(make, seed, clearance, omega_max, tile,
                                                  monkeypatch):
    """The broad phase by grid tiles (each with its own affine fit, broad.local_pairs) keeps
    exactly the rows and bounds of every coarse step that the one global fit keeps
    (the global query), and the report is the same."""
    pat = make(seed)
    geo = Geometry(pat)
    omegas = np.linspace(0.0, omega_max, 8)

    def rows_and_report(min_tiles: int):
        monkeypatch.setattr(broad, "MIN_TILES", min_tiles)
        rows, m = coarse_rows(geo, States(geo, 1.0, omegas), len(omegas), clearance)
        order = np.lexsort(rows.T[::-1])
        return rows[order], m[order], collisions(pat, omega_max, clearance=clearance)

    monkeypatch.setattr(broad, "TILE", tile)
    monkeypatch.setattr(broad, "TILE_REACH", -np.inf)  # tiles in every step
    assert len(broad.tiles(geo)[2]) >= 4
    calls = []
    local_pairs = broad.local_pairs
    monkeypatch.setattr(broad, "local_pairs",
                        lambda *a: calls.append(1) or local_pairs(*a))
    rows, m, report = rows_and_report(1)
    assert len(calls) >= len(omegas) - 1  # every coarse step took the tiles
    global_rows, global_m, global_report = rows_and_report(10 ** 9)
    assert len(global_rows) > 0
    np.testing.assert_array_equal(rows, global_rows)
    np.testing.assert_array_equal(m, global_m)
    assert report == global_report


def test_tiles_only_where_the_global_reaches_are_far(monkeypatch):
    """A nearly uniformly folding sheet (the perturbed Miura-ori) keeps the global reaches
    a fraction of a panel: with the default TILE_REACH no coarse step takes the tiles
    however many there are; with TILE_REACH = 0 (every median reach is above it) each
    does."""
    pat = perturbed_miura(0)
    geo = Geometry(pat)
    omegas = np.linspace(0.0, 3.0, 8)
    monkeypatch.setattr(broad, "TILE", 2)
    monkeypatch.setattr(broad, "MIN_TILES", 1)
    calls = []
    local_pairs = broad.local_pairs
    monkeypatch.setattr(broad, "local_pairs",
                        lambda *a: calls.append(1) or local_pairs(*a))
    coarse_rows(geo, States(geo, 1.0, omegas), len(omegas), 0.0)
    assert calls == []
    monkeypatch.setattr(broad, "TILE_REACH", 0.0)
    coarse_rows(geo, States(geo, 1.0, omegas), len(omegas), 0.0)
    assert len(calls) == len(omegas) - 1


@pytest.mark.parametrize("call, words", [
    (lambda pat: collisions(pat.boundary, 1.0), "^pattern must be a crease pattern .*got a "
                                                "BoundaryData"),
    (lambda pat: collisions(pat, [1.0, 2.0]), r"^omega_max must be a single number in \[-pi, "
                                              r"pi\], got a list of 2 numbers"),
    (lambda pat: collisions(pat, "1"), "^omega_max must be a number"),
    (lambda pat: collisions(pat, 1.0, clearance=-1.0), "^clearance must be a finite number >= 0"),
    (lambda pat: collisions(pat, 1.0, tol=np.nan), "^tol must be a finite number > 0"),
    (lambda pat: triangle_distance(np.zeros((2, 3, 3)), np.zeros((1, 3, 3))),
     r"^B must be triangles \(2, 3, 3\)"),
    (lambda pat: triangles_intersect(np.zeros((1, 3, 3)), np.zeros((1, 3, 3)), scale=0),
     "^scale must be a finite number > 0"),
    (lambda pat: near_pairs(pat, np.zeros((2, 2, 3)), 1.0),
     r"^Y must be an array of finite numbers of shape \(3, 4, 3\)"),
    (lambda pat: panel_distance(None, np.zeros((1, 12, 3)), [0], [0], [1]),
     r"^geo must be the crease pattern \(rffqm_nlp.Pattern\) of the states"),
    (lambda pat: panel_distance(pat, np.zeros((1, 12, 3)), [0], [0], [6]),
     r"^q must be a 1-D array of whole numbers in \[0, 6\)"),
])
def test_bad_arguments_are_refused_in_one_line(call, words):
    pat = nm.march(rq.miura_boundary(2, 3))
    with pytest.raises(InputError, match=words) as exc:
        call(pat)
    assert "\n" not in str(exc.value)


def test_degenerate_triangles_have_no_distance_here():
    """Triangles whose corners lie on a line give no finite distance here: refused, not
    NaN; proper ones keep theirs."""
    line = np.array([[[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]])
    tri = np.array([[[0.0, 0, 1], [1, 0, 1], [0, 1, 1]]])
    assert triangle_distance(tri, tri + [0, 0, 2.0])[0] == pytest.approx(2.0)
    try:
        d = triangle_distance(line, tri)
    except InputError as exc:
        assert "degenerate" in str(exc)
    else:
        assert np.all(np.isfinite(d))



def test_clearance_helpers_refuse_bad_arguments():
    clearance = importlib.import_module("rffqm_nlp.design.clearance")
    pat = nm.march(rq.miura_boundary(2, 3))
    for call, words in (
            (lambda: clearance.closest(pat, [1.0, 2.0], 0.1), "^omega must be a single number"),
            (lambda: clearance.closest(pat, 1.0, -0.1), "^clearance must be a finite number"),
            (lambda: clearance.closest(pat.boundary, 1.0, 0.1), "^pattern must be a crease"),
            (lambda: clearance.panel_corners(0, 3), r"^N must be a whole number in \[1, "),
            (lambda: clearance.choose_axis(np.zeros((3, 3)), np.zeros((4, 3))),
             r"^P must be the corners \(4, 3\) of a panel"),
            (lambda: clearance.constrain(None, pat, 1.0, [[0, 1]], 0.1), "^nlp must be the "
                                                                         "design's NLP")):
        with pytest.raises(InputError, match=words):
            call()
    pairs, worst = clearance.closest(pat, 1.0, 0.01)
    assert pairs.shape[1] == 2 and (worst.pair is None) == (len(pairs) == 0)


# --------------------------------------------------------------------------- halving, blocks

def report_with(pat, omega_max, clearance, monkeypatch, split, one_query):
    """The report with motion.SPLIT_REACH = split and broad.ONE_QUERY = one_query, and the
    number of steps the broad phase looked at."""
    monkeypatch.setattr(motion, "SPLIT_REACH", split)
    monkeypatch.setattr(broad, "ONE_QUERY", one_query)
    calls = []
    step = broad.step
    monkeypatch.setattr(broad, "step", lambda *a: calls.append(1) or step(*a))
    return collisions(pat, omega_max, clearance=clearance), len(calls)


@pytest.mark.parametrize("make, seed, clearance, omega_max", [
    (random_recipe, 29, 0.003, 2.5), (random_recipe, 22, 0.0015, -3.0),   # in contact
    (random_recipe, 22, 0.0, 2.0), (random_recipe, 16, 0.03, 2.4),
    (perturbed_miura, 0, 0.4, 3.0), (perturbed_miura, 1, 0.2, -3.0)])
def test_halving_far_steps_and_blocks_keep_the_report(make, seed, clearance, omega_max,
                                                      monkeypatch):
    """Halving the steps whose reaches are far (motion.SPLIT_REACH: never, by default, or
    nearly every step) and the tree queries (one a step, or blocks of panels of similar
    reach, broad.ONE_QUERY) give the same report: the halves are the ones the refinement
    follows, so the samples that can report a contact are the same."""
    pat = make(seed)
    plain, n_plain = report_with(pat, omega_max, clearance, monkeypatch, np.inf, 10 ** 12)
    default, _ = report_with(pat, omega_max, clearance, monkeypatch, 2.0, 2 ** 17)
    halved, n_halved = report_with(pat, omega_max, clearance, monkeypatch, 0.25, 0)
    assert default == plain and halved == plain
    assert n_halved > n_plain


@settings(max_examples=12, deadline=None)
@given(st.integers(0, 1000), st.floats(0.0, 0.12), st.sampled_from([0.0, 0.05, 0.3]),
       st.sampled_from([2.5, -2.5, 3.1]))
def test_halving_keeps_the_report_of_perturbed_miuras(seed, perturbation, clearance, omega_max):
    """Perturbed Miura-ori (5 x 6, angles perturbed by up to 0.12 pi; in contact or free):
    the same report with every far step halved as without halving."""
    try:
        pat = nm.march(rq.perturb_angles(rq.miura_boundary(5, 6, alpha0=1.1),
                                         perturbation * np.pi, seed))
    except MarchingError:
        assume(False)
    with pytest.MonkeyPatch.context() as mp:
        plain, _ = report_with(pat, omega_max, clearance, mp, np.inf, 10 ** 12)
        halved, _ = report_with(pat, omega_max, clearance, mp, 0.25, 0)
    assert halved == plain


@pytest.mark.parametrize("make, seed, clearance", [(random_recipe, 29, 0.0),
                                                   (random_recipe, 16, 0.05),
                                                   (perturbed_miura, 0, 0.2)])
def test_blocks_of_similar_reach_give_the_rows_of_one_query(make, seed, clearance,
                                                            monkeypatch):
    """The tree queries by blocks of panels of similar reach (broad.CLASS) keep exactly the
    rows and bounds of one query a step."""
    pat = make(seed)
    geo = Geometry(pat)
    omegas = np.linspace(0.0, 2.4, 9)

    def rows_with(one_query: int):
        monkeypatch.setattr(broad, "ONE_QUERY", one_query)
        rows, m = coarse_rows(geo, States(geo, 1.0, omegas), len(omegas), clearance)
        order = np.lexsort(rows.T[::-1])
        return rows[order], m[order]

    one, blocks = rows_with(10 ** 12), rows_with(0)
    assert len(one[0]) > 0
    np.testing.assert_array_equal(one[0], blocks[0])
    np.testing.assert_array_equal(one[1], blocks[1])


def test_panel_frames_are_orthonormal_along_the_first_edge():
    """The frames of the panel table (rows: the axis along a -> b made normal to the
    panel's normal, the normal's cross product with it, the normal) at every state."""
    pat = random_recipe(22)
    geo = Geometry(pat)
    states = States(geo, 1.0, np.linspace(0.0, 2.5, 6))
    s, p = np.repeat(np.arange(6), pat.N * pat.M), np.tile(np.arange(pat.N * pat.M), 6)
    F, Q, n = states.frames(s, p), states.quads(s, p), states.normals(s, p)
    np.testing.assert_allclose(F @ F.transpose(0, 2, 1), np.broadcast_to(np.eye(3), F.shape),
                               atol=1e-12)
    np.testing.assert_array_equal(F[:, 2], n)
    edge = Q[:, 1] - Q[:, 0]
    along = edge - np.sum(edge * n, axis=1)[:, None] * n
    np.testing.assert_allclose(F[:, 0], along / np.linalg.norm(along, axis=1)[:, None],
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(F), 1.0, atol=1e-12)
