"""The transcriptions (rffqm_nlp.design.transcription): both state the same NLP, its
derivatives and IPOPT's Hessians of it (rffqm_nlp.design.solvers.ipopt.hessians), the
loss, the rows appended to it, and the lifted variables of the simultaneous one. The
stencil Jacobians are checked in tests/test_stencils.py, the correspondence in
tests/test_correspondence.py."""

from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rffqm_nlp as rq
from rffqm_nlp.design import transcription
from rffqm_nlp.design.solvers.ipopt.hessians import gauss_newton_hessian, lagrangian_hessian
from rffqm_nlp.design.transcription.lifting import MeanTree, sides_by_antidiagonal
from rffqm_nlp.model import numpy_model
from rffqm_nlp.model.lengths import side_length_lp
from rffqm_nlp.targets import shape

TRANSCRIPTIONS = ["sequential", "simultaneous"]


def bundled(name: str, panels: int = 8, **fields) -> rq.DesignProblem:
    """The bundled target file's problem at panels x panels."""
    problem, _ = rq.load_design(f"targets/{name}.toml")
    return replace(problem, panels=(panels, panels), **fields)


def transcribed(problem: rq.DesignProblem, name: str) -> transcription.NLP:
    return problem.transcribe(options=rq.SolveOptions(solver="ipopt", transcription=name))


# ------------------------------------------------------------------ one problem, two NLPs
@pytest.mark.parametrize("layout", ["zigzag_i", "zigzag_j"])
def test_transcriptions_state_the_same_problem_at_the_start(layout):
    # zigzag_j has sigma = -1 vertices with alpha + beta > pi, where the simultaneous crease
    # quaternions are those of the marching times -1 (lifting.crease_quaternion_signs).
    prob = bundled("quarter_vase", layout=layout)
    seq, sim = (transcribed(prob, name) for name in TRANSCRIPTIONS)

    def evaluate(nlp):
        F = ca.Function("F", [nlp.x], [nlp.residuals, nlp.g, *nlp.folded.call([nlp.x])])
        res, g, *Y = (np.array(v.full()) for v in F(nlp.x0))
        return res.ravel(), g.ravel(), np.stack(Y, -1)

    r1, g1, Y1 = evaluate(seq)
    r2, g2, Y2 = evaluate(sim)
    np.testing.assert_allclose(r2, r1, atol=1e-12)
    np.testing.assert_allclose(Y2, Y1, atol=1e-12)
    # The simultaneous start satisfies its marching equations, so it is a feasible point.
    assert np.all(g2 >= sim.lbg - 1e-10) and np.all(g2 <= sim.ubg + 1e-10)
    assert np.all(g1 >= seq.lbg - 1e-10) and np.all(g1 <= seq.ubg + 1e-10)
    # Fixing a group pins the same boundary data in both.
    fixed = transcribed(replace(prob, fix=("lengths",)), "simultaneous")
    idx = fixed.groups["lengths"]
    np.testing.assert_array_equal(fixed.lbx[idx], fixed.ubx[idx])
    np.testing.assert_allclose(fixed.x0[idx], prob.start().boundary.lengths)


@pytest.fixture(scope="module", params=["zigzag_i", "zigzag_j"])
def both(request):
    """The 6 x 6 quarter vase (a free correspondence) in both transcriptions, with the
    Function x -> (residuals, Yx, Yy, Yz, Tx, Ty, Tz) of each."""
    prob = bundled("quarter_vase", 6, layout=request.param)
    out = []
    for name in TRANSCRIPTIONS:
        nlp = transcribed(prob, name)
        out.append((nlp, ca.Function("F", [nlp.x], [nlp.residuals, *nlp.folded.call([nlp.x]),
                                                     *nlp.free_target.call([nlp.x])])))
    return prob, out


def design_point(nlp: transcription.NLP, bd: rq.BoundaryData, omega: float,
                 rigid: np.ndarray, controls: np.ndarray) -> np.ndarray:
    """x of ``nlp`` with these boundary data, omega, alignment (q, t) and controls: the
    boundary entries found through ``unpack`` (a selection of x), the alignment last but
    the controls in the sequential x and last in the simultaneous one, the rest marched
    (``project``)."""
    x = nlp.x0.copy()
    where = nlp.unpack(np.arange(x.size, dtype=float))[0].full().ravel().astype(int)
    x[where], x[nlp.groups["omega"]], x[nlp.grid_index] = bd.to_vector(), omega, controls
    if nlp.project is None:
        x[nlp.groups["rigid"]] = rigid
        return x
    x[x.size - 7:] = rigid
    out = nlp.project(x)
    assert out is not None
    return out


@settings(max_examples=3, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_both_transcriptions_state_the_same_loss_and_fold_at_any_design(both, seed):
    """Away from the start (other boundary data, omega, alignment and controls), the
    sequential NLP and the simultaneous one, re-marched, have the same residuals (so the
    same objective), folded state and target lattice, to round-off."""
    prob, ((seq, F_seq), (sim, F_sim)) = both
    rng = np.random.default_rng(seed)
    start = prob.start()
    bd = side_length_lp(rq.perturb_angles(start.boundary, 0.02, rng))
    assert np.array_equal(numpy_model.march(bd).sigma,
                          numpy_model.march(start.boundary).sigma)
    omega = start.omega + rng.uniform(-0.05, 0.05)
    rigid = seq.x0[seq.groups["rigid"]] + 0.02 * rng.standard_normal(7)
    grid = seq.grid_index
    free = seq.lbx[grid] < seq.ubx[grid]
    controls = seq.x0[grid] + np.where(free, 0.01 * rng.uniform(-1, 1, grid.size), 0.0)
    x_seq, x_sim = (design_point(nlp, bd, omega, rigid, controls) for nlp in (seq, sim))
    out_seq, out_sim = ([v.full() for v in F(x)] for F, x in ((F_seq, x_seq), (F_sim, x_sim)))
    scale = np.abs(out_seq[0]).max()
    np.testing.assert_allclose(out_sim[0], out_seq[0], rtol=0, atol=1e-12 * scale)
    for mine, theirs in zip(out_sim[1:], out_seq[1:]):
        np.testing.assert_allclose(mine, theirs, rtol=0, atol=1e-12 * prob.target.diameter())
    np.testing.assert_allclose(seq.folded_array(x_seq),
                               numpy_model.fold(numpy_model.march(bd), omega),
                               atol=1e-12 * prob.target.diameter())
    at_start = F_seq(seq.x0)[0].full()
    assert np.abs(out_seq[0] - at_start).max() > 1e-3 * scale  # not the start's residuals


# ------------------------------------------------------------------ derivatives, Hessians
@pytest.mark.parametrize("name", TRANSCRIPTIONS)
def test_nlp_derivatives_match_finite_differences(name):
    """Gradient, constraint Jacobian and the Hessian of the Lagrangian IPOPT uses."""
    nlp = transcribed(bundled("hyperboloid"), name)
    f = 0.5 * ca.sumsqr(nlp.residuals)
    lam = ca.MX.sym("lam", nlp.g.numel())
    lagrangian_grad = ca.gradient(f + ca.dot(lam, nlp.g), nlp.x)
    F = ca.Function("F", [nlp.x, lam], [f, ca.gradient(f, nlp.x), nlp.g,
                                        ca.jacobian(nlp.g, nlp.x), lagrangian_grad,
                                        ca.jacobian(lagrangian_grad, nlp.x)])
    rng = np.random.default_rng(1)
    x0 = nlp.x0 + 1e-3 * rng.normal(size=nlp.x0.size)
    mult = rng.normal(size=nlp.g.numel())
    _, grad, _, jac, _, hess = (np.array(v.full()) for v in F(x0, mult))
    if nlp.parts is not None:  # IPOPT gets the Hessian assembled around the global rows
        H = lagrangian_hessian(nlp)
        assert H.sparsity_out(0) == ca.triu(F.sparsity_out(5))
        upper = np.array(ca.densify(H(x0, [], 1.0, mult)).full())
        np.testing.assert_allclose(upper, np.triu(hess), rtol=0, atol=1e-12 * np.abs(hess).max())
        hess = upper + np.triu(upper, 1).T
    h = 1e-6
    for _ in range(3):
        d = rng.normal(size=x0.size)
        fp, _, gp, _, lp, _ = F(x0 + h * d, mult)
        fm, _, gm, _, lm, _ = F(x0 - h * d, mult)
        assert float((fp - fm) / (2 * h)) == pytest.approx(float(grad.ravel() @ d), rel=1e-6)
        for plus, minus, exact in ((gp, gm, jac @ d), (lp, lm, hess @ d)):
            fd = (plus - minus).full().ravel() / (2 * h)
            np.testing.assert_allclose(fd, exact.ravel(), rtol=1e-5,
                                       atol=1e-6 * np.abs(exact).max())


def test_the_assembled_hessian_scales_with_the_objective_multiplier():
    """lam_f weighs the objective's part only: H(lam_f) - H(0) = lam_f (H(1) - H(0))."""
    nlp = transcribed(bundled("sphere_cap", 4), "simultaneous")
    H = lagrangian_hessian(nlp)
    rng = np.random.default_rng(4)
    x = nlp.x0 + 1e-3 * rng.standard_normal(nlp.x0.size)
    mult = rng.standard_normal(nlp.g.numel())
    at = {s: np.array(ca.densify(H(x, [], s, mult)).full()) for s in (0.0, 1.0, 2.5)}
    objective = at[1.0] - at[0.0]
    assert np.abs(objective).max() > 0 and np.abs(at[0.0]).max() > 0
    np.testing.assert_allclose(at[2.5] - at[0.0], 2.5 * objective, rtol=0,
                               atol=1e-12 * np.abs(at[2.5]).max())


@pytest.mark.parametrize("name", TRANSCRIPTIONS)
def test_gauss_newton_hessian_is_jtj_plus_the_damping(name):
    """lam_f (J' J + damping D), upper triangle, J the residuals' Jacobian (by central
    differences), D the NLP's damping weights; the constraints' multipliers play no part."""
    nlp = transcribed(bundled("quarter_vase"), name)
    x = nlp.x0 + 1e-3 * np.random.default_rng(2).normal(size=nlp.x0.size)
    res = ca.Function("r", [nlp.x], [nlp.residuals])
    h, eye = 1e-6, np.eye(x.size)
    J = np.column_stack([(res(x + h * e) - res(x - h * e)).full().ravel() / (2 * h)
                         for e in eye])
    for damping in (0.0, 0.05):
        H = gauss_newton_hessian(nlp, damping)(x, [], 0.7, np.ones(nlp.g.numel()))
        expected = np.triu(0.7 * (J.T @ J + damping * np.diag(nlp.damping_weights)))
        np.testing.assert_allclose(np.array(ca.densify(H).full()), expected,
                                   atol=1e-6 * np.abs(expected).max())


# ------------------------------------------------------------------ the loss
def folded_lattice(seed: int) -> np.ndarray:
    """The coarse lattice (5, 5, 3) of a perturbed, folded 8 x 8 Miura."""
    bd = rq.perturb_angles(rq.miura_boundary(8, 8, 1.0, 1.2, 1.1, "zigzag_i"), 0.05, seed)
    return shape.coarse_grain(numpy_model.fold(numpy_model.march(bd), 1.5))


def loss_values(r: np.ndarray, target: np.ndarray, weights: dict, spacing: float):
    """loss_residuals at the lattice r (n, m, 3) aligned onto the target by Kabsch."""
    R, t, _ = shape.kabsch(r, target)
    res = transcription.loss_residuals([ca.DM(r[..., c]) for c in range(3)], ca.DM(R),
                                       ca.DM(t), target, weights, spacing)
    return np.array(ca.evalf(res).full()).ravel()


@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_the_loss_is_the_same_for_a_moved_target_with_the_alignment_refitted(seed):
    """A rigid motion (Q, c) of the target, the alignment fitted again: the forms' rows are
    the same, the position rows of every point are rotated by Q (so the same loss); the
    position term is the weighted mean square distance over the spacing squared."""
    rng = np.random.default_rng(seed)
    r = folded_lattice(seed)
    target = r + 0.05 * rng.standard_normal(r.shape)
    Q = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    Q *= np.linalg.det(Q)  # a rotation
    moved = target @ Q.T + rng.uniform(-5, 5, 3)
    spacing = 0.7
    forms, position = {"forms": 0.5}, {"position": 2.0}
    a, b = loss_values(r, target, forms, spacing), loss_values(r, moved, forms, spacing)
    np.testing.assert_allclose(b, a, rtol=0, atol=1e-10 * np.abs(a).max())
    a, b = loss_values(r, target, position, spacing), loss_values(r, moved, position, spacing)
    n = r.shape[0] * r.shape[1]
    np.testing.assert_allclose(b.reshape(n, 3), a.reshape(n, 3) @ Q.T, rtol=0, atol=1e-11)
    R, t, rms = shape.kabsch(r, target)
    assert np.sum(a ** 2) == pytest.approx(2.0 * rms ** 2 / spacing ** 2, rel=1e-10)
    both = loss_values(r, target, {**forms, **position}, spacing)
    np.testing.assert_array_equal(both, np.concatenate([loss_values(r, target, forms, spacing),
                                                        a]))


# ------------------------------------------------------------------ rows appended
@pytest.mark.parametrize("name", TRANSCRIPTIONS)
def test_rows_appended_keep_the_bounds_beside_their_rows(name):
    nlp = transcribed(bundled("sphere_cap", 4), name)
    n_g = nlp.g.numel()
    rows = ca.vertcat(nlp.x[0] * nlp.x[1], ca.sumsqr(nlp.x[:3]))
    out = nlp.with_rows(rows, [0, -1], [np.inf, 2])
    again = out.with_rows(nlp.x[2], np.array([-3.0]), np.array([3.0]))
    for nlp_ in (out, again):
        assert nlp_.g.numel() == nlp_.lbg.size == nlp_.ubg.size
        assert nlp_.lbg.dtype == nlp_.ubg.dtype == float
    np.testing.assert_array_equal(again.lbg, np.concatenate([nlp.lbg, [0, -1, -3]]))
    np.testing.assert_array_equal(again.ubg, np.concatenate([nlp.ubg, [np.inf, 2, 3]]))
    x = nlp.x0 + 0.01 * np.sin(np.arange(nlp.x0.size))
    g = ca.Function("g", [again.x], [again.g])(x).full().ravel()
    np.testing.assert_array_equal(g[:n_g], ca.Function("g", [nlp.x], [nlp.g])(x).full().ravel())
    np.testing.assert_allclose(g[n_g:], [x[0] * x[1], np.sum(x[:3] ** 2), x[2]], rtol=1e-14)
    assert nlp.g.numel() == nlp.lbg.size == n_g  # the NLP itself is left as it was
    assert (again.g_jacobian is None) == (name == "sequential")


# ------------------------------------------------------------------ lifted variables
@settings(max_examples=50, deadline=None)
@given(st.integers(2, 3000), st.integers(2, 20), st.randoms(use_true_random=False),
       st.booleans())
def test_mean_tree_root_is_the_mean_and_every_row_is_local(K, branching, rnd, shuffled):
    order = np.array(rnd.sample(range(K), K)) if shuffled else None
    tree = MeanTree(K, branching, order)
    sides = np.array([rnd.uniform(0.1, 10) for _ in range(K)])
    s, P = ca.MX.sym("s", K), ca.MX.sym("P", tree.size)
    nodes = ca.Function("nodes", [s], [tree.expression(s)])(sides).full().ravel()
    assert nodes.size == tree.size and nodes[-1] == pytest.approx(sides.mean(), rel=1e-13)
    res, mean = tree.residuals(s, P)
    F = ca.Function("F", [s, P], [res, mean])
    r, m = F(sides, nodes)
    assert np.abs(r.full()).max(initial=0) <= 1e-12 * sides.max() and float(m) == nodes[-1]
    jac = ca.jacobian_sparsity(res, ca.vertcat(s, P))
    rows = np.diff(np.array(jac.T.colind()))  # entries per residual row
    assert rows.max(initial=0) <= branching + 1
    if order is not None:  # level 1 averages the sides in blocks of that order
        first = tree.levels[0].sparse().tocoo()
        np.testing.assert_array_equal(first.row[np.argsort(first.col)],
                                      np.argsort(order) // branching)


@pytest.mark.parametrize("N, M", [(1, 1), (3, 5), (6, 2)])
def test_sides_by_antidiagonal_is_a_permutation_by_first_vertex(N, M):
    order = sides_by_antidiagonal(N, M)
    i = np.concatenate([np.arange(N + 1)[:, None].repeat(M, 1).ravel("F"),
                        np.arange(N)[:, None].repeat(M + 1, 1).ravel("F")])
    j = np.concatenate([np.arange(M)[None, :].repeat(N + 1, 0).ravel("F"),
                        np.arange(M + 1)[None, :].repeat(N, 0).ravel("F")])
    np.testing.assert_array_equal(np.sort(order), np.arange((N + 1) * M + N * (M + 1)))
    assert np.all(np.diff((i + j)[order]) >= 0)
