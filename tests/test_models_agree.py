"""The CasADi marching graph (rffqm_nlp.model.marching) and the independent NumPy model
(rffqm_nlp.model.numpy_model) compute the same patterns, folded states and fold angles, and reject
the same boundary data with the same check at the same panel."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

import rffqm_nlp as rq
from rffqm_nlp.model import marching as mg
from rffqm_nlp.model import numpy_model as nm
from rffqm_nlp.model import vertex as vx
from rffqm_nlp.errors import InfeasibleDesign
from rffqm_nlp.model.lengths import side_length_lp

from helpers import admissible_vertex

PI = np.pi
RTOL = 1e-10
#: omega = 0, near 0, near and at +-pi, and a few interior values.
OMEGAS = [0.0, 1e-8, -1e-8, 0.4, -1.3, 2.2, PI - 1e-8, -(PI - 1e-8), PI, -PI]
FIELDS = ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")
LAYOUTS = ("zigzag_j", "zigzag_i")
SETTINGS = settings(max_examples=60, deadline=None)

sizes = st.integers(1, 6)
seeds = st.integers(0, 2**32 - 1)
layouts = st.sampled_from(LAYOUTS)
omegas = st.floats(-PI, PI)


def miura(N, M, layout, a=1.0, b=1.3, alpha0=1.1):
    return rq.miura_boundary(N, M, a=a, b=b, alpha0=alpha0, layout=layout)


def outcome(model, bd):
    """The marched pattern, or the (check, panel) of the MarchingError raised."""
    try:
        return model.march(bd)
    except rq.MarchingError as exc:
        return exc.check, exc.panel


def assert_patterns_agree(p, q):
    """All fields equal to RTOL: lengths and positions relative to the pattern size."""
    scale = max(1.0, np.abs(p.X).max())
    assert p.X.shape == q.X.shape
    np.testing.assert_array_equal(p.sigma, q.sigma)
    for name in ("alpha", "beta"):
        np.testing.assert_allclose(getattr(p, name), getattr(q, name), rtol=0, atol=RTOL,
                                   err_msg=name)
    for name in ("lh", "lv", "X"):
        np.testing.assert_allclose(getattr(p, name), getattr(q, name), rtol=0,
                                   atol=RTOL * scale, err_msg=name)
    np.testing.assert_allclose(p.mu, q.mu, rtol=RTOL, atol=RTOL, err_msg="mu")


def assert_folds_agree(p, q, ws):
    """fold (scalar and batched omega) and fold_angles agree at every omega in ``ws``."""
    atol = RTOL * max(1.0, np.abs(p.X).max())
    for w in ws:
        Yc, Yn = mg.fold(p, w), nm.fold(q, w)
        assert Yc.shape == Yn.shape == p.X.shape
        np.testing.assert_allclose(Yc, Yn, rtol=0, atol=atol, err_msg=f"Y at omega={w!r}")
        for gc, gn, name in zip(mg.fold_angles(p, w), nm.fold_angles(q, w), ("gh", "gv")):
            assert gc.shape == gn.shape
            np.testing.assert_allclose(gc, gn, rtol=0, atol=RTOL,
                                       err_msg=f"{name} at omega={w!r}")
    ws = np.asarray(ws, dtype=float)
    np.testing.assert_allclose(mg.fold(p, ws), nm.fold(q, ws), rtol=0, atol=atol,
                               err_msg="batched fold")


def assert_models_agree(bd, ws):
    p, q = outcome(mg, bd), outcome(nm, bd)
    if isinstance(p, tuple) or isinstance(q, tuple):
        assert p == q, f"CasADi: {p}, NumPy: {q}"
        return False
    for name in FIELDS:
        assert getattr(p, name).shape == getattr(q, name).shape, name
    assert_patterns_agree(p, q)
    assert_folds_agree(p, q, ws)
    return True


# --------------------------------------------------------------------------- one vertex

@SETTINGS
@given(admissible_vertex(), omegas)
def test_vertex_functions_take_the_same_arguments(v, omega):
    """numpy_model's printed forms and vertex's half-angle forms, called the same way."""
    a, b, s = v
    for name in ("mu1", "mu2"):
        assert getattr(nm, name)(a, b, s) == pytest.approx(getattr(vx, name)(a, b, s),
                                                           rel=1e-9), name
    for name in ("gamma1_bar", "gamma2_bar"):
        assert getattr(nm, name)(omega, a, b, s) == pytest.approx(
            getattr(vx, name)(omega, a, b, s), abs=1e-9), name


# --------------------------------------------------------------------------- random patterns

@SETTINGS
@given(sizes, sizes, layouts, seeds, omegas)
def test_lp_length_patterns_agree(N, M, layout, seed, omega):
    """Perturbed Miuras (0.05 pi, the paper's Fig. Random input) with LP side lengths."""
    try:
        bd = side_length_lp(rq.perturb_angles(miura(N, M, layout), 0.05 * PI, seed))
    except (rq.MarchingError, InfeasibleDesign, rq.BoundaryDataError):
        assume(False)
    assert assert_models_agree(bd, [*OMEGAS, omega])


@SETTINGS
@given(sizes, sizes, layouts, seeds, st.floats(1e-6, 0.02 * PI), omegas)
def test_miura_length_patterns_agree(N, M, layout, seed, amplitude, omega):
    """Small perturbations of a Miura with its own side lengths (either both models march
    the same pattern or both raise the same MarchingError)."""
    bd = rq.perturb_angles(miura(N, M, layout), amplitude, seed)
    assert_models_agree(bd, [*OMEGAS, omega])


@pytest.mark.parametrize("layout", LAYOUTS)
def test_larger_pattern_agrees(layout):
    bd = side_length_lp(rq.perturb_angles(miura(14, 11, layout), 0.02 * PI, 7))
    assert assert_models_agree(bd, OMEGAS)


@pytest.mark.parametrize("layout", LAYOUTS)
def test_exact_miura_agrees(layout):
    assert assert_models_agree(miura(5, 4, layout, a=0.7, b=1.9, alpha0=0.8), OMEGAS)


# --------------------------------------------------------------------------- failures

FAILING_CASES = [(n, seed) for n in (5, 8, 12, 20, 40) for seed in range(6)]


@pytest.mark.parametrize("n, seed", FAILING_CASES)
def test_random_input_same_outcome(n, seed):
    """The paper's Fig. Random input: 0.05 pi around a Miura with Miura lengths."""
    bd = rq.perturb_angles(rq.miura_boundary(n, n), 0.05 * PI, seed)
    assert_models_agree(bd, [0.0, 1.0, PI])


def test_random_input_cases_do_fail():
    """Most of the cases above fail (final check), so they really test the errors."""
    fails = [isinstance(outcome(nm, rq.perturb_angles(rq.miura_boundary(n, n), 0.05 * PI, s)),
                        tuple) for n, s in FAILING_CASES]
    assert sum(fails) >= len(FAILING_CASES) // 2


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("seed", range(8))
def test_large_perturbation_same_error(layout, seed):
    """0.3 pi perturbations: first-check as well as final-check failures (every one of these
    seeds gives admissible vertices; a BoundaryDataError fails the test)."""
    bd = rq.perturb_angles(miura(6, 6, layout), 0.3 * PI, seed)
    assert_models_agree(bd, [0.5])


def test_large_perturbations_hit_the_first_check():
    checks = set()
    for layout in LAYOUTS:
        for seed in range(8):
            res = outcome(nm, rq.perturb_angles(miura(6, 6, layout), 0.3 * PI, seed))
            if isinstance(res, tuple):
                checks.add(res[0])
    assert {"first", "final"} <= checks


@pytest.mark.parametrize("bracket", [(1.6, 1.7), (2.3, 2.45)])
def test_second_check_same_error(bracket):
    """|mu_abc| = 1 at panel (1, 1), found by root finding on beta of vertex (1, 1)."""
    base = rq.miura_boundary(3, 4, alpha0=1.1)

    def with_beta(x):
        left = base.left.copy()
        left[0, 1] = x
        return rq.BoundaryData(left, base.bottom, base.l_left, base.l_bottom)

    def excess(x):
        a, b, c = with_beta(x).left[0], base.left[1], base.bottom[0]
        mu = (nm.mu1(a[0], a[1], a[2]) * nm.mu2(PI - b[1], PI - b[0], b[2])
              * nm.mu2(c[1], c[0], c[2]))
        return abs(mu) - 1

    bd = with_beta(brentq(excess, *bracket, xtol=1e-16, rtol=1e-15))
    assert outcome(mg, bd) == outcome(nm, bd) == ("second", (1, 1))
