"""The folding motion's exact velocity and what follows from it: Poisson's ratio of the
pattern and of each cell of its coarse lattice.

The velocity dY/domega of every vertex is the forward-mode derivative of the CasADi fold
graph (:func:`rffqm_nlp.model.marching.fold_function`, eq:foldInitial .. eq:finalCalc):
exact to round-off, no finite difference. It is the folding motion with panel (1, 1) held
(R^{11} = I, y^{11} = 0).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from ..errors import InputError
from ..model import numpy_model
from ..model.backend import finite_result
from ..model.marching import fold_function
from ..model.pattern import Pattern, check_fold_angle, check_pattern
from ..targets.shape import coarse_grain

#: |omega| at most this (flat) or at least pi minus this (folded flat) has no Poisson's
#: ratio: the lengths L1 and L2 are stationary there (0/0).
FLAT_TOL = 1e-6


@lru_cache(maxsize=8)
def _velocity_function(N: int, M: int) -> ca.Function:
    """The forward derivative of the fold graph of N x M panels along omega."""
    return fold_function(N, M).forward(1)


def folded_state(pattern: Pattern, omega: Any) -> tuple[np.ndarray, np.ndarray]:
    """The folded vertices Y and their exact velocity dY/domega, both (N+1, M+1, 3), of
    ``pattern`` at ``omega`` (in [-pi, pi]), in the pattern's length unit (per radian).

    Y is the NumPy model's fold (:func:`rffqm_nlp.numpy_model.fold`); the velocity is the
    CasADi fold graph's forward derivative (module docstring). Raises :class:`InputError`
    for a pattern that is not a :class:`~rffqm_nlp.Pattern` or an omega outside [-pi, pi].
    """
    check_pattern(pattern, "pattern")
    w = check_fold_angle(omega)
    Y = numpy_model.fold(pattern, w)
    f = fold_function(pattern.N, pattern.M)
    args = [pattern.alpha, pattern.beta, pattern.sigma, pattern.lh, pattern.lv, w]
    nominal = f(*args)
    rates = _velocity_function(pattern.N, pattern.M)(*args, *nominal, 0, 0, 0, 0, 0, 1.0)
    V = np.stack([np.asarray(r, dtype=float) for r in rates], axis=-1)
    return Y, finite_result(V, "the folding velocity is not finite: the pattern has a "
                               "vertex outside MV(alpha, beta)")


def folding_velocity(pattern: Pattern, omega: Any) -> np.ndarray:
    """The exact folding velocity dY/domega (N+1, M+1, 3) of ``pattern`` at ``omega``, in
    the pattern's length unit per radian (:func:`folded_state`)."""
    return folded_state(pattern, omega)[1]


def _log_rate(Y: np.ndarray, V: np.ndarray, start: tuple, end: tuple) -> np.ndarray:
    """d ln|Y[end] - Y[start]| / domega for index tuples (arrays broadcast)."""
    chord = Y[end] - Y[start]
    return np.einsum("...k,...k->...", chord, V[end] - V[start]) / np.einsum(
        "...k,...k->...", chord, chord)


def _ratio(d2: np.ndarray, d1: np.ndarray) -> np.ndarray:
    """-d2 / d1, refused where d1 vanishes."""
    if np.any(np.abs(d1) <= 1e-14 * np.maximum(1.0, np.abs(d2))):
        raise InputError("Poisson's ratio has no value here: the length L1 does not change "
                         "with omega at this state; choose another omega")
    return -d2 / d1


def _check_state(w: float) -> None:
    if abs(w) <= FLAT_TOL or abs(w) >= np.pi - FLAT_TOL:
        raise InputError(f"omega must lie strictly between flat and folded flat for "
                         f"Poisson's ratio (|omega| in ({FLAT_TOL:g}, pi - {FLAT_TOL:g})), "
                         f"got {w:g}")


def poisson_ratio(pattern: Pattern, omega: Any) -> float:
    """Poisson's ratio of the folding motion, -(dL2/L2)/(dL1/L1), at ``omega``.

    L1 is the folded distance from vertex (1, 1) to (N+1, 1), L2 from (1, 1) to (1, M+1);
    both rates come from the exact velocity (:func:`folded_state`). ``omega`` must lie
    strictly between flat and folded flat (:data:`FLAT_TOL`), where the lengths are
    stationary. Raises :class:`InputError` otherwise.
    """
    w = check_fold_angle(omega)
    _check_state(w)
    Y, V = folded_state(pattern, w)
    d1 = _log_rate(Y, V, (0, 0), (-1, 0))
    d2 = _log_rate(Y, V, (0, 0), (0, -1))
    return float(_ratio(np.asarray(d2), np.asarray(d1)))


def poisson_map(pattern: Pattern, omega: Any) -> np.ndarray:
    """Poisson's ratio of every cell of the coarse lattice r(i, j) = y^{(2i)(2j)}
    (docs/paper.md s.8), (N/2, M/2), for a pattern of even N and M.

    A cell's L1 rate is the mean of d ln(length)/domega of its two sides along i, its L2
    rate that of its two sides along j; the cell's ratio is -(L2 rate)/(L1 rate), as in
    :func:`poisson_ratio`. Raises :class:`InputError` for odd N or M and where
    :func:`poisson_ratio` would.
    """
    w = check_fold_angle(omega)
    _check_state(w)
    Y, V = folded_state(pattern, w)
    if pattern.N % 2 or pattern.M % 2:
        raise InputError(f"poisson_map needs even N and M (a coarse lattice of 2 x 2 panel "
                         f"cells), got {pattern.N} x {pattern.M} panels")
    R, dR = coarse_grain(Y), coarse_grain(V)
    lo, hi = slice(None, -1), slice(1, None)
    d1 = (_log_rate(R, dR, (lo, lo), (hi, lo)) + _log_rate(R, dR, (lo, hi), (hi, hi))) / 2
    d2 = (_log_rate(R, dR, (lo, lo), (lo, hi)) + _log_rate(R, dR, (hi, lo), (hi, hi))) / 2
    return _ratio(d2, d1)
