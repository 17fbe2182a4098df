"""backend: one NumPy/CasADi dispatch for the formulas written once for both, and the checks
of the public functions' numeric arguments and results."""

import casadi as ca
import numpy as np
import pytest

from rffqm_nlp.targets import shape
from rffqm_nlp.targets import surfaces
from rffqm_nlp.model import vertex
from rffqm_nlp.model.backend import (CASADI, NUMPY, check_formula_args, finite_array, finite_result,
                               is_casadi, math_for)
from rffqm_nlp.errors import InputError, SurfaceError
from rffqm_nlp.files import Key


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


# --------------------------------------------------------------------------- argument checks
@pytest.mark.parametrize("value, kwargs, words", [
    ("abc", {}, "x must be a finite number or an array of finite numbers, got the string 'abc'"),
    (None, {}, "got None"), ({"a": 1}, {}, "got a table"), (True, {}, "got booleans"),
    ([1.0, "a"], {}, "got a list of 2 items holding something other than numbers"),
    ([[1.0], [1.0, 2.0]], {}, "got a ragged or mixed list"), (1 + 2j, {}, "complex numbers"),
    ([10**400], {}, "too large for a float"), (np.array([1.0, np.inf]), {}, "got inf at index "
                                                                              "(1,)"),
    (np.zeros((2, 3)), {"shape": (None, 3, 3)}, "of shape (n, 3, 3), got shape (2, 3)"),
    (np.zeros(0), {"least": 1}, "with at least 1 entry, got shape (0,)"),
    (np.zeros(3), {"ndim": 2}, "a 2-D array of finite numbers, got shape (3,)"),
    (ca.SX.sym("x"), {}, "got a SX"),
])
def test_finite_array_refuses_in_one_line_naming_the_argument(value, kwargs, words):
    with pytest.raises(InputError) as exc:
        finite_array(value, "x", **kwargs)
    assert words in str(exc.value) and str(exc.value).startswith("x must be")


def test_finite_array_copies_and_lets_nan_through_on_request():
    src = np.array([1, 2], dtype=np.int32)
    out = finite_array(src, "x")
    assert out.dtype == float and out is not src
    assert np.isnan(finite_array([np.nan], "x", finite=False)[0])
    with pytest.raises(SurfaceError):
        finite_array("a", "u", error=SurfaceError)
    with pytest.raises(InputError, match="takes shape as a tuple"):
        finite_array(1.0, "x", shape=3)


def test_formula_arguments_and_results():
    """check_formula_args says whether a graph is built and refuses numeric arguments that
    are not finite, broadcasting numbers (sigma +1 or -1); finite_result refuses NaN."""
    assert check_formula_args(alpha=1.0, sigma=np.array([1.0, -1.0])) is False
    assert check_formula_args(alpha=ca.SX.sym("a"), sigma=1.0) is True
    for kwargs, words in (({"sigma": 0.5}, r"sigma must be \+1 or -1"),
                          ({"alpha": ca.SX.sym("a"), "sigma": "a"}, "sigma must be"),
                          ({"alpha": "a"}, "alpha must be"),
                          ({"alpha": np.ones(2), "beta": np.ones(3)}, "must broadcast")):
        with pytest.raises(InputError, match=words):
            check_formula_args(**kwargs)
    value = (1.0, np.ones(2))
    assert finite_result(value, "never") is value
    with pytest.raises(InputError, match="^the reason$"):
        finite_result((1.0, np.array([np.nan])), "the reason")
    with pytest.raises(InputError, match="checks numbers"):
        finite_result("text", "x")


