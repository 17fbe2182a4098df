"""One cell of the alternating perturbation of a Miura-ori, exactly (docs/closed_form.md).

Everything here is in the *canonical frame*: the layout "zigzag_j" (zig-zag creases along
j, sigma = -1), the zig-zag creases folded by ``omega_z`` > 0 (they all fold by +-omega_z,
eq:foldMiddle and eq:foldFinal), alpha0 the Miura's acute angle. The perturbation puts
alpha = theta_j + s_i delta_j, beta = theta_j - s_i delta_j at vertex (i, j) (theta_j the
Miura's angle, s_i = +1 on odd rows, -1 on even ones) and multiplies the straight sides of
the even rows by (1 + Delta). The march keeps these angles exactly (docs/closed_form.md s.2).

* :func:`zigzag_gain`: kx / (d delta / dX) of a pattern whose delta varies slowly along the
  zig-zag direction (X the folded arc length), exact in delta, and the folded length of one
  column per unit side;
* :func:`straight_gain`: the same for Delta along the straight direction;
* :class:`Tilt`: the turning angle of the folded lattice as a function of the perturbation
  (the integral of a gain), with its inverse: a curvature field integrated along a line
  gives the turning, and the turning gives the perturbation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import brentq

from ....errors import InfeasibleDesign, InputError
from ....files import Key, check_value
from ....model.backend import finite_array, finite_result

E1 = np.array([1.0, 0.0, 0.0])
E3 = np.array([0.0, 0.0, 1.0])
#: Points of the tables that :class:`Tilt` integrates and inverts.
TABLE_POINTS = 1025

_ACUTE = Key("number", low=0.0, high=np.pi / 2, low_open=True, high_open=True,
             hint="(radians)")
_FOLD = Key("number", low=0.0, high=np.pi, low_open=True, high_open=True, hint="(radians)")


def _checked(alpha0: float, omega_z: float) -> tuple[float, float]:
    """alpha0 in (0, pi/2) and omega_z in (0, pi), else :class:`InputError`."""
    return check_value(alpha0, _ACUTE, "alpha0"), check_value(omega_z, _FOLD, "omega_z")


def _in_plane(phi: np.ndarray) -> np.ndarray:
    """Unit vectors (cos phi, sin phi, 0), shape phi.shape + (3,)."""
    return np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=-1)


def _rotated(axis: np.ndarray, angle: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v rotated by ``angle`` about the unit ``axis`` (right-handed, eq:localRots); the
    arguments broadcast, vectors along the last axis."""
    c, s = np.cos(angle)[..., None], np.sin(angle)[..., None]
    return (v * c + np.cross(axis, v) * s
            + axis * np.sum(axis * v, axis=-1, keepdims=True) * (1 - c))


def _cell(delta: np.ndarray, alpha0: float, omega_z: float) -> dict[str, np.ndarray]:
    """The bottom-left cell's vectors at a uniform delta (shape S), in the flat frame of
    panel (1, 1), each S + (3,): ``p`` the fold of one period along the zig-zag (two sides
    of unit length), ``dp`` its derivative in delta, ``zeta`` the rotation vector of one
    period per unit change of delta between its columns, ``u1``, ``u2`` the folded
    straight sides of rows 1 and 2 (unit length)."""
    d = np.asarray(delta, dtype=float)
    k = np.tan(omega_z / 2) * np.cos(alpha0)
    g = -2 * np.arctan(k / np.cos(d))                       # eq:foldMiddle, vertex (1, 2)
    dg = (-2 * k * np.sin(d) / (np.cos(d) ** 2 + k * k))[..., None]
    t = _in_plane(alpha0 + d)                                # the straight crease at (1, 2)
    e_b = np.broadcast_to(-_in_plane(np.asarray(2 * alpha0)), t.shape)
    qe_b = _rotated(t, g, e_b)
    p = E1 + qe_b
    dp = np.cross(E3, qe_b) - _rotated(t, g, np.cross(E3, e_b)) + dg * np.cross(t, qe_b)
    zeta = _rotated(t, g, np.broadcast_to(E3, t.shape)) - E3 - dg * t
    u2 = _rotated(E1, np.full(d.shape, -omega_z), _in_plane(alpha0 - d))
    return {"p": p, "dp": dp, "zeta": zeta, "u1": t, "u2": u2}


def first_order_gains(alpha0: float, omega_z: float) -> tuple[float, float]:
    """(G0, P0): :func:`zigzag_gain` at delta = 0 and :func:`straight_gain` at
    Delta = delta = 0 in closed form (docs/closed_form.md s.3, s.4). With theta = omega_z / 2
    (Schenk and Guest's fold angle of the Miura-ori, docs/paper.md s.6) and
    sin(psi) = sin(theta) sin(alpha0) (the straight creases' slope out of the lattice's
    plane): G0 = tan(theta) cos(alpha0)^2 / (sin(alpha0) cos(psi)), P0 = tan(psi) / 2.
    ``alpha0`` in (0, pi/2), ``omega_z`` in (0, pi); else :class:`InputError`."""
    alpha0, omega_z = _checked(alpha0, omega_z)
    theta = omega_z / 2
    psi = np.arcsin(np.sin(theta) * np.sin(alpha0))
    return (float(np.tan(theta) * np.cos(alpha0) ** 2 / (np.sin(alpha0) * np.cos(psi))),
            float(np.tan(psi) / 2))


def _perturbation(delta: np.ndarray, alpha0: float) -> np.ndarray:
    """``delta`` as finite numbers with |delta| < alpha0 (every sector angle in (0, pi)),
    else :class:`InputError`."""
    delta = finite_array(delta, "delta")
    if np.any(np.abs(delta) >= alpha0):
        raise InputError(f"delta must stay within (-alpha0, alpha0) = (-{alpha0:g}, "
                         f"{alpha0:g}) so that every sector angle lies in (0, pi)")
    return delta


def _unit_normal(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The lattice's unit normal r_u x r_v from a step q along i and p along j."""
    n = np.cross(q, p)
    return n / np.linalg.norm(n, axis=-1, keepdims=True)


def zigzag_gain(delta: np.ndarray, alpha0: float, omega_z: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """(G, w), each shaped like ``delta``: the curvature along the zig-zag direction per
    unit d(delta)/dX, kx = G(delta) d(delta)/dX, and the folded length of one column per
    unit zig-zag side (docs/closed_form.md s.3). Canonical frame: ``alpha0`` in (0, pi/2),
    ``omega_z`` in (0, pi), ``delta`` finite numbers (radians) with |delta| < alpha0; else
    :class:`InputError`."""
    alpha0, omega_z = _checked(alpha0, omega_z)
    return finite_result(_zigzag_gain(_perturbation(delta, alpha0), alpha0, omega_z),
                         "zigzag_gain has no finite value here")


def _zigzag_gain(delta: np.ndarray, alpha0: float, omega_z: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`zigzag_gain` of checked arguments."""
    c = _cell(delta, alpha0, omega_z)
    p = c["p"]
    n = _unit_normal(c["u1"] + c["u2"], p)
    length = np.linalg.norm(p, axis=-1)
    bend = np.sum((np.cross(c["zeta"], p) + 2 * c["dp"]) * n, axis=-1)
    return bend / (2 * length), length / 2


def straight_gain(Delta: np.ndarray, delta: float, alpha0: float, omega_z: float
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(P, w), each shaped like ``Delta``: the curvature along the straight direction per
    unit d(Delta)/dY, ky = P(Delta) d(Delta)/dY, and the folded length of one period (two
    rows) per unit side of the odd row, at the angle perturbation ``delta``
    (docs/closed_form.md s.4). Canonical frame: ``alpha0`` in (0, pi/2), ``omega_z`` in
    (0, pi), |delta| < alpha0, ``Delta`` finite numbers > -1; else :class:`InputError`."""
    alpha0, omega_z = _checked(alpha0, omega_z)
    delta = _perturbation(delta, alpha0)
    if delta.ndim:
        raise InputError(f"delta must be one number, got shape {delta.shape}")
    delta = float(delta)
    D = finite_array(Delta, "Delta")
    if np.any(D <= -1):
        raise InputError("Delta must be > -1 (the even rows' sides stay positive)")
    return finite_result(_straight_gain(D, delta, alpha0, omega_z),
                         "straight_gain has no finite value here: Delta is too large")


def _straight_gain(D: np.ndarray, delta: float, alpha0: float, omega_z: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`straight_gain` of checked arguments."""
    c = _cell(np.full(D.shape, float(delta)), alpha0, omega_z)
    q = c["u1"] + (1 + D)[..., None] * c["u2"]
    length = np.linalg.norm(q, axis=-1)
    return np.sum(c["u2"] * _unit_normal(q, c["p"]), axis=-1) / length, length


@dataclass(frozen=True)
class Tilt:
    """A turning angle as a monotone function of a perturbation v (delta, or log(1 + Delta)),
    tabulated: ``values`` (k,) increasing, ``angles`` (k,) the integral of the gain from
    v = 0 (where the angle is 0)."""

    values: np.ndarray
    angles: np.ndarray

    @classmethod
    def of_gain(cls, values: np.ndarray, gains: np.ndarray) -> "Tilt":
        """The integral of ``gains`` (k,) over ``values`` (k,), 0 at the value 0 (a grid
        point), kept on the widest interval around 0 where the gain is positive."""
        zero = int(np.argmin(np.abs(values)))
        bad = np.flatnonzero(gains <= 0)
        if zero in bad:
            raise InfeasibleDesign("the alternating perturbation does not bend this Miura-ori "
                                   "at this fold (its gain is not positive): give omega in "
                                   "(0, pi) away from 0 and pi")
        lo = int(bad[bad < zero].max()) + 1 if np.any(bad < zero) else 0
        hi = int(bad[bad > zero].min()) if np.any(bad > zero) else len(values)
        v, gain = values[lo:hi], gains[lo:hi]
        angles = cumulative_trapezoid(gain, v, initial=0.0)
        return cls(values=v, angles=angles - angles[zero - lo])

    def value(self, angle: np.ndarray) -> np.ndarray:
        """The perturbation whose turning is ``angle`` (inside :attr:`angles`' range)."""
        return np.interp(angle, self.angles, self.values)

    def centred(self, turning: np.ndarray, what: str) -> np.ndarray:
        """The perturbation at each point of ``turning`` (a line's turning angles, from an
        unknown start): the start chosen so that the largest and the smallest perturbation
        are opposite. Raises :class:`InfeasibleDesign` (naming ``what``) when the turning's
        range exceeds what the table holds."""
        t_lo, t_hi = float(np.min(turning)), float(np.max(turning))
        a_lo, a_hi = float(self.angles[0]), float(self.angles[-1])
        if not np.isfinite(t_hi - t_lo) or t_hi - t_lo >= a_hi - a_lo:
            raise InfeasibleDesign(
                f"the {what} turns the folded lattice by {t_hi - t_lo:.4g} rad along its line, "
                f"but the alternating perturbation reaches at most {a_hi - a_lo:.4g} rad at this "
                "fold: give a smaller curvature or footprint, or a larger omega")
        if t_hi == t_lo:
            return self.value(np.asarray(turning) - t_hi)

        def imbalance(shift: float) -> float:
            return float(self.value(t_hi - shift) + self.value(t_lo - shift))

        shift = brentq(imbalance, t_hi - a_hi, t_lo - a_lo, xtol=1e-15)
        return self.value(np.asarray(turning) - shift)


def _symmetric(half: float) -> np.ndarray:
    """:data:`TABLE_POINTS` values from -half to half, the middle one exactly 0."""
    values = np.linspace(-half, half, TABLE_POINTS)
    values[TABLE_POINTS // 2] = 0.0
    return values


def zigzag_tilt(alpha0: float, omega_z: float, max_delta: float) -> Tilt:
    """The turning along the zig-zag direction as a function of delta in
    [-max_delta, max_delta] (the integral of :func:`zigzag_gain`)."""
    values = _symmetric(min(max_delta, alpha0 * (1 - 1e-9)))
    return Tilt.of_gain(values, _zigzag_gain(values, alpha0, omega_z)[0])


def straight_tilt(alpha0: float, omega_z: float, delta: float, max_ratio: float) -> Tilt:
    """The turning along the straight direction as a function of v = log(1 + Delta), the
    ratio of the even rows' sides to the odd rows' within [1 / max_ratio, max_ratio]: the
    integral of :func:`straight_gain` times d(Delta)/dv = 1 + Delta."""
    values = _symmetric(np.log(max_ratio))
    ratio = np.exp(values)
    return Tilt.of_gain(values, ratio * _straight_gain(ratio - 1, delta, alpha0, omega_z)[0])
