"""The marching algorithm as CasADi graphs: crease pattern and folded states.

One panel cell (eq:marchingSector .. eq:getSides) is a small SX ``casadi.Function``; a row of
panels is its ``mapaccum`` along j, the pattern is the ``mapaccum`` of rows along i, so the
graph size does not grow with the pattern. The folded states are the kinematics of
:mod:`~rffqm_nlp.model.kinematics` (eq:foldInitial .. eq:finalCalc) on the pattern. Each
graph is built once per size and kept for the last :data:`SIZE_CACHE` sizes; :func:`march`
and :func:`fold` evaluate them on NumPy arrays (:class:`Evaluation`). Vertex arrays are
(N+1, M+1) matrices, vertex (i, j) at [i-1, j-1]. The kinematics' public names are
re-exported here (``rq.marching.qmul``, ...).
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any

import casadi as ca
import numpy as np

from . import kinematics
from . import vertex as vx
from .backend import finite_array, finite_result
from .boundary import BoundaryData, check_boundary, check_size
from ..errors import InputError, MarchingError
from ..files import Key, check_value, describe_value
from .kinematics import (PI, SIZE_CACHE, Quaternion, crease_quaternion, crease_quaternions,
                         edge_directions, fold_multipliers, folded_vertices, qmul,
                         rotate_planar, rotated_edges)
from .pattern import (Pattern, check_fold_angle, check_fold_memory, check_folded,
                      check_march_memory, check_omega, check_pattern)

__all__ = ["MU_TOL", "PI", "SIZE_CACHE", "Evaluation", "Quaternion", "boundary_inputs",
           "cached_graphs", "crease_quaternion", "crease_quaternions", "edge_directions",
           "evaluate", "fold", "fold_angles", "fold_function", "fold_multipliers",
           "folded_function", "folded_vertices", "locate_failure", "march", "marched_function",
           "panel_cell", "panel_quaternions_function", "pattern_function", "qmul",
           "rotate_planar", "rotated_edges"]

#: The second check fails when | |mu_abc| - 1 | is at most this.
MU_TOL = 1e-12


# --------------------------------------------------------------------------- pattern
@lru_cache(maxsize=1)
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


@lru_cache(maxsize=SIZE_CACHE)
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


def pattern_function(N: int, M: int) -> ca.Function:
    """Boundary data -> crease pattern, as one CasADi Function (built once per size).

    Inputs: ``left`` (3 x N+1), ``bottom`` (3 x M) (rows alpha, beta, sigma), ``l_left``
    (1 x N), ``l_bottom`` (1 x M). Outputs: ``alpha, beta, sigma`` (N+1 x M+1), ``lh``
    (N+1 x M), ``lv`` (N x M+1), ``mu`` and ``alpha_d`` (N x M), flat positions ``Xx, Xy``
    (N+1 x M+1). N and M are whole numbers in [1, MAX_SIDE] (:func:`check_size`).
    """
    return _pattern_function(*check_size(N, M))


@lru_cache(maxsize=SIZE_CACHE)
def _pattern_function(N: int, M: int) -> ca.Function:
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




# --------------------------------------------------------------------------- folding
def panel_quaternions_function(N: int, M: int) -> ca.Function:
    """Pattern and omega -> the 4 components (N x M) of every panel's rotation quaternion."""
    return _panel_quaternions_function(*check_size(N, M))


@lru_cache(maxsize=SIZE_CACHE)
def _panel_quaternions_function(N: int, M: int) -> ca.Function:
    alpha, beta, sigma = (ca.MX.sym(n, N + 1, M + 1) for n in ("alpha", "beta", "sigma"))
    lh = ca.MX.sym("lh", N + 1, M)
    lv = ca.MX.sym("lv", N, M + 1)
    omega = ca.MX.sym("omega")
    _, quat = folded_vertices(alpha, beta, sigma, lh, lv, omega)
    return ca.Function("panel_quaternions", [alpha, beta, sigma, lh, lv, omega], quat)


def fold_function(N: int, M: int) -> ca.Function:
    """Pattern and omega -> folded vertices, as one CasADi Function.

    Inputs: ``alpha, beta, sigma`` (N+1 x M+1), ``lh`` (N+1 x M), ``lv`` (N x M+1),
    ``omega``. Outputs: ``Yx, Yy, Yz`` (N+1 x M+1) with R^{11} = I, y^{11} = x^{11} = 0.
    """
    return _fold_function(*check_size(N, M))


@lru_cache(maxsize=SIZE_CACHE)
def _fold_function(N: int, M: int) -> ca.Function:
    alpha, beta, sigma = (ca.MX.sym(n, N + 1, M + 1) for n in ("alpha", "beta", "sigma"))
    lh = ca.MX.sym("lh", N + 1, M)
    lv = ca.MX.sym("lv", N, M + 1)
    omega = ca.MX.sym("omega")
    (Yx, Yy, Yz), _ = folded_vertices(alpha, beta, sigma, lh, lv, omega)
    return ca.Function("fold", [alpha, beta, sigma, lh, lv, omega], [Yx, Yy, Yz],
                       ["alpha", "beta", "sigma", "lh", "lv", "omega"], ["Yx", "Yy", "Yz"])


def folded_function(N: int, M: int) -> ca.Function:
    """Boundary data and omega -> folded vertices: :func:`pattern_function` then
    :func:`fold_function`, the differentiable map the inverse design optimises through.

    Inputs: ``left, bottom, l_left, l_bottom`` as in :func:`pattern_function`, ``omega``.
    Outputs: ``Yx, Yy, Yz`` (N+1 x M+1).
    """
    return _folded_function(*check_size(N, M))


@lru_cache(maxsize=SIZE_CACHE)
def _folded_function(N: int, M: int) -> ca.Function:
    pattern = _pattern_function(N, M)
    inputs = pattern.mx_in()
    alpha, beta, sigma, lh, lv, *_ = pattern.call(inputs)
    omega = ca.MX.sym("omega")
    Y, _ = folded_vertices(alpha, beta, sigma, lh, lv, omega)
    return ca.Function("folded", [*inputs, omega], list(Y),
                       [*pattern.name_in(), "omega"], ["Yx", "Yy", "Yz"])


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
    return _marched_function(*check_size(N, M))


@lru_cache(maxsize=SIZE_CACHE)
def _marched_function(N: int, M: int) -> ca.Function:
    pattern = _pattern_function(N, M)
    inputs = pattern.mx_in()
    alpha, beta, sigma, lh, lv, mu, alpha_d, _, _ = pattern.call(inputs)
    omega = ca.MX.sym("omega")
    Y, quat = folded_vertices(alpha, beta, sigma, lh, lv, omega)
    return ca.Function(
        "marched", [*inputs, omega],
        [alpha, beta, sigma, lh, lv, mu, alpha_d, edge_directions(alpha, beta), *quat, *Y],
        [*pattern.name_in(), "omega"],
        ["alpha", "beta", "sigma", "lh", "lv", "mu", "alpha_d", "theta_h",
         "Qw", "Qx", "Qy", "Qz", "Yx", "Yy", "Yz"])


# --------------------------------------------------------------------------- evaluation
def boundary_inputs(bd: BoundaryData) -> list[np.ndarray]:
    """The inputs of :func:`pattern_function` for boundary data ``bd``."""
    check_boundary(bd)
    return [bd.left.T, bd.bottom.T, bd.l_left[None, :], bd.l_bottom[None, :]]


def locate_failure(alpha_d: np.ndarray, mu: np.ndarray, lh: np.ndarray,
                   lv: np.ndarray) -> tuple[str, tuple[int, int]] | None:
    """The first failing check in marching order, or None when the pattern is valid.

    Panels are visited row-major; a panel's inputs all come from earlier panels, so the
    first flagged panel is a genuine failure. NaN counts as a failure. ``alpha_d`` and
    ``mu`` are (N, M), ``lh`` (N+1, M), ``lv`` (N, M+1) arrays of numbers (NaN allowed).
    """
    alpha_d = finite_array(alpha_d, "alpha_d", ndim=2, finite=False,
                           allowed="an (N, M) array of numbers")
    N, M = alpha_d.shape
    mu = finite_array(mu, "mu", shape=(N, M), finite=False,
                      allowed=f"an ({N}, {M}) array of numbers like alpha_d")
    lh = finite_array(lh, "lh", shape=(N + 1, M), finite=False,
                      allowed=f"an ({N + 1}, {M}) array of numbers (N+1, M)")
    lv = finite_array(lv, "lv", shape=(N, M + 1), finite=False,
                      allowed=f"an ({N}, {M + 1}) array of numbers (N, M+1)")
    if N < 1 or M < 1:
        raise InputError(f"alpha_d must have at least one panel, got shape {(N, M)}")
    return _locate_failure(alpha_d, mu, lh, lv)


def march(bd: BoundaryData) -> Pattern:
    """March the crease pattern of ``bd`` with the CasADi graph.

    Raises :class:`MarchingError` naming the check and the first failing panel;
    :class:`InputError` when ``bd`` is not :class:`BoundaryData`, when the march needs more
    memory than this machine has left, and when the flat positions overflow (sides near
    the largest float).
    """
    check_boundary(bd)
    check_march_memory(bd.N, bd.M)
    out = Evaluation._made(_pattern_function(bd.N, bd.M), boundary_inputs(bd)).run()
    alpha, beta, sigma, lh, lv, mu, alpha_d, Xx, Xy = out
    failure = _locate_failure(alpha_d, mu, lh, lv)
    if failure is not None:
        check, (i, j) = failure
        detail = (f"alpha_d = {alpha_d[i - 1, j - 1]:.6g}, mu_abc = {mu[i - 1, j - 1]:.6g}, "
                  f"l_cd = {lv[i - 1, j]:.6g}, l_bd = {lh[i, j - 1]:.6g}")
        raise MarchingError(check, (i, j), detail)
    X = np.stack([Xx, Xy, np.zeros_like(Xx)], axis=-1)
    finite_result(X, "the flat positions of the pattern overflow (its side lengths are too "
                     "large for floating point); scale the boundary lengths down")
    return Pattern._made(alpha=alpha, beta=beta, sigma=sigma, lh=lh, lv=lv, mu=mu, X=X)


def fold(pat: Pattern, omega: float | np.ndarray) -> np.ndarray:
    """Folded vertex positions: (N+1, M+1, 3) for scalar omega, (K, N+1, M+1, 3) for K values.

    Raises :class:`InputError` when ``pat`` is not a :class:`Pattern`, for an invalid
    omega (:func:`~rffqm_nlp.model.pattern.check_omega`), when the states need more memory than
    this machine has left, and when the pattern has no finite folded state (a vertex
    outside MV(alpha, beta): a pattern that was not marched).
    """
    check_pattern(pat, "pat")
    om = check_omega(omega)
    check_fold_memory(pat.N, pat.M, om.size)
    ev = Evaluation._made(_fold_function(pat.N, pat.M),
                          [pat.alpha, pat.beta, pat.sigma, pat.lh, pat.lv, 0.0])
    states = []
    for w in np.atleast_1d(om):
        ev._args[5][0] = w
        states.append(check_folded(np.stack(ev.run(), axis=-1)))
    return states[0] if om.ndim == 0 else np.stack(states)


def evaluate(f: ca.Function, args: list) -> list[np.ndarray]:
    """Evaluate ``f`` once on NumPy inputs; dense NumPy outputs (see :class:`Evaluation`).
    The outputs are what ``f`` computes: NaN in a march's outputs marks a failed panel
    (:func:`locate_failure`)."""
    return Evaluation(f, args).run()


def _locate_failure(alpha_d, mu, lh, lv):
    """:func:`locate_failure` on arrays of the right shapes (from a march)."""
    first = ~((alpha_d > 0) & (alpha_d < PI))
    second = ~(np.abs(np.abs(mu) - 1) > MU_TOL)
    final = ~((lv[:, 1:] > 0) & (lh[1:, :] > 0))
    bad = first | second | final
    if not bad.any():
        return None
    i, j = np.unravel_index(np.argmax(bad.ravel()), bad.shape)
    check = "first" if first[i, j] else "second" if second[i, j] else "final"
    return check, (int(i) + 1, int(j) + 1)


class Evaluation:
    """A CasADi Function evaluated on NumPy arrays in place, through its buffer.

    This skips the DM conversions of ``Function.call``, a large share of the time of a large
    march or fold, and lets one input be changed between runs. ``f`` is a CasADi Function,
    ``args`` one array of real numbers per input with exactly as many entries as the input
    has nonzeros (any shape; NaN and infinity pass through to ``f``); anything else raises
    :class:`InputError` before the buffer is touched.
    """

    def __init__(self, f: ca.Function, args: list):
        if not isinstance(f, ca.Function):
            raise InputError(f"f must be a CasADi Function, got {describe_value(f)}")
        if isinstance(args, (str, bytes)) or not isinstance(args, (list, tuple)) \
                or len(args) != f.n_in():
            raise InputError(f"args must be a list of {f.n_in()} arrays (one per input of "
                             f"{f.name()}), got {describe_value(args)}")
        self._f = f
        self._start([self._input(k, a) for k, a in enumerate(args)])

    @classmethod
    def _made(cls, f: ca.Function, args: list) -> "Evaluation":
        """An Evaluation of this module's own inputs (arrays of numbers of the right sizes,
        from checked boundary data or a Pattern): no checks, no time spent on them."""
        ev = cls.__new__(cls)
        ev._f = f
        ev._start([np.array(np.ravel(a, order="F"), dtype=float) for a in args])
        return ev

    def _start(self, args: list[np.ndarray]) -> None:
        """Point the buffer at the input vectors ``args`` and at new output arrays."""
        f = self._f
        self._args = args
        self._buf, self._trigger = f.buffer()
        for k, a in enumerate(self._args):
            self._buf.set_arg(k, memoryview(a))
        self._res = [np.empty(f.nnz_out(k)) for k in range(f.n_out())]
        for k, r in enumerate(self._res):
            self._buf.set_res(k, memoryview(r))
        # Outputs can be structurally sparse (e.g. y^{11} = 0): scatter the nonzeros.
        self._where = [None if f.sparsity_out(k).is_dense()
                       else tuple(np.asarray(i) for i in f.sparsity_out(k).get_triplet())
                       for k in range(f.n_out())]

    def _input(self, k: int, value: Any) -> np.ndarray:
        """Input ``k`` as a contiguous float vector of its nonzeros, checked."""
        if (isinstance(value, (float, np.floating)) or isinstance(value, np.ndarray)
                and value.dtype.kind in "iuf" and value.ndim <= 2):
            arr = np.asarray(value, dtype=float)        # the quick way: numbers of the size
            if arr.size == self._f.nnz_in(k):
                return np.array(arr.ravel(order="F"))     # a copy: set() writes into it
        name = self._f.name_in(k)
        want = self._f.nnz_in(k)
        arr = finite_array(value, f"input {name} of {self._f.name()}", finite=False,
                           allowed=f"an array of {want} real numbers")
        if arr.size != want:
            raise InputError(f"input {name} of {self._f.name()} must have {want} entries "
                             f"({self._f.size1_in(k)} x {self._f.size2_in(k)}), got shape "
                             f"{arr.shape}")
        return np.array(arr.ravel(order="F"))

    def set(self, k: int, value) -> None:
        """Overwrite input ``k`` in place (same size)."""
        if not (type(k) is int and 0 <= k < len(self._args)):
            k = check_value(k, Key("whole", low=0, high=len(self._args) - 1), "k")
        self._args[k][:] = self._input(k, value)

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
    not creases and get 0. gamma > 0 is a valley (eq:MVAngles). ``omega`` is one number in
    [-pi, pi]; :class:`InputError` as :func:`fold`.
    """
    check_pattern(pat, "pat")
    om = check_fold_angle(omega)
    kh, kv = (k.full() for k in _multiplier_function(pat.N, pat.M)(pat.alpha, pat.beta,
                                                                   pat.sigma))
    half = om / 2
    with np.errstate(all="ignore"):
        gh = 2 * np.arctan2(kh[:, :-1] * np.sin(half), np.cos(half))
        gv = 2 * np.arctan2(kv[:-1, :] * np.sin(half), np.cos(half))
    gh[[0, -1], :] = 0.0
    gv[:, [0, -1]] = 0.0
    return check_folded(gh), check_folded(gv)


@lru_cache(maxsize=SIZE_CACHE)
def _multiplier_function(N: int, M: int) -> ca.Function:
    sym = [ca.MX.sym(n, N + 1, M + 1) for n in ("alpha", "beta", "sigma")]
    return ca.Function("multipliers", sym, list(fold_multipliers(*sym)))


def cached_graphs() -> int:
    """How many size-keyed CasADi functions this module and
    :mod:`~rffqm_nlp.model.kinematics` hold now (each kind keeps at most
    :data:`SIZE_CACHE`)."""
    return sum(f.cache_info().currsize for f in _SIZE_KEYED) + kinematics.cached_graphs()


_SIZE_KEYED = tuple(f for f in list(globals().values())
                    if callable(f) and hasattr(f, "cache_info") and f is not panel_cell)
