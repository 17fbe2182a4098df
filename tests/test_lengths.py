"""Side lengths for fixed angles (rffqm_nlp.model.lengths): the LP eq:linearP and the NLP by IPOPT
over the same feasible set, on the paper's Fig. Random inputs."""

import numpy as np
import pytest
from scipy.optimize import linprog

import rffqm_nlp as rq
from rffqm_nlp.model import lengths
from rffqm_nlp.errors import InfeasibleDesign, InputError, SolverFailed
from rffqm_nlp.model.lengths import length_maps, length_spread, side_length_lp, side_length_nlp
from rffqm_nlp.model.marching import march, pattern_function

SEEDS = (0, 1, 2)
OBJECTIVES = ("max_min", "uniform")


def fig_random(seed, n=10):
    """The paper's Fig. Random input: Miura boundary angles perturbed by U(+-0.05 pi)."""
    return rq.perturb_angles(rq.miura_boundary(n, n), 0.05 * np.pi, seed)


def sides_matrix_by_marching(bd):
    """Column k: all sides (lh then lv) marched from ell = e_k with the unchecked CasADi graph.

    Independent of rffqm_nlp.model.lengths.length_maps' coefficient recursion.
    """
    N, M = bd.N, bd.M
    f = pattern_function(N, M)
    cols = []
    for k in range(N + M):
        e = np.zeros(N + M)
        e[k] = 1.0
        out = f.call([bd.left.T, bd.bottom.T, e[None, :N], e[None, N:]])
        cols.append(np.concatenate([np.array(out[3].full()).ravel(),
                                    np.array(out[4].full()).ravel()]))
    return np.column_stack(cols)


def linprog_max_min(A):
    """max t s.t. A ell >= t, mean(A ell) = 1, solved by HiGHS."""
    K, n = A.shape
    c = np.zeros(n + 1)
    c[-1] = -1.0
    res = linprog(c, A_ub=np.hstack([-A, np.ones((K, 1))]), b_ub=np.zeros(K),
                  A_eq=np.append(A.mean(axis=0), 0.0)[None, :], b_eq=[1.0],
                  bounds=[(None, None)] * (n + 1), method="highs")
    assert res.status == 0, res.message
    return -res.fun


def log_variance(sides):
    return float(np.var(np.log(sides)))


# --------------------------------------------------------------------------- linear maps, LP
@pytest.mark.parametrize("seed", SEEDS)
def test_length_maps_are_the_marched_sides_of_unit_lengths(seed):
    bd = fig_random(seed, n=6)
    maps = length_maps(bd)
    A = sides_matrix_by_marching(bd)
    np.testing.assert_allclose(maps.all_sides, A, rtol=1e-10, atol=1e-10)
    assert maps.interior.shape == (2 * 6 * 6, 12)
    pat = march(side_length_lp(bd))
    np.testing.assert_allclose(maps.all_sides @ pat.boundary.lengths, pat.side_lengths,
                               rtol=1e-9)


@pytest.mark.parametrize("seed", SEEDS)
def test_lp_is_eq_linearP_shifted_by_delta(seed):
    """sum(ell) is HiGHS's optimum of min sum(ell), interior sides >= eps, ell >= 0, computed
    here on the marched matrix; the result is that optimum plus delta."""
    bd, eps, delta = fig_random(seed), 1e-2, 1e-7
    ell = side_length_lp(bd, eps=eps, delta=delta).lengths - delta
    N = bd.N
    A = sides_matrix_by_marching(bd)
    lh_rows = np.arange((N + 1) * bd.M).reshape(N + 1, bd.M)[1:].ravel()
    lv_rows = (N + 1) * bd.M + np.arange(N * (bd.M + 1)).reshape(N, bd.M + 1)[:, 1:].ravel()
    interior = A[np.concatenate([lh_rows, lv_rows])]
    res = linprog(np.ones(A.shape[1]), A_ub=-interior, b_ub=-eps * np.ones(len(interior)),
                  bounds=(0, None), method="highs")
    assert ell.sum() == pytest.approx(res.fun, rel=1e-8)
    assert (interior @ ell).min() >= eps * (1 - 1e-8)
    assert march(side_length_lp(bd)).side_lengths.min() > 0


@pytest.mark.parametrize("kwargs", [{"eps": 0.0}, {"eps": -1.0}, {"eps": float("nan")},
                                    {"delta": 0.0}, {"delta": -1.0}, {"delta": float("nan")},
                                    {"eps": "small"}, {"delta": "small"}, {"eps": [0.1]},
                                    {"eps": None}, {"delta": True}])
def test_lp_invalid_arguments(kwargs):
    with pytest.raises(InputError, match=f"^{next(iter(kwargs))} must"):
        side_length_lp(fig_random(0, n=4), **kwargs)


@pytest.mark.parametrize("call, words", [
    (lambda: side_length_lp(march(rq.miura_boundary(2, 2))), "^bd must be boundary data"),
    (lambda: lengths.length_maps(None), "^bd must be boundary data"),
    (lambda: lengths.memory_estimate(2, 2, "qp"), "^program must be one of 'lp', 'nlp'"),
    (lambda: lengths.memory_estimate(-2, 2, "lp"), r"^N must be a whole number in \[1, "),
    (lambda: lengths.check_memory(rq.miura_boundary(2, 2), "lp", 5), "^name must be a string"),
    (lambda: lengths.length_spread([], []), "^length_spread needs at least one side"),
    (lambda: lengths.length_spread([1.0, 0.0], [1.0]), "the smallest 0"),
    (lambda: lengths.length_spread([1.0, np.nan], [1.0]), "^lh must be .* got nan"),
    (lambda: lengths.length_spread("ab", [1.0]), "^lh must be a finite number or an array"),
    (lambda: lengths.LengthMaps(np.zeros((3, 2, 5)), np.zeros((2, 3, 5))), "^Lh must be an "
                                                                            r"\(N\+1, M, N\+M\)"),
    (lambda: side_length_nlp(rq.miura_boundary(2, 2), verbose="yes"), "^verbose must be true "
                                                                       "or false"),
])
def test_length_functions_refuse_bad_arguments_in_one_line(call, words):
    with pytest.raises(InputError, match=words) as exc:
        call()
    assert "\n" not in str(exc.value)


def test_length_spread_of_a_pattern_is_finite():
    pat = march(rq.miura_boundary(2, 3, a=1.0, b=2.0))
    spread = lengths.length_spread(pat.lh, pat.lv)
    assert spread["max_over_min"] == pytest.approx(2.0) and all(map(np.isfinite,
                                                                    spread.values()))


# --------------------------------------------------------------------------- NLP
@pytest.fixture(scope="module")
def solved():
    """{seed: {"lp" | "max_min" | "uniform": Pattern}} on the Fig. Random inputs."""
    out = {}
    for seed in SEEDS:
        bd = fig_random(seed)
        out[seed] = {"bd": bd, "lp": march(side_length_lp(bd))}
        for obj in OBJECTIVES:
            out[seed][obj] = march(side_length_nlp(bd, obj).boundary)
    return out


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("objective", OBJECTIVES)
def test_patterns_march_with_positive_sides(solved, seed, objective):
    pat = solved[seed][objective]
    bd = solved[seed]["bd"]
    sides = pat.side_lengths
    assert np.all(sides > 0)
    assert sides.mean() == pytest.approx(1.0, abs=1e-9)
    # the angles are those of the input: only the lengths changed
    np.testing.assert_array_equal(pat.boundary.left, bd.left)
    np.testing.assert_array_equal(pat.boundary.bottom, bd.bottom)
    np.testing.assert_allclose(pat.alpha, solved[seed]["lp"].alpha, atol=1e-12)


@pytest.mark.parametrize("seed", SEEDS)
def test_max_min_beats_lp_and_uniform(solved, seed):
    spread = {k: length_spread(solved[seed][k].lh, solved[seed][k].lv)["min_over_mean"]
              for k in ("lp", *OBJECTIVES)}
    assert spread["max_min"] >= spread["lp"] - 1e-9
    assert spread["max_min"] >= spread["uniform"] - 1e-9


def test_lp_drives_some_side_near_zero(solved):
    """The paper's complaint: the LP's smallest side is far below the max-min optimum."""
    ratios = [length_spread(solved[s]["lp"].lh, solved[s]["lp"].lv)["min_over_mean"]
              / length_spread(solved[s]["max_min"].lh, solved[s]["max_min"].lv)["min_over_mean"]
              for s in SEEDS]
    assert min(ratios) < 0.05


@pytest.mark.parametrize("seed", SEEDS)
def test_uniform_lowers_log_variance(solved, seed):
    lv = {k: log_variance(solved[seed][k].side_lengths) for k in ("lp", *OBJECTIVES)}
    assert lv["uniform"] <= lv["max_min"] + 1e-9
    assert lv["uniform"] <= lv["lp"] + 1e-9


@pytest.mark.parametrize("seed", SEEDS)
def test_max_min_certified_by_linprog(solved, seed):
    bd = solved[seed]["bd"]
    t_lp = linprog_max_min(sides_matrix_by_marching(bd))
    sol = side_length_nlp(bd, "max_min")
    assert sol.objective == pytest.approx(t_lp, abs=1e-6)
    sides = solved[seed]["max_min"].side_lengths
    assert sides.min() / sides.mean() == pytest.approx(t_lp, abs=1e-6)
    np.testing.assert_allclose(sol.sides, sides, atol=1e-9)


@pytest.mark.parametrize("layout", ["zigzag_j", "zigzag_i"])
@pytest.mark.parametrize("a, b", [(1.0, 1.0), (1.0, 2.5)])
def test_uniform_on_miura_gives_equal_sides(layout, a, b):
    bd = rq.miura_boundary(6, 8, a=a, b=b, layout=layout)
    pat = march(side_length_nlp(bd, "uniform").boundary)
    np.testing.assert_allclose(pat.side_lengths, 1.0, atol=1e-8)
    # with a = b the input lengths themselves were already optimal (up to scale)
    if a == b:
        np.testing.assert_allclose(march(bd).side_lengths, pat.side_lengths, atol=1e-8)


def test_max_min_where_ipopt_failed_is_certified_by_the_dual_lp():
    """100 x 100 perturbed Miura angles, where the max-min LP solved with IPOPT stopped with
    Restoration_Failed (2026-12-02; docs/decisions/memory.md, "Side lengths: the max-min LP
    with HiGHS"): the marched pattern's smallest side over its mean is t*, and the dual LP,
    min lam s.t. A' y = lam mean_row, sum(y) = 1, y >= 0, attains it (strong duality: no
    larger t exists)."""
    bd = rq.perturb_angles(rq.miura_boundary(100, 100), 0.02, seed=0)
    sol = side_length_nlp(bd, "max_min", min_length=1e-6)
    sides = march(sol.boundary).side_lengths
    assert sol.objective > 0.4
    assert sides.min() / sides.mean() == pytest.approx(sol.objective, abs=1e-9)
    A = length_maps(bd).all_sides
    K, n = A.shape
    dual = linprog(np.append(np.zeros(K), 1.0),
                   A_eq=np.vstack([np.hstack([A.T, -A.mean(axis=0)[:, None]]),
                                   np.append(np.ones(K), 0.0)]),
                   b_eq=np.append(np.zeros(n), 1.0), bounds=[(0, None)] * K + [(None, None)],
                   method="highs")
    assert dual.status == 0 and dual.fun == pytest.approx(sol.objective, abs=1e-7)


def test_max_min_on_miura_is_one():
    sol = side_length_nlp(rq.miura_boundary(5, 7, a=1.0, b=3.0), "max_min")
    assert sol.objective == pytest.approx(1.0, abs=1e-8)


@pytest.fixture(scope="module")
def infeasible():
    """20 x 20 Fig. Random angles whose LP (eq:linearP) is infeasible."""
    bd = fig_random(0, n=20)
    with pytest.raises(InfeasibleDesign):
        side_length_lp(bd)
    return bd


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_infeasible_angles_raise(infeasible, objective):
    with pytest.raises(InfeasibleDesign, match="no positive side lengths"):
        side_length_nlp(infeasible, objective)


@pytest.mark.parametrize("objective", OBJECTIVES)
def test_min_length_above_optimum_raises(solved, objective):
    bd = solved[0]["bd"]
    t = length_spread(solved[0]["max_min"].lh, solved[0]["max_min"].lv)["min_over_mean"]
    with pytest.raises(InfeasibleDesign, match="min_length"):
        side_length_nlp(bd, objective, min_length=min(0.99, t + 0.05))


def test_min_length_is_respected(solved):
    bd = solved[1]["bd"]
    t = length_spread(solved[1]["max_min"].lh, solved[1]["max_min"].lv)["min_over_mean"]
    floor = 0.9 * t
    pat = march(side_length_nlp(bd, "uniform", min_length=floor).boundary)
    assert pat.side_lengths.min() >= floor * (1 - 1e-6)


def test_solver_failure_carries_ipopt_status(solved):
    with pytest.raises(SolverFailed) as info:
        side_length_nlp(solved[0]["bd"], "uniform", max_iter=1)
    assert info.value.status == "Maximum_Iterations_Exceeded"
    assert "Maximum_Iterations_Exceeded" in str(info.value)


@pytest.mark.parametrize("kwargs", [
    {"objective": "min_max"}, {"objective": None}, {"min_length": 0.0}, {"min_length": 1.0},
    {"min_length": -0.1}, {"min_length": float("nan")}, {"min_length": "0.1"},
    {"min_length": True}, {"tol": 0.0}, {"tol": "small"}, {"max_iter": 0}, {"max_iter": 2.5},
    {"max_iter": "many"}])
def test_invalid_arguments(kwargs):
    with pytest.raises(InputError, match=f"^{next(iter(kwargs))} must be"):
        side_length_nlp(rq.miura_boundary(2, 2), **kwargs)


def test_rejects_non_boundary_data():
    with pytest.raises(InputError, match="BoundaryData"):
        side_length_nlp({"left": [[1.0, 1.0, -1.0]]})
