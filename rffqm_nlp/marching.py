"""The marching algorithm as CasADi graphs: crease pattern and folded states.

One panel cell (eq:marchingSector .. eq:getSides) is a small SX ``casadi.Function``; a row of
panels is its ``mapaccum`` along j, the pattern is the ``mapaccum`` of rows along i, so the
graph size does not grow with the pattern. The kinematics (eq:foldInitial .. eq:finalCalc)
is written with whole-matrix MX operations: every fold angle obeys
tan(gamma/2) = k tan(omega/2) with a pattern constant k, panel rotations are cumulative
quaternion products (a ``mapaccum`` over rows) and positions are cumulative sums of rotated
flat edge vectors. Vertex arrays are (N+1, M+1) matrices, vertex (i, j) at [i-1, j-1].
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import lru_cache

import casadi as ca
import numpy as np

from . import vertex as vx
from .backend import Scalar
from .boundary import BoundaryData
from .errors import InputError, MarchingError
from .pattern import Pattern, check_omega

#: A quaternion's 4 components (w, x, y, z), each a CasADi matrix (or a number).
Quaternion = Sequence[Scalar]

PI = np.pi
#: The second check fails when | |mu_abc| - 1 | is at most this.
MU_TOL = 1e-12


# --------------------------------------------------------------------------- pattern
@lru_cache(maxsize=None)
def panel_cell() -> ca.Function:
    """One panel (i, j): vertex triples of b, a, c and sides l_ab, l_ac -> vertex d, sides.

    Inputs ``x = (alpha, beta, sigma) of b, l_ab`` (the accumulator along a row) and
    ``u = (alpha, beta, sigma) of a, (alpha, beta, sigma) of c, l_ac``; outputs
    ``x_next = (alpha, beta, sigma) of d, l_cd`` and ``y = (l_bd, mu_abc, alpha_d)``.
    Roles follow docs/paper.md s.1 (eq:marchingSector, eq:marchingMV, eq:marchingSides).
    """
    x = ca.SX.sym("x", 4)
    u = ca.SX.sym("u", 7)
    alpha_a, beta_a, sigma_a = u[0], u[1], u[2]
    alpha_b, beta_b, sigma_b = PI - x[1], PI - x[0], x[2]
    alpha_c, beta_c, sigma_c = u[4], u[3], u[5]
    total = alpha_a + alpha_b + alpha_c
    alpha_d = 2 * PI - total
    mu = (vx.mu1(alpha_a, beta_a, sigma_a) * vx.mu2(alpha_b, beta_b, sigma_b)
          * vx.mu2(alpha_c, beta_c, sigma_c))
    beta_d, sigma_d = vx.design_d(alpha_d, mu)
    l_cd, l_bd = vx.panel_sides(alpha_a, alpha_b, alpha_c, x[3], u[6])
    x_next = ca.vertcat(PI - alpha_d, PI - beta_d, sigma_d, l_cd)
    return ca.Function("panel", [x, u], [x_next, ca.vertcat(l_bd, mu, alpha_d)],
                       ["x", "u"], ["x_next", "y"])


@lru_cache(maxsize=None)
def _row_step(M: int) -> ca.Function:
    """Row i of vertices (3 x M+1), its lengths lh (1 x M) and the left data -> row i+1."""
    along_row = panel_cell().mapaccum("row", M)
    V = ca.MX.sym("V", 3, M + 1)
    Lh = ca.MX.sym("Lh", 1, M)
    left = ca.MX.sym("left", 4)
    xs, ys = along_row(left, ca.vertcat(V[:, :M], V[:, 1:], Lh))
    return ca.Function("row_step", [V, Lh, left],
                       [ca.horzcat(left[:3], xs[:3, :]), ys[0, :], ca.horzcat(left[3], xs[3, :]),
                        ys[1, :], ys[2, :]])


@lru_cache(maxsize=None)
def pattern_function(N: int, M: int) -> ca.Function:
    """Boundary data -> crease pattern, as one CasADi Function.

    Inputs: ``left`` (3 x N+1), ``bottom`` (3 x M) (rows alpha, beta, sigma), ``l_left``
    (1 x N), ``l_bottom`` (1 x M). Outputs: ``alpha, beta, sigma`` (N+1 x M+1), ``lh``
    (N+1 x M), ``lv`` (N x M+1), ``mu`` and ``alpha_d`` (N x M), flat positions ``Xx, Xy``
    (N+1 x M+1).
    """
    left = ca.MX.sym("left", 3, N + 1)
    bottom = ca.MX.sym("bottom", 3, M)
    l_left = ca.MX.sym("l_left", 1, N)
    l_bottom = ca.MX.sym("l_bottom", 1, M)
    rows = _row_step(M).mapaccum("rows", N, 2)
    row1 = ca.horzcat(left[:, 0], bottom)
    V, Lh, Lv, mu, alpha_d = rows(row1, l_bottom, ca.vertcat(left[:, 1:], l_left))

    def stack(first, blocks, width):
        body = ca.reshape(blocks, width, N).T
        return body if first is None else ca.vertcat(first, body)

    alpha, beta, sigma = (stack(row1[k, :], V[k, :], M + 1) for k in range(3))
    lh = stack(l_bottom, Lh, M)
    lv = stack(None, Lv, M + 1)
    Xx, Xy = _flat_positions(alpha, beta, lh, lv)
    return ca.Function(
        "pattern", [left, bottom, l_left, l_bottom],
        [alpha, beta, sigma, lh, lv, stack(None, mu, M), stack(None, alpha_d, M), Xx, Xy],
        ["left", "bottom", "l_left", "l_bottom"],
        ["alpha", "beta", "sigma", "lh", "lv", "mu", "alpha_d", "Xx", "Xy"])


def edge_directions(alpha: ca.MX, beta: ca.MX) -> ca.MX:
    """Directions of the horizontal edges (N+1 x M+1; the last column is auxiliary).

    Accumulated sector angles (docs/paper.md s.4): along the left column the direction turns by
    alpha(i, 1) - beta(i+1, 1), along a row by pi - alpha - beta of each vertex.
    """
    first_col = ca.vertcat(0, ca.cumsum(alpha[:-1, 0] - beta[1:, 0], 0))
    turn = PI - alpha[:, 1:] - beta[:, 1:]
    return ca.repmat(first_col, 1, alpha.shape[1]) + ca.horzcat(
        ca.MX.zeros(alpha.shape[0], 1), ca.cumsum(turn, 1))


def _flat_positions(alpha, beta, lh, lv):
    """Flat vertex positions as cumulative sums of edge vectors (stable, docs/paper.md s.4)."""
    theta_h = edge_directions(alpha, beta)
    theta_v = theta_h[:-1, :] + alpha[:-1, :]
    bottom_x = ca.horzcat(0, ca.cumsum(lh[0, :] * ca.cos(theta_h[0, :-1]), 1))
    bottom_y = ca.horzcat(0, ca.cumsum(lh[0, :] * ca.sin(theta_h[0, :-1]), 1))
    Xx = ca.vertcat(bottom_x, ca.repmat(bottom_x, lv.shape[0], 1)
                    + ca.cumsum(lv * ca.cos(theta_v), 0))
    Xy = ca.vertcat(bottom_y, ca.repmat(bottom_y, lv.shape[0], 1)
                    + ca.cumsum(lv * ca.sin(theta_v), 0))
    return Xx, Xy


# --------------------------------------------------------------------------- kinematics
def _sign_products(signs, axis: int):
    """Cumulative products of +-1 entries along ``axis`` (exact: parity of a count)."""
    count = ca.cumsum((1 - signs) / 2, axis)
    return 1 - 2 * ca.fmod(count, 2)


def fold_multipliers(alpha: ca.MX, beta: ca.MX, sigma: ca.MX) -> tuple[ca.MX, ca.MX]:
    """Factors kh (N+1 x M+1), kv (N+1 x M+1) with tan(gamma/2) = k tan(omega/2).

    kh[i, j] belongs to gamma1 of vertex (i+1, j+1) (the horizontal edge to its right),
    kv[i, j] to gamma2 (the vertical edge above it): eq:foldInitial, eq:foldMiddle and
    eq:foldFinal with the half-angle forms of gamma2_bar and gamma1_bar.
    """
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
    the same rotation.
    """
    r = ca.sqrt(c * c * k_den * k_den + k * k * s * s)
    w, sh = c * k_den / r, sign * k * s / r
    return w, sh * ca.cos(theta), sh * ca.sin(theta), 0 * w


@lru_cache(maxsize=None)
def panel_quaternions_function(N: int, M: int) -> ca.Function:
    """Pattern and omega -> the 4 components (N x M) of every panel's rotation quaternion."""
    alpha, beta, sigma = (ca.MX.sym(n, N + 1, M + 1) for n in ("alpha", "beta", "sigma"))
    lh = ca.MX.sym("lh", N + 1, M)
    lv = ca.MX.sym("lv", N, M + 1)
    omega = ca.MX.sym("omega")
    _, quat = _fold_expr(alpha, beta, sigma, lh, lv, omega)
    return ca.Function("panel_quaternions", [alpha, beta, sigma, lh, lv, omega], quat)


def qmul(p: Quaternion, q: Quaternion) -> Quaternion:
    """Quaternion product p q, componentwise on (w, x, y, z) sequences of matrices."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw)


@lru_cache(maxsize=None)
def _qmul_step(width: int) -> ca.Function:
    P = ca.MX.sym("P", 4, width)
    Q = ca.MX.sym("Q", 4, width)
    prod = qmul([P[k, :] for k in range(4)], [Q[k, :] for k in range(4)])
    return ca.Function("qmul", [P, Q], [ca.vertcat(*prod)])


def _cumulative_qprod(first, steps, count: int, width: int):
    """Q_0 = first, Q_k = Q_{k-1} * steps_k: quaternion rows (4 x width) over ``count`` steps."""
    if count == 0:
        return first
    acc = _qmul_step(width).mapaccum("qprod", count)
    return ca.horzcat(first, acc(first, steps))


def rotate_planar(q, vx_, vy_):
    """Rotate in-plane vectors (vx, vy, 0) by unit quaternions q = (w, x, y, z), elementwise."""
    w, x, y, z = q
    return ((1 - 2 * (y * y + z * z)) * vx_ + 2 * (x * y - w * z) * vy_,
            2 * (x * y + w * z) * vx_ + (1 - 2 * (x * x + z * z)) * vy_,
            2 * (x * z - w * y) * vx_ + 2 * (y * z + w * x) * vy_)


@lru_cache(maxsize=None)
def fold_function(N: int, M: int) -> ca.Function:
    """Pattern and omega -> folded vertices, as one CasADi Function.

    Inputs: ``alpha, beta, sigma`` (N+1 x M+1), ``lh`` (N+1 x M), ``lv`` (N x M+1),
    ``omega``. Outputs: ``Yx, Yy, Yz`` (N+1 x M+1) with R^{11} = I, y^{11} = x^{11} = 0.
    """
    alpha, beta, sigma = (ca.MX.sym(n, N + 1, M + 1) for n in ("alpha", "beta", "sigma"))
    lh = ca.MX.sym("lh", N + 1, M)
    lv = ca.MX.sym("lv", N, M + 1)
    omega = ca.MX.sym("omega")
    (Yx, Yy, Yz), _ = _fold_expr(alpha, beta, sigma, lh, lv, omega)
    return ca.Function("fold", [alpha, beta, sigma, lh, lv, omega], [Yx, Yy, Yz],
                       ["alpha", "beta", "sigma", "lh", "lv", "omega"], ["Yx", "Yy", "Yz"])


@lru_cache(maxsize=None)
def folded_function(N: int, M: int) -> ca.Function:
    """Boundary data and omega -> folded vertices: :func:`pattern_function` then
    :func:`fold_function`, the differentiable map the inverse design optimises through.

    Inputs: ``left, bottom, l_left, l_bottom`` as in :func:`pattern_function`, ``omega``.
    Outputs: ``Yx, Yy, Yz`` (N+1 x M+1).
    """
    pattern = pattern_function(N, M)
    inputs = pattern.mx_in()
    alpha, beta, sigma, lh, lv, *_ = pattern.call(inputs)
    omega = ca.MX.sym("omega")
    Y, _ = _fold_expr(alpha, beta, sigma, lh, lv, omega)
    return ca.Function("folded", [*inputs, omega], list(Y),
                       [*pattern.name_in(), "omega"], ["Yx", "Yy", "Yz"])


@lru_cache(maxsize=None)
def marched_function(N: int, M: int) -> ca.Function:
    """Boundary data and omega -> the crease pattern and its folded state, as one CasADi
    Function: :func:`pattern_function`, then the kinematics of :func:`fold_function` and
    :func:`panel_quaternions_function` on the marched pattern (one evaluation where the
    three would march and fold twice).

    Inputs: ``left, bottom, l_left, l_bottom`` as in :func:`pattern_function`, ``omega``.
    Outputs: ``alpha, beta, sigma, lh, lv, mu, alpha_d`` as in :func:`pattern_function`,
    ``theta_h`` (:func:`edge_directions`, N+1 x M+1), the panel quaternions ``Qw, Qx, Qy,
    Qz`` (N x M) and the folded vertices ``Yx, Yy, Yz`` (N+1 x M+1).
    """
    pattern = pattern_function(N, M)
    inputs = pattern.mx_in()
    alpha, beta, sigma, lh, lv, mu, alpha_d, _, _ = pattern.call(inputs)
    omega = ca.MX.sym("omega")
    Y, quat = _fold_expr(alpha, beta, sigma, lh, lv, omega)
    return ca.Function(
        "marched", [*inputs, omega],
        [alpha, beta, sigma, lh, lv, mu, alpha_d, edge_directions(alpha, beta), *quat, *Y],
        [*pattern.name_in(), "omega"],
        ["alpha", "beta", "sigma", "lh", "lv", "mu", "alpha_d", "theta_h",
         "Qw", "Qx", "Qy", "Qz", "Yx", "Yy", "Yz"])


def crease_quaternions(alpha: ca.MX, beta: ca.MX, sigma: ca.MX, theta_h: ca.MX,
                       omega: Scalar) -> tuple[Quaternion, Quaternion]:
    """Rotation quaternions of the creases the kinematics march crosses (eq:defGrads).

    Returns (qv, qh): qv for the vertical creases of the bottom row, R_{t2}(-gamma2^{1j}),
    j = 2..M (4 components, 1 x M-1), and qh for the horizontal creases R_{t1}(gamma1^{ij}),
    i = 2..N, j = 1..M (4 components, N-1 x M).
    """
    N, M = alpha.shape[0] - 1, alpha.shape[1] - 1
    c, s = ca.cos(omega / 2), ca.sin(omega / 2)
    kh, kv = fold_multipliers(alpha, beta, sigma)
    theta_v = theta_h[:-1, :] + alpha[:-1, :]
    qv = crease_quaternion(theta_v[0, 1:M], kv[0, 1:M], c, s, sign=-1.0)
    qh = crease_quaternion(theta_h[1:N, :M], kh[1:N, :M], c, s)
    return qv, qh


def rotated_edges(quat: Quaternion, alpha: ca.MX, theta_h: ca.MX, lh: ca.MX,
                  lv: ca.MX) -> tuple[tuple[ca.MX, ...], tuple[ca.MX, ...]]:
    """Folded edge vectors: the bottom edges by their panel's rotation, the vertical edges by
    the panel on their right (the last column by the panel on its left).

    ``quat`` are the 4 components (N x M) of the panel rotations. Returns (bottom, vertical)
    as 3 components each, 1 x M and N x M+1.
    """
    M = lh.shape[1]
    theta_v = theta_h[:-1, :] + alpha[:-1, :]
    bottom = rotate_planar([comp[0, :] for comp in quat], lh[0, :] * ca.cos(theta_h[0, :M]),
                            lh[0, :] * ca.sin(theta_h[0, :M]))
    quat_v = [ca.horzcat(comp, comp[:, M - 1]) for comp in quat]
    vertical = rotate_planar(quat_v, lv * ca.cos(theta_v), lv * ca.sin(theta_v))
    return bottom, vertical


def _fold_expr(alpha, beta, sigma, lh, lv, omega):
    N, M = lv.shape[0], lh.shape[1]
    theta_h = edge_directions(alpha, beta)
    qv, qh = crease_quaternions(alpha, beta, sigma, theta_h, omega)
    # R^{1j} = R^{1(j-1)} R_{t2}(-gamma2^{1j}); R^{ij} = R^{(i-1)j} R_{t1}(gamma1^{ij}).
    q_row1 = _cumulative_qprod(ca.DM([1, 0, 0, 0]), ca.vertcat(*qv), M - 1, 1)
    steps = ca.vertcat(*(ca.reshape(comp.T, 1, M * (N - 1)) for comp in qh))
    Q = _cumulative_qprod(q_row1, steps, N - 1, M)
    quat = [ca.reshape(Q[k, :], M, N).T for k in range(4)]  # (N x M) per component
    bottom, vertical = rotated_edges(quat, alpha, theta_h, lh, lv)
    out = []
    for b, v in zip(bottom, vertical):
        row1 = ca.horzcat(0, ca.cumsum(b, 1))
        out.append(ca.vertcat(row1, ca.repmat(row1, N, 1) + ca.cumsum(v, 0)))
    return tuple(out), quat


# --------------------------------------------------------------------------- evaluation
def boundary_inputs(bd: BoundaryData) -> list[np.ndarray]:
    """The inputs of :func:`pattern_function` for boundary data ``bd``."""
    return [bd.left.T, bd.bottom.T, bd.l_left[None, :], bd.l_bottom[None, :]]


def locate_failure(alpha_d: np.ndarray, mu: np.ndarray, lh: np.ndarray,
                   lv: np.ndarray) -> tuple[str, tuple[int, int]] | None:
    """The first failing check in marching order, or None when the pattern is valid.

    Panels are visited row-major; a panel's inputs all come from earlier panels, so the
    first flagged panel is a genuine failure. NaN counts as a failure.
    """
    first = ~((alpha_d > 0) & (alpha_d < PI))
    second = ~(np.abs(np.abs(mu) - 1) > MU_TOL)
    final = ~((lv[:, 1:] > 0) & (lh[1:, :] > 0))
    bad = first | second | final
    if not bad.any():
        return None
    i, j = np.unravel_index(np.argmax(bad.ravel()), bad.shape)
    check = "first" if first[i, j] else "second" if second[i, j] else "final"
    return check, (int(i) + 1, int(j) + 1)


def march(bd: BoundaryData) -> Pattern:
    """March the crease pattern of ``bd`` with the CasADi graph.

    Raises :class:`MarchingError` naming the check and the first failing panel.
    """
    if not isinstance(bd, BoundaryData):
        raise InputError(f"march expects BoundaryData, got {type(bd).__name__}")
    out = evaluate(pattern_function(bd.N, bd.M), boundary_inputs(bd))
    alpha, beta, sigma, lh, lv, mu, alpha_d, Xx, Xy = out
    failure = locate_failure(alpha_d, mu, lh, lv)
    if failure is not None:
        check, (i, j) = failure
        detail = (f"alpha_d = {alpha_d[i - 1, j - 1]:.6g}, mu_abc = {mu[i - 1, j - 1]:.6g}, "
                  f"l_cd = {lv[i - 1, j]:.6g}, l_bd = {lh[i, j - 1]:.6g}")
        raise MarchingError(check, (i, j), detail)
    X = np.stack([Xx, Xy, np.zeros_like(Xx)], axis=-1)
    return Pattern(alpha=alpha, beta=beta, sigma=sigma, lh=lh, lv=lv, mu=mu, X=X)


def fold(pat: Pattern, omega: float | np.ndarray) -> np.ndarray:
    """Folded vertex positions: (N+1, M+1, 3) for scalar omega, (K, N+1, M+1, 3) for K values."""
    if not isinstance(pat, Pattern):
        raise InputError(f"fold expects a Pattern, got {type(pat).__name__}")
    om = check_omega(omega)
    ev = Evaluation(fold_function(pat.N, pat.M),
                    [pat.alpha, pat.beta, pat.sigma, pat.lh, pat.lv, 0.0])
    states = []
    for w in np.atleast_1d(om):
        ev.set(5, w)
        states.append(np.stack(ev.run(), axis=-1))
    return states[0] if om.ndim == 0 else np.stack(states)


def evaluate(f: ca.Function, args: list) -> list[np.ndarray]:
    """Evaluate ``f`` once on NumPy inputs; dense NumPy outputs (see :class:`Evaluation`)."""
    return Evaluation(f, args).run()


class Evaluation:
    """A CasADi Function evaluated on NumPy arrays in place, through its buffer.

    This skips the DM conversions of ``Function.call``, a large share of the time of a large
    march or fold, and lets one input be changed between runs.
    """

    def __init__(self, f: ca.Function, args: list):
        self._f = f
        self._buf, self._trigger = f.buffer()
        self._args = [np.ascontiguousarray(np.asarray(a, dtype=float).ravel(order="F"))
                      for a in args]
        for k, a in enumerate(self._args):
            self._buf.set_arg(k, memoryview(a))
        self._res = [np.empty(f.nnz_out(k)) for k in range(f.n_out())]
        for k, r in enumerate(self._res):
            self._buf.set_res(k, memoryview(r))
        # Outputs can be structurally sparse (e.g. y^{11} = 0): scatter the nonzeros.
        self._where = [None if f.sparsity_out(k).is_dense()
                       else tuple(np.asarray(i) for i in f.sparsity_out(k).get_triplet())
                       for k in range(f.n_out())]

    def set(self, k: int, value) -> None:
        """Overwrite input ``k`` in place (same size)."""
        self._args[k][:] = np.asarray(value, dtype=float).ravel(order="F")

    def run(self) -> list[np.ndarray]:
        """Evaluate; fresh dense output arrays in the Function's output shapes."""
        self._trigger()
        out = []
        for k, (r, where) in enumerate(zip(self._res, self._where)):
            if where is None:
                out.append(r.reshape(self._f.size_out(k), order="F").copy())
            else:
                dense = np.zeros(self._f.size_out(k))
                dense[where] = r
                out.append(dense)
        return out


def fold_angles(pat: Pattern, omega: float) -> tuple[np.ndarray, np.ndarray]:
    """Fold angle of every edge at ``omega``: gamma_h (N+1, M), gamma_v (N, M+1).

    Boundary edges (bottom and top rows of gamma_h, first and last columns of gamma_v) are
    not creases and get 0. gamma > 0 is a valley (eq:MVAngles).
    """
    om = float(check_omega(omega))
    kh, kv = (k.full() for k in _multiplier_function(pat.N, pat.M)(pat.alpha, pat.beta,
                                                                   pat.sigma))
    half = om / 2
    gh = 2 * np.arctan2(kh[:, :-1] * np.sin(half), np.cos(half))
    gv = 2 * np.arctan2(kv[:-1, :] * np.sin(half), np.cos(half))
    gh[[0, -1], :] = 0.0
    gv[:, [0, -1]] = 0.0
    return gh, gv


@lru_cache(maxsize=None)
def _multiplier_function(N: int, M: int) -> ca.Function:
    sym = [ca.MX.sym(n, N + 1, M + 1) for n in ("alpha", "beta", "sigma")]
    return ca.Function("multipliers", sym, list(fold_multipliers(*sym)))
