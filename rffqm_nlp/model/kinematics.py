"""The folding kinematics as CasADi expressions: fold multipliers, crease and panel rotations,
folded vertex positions.

The kinematics (eq:foldInitial .. eq:finalCalc) is written with whole-matrix MX operations:
every fold angle obeys tan(gamma/2) = k tan(omega/2) with a pattern constant k
(:func:`fold_multipliers`), panel rotations are cumulative quaternion products (a
``mapaccum`` over rows) and positions are cumulative sums of rotated flat edge vectors
(:func:`folded_vertices`). Vertex arrays are (N+1, M+1) matrices, vertex (i, j) at
[i-1, j-1]. Every public function takes CasADi matrices (giving expressions) or finite
numbers (giving DMs, checked finite); :mod:`~rffqm_nlp.model.marching` builds its graphs
from them.
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from . import vertex as vx
from .backend import Scalar, finite_array, finite_result, is_casadi
from ..errors import InputError
from ..files import describe_value

#: A quaternion's 4 components (w, x, y, z), each a CasADi matrix (or a number).
Quaternion = Sequence[Scalar]

PI = np.pi

#: CasADi functions kept for each kind of graph, for the sizes used last: a sweep over
#: sizes would otherwise hold every size's graphs (:func:`cached_graphs`).
SIZE_CACHE = 8


# --------------------------------------------------------------------------- arguments
def _matrices(what: str, elementwise: bool = False, **args: Any) -> tuple[list, bool]:
    """The arguments of the graph builder ``what``, each a CasADi matrix or finite real
    numbers (a 2-D array becomes a DM, a 1-D one a column, a number a float), and whether
    all were numeric (the result is then a number to check). :class:`InputError` names an
    argument of another kind, and an SX unless the builder is ``elementwise`` (the matrix
    builders are made of MX operations)."""
    numeric = not is_casadi(*args.values())
    out = []
    for name, value in args.items():
        if isinstance(value, ca.SX) and not elementwise:
            raise InputError(f"{what}: {name} must be an MX matrix or finite real numbers (the "
                             "kinematics is built of MX operations), got an SX")
        if is_casadi(value):
            out.append(value)
            continue
        arr = finite_array(value, name, allowed="a CasADi matrix or finite real numbers "
                           "(a number or an array of at most 2 dimensions)")
        if arr.ndim > 2:
            raise InputError(f"{what}: {name} must be a matrix (at most 2 dimensions), got "
                             f"shape {arr.shape}")
        # beside a symbol a number stays a matrix (a DM indexes like one)
        out.append(ca.DM(arr) if arr.ndim or not numeric else float(arr))
    return out, numeric


def _shape(x: Any) -> tuple[int, int]:
    """The (rows, columns) of a CasADi matrix or a float (1, 1)."""
    return tuple(x.shape) if is_casadi(x) else (1, 1)


def _same_shape(what: str, names: str, values: list, least: tuple[int, int] = (1, 1)) -> tuple:
    """The common (rows, columns) of ``values`` (``names``, comma-separated), at least
    ``least``; :class:`InputError` otherwise."""
    shapes = [_shape(v) for v in values]
    if len(set(shapes)) != 1 or shapes[0][0] < least[0] or shapes[0][1] < least[1]:
        raise InputError(f"{what}: {names} must be matrices of one shape of at least "
                         f"{least[0]} x {least[1]}, got shapes {', '.join(map(str, shapes))}")
    return shapes[0]


def _shapes_are(what: str, whose: str, checks: list[tuple[str, Any, tuple[int, int]]]) -> None:
    """Each (name, value, shape) of ``checks``: the value has that shape (for ``whose``);
    :class:`InputError` otherwise."""
    for name, value, want in checks:
        if _shape(value) != want:
            raise InputError(f"{what}: {name} must be {want[0]} x {want[1]} for {whose}, "
                             f"got {_shape(value)}")



def _one_number(what: str, omega: Any) -> None:
    """``omega`` is one number (or 1 x 1); :class:`InputError` otherwise."""
    if _shape(omega) != (1, 1):
        raise InputError(f"{what}: omega must be a number, got shape {_shape(omega)}")


def _numeric_result(value: Any, what: str) -> Any:
    """A result computed from numbers (CasADi DMs), unless an entry is NaN or infinite."""
    parts = value if isinstance(value, (tuple, list)) else [value]
    finite_result(tuple(ca.DM(p).full() for p in _flat(parts)), what)
    return value


def _flat(parts) -> list:
    out = []
    for p in parts:
        out.extend(_flat(p) if isinstance(p, (tuple, list)) else [p])
    return out


def _quaternion(q: Any, name: str, what: str) -> list:
    """A quaternion argument: a sequence of 4 components (w, x, y, z), or a CasADi vector
    of 4 entries."""
    if is_casadi(q) and q.numel() == 4:
        return [q[i] for i in range(4)]
    if isinstance(q, (str, bytes)) or not isinstance(q, (tuple, list)) or len(q) != 4:
        raise InputError(f"{what}: {name} must be a quaternion, a sequence of 4 components "
                         f"(w, x, y, z), got {describe_value(q)}")
    return list(q)


def edge_directions(alpha: ca.MX, beta: ca.MX) -> ca.MX:
    """Directions of the horizontal edges (N+1 x M+1; the last column is auxiliary).

    Accumulated sector angles (docs/paper.md s.4): along the left column the direction turns by
    alpha(i, 1) - beta(i+1, 1), along a row by pi - alpha - beta of each vertex. ``alpha``,
    ``beta``: MX matrices or finite numbers of one shape of at least 2 x 2 (numbers give a
    DM).
    """
    (alpha, beta), numeric = _matrices("edge_directions", alpha=alpha, beta=beta)
    _same_shape("edge_directions", "alpha, beta", [alpha, beta], least=(2, 2))
    alpha, beta = ca.MX(alpha) if numeric else alpha, ca.MX(beta) if numeric else beta
    out = _edge_directions(alpha, beta)
    return ca.evalf(out) if numeric else out


def _edge_directions(alpha, beta):
    first_col = ca.vertcat(0, ca.cumsum(alpha[:-1, 0] - beta[1:, 0], 0))
    turn = PI - alpha[:, 1:] - beta[:, 1:]
    return ca.repmat(first_col, 1, alpha.shape[1]) + ca.horzcat(
        ca.MX.zeros(alpha.shape[0], 1), ca.cumsum(turn, 1))


# --------------------------------------------------------------------------- kinematics
def _sign_products(signs, axis: int):
    """Cumulative products of +-1 entries along ``axis`` (exact: parity of a count)."""
    count = ca.cumsum((1 - signs) / 2, axis)
    return 1 - 2 * ca.fmod(count, 2)


def fold_multipliers(alpha: ca.MX, beta: ca.MX, sigma: ca.MX) -> tuple[ca.MX, ca.MX]:
    """Factors kh (N+1 x M+1), kv (N+1 x M+1) with tan(gamma/2) = k tan(omega/2).

    kh[i, j] belongs to gamma1 of vertex (i+1, j+1) (the horizontal edge to its right),
    kv[i, j] to gamma2 (the vertical edge above it): eq:foldInitial, eq:foldMiddle and
    eq:foldFinal with the half-angle forms of gamma2_bar and gamma1_bar. ``alpha, beta,
    sigma``: MX matrices or finite numbers of one shape of at least 2 x 2. Numbers give
    DMs, and :class:`InputError` where a vertex has no finite multiplier.
    """
    (alpha, beta, sigma), numeric = _matrices("fold_multipliers", alpha=alpha, beta=beta,
                                              sigma=sigma)
    _same_shape("fold_multipliers", "alpha, beta, sigma", [alpha, beta, sigma], least=(2, 2))
    if numeric:
        alpha, beta, sigma = (ca.MX(x) for x in (alpha, beta, sigma))
        return _numeric_result(tuple(ca.evalf(x) for x in _fold_multipliers(alpha, beta, sigma)),
                               "fold_multipliers: a vertex has sigma outside MV(alpha, "
                               "beta), where its multiplier is 0 or infinite")
    return _fold_multipliers(alpha, beta, sigma)


def _fold_multipliers(alpha, beta, sigma):
    m2 = vx.mu2(alpha, beta, sigma)
    kh0 = ca.horzcat(1, _sign_products(-sigma[0, 1:], 1))
    kv0 = -kh0 / m2[0, :]
    kv = ca.repmat(kv0, alpha.shape[0], 1) * ca.vertcat(
        ca.MX.ones(1, alpha.shape[1]), _sign_products(sigma[1:, :], 0))
    kh = ca.vertcat(kh0, -kv[1:, :] * m2[1:, :])
    return kh, kv


def crease_quaternion(theta: Scalar, k: Scalar, c: Scalar, s: Scalar, sign: float = 1.0,
                      k_den: Scalar = 1.0) -> Quaternion:
    """Unit quaternion of R_t(sign * gamma), t = (cos theta, sin theta, 0),
    tan(gamma/2) = (k / k_den) s / c.

    With the multiplier given as a ratio (``k_den``) the quaternion stays smooth where k_den
    passes 0 (gamma through pi); it is then sign(k_den) times the quaternion of k / k_den,
    the same rotation. Arguments: CasADi matrices or finite numbers of one shape (or
    numbers); numbers give DMs.
    """
    (theta, k, c, s, sign, k_den), numeric = _matrices(
        "crease_quaternion", elementwise=True, theta=theta, k=k, c=c, s=s, sign=sign, k_den=k_den)
    _broadcast("crease_quaternion", dict(theta=theta, k=k, c=c, s=s, sign=sign, k_den=k_den))
    out = _crease_quaternion(theta, k, c, s, sign, k_den)
    if numeric:
        out = tuple(ca.DM(q) for q in out)
        return _numeric_result(out, "crease_quaternion: c k_den and k s vanish together, "
                                    "where the rotation is undefined")
    return out


def _broadcast(what: str, args: dict) -> None:
    """CasADi's elementwise broadcasting: every argument 1 x 1 or of one shape."""
    shapes = {name: _shape(v) for name, v in args.items()}
    big = {s for s in shapes.values() if s != (1, 1)}
    if len(big) > 1:
        raise InputError(f"{what}: the arguments must be numbers or matrices of one shape, "
                         f"got shapes {', '.join(f'{n} {s}' for n, s in shapes.items())}")


def _crease_quaternion(theta, k, c, s, sign=1.0, k_den=1.0):
    r = ca.sqrt(c * c * k_den * k_den + k * k * s * s)
    w, sh = c * k_den / r, sign * k * s / r
    return w, sh * ca.cos(theta), sh * ca.sin(theta), 0 * w


def qmul(p: Quaternion, q: Quaternion) -> Quaternion:
    """Quaternion product p q, componentwise on (w, x, y, z) sequences of matrices (CasADi
    matrices or finite numbers of one shape; numbers give DMs)."""
    p, q = _quaternion(p, "p", "qmul"), _quaternion(q, "q", "qmul")
    parts, numeric = _matrices("qmul", True, **{f"p[{i}]": x for i, x in enumerate(p)},
                               **{f"q[{i}]": x for i, x in enumerate(q)})
    _broadcast("qmul", {f"component {i}": x for i, x in enumerate(parts)})
    out = _qmul(parts[:4], parts[4:])
    return tuple(ca.DM(x) for x in out) if numeric else out


def _qmul(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


@lru_cache(maxsize=SIZE_CACHE)
def _qmul_step(width: int) -> ca.Function:
    P = ca.MX.sym("P", 4, width)
    Q = ca.MX.sym("Q", 4, width)
    prod = _qmul([P[k, :] for k in range(4)], [Q[k, :] for k in range(4)])
    return ca.Function("qmul", [P, Q], [ca.vertcat(*prod)])


def _cumulative_qprod(first, steps, count: int, width: int):
    """Q_0 = first, Q_k = Q_{k-1} * steps_k: quaternion rows (4 x width) over ``count`` steps."""
    if count == 0:
        return first
    acc = _qmul_step(width).mapaccum("qprod", count)
    return ca.horzcat(first, acc(first, steps))


def rotate_planar(q, vx_, vy_):
    """Rotate in-plane vectors (vx, vy, 0) by unit quaternions q = (w, x, y, z), elementwise
    (CasADi matrices or finite numbers of one shape; numbers give DMs)."""
    q = _quaternion(q, "q", "rotate_planar")
    parts, numeric = _matrices("rotate_planar", True,
                               **{f"q[{i}]": x for i, x in enumerate(q)},
                               vx=vx_, vy=vy_)
    _broadcast("rotate_planar", {f"argument {i}": x for i, x in enumerate(parts)})
    out = _rotate_planar(parts[:4], parts[4], parts[5])
    return tuple(ca.DM(x) for x in out) if numeric else out


def _rotate_planar(q, vx_, vy_):
    w, x, y, z = q
    return ((1 - 2 * (y * y + z * z)) * vx_ + 2 * (x * y - w * z) * vy_,
            2 * (x * y + w * z) * vx_ + (1 - 2 * (x * x + z * z)) * vy_,
            2 * (x * z - w * y) * vx_ + 2 * (y * z + w * x) * vy_)


def crease_quaternions(alpha: ca.MX, beta: ca.MX, sigma: ca.MX, theta_h: ca.MX,
                       omega: Scalar) -> tuple[Quaternion, Quaternion]:
    """Rotation quaternions of the creases the kinematics march crosses (eq:defGrads).

    Returns (qv, qh): qv for the vertical creases of the bottom row, R_{t2}(-gamma2^{1j}),
    j = 2..M (4 components, 1 x M-1), and qh for the horizontal creases R_{t1}(gamma1^{ij}),
    i = 2..N, j = 1..M (4 components, N-1 x M). The matrices are (N+1 x M+1), N, M >= 1,
    ``omega`` a number or 1 x 1; numbers give DMs.
    """
    (alpha, beta, sigma, theta_h, omega), numeric = _matrices(
        "crease_quaternions", alpha=alpha, beta=beta, sigma=sigma, theta_h=theta_h,
        omega=omega)
    _same_shape("crease_quaternions", "alpha, beta, sigma, theta_h",
                [alpha, beta, sigma, theta_h], least=(2, 2))
    _one_number("crease_quaternions", omega)
    if numeric:
        alpha, beta, sigma, theta_h = (ca.MX(x) for x in (alpha, beta, sigma, theta_h))
        qv, qh = _crease_quaternions(alpha, beta, sigma, theta_h, omega)
        out = (tuple(ca.evalf(x) for x in qv), tuple(ca.evalf(x) for x in qh))
        return _numeric_result(out, "crease_quaternions: a vertex has sigma outside "
                                    "MV(alpha, beta), where its multiplier is 0 or infinite")
    return _crease_quaternions(alpha, beta, sigma, theta_h, omega)


def _crease_quaternions(alpha, beta, sigma, theta_h, omega):
    N, M = alpha.shape[0] - 1, alpha.shape[1] - 1
    c, s = ca.cos(omega / 2), ca.sin(omega / 2)
    kh, kv = _fold_multipliers(alpha, beta, sigma)
    theta_v = theta_h[:-1, :] + alpha[:-1, :]
    qv = _crease_quaternion(theta_v[0, 1:M], kv[0, 1:M], c, s, sign=-1.0)
    qh = _crease_quaternion(theta_h[1:N, :M], kh[1:N, :M], c, s)
    return qv, qh


def rotated_edges(quat: Quaternion, alpha: ca.MX, theta_h: ca.MX, lh: ca.MX,
                  lv: ca.MX) -> tuple[tuple[ca.MX, ...], tuple[ca.MX, ...]]:
    """Folded edge vectors: the bottom edges by their panel's rotation, the vertical edges by
    the panel on their right (the last column by the panel on its left).

    ``quat`` are the 4 components (N x M) of the panel rotations. Returns (bottom, vertical)
    as 3 components each, 1 x M and N x M+1. Numbers give DMs.
    """
    quat = _quaternion(quat, "quat", "rotated_edges")
    parts, numeric = _matrices("rotated_edges", **{f"quat[{i}]": q for i, q in enumerate(quat)},
                               alpha=alpha, theta_h=theta_h, lh=lh, lv=lv)
    N, M = _same_shape("rotated_edges", "quat's components", parts[:4])
    _shapes_are("rotated_edges", f"quat's {N} x {M} panels",
                [("alpha", parts[4], (N + 1, M + 1)), ("theta_h", parts[5], (N + 1, M + 1)),
                 ("lh", parts[6], (N + 1, M)), ("lv", parts[7], (N, M + 1))])
    out = _rotated_edges(parts[:4], *parts[4:])
    if numeric:
        return _numeric_result(tuple(tuple(ca.DM(x) for x in part) for part in out),
                               "rotated_edges: the rotated edges are not finite")
    return out


def _rotated_edges(quat, alpha, theta_h, lh, lv):
    M = lh.shape[1]
    theta_v = theta_h[:-1, :] + alpha[:-1, :]
    bottom = _rotate_planar([comp[0, :] for comp in quat], lh[0, :] * ca.cos(theta_h[0, :M]),
                             lh[0, :] * ca.sin(theta_h[0, :M]))
    quat_v = [ca.horzcat(comp, comp[:, M - 1]) for comp in quat]
    vertical = _rotate_planar(quat_v, lv * ca.cos(theta_v), lv * ca.sin(theta_v))
    return bottom, vertical


def _fold_expr(alpha, beta, sigma, lh, lv, omega):
    """:func:`folded_vertices` on CasADi MX matrices of the right shapes (unchecked)."""
    N, M = lv.shape[0], lh.shape[1]
    theta_h = _edge_directions(alpha, beta)
    qv, qh = _crease_quaternions(alpha, beta, sigma, theta_h, omega)
    # R^{1j} = R^{1(j-1)} R_{t2}(-gamma2^{1j}); R^{ij} = R^{(i-1)j} R_{t1}(gamma1^{ij}).
    q_row1 = _cumulative_qprod(ca.DM([1, 0, 0, 0]), ca.vertcat(*qv), M - 1, 1)
    steps = ca.vertcat(*(ca.reshape(comp.T, 1, M * (N - 1)) for comp in qh))
    Q = _cumulative_qprod(q_row1, steps, N - 1, M)
    quat = [ca.reshape(Q[k, :], M, N).T for k in range(4)]  # (N x M) per component
    bottom, vertical = _rotated_edges(quat, alpha, theta_h, lh, lv)
    out = []
    for b, v in zip(bottom, vertical):
        row1 = ca.horzcat(0, ca.cumsum(b, 1))
        out.append(ca.vertcat(row1, ca.repmat(row1, N, 1) + ca.cumsum(v, 0)))
    return tuple(out), quat


def folded_vertices(alpha: ca.MX, beta: ca.MX, sigma: ca.MX, lh: ca.MX, lv: ca.MX,
                    omega: Scalar) -> tuple[tuple[ca.MX, ...], tuple[ca.MX, ...]]:
    """Folded vertex positions and panel rotations of a pattern at ``omega`` (eq:defGrads
    .. eq:finalCalc).

    Returns ((Yx, Yy, Yz), (Qw, Qx, Qy, Qz)): the positions (N+1 x M+1 each) with
    R^{11} = I and y^{11} = x^{11} = 0, and the 4 components (N x M) of every panel's
    rotation quaternion. ``alpha, beta, sigma`` are (N+1 x M+1), ``lh`` (N+1 x M), ``lv``
    (N x M+1), N, M >= 1, ``omega`` a number or 1 x 1: MX matrices or numbers (numbers give
    DMs; SX is refused).
    """
    (alpha, beta, sigma, lh, lv, omega), numeric = _matrices(
        "folded_vertices", alpha=alpha, beta=beta, sigma=sigma, lh=lh, lv=lv, omega=omega)
    rows, cols = _same_shape("folded_vertices", "alpha, beta, sigma", [alpha, beta, sigma],
                             least=(2, 2))
    _shapes_are("folded_vertices", f"alpha's {rows} x {cols} vertices",
                [("lh", lh, (rows, cols - 1)), ("lv", lv, (rows - 1, cols))])
    _one_number("folded_vertices", omega)
    if numeric:
        alpha, beta, sigma, lh, lv = (ca.MX(x) for x in (alpha, beta, sigma, lh, lv))
        Y, quat = _fold_expr(alpha, beta, sigma, lh, lv, omega)
        out = (tuple(ca.evalf(x) for x in Y), tuple(ca.evalf(x) for x in quat))
        return _numeric_result(out, "folded_vertices: a vertex has sigma outside "
                                    "MV(alpha, beta), where its multiplier is 0 or infinite")
    return _fold_expr(alpha, beta, sigma, lh, lv, omega)


def cached_graphs() -> int:
    """How many size-keyed CasADi functions this module holds now (at most
    :data:`SIZE_CACHE`)."""
    return _qmul_step.cache_info().currsize
