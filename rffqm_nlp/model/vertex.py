"""One degree-4 vertex: fold-angle multipliers, fold-angle functions and the design formula.

Every function is written once over the math of :func:`backend.math_for` and serves NumPy
arrays and CasADi symbols alike. All forms are the smooth half-angle ones (docs/paper.md
s.2): for the a-role sector angles (alpha, beta) and sign sigma,

    mu2^{-1}(alpha, beta) = cos((alpha - beta)/2) / cos((alpha + beta)/2),
    mu2^{+1}(alpha, beta) = -sin((alpha - beta)/2) / sin((alpha + beta)/2),

which equal eq:foldAngMult, and mu1^{-sigma} = 1 / mu2^{sigma}. The fold-angle functions are
tan(gamma2_bar/2) = -tan(omega/2)/mu2 and tan(gamma1_bar/2) = -tan(omega/2)/mu1.

Every function checks its arguments (:func:`rffqm_nlp.model.backend.check_formula_args`: CasADi
matrices, or finite real numbers and arrays broadcasting together, a sign sigma +1 or -1)
and, on numbers, its result: where the formula has no finite value (a multiplier at its
pole, sigma outside MV(alpha, beta); a panel whose angles sum to a multiple of pi) it
raises :class:`~rffqm_nlp.errors.InputError` saying so instead of returning NaN or
infinity. CasADi graphs are returned unchecked.
"""

from __future__ import annotations

from typing import Any

import casadi as ca
import numpy as np

from .backend import Scalar, check_formula_args, finite_result, is_casadi, math_for
from ..errors import InputError

#: Why a multiplier has no finite value, for the errors.
_POLE = ("sigma is not in MV(alpha, beta) (cos(beta) = sigma cos(alpha)), where the "
         "multiplier is 0 or infinite; give an admissible vertex (Theorem 2.1)")


def _arrays(*values: Any) -> tuple:
    """The (checked) arguments with lists and tuples of numbers as float arrays."""
    return tuple(np.asarray(v, dtype=float) if isinstance(v, (list, tuple)) else v
                 for v in values)


def _checked(symbolic: bool, value: Any, what: str) -> Any:
    """``value`` as it is for a graph, else unless it holds NaN or infinity."""
    return value if symbolic else finite_result(value, what)


def mu2(alpha: Scalar, beta: Scalar, sigma: Scalar) -> Scalar:
    """Fold-angle multiplier mu2^sigma(alpha, beta) (eq:foldAngMult), half-angle form."""
    symbolic = check_formula_args(alpha=alpha, beta=beta, sigma=sigma)
    num, den = _mu2_terms(*_arrays(alpha, beta, sigma))
    with np.errstate(divide="ignore", invalid="ignore"):
        return _checked(symbolic, num / den, f"mu2 has no finite value: {_POLE}")


def mu2_terms(alpha: Scalar, beta: Scalar, sigma: Scalar) -> tuple[Scalar, Scalar]:
    """Numerator and denominator of :func:`mu2`: (cos h-, cos h+) at sigma = -1 and
    (-sin h-, sin h+) at sigma = +1, h-+ = (alpha -+ beta)/2.

    Both are smooth and never vanish together for angles in (0, pi), so a quantity
    proportional to mu2 or to 1 / mu2 can be written without a quotient through the points
    where mu2 is 0 or infinite (see transcription.lifting.local_crease_quaternions).
    """
    check_formula_args(alpha=alpha, beta=beta, sigma=sigma)
    return _mu2_terms(*_arrays(alpha, beta, sigma))


def _mu2_terms(alpha, beta, sigma):
    op = math_for(alpha, beta, sigma)
    h_minus, h_plus = (alpha - beta) / 2, (alpha + beta) / 2
    return (op.where(sigma < 0, op.cos(h_minus), -op.sin(h_minus)),
            op.where(sigma < 0, op.cos(h_plus), op.sin(h_plus)))


def mu1(alpha: Scalar, beta: Scalar, sigma: Scalar) -> Scalar:
    """Fold-angle multiplier mu1^{-sigma}(alpha, beta) = 1 / mu2^sigma(alpha, beta)."""
    symbolic = check_formula_args(alpha=alpha, beta=beta, sigma=sigma)
    num, den = _mu2_terms(*_arrays(alpha, beta, sigma))
    with np.errstate(divide="ignore", invalid="ignore"):
        return _checked(symbolic, den / num, f"mu1 has no finite value: {_POLE}")


def mv_multiplier(alpha: Scalar, beta: Scalar, sigma: np.ndarray) -> Scalar:
    """The fold multiplier that vanishes where sigma leaves MV(alpha, beta) (Theorem 2.1).

    mu2^{+1} = -sin(h-)/sin(h+) at sigma = +1 vertices (zero at alpha = beta) and
    mu1^{+1} = 1/mu2^{-1} = cos(h+)/cos(h-) at sigma = -1 vertices (zero at alpha + beta = pi),
    with h-+ = (alpha -+ beta)/2; finite for angles in (0, pi). Across a zero, mu2 changes
    sign and with it the sign of gamma2 (tan(gamma2/2) = -tan(omega/2)/mu2): a mountain crease
    of the vertex becomes a valley. Holding the sign of this multiplier holds the vertex's MV
    assignment. ``sigma`` is numeric (the signs are data, not design variables).
    """
    if is_casadi(sigma):
        raise InputError("sigma of mv_multiplier must be numbers (+1 or -1), not a CasADi "
                         "matrix: the signs are data, not design variables")
    symbolic = check_formula_args(alpha=alpha, beta=beta, sigma=sigma)
    alpha, beta = _arrays(alpha, beta)
    plus = (np.asarray(sigma, dtype=float) > 0).astype(float)
    if is_casadi(alpha, beta):
        matrix = alpha if is_casadi(alpha) else beta
        if plus.size != matrix.numel():
            raise InputError(f"sigma of mv_multiplier must have one sign per entry of alpha "
                             f"({matrix.numel()}), got {plus.size}")
        plus = ca.reshape(ca.DM(plus), *matrix.shape)
    num, den = _mu2_terms(alpha, beta, 2 * plus - 1)
    # num / den at sigma = +1, den / num at sigma = -1: both divisors stay positive
    with np.errstate(divide="ignore", invalid="ignore"):
        value = (plus * num + (1 - plus) * den) / (plus * den + (1 - plus) * num)
    return _checked(symbolic, value, "mv_multiplier has no finite value: the angles are "
                                     "outside (0, pi), where its divisor vanishes")


def fold_by_multiplier(omega: Scalar, mu: Scalar) -> Scalar:
    """The group element g with tan(g/2) = -tan(omega/2)/mu, on omega in [-pi, pi].

    Written with atan2 so omega = +-pi (folded flat) is exact: g = -sign(mu) omega there.
    """
    symbolic = check_formula_args(omega=omega, mu=mu)
    return _checked(symbolic, _fold_by_multiplier(*_arrays(omega, mu)), "fold_by_multiplier "
                    "has no finite value")


def _fold_by_multiplier(omega, mu):
    op = math_for(omega, mu)
    half = omega / 2
    return 2 * op.atan2(-op.sin(half) * _sign(mu, op), op.fabs(mu) * op.cos(half))


def gamma2_bar(omega: Scalar, alpha: Scalar, beta: Scalar, sigma: Scalar) -> Scalar:
    """gamma2 as a function of gamma1 = omega at a vertex (Theorem 2.1)."""
    return fold_by_multiplier(omega, mu2(alpha, beta, sigma))


def gamma1_bar(omega: Scalar, alpha: Scalar, beta: Scalar, sigma: Scalar) -> Scalar:
    """Inverse of :func:`gamma2_bar` (eq:inverse): gamma1 as a function of gamma2 = omega."""
    return fold_by_multiplier(omega, mu1(alpha, beta, sigma))


def fold_angles(omega: Scalar, alpha: Scalar, beta: Scalar,
                sigma: Scalar) -> tuple[Scalar, Scalar, Scalar, Scalar]:
    """(gamma1, gamma2, gamma3, gamma4) at a vertex (eq:foldParams)."""
    check_formula_args(omega=omega, alpha=alpha, beta=beta, sigma=sigma)
    omega, sigma = _arrays(omega, sigma)
    g2 = gamma2_bar(omega, alpha, beta, sigma)
    return omega, g2, -sigma * omega, sigma * g2


def design_d(alpha_d: Scalar, mu_abc: Scalar) -> tuple[Scalar, Scalar]:
    """The design formula (eq:SuperParam) in half-angle form: (beta_d, sigma_d).

    sigma_d = -sign(mu^2 - 1). Solving mu2^{sigma_d}(alpha_d, beta_d) = mu with
    u = tan(alpha_d/2), v = tan(beta_d/2) and k = (mu - 1)/(mu + 1) gives v = k/u for
    sigma_d = -1 and v = -u/k for sigma_d = +1; v > 0 whenever |mu| != 1.
    """
    symbolic = check_formula_args(alpha_d=alpha_d, mu_abc=mu_abc)
    with np.errstate(over="ignore"):            # mu^2 of a huge mu: outside, as it should
        out = _design_d(*_arrays(alpha_d, mu_abc))
    return _checked(symbolic, out, "design_d has no solution: |mu_abc| = 1 (eq:secondCheck) "
                                   "or alpha_d a multiple of pi")


def _design_d(alpha_d, mu_abc):
    op = math_for(alpha_d, mu_abc)
    outside = mu_abc * mu_abc > 1
    sigma_d = op.where(outside, -1.0, 1.0)
    u = op.tan(alpha_d / 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = op.where(outside, (mu_abc - 1) / ((mu_abc + 1) * u), u * (1 + mu_abc) / (1 - mu_abc))
    return 2 * op.atan(v), sigma_d


def panel_sides(alpha_a: Scalar, alpha_b: Scalar, alpha_c: Scalar, l_ab: Scalar,
                l_ac: Scalar) -> tuple[Scalar, Scalar]:
    """(l_cd, l_bd) from the panel's angles and its left and bottom sides (eq:getSides)."""
    symbolic = check_formula_args(alpha_a=alpha_a, alpha_b=alpha_b, alpha_c=alpha_c,
                                  l_ab=l_ab, l_ac=l_ac)
    s, cd, bd = _panel_side_terms(*_arrays(alpha_a, alpha_b, alpha_c, l_ab, l_ac))
    with np.errstate(divide="ignore", invalid="ignore"):
        sides = cd / s, bd / s
    return _checked(symbolic, sides, "panel_sides has no finite value: alpha_a + alpha_b + "
                                     "alpha_c is a multiple of pi (alpha_d = 0 or pi fails "
                                     "the first check, eq:firstCheck)")


def panel_side_residuals(alpha_a: Scalar, alpha_b: Scalar, alpha_c: Scalar, l_ab: Scalar,
                         l_ac: Scalar, l_cd: Scalar, l_bd: Scalar) -> tuple[Scalar, Scalar]:
    """eq:getSides as residuals multiplied through by its denominator
    s = sin(alpha_a + alpha_b + alpha_c) = -sin(alpha_d): s l_cd - (...), s l_bd - (...).

    They vanish exactly where :func:`panel_sides` gives (l_cd, l_bd) whenever s != 0, which
    holds for alpha_d in (0, pi), and are smooth where the quotient is not: an infeasible
    iterate of the simultaneous transcription can make a panel thin (alpha_d near 0 or pi),
    where the quotient and its derivatives grow like 1 / s and 1 / s^2.
    """
    symbolic = check_formula_args(alpha_a=alpha_a, alpha_b=alpha_b, alpha_c=alpha_c,
                                  l_ab=l_ab, l_ac=l_ac, l_cd=l_cd, l_bd=l_bd)
    alpha_a, alpha_b, alpha_c, l_ab, l_ac, l_cd, l_bd = _arrays(
        alpha_a, alpha_b, alpha_c, l_ab, l_ac, l_cd, l_bd)
    s, cd, bd = _panel_side_terms(alpha_a, alpha_b, alpha_c, l_ab, l_ac)
    with np.errstate(over="ignore", invalid="ignore"):
        out = s * l_cd - cd, s * l_bd - bd
    return _checked(symbolic, out, "panel_side_residuals overflow: the lengths are too large "
                                   "for floating point")


def _panel_side_terms(alpha_a, alpha_b, alpha_c, l_ab, l_ac):
    """The denominator and the two numerators of eq:getSides: (s, s l_cd, s l_bd)."""
    op = math_for(alpha_a, alpha_b, alpha_c, l_ab, l_ac)
    s = op.sin(alpha_a + alpha_b + alpha_c)
    return (s, -op.sin(alpha_b) * l_ab + op.sin(alpha_a + alpha_b) * l_ac,
            op.sin(alpha_a + alpha_c) * l_ab - op.sin(alpha_c) * l_ac)


def _sign(x, op):
    return op.where(x < 0, -1.0, 1.0)
