"""The CasADi marching graph: invariants of docs/paper.md s.7, closed forms, errors, gradients."""

import casadi as ca
import numpy as np
import pytest
from hypothesis import assume, given, strategies as st

import rffqm_nlp as rq
from rffqm_nlp.model import kinematics
from rffqm_nlp.model import marching as mg
from rffqm_nlp.model import numpy_model
from rffqm_nlp.model import vertex as vx
from rffqm_nlp.model.lengths import side_length_lp

from forward_oracle import rot_about, unit
from helpers import admissible_vertex, panel_distances, panel_rotations

OMEGAS = [0.0, 1e-9, 0.3, -1.1, 2.5, np.pi - 1e-9, np.pi, -np.pi]


def small_perturbed(N, M, seed, amplitude=0.01 * np.pi, layout="zigzag_j"):
    bd = rq.perturb_angles(rq.miura_boundary(N, M, a=1.0, b=1.3, alpha0=1.1, layout=layout),
                           amplitude, seed)
    return side_length_lp(bd)


# --------------------------------------------------------------- one vertex (s.7 items 1, 2)
@given(admissible_vertex(), st.floats(-np.pi, np.pi))
def test_vertex_loop_closes(v, omega):
    a, b, s = v
    t1 = unit(0.0)
    t2 = unit(a)
    t3 = unit(a + b)
    t4 = unit(a + b + np.pi - a)
    g1, g2, g3, g4 = vx.fold_angles(omega, a, b, s)
    loop = rot_about(t1, g1) @ rot_about(t2, g2) @ rot_about(t3, g3) @ rot_about(t4, g4)
    np.testing.assert_allclose(loop, np.eye(3), atol=1e-12)


@given(admissible_vertex(), st.floats(-np.pi, np.pi))
def test_gamma_bar_inverse_and_maekawa(v, omega):
    a, b, s = v
    g1, g2, g3, g4 = vx.fold_angles(omega, a, b, s)
    assert vx.gamma1_bar(g2, a, b, s) == pytest.approx(omega, abs=1e-12)
    if 1e-6 < abs(omega) < np.pi - 1e-6:
        assert np.sin(g1) * np.sin(g2) * np.sin(g3) * np.sin(g4) < 0


@given(admissible_vertex(), st.floats(0.05, np.pi - 0.05))
def test_gamma2_bar_matches_paper_arccos_form(v, omega):
    a, b, s = v
    arg = (((-s + np.cos(a) * np.cos(b)) * np.cos(omega) + np.sin(a) * np.sin(b))
           / (-s + np.cos(a) * np.cos(b) + np.sin(a) * np.sin(b) * np.cos(omega)))
    paper = np.sign((s * np.cos(b) - np.cos(a)) * omega) * np.arccos(np.clip(arg, -1, 1))
    assert vx.gamma2_bar(omega, a, b, s) == pytest.approx(paper, abs=1e-7)


@given(st.floats(np.pi + 0.05, 2 * np.pi - 0.05), st.floats(-5, 5))
def test_design_formula_matches_paper(total, mu):
    if abs(abs(mu) - 1) < 1e-3 or abs(mu) < 1e-3:
        return
    sigma_d = -np.sign(mu ** 2 - 1)
    paper = np.arccos(sigma_d * (2 * mu - (mu ** 2 + 1) * np.cos(total))
                      / (2 * mu * np.cos(total) - (mu ** 2 + 1)))
    beta_d, s_d = vx.design_d(2 * np.pi - total, mu)
    assert s_d == sigma_d
    assert beta_d == pytest.approx(paper, abs=1e-9)
    assert vx.mu2(2 * np.pi - total, beta_d, s_d) == pytest.approx(mu, rel=1e-9)


@given(admissible_vertex(), st.floats(0.05, np.pi - 0.05))
def test_mv_multiplier_is_the_vanishing_multiplier_and_fixes_the_folds(v, omega):
    a, b, s = v
    mv = vx.mv_multiplier(np.array([a]), np.array([b]), np.array([s]))[0]
    mu2 = vx.mu2(a, b, s)
    assert mv == pytest.approx(mu2 if s > 0 else 1 / mu2, rel=1e-12)
    # its sign (with sigma) decides the mountain-valley sign of gamma2 = gamma2_bar(omega)
    assert np.sign(vx.gamma2_bar(omega, a, b, s)) == -np.sign(mv)
    sym = ca.SX.sym("ab", 2)
    cas = ca.Function("mv", [sym], [vx.mv_multiplier(sym[0], sym[1], np.array([s]))])
    assert float(cas([a, b])) == pytest.approx(mv, rel=1e-14)


@given(st.integers(0, 10 ** 6), st.floats(0.005, 0.05), st.sampled_from(["zigzag_i", "zigzag_j"]))
def test_boundary_mv_and_mu_sides_hold_every_crease_mv(seed, amplitude, layout):
    """The design's MV constraints are on the boundary multipliers and the panels' |mu_abc|
    only: holding both must hold the mountain-valley sign of every crease."""
    miura = rq.miura_boundary(6, 6, a=1.0, b=1.0, alpha0=1.3, layout=layout)
    try:
        pat = numpy_model.march(rq.perturb_angles(miura, amplitude, seed))
    except rq.MarchingError:
        assume(False)
    ref = numpy_model.march(miura)
    mv = [vx.mv_multiplier(p.alpha, p.beta, p.sigma) for p in (pat, ref)]
    boundary = [np.concatenate([m[:, 0], m[0, 1:]]) for m in mv]
    assume(np.all(np.sign(boundary[0]) == np.sign(boundary[1])))
    assume(np.all((np.abs(pat.mu) > 1) == (np.abs(ref.mu) > 1)))
    for mine, theirs in zip(numpy_model.fold_angles(pat, 1.0),
                            numpy_model.fold_angles(ref, 1.0)):
        np.testing.assert_array_equal(np.sign(mine), np.sign(theirs))


@given(st.floats(0.2, 2.9), st.floats(0.2, 2.9), st.floats(0.2, 2.9), st.floats(0.1, 5),
       st.floats(0.1, 5))
def test_side_residuals_vanish_exactly_at_the_sides(a, b, c, l_ab, l_ac):
    assume(abs(np.sin(a + b + c)) > 0.05)
    l_cd, l_bd = vx.panel_sides(a, b, c, l_ab, l_ac)
    scale = max(l_ab, l_ac)
    for r in vx.panel_side_residuals(a, b, c, l_ab, l_ac, l_cd, l_bd):
        assert abs(r) <= 1e-13 * scale
    r_cd, r_bd = vx.panel_side_residuals(a, b, c, l_ab, l_ac, l_cd + 1.0, l_bd)
    assert r_cd == pytest.approx(np.sin(a + b + c), abs=1e-12) and abs(r_bd) <= 1e-13 * scale


# --------------------------------------------------------------- the pattern
@pytest.mark.parametrize("layout", ["zigzag_j", "zigzag_i"])
def test_miura_pattern_is_parallelograms(layout):
    pat = mg.march(rq.miura_boundary(4, 6, a=1.0, b=1.5, alpha0=1.0, layout=layout))
    ang = pat.panel_angles
    np.testing.assert_allclose(ang[..., 0], ang[..., 3], atol=1e-13)
    np.testing.assert_allclose(ang[..., 1], ang[..., 2], atol=1e-13)
    np.testing.assert_allclose(ang.sum(-1), 2 * np.pi, atol=1e-13)
    assert set(np.unique(pat.sigma)) == {-1.0 if layout == "zigzag_j" else 1.0}


def test_pattern_panel_angles_and_flat_geometry_agree():
    pat = mg.march(small_perturbed(6, 7, seed=3))
    X = pat.X
    a, b, c, d = X[:-1, :-1], X[1:, :-1], X[:-1, 1:], X[1:, 1:]

    def angle(p, q, r):
        u, v = q - p, r - p
        norms = np.linalg.norm(u, axis=-1) * np.linalg.norm(v, axis=-1)
        return np.arccos(np.sum(u * v, -1) / norms)

    measured = np.stack([angle(a, c, b), angle(b, a, d), angle(c, d, a), angle(d, b, c)], -1)
    np.testing.assert_allclose(measured, pat.panel_angles, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(c - a, axis=-1), pat.lh[:-1], rtol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(d - b, axis=-1), pat.lh[1:], rtol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(b - a, axis=-1), pat.lv[:, :-1], rtol=1e-13)
    np.testing.assert_allclose(np.linalg.norm(d - c, axis=-1), pat.lv[:, 1:], rtol=1e-13)
    assert np.all(X[..., 2] == 0) and np.all(X[0, 0] == 0) and X[0, 1, 1] == 0 < X[0, 1, 0]


# --------------------------------------------------------------- kinematics (s.7 items 3-5)
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_every_vertex_satisfies_theorem_2_1(seed):
    pat = mg.march(small_perturbed(5, 6, seed))
    omega = 1.3
    gh, gv = mg.fold_angles(pat, omega)
    X = pat.X
    for i in range(1, pat.N):
        for j in range(1, pat.M):
            a, b, s = pat.alpha[i, j], pat.beta[i, j], pat.sigma[i, j]
            g1, g2, g3, g4 = gh[i, j], gv[i, j], gh[i, j - 1], gv[i - 1, j]
            assert g3 == pytest.approx(-s * g1, abs=1e-12)
            assert g4 == pytest.approx(s * g2, abs=1e-12)
            assert vx.gamma2_bar(g1, a, b, s) == pytest.approx(g2, abs=1e-12)
            tang = [X[i, j + 1] - X[i, j], X[i + 1, j] - X[i, j], X[i, j - 1] - X[i, j],
                    X[i - 1, j] - X[i, j]]
            tang = [t / np.linalg.norm(t) for t in tang]
            loop = (rot_about(tang[0], g1) @ rot_about(tang[1], g2) @ rot_about(tang[2], g3)
                    @ rot_about(tang[3], g4))
            np.testing.assert_allclose(loop, np.eye(3), atol=1e-12)


@pytest.mark.parametrize("omega", [0.4, -2.0, 3.0])
def test_panel_compatibility_both_deformation_gradients_agree(omega):
    pat = mg.march(small_perturbed(5, 5, seed=7))
    R = panel_rotations(pat.X, mg.fold(pat, omega))
    gh, gv = mg.fold_angles(pat, omega)
    X = pat.X
    np.testing.assert_allclose(R[0, 0], np.eye(3), atol=1e-13)
    for i in range(pat.N):
        for j in range(pat.M):
            if j > 0:
                t2 = X[i + 1, j] - X[i, j]
                left = R[i, j - 1] @ rot_about(t2 / np.linalg.norm(t2), -gv[i, j])
                np.testing.assert_allclose(R[i, j], left, atol=1e-12)
            if i > 0:
                t1 = X[i, j + 1] - X[i, j]
                below = R[i - 1, j] @ rot_about(t1 / np.linalg.norm(t1), gh[i, j])
                np.testing.assert_allclose(R[i, j], below, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 5])
def test_isometry_flat_and_folded_flat(seed):
    pat = mg.march(small_perturbed(8, 9, seed))
    d0 = panel_distances(pat.X)
    Y = mg.fold(pat, np.array(OMEGAS))
    for k, omega in enumerate(OMEGAS):
        np.testing.assert_allclose(panel_distances(Y[k]), d0, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(Y[0], pat.X, atol=1e-14)
    for k in (6, 7):
        pts = Y[k].reshape(-1, 3) - Y[k].reshape(-1, 3).mean(0)
        sv = np.linalg.svd(pts, compute_uv=False)
        assert sv[-1] < 1e-10 * sv[0]


def test_large_pattern_isometry():
    bd = rq.perturb_angles(rq.miura_boundary(120, 120, alpha0=1.1), 0.001 * np.pi, seed=1)
    pat = mg.march(bd)
    scale = np.abs(pat.X).max()
    Y = mg.fold(pat, 2.0)
    err = np.abs(panel_distances(Y) - panel_distances(pat.X)).max()
    assert err < 1e-10 * scale


@pytest.mark.parametrize("layout", ["zigzag_j", "zigzag_i"])
@pytest.mark.parametrize("omega", [0.2, 1.0, -2.2, 3.0, np.pi])
def test_miura_matches_schenk_guest(layout, omega):
    a, b, alpha0 = 1.0, 1.4, 1.05
    pat = mg.march(rq.miura_boundary(4, 4, a=a, b=b, alpha0=alpha0, layout=layout))
    Y = mg.fold(pat, omega)
    if layout == "zigzag_j":
        theta = abs(omega) / 2
        straight, zigzag = Y[2, 1] - Y[0, 1], Y[1, 2] - Y[1, 0]
        e_a, e_b = Y[1, 1] - Y[0, 1], Y[1, 1] - Y[1, 0]
    else:
        theta = np.arctan(np.tan(abs(omega) / 2) / np.cos(alpha0))
        straight, zigzag = Y[1, 2] - Y[1, 0], Y[2, 1] - Y[0, 1]
        e_a, e_b = Y[1, 1] - Y[1, 0], Y[1, 1] - Y[0, 1]
    c2 = np.cos(theta) ** 2 * np.tan(alpha0) ** 2
    H = a * np.sin(theta) * np.sin(alpha0)
    S = b * np.cos(theta) * np.tan(alpha0) / np.sqrt(1 + c2)
    L = a * np.sqrt(1 - np.sin(theta) ** 2 * np.sin(alpha0) ** 2)
    V = b / np.sqrt(1 + c2)

    def perp(e, d):
        d = d / np.linalg.norm(d)
        return np.linalg.norm(e - (e @ d) * d)

    assert np.linalg.norm(straight) / 2 == pytest.approx(L, abs=1e-11)
    assert perp(e_a, straight) == pytest.approx(H, abs=1e-11)
    assert np.linalg.norm(zigzag) / 2 == pytest.approx(S, abs=1e-11)
    if S > 1e-6:  # folded flat: the zig-zag closes up (S = 0) and has no direction
        assert perp(e_b, zigzag) == pytest.approx(V, abs=1e-11)


def test_fold_accepts_arrays_and_rejects_bad_omega():
    pat = mg.march(small_perturbed(3, 4, seed=1))
    om = np.linspace(-np.pi, np.pi, 5)
    Y = mg.fold(pat, om)
    assert Y.shape == (5, 4, 5, 3)
    for k, w in enumerate(om):
        np.testing.assert_allclose(Y[k], mg.fold(pat, w), atol=1e-15)
    for bad in (np.pi + 1e-6, np.nan, np.inf, [[0.1]]):
        with pytest.raises(rq.InputError):
            mg.fold(pat, bad)


# --------------------------------------------------------------- checks and errors (item 7)
def test_fig_random_miura_lengths_fail_final_check_and_lp_lengths_march():
    bd = rq.perturb_angles(rq.miura_boundary(10, 10), 0.05 * np.pi, seed=0)
    with pytest.raises(rq.MarchingError) as exc:
        mg.march(bd)
    assert exc.value.check == "final"
    i, j = exc.value.panel
    assert f"panel ({i}, {j})" in str(exc.value)
    # The named panel is the first with a non-positive side, computed here row-major by hand.
    out = mg.pattern_function(10, 10).call(mg.boundary_inputs(bd))
    lh, lv = out[3].full(), out[4].full()
    bad = (lv[:, 1:] <= 0) | (lh[1:, :] <= 0)
    first = np.argwhere(bad)[0]
    assert (i, j) == (first[0] + 1, first[1] + 1)
    pat = mg.march(side_length_lp(bd))
    assert pat.lh.min() > 0 and pat.lv.min() > 0


def raw_checks(bd):
    """alpha_d and mu_abc of every panel straight from the graph, with no check applied."""
    out = mg.pattern_function(bd.N, bd.M).call(mg.boundary_inputs(bd))
    return out[6].full(), out[5].full()


def test_first_check_failure_names_panel():
    bd = rq.miura_boundary(3, 3, alpha0=1.2)
    left, bottom = bd.left.copy(), bd.bottom.copy()
    # These make alpha_a + alpha_b of panel (1, 2) small (about 1.21); alpha_c = beta(1, 3) = 1.0
    # then leaves alpha_d = 2 pi - sum > pi there, while panel (1, 1) is fine.
    left[1, :2] = [1.2, 0.3]
    bottom[0, :2] = [1.2, 1.0]
    bottom[1, :2] = [1.0, 1.0]
    bad = rq.BoundaryData(left, bottom, bd.l_left, bd.l_bottom)
    alpha_d, _ = raw_checks(bad)
    assert 0 < alpha_d[0, 0] < np.pi and not 0 < alpha_d[0, 1] < np.pi
    with pytest.raises(rq.MarchingError, match=r"first check failed at panel \(1, 2\)") as exc:
        mg.march(bad)
    assert (exc.value.check, exc.value.panel) == ("first", (1, 2))


def test_second_check_failure_names_panel():
    from scipy.optimize import brentq

    bd = rq.miura_boundary(2, 3, alpha0=1.2)

    def with_beta11(beta):
        left = bd.left.copy()
        left[0, 1] = beta
        return rq.BoundaryData(left, bd.bottom, bd.l_left, bd.l_bottom)

    # |mu_abc| = 1 at panel (1, 1) for one beta of vertex (1, 1): solve for it on the graph.
    beta = brentq(lambda b: abs(raw_checks(with_beta11(b))[1][0, 0]) - 1, 1.2, 1.9, xtol=1e-16)
    bad = with_beta11(beta)
    assert abs(abs(raw_checks(bad)[1][0, 0]) - 1) < 1e-12
    with pytest.raises(rq.MarchingError) as exc:
        mg.march(bad)
    assert (exc.value.check, exc.value.panel) == ("second", (1, 1))


@pytest.mark.parametrize("change, match", [
    (lambda d: d.update(left=d["left"][:, :2]), "shape"),
    (lambda d: d.update(l_left=d["l_left"][:-1]), "l_left"),
    (lambda d: d["left"].__setitem__((1, 0), np.nan), r"\(2, 1\).*alpha"),
    (lambda d: d["bottom"].__setitem__((0, 1), 3.5), r"\(1, 2\).*beta"),
    (lambda d: d["left"].__setitem__((0, slice(0, 2)), np.pi / 2), "pi/2"),
    (lambda d: d["left"].__setitem__((2, 2), 1.0), r"\(3, 1\).*MV"),
    (lambda d: d["left"].__setitem__((2, 2), 0.5), "sigma"),
    (lambda d: d["l_bottom"].__setitem__(1, 0.0), "l_bottom"),
    (lambda d: d["l_left"].__setitem__(0, -1.0), "l_left"),
    (lambda d: d["l_left"].__setitem__(0, np.inf), "l_left"),
])
def test_invalid_boundary_data_raises(change, match):
    bd = rq.miura_boundary(3, 3)
    d = {k: np.array(getattr(bd, k)) for k in ("left", "bottom", "l_left", "l_bottom")}
    change(d)
    with pytest.raises(rq.InputError, match=match):
        rq.BoundaryData(**d)


def test_miura_boundary_rejects_bad_parameters():
    for kwargs in ({"alpha0": 1.7}, {"a": -1.0}, {"layout": "diagonal"}):
        with pytest.raises(rq.InputError):
            rq.miura_boundary(2, 2, **kwargs)
    with pytest.raises(rq.InputError):
        rq.miura_boundary(0, 2)


@pytest.mark.parametrize("call, words", [
    (lambda: rq.miura_boundary(2, np.nan), "M must be a whole number in [1, 100000] (panels), "
                                           "got the number nan"),
    (lambda: rq.miura_boundary(2.0, 2), "N must be a whole number in [1, 100000] (panels), got "
                                        "the number 2"),
    (lambda: rq.miura_boundary(10**30, 2), "got a whole number of 31 digits"),
    (lambda: rq.miura_boundary(None, 2), "N must be a whole number"),
    (lambda: rq.miura_boundary(2, 2, a="1"), "a must be a finite number > 0 (a length), got "
                                             "the string '1'"),
    (lambda: rq.miura_boundary(2, 2, alpha0=np.array([1.0, 1.1])), "alpha0 must be a finite "
                                                                    "number in (0, 1.5708)"),
    (lambda: rq.miura_boundary(2, 2, layout=5), "layout must be one of 'zigzag_j', 'zigzag_i'"),
    (lambda: rq.perturb_angles(rq.miura_boundary(2, 2), 0.1, seed=-1),
     "seed must be a whole number in [0, 9.22337e+18] (or None), got the whole number -1"),
    (lambda: rq.perturb_angles(rq.miura_boundary(2, 2), 0.1, seed=1.5), "seed must be a whole"),
    (lambda: rq.perturb_angles(rq.miura_boundary(2, 2), "wide"), "amplitude must be a finite "
                                                                 "number >= 0"),
    (lambda: rq.perturb_angles(rq.numpy_model.march(rq.miura_boundary(2, 2)), 0.1),
     "bd must be boundary data (rffqm_nlp.BoundaryData, e.g. from miura_boundary), got a "
     "Pattern"),
    (lambda: rq.boundary.refine(None, rq.miura_boundary(2, 2), rq.miura_boundary(2, 2)),
     "design must be boundary data"),
    (lambda: rq.boundary.mv_set("a", 1.0), "alpha must be a finite number"),
    (lambda: rq.BoundaryData(left="rm -rf", bottom=[], l_left=[], l_bottom=[]),
     "left must be an array of numbers, got a string of 6 characters"),
    (lambda: rq.BoundaryData.from_dict([1, 2]), "boundary data must be a table"),
    (lambda: rq.miura_boundary(2, 2).with_lengths([1.0, np.nan, 1.0, 1.0]),
     "lengths must be N + M = 4 finite positive lengths, got nan at index (1,)"),
    (lambda: rq.BoundaryData.from_vector(np.ones(3), np.ones(5), 2, 2), "x must be a design "
                                                                        "vector of 14"),
])
def test_boundary_functions_name_the_argument_and_what_it_allows(call, words):
    with pytest.raises(rq.InputError) as exc:
        call()
    assert words in str(exc.value) and "\n" not in str(exc.value)


def test_perturb_angles_keeps_taking_generators_and_none():
    bd = rq.miura_boundary(2, 2)
    same = [rq.perturb_angles(bd, 0.01, seed=s) for s in (np.random.default_rng(4), 4)]
    np.testing.assert_array_equal(same[0].left, same[1].left)
    assert rq.perturb_angles(bd, 0.01).N == 2
    assert rq.perturb_angles(bd, 0.01, seed=np.int64(7)).N == 2


@pytest.mark.parametrize("zero", [0.0, -0.0, np.float64(-0.0)])
def test_perturb_angles_by_zero_keeps_the_boundary(zero):
    """A zero amplitude (signed too, which NumPy's uniform refuses) perturbs nothing."""
    bd = rq.miura_boundary(2, 2)
    same = rq.perturb_angles(bd, zero, seed=3)
    np.testing.assert_array_equal(same.left, bd.left)
    np.testing.assert_array_equal(same.bottom, bd.bottom)


def test_march_and_fold_refuse_the_wrong_objects_and_unfoldable_patterns():
    bd = rq.miura_boundary(2, 2)
    pat = mg.march(bd)
    for model in (mg, numpy_model):
        with pytest.raises(rq.InputError, match="^bd must be boundary data .* got a Pattern"):
            model.march(pat)
        with pytest.raises(rq.InputError, match="^pat must be a crease pattern .*march it "
                                                "first"):
            model.fold(bd, 1.0)
    beta = pat.beta.copy()
    beta[0, 0] = pat.alpha[0, 0]                 # alpha = beta with sigma = +1: not in MV
    broken = rq.Pattern(pat.alpha, beta, np.ones_like(pat.sigma), pat.lh, pat.lv, pat.mu,
                        pat.X)
    for fold in (mg.fold, numpy_model.fold, mg.fold_angles, numpy_model.fold_angles):
        with pytest.raises(rq.InputError, match="no finite folded state"):
            fold(broken, 1.0)
    with pytest.raises(rq.InputError, match="^omega must be a single number"):
        mg.fold_angles(pat, [0.1, 0.2])


def test_the_graph_sizes_are_checked_before_any_graph_is_built():
    for make in (mg.pattern_function, mg.fold_function, mg.folded_function,
                 mg.marched_function, mg.panel_quaternions_function):
        for N, M in ((0, 2), (2, -1), (2.0, 2), (10**6, 2), ("2", 2)):
            with pytest.raises(rq.InputError, match="must be a whole number in"):
                make(N, M)
    assert mg.pattern_function(2, 3) is mg.pattern_function(np.int64(2), 3)   # one cache


def test_evaluation_checks_its_inputs_and_never_writes_into_them():
    """The buffer is only pointed at vectors of the input's size (a shorter one would be
    read past its end), and set() writes into the Evaluation's own copy."""
    bd = rq.miura_boundary(2, 2)
    f = mg.pattern_function(2, 2)
    args = mg.boundary_inputs(bd)
    for bad, words in ((args[:3], "args must be a list of 4 arrays"),
                       ([np.zeros(2)] + args[1:], "input left of pattern must have 9 entries"),
                       (["abc"] + args[1:], "input left of pattern must be an array of 9"),
                       ("abcd", "args must be a list of 4 arrays")):
        with pytest.raises(rq.InputError, match=words):
            mg.Evaluation(f, bad)
    with pytest.raises(rq.InputError, match="f must be a CasADi Function"):
        mg.evaluate(lambda x: x, args)
    mine = np.array(args[2])                   # l_left, writable
    ev = mg.Evaluation(f, [args[0], args[1], mine, args[3]])
    ev.set(2, np.full(2, 2.0))
    np.testing.assert_array_equal(mine, args[2])
    np.testing.assert_allclose(ev.run()[4][:, 0], 2.0)       # lv's first column: l_left
    for k, value in ((4, 1.0), (-1, 1.0), (2, np.ones(3)), (2.0, np.ones(2))):
        with pytest.raises(rq.InputError):
            ev.set(k, value)


def test_locate_failure_checks_the_shapes_and_keeps_nan_a_failure():
    ok = (np.ones((2, 2)), np.full((2, 2), 3.0), np.ones((3, 2)), np.ones((2, 3)))
    assert mg.locate_failure(*ok) is None
    nan_mu = (ok[0], np.where(np.eye(2) > 0, np.nan, 3.0), ok[2], ok[3])
    assert mg.locate_failure(*nan_mu) == ("second", (1, 1))
    with pytest.raises(rq.InputError, match=r"lv must be an \(2, 3\) array"):
        mg.locate_failure(ok[0], ok[1], ok[2], np.ones((2, 2)))


def test_graph_builders_take_numbers_and_refuse_mismatched_shapes():
    """On numbers the graph builders give DMs equal to their graphs' values; matrices of
    the wrong shapes and non-numbers are InputErrors, not CasADi assertions."""
    pat = mg.march(rq.miura_boundary(2, 3))
    A = ca.MX.sym("A", 3, 4)
    B = ca.MX.sym("B", 3, 4)
    graph = ca.Function("e", [A, B], [mg.edge_directions(A, B)])
    np.testing.assert_allclose(mg.edge_directions(pat.alpha, pat.beta).full(),
                               graph(pat.alpha, pat.beta).full(), rtol=1e-14)
    kh, kv = mg.fold_multipliers(pat.alpha, pat.beta, pat.sigma)
    assert np.all(np.isfinite(kh.full())) and kv.shape == (3, 4)
    w, x, y, z = mg.qmul((1.0, 0.0, 0.0, 0.0), (0.0, 1.0, 0.0, 0.0))
    assert [float(c) for c in (w, x, y, z)] == [0.0, 1.0, 0.0, 0.0]
    for call, words in (
            (lambda: mg.edge_directions(np.ones((3, 3)), np.ones((2, 3))), "one shape"),
            (lambda: mg.fold_multipliers(pat.alpha, pat.beta, "x"), "sigma must be"),
            (lambda: mg.qmul((1.0, 0.0), (1.0, 0.0, 0.0, 0.0)), "p must be a quaternion"),
            (lambda: mg.crease_quaternion(np.ones(2), np.ones(3), 1.0, 0.0),
             "numbers or matrices of one shape"),
            (lambda: mg.crease_quaternions(pat.alpha, pat.beta, pat.sigma, np.zeros((3, 4)),
                                           [1.0, 2.0]), "omega must be a number"),
            (lambda: mg.rotated_edges((np.ones((2, 3)),) * 4, pat.alpha, np.zeros((3, 4)),
                                      pat.lh, pat.lv[:, :2]), "lv must be 2 x 4")):
        with pytest.raises(rq.InputError, match=words):
            call()


def test_folded_vertices_on_numbers_are_the_fold_graphs_values():
    """The kinematics' folded state on numbers: DMs equal to the values of fold_function
    and panel_quaternions_function; shapes that do not fit alpha's, a list for omega, SX
    symbols (the kinematics is MX) and non-numbers are InputErrors."""
    pat = mg.march(small_perturbed(3, 4, seed=1))
    args = [pat.alpha, pat.beta, pat.sigma, pat.lh, pat.lv, 0.8]
    Y, quat = kinematics.folded_vertices(*args)
    want = mg.evaluate(mg.fold_function(3, 4), args) + mg.evaluate(
        mg.panel_quaternions_function(3, 4), args)
    assert [x.shape for x in Y + quat] == [(4, 5)] * 3 + [(3, 4)] * 4
    for got, value in zip(Y + quat, want):
        np.testing.assert_allclose(got.full(), value, rtol=0, atol=1e-13)
    for k, bad, words in ((3, pat.lh[:, :2], r"lh must be 4 x 4 for alpha's 4 x 5 vertices"),
                          (4, pat.lv.T, "lv must be 3 x 5"),
                          (1, pat.beta[:, :2], "alpha, beta, sigma must be matrices of one"),
                          (5, [1.0, 2.0], "omega must be a number"),
                          (5, ca.SX.sym("w"), "omega must be an MX matrix or finite real numbers"),
                          (2, "x", "sigma must be")):
        with pytest.raises(rq.InputError, match=words):
            kinematics.folded_vertices(*args[:k], bad, *args[k + 1:])


def test_vertex_formulas_refuse_poles_on_numbers_and_build_graphs_on_symbols():
    """A multiplier at its pole (sigma outside MV(alpha, beta)) is an InputError on
    numbers, never inf; on symbols the formulas build their graphs as before."""
    for f, args in ((vx.mu1, (1.0, 1.0, 1.0)),              # 1 / mu2^{+1}(a, a) = 1 / 0
                    (numpy_model.mu1, (1.0, np.pi - 1.0, -1.0)),
                    (numpy_model.mu2, (1.0, 1.0, 1.0)),     # the printed form: 0 / 0
                    (vx.mu2, (0.0, 0.0, 1.0))):
        with pytest.raises(rq.InputError, match="sigma is not in MV"):
            f(*args)
    with pytest.raises(rq.InputError, match="multiple of pi"):
        vx.panel_sides(0.0, 0.0, 0.0, 1.0, 1.0)      # sin(0) = 0 exactly
    with pytest.raises(rq.InputError, match=r"\|mu_abc\| = 1"):
        vx.design_d(0.0, 1.0)
    for bad, words in (("a", "alpha must be a finite number"), (np.nan, "got nan"),
                       ([1.0, 2.0, 3.0], "must broadcast together")):
        with pytest.raises(rq.InputError, match=words):
            vx.mu2(bad, np.ones(2), 1.0)
    with pytest.raises(rq.InputError, match="sigma must be \\+1 or -1"):
        vx.gamma2_bar(0.3, 1.0, 1.2, 0.5)
    a = ca.SX.sym("a")
    mu = ca.Function("mu", [a], [vx.mu2(a, 1.2, -1.0)])
    assert float(mu(1.0)) == pytest.approx(vx.mu2(1.0, 1.2, -1.0), rel=1e-14)
    assert vx.mu2([1.0, 1.1], 1.2, -1.0).shape == (2,)        # lists are arrays


@pytest.mark.parametrize("N, M, seed", [(1, 1, 0), (3, 5, 1), (6, 4, 2)])
def test_marched_function_is_the_march_then_the_fold(N, M, seed):
    """One Function for the march and the kinematics: the same values as pattern_function,
    fold_function and panel_quaternions_function, and the NumPy model's to round-off."""
    bd = small_perturbed(N, M, seed=seed, amplitude=0.03 * np.pi)
    omega = 1.3
    out = mg.evaluate(mg.marched_function(N, M), [*mg.boundary_inputs(bd), omega])
    pattern = mg.evaluate(mg.pattern_function(N, M), mg.boundary_inputs(bd))[:7]
    args = [*pattern[:5], omega]
    quat = mg.evaluate(mg.panel_quaternions_function(N, M), args)
    folded = mg.evaluate(mg.fold_function(N, M), args)
    for got, want in zip(out[:7] + out[8:], pattern + quat + folded):
        np.testing.assert_array_equal(got, want)
    reference = numpy_model.march(bd)
    for got, want in zip(out[:5], (reference.alpha, reference.beta, reference.sigma,
                                   reference.lh, reference.lv)):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.stack(out[12:15], axis=-1),
                               numpy_model.fold(reference, omega), rtol=0, atol=1e-12)
    a, b = ca.MX.sym("a", N + 1, M + 1), ca.MX.sym("b", N + 1, M + 1)
    theta = ca.Function("theta", [a, b], [mg.edge_directions(a, b)])
    np.testing.assert_array_equal(out[7], theta(out[0], out[1]).full())


# --------------------------------------------------------------- derivatives
def test_gradients_match_central_differences():
    N, M = 4, 5
    bd = small_perturbed(N, M, seed=2, amplitude=0.02 * np.pi)
    f = mg.folded_function(N, M)
    x = ca.MX.sym("x", 2 * (N + 1 + M) + N + M + 1)
    sig = bd.sigma
    nv = N + 1 + M

    def unpack(x):
        ang = ca.horzcat(x[:nv], x[nv:2 * nv], ca.DM(sig)).T
        return [ang[:, :N + 1], ang[:, N + 1:], x[2 * nv:2 * nv + N].T,
                x[2 * nv + N:2 * nv + N + M].T, x[-1]]

    Y = ca.vertcat(*(ca.vec(y) for y in f.call(unpack(x))))
    F = ca.Function("F", [x], [Y, ca.jacobian(Y, x)])
    x0 = np.concatenate([bd.to_vector(), [1.7]])
    rng = np.random.default_rng(0)
    y0, J = (np.array(v.full()) for v in F(x0))
    h = 1e-6
    for _ in range(5):
        d = rng.normal(size=x0.size)
        fd = (F(x0 + h * d)[0].full() - F(x0 - h * d)[0].full()).ravel() / (2 * h)
        jd = (J @ d).ravel()
        assert np.linalg.norm(fd - jd) <= 1e-6 * np.linalg.norm(jd)


def test_the_graph_caches_are_bounded():
    """A sweep over sizes keeps at most SIZE_CACHE graphs of each kind, not one per size."""
    before = mg.cached_graphs()
    for n in range(1, 5 * mg.SIZE_CACHE + 1):
        mg.fold_function(n, 1)
    assert mg.cached_graphs() - before <= 2 * mg.SIZE_CACHE


@pytest.mark.parametrize("call", [
    lambda s: mg.edge_directions(alpha=1.0, beta=s),
    lambda s: mg.fold_multipliers(alpha=s, beta=0.3, sigma=1.0),
    lambda s: mg.folded_vertices(s, s, s, s, s, 0.5)])
def test_an_sx_argument_is_refused_in_one_line(call):
    """The matrix builders are made of MX operations: an SX symbol, alone or beside numbers,
    is refused by name, never a raw CasADi error (found by tests/test_fuzz_api.py); the
    elementwise ones (qmul, crease_quaternion, rotate_planar) take SX, as the stencils do."""
    with pytest.raises(rq.InputError, match=r"must be an MX matrix or finite real numbers .* got "
                                         r"an SX$"):
        call(ca.SX.sym("s"))


def test_edge_directions_need_two_vertices_a_side():
    with pytest.raises(rq.InputError, match="at least 2 x 2"):
        mg.edge_directions(alpha=ca.MX.sym("a"), beta=0.3)
    assert mg.edge_directions(alpha=np.full((2, 3), 1.0), beta=np.full((2, 3), 1.0)
                                    ).shape == (2, 3)


def test_the_elementwise_builders_take_sx_beside_numbers():
    s = ca.SX.sym("s")
    w, x, y, z = mg.qmul(p=(1.0, s, 0.0, 0.0), q=(0.0, 1.0, 0.0, 0.0))
    f = ca.Function("f", [s], [ca.vertcat(w, x, y, z)])
    np.testing.assert_allclose(f(0.5).full().ravel(), [-0.5, 1.0, 0.0, 0.0])
