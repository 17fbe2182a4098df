"""Invariant tests of the plain-NumPy forward model (docs/paper.md s.7)."""

from __future__ import annotations

import itertools
import math
import re

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from rffqm_nlp import BoundaryData, MarchingError, miura_boundary, perturb_angles
from rffqm_nlp.errors import InputError
from rffqm_nlp.model import numpy_model as nm
from rffqm_nlp.model.numpy_model import fold, fold_angles, gamma1_bar, gamma2_bar, march, mu1, mu2

from forward_oracle import fold_loop, march_loop

PI = np.pi
SETTINGS = settings(max_examples=60, deadline=None)
omegas = st.floats(-PI, PI)
interior_omegas = st.floats(1e-3, PI - 1e-3) | st.floats(-PI + 1e-3, -1e-3)


# --------------------------------------------------------------------------- helpers

def rot(t, gamma):
    """R_t(gamma) of eq:localRots with t_perp = -(t.e2) e1 + (t.e1) e2 (typo fixed)."""
    t = np.array([t[0], t[1], 0.0])
    tp, e3 = np.array([-t[1], t[0], 0.0]), np.array([0.0, 0.0, 1.0])
    tt = np.outer(t, t)
    return tt + np.cos(gamma) * (np.eye(3) - tt) + np.sin(gamma) * (
        np.outer(e3, tp) - np.outer(tp, e3))


def e(theta):
    return np.array([np.cos(theta), np.sin(theta)])


def vertex_tangents(alpha, beta):
    """t1..t4 of eq:tansLocal for t1 = e1 (t1 denominator typo fixed)."""
    return e(0.0), e(alpha), e(alpha + beta), e(beta - PI)


@st.composite
def vertices(draw):
    """Admissible (alpha, beta, sigma) kept away from the MV boundary."""
    a = draw(st.floats(0.05, PI - 0.05))
    b = draw(st.floats(0.05, PI - 0.05))
    s = draw(st.sampled_from([1.0, -1.0]))
    assume(abs(np.cos(b) - s * np.cos(a)) > 1e-2)
    return a, b, s


def perturbed_pattern(N, M, seed, amplitude=0.01 * PI):
    """A perturbed Miura with Miura lengths; None if it does not march."""
    bd = perturb_angles(miura_boundary(N, M, a=1.0, b=1.2, alpha0=1.1), amplitude, seed=seed)
    try:
        return march(bd)
    except MarchingError:
        return None


patterns = st.builds(perturbed_pattern, st.integers(1, 6), st.integers(1, 6),
                     st.integers(0, 10**6))


def panel_distances(P):
    """4 sides and 2 diagonals of every panel, (..., N, M, 6), for positions (..., N+1, M+1, 3)."""
    a, b, c, d = P[..., :-1, :-1, :], P[..., 1:, :-1, :], P[..., :-1, 1:, :], P[..., 1:, 1:, :]
    return np.stack([np.linalg.norm(u - v, axis=-1)
                     for u, v in ((a, b), (a, c), (b, d), (c, d), (a, d), (b, c))], axis=-1)


def unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rotations_both_ways(pat, omega):
    """Both formulas of eq:defGrads at the interior panels i, j > 1, from numpy_model's
    pieces: (R^{(i-1)j} R_{t1}(gamma_1^{ij}), R^{i(j-1)} R_{t2}(-gamma_2^{ij})), each
    (K, N-1, M-1, 3, 3); they agree on a compatible pattern."""
    w, _ = nm._omegas(omega)
    R = nm._panel_rotations(pat, w)
    _, k2 = nm._fold_tangent_factors(pat)
    _, phi_v = nm._edge_directions(pat.alpha, pat.beta)
    S, C = np.sin(w / 2)[:, None, None], nm._cos_half(w)[:, None, None]
    right = nm._crease_rotation(nm._unit(phi_v[1:, 1:-1]), -k2[1:-1, 1:-1], S, C)
    return R[:, 1:, 1:], R[:, 1:, :-1] @ right


# --------------------------------------------------------------------------- 1, 2: one vertex

@SETTINGS
@given(vertices(), omegas)
def test_vertex_loop_is_identity(v, omega):
    a, b, s = v
    g2 = gamma2_bar(omega, a, b, s)
    gammas = (omega, g2, -s * omega, s * g2)                         # eq:foldParams
    loop = np.eye(3)
    for t, g in zip(vertex_tangents(a, b), gammas):
        loop = loop @ rot(t, g)
    assert np.abs(loop - np.eye(3)).max() < 1e-12


@SETTINGS
@given(vertices(), omegas)
def test_gamma1_bar_inverts_gamma2_bar(v, omega):
    a, b, s = v
    assert abs(gamma1_bar(gamma2_bar(omega, a, b, s), a, b, s) - omega) < 1e-12
    assert abs(mu1(a, b, s) * mu2(a, b, s) - 1) < 1e-12


@SETTINGS
@given(vertices(), st.floats(0.1, PI - 0.1) | st.floats(-PI + 0.1, -0.1))
def test_gamma2_bar_matches_printed_arccos_form(v, omega):
    a, b, s = v
    num = (-s + np.cos(a) * np.cos(b)) * np.cos(omega) + np.sin(a) * np.sin(b)
    den = -s + np.cos(a) * np.cos(b) + np.sin(a) * np.sin(b) * np.cos(omega)
    printed = np.sign((s * np.cos(b) - np.cos(a)) * omega) * np.arccos(np.clip(num / den, -1, 1))
    assert abs(gamma2_bar(omega, a, b, s) - printed) < 1e-6


@SETTINGS
@given(vertices(), interior_omegas)
def test_maekawa(v, omega):
    a, b, s = v
    g2 = gamma2_bar(omega, a, b, s)
    assert np.sin(omega) * np.sin(g2) * np.sin(-s * omega) * np.sin(s * g2) < 0


@SETTINGS
@given(vertices())
def test_sigma_is_minus_the_sign_of_log_abs_mu2(v):
    """|mu_2^{-1}| > 1 > |mu_2^{+1}| (|cos((a-b)/2)|, |sin((a-b)/2)| over the (a+b)/2 ones),
    the reason for sigma_d = -sign(mu_abc^2 - 1) in eq:marchingFinal."""
    a, b, s = v
    assert s * (abs(mu2(a, b, s)) - 1) < 0


@SETTINGS
@given(patterns)
def test_marched_vertices_are_admissible(pat):
    assume(pat is not None)
    a, b, s = pat.alpha, pat.beta, pat.sigma
    assert np.all((a > 0) & (a < PI) & (b > 0) & (b < PI))
    assert np.all(np.abs(np.cos(b) - s * np.cos(a)) > 1e-10)          # s in MV(a, b)
    assert np.all(s * (np.abs(mu2(a, b, s)) - 1) < 0)
    assert np.all(np.abs(pat.mu - mu2(PI - a[1:, 1:], PI - b[1:, 1:], s[1:, 1:])) < 1e-9 * (
        1 + np.abs(pat.mu)))                                            # mu_abc = mu_2d


# --------------------------------------------------------------------------- 3: panels

@SETTINGS
@given(patterns, st.lists(omegas, min_size=1, max_size=3))
def test_panel_compatibility(pat, ws):
    assume(pat is not None and pat.N > 1 and pat.M > 1)
    from_below, from_left = rotations_both_ways(pat, ws)
    assert np.abs(from_below - from_left).max() < 1e-12
    gh, _ = fold_angles(pat, np.array(ws))
    s = pat.sigma[1:-1, 1:-1]
    # gamma_3^{ij} = -sigma^{ij} gamma_1^{ij} (eq:foldParams) is the crease gamma_1^{i(j-1)}
    assert np.abs(-s * gh[:, 1:-1, 1:] - gh[:, 1:-1, :-1]).max() < 1e-12


@SETTINGS
@given(patterns, interior_omegas)
def test_pattern_vertex_loops_and_maekawa(pat, omega):
    assume(pat is not None and pat.N > 1 and pat.M > 1)
    gh, gv = fold_angles(pat, omega)
    X = pat.X
    for p in range(1, pat.N):
        for q in range(1, pat.M):
            nbrs = (X[p, q + 1], X[p + 1, q], X[p, q - 1], X[p - 1, q])
            gammas = (gh[p, q], gv[p, q], gh[p, q - 1], gv[p - 1, q])
            loop = np.eye(3)
            for x, g in zip(nbrs, gammas):
                loop = loop @ rot(unit(x - X[p, q]), g)
            assert np.abs(loop - np.eye(3)).max() < 1e-12
            assert np.prod(np.sin(gammas)) < 0


@SETTINGS
@given(patterns, interior_omegas)
def test_fold_angles_are_the_dihedral_angles_of_the_folded_state(pat, omega):
    """gamma > 0 is a valley seen from +e3: measured from fold() with the sign of eq:localRots."""
    assume(pat is not None)
    Y = fold(pat, omega)
    gh, gv = fold_angles(pat, omega)
    n = unit(np.cross(Y[:-1, 1:] - Y[:-1, :-1], Y[1:, :-1] - Y[:-1, :-1]))   # panel normals
    T = unit(Y[1:-1, 1:] - Y[1:-1, :-1])
    lo, hi = n[:-1], n[1:]
    meas = np.arctan2(np.sum(np.cross(lo, hi) * T, -1), np.sum(lo * hi, -1))
    assert np.allclose(meas, gh[1:-1], atol=1e-10)
    T = unit(Y[1:, 1:-1] - Y[:-1, 1:-1])
    left, right = n[:, :-1], n[:, 1:]
    meas = np.arctan2(np.sum(np.cross(right, left) * T, -1), np.sum(right * left, -1))
    assert np.allclose(meas, gv[:, 1:-1], atol=1e-10)
    assert np.all(gh[[0, -1]] == 0) and np.all(gv[:, [0, -1]] == 0)


# --------------------------------------------------------------------------- 4: isometry

@SETTINGS
@given(patterns, st.lists(omegas, min_size=1, max_size=4))
def test_isometry_small(pat, ws):
    assume(pat is not None)
    Y = fold(pat, np.array(ws))
    ref = panel_distances(pat.X)
    assert np.abs(panel_distances(Y) - ref).max() < 1e-12 * ref.max()
    assert np.all(np.isfinite(Y))


def flat_closure_error(pat):
    """Max distance between the two ways of reaching each panel's d corner in X (via c and
    via b), with directions from the panel angles, plus the edge-length mismatch."""
    X = pat.X
    aa, ab, ac, _ = np.moveaxis(pat.panel_angles, -1, 0)
    ea = X[:-1, 1:] - X[:-1, :-1]
    th = np.arctan2(ea[..., 1], ea[..., 0])
    l_cd, l_bd = pat.lv[:, 1:], pat.lh[1:]
    via_c = X[:-1, 1:, :2] + l_cd[..., None] * np.moveaxis(e(th + PI - ac), 0, -1)
    via_b = X[1:, :-1, :2] + l_bd[..., None] * np.moveaxis(e(th + aa + PI + ab), 0, -1)
    err = max(np.abs(via_c - X[1:, 1:, :2]).max(), np.abs(via_b - X[1:, 1:, :2]).max())
    lengths = max(np.abs(np.linalg.norm(np.diff(X, axis=1), axis=-1) - pat.lh).max(),
                  np.abs(np.linalg.norm(np.diff(X, axis=0), axis=-1) - pat.lv).max())
    return max(err, lengths)


def test_isometry_and_flat_consistency_large():
    pat = perturbed_pattern(120, 110, seed=1, amplitude=1e-3 * PI)
    assert pat is not None
    diam = np.ptp(pat.X[..., :2], axis=(0, 1)).max()
    assert flat_closure_error(pat) < 1e-11 * diam
    ref = panel_distances(pat.X)
    Y = fold(pat, np.array([-PI, -1.0, 0.3, 2.5, PI]))
    assert np.abs(panel_distances(Y) / ref - 1).max() < 1e-9
    assert np.all(np.isfinite(Y))


# --------------------------------------------------------------------------- 5: flat states

@SETTINGS
@given(patterns)
def test_flat_and_folded_flat_states(pat):
    assume(pat is not None)
    assert np.array_equal(fold(pat, 0.0), pat.X)
    assert np.all(pat.X[..., 2] == 0) and np.all(pat.X[0, 0] == 0)
    assert pat.X[0, 1, 1] == 0 and pat.X[0, 1, 0] > 0
    for w in (PI, -PI):
        Y = fold(pat, w).reshape(-1, 3)
        sv = np.linalg.svd(Y - Y.mean(axis=0), compute_uv=False)
        assert sv[-1] < 1e-12 * sv[0]


# --------------------------------------------------------------------------- 6: Miura

def schenk_guest(a, b, alpha0, theta):
    """H, S, L, V of the Schenk & Guest (2013) unit cell (docs/paper.md s.6)."""
    q = np.sqrt(1 + np.cos(theta) ** 2 * np.tan(alpha0) ** 2)
    return (a * np.sin(theta) * np.sin(alpha0), b * np.cos(theta) * np.tan(alpha0) / q,
            a * np.sqrt(1 - np.sin(theta) ** 2 * np.sin(alpha0) ** 2), b / q)


@SETTINGS
@given(st.floats(0.3, 3.0), st.floats(0.3, 3.0), st.floats(0.2, PI / 2 - 0.05), omegas,
       st.sampled_from(["zigzag_j", "zigzag_i"]))
def test_miura_matches_schenk_guest(a, b, alpha0, omega, layout):
    """u: two cells along the a-creases (|u| = 2L); v: two cells along the zig-zag b-creases
    (|v| = 2S), u . v = 0; an a-edge rises H out of the (u, v) plane; a b-edge has the
    component V along u and lies in the (u, v) plane."""
    Y = fold(march(miura_boundary(3, 3, a=a, b=b, alpha0=alpha0, layout=layout)), omega)
    if layout == "zigzag_j":
        theta = abs(omega) / 2
        u, v, ea, eb = Y[2, 0] - Y[0, 0], Y[0, 2] - Y[0, 0], Y[1, 0] - Y[0, 0], Y[0, 1] - Y[0, 0]
    else:
        theta = np.arctan(np.tan(abs(omega) / 2) / np.cos(alpha0))
        u, v, ea, eb = Y[0, 2] - Y[0, 0], Y[2, 0] - Y[0, 0], Y[0, 1] - Y[0, 0], Y[1, 0] - Y[0, 0]
    H, S, L, V = schenk_guest(a, b, alpha0, theta)
    n = unit(np.cross(u, v))
    tol = 1e-11 * max(a, b)
    assert abs(np.linalg.norm(u) - 2 * L) < tol
    assert abs(np.linalg.norm(v) - 2 * S) < tol
    assert abs(u @ v) < tol * max(a, b)
    assert abs(abs(ea @ n) - H) < tol
    assert abs(abs(eb @ unit(u)) - V) < tol
    assert abs(eb @ n) < tol


# --------------------------------------------------------------------------- 7: failures

def with_vertex(bd, vertex, alpha=None, beta=None, sigma=None):
    """Boundary data with the triple of the boundary vertex (i, 1) or (1, j) changed."""
    left, bottom = bd.left.copy(), bd.bottom.copy()
    i, j = vertex
    row = left[i - 1] if j == 1 else bottom[j - 2]
    for k, val in enumerate((alpha, beta, sigma)):
        if val is not None:
            row[k] = val
    return BoundaryData(left, bottom, bd.l_left, bd.l_bottom)


def test_first_check_fails_at_panel_1_2():
    """alpha_a = alpha^{12}, alpha_b = beta_d^{11} and alpha_c = beta^{13} of panel (1, 2):
    pick beta^{13} so that their sum is below pi (with a Miura left column,
    alpha^{12} + beta_d^{11} = pi and the check cannot fail there)."""
    bd = with_vertex(miura_boundary(3, 3, alpha0=1.1), (2, 1), alpha=0.6, beta=0.6)
    bd = with_vertex(bd, (1, 2), alpha=0.3)
    one = BoundaryData(bd.left[:2], bd.bottom[:1], bd.l_left[:1], bd.l_bottom[:1])
    alpha_b = PI - march(one).beta[1, 1]                  # beta_d of panel (1, 1)
    y = (PI - 0.3 - alpha_b) / 2
    assert 0 < y < PI
    bad = with_vertex(bd, (1, 3), beta=y)
    for f in (march, march_loop):
        with pytest.raises(MarchingError) as err:
            f(bad)
        assert (err.value.check, err.value.panel) == ("first", (1, 2))


def test_second_check_fails_at_panel_1_2():
    """Solve mu_1a mu_2b mu_2^{s}(alpha_c, x) = +-1 of panel (1, 2) for x = alpha^{13}
    (= beta_c), i.e. (cos alpha_c - tau) cos x + sin alpha_c sin x = s (1 - tau cos alpha_c).
    A Miura vertex has |mu| != 1 and a Miura panel |mu_1a mu_2b| = 1, so vertex (2, 1) is
    changed first."""
    bd = with_vertex(miura_boundary(3, 3, alpha0=1.1), (2, 1), alpha=0.6, beta=0.6)
    pat = march(bd)
    a, b, s = pat.alpha, pat.beta, pat.sigma
    mu_ab = mu1(a[0, 1], b[0, 1], s[0, 1]) * mu2(PI - b[1, 1], PI - a[1, 1], s[1, 1])
    alpha_c = b[0, 2]
    found = 0
    for target, s_c in itertools.product((1.0, -1.0), (1.0, -1.0)):
        tau = target / mu_ab
        r = math.hypot(math.cos(alpha_c) - tau, math.sin(alpha_c))
        phi = math.atan2(math.sin(alpha_c), math.cos(alpha_c) - tau)
        rhs = s_c * (1 - tau * math.cos(alpha_c))
        if abs(rhs) > r:
            continue
        for x in (phi + math.acos(rhs / r), phi - math.acos(rhs / r)):
            x = math.remainder(x, 2 * PI)
            if not 0.05 < x < PI - 0.05 or abs(x - alpha_c) < 0.05:
                continue
            bad = with_vertex(bd, (1, 3), alpha=x, sigma=s_c)
            assert abs(abs(mu_ab * mu2(alpha_c, x, s_c)) - 1) < 1e-13
            for f in (march, march_loop):
                with pytest.raises(MarchingError) as err:
                    f(bad)
                assert (err.value.check, err.value.panel) == ("second", (1, 2))
            found += 1
    assert found > 0


def first_nonpositive_length_panel(bd):
    """Reference loop: the row-major-first panel with l_cd <= 0 or l_bd <= 0."""
    N, M = bd.N, bd.M
    al = {(p, 0): r[0] for p, r in enumerate(bd.left)} | {
        (0, q + 1): r[0] for q, r in enumerate(bd.bottom)}
    be = {(p, 0): r[1] for p, r in enumerate(bd.left)} | {
        (0, q + 1): r[1] for q, r in enumerate(bd.bottom)}
    sg = {(p, 0): r[2] for p, r in enumerate(bd.left)} | {
        (0, q + 1): r[2] for q, r in enumerate(bd.bottom)}
    lv = {(p, 0): x for p, x in enumerate(bd.l_left)}
    lh = {(0, q): x for q, x in enumerate(bd.l_bottom)}
    for p in range(N):
        for q in range(M):
            aa, ab, ac = al[p, q], PI - be[p + 1, q], be[p, q + 1]
            A = aa + ab + ac
            assert 0 < 2 * PI - A < PI
            m = (mu1(aa, be[p, q], sg[p, q]) * mu2(ab, PI - al[p + 1, q], sg[p + 1, q])
                 * mu2(ac, al[p, q + 1], sg[p, q + 1]))
            assert abs(abs(m) - 1) > 1e-12
            sd = -np.sign(m * m - 1)
            arg = sd * (2 * m - (m * m + 1) * np.cos(A)) / (2 * m * np.cos(A) - (m * m + 1))
            al[p + 1, q + 1], be[p + 1, q + 1], sg[p + 1, q + 1] = (
                A - PI, PI - np.arccos(np.clip(arg, -1, 1)), sd)
            l_ab, l_ac = lv[p, q], lh[p, q]
            lv[p, q + 1] = (-np.sin(ab) * l_ab + np.sin(aa + ab) * l_ac) / np.sin(A)
            lh[p + 1, q] = (np.sin(aa + ac) * l_ab - np.sin(ac) * l_ac) / np.sin(A)
            if lv[p, q + 1] <= 0 or lh[p + 1, q] <= 0:
                return p + 1, q + 1
    return None


@pytest.mark.parametrize("seed", [0, 1, 2, 7])
def test_final_check_fails_on_fig_random(seed):
    bd = perturb_angles(miura_boundary(20, 20), 0.05 * PI, seed=seed)
    panel = first_nonpositive_length_panel(bd)
    assert panel is not None
    with pytest.raises(MarchingError) as err:
        march(bd)
    assert (err.value.check, err.value.panel) == ("final", panel)
    # the lengths as plain numbers, not NumPy's repr of a scalar ("np.float64(...)")
    assert re.search(r"l_cd = -?[0-9.e+-]+, l_bd = -?[0-9.e+-]+", str(err.value))
    assert "np." not in str(err.value)


# --------------------------------------------------------------------------- API

def test_fold_batches_equal_scalar_folds():
    pat = perturbed_pattern(5, 4, seed=3)
    ws = np.array([-PI, -0.4, 0.0, 1e-9, 2.0, PI])
    Y = fold(pat, ws)
    assert Y.shape == (6, 6, 5, 3)
    for k, w in enumerate(ws):
        assert np.array_equal(Y[k], fold(pat, float(w)))
    gh, gv = fold_angles(pat, ws)
    assert gh.shape == (6, 6, 4) and gv.shape == (6, 5, 5)
    for k, w in enumerate(ws):
        assert all(np.array_equal(x[k], y) for x, y in zip((gh, gv), fold_angles(pat, w)))
    assert np.all(np.isfinite(Y)) and np.all(np.isfinite(gh)) and np.all(np.isfinite(gv))


@pytest.mark.parametrize("bad", [PI + 1e-12, -4.0, np.nan, np.inf, [0.1, 3.2], [[0.1]]])
def test_omega_outside_range_raises(bad):
    pat = perturbed_pattern(2, 2, seed=0)
    with pytest.raises(InputError):
        fold(pat, bad)
    with pytest.raises(InputError):
        fold_angles(pat, bad)


def test_pattern_fields():
    pat = march(miura_boundary(3, 4))
    assert pat.alpha.shape == (4, 5) and pat.lh.shape == (4, 4) and pat.lv.shape == (3, 5)
    assert pat.mu.shape == (3, 4) and pat.X.shape == (4, 5, 3)
    assert np.all(np.abs(np.abs(pat.mu) - 1) > 1e-12)
    for arr in (pat.alpha, pat.beta, pat.sigma, pat.lh, pat.lv, pat.mu, pat.X):
        assert np.all(np.isfinite(arr))


def test_baseline_loop_agrees():
    bd = perturb_angles(miura_boundary(6, 7, a=1.0, b=1.3, alpha0=1.1), 0.01 * PI, seed=3)
    fast, slow = march(bd), march_loop(bd)
    for name in ("alpha", "beta", "sigma", "lh", "lv", "mu", "X"):
        assert np.abs(getattr(fast, name) - getattr(slow, name)).max() < 1e-9
    for w in (-PI, -1.2, 0.0, 0.7, PI):
        assert np.abs(fold(fast, w) - fold_loop(slow, w)).max() < 1e-9
