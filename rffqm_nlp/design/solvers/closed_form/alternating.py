"""The closed-form alternating perturbation: boundary data for prescribed curvatures kx(x),
ky(y) along the pattern's two directions (docs/closed_form.md).

The pattern has 2N x 2M panels and a coarse lattice of (N+1) x (M+1) points; x runs along
i (the lattice's first index, a target's u) over [0, Lx], y along j over [0, Ly], both
folded arc lengths. Along the zig-zag direction of the Miura-ori (i in the layout
"zigzag_i", j in "zigzag_j") the sector angles alternate by +-delta; along the straight
direction every second straight side is longer by the factor (1 + Delta). Each line's
curvature, integrated into a turning angle, gives its perturbation through the exact
one-cell relations of :mod:`.cell`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Union

import numpy as np

from ....errors import InfeasibleDesign, InputError, MarchingError, one_line
from ....files import Key, check_value, describe_value
from ....model import numpy_model
from ....model.backend import finite_array
from ....model.boundary import LAYOUTS, MAX_SIDE, BoundaryData, check_boundary
from .cell import straight_gain, straight_tilt, zigzag_gain, zigzag_tilt

#: A curvature along one direction: a number, a function of the arc length (taking and
#: returning NumPy arrays), or its values at the coarse lattice's points.
CurvatureField = Union[float, Callable[[np.ndarray], Any], np.ndarray]
#: The largest ratio of an even row's straight side to the odd row's (and its inverse).
MAX_RATIO = 20.0
#: Most secant rounds for the zig-zag creases' fold angle in the layout "zigzag_i", and
#: the change of the first delta at which they stop (radians).
FOLD_ROUNDS = 20
FOLD_TOL = 1e-13

_PANELS = Key("list", length=2, item=Key("whole", low=2, high=2 * MAX_SIDE, even=True),
              hint="(2N, 2M)")
_SIZE = Key("list", length=2, item=Key("number", low=0.0, low_open=True), hint="(Lx, Ly)")
_ACUTE = Key("number", low=0.0, high=np.pi / 2, low_open=True, high_open=True,
             hint="(radians)")
_OMEGA = Key("number", low=-np.pi, high=np.pi, low_open=True, high_open=True,
             hint="(radians, not 0)")
_RATIO = Key("number", low=1.0, high=1e6, low_open=True)


@dataclass(frozen=True)
class ClosedForm:
    """A closed-form design: ``boundary`` (BoundaryData of 2N x 2M panels), to be folded at
    ``omega``; ``delta`` the angle perturbation at the vertex lines across the zig-zag
    direction (2K+1,) and ``Delta`` the side perturbation of each period along the straight
    direction (L,), with (K, L) = (N, M) in "zigzag_i" and (M, N) in "zigzag_j"."""

    boundary: BoundaryData
    omega: float
    delta: np.ndarray
    Delta: np.ndarray


def closed_form_boundary(kx: CurvatureField, ky: CurvatureField, *,
                         panels: tuple[int, int], size: tuple[float, float],
                         alpha0: float = 1.1, layout: str = "zigzag_i", omega: float = 2.0,
                         steps: tuple[Any, Any] | None = None, min_angle: float = 0.0,
                         max_ratio: float = MAX_RATIO) -> ClosedForm:
    """The alternating perturbation of the Miura-ori (``alpha0``, ``layout``) of ``panels``
    = (2N, 2M) whose coarse lattice folded at ``omega`` has the normal curvature ``kx`` along
    x (i) and ``ky`` along y (j), against the lattice's normal r_u x r_v, in 1 / length.

    ``kx``: a number, a function of x in [0, Lx] or its N+1 values at the coarse points;
    ``ky`` likewise in y over [0, Ly], M+1 values. ``size`` = (Lx, Ly): the folded lattice's
    lengths along its lines; ``steps``: relative lengths of its N steps along x and M along
    y (default equal). ``min_angle``: every sector angle in [min_angle, pi - min_angle];
    ``max_ratio``: the straight sides of two rows differ at most by this factor.
    Raises :class:`InputError` for arguments outside these, :class:`InfeasibleDesign`
    (naming what to change) when the curvatures need a perturbation beyond these limits
    or the pattern does not march.
    """
    n2, m2 = check_value(panels, _PANELS, "panels")
    Lx, Ly = check_value(size, _SIZE, "size")
    alpha0 = check_value(alpha0, _ACUTE, "alpha0")
    layout = check_value(layout, Key("choice", choices=LAYOUTS), "layout")
    omega = check_value(omega, _OMEGA, "omega")
    min_angle = check_value(min_angle, Key("number", low=0.0, high=alpha0, high_open=True,
                                           hint="(below alpha0)"), "min_angle")
    max_ratio = check_value(max_ratio, _RATIO, "max_ratio")
    if omega == 0:
        raise InputError("omega must not be 0: the flat state has no curvature; give a fold "
                         "in (-pi, 0) or (0, pi)")
    N, M = n2 // 2, m2 // 2
    steps_x, steps_y = _steps(steps, (N, M), (Lx, Ly))
    k_x = _field(kx, "kx", np.concatenate([[0.0], np.cumsum(steps_x)]))
    k_y = _field(ky, "ky", np.concatenate([[0.0], np.cumsum(steps_y)]))
    if layout == "zigzag_j":
        sign = float(np.sign(omega))
        made = _canonical(sign * k_y, steps_y, sign * k_x, steps_x, alpha0, abs(omega),
                          alpha0 - min_angle, max_ratio)
        bd, delta, Delta = made.boundary(), made.delta, made.Delta
    else:
        bd, delta, Delta = _zigzag_i(k_x, steps_x, k_y, steps_y, alpha0, omega,
                                     alpha0 - min_angle, max_ratio)
    try:
        numpy_model.march(bd)
    except MarchingError as exc:
        raise InfeasibleDesign(f"the closed-form pattern does not march ({one_line(exc)}): "
                               "give smaller curvatures or more panels") from exc
    return ClosedForm(boundary=bd, omega=omega, delta=delta, Delta=Delta)


def zigzag_fold(omega: float, alpha0: float, delta: float) -> float:
    """The fold angle of the zig-zag creases of the layout "zigzag_i" folded at ``omega``
    whose first zig-zag vertex line has the angle perturbation ``delta``: the crease
    (1, 1) -> (2, 1), whose multiplier is cos(alpha0) / cos(delta) (eq:foldAngMult), so
    tan(omega_z / 2) = -tan(omega / 2) cos(delta) / cos(alpha0) (eq:foldParams).
    ``omega`` in (-pi, pi), ``alpha0`` in (0, pi/2), |delta| < alpha0; else
    :class:`InputError`."""
    omega = check_value(omega, _OMEGA, "omega")
    alpha0 = check_value(alpha0, _ACUTE, "alpha0")
    delta = check_value(delta, Key("number", low=-alpha0, high=alpha0, low_open=True,
                                   high_open=True), "delta")
    return _zigzag_fold(omega, alpha0, delta)


def _zigzag_fold(omega: float, alpha0: float, delta: float) -> float:
    """:func:`zigzag_fold` of checked arguments."""
    return float(-2 * np.arctan(np.tan(omega / 2) * np.cos(delta) / np.cos(alpha0)))


def _zigzag_i(k_x: np.ndarray, steps_x: np.ndarray, k_y: np.ndarray, steps_y: np.ndarray,
              alpha0: float, omega: float, max_delta: float, max_ratio: float
              ) -> tuple[BoundaryData, np.ndarray, np.ndarray]:
    """The design in the layout "zigzag_i": the canonical pattern, mirrored across its
    diagonal (:func:`transposed`), whose zig-zag fold depends on its first delta: a fixed
    point, found by the secant method on that delta."""
    def design(first: float) -> tuple[Canonical, float]:
        omega_z = _zigzag_fold(omega, alpha0, first)
        sign = float(np.sign(omega_z))
        made = _canonical(sign * k_x, steps_x, sign * k_y, steps_y, alpha0, abs(omega_z),
                          max_delta, max_ratio)
        return made, float(made.delta[0]) - first

    a, (made, fa) = 0.0, design(0.0)
    b = float(made.delta[0])
    for _ in range(FOLD_ROUNDS):
        made, fb = design(b)
        if abs(fb) <= FOLD_TOL or fb == fa:
            break
        a, b, fa = b, b - fb * (b - a) / (fb - fa), fb
    return transposed(made.boundary()), made.delta, made.Delta


@dataclass(frozen=True)
class Canonical:
    """The canonical design's boundary data as arrays (:class:`BoundaryData`'s fields) and
    its perturbations."""

    left: np.ndarray
    bottom: np.ndarray
    sides: np.ndarray
    widths: np.ndarray
    delta: np.ndarray
    Delta: np.ndarray

    def boundary(self) -> BoundaryData:
        """The boundary data (validated)."""
        return BoundaryData(self.left, self.bottom, self.sides, self.widths)


def _canonical(k_xi: np.ndarray, steps_xi: np.ndarray, k_eta: np.ndarray,
               steps_eta: np.ndarray, alpha0: float, omega_z: float, max_delta: float,
               max_ratio: float) -> Canonical:
    """The canonical ("zigzag_j", zig-zag creases folded by omega_z > 0) design for the
    curvature k_xi (K+1,) at the coarse points along the zig-zag direction j with steps
    (K,), and k_eta (L+1,) along the straight direction i with steps (L,): delta (2K+1,)
    at the vertex lines, Delta (L,) per period."""
    ends, middles = _turning(k_xi, steps_xi)
    line = np.empty(2 * len(steps_xi) + 1)
    line[0::2], line[1::2] = ends, middles
    delta = zigzag_tilt(alpha0, omega_z, max_delta).centred(line, "curvature along the "
                                                                  "zig-zag direction")
    widths = np.repeat(steps_xi / (2 * zigzag_gain(delta[1::2], alpha0, omega_z)[1]), 2)
    mean_delta = float(np.mean(delta))
    log_ratio = straight_tilt(alpha0, omega_z, mean_delta, max_ratio).centred(
        _turning(k_eta, steps_eta)[1], "curvature along the straight direction")
    Delta = np.expm1(log_ratio)
    odd = steps_eta / straight_gain(Delta, mean_delta, alpha0, omega_z)[1]
    sides = np.column_stack([odd, odd * (1 + Delta)]).ravel()
    s = np.where(np.arange(2 * len(steps_eta) + 1) % 2 == 0, 1.0, -1.0)
    theta = np.where(np.arange(len(delta)) % 2 == 0, alpha0, np.pi - alpha0)
    left = np.column_stack([alpha0 + s * delta[0], alpha0 - s * delta[0], -np.ones_like(s)])
    bottom = np.column_stack([theta[1:] + delta[1:], theta[1:] - delta[1:],
                              -np.ones(len(delta) - 1)])
    return Canonical(left=left, bottom=bottom, sides=sides, widths=widths, delta=delta,
                     Delta=Delta)


def _turning(k: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The turning angle from the line's start, at its coarse points (n+1,) and at the
    middles of its steps (n,), for the curvature ``k`` (n+1,) at the coarse points, linear
    in arc length between them; ``steps`` (n,) the arc lengths."""
    ends = np.concatenate([[0.0], np.cumsum(steps * (k[:-1] + k[1:]) / 2)])
    return ends, ends[:-1] + steps * (3 * k[:-1] + k[1:]) / 8


def transposed(bd: BoundaryData) -> BoundaryData:
    """The pattern mirrored across its diagonal: vertex (i, j) becomes (j, i), its a-role
    triple (alpha, beta, sigma) becomes (alpha, pi - beta, -sigma) (the upper-left panel
    becomes the lower-right one; docs/closed_form.md s.5), the left and bottom sides swap.
    ``bd`` must be :class:`BoundaryData`; else :class:`InputError`."""
    check_boundary(bd)

    def mirrored(tri: np.ndarray) -> np.ndarray:
        return np.column_stack([tri[:, 0], np.pi - tri[:, 1], -tri[:, 2]])

    return BoundaryData(mirrored(np.vstack([bd.left[:1], bd.bottom])), mirrored(bd.left[1:]),
                        bd.l_bottom, bd.l_left)


def _steps(steps: Any, counts: tuple[int, int], size: tuple[float, float]
           ) -> tuple[np.ndarray, np.ndarray]:
    """The coarse lattice's step lengths along x (N,) and y (M,): ``steps`` (relative,
    positive) scaled to ``size``, equal by default."""
    if steps is None:
        return tuple(np.full(n, length / n) for n, length in zip(counts, size))
    if not isinstance(steps, (tuple, list)) or len(steps) != 2:
        raise InputError(f"steps must be a pair of arrays of N and M positive lengths, got "
                         f"{describe_value(steps)}")
    out = []
    for name, value, n, length in zip(("steps[0]", "steps[1]"), steps, counts, size):
        arr = finite_array(value, name, shape=(n,), allowed=f"{n} positive relative lengths")
        if np.any(arr <= 0):
            raise InputError(f"{name} must hold {n} positive relative lengths")
        out.append(arr * (length / arr.sum()))
    return out[0], out[1]


def _field(k: CurvatureField, name: str, positions: np.ndarray) -> np.ndarray:
    """The curvature ``k`` at ``positions`` (n,): a number, a function of the arc length
    or n values; finite numbers, else :class:`InputError`."""
    n = len(positions)
    if callable(k):
        try:
            values = np.broadcast_to(np.asarray(k(positions.copy()), dtype=float), (n,))
        except (TypeError, ValueError, ArithmeticError) as exc:
            raise InputError(f"{name} must be a function of the arc length that takes and "
                             f"returns NumPy arrays of numbers: {one_line(exc)}") from exc
        return finite_array(values, name, shape=(n,), allowed="a function with finite values")
    if not isinstance(k, (list, tuple, np.ndarray)) or getattr(k, "ndim", 1) == 0:
        return np.full(n, check_value(k, Key("number"), name))
    return finite_array(k, name, shape=(n,), allowed=f"a number, a function or {n} values")
