"""Levenberg-Marquardt on the marching manifold (rffqm_nlp.design.solvers.levenberg_marquardt)."""

from dataclasses import replace
from types import SimpleNamespace

import casadi as ca
import numpy as np
import pytest
import scipy.linalg as la
import scipy.sparse as sp
from scipy.optimize import lsq_linear
from hypothesis import given, settings, strategies as st
from threadpoolctl import threadpool_info, threadpool_limits

import rffqm_nlp as rq
from rffqm_nlp.model import numpy_model
from rffqm_nlp.design.solvers import levenberg_marquardt as lm
from rffqm_nlp.design.solvers.levenberg_marquardt import (gram, levels, loop, secant, steps,
                                                          window)
from rffqm_nlp.design import DesignProblem, SolveOptions

LM = "levenberg-marquardt"


PROBLEM_FIELDS = set(DesignProblem.__dataclass_fields__)


def small(name: str, **kw) -> tuple[DesignProblem, SolveOptions]:
    """The 8 x 8 target with Levenberg-Marquardt; ``kw`` sets DesignProblem and SolveOptions
    fields."""
    problem, options = rq.load_design(f"targets/{name}.toml")
    return (replace(problem, **{"panels": (8, 8), **{k: v for k, v in kw.items()
                                                     if k in PROBLEM_FIELDS}}),
            replace(options, **{"stop_rms": None, "solver": LM,
                                **{k: v for k, v in kw.items() if k not in PROBLEM_FIELDS}}))


@pytest.fixture(scope="module")
def manifold():
    prob, _ = small("quarter_vase")
    return prob, lm.Manifold(prob.transcribe())


def test_marching_equations_are_ordered_in_levels(manifold):
    """Every equation uses, besides its own unknown, only unknowns of equations of lower
    levels, and its own unknown's coefficient does not vanish."""
    _, man = manifold
    G = man.jacobian_g.pattern().tocsr()
    C = G[man.eq][:, man.state].tocsr()
    level = np.empty(man.eq.size, dtype=int)
    for k, rows in enumerate(man.levels):
        level[rows] = k
    assert sorted(np.concatenate(man.levels)) == list(range(man.eq.size))
    assert sorted(man.match) == list(range(man.state.size))  # one unknown per equation
    owner = np.empty(man.state.size, dtype=int)
    owner[man.match] = np.arange(man.eq.size)
    for e in range(man.eq.size):
        uses = set(C.indices[C.indptr[e]:C.indptr[e + 1]].tolist()) - {man.match[e]}
        assert all(level[owner[u]] < level[e] for u in uses)
    assert len(man.levels) < man.eq.size / 10  # few levels: a product each
    Gx = man.jacobian_g(man.nlp.project(man.nlp.x0))
    own = C.tocoo()
    own_value = Gx[own.data[own.col == man.match[own.row]].astype(int) - 1]
    assert np.abs(own_value).min() > 1e-3


@settings(max_examples=50, deadline=None)
@given(n=st.integers(2, 40), data=st.data())
def test_postponed_chains_sit_just_below_their_earliest_user(n, data):
    """On a random DAG of equations (each uses a few earlier ones): the postponed levels
    stay a valid order with no more levels; a chain equation (at most one input, itself a
    chain's) sits one level below its earliest user, every other keeps its earliest level."""
    deps = [sorted(data.draw(st.sets(st.integers(0, e - 1), max_size=min(e, 3))))
            if e else [] for e in range(n)]
    rows = np.repeat(np.arange(n), [len(d) for d in deps])
    cols = np.array([u for d in deps for u in d], dtype=int)
    D = sp.csr_matrix((np.ones(rows.size), (rows, cols)), shape=(n, n))
    level = np.zeros(n, dtype=int)
    for e in range(n):
        level[e] = 1 + max((level[u] for u in deps[e]), default=-1)
    late = levels.postponed(level, D, D.T.tocsr())
    users = [[e for e in range(n) if u in deps[e]] for u in range(n)]
    chain = np.zeros(n, dtype=bool)
    for e in range(n):
        chain[e] = len(deps[e]) == 0 or (len(deps[e]) == 1 and chain[deps[e][0]])
    assert late.max() == level.max()
    for e in range(n):
        assert all(late[u] < late[e] for u in deps[e])
        if chain[e] and users[e]:
            assert late[e] == min(late[u] for u in users[e]) - 1
        else:
            assert late[e] == level[e]


def test_the_working_set_grows_like_the_side_of_the_pattern(monkeypatch):
    """The rows of S the pass holds at once grow like N + M, not like the pattern: the
    chains (the lifted fold multiplier angles) wait just below the level that reads them,
    and the partial means of the sides group sides of neighbouring anti-diagonals."""
    monkeypatch.setattr(window, "WHOLE_S", 0)
    pool = {}
    for n in (10, 20):
        prob, _ = small("sphere_cap", panels=(n, n))
        pool[n] = lm.Manifold(prob.transcribe()).window.pool
    assert pool[20] <= 2.1 * pool[10]


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_sensitivity_and_reduced_jacobian_match_finite_differences_of_the_march(manifold, seed):
    """S = ds/dd and J_d + J_s S against central differences of the re-march, at a
    perturbed (admissible) design."""
    _, man = manifold
    nlp, rng = man.nlp, np.random.default_rng(seed)
    x = nlp.x0.copy()
    x[man.design] += 1e-3 * rng.standard_normal(man.design.size)
    x = nlp.project(x)
    assert x is not None
    lin = man.linearize(man.point(x))
    S = _whole_sensitivity(lin, np.eye(man.design.size))
    np.testing.assert_array_equal(lin.state_change(np.eye(man.design.size)), S[man.read])
    residuals = ca.Function("r", [nlp.x], [nlp.residuals])
    Jr = lin.jacobian_times(np.eye(man.design.size))
    h = 1e-6
    for k in rng.choice(man.design.size, 12, replace=False):
        xp, xm = x.copy(), x.copy()
        xp[man.design[k]] += h
        xm[man.design[k]] -= h
        xp, xm = nlp.project(xp), nlp.project(xm)
        fd = (xp[man.state] - xm[man.state]) / (2 * h)
        np.testing.assert_allclose(S[:, k], fd, atol=1e-6 * max(1.0, np.abs(fd).max()))
        fd_r = (residuals(xp) - residuals(xm)).full().ravel() / (2 * h)
        np.testing.assert_allclose(Jr[:, k], fd_r, atol=1e-6 * max(1.0, np.abs(fd_r).max()))



@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_the_level_pass_and_the_sweeps_match_the_dense_sensitivity(manifold, seed):
    """J' J, J' r and S_p' D_p S_p accumulated level by level in the working set
    (window.Window), S' by the backward sweep, and the inequality rows, against the
    products of the whole S (the forward sweep of the identity, checked against finite
    differences above) to round-off; the working set is a part of the state. The free
    correspondence's controls are the lifted columns, reduced outside the pool."""
    _, man = manifold
    nlp = man.nlp
    unpinned = (nlp.lbx < nlp.ubx)[nlp.grid_index].sum()
    assert unpinned == 16  # 4 x 4 controls of u and of v, their edges pinned
    assert man.window.free.size == unpinned  # the rigid alignment stays in the pool
    _assert_level_pass_matches_dense(man, seed)


@pytest.mark.parametrize("whole, chunk", [(True, None), (False, None), (False, 7)])
def test_the_level_pass_without_a_lift_matches_the_dense_sensitivity(monkeypatch, whole,
                                                                     chunk):
    """The same in the lattice mode: every design column in the pool; with S kept whole
    (the default at this size), with the working set alone, and with each level's rows
    computed a few at a time (``chunk``; by default, at this size, all at once)."""
    if not whole:
        monkeypatch.setattr(window, "WHOLE_S", 0)
    if chunk is not None:
        monkeypatch.setattr(window, "CHUNK_ROWS", chunk)
    prob, _ = small("sphere_cap", correspondence="lattice")
    man = lm.Manifold(prob.transcribe())
    assert man.window.free.size == 0
    assert man.window.whole == whole
    chunks = [len(level) for level in man.window.chunks]
    assert (max(chunks) > 1) == (chunk is not None)
    for seed in (0, 1):
        _assert_level_pass_matches_dense(man, seed)


def test_the_solve_is_the_same_with_s_whole_and_with_the_working_set(monkeypatch):
    """S kept whole changes how the steps' rows and sweeps are computed, not the steps:
    the same iterations, loss and design as with the working set alone."""
    prob, opts = small("quarter_vase")
    modes, call = [], window.Window.__call__
    monkeypatch.setattr(window.Window, "__call__",
                        lambda self, *a, **k: modes.append(self.whole) or call(self, *a, **k))
    whole = prob.solve(opts)
    monkeypatch.setattr(window, "WHOLE_S", 0)
    working = prob.solve(opts)
    assert modes == [True] * (len(modes) - modes.count(False)) + [False] * modes.count(False)
    assert modes.count(False) > 0 and modes.count(True) > 0
    assert whole.stats.status == working.stats.status == "Solve_Succeeded"
    assert whole.stats.iterations == working.stats.iterations
    np.testing.assert_allclose(whole.stats.objective, working.stats.objective, rtol=1e-10)
    np.testing.assert_allclose(whole.boundary.left, working.boundary.left, rtol=0, atol=1e-8)
    np.testing.assert_allclose(whole.boundary.bottom, working.boundary.bottom, rtol=0,
                               atol=1e-8)


@pytest.mark.parametrize("width, correspondence", [(8, "free"), (16, "free"),
                                                   (12, "lattice")])
def test_the_level_pass_in_bands_matches_the_dense_sensitivity(monkeypatch, width,
                                                               correspondence):
    """With the Gram matrices cut into bands (forced at this size): every row of S is zero
    outside the columns its span gives (the boundary data from the corner to its vertex),
    the spans are narrower than the pool, and the pass gives the dense products."""
    monkeypatch.setattr(gram, "BAND_WIDTH", width)
    prob, _ = small("quarter_vase", correspondence=correspondence)
    man = lm.Manifold(prob.transcribe())
    level_pass = man.window
    assert gram.bands(level_pass.marching.size).size > 3
    p = man.point(man.nlp.project(man.nlp.x0))
    lin = man.linearize(p)
    S = _whole_sensitivity(lin, np.eye(man.design.size))[:, level_pass.marching]  # pool columns
    first, last = level_pass.spans(lin.sensitivity.levels, level_pass.design_span)
    columns = np.arange(S.shape[1])
    outside = (columns < first[:, None]) | (columns > last[:, None])
    assert np.all(S[outside] == 0)
    assert np.mean(last - first + 1) < 0.75 * level_pass.marching.size
    _assert_level_pass_matches_dense(man, 0)


def _whole_sensitivity(lin, X: np.ndarray) -> np.ndarray:
    """S B X in every state row (n_s, p), by the forward sweep (a step reads only the
    rows ``read``)."""
    return lin.sensitivity.levels.forward(lin.sensitivity.basis @ X)


def _assert_level_pass_matches_dense(man: lm.Manifold, seed: int) -> None:
    nlp, rng = man.nlp, np.random.default_rng(seed)
    x = nlp.x0.copy()
    x[man.design] += 1e-3 * rng.standard_normal(man.design.size)
    p = man.point(nlp.project(x))
    lin = man.linearize(p)
    S = _whole_sensitivity(lin, np.eye(man.design.size))
    Jr = lin.jacobian_times(np.eye(man.design.size))
    Sp = S[man.pattern] * np.sqrt(man.pattern_weights)[:, None]

    def close(mine, dense):
        np.testing.assert_allclose(mine, dense, rtol=0, atol=1e-12 * np.abs(dense).max())

    close(lin.JtJ, Jr.T @ Jr)
    close(lin.grad, Jr.T @ p.r)
    close(lin.pattern_metric, Sp.T @ Sp)
    close(lin.state_change(np.eye(man.design.size)), S[man.read])
    Y = rng.standard_normal((man.read.size, 3))
    close(lin.sensitivity.adjoint(Y), S[man.read].T @ Y)
    assert (lin.sensitivity.whole is not None) == man.window.whole
    w = rng.standard_normal(p.r.size)
    close(lin.jacobian_transpose(w), Jr.T @ w)
    m = steps.model(man, p, lin)
    stepper = steps.Steps(man)
    which = rng.choice(m.lower.size, 40, replace=False)
    ng, nbd = man.ineq.size, man.bounded_design.size
    A = np.vstack([lin.G_design.toarray() + lin.G_state @ S[man.read],
                   np.eye(man.design.size)[man.bounded_design], S[man.bounded_state]])
    assert ng + nbd + man.bounded_state.size == A.shape[0]
    close(stepper.rows(m, which), A[which])
    again = np.concatenate([which[::-2], rng.choice(m.lower.size, 10, replace=False)])
    swept = []
    sweep = stepper.swept
    stepper.swept = lambda m_, rows_: swept.append(rows_) or sweep(m_, rows_)
    close(stepper.rows(m, again), A[again])  # partly from the model's rows known so far
    assert set(m.known) == set(which) | set(again)
    assert sorted(np.concatenate(swept)) == sorted(set(again) - set(which))  # the new only
    dd = rng.standard_normal(man.design.size)
    close(stepper.change(m, dd), A @ dd)
    if man.window.whole:
        assert man.window.pool == man.state.size
        close(lin.sensitivity.whole, S[man.read][:, man.window.marching])
    else:
        assert man.window.pool < man.state.size
    bare = man.linearize(p, metric=False)  # the pass without the metric: the rest the same
    assert bare.pattern_metric is None
    close(bare.JtJ, Jr.T @ Jr)
    close(bare.grad, Jr.T @ p.r)
    np.testing.assert_array_equal(steps.model(man, p, bare, m.M).M, m.M)
    with pytest.raises(ValueError, match="metric"):
        steps.model(man, p, bare)


@pytest.mark.parametrize("knots", [2, 3, 4])
def test_the_boundary_basis_interpolates_each_class_between_its_knots(knots):
    """Each class of boundary data (one array, one edge, one parity) longer than ``knots``
    is linear between ``knots`` knots: B's rows sum to one, have at most two entries, and
    reproduce from the knots' values any linear function of the place along the edge; a
    column never mixes classes; other design variables are their own columns."""
    prob, _ = small("quarter_vase", panels=(16, 16))
    nlp = prob.transcribe()
    man = lm.Manifold(nlp)
    klass, position = nlp.boundary_class[man.design], man.position
    sizes = np.bincount(klass[klass >= 0])
    assert sizes.size == 12 and sizes.max() > knots
    B, at = lm.boundary_basis(klass, position, knots)
    assert B.shape == (man.design.size, int(np.sum(klass < 0) + np.minimum(sizes, knots).sum()))
    np.testing.assert_allclose(np.asarray(B.sum(axis=1)).ravel(), 1.0, rtol=0, atol=1e-15)
    assert np.diff(B.indptr).max() == 2
    linear = lambda t: 0.3 + 2.0 * np.abs(t)  # noqa: E731
    np.testing.assert_allclose(B @ linear(at), linear(position), rtol=0, atol=1e-12)
    coo = B.tocoo()
    for column in range(B.shape[1]):
        assert np.unique(klass[coo.row[coo.col == column]]).size == 1
    own = np.flatnonzero(klass < 0)
    assert np.all(np.diff(B[own].indptr) == 1) and np.all(B[own].data == 1)
    assert lm.boundary_basis(klass, position, int(sizes.max())) is None
    with pytest.raises(rq.InputError, match="at least 2"):
        lm.boundary_basis(klass, position, 1)


@pytest.mark.parametrize("whole", [True, False])
@pytest.mark.parametrize("correspondence", ["free", "lattice"])
def test_the_pass_in_a_coarse_basis_is_the_whole_designs_times_the_basis(monkeypatch, whole,
                                                                         correspondence):
    """Every derivative of the manifold in the coarse basis B is that of the whole design
    times B: J' J, J' r, the metric, the sweeps, the inequality rows and their change, with
    S B kept whole or by its working set (whose rows are zero outside their spans)."""
    if not whole:
        monkeypatch.setattr(window, "WHOLE_S", 0)
    prob, _ = small("quarter_vase", panels=(16, 16), correspondence=correspondence)
    nlp, rng = prob.transcribe(), np.random.default_rng(3)
    coarse, full = lm.Manifold(nlp, knots=3), lm.Manifold(nlp)
    assert coarse.coarse and not full.coarse and coarse.window.whole == whole
    B = coarse.basis.toarray()
    x = nlp.x0.copy()
    x[coarse.design] += 1e-3 * rng.standard_normal(coarse.design.size)
    p = coarse.point(nlp.project(x))
    a, b = coarse.linearize(p), full.linearize(p)

    def close(mine, dense):
        np.testing.assert_allclose(mine, dense, rtol=0, atol=1e-12 * np.abs(dense).max())

    close(a.JtJ, B.T @ b.JtJ @ B)
    close(a.grad, B.T @ b.grad)
    U, Y = rng.standard_normal((B.shape[1], 3)), rng.standard_normal((coarse.read.size, 3))
    close(a.state_change(U), b.state_change(B @ U))
    close(a.jacobian_times(U), b.jacobian_times(B @ U))
    close(a.sensitivity.adjoint(Y), B.T @ b.sensitivity.adjoint(Y))
    w = rng.standard_normal(p.r.size)
    close(a.jacobian_transpose(w), B.T @ b.jacobian_transpose(w))
    ma, mb = steps.model(coarse, p, a), steps.model(full, p, b)
    close(ma.M, B.T @ mb.M @ B)
    which = rng.choice(ma.lower.size, 40, replace=False)
    close(steps.Steps(coarse).rows(ma, which), steps.Steps(full).rows(mb, which) @ B)
    du = rng.standard_normal(B.shape[1])
    close(steps.Steps(coarse).change(ma, du), steps.Steps(full).change(mb, B @ du))
    level_pass = coarse.window
    S = _whole_sensitivity(a, np.eye(B.shape[1]))[:, level_pass.marching]
    first, last = level_pass.spans(a.sensitivity.levels, level_pass.design_span)
    columns = np.arange(S.shape[1])
    assert np.all(S[(columns < first[:, None]) | (columns > last[:, None])] == 0)


def test_a_run_in_a_coarse_basis_goes_on_in_the_whole_design_to_its_optimum(monkeypatch):
    """Optimal in the coarse basis, the run is refined once and ends at the whole design's
    optimum (that of a run without the basis), its optimality error scaled as the first
    run's, every accepted step logged once; with a fit reached in the coarse basis it is not
    refined."""
    prob, opts = small("quarter_vase", panels=(16, 16))
    refined, refine = [], lm.Manifold.refine
    monkeypatch.setattr(lm.Manifold, "refine",
                        lambda self: refined.append(self.basis.shape) or refine(self))
    runs, run = [], loop.run

    def logged(*args, **kw):
        out = run(*args, **kw)
        runs.append((kw.get("scale"), out.scale))
        return out

    monkeypatch.setattr(loop, "run", logged)
    coarse = prob.solve(replace(opts, boundary_knots=3))
    assert len(refined) == 1 and refined[0][1] < refined[0][0]
    assert len(runs) == 2 and runs[0][0] is None and runs[1] == (runs[0][1], runs[0][1])
    whole = prob.solve(replace(opts, boundary_knots=0))
    assert len(refined) == 1
    assert coarse.stats.status == whole.stats.status == "Solve_Succeeded"
    assert coarse.stats.objective == pytest.approx(whole.stats.objective, rel=1e-6)
    assert len(coarse.stats.history["objective"]) == coarse.stats.iterations + 1
    fit = prob.solve(replace(opts, boundary_knots=3, stop_rms=0.05))
    assert fit.stats.status == "Fit_Reached" and len(refined) == 1


def test_a_coarse_basis_is_left_once_its_loss_stops_falling(monkeypatch):
    """In a coarse basis the run ends once its loss fell by less than BASIS_STALL of itself
    over the last BASIS_STALL_STEPS steps, before it is optimal there, and goes on in the
    whole design to the optimum of the run that stays in the basis to ``tol``."""
    prob, opts = small("quarter_vase", panels=(16, 16), boundary_knots=3)
    refine = lm.Manifold.refine

    def solved(stall: float) -> tuple[rq.DesignResult, list[float], int]:
        losses, at = [], []
        monkeypatch.setattr(loop, "BASIS_STALL", stall)
        monkeypatch.setattr(lm.Manifold, "refine",
                            lambda self: at.append(len(losses) - 1) or refine(self))
        res = prob.solve(opts, callback=lambda d: losses.append(d["objective"]))
        assert len(at) == 1 and res.stats.status == "Solve_Succeeded"
        return res, losses, at[0]

    stall, steps = lm.BASIS_STALL, lm.BASIS_STALL_STEPS
    early, losses, k = solved(stall)
    late, _, k_late = solved(0.0)
    assert steps <= k < k_late
    assert losses[k - steps] - losses[k] < stall * losses[k]
    assert all(losses[i - steps] - losses[i] >= stall * losses[i] for i in range(steps, k))
    assert early.stats.objective == pytest.approx(late.stats.objective, rel=1e-8)


@pytest.mark.parametrize("name", ["sphere_cap", "hyperboloid", "quarter_vase"])
def test_levenberg_marquardt_alone_reaches_ipopts_optimum(name):
    """To tol 1e-6, with no IPOPT handover: IPOPT's loss (at tol 1e-9) to 1e-6, its design
    to 1e-4."""
    # the lattice mode for the sphere cap: at 8 x 8 panels its free correspondence has two
    # local minima, one for each solver (docs/meshes.md)
    prob, opts = small(name, correspondence="lattice" if name == "sphere_cap" else "free")
    marched = prob.solve(opts)
    ipopt = prob.solve(opts, solver="ipopt", tol=1e-9)
    assert marched.stats.status == "Solve_Succeeded" and marched.stats.solver == LM
    assert 0 < marched.stats.marched_iterations == marched.stats.iterations  # LM alone
    assert marched.stats.objective == pytest.approx(ipopt.stats.objective, rel=1e-6)
    spacing = prob.start().spacing
    np.testing.assert_allclose(marched.boundary.to_vector(), ipopt.boundary.to_vector(),
                               atol=1e-4 * spacing)
    assert marched.omega == pytest.approx(ipopt.omega, abs=1e-4)
    np.testing.assert_allclose(marched.folded[::2, ::2], ipopt.folded[::2, ::2],
                               atol=1e-4 * prob.target.diameter())


def _reduced_gradient(man: lm.Manifold, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of f(d) = 0.5 |r(march(d))|^2 over the design at x."""
    f = ca.Function("f", [man.nlp.x], [man.nlp.objective])
    grad = np.empty(man.design.size)
    for k, i in enumerate(man.design):
        xp, xm = x.copy(), x.copy()
        xp[i] += h
        xm[i] -= h
        grad[k] = float(f(man.nlp.project(xp)) - f(man.nlp.project(xm))) / (2 * h)
    return grad


def test_success_means_a_stationary_point_of_the_marched_loss(manifold):
    """The 8 x 8 quarter vase's optimum has no active inequality: there the gradient of the
    marched loss, by finite differences of the NumPy march, vanishes; before it does, the
    run does not report success."""
    _, man = manifold
    nlp = man.nlp
    out = lm.levenberg_marquardt(nlp, nlp.x0, 0.03, 100, tol=1e-6, manifold=man)
    assert out.status == "Solve_Succeeded" and out.kkt_error <= 1e-6
    assert np.abs(_reduced_gradient(man, out.x)).max() <= 1e-5
    assert np.abs(_reduced_gradient(man, nlp.project(nlp.x0))).max() > 1e-2
    early = lm.levenberg_marquardt(nlp, nlp.x0, 0.03, 3, tol=1e-6, manifold=man)
    assert early.status == "Maximum_Iterations_Exceeded" and not early.success
    assert early.kkt_error > 1e-6
    assert np.abs(_reduced_gradient(man, early.x)).max() > 1e-5
    loose = lm.levenberg_marquardt(nlp, nlp.x0, 0.03, 100, tol=1e-2, manifold=man)
    assert loose.success and 1e-6 < loose.kkt_error <= 1e-2
    assert loose.iterations < out.iterations


def _kkt_error(grad, A, y, lower, upper) -> float:
    """steps.kkt_error at a model with gradient ``grad`` and the QP rows A (k, n), all
    active with the multipliers y, their bounds minus their values ``lower``, ``upper``."""
    A = np.asarray(A, dtype=float)
    m = SimpleNamespace(grad=np.asarray(grad, dtype=float), lower=np.asarray(lower, dtype=float),
                        upper=np.asarray(upper, dtype=float))
    stepper = SimpleNamespace(rows=lambda _, which: A[which])
    step = steps.Step(dd=np.zeros(A.shape[1]), which=np.arange(A.shape[0]),
                      multipliers=np.asarray(y, dtype=float))
    return steps.kkt_error(m, stepper, step)


def test_the_optimality_error_takes_the_better_multipliers():
    """The QP's multipliers lag the point's by the damped step; the least-squares ones of
    the right sign (CasADi's: negative at a lower bound) give the error where they do
    better, complementarity included."""
    A, held, free = [[1.0, 0.0]], ([0.0], [np.inf]), ([-0.2], [np.inf])
    assert _kkt_error([1.0, 0.1], A, [-0.5], *held) == pytest.approx(0.1)  # y = -1, not -0.5
    assert _kkt_error([-1.0, 0.1], A, [-0.5], *held) == pytest.approx(1.0)  # y = 0: not +1
    assert _kkt_error([1.0, 0.1], A, [-0.5], *free) == pytest.approx(0.2)  # 1 x the gap 0.2
    assert _kkt_error([1.0, 0.1], A, [-0.5], [0.0], [0.0]) == pytest.approx(0.1)  # equality
    assert _kkt_error([1.0, -2.0], A, [0.0], *held) == 2.0  # in the QP, not active


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 16), k=st.integers(1, 4))
def test_least_squares_multipliers_are_the_sign_bounded_fit(seed, k):
    """steps.least_squares_multipliers against SciPy's bounded least squares: the same
    residual |grad + A' y|, the signs kept; the error never exceeds the QP multipliers'."""
    rng = np.random.default_rng(seed)
    A, grad = rng.standard_normal((k, 6)), rng.standard_normal(6)
    sign = rng.choice([-1.0, 1.0], k)
    y = steps.least_squares_multipliers(A, grad, sign)
    assert np.all(y * sign >= 0)
    bounds = (np.where(sign > 0, 0, -np.inf), np.where(sign > 0, np.inf, 0))
    best = lsq_linear(A.T, -grad, bounds=bounds, tol=1e-12).x
    assert np.linalg.norm(grad + A.T @ y) <= np.linalg.norm(grad + A.T @ best) + 1e-9
    qp = sign * rng.uniform(0, 2, k)
    held = (np.zeros(k), np.zeros(k))
    assert _kkt_error(grad, A, qp, *held) <= np.abs(grad + A.T @ qp).max() + 1e-15


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), k=st.integers(1, 5))
def test_the_secant_term_meets_the_newest_secant_pair(seed, k):
    """B from k secant pairs (step s, y with y's > 0, any y_sharp) is symmetric and meets
    the newest pair's secant condition B s = y_sharp whatever came before (the older pairs
    and the sizing); no pairs give B = 0."""
    rng = np.random.default_rng(seed)
    n = 9
    pairs = []
    for _ in range(k):
        s = rng.normal(size=n)
        y = s * rng.uniform(0.1, 10) + 0.1 * rng.normal(size=n) * np.linalg.norm(s)
        y = y if y @ s > 0 else -y
        pairs.append((s, y, rng.normal(size=n)))
    B = secant.secant_term(pairs, n)
    np.testing.assert_allclose(B, B.T, atol=1e-12 * np.abs(B).max())
    s, _, y_sharp = pairs[-1]
    np.testing.assert_allclose(B @ s, y_sharp, atol=1e-9 * (1 + np.abs(B).max()))
    np.testing.assert_array_equal(secant.secant_term([], n), np.zeros((n, n)))


def test_the_secant_term_is_built_from_the_last_accepted_steps(monkeypatch):
    """Every iteration after the first rebuilds B from the last SECANT_PAIRS accepted steps
    (TAIL_PAIRS in the tail), a window sliding by one step, the newest the change of the
    design just accepted."""
    seen, accepted = [], []
    monkeypatch.setattr(secant, "secant_term", lambda pairs, n: (
        seen.append([p[0] for p in pairs]), np.zeros((n, n)))[1])
    monkeypatch.setattr(secant, "tail_term", lambda pairs, JtJ: (
        seen.append([p[0] for p in pairs]), np.zeros_like(JtJ))[1])
    last = secant.Last.__init__

    def recorded(self, m, steps_, step, change, trial):
        accepted.append(change)
        last(self, m, steps_, step, change, trial)

    monkeypatch.setattr(secant.Last, "__init__", recorded)
    prob, opts = small("sphere_cap")
    stats = prob.solve(opts).stats
    assert stats.iterations > secant.SECANT_PAIRS + 2 and len(seen) == stats.iterations
    for i, pairs in enumerate(seen):
        expected = accepted[max(0, i + 1 - len(pairs)):i + 1]
        assert len(pairs) == len(expected)
        assert len(pairs) in (min(i + 1, secant.SECANT_PAIRS), min(i + 1, secant.TAIL_PAIRS))
        for a, b in zip(pairs, expected):
            assert a is b


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), k=st.integers(1, 9))
def test_the_tail_term_keeps_the_model_positive_definite_and_meets_the_newest_pair(seed, k):
    """In the tail J'J + B is J'J updated by BFGS over the pairs: symmetric, positive
    definite, and meeting the newest pair's structured secant condition
    (J'J + B) s = J'J s + y_sharp wherever s' (J'J s + y_sharp) > 0; a pair without that
    curvature is skipped, and no pairs give B = 0."""
    rng = np.random.default_rng(seed)
    n = 9
    J = rng.normal(size=(12, n))
    JtJ = J.T @ J
    pairs = []
    for s in rng.normal(size=(k, n)):
        y_sharp = rng.normal(size=n)
        if abs(s @ (JtJ @ s + y_sharp)) < 0.1 * (s @ JtJ @ s):  # clearly one side of 0
            y_sharp += 0.2 * JtJ @ s
        pairs.append((s, rng.normal(size=n), y_sharp))
    B = secant.tail_term(pairs, JtJ)
    H = JtJ + B
    np.testing.assert_allclose(B, B.T, atol=1e-10 * np.abs(H).max())
    assert np.linalg.eigvalsh(0.5 * (H + H.T)).min() > 0
    s, _, y_sharp = pairs[-1]
    if s @ (JtJ @ s + y_sharp) > 0:
        np.testing.assert_allclose(H @ s, JtJ @ s + y_sharp,
                                   atol=1e-8 * np.abs(H).max() * np.linalg.norm(s))
    else:
        np.testing.assert_allclose(B, secant.tail_term(pairs[:-1], JtJ), atol=1e-12)
    np.testing.assert_array_equal(secant.tail_term([], JtJ), np.zeros((n, n)))


@pytest.mark.parametrize("history, tail", [
    ([(frozenset({4, 7}), 1e-4)] * 3, True),
    ([(frozenset({4, 7}), 1e-2)] + [(frozenset({4, 7}), 1e-4)] * 2, False),  # damping
    ([(frozenset({4}), 1e-4)] + [(frozenset({4, 7}), 1e-4)] * 2, False),  # rows changed
    ([(frozenset(), 1e-4)] * 3, False),  # no row active
    ([(frozenset({4, 7}), 1e-4)] * 2, False),  # too few steps
])
def test_the_tail_is_the_same_active_rows_at_a_small_damping(monkeypatch, history, tail):
    monkeypatch.setattr(secant, "TAIL_STEPS", 3)
    assert secant.TAIL_DAMPING > 1e-4
    assert secant.in_tail(history) is tail


@pytest.mark.parametrize("leaves", [True, False])
def test_a_step_that_leaves_the_marchs_domain_doubles_the_damping(manifold, monkeypatch,
                                                                     leaves):
    """A trial point that does not march (project gives None) doubles lam and keeps Nielsen's
    factor; a trial whose loss rises multiplies lam by that factor, which doubles each time
    (2, 4, 8): from 0.03, three failed trials then 0.24 against 1.92."""
    prob, man = manifold
    nlp, seen, trials = man.nlp, [], []
    project, point, call = nlp.project, man.point, steps.Steps.__call__
    monkeypatch.setattr(steps.Steps, "__call__",
                        lambda self, m, lam, shift: (seen.append(lam), call(self, m, lam,
                                                                            shift))[1])

    def failing(x):  # the start, then three trials that fail, then the rest as they are
        trials.append(x)
        return None if leaves and 1 < len(trials) <= 4 else project(x)

    def rising(x):
        p = point(x)
        return replace(p, r=10 * p.r) if not leaves and 1 < len(trials) <= 4 else p

    monkeypatch.setattr(nlp, "project", failing)
    monkeypatch.setattr(man, "point", rising)
    out = lm.levenberg_marquardt(nlp, nlp.x0, 0.03, 1, manifold=man)
    assert out.iterations == 1 and len(trials) >= 5
    assert seen[:4] == pytest.approx([0.03, 0.06, 0.12, 0.24] if leaves
                                     else [0.03, 0.06, 0.24, 1.92], rel=1e-12)


def _blas_threads() -> set[int]:
    return {i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"}


def test_blas_runs_on_one_thread_while_s_is_whole(manifold, monkeypatch):
    """The run (and Manifold.blas_threads) limits BLAS to one thread when the pass keeps S
    whole, and leaves it as it was otherwise; the limit ends with the run."""
    prob, man = manifold
    assert man.window.whole
    monkeypatch.setattr(window, "WHOLE_S", 0)
    large = lm.Manifold(prob.transcribe())
    assert not large.window.whole
    seen = []
    run = loop.run
    monkeypatch.setattr(loop, "run",
                        lambda *a: (seen.append(_blas_threads()), run(*a))[1])
    with threadpool_limits(limits=2, user_api="blas"):
        assert _blas_threads() == {2}
        with man.blas_threads():
            assert _blas_threads() == {1}
        assert _blas_threads() == {2}
        with large.blas_threads():
            assert _blas_threads() == {2}
        out = lm.levenberg_marquardt(man.nlp, man.nlp.x0, 0.03, 2, manifold=man)
        assert out.iterations == 2 and seen == [{1}] and _blas_threads() == {2}
        lm.levenberg_marquardt(large.nlp, large.nlp.x0, 0.03, 2, manifold=large)
        assert seen == [{1}, {2}]


def test_every_step_is_an_admissible_design_with_a_lower_loss():
    seen = []
    prob, opts = small("sphere_cap", stop_rms=0.0125)
    nlp = prob.transcribe()
    res = prob.solve(opts, callback=seen.append)
    assert res.stats.status == "Fit_Reached" and res.fit.rms <= 0.0125
    assert res.stats.iterations == res.stats.marched_iterations == len(seen) - 1 > 1
    assert seen[0]["objective"] == pytest.approx(
        float(ca.Function("f", [nlp.x], [nlp.objective])(nlp.x0)), rel=1e-12)  # the start
    objective = [e["objective"] for e in seen]
    assert np.all(np.diff(objective) < 0)
    assert max(e["inf_pr"] for e in seen) <= lm.FEASIBLE
    assert seen[-1]["objective"] == pytest.approx(res.stats.objective, rel=1e-12)


def test_an_active_side_bound_holds_on_the_remarch():
    """min_length = 0.6, which the 8 x 8 sphere cap's best fit breaks (its smallest side is
    0.54 of the mean): the QP keeps the smallest side at the bound on every re-march, and
    the run ends at IPOPT's optimum, its multiplier included in the optimality test."""
    prob, opts = small("sphere_cap", min_length=0.6, correspondence="lattice")
    nlp = prob.transcribe()
    out = lm.levenberg_marquardt(nlp, nlp.x0, opts.damping, 100)
    assert out.status == "Solve_Succeeded" and out.iterations > 3
    vec = nlp.unpack(out.x)[0].full().ravel()
    sides = numpy_model.march(rq.BoundaryData.from_vector(
        vec, prob.start().boundary.sigma, 8, 8)).side_lengths
    assert sides.min() - 0.6 * sides.mean() >= -lm.FEASIBLE  # held: its row's tolerance
    assert sides.min() / sides.mean() / 0.6 <= 1 + 1e-6  # active
    ipopt = prob.solve(opts, solver="ipopt", tol=1e-9)
    assert out.objective == pytest.approx(ipopt.stats.objective, rel=1e-6)
    again = lm.levenberg_marquardt(nlp, nlp.x0, opts.damping, 100)
    assert again.objective == out.objective  # deterministic
    looser = replace(prob, min_length=0.3).transcribe()
    assert lm.levenberg_marquardt(looser, looser.x0, opts.damping, 100).objective \
        < out.objective  # the bound costs fit


def test_fixed_groups_stay_at_their_start():
    prob, opts = small("hyperboloid", fix=("lengths", "omega"), stop_rms=0.02)
    res = prob.solve(opts)
    start = prob.start()
    for side in ("l_left", "l_bottom"):
        np.testing.assert_array_equal(getattr(res.boundary, side), getattr(start.boundary, side))
    assert res.omega == start.omega
    assert res.stats.marched_iterations > 0


def test_iteration_and_time_limits_raise_solver_failed_with_an_admissible_best():
    prob, opts = small("sphere_cap", max_iter=1, tol=1e-12)
    with pytest.raises(rq.SolverFailed, match="Maximum_Iterations_Exceeded") as exc:
        prob.solve(opts)
    nlp = prob.transcribe()
    best = exc.value.best_iterate
    F = ca.Function("F", [nlp.x], [0.5 * ca.sumsqr(nlp.residuals), nlp.g])
    f, g = F(best)
    g = g.full().ravel()
    assert np.all(g >= nlp.lbg - 1e-9) and np.all(g <= nlp.ubg + 1e-9)
    assert float(f) < float(F(nlp.x0)[0])  # one step, which lowered the loss
    assert exc.value.stats.history["objective"] == [pytest.approx(float(F(nlp.x0)[0])),
                                                    pytest.approx(float(f))]
    prob, opts = small("sphere_cap", time_limit=1e-6)
    with pytest.raises(rq.SolverFailed, match="Maximum_WallTime_Exceeded"):
        prob.solve(opts)


@pytest.mark.parametrize("kw", [{"solver": "newton"}, {"transcription": "sequential"},
                                {"damping": 0.0}, {"boundary_knots": 1}])
def test_invalid_solver_options_raise_input_error(kw):
    with pytest.raises(rq.InputError):
        small("sphere_cap", **kw)


def test_a_start_that_does_not_march_takes_no_step(manifold):
    _, man = manifold
    x = man.nlp.x0.copy()
    x[man.nlp.groups["angles"]] = 3.0  # every boundary angle near pi: does not march
    out = lm.levenberg_marquardt(man.nlp, x, 0.03, 10)
    assert out.status == "Inadmissible_Start" and out.iterations == out.restored == 0
    np.testing.assert_array_equal(out.x, x)


@pytest.fixture(scope="module")
def short_sides():
    """The 8 x 8 quarter vase with min_length 0.9: its Miura start's smallest side is 0.82
    of the mean, so the start marches but breaks a row."""
    return small("quarter_vase", min_length=0.9)


def test_a_start_that_breaks_a_row_is_restored_then_solved_to_ipopts_optimum(short_sides):
    """Restoration steps (the loss free to rise) until every row holds, then admissible
    steps to the optimality conditions, by Levenberg-Marquardt alone, at IPOPT's optimum
    from the same start."""
    prob, opts = short_sides
    nlp = prob.transcribe()
    man = lm.Manifold(nlp)
    assert man.violation(man.point(nlp.project(nlp.x0))) > 1e-2
    opts = replace(opts, tol=1e-9)
    res = prob.solve(opts)
    stats = res.stats
    assert stats.status == "Solve_Succeeded"
    assert stats.marched_iterations == stats.iterations > stats.restoration_iterations > 0
    violation = np.array(stats.history["inf_pr"])
    k = stats.restoration_iterations
    assert np.all(violation[k:] <= lm.FEASIBLE) and np.all(violation[:k] > lm.FEASIBLE)
    assert res.fit.min_side_over_mean >= 0.9 * (1 - 1e-6)
    assert rq.SolveStats.from_dict(stats.to_dict()).restoration_iterations == k
    ipopt = prob.solve(replace(opts, solver="ipopt"))
    assert stats.objective == pytest.approx(ipopt.stats.objective, rel=1e-6)


def test_a_restoration_of_several_steps_lowers_the_violation_at_each():
    """The 8 x 8 sphere cap with min_length 0.97 needs more than one restoration step:
    each lowers the largest violation, the last reaches FEASIBLE, and every row holds at
    Levenberg-Marquardt's later iterates (those before IPOPT's, where it stalls)."""
    prob, opts = small("sphere_cap", min_length=0.97)
    res = prob.solve(opts)
    k = res.stats.restoration_iterations
    violation = np.array(res.stats.history["inf_pr"])
    assert res.stats.status == "Solve_Succeeded" and k >= 2
    assert np.all(np.diff(violation[:k + 1]) < 0) and violation[k] <= lm.FEASIBLE
    assert np.all(violation[k:res.stats.marched_iterations + 1] <= lm.FEASIBLE)
    assert res.fit.min_side_over_mean >= 0.97 * (1 - 1e-6)


@pytest.mark.parametrize("reach", [1.0, 0.5, 0.125])
def test_a_partial_target_asks_the_broken_rows_for_that_part_of_their_gap(short_sides,
                                                                          reach):
    """At a large damping the step's change of the most broken row is ``reach`` of its
    way back to its bound (the QP holds it there), and the rows that hold keep theirs."""
    prob, _ = short_sides
    man = lm.Manifold(prob.transcribe())
    p = man.marched(man.nlp.x0)
    m = steps.model(man, p, man.linearize(p))
    gap = np.maximum(m.lower, 0.0) + np.maximum(-m.upper, 0.0)
    worst = int(np.argmax(gap))
    step = steps.Steps(man)(m, 1e6, steps.partial_target(m, reach))
    change = steps.Steps(man).change(m, step.dd)
    assert change[worst] == pytest.approx(reach * gap[worst], rel=1e-6)
    holds = gap == 0
    assert np.all(change[holds] >= m.lower[holds] - 1e-9)
    assert np.all(change[holds] <= m.upper[holds] + 1e-9)


def test_a_restoration_cut_short_by_max_iter_ends_with_that_status_not_ipopt():
    """Two iterations for a start that needs three restoration steps: SolverFailed with
    Levenberg-Marquardt's status, both iterations counted as restoration, no IPOPT and no
    best iterate (none was admissible)."""
    prob, opts = small("sphere_cap", min_length=0.97, max_iter=2)
    with pytest.raises(rq.SolverFailed, match="Levenberg-Marquardt solve did not finish the "
                       "design: status Maximum_Iterations_Exceeded") as info:
        prob.solve(opts)
    stats = info.value.stats
    assert stats.status == "Maximum_Iterations_Exceeded"
    assert stats.iterations == stats.marched_iterations == stats.restoration_iterations == 2
    assert len(stats.history["inf_pr"]) == 3 and info.value.best_iterate is None


def test_a_restoration_that_fails_in_the_coarse_basis_restarts_in_the_whole_design(
        short_sides, monkeypatch):
    prob, _ = short_sides
    nlp = prob.transcribe()
    man = lm.Manifold(nlp, 2)
    assert man.coarse
    whole = steps.Steps.__call__
    monkeypatch.setattr(steps.Steps, "__call__", lambda self, m, lam, shift: (
        None if self.man.coarse else whole(self, m, lam, shift)))
    out = lm.levenberg_marquardt(nlp, nlp.x0, 0.03, 200, manifold=man)
    assert not man.coarse and out.status == "Solve_Succeeded" and out.restored >= 1
    assert man.violation(man.point(out.x)) <= lm.FEASIBLE


def test_a_failed_restoration_hands_the_start_as_given_to_ipopt(short_sides, monkeypatch):
    prob, opts = short_sides
    nlp = prob.transcribe()
    monkeypatch.setattr(steps.Steps, "__call__", lambda self, m, lam, shift: None)
    out = lm.levenberg_marquardt(nlp, nlp.x0, 0.03, 10)
    assert out.status == "Inadmissible_Start" and out.iterations == out.restored == 0
    np.testing.assert_array_equal(out.x, nlp.x0)
    res = prob.solve(opts)
    assert res.stats.marched_iterations == 0 and res.stats.status == "Solve_Succeeded"
    assert res.fit.min_side_over_mean >= 0.9 * (1 - 1e-6)


def test_a_solver_ending_in_nan_raises_solver_failed_never_a_result(monkeypatch):
    prob, opts = small("sphere_cap", stop_rms=0.05)

    def nan_run(man, x, *args, **kw):  # the run in the manifold's basis
        return loop.MarchedOutcome(x=np.full_like(x, np.nan), objective=float("nan"),
                            iterations=1, status="Fit_Reached")

    monkeypatch.setattr(loop, "run", nan_run)
    with pytest.raises(rq.SolverFailed, match="NaN or inf in the design vector") as exc:
        prob.solve(opts)
    assert exc.value.status == "non_finite" and exc.value.stats.status == "Fit_Reached"


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2 ** 31), rows=st.integers(1, 60), n=st.integers(2, 40))
def test_step_qp_meets_its_optimality_conditions(manifold, seed, rows, n):
    """The step's QP in least-distance form returns the solution and multipliers of
    min 0.5 dd' H dd + g' dd s.t. lba <= A dd <= uba: H dd + g + A' y = 0, every row within
    its bounds, y <= 0 only at a lower bound and y >= 0 only at an upper one (CasADi's
    sign). Random problems, feasible by construction (each row a one-sided bound that a
    random point keeps), the unconstrained minimiser breaking every row."""
    rng = np.random.default_rng(seed)
    X = rng.standard_normal((n, n))
    H = X @ X.T + 0.1 * np.eye(n)
    g, A = rng.standard_normal(n), rng.standard_normal((rows, n))
    kept, free = A @ rng.standard_normal(n), A @ np.linalg.solve(H, -g)
    below = free < kept  # the unconstrained step breaks a lower bound at the kept value
    lba = np.where(below, kept, -1e20)
    uba = np.where(below, 1e20, kept)
    R = la.cho_factor(H, lower=False)[0]
    R[np.tril_indices(n, -1)] = rng.standard_normal(n * (n - 1) // 2)  # not to be read
    step = steps.Steps(manifold[1]).qp(R, g, np.arange(rows), A, lba, uba)
    dd, y = step.dd, step.multipliers
    scale = 1 + np.abs(g).max() + np.abs(A.T @ y).max()
    assert np.abs(H @ dd + g + A.T @ y).max() < 1e-9 * scale
    Ad = A @ dd
    assert np.all(Ad >= lba - 1e-9 * scale) and np.all(Ad <= uba + 1e-9 * scale)
    assert np.all(-y[y < 0] * (Ad - lba)[y < 0] < 1e-9 * scale)
    assert np.all(y[y > 0] * (uba - Ad)[y > 0] < 1e-9 * scale)
    assert np.any(np.abs(y) > 1e-9)  # some row binds
