"""Side lengths by nonlinear optimisation over the LP's feasible set (CasADi + IPOPT).

The paper (section "A linear program for the side lengths", Fig. Random) fixes the sector
angles by marching, notes that every side is linear in the boundary lengths
ell = (l_ab^{11..N1}, l_ac^{11..1M}) and picks ell by the LP eq:linearP (minimise sum(ell)).
That objective is arbitrary and drives some sides to nearly zero; the paper suggests, and
leaves to future work, a nonlinear objective "that attempts to keep the aspect ratios of the
panels as uniform as possible, while optimizing over the same feasible set". This module does
that.

Notation: s = A ell (K,) are *all* K = (N+1)M + N(M+1) edge lengths of the pattern (the
boundary sides ell included), A from :func:`rffqm_nlp.lengths.length_maps`. Every problem
fixes the scale by the linear equality mean(s) = 1 and asks s >= min_length (= min_length
times the mean side). Up to that scale and the strictness of the bounds this is the LP's
feasible set: {A_interior ell >= eps, ell >= 0}.

Objectives:

* ``"max_min"``: maximise t subject to s >= t (epigraph form). This is an LP; it is solved
  here with IPOPT too (exact derivatives, interior point) so both objectives share one code
  path and one error model; the tests certify its optimum against SciPy's HiGHS to 1e-6. Its
  optimum t* decides feasibility: no pattern with all sides >= min_length * mean exists
  iff t* < min_length, and no valid pattern at all iff t* <= 0.
* ``"uniform"``: minimise the variance of log side lengths,
  var(log s) = mean(log(s)^2) - mean(log s)^2. Chosen over "sum of squared deviations of
  each panel's aspect ratio from 1" because (i) it is scale-invariant and 0 exactly when all
  sides are equal, so a Miura-ori with a = b is recovered exactly; (ii) it penalises a side
  going to zero without bound (log s -> -inf), a built-in barrier against the LP's
  near-degenerate panels, and penalises over-long sides symmetrically; (iii) it controls the
  spread of sizes across the pattern, which a per-panel aspect-ratio objective does not (a
  tiny square panel next to a large one has perfect aspect ratios); (iv) "aspect ratio" of a
  general quadrilateral panel needs an arbitrary definition, while equal sides imply
  per-panel aspect ratios near 1 wherever the angles allow it. The sides are lifted to
  variables s with bounds s >= min_length and equalities s = A ell, so IPOPT's interior point
  iterates never evaluate log of a non-positive number. The objective is not convex in s, so
  IPOPT returns a local minimiser; it is started at the max-min solution (feasible, every
  side >= t*).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from .boundary import BoundaryData
from .errors import InfeasibleDesign, InputError, SolverFailed, raise_for_ipopt
from .lengths import length_maps

OBJECTIVES: tuple[str, ...] = ("max_min", "uniform")
#: Default lower bound on every side, as a fraction of the mean side.
DEFAULT_MIN_LENGTH = 1e-3


@dataclass(frozen=True)
class SideLengthSolution:
    """A solved side-length problem: the boundary data and what the solver reported.

    ``sides`` (K,) are all edge lengths (rows of :func:`all_sides_matrix`), mean 1;
    ``min_over_mean`` is the smallest of them; ``objective`` the optimal objective value
    (t* for "max_min", var(log s) for "uniform"); ``stats`` IPOPT's status and counts.
    """

    boundary: BoundaryData
    sides: np.ndarray
    objective: float
    min_over_mean: float
    stats: dict


def all_sides_matrix(bd: BoundaryData) -> np.ndarray:
    """A (K, N+M): every edge length of the pattern of ``bd``'s angles is ``A @ ell``.

    Rows: the horizontal edges ``lh`` (N+1, M) row-major, then the vertical edges ``lv``
    (N, M+1) row-major (the order of :attr:`Pattern.side_lengths`). Raises
    :class:`MarchingError` when the angles fail the first or the second check.
    """
    maps = length_maps(bd)
    n = maps.Lh.shape[-1]
    return np.concatenate([maps.Lh.reshape(-1, n), maps.Lv.reshape(-1, n)])


def side_length_nlp(bd: BoundaryData, objective: str = "max_min",
                    min_length: float | None = None, *, tol: float = 1e-10,
                    max_iter: int = 3000, verbose: bool = False) -> BoundaryData:
    """Boundary data with the angles of ``bd`` and optimised side lengths (mean side 1).

    See the module docstring for the objectives. ``min_length`` (default
    :data:`DEFAULT_MIN_LENGTH`) is the lower bound on every side as a fraction of the mean
    side, in (0, 1). Raises :class:`InfeasibleDesign` when no lengths give every side
    >= min_length * mean (in particular when no valid pattern exists for these angles),
    :class:`SolverFailed` with IPOPT's status when IPOPT does not succeed,
    :class:`MarchingError` when the angles themselves fail the marching checks and
    :class:`InputError` on invalid arguments.
    """
    return solve_side_lengths(bd, objective, min_length, tol=tol, max_iter=max_iter,
                              verbose=verbose).boundary


def solve_side_lengths(bd: BoundaryData, objective: str = "max_min",
                       min_length: float | None = None, *, tol: float = 1e-10,
                       max_iter: int = 3000, verbose: bool = False) -> SideLengthSolution:
    """:func:`side_length_nlp` returning the full :class:`SideLengthSolution`."""
    if not isinstance(bd, BoundaryData):
        raise InputError(f"side_length_nlp expects BoundaryData, got {type(bd).__name__}")
    if objective not in OBJECTIVES:
        raise InputError(f"objective must be one of {OBJECTIVES}, got {objective!r}")
    if min_length is None:
        min_length = DEFAULT_MIN_LENGTH
    if not (_is_number(min_length) and np.isfinite(min_length) and 0 < min_length < 1):
        raise InputError(
            f"min_length is a fraction of the mean side and must be a number in (0, 1), got "
            f"{min_length!r} (1 would force all sides equal)")
    min_length = float(min_length)
    if not (_is_number(tol) and np.isfinite(tol) and tol > 0):
        raise InputError(f"tol must be a finite positive number, got {tol!r}")
    if not (_is_number(max_iter) and np.isfinite(max_iter) and max_iter >= 1
            and int(max_iter) == max_iter):
        raise InputError(f"max_iter must be a positive integer, got {max_iter!r}")

    A = all_sides_matrix(bd)
    K, n = A.shape
    mean_row = A.mean(axis=0)
    if not np.any(np.abs(mean_row) > 0):
        raise InfeasibleDesign("the mean side length is identically zero for these angles")
    opts = _ipopt_options(tol, int(max_iter), verbose)

    ell, t_star, stats = _max_min(A, mean_row, opts)
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
    value = t_star
    if objective == "uniform":
        s0 = np.maximum(A @ ell, min_length)
        ell, value, stats = _uniform(A, mean_row, min_length, ell, s0, opts)

    sides = A @ ell
    scale = sides.mean()
    ell, sides = ell / scale, sides / scale
    try:
        result = bd.with_lengths(ell)
    except InputError as exc:
        raise SolverFailed(f"IPOPT's lengths are not admissible boundary lengths: {exc}",
                           status="invalid_lengths", stats=stats, last_iterate=ell) from exc
    floor = min_length * (1 - 1e-6) if objective == "uniform" else t_star * (1 - 1e-6)
    if sides.min() < floor:
        raise SolverFailed(
            f"the solution violates its bound: smallest side {sides.min():.3g} of the mean, "
            f"bound {floor:.3g}", status="bound_violated", stats=stats, last_iterate=ell)
    return SideLengthSolution(boundary=result, sides=sides, objective=float(value),
                              min_over_mean=float(sides.min()), stats=stats)


def _is_number(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)


# --------------------------------------------------------------------------- solvers
def _ipopt_options(tol: float, max_iter: int, verbose: bool) -> dict[str, Any]:
    return {"ipopt.tol": float(tol), "ipopt.constr_viol_tol": 1e-10,
            "ipopt.max_iter": max_iter, "ipopt.print_level": 5 if verbose else 0,
            "print_time": verbose, "ipopt.sb": "yes"}


def _solve(name: str, x, f, g, opts: dict, x0, lbx, ubx, lbg, ubg) -> tuple[np.ndarray, float,
                                                                          dict]:
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
                        "raise max_iter or relax tol", stats, xs)
    return xs, float(sol["f"]), stats


def _max_min(A: np.ndarray, mean_row: np.ndarray, opts: dict):
    """max t s.t. A ell >= t, mean_row . ell = 1 (variables ell, t, both free)."""
    K, n = A.shape
    x = ca.MX.sym("x", n + 1)
    ell, t = x[:n], x[n]
    g = ca.vertcat(ca.mtimes(ca.DM(A), ell) - t, ca.dot(ca.DM(mean_row), ell))
    # Start: equal boundary lengths scaled to mean side 1 (any point is fine for an LP).
    ell0 = np.ones(n) / mean_row.sum() if mean_row.sum() > 0 else np.ones(n)
    x0 = np.append(ell0, (A @ ell0).min())
    xs, f, stats = _solve("max_min", x, -t, g, opts, x0, -np.inf, np.inf,
                          np.append(np.zeros(K), 1.0), np.append(np.full(K, np.inf), 1.0))
    return xs[:n], -f, stats


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


__all__ = ["DEFAULT_MIN_LENGTH", "OBJECTIVES", "SideLengthSolution", "all_sides_matrix",
           "side_length_nlp", "solve_side_lengths"]
