"""backend: one NumPy/CasADi dispatch for the formulas written once for both."""

import casadi as ca
import numpy as np
import pytest

from rffqm_nlp import shape, surfaces, vertex
from rffqm_nlp.backend import CASADI, NUMPY, is_casadi, math_for


@pytest.mark.parametrize("args", [
    (np.array([0.1, 0.2]),), (0.3,), (1,), (np.float64(0.3),), (0.3, np.ones((2, 2))), ()])
def test_numbers_and_arrays_get_numpy(args):
    assert not is_casadi(*args)
    assert math_for(*args) is NUMPY


@pytest.mark.parametrize("args", [
    (ca.SX.sym("x"),), (ca.MX.sym("x", 2, 3),), (ca.DM([1.0, 2.0]),),
    (0.3, ca.SX.sym("x")), (np.ones(3), ca.DM(2.0)), (ca.MX.sym("x"), 1.0, np.zeros(2))])
def test_any_casadi_argument_gets_casadi(args):
    assert is_casadi(*args)
    assert math_for(*args) is CASADI


def test_both_namespaces_have_the_same_names():
    assert vars(NUMPY).keys() == vars(CASADI).keys()
    assert surfaces.mathlib is math_for


def _written_once(u, v):
    m = math_for(u, v)
    r = m.sqrt(u * u + v * v + 1.0)
    return (m.sin(u) * m.cos(v) + m.tan(u / 3) - m.atan(v) + m.atan2(v, u) + m.exp(-r)
            + m.log(r) + m.sinh(u) * m.cosh(v) + m.tanh(u - v) + m.fabs(u - v)
            + m.where(u > v, u, 2 * v) + m.pi)


def test_a_function_written_with_it_gives_the_same_numbers_on_both():
    rng = np.random.default_rng(0)
    u, v = rng.uniform(-2, 2, 50), rng.uniform(-2, 2, 50)
    expected = _written_once(u, v)
    for kind in (ca.SX, ca.MX):
        us, vs = kind.sym("u"), kind.sym("v")
        f = ca.Function("f", [us, vs], [_written_once(us, vs)])
        np.testing.assert_allclose(np.ravel(f(u[None, :], v[None, :])), expected, rtol=1e-14)
    dm = _written_once(ca.DM(u), ca.DM(v))
    assert isinstance(dm, ca.DM)
    np.testing.assert_allclose(np.ravel(dm), expected, rtol=1e-14)
    mixed = _written_once(ca.DM(u), v)  # one CasADi argument is enough
    np.testing.assert_allclose(np.ravel(mixed), expected, rtol=1e-14)
    assert float(_written_once(0.5, -0.25)) == pytest.approx(_written_once(ca.DM(0.5), -0.25))


def test_vertex_and_shape_dispatch_through_it():
    a, b, s = np.array([1.0, 2.0]), np.array([1.3, 0.7]), np.array([-1.0, 1.0])
    sym = ca.SX.sym("a", 2), ca.SX.sym("b", 2)
    mu = ca.Function("mu", list(sym), [vertex.mv_multiplier(*sym, s)])
    np.testing.assert_allclose(np.ravel(mu(a, b)), vertex.mv_multiplier(a, b, s), rtol=1e-14)
    P = np.random.default_rng(1).normal(size=(3, 4, 3))
    comps = [ca.SX.sym(c, 3, 4) for c in "xyz"]
    forms = ca.Function("f", comps, list(shape.fundamental_forms(comps)))
    for got, want in zip(forms(*(P[..., k] for k in range(3))), shape.fundamental_forms(P)):
        np.testing.assert_allclose(got.full(), want, rtol=1e-14)
