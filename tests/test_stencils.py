"""Jacobians assembled from local stencils (rffqm_nlp.design.stencils) against CasADi's Jacobian
of the whole expression."""

from dataclasses import replace
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rffqm_nlp as rq
from rffqm_nlp.design import clearance
from rffqm_nlp.model import numpy_model
from rffqm_nlp.design import stencils
from rffqm_nlp.model.lengths import side_length_lp


def assembled(jac: stencils.LocalJacobian, x: np.ndarray):
    """The stencil Jacobian at x as a scipy CSC matrix."""
    G = jac.pattern()
    G.data = jac(x)[G.data.astype(int) - 1]
    return G


def assert_lifted_same(jac: stencils.LiftedJacobian, x: np.ndarray, reference) -> None:
    """A lifted Jacobian at x: its direct part F_x within the reference's sparsity, and
    F_x + F_u H the reference's values to round-off (the product is dense in its columns).
    The Lift's products against the dense one."""
    nonzeros, lift = jac(x)
    G = jac.pattern()
    G.data = np.ones(G.nnz)
    R = reference.tocsc().copy()
    R.data = np.ones(R.nnz)
    assert (G - G.multiply(R)).nnz == 0
    G.data = nonzeros[jac.pattern().data.astype(int) - 1]
    dense = G.toarray()
    product = lift.Fu.toarray() @ lift.H
    dense[np.ix_(lift.rows, lift.columns)] += product
    ref = reference.toarray()
    np.testing.assert_allclose(dense, ref, rtol=0, atol=1e-13 * max(1.0, np.abs(ref).max()))
    rng = np.random.default_rng(0)
    X, w = rng.standard_normal((G.shape[1], 2)), rng.standard_normal((G.shape[0], 2))

    def close(a, b):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * np.abs(b).max())

    close(lift.times(X), product @ X[lift.columns])
    close(lift.transpose_times(w), product.T @ w[lift.rows])
    close(lift.product(), product)


def assert_same(G, reference) -> None:
    """Same sparsity and the same values to round-off."""
    reference = reference.tocsc()
    reference.sort_indices()
    assert G.shape == reference.shape
    np.testing.assert_array_equal(G.indptr, reference.indptr)
    np.testing.assert_array_equal(G.indices, reference.indices)
    scale = max(1.0, np.abs(reference.data).max())
    np.testing.assert_allclose(G.data, reference.data, rtol=0, atol=1e-13 * scale)


def test_a_toy_stencil_with_a_repeated_column_and_linear_rows():
    """g = (x_i x_{i+1}^2 + p_i x_i for i < 3, x_0 - 2 x_3): a variable twice in one
    instance sums its two entries; the linear row comes as triplets."""
    z, p = ca.SX.sym("z", 3), ca.SX.sym("p", 1)
    f = ca.Function("f", [z, p], [z[0] * z[1] ** 2 + p * z[2]])
    s = stencils.stencil(f, [[0, 1, 0], [1, 2, 1], [2, 3, 2]], [[0], [1], [2]],
                         [[1.5], [-2.0], [0.5]])
    const = stencils.Constant(np.array([3, 3]), np.array([0, 3]), np.array([1.0, -2.0]))
    jac = stencils.LocalJacobian([s], [const], (4, 4))
    x = ca.MX.sym("x", 4)
    pv = [1.5, -2.0, 0.5]
    g = ca.vertcat(*(x[i] * x[i + 1] ** 2 + pv[i] * x[i] for i in range(3)), x[0] - 2 * x[3])
    value = np.array([0.3, -1.2, 2.0, 0.7])
    assert_same(assembled(jac, value),
                ca.Function("J", [x], [ca.jacobian(g, x)])(value).sparse())


def test_a_lifted_jacobian_is_the_chain_rule():
    """g = (x_0 u_0 + u_1^2, x_3 u_1, x_0 + x_3) at u = h(x) = (x_1^2, x_1 x_2, 0): the
    Jacobian of g(x, h(x)) from the local one over (x, u) and H = dh/dx in the columns
    (1, 2) it reads, against CasADi's; u_2 is read by no row."""
    z = ca.SX.sym("z", 5)  # x_0, x_3, u_0, u_1, u_2
    p = ca.SX.sym("p", 0)
    f = ca.Function("f", [z, p], [ca.vertcat(z[0] * z[2] + z[3] ** 2, z[1] * z[3], z[0] + z[1])])
    inner = stencils.LocalJacobian([stencils.stencil(f, [[0, 3, 4, 5, 6]], [[0, 1, 2]])], [],
                                   (3, 4 + 3))

    def lift(x):
        return (np.array([x[1] ** 2, x[1] * x[2], 0.0]),
                np.array([[2 * x[1], 0.0], [x[2], x[1]], [0.0, 0.0]]))

    jac = stencils.LiftedJacobian(inner, lift, np.array([1, 2]), 4)
    x = ca.MX.sym("x", 4)
    u0, u1 = x[1] ** 2, x[1] * x[2]
    g = ca.vertcat(x[0] * u0 + u1 ** 2, x[3] * u1, x[0] + x[3])
    value = np.array([0.3, -1.2, 2.0, 0.7])
    assert list(jac.rows) == [0, 1]
    assert_lifted_same(jac, value, ca.Function("J", [x], [ca.jacobian(g, x)])(value).sparse())


def test_rows_covered_twice_or_not_at_all_are_refused():
    z, p = ca.SX.sym("z", 1), ca.SX.sym("p", 0)
    s = stencils.stencil(ca.Function("f", [z, p], [z ** 2]), [[0], [1]], [[0], [0]])
    with pytest.raises(RuntimeError, match="cover"):
        stencils.LocalJacobian([s], [], (2, 2)).pattern()


def test_index_arrays_of_the_wrong_shape_are_refused():
    z, p = ca.SX.sym("z", 2), ca.SX.sym("p", 0)
    with pytest.raises(ValueError, match="columns has shape"):
        stencils.stencil(ca.Function("f", [z, p], [z[0] * z[1]]), [[0, 1, 2]], [[0]])


def problem(name: str, n: int, **kw):
    problem, _ = rq.load_design(f"targets/{name}.toml")
    return replace(problem, panels=(n, n), **kw)


def casadi_jacobian(nlp, x: np.ndarray, of: str = "g"):
    return ca.Function("J", [nlp.x], [ca.jacobian(getattr(nlp, of), nlp.x)])(x).sparse()


CASES = [("sphere_cap", 4, {}), ("hyperboloid", 6, {}), ("quarter_vase", 8, {}),
         ("sphere_cap", 6, {"fix": ("omega",)}),
         ("hyperboloid", 6, {"weights": {"position": 1.0, "forms": 0.5, "regularization": 0.2,
                                         "smoothness": 0.3}}),
         ("hyperboloid", 4, {"correspondence": "lattice"}),
         ("sphere_cap", 4, {"correspondence": "lattice",
                            "weights": {"position": 1.0, "forms": 0.0, "regularization": 0.0,
                                        "smoothness": 0.2}}),
         ("quarter_vase", 4, {"weights": {"position": 0.0, "forms": 1.0,
                                          "regularization": 0.1}}),
         ("quarter_vase", 6, {"correspondence": "free"})]


@pytest.mark.parametrize("case", CASES)
@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_the_simultaneous_jacobians_are_casadis(case, seed):
    """The simultaneous transcription's Jacobians from stencils have CasADi's sparsity and
    values at a random point near the start: g's (every block of rows: the panel cell, edge
    directions, lifted multipliers, rotations, vertices, partial means, margins, boundary
    MV, sides, a free correspondence's grid rows) and the residuals' (the loss, the
    alignment's norm, the Tikhonov and smoothness terms, a free grid's Tikhonov term)."""
    name, n, kw = case
    nlp = problem(name, n, **kw).transcribe()
    x = nlp.x0 + 0.05 * np.random.default_rng(seed).standard_normal(nlp.x0.size)
    assert_same(assembled(nlp.g_jacobian, x), casadi_jacobian(nlp, x))
    reference = casadi_jacobian(nlp, x, "residuals")
    if kw.get("correspondence", "free") == "free":
        assert_lifted_same(nlp.r_jacobian, x, reference)
    else:
        assert_same(assembled(nlp.r_jacobian, x), reference)


@settings(max_examples=4, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_the_jacobian_is_casadis_with_valley_vertex_signs(seed):
    """Started from a perturbed Miura with its zig-zag along j, every vertex sign sigma (a
    parameter of the stencils) is -1; the bundled targets' starts have +1."""
    prob = problem("hyperboloid", 6)
    miura = rq.miura_boundary(6, 6, a=1.0, b=1.3, alpha0=1.1, layout="zigzag_j")
    bd = side_length_lp(rq.perturb_angles(miura, 0.02, seed))
    sigma = numpy_model.march(bd).sigma
    assert np.all(sigma == -1)
    start = prob.start()
    nlp = prob.transcribe(initial=SimpleNamespace(
        boundary=bd, omega=start.omega, rotation=start.rotation,
        translation=start.translation, problem={}))  # no recorded problem: no map to keep
    x = nlp.x0 + 0.05 * np.random.default_rng(seed).standard_normal(nlp.x0.size)
    assert_same(assembled(nlp.g_jacobian, x), casadi_jacobian(nlp, x))


def test_clearance_rows_appended_to_the_nlp_join_its_stencils():
    """NLP.with_rows (here the clearance rows of rffqm_nlp.design.clearance) extends the stencil
    Jacobian by the new rows."""
    prob = problem("sphere_cap", 6)
    nlp = prob.transcribe()
    pattern = numpy_model.march(prob.start().boundary)
    pairs = np.array([[0, 7], [3, 20], [5, 30]])
    out = clearance.constrain(nlp, pattern, 1.0, pairs, 0.01)
    assert out.g.numel() > nlp.g.numel()
    x = out.x0 + 0.01 * np.random.default_rng(1).standard_normal(out.x0.size)
    assert_same(assembled(out.g_jacobian, x), casadi_jacobian(out, x))
