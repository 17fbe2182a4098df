"""Side lengths for fixed sector angles: the paper's LP and a nonlinear replacement.

Once the sector angles are marched, every side of the pattern is linear in the boundary
lengths ell = (l_ab^{11..N1}, l_ac^{11..1M}) (eq:getSides): :func:`length_maps` gives
those linear maps. Two ways to choose ell over the same feasible set
{l_cd^{ij}, l_bd^{ij} > 0, ell >= 0}:

* :func:`side_length_lp`, the paper's linear program eq:linearP (SciPy's HiGHS): minimise
  sum(ell) subject to every computed side >= eps, then shift ell by delta. Its objective
  is arbitrary and drives some sides to nearly zero.
* :func:`side_length_nlp` (HiGHS, and CasADi + IPOPT), the objective the paper leaves to
  future work ("keep the aspect ratios of the panels as uniform as possible, while
  optimizing over the same feasible set"). With s = A ell (K,) all K = (N+1)M + N(M+1)
  sides, the scale fixed by mean(s) = 1 and s >= min_length:

  - ``"max_min"``: maximise t subject to s >= t, an LP solved with HiGHS (as
    :func:`side_length_lp`; IPOPT, which solved it before, stopped with Restoration_Failed
    on larger perturbed patterns that HiGHS solves: docs/decisions/memory.md, "Side lengths: the
    max-min LP with HiGHS"). Its optimum t* decides feasibility: no pattern with every
    side >= min_length (times the mean) exists iff t* < min_length, and no valid pattern
    at all iff t* <= 0.
  - ``"uniform"``: minimise var(log s) (IPOPT). It is scale-invariant and 0 exactly when
    all sides are equal (a Miura-ori with a = b is recovered exactly); it penalises a side
    going to zero without bound (a barrier against the LP's near-degenerate panels) and
    long sides symmetrically; it controls the spread of sizes across the pattern, which a
    per-panel aspect ratio does not; and equal sides give per-panel aspect ratios near 1
    wherever the angles allow it, without defining the aspect ratio of a general
    quadrilateral. The sides are variables s >= min_length with s = A ell, so IPOPT never
    takes the log of a non-positive number. Not convex in s: IPOPT returns a local
    minimiser, started at the max-min solution.

:func:`side_length_nlp` returns a :class:`SideLengthSolution` (the boundary data and
what the last solver reported); :func:`length_spread` summarises a pattern's sides. Both
refuse, before any work, a pattern whose program needs more memory than the machine has
(:func:`check_memory`): their constraint matrices are dense in ell, so they grow like
N M (N + M).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np
from scipy.optimize import linprog

from .. import memory
from .backend import finite_array
from .boundary import BoundaryData, check_boundary, check_size
from ..errors import InfeasibleDesign, InputError, MarchingError, SolverFailed, raise_for_ipopt
from ..files import Key, check_value
from ..ipopt_options import NO_OPTION_FILE
from .marching import boundary_inputs, evaluate, locate_failure, pattern_function
from .vertex import panel_sides

#: The objectives of :func:`side_length_nlp`.
OBJECTIVES: tuple[str, ...] = ("max_min", "uniform")
#: Default lower bound of :func:`side_length_nlp` on every side, as a fraction of the mean.
DEFAULT_MIN_LENGTH = 1e-3
_MIN_LENGTH = Key("number", low=0, high=1, low_open=True, high_open=True,
                  hint="(a fraction of the mean side; 1 would force all sides equal)")
_PROGRAM = Key("choice", choices=("lp", "nlp"))


# --------------------------------------------------------------------------- linear maps
@dataclass(frozen=True)
class LengthMaps:
    """Linear maps from ell (N+M,) to every side: ``lh = Lh @ ell``, ``lv = Lv @ ell``.

    ``Lh`` is (N+1, M, N+M), ``Lv`` is (N, M+1, N+M).
    """

    Lh: np.ndarray
    Lv: np.ndarray

    def __post_init__(self) -> None:
        Lh = finite_array(self.Lh, "Lh", ndim=3, allowed="an (N+1, M, N+M) array of finite "
                          "numbers with N, M >= 1")
        n1, M, n = Lh.shape
        if n1 < 2 or M < 1 or n != n1 - 1 + M:
            raise InputError(f"Lh must be an (N+1, M, N+M) array of finite numbers with N, "
                             f"M >= 1, got shape {Lh.shape}")
        Lv = finite_array(self.Lv, "Lv", shape=(n1 - 1, M + 1, n))
        object.__setattr__(self, "Lh", Lh)
        object.__setattr__(self, "Lv", Lv)

    @property
    def interior(self) -> np.ndarray:
        """(2NM, N+M): the rows of the sides marching computes (l_cd, l_bd of every panel),
        the LP's constraint matrix."""
        n = self.Lh.shape[-1]
        return np.concatenate([self.Lv[:, 1:].reshape(-1, n), self.Lh[1:, :].reshape(-1, n)])

    @property
    def all_sides(self) -> np.ndarray:
        """(K, N+M): the rows of every side, ``lh`` (N+1, M) row-major then ``lv`` (N, M+1)
        row-major (the order of :attr:`Pattern.side_lengths`)."""
        n = self.Lh.shape[-1]
        return np.concatenate([self.Lh.reshape(-1, n), self.Lv.reshape(-1, n)])


def length_maps(bd: BoundaryData) -> LengthMaps:
    """The linear maps of the side lengths for the angles of ``bd`` (its lengths are ignored).

    The angles are marched once; the sides then follow eq:getSides with coefficient vectors
    in place of numbers. Raises :class:`MarchingError` if the angles fail the first or the
    second check; :class:`InputError` when ``bd`` is not :class:`BoundaryData`.
    """
    check_boundary(bd)
    N, M = bd.N, bd.M
    alpha, beta, _, _, _, mu, alpha_d, _, _ = evaluate(pattern_function(N, M),
                                                       boundary_inputs(bd))
    failure = locate_failure(alpha_d, mu, np.ones((N + 1, M)), np.ones((N, M + 1)))
    if failure is not None:
        raise MarchingError(*failure)
    a_a, a_b, a_c = alpha[:-1, :-1], np.pi - beta[1:, :-1], beta[:-1, 1:]
    cd_ab, bd_ab = panel_sides(a_a, a_b, a_c, 1.0, 0.0)
    cd_ac, bd_ac = panel_sides(a_a, a_b, a_c, 0.0, 1.0)
    n = N + M
    Lh = np.zeros((N + 1, M, n))
    Lv = np.zeros((N, M + 1, n))
    Lv[:, 0, :N] = np.eye(N)
    Lh[0, :, N:] = np.eye(M)
    for i in range(N):
        for j in range(M):
            Lv[i, j + 1] = cd_ab[i, j] * Lv[i, j] + cd_ac[i, j] * Lh[i, j]
            Lh[i + 1, j] = bd_ab[i, j] * Lv[i, j] + bd_ac[i, j] * Lh[i, j]
    return LengthMaps(Lh=Lh, Lv=Lv)


# --------------------------------------------------------------------------- memory
def memory_estimate(N: int, M: int, program: str) -> float:
    """Bytes that a side-length ``program`` ("lp": HiGHS' LPs, "nlp": IPOPT's "uniform"
    NLP) needs for N x M panels (:func:`rffqm_nlp.memory.lengths_estimate`)."""
    N, M = check_size(N, M)
    program = check_value(program, _PROGRAM, "program")
    return memory.lengths_estimate(N, M, program)


def check_memory(bd: BoundaryData, program: str, name: str) -> None:
    """Refuse, before any work, side lengths of ``bd``'s pattern that this machine cannot
    hold with ``program`` (:func:`memory_estimate`): one :class:`InputError` line naming
    the function ``name``."""
    check_boundary(bd)
    program = check_value(program, _PROGRAM, "program")
    name = check_value(name, Key("string"), "name")
    memory.refuse_beyond(memory_estimate(bd.N, bd.M, program),
                         f"{name} on {bd.N} x {bd.M} panels",
                         "choose fewer panels or keep the given side lengths")


# --------------------------------------------------------------------------- the LP
def side_length_lp(bd: BoundaryData, eps: float = 1e-2,
                   delta: float | None = None) -> BoundaryData:
    """Boundary data with the angles of ``bd`` and side lengths from the LP (eq:linearP).

    ``eps`` is the lower bound on every computed side; the result is ell* + delta 1 with
    ``delta`` (default: the smaller of eps and half the admissible shift) keeping every side
    positive. Raises :class:`InfeasibleDesign` when no positive lengths exist for these
    angles, :class:`MarchingError` when the angles themselves fail, :class:`InputError`
    when this machine cannot hold the LP (:func:`check_memory`) and for arguments of the
    wrong kind (``bd`` not BoundaryData, ``eps`` not a finite number > 0, ``delta`` neither
    None nor a finite number in the admissible range).
    """
    check_boundary(bd)
    eps = check_value(eps, Key("number", low=0.0, low_open=True, hint="(a length)"), "eps")
    if delta is not None:
        delta = check_value(delta, Key("number", low=0.0, low_open=True,
                                          hint="(a length, or None)"), "delta")
    check_memory(bd, "lp", "side_length_lp")
    A = length_maps(bd).interior
    n = A.shape[1]
    res = linprog(np.ones(n), A_ub=-A, b_ub=-eps * np.ones(A.shape[0]), bounds=(0, None),
                  method="highs")
    if res.status == 2:
        raise InfeasibleDesign(
            "no positive side lengths exist for these sector angles (the LP of eq:linearP is "
            "infeasible); change the boundary angles")
    if not res.success:
        raise InfeasibleDesign(f"the side-length LP failed: {res.message}")
    ell = np.asarray(res.x)
    shift = A @ np.ones(n)
    max_delta = np.inf if shift.min() >= 0 else eps / -shift.min()
    if delta is None:
        delta = min(eps, 0.5 * max_delta)
    elif not (0 < delta < max_delta):
        raise InputError(f"delta must lie in (0, {max_delta:.6g}) to keep every side positive, "
                         f"got {delta:g}")
    lengths = ell + delta
    if not np.all(np.isfinite(lengths)):
        raise InfeasibleDesign(f"the side-length LP's lengths overflow for eps = {eps:g}; "
                               "choose a smaller eps")
    return bd.with_lengths(lengths)


# --------------------------------------------------------------------------- the NLP
@dataclass(frozen=True)
class SideLengthSolution:
    """A solved side-length NLP: the boundary data and what the solver reported.

    ``sides`` (K,) are all edge lengths (rows of :attr:`LengthMaps.all_sides`), mean 1;
    ``min_over_mean`` is the smallest of them; ``objective`` the optimal objective value
    (t* for "max_min", var(log s) for "uniform"); ``stats`` the last solver's status,
    success, iterations and objective (HiGHS' for "max_min", IPOPT's for "uniform").
    """

    boundary: BoundaryData
    sides: np.ndarray
    objective: float
    min_over_mean: float
    stats: dict


def side_length_nlp(bd: BoundaryData, objective: str = "max_min",
                    min_length: float | None = None, *, tol: float = 1e-10,
                    max_iter: int = 3000, verbose: bool = False) -> SideLengthSolution:
    """Optimised side lengths (mean side 1) for the angles of ``bd``: the solution's
    ``boundary`` is ``bd`` with those lengths.

    ``objective`` is one of :data:`OBJECTIVES` (see the module docstring). ``min_length``
    (default :data:`DEFAULT_MIN_LENGTH`) is the lower bound on every side as a fraction of
    the mean side, in (0, 1). ``tol``, ``max_iter`` and ``verbose`` are IPOPT's, for
    "uniform" (the max-min LP runs to HiGHS' own tolerances). Raises
    :class:`InfeasibleDesign` when no lengths give every side >= min_length * mean (in
    particular when no valid pattern exists for these angles), :class:`SolverFailed` with
    the solver's status when HiGHS or IPOPT does not succeed,
    :class:`MarchingError` when the angles themselves fail the marching checks and
    :class:`InputError` on invalid arguments or a program this machine cannot hold
    (:func:`check_memory`).
    """
    check_boundary(bd)
    objective = check_value(objective, Key("choice", choices=OBJECTIVES), "objective")
    min_length = check_value(DEFAULT_MIN_LENGTH if min_length is None else min_length,
                                _MIN_LENGTH, "min_length")
    tol = check_value(tol, Key("number", low=0, low_open=True), "tol")
    max_iter = check_value(max_iter, Key("whole", low=1, high=2**31 - 1), "max_iter")
    verbose = check_value(verbose, Key("bool"), "verbose")
    check_memory(bd, "lp" if objective == "max_min" else "nlp", "side_length_nlp")
    A = length_maps(bd).all_sides
    mean_row = A.mean(axis=0)
    if not np.any(np.abs(mean_row) > 0):
        raise InfeasibleDesign("the mean side length is identically zero for these angles")
    ell, t_star, stats = _max_min(A, mean_row)
    _check_feasible(t_star, min_length)
    value = t_star
    if objective == "uniform":
        s0 = np.maximum(A @ ell, min_length)
        ell, value, stats = _uniform(A, mean_row, min_length, ell, s0,
                                     _ipopt_options(tol, int(max_iter), verbose))
    floor = (min_length if objective == "uniform" else t_star) * (1 - 1e-6)
    return _solution(bd, A, ell, float(value), floor, stats)


def _check_feasible(t_star: float, min_length: float) -> None:
    """Raise :class:`InfeasibleDesign` unless the max-min optimum t* reaches min_length."""
    if t_star <= 0:
        raise InfeasibleDesign(
            f"no positive side lengths exist for these sector angles: the largest achievable "
            f"smallest side is {t_star:.3g} times the mean side (the LP of eq:linearP is "
            "infeasible); change the boundary angles")
    if t_star < min_length:
        raise InfeasibleDesign(
            f"every side >= min_length = {min_length:g} times the mean side is impossible for "
            f"these sector angles: the best achievable is {t_star:.3g}; lower min_length or "
            "change the boundary angles")


def _solution(bd: BoundaryData, A: np.ndarray, ell: np.ndarray, value: float, floor: float,
              stats: dict) -> SideLengthSolution:
    """The solution scaled to mean side 1; :class:`SolverFailed` if a side is below ``floor``
    or the lengths are not admissible boundary lengths."""
    sides = A @ ell
    scale = sides.mean()
    ell, sides = ell / scale, sides / scale
    try:
        boundary = bd.with_lengths(ell)
    except InputError as exc:
        raise SolverFailed(f"the solver's lengths are not admissible boundary lengths: {exc}",
                           status="invalid_lengths", last_iterate=ell) from exc
    if sides.min() < floor:
        raise SolverFailed(
            f"the solution violates its bound: smallest side {sides.min():.3g} of the mean, "
            f"bound {floor:.3g}", status="bound_violated", last_iterate=ell)
    return SideLengthSolution(boundary=boundary, sides=sides, objective=value,
                              min_over_mean=float(sides.min()), stats=stats)


def _ipopt_options(tol: float, max_iter: int, verbose: bool) -> dict[str, Any]:
    return {"ipopt.tol": float(tol), "ipopt.constr_viol_tol": 1e-10,
            "ipopt.max_iter": max_iter, "ipopt.print_level": 5 if verbose else 0,
            "print_time": verbose, "ipopt.sb": "yes", **NO_OPTION_FILE}


def _solve(name: str, x, f, g, opts: dict, x0, lbx, ubx, lbg,
           ubg) -> tuple[np.ndarray, float, dict]:
    """IPOPT on min f(x) s.t. lbg <= g(x) <= ubg, lbx <= x <= ubx: (x*, f*, stats)."""
    solver = ca.nlpsol(name, "ipopt", {"x": x, "f": f, "g": g}, opts)
    sol = solver(x0=x0, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
    st = solver.stats()
    xs = np.asarray(sol["x"].full()).ravel()
    stats = {"status": st["return_status"], "success": bool(st["success"]),
             "iterations": int(st["iter_count"]), "objective": float(sol["f"])}
    if not st["success"]:
        raise_for_ipopt(st["return_status"], stats["iterations"],
                        f"the {name} side-length problem",
                        "lower min_length or change the boundary angles",
                        "raise max_iter or relax tol", last_iterate=xs)
    return xs, float(sol["f"]), stats


def _max_min(A: np.ndarray, mean_row: np.ndarray) -> tuple[np.ndarray, float, dict]:
    """max t s.t. A ell >= t, mean_row . ell = 1 (variables ell, t, both free), an LP solved
    with HiGHS: (ell*, t*, stats). Always feasible and bounded (t <= mean(A ell) = 1), so
    any other outcome is a :class:`SolverFailed` with HiGHS' message."""
    K, n = A.shape
    cost = np.zeros(n + 1)
    cost[n] = -1.0
    res = linprog(cost, A_ub=np.hstack([-A, np.ones((K, 1))]), b_ub=np.zeros(K),
                  A_eq=np.append(mean_row, 0.0)[None, :], b_eq=[1.0], bounds=(None, None),
                  method="highs")
    if not res.success:
        raise SolverFailed(f"HiGHS did not solve the max_min side-length LP: {res.message}",
                           status=str(res.status))
    t_star = float(-res.fun)
    stats = {"status": res.message, "success": True, "iterations": int(res.nit),
             "objective": t_star}
    return np.asarray(res.x[:n]), t_star, stats


def _uniform(A: np.ndarray, mean_row: np.ndarray, min_length: float, ell0: np.ndarray,
             s0: np.ndarray, opts: dict):
    """min var(log s) s.t. s = A ell, mean(s) = 1, s >= min_length (variables ell, s)."""
    K, n = A.shape
    x = ca.MX.sym("x", n + K + 1)
    ell, s, m = x[:n], x[n:n + K], x[n + K]
    # var(log s) = min over m of mean((log s - m)^2); the free variable m keeps the Hessian
    # sparse (the closed form with mean(log s)^2 couples every pair of sides).
    f = ca.sumsqr(ca.log(s) - m) / K
    g = ca.vertcat(ca.mtimes(ca.DM(A), ell) - s, ca.sum1(s) / K)
    lbx = np.concatenate([np.full(n, -np.inf), np.full(K, min_length), [-np.inf]])
    x0 = np.concatenate([ell0, s0, [np.log(s0).mean()]])
    xs, f_val, stats = _solve("uniform", x, f, g, opts, x0, lbx, np.inf,
                              np.append(np.zeros(K), 1.0), np.append(np.zeros(K), 1.0))
    return xs[:n], f_val, stats


# --------------------------------------------------------------------------- summary
def length_spread(lh: np.ndarray, lv: np.ndarray) -> dict[str, float]:
    """Summary of a pattern's side lengths lh (N+1, M) and lv (N, M+1): smallest/mean,
    largest/mean, max/min. The sides are finite positive numbers (at least one of them);
    anything else raises :class:`InputError`."""
    sides = np.concatenate([np.ravel(finite_array(lh, "lh")), np.ravel(finite_array(lv, "lv"))])
    if sides.size == 0 or sides.min() <= 0 or not np.isfinite(sides.sum()):
        raise InputError("length_spread needs at least one side, every side a finite positive "
                         "length (their sum finite), got "
                         + (f"{sides.size} sides, the smallest {sides.min():g}" if sides.size
                            else "no sides"))
    mean = sides.mean()
    return {"min_over_mean": float(sides.min() / mean), "max_over_mean": float(sides.max() / mean),
            "max_over_min": float(sides.max() / sides.min())}
