"""The paper's side-length linear program (eq:linearP), solved with SciPy's HiGHS.

Every side length of a marched pattern is linear in the boundary lengths
ell = (l_ab^{11..N1}, l_ac^{11..1M}) once the angles are fixed (eq:getSides). The LP
minimises sum(ell) subject to l_cd^{ij}, l_bd^{ij} >= eps and ell >= 0; the lengths used
are ell* + delta (the paper's delta shift), with delta small enough that every side stays
positive. This is the baseline the inverse design replaces with inline constraints.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from .boundary import BoundaryData
from .errors import InfeasibleDesign, InputError, MarchingError
from .marching import boundary_inputs, evaluate, locate_failure, pattern_function
from .vertex import panel_sides


@dataclass(frozen=True)
class LengthMaps:
    """Linear maps from ell (N+M,) to every side: ``lh = Lh @ ell``, ``lv = Lv @ ell``.

    ``Lh`` is (N+1, M, N+M), ``Lv`` is (N, M+1, N+M). ``interior`` (2NM, N+M) stacks the
    rows of the sides that marching computes (l_cd, l_bd of every panel), the LP's
    constraint matrix.
    """

    Lh: np.ndarray
    Lv: np.ndarray

    @property
    def interior(self) -> np.ndarray:
        n = self.Lh.shape[-1]
        return np.concatenate([self.Lv[:, 1:].reshape(-1, n), self.Lh[1:, :].reshape(-1, n)])


def length_maps(bd: BoundaryData) -> LengthMaps:
    """The linear maps of the side lengths for the angles of ``bd`` (its lengths are ignored).

    The angles are marched once; the sides then follow eq:getSides with coefficient vectors
    in place of numbers. Raises :class:`MarchingError` if the angles fail the first or the
    second check.
    """
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


def side_length_lp(bd: BoundaryData, eps: float = 1e-2,
                   delta: float | None = None) -> BoundaryData:
    """Boundary data with the angles of ``bd`` and side lengths from the LP (eq:linearP).

    ``eps`` is the lower bound on every computed side; the result is ell* + delta 1 with
    ``delta`` (default: the largest of eps and half the admissible shift, whichever is
    smaller) keeping every side positive. Raises :class:`InfeasibleDesign` when no positive
    lengths exist for these angles, :class:`MarchingError` when the angles themselves fail.
    """
    if not (np.isfinite(eps) and eps > 0):
        raise InputError(f"eps must be a finite positive length, got {eps!r}")
    maps = length_maps(bd)
    A = maps.interior
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
                         f"got {delta!r}")
    return bd.with_lengths(ell + delta)


def length_spread(lh: np.ndarray, lv: np.ndarray) -> dict[str, float]:
    """Summary of a pattern's side lengths: smallest/mean, largest/mean, max/min."""
    sides = np.concatenate([np.ravel(lh), np.ravel(lv)])
    mean = sides.mean()
    return {"min_over_mean": float(sides.min() / mean), "max_over_mean": float(sides.max() / mean),
            "max_over_min": float(sides.max() / sides.min())}
