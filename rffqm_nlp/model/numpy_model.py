"""Plain-NumPy forward model of RFFQM: marching and folding, written from the paper.

This is the independent yardstick for the CasADi model. Conventions (docs/paper.md s.1):
vertex (i, j) (1-based) is stored at ``[i-1, j-1]`` and carries its a-role triple
(alpha, beta, sigma); panel (i, j) has corners a = (i, j), b = (i+1, j), c = (i, j+1),
d = (i+1, j+1).

* :func:`march` is the crease-pattern marching of eq:marchingSector .. eq:finalCheck, one
  vectorised step per anti-diagonal of panels; flat positions are cumulative sums of
  edge vectors whose directions are accumulated sector angles (docs/paper.md s.4).
* :func:`fold` is the kinematics of eq:creaseInputs .. eq:finalCalc. Every fold angle has
  tan(gamma/2) = k tan(omega/2) with a constant k per crease (docs/paper.md s.2), so its
  cosine and sine are rational in (cos(omega/2), sin(omega/2)); the deformation gradients
  (eq:defGrads) are cumulative products of crease rotations (eq:localRots), one batched
  matrix product per row, and deformed positions are cumulative sums of rotated edges.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .backend import check_formula_args, finite_array, finite_result
from .boundary import BoundaryData, check_boundary
from ..errors import InputError, MarchingError
from .pattern import (Pattern, check_fold_memory, check_folded, check_march_memory, check_omega,
                      check_pattern)

#: | |mu_abc| - 1 | at or below this fails the second check (eq:secondCheck).
SECOND_CHECK_TOL = 1e-12

_CHECKS = ("first", "second", "final")

#: Why a vertex's fold-angle multiplier has no finite value, for the errors.
_POLE = ("sigma is not in MV(alpha, beta) (cos(beta) = sigma cos(alpha)), where the "
         "fold-angle multiplier is 0 or infinite; give an admissible vertex (Theorem 2.1)")


def _vertex_args(alpha, beta, sigma) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arguments of a one-vertex formula checked, as float arrays: finite numbers that
    broadcast together, sigma +1 or -1 (:func:`rffqm_nlp.model.backend.check_formula_args`)."""
    if check_formula_args(alpha=alpha, beta=beta, sigma=sigma):
        raise InputError("the NumPy model takes numbers and NumPy arrays, not CasADi "
                         "symbols; use rffqm_nlp.model.vertex for those")
    return tuple(np.asarray(x, dtype=float) for x in (alpha, beta, sigma))


# --------------------------------------------------------------------------- one vertex

def _multiplier(formula, name: str, alpha, beta, sigma) -> np.ndarray:
    """``formula`` (:func:`_mu2` or :func:`_mu1`) at the checked arguments; refused where
    it is 0 or infinite (sigma not in MV(alpha, beta))."""
    alpha, beta, sigma = _vertex_args(alpha, beta, sigma)
    with np.errstate(all="ignore"):
        value = formula(alpha, beta, sigma)
        finite_result((value, 1 / value), f"{name} has no finite value: {_POLE}")
    return value


def mu2(alpha: ArrayLike, beta: ArrayLike, sigma: ArrayLike) -> np.ndarray:
    """Fold angle multiplier mu_2^sigma(alpha, beta) of eq:foldAngMult, as printed; the
    arguments in :func:`rffqm_nlp.model.vertex.mu2`'s order. Raises :class:`InputError` for
    arguments that are not finite numbers broadcasting together (sigma +1 or -1) and where
    sigma is not in MV(alpha, beta) (mu2 is 0 or infinite there)."""
    return _multiplier(_mu2, "mu2", alpha, beta, sigma)


def _mu2(alpha, beta, sigma):
    return _mu2_cs(np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta), sigma)


def _mu2_cs(ca, sa, cb, sb, sigma):
    """mu_2^sigma of eq:foldAngMult from the cosines and sines of alpha and beta."""
    return (-sigma + ca * cb + sa * sb) / (cb - sigma * ca)


def mu1(alpha: ArrayLike, beta: ArrayLike, sigma: ArrayLike) -> np.ndarray:
    """mu_1^{-sigma}(alpha, beta) = mu_2^{-sigma}(alpha, pi - beta) (eq:foldAngMult).

    ``sigma`` is the vertex sign; the result equals 1 / mu2(alpha, beta, sigma). Raises
    :class:`InputError` as :func:`mu2` does.
    """
    return _multiplier(_mu1, "mu1", alpha, beta, sigma)


def _mu1(alpha, beta, sigma):
    return _mu2(alpha, np.pi - beta, -sigma)


def gamma2_bar(omega: ArrayLike, alpha: ArrayLike, beta: ArrayLike,
               sigma: ArrayLike) -> np.ndarray:
    """gamma_2bar^sigma(omega; alpha, beta) of Theorem 2.1 in the form
    tan(gamma/2) = -tan(omega/2) / mu2 (docs/paper.md s.2), omega in [-pi, pi]. Raises
    :class:`InputError` as :func:`mu2` does, and for omega outside [-pi, pi]."""
    return _half_angle_map(*_together(_angles(omega), -1.0 / mu2(alpha, beta, sigma)))


def gamma1_bar(omega: ArrayLike, alpha: ArrayLike, beta: ArrayLike,
               sigma: ArrayLike) -> np.ndarray:
    """gamma_1bar^{-sigma}(omega; alpha, beta) (eq:inverse), the inverse of
    :func:`gamma2_bar`: tan(gamma/2) = -tan(omega/2) / mu1. Raises :class:`InputError` as
    :func:`gamma2_bar` does."""
    return _half_angle_map(*_together(_angles(omega), -1.0 / mu1(alpha, beta, sigma)))


def _together(w: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """omega and a vertex's multiplier factor, unless their shapes do not broadcast."""
    try:
        np.broadcast_shapes(np.shape(w), np.shape(k))
    except ValueError:
        raise InputError(f"omega and the vertex arguments must broadcast together, got "
                         f"shapes {np.shape(w)} and {np.shape(k)}") from None
    return w, k


def _angles(omega) -> np.ndarray:
    """omega (any shape) checked: finite numbers in [-pi, pi]."""
    w = finite_array(omega, "omega", allowed="a number or an array of numbers in [-pi, pi]")
    if np.any(np.abs(w) > np.pi):
        raise InputError(f"omega must lie in [-pi, pi], got {float(w[np.abs(w) > np.pi][0]):g}")
    return w


def _half_angle_map(omega, k):
    """The angle gamma in [-pi, pi] with tan(gamma/2) = k tan(omega/2)."""
    omega = np.asarray(omega, dtype=float)
    return 2.0 * np.arctan2(k * np.sin(omega / 2), _cos_half(omega))


def _cos_half(omega):
    """cos(omega/2), exactly 0 at |omega| = pi (the folded-flat state)."""
    return np.where(np.abs(omega) == np.pi, 0.0, np.cos(omega / 2))


# --------------------------------------------------------------------------- marching

def march(bd: BoundaryData) -> Pattern:
    """March the crease pattern from the boundary data (eq:marchingSector .. eq:finalCheck).

    Raises :class:`MarchingError` naming the check ("first", "second", "final") and the
    1-based panel of the first failure in marching order (row-major); :class:`InputError`
    when ``bd`` is not :class:`BoundaryData`, when the march needs more memory than this
    machine has left, and when the flat positions overflow (sides near the largest float).
    """
    check_boundary(bd)
    check_march_memory(bd.N, bd.M)
    alpha, beta, sigma, lh, lv, mu = _march_diagonals(bd)
    phi_h, phi_v = _edge_directions(alpha, beta)
    X = _assemble(_edge_vectors(lh, phi_h), _edge_vectors(lv, phi_v))
    finite_result(X, "the flat positions of the pattern overflow (its side lengths are too "
                     "large for floating point); scale the boundary lengths down")
    return Pattern._made(alpha=alpha, beta=beta, sigma=sigma, lh=lh, lv=lv, mu=mu, X=X)


#: Rows of the per-vertex table used while marching.
_ALPHA, _BETA, _SIGMA, _CA, _SA, _CB, _SB = range(7)


def _vertex_rows(alpha, beta, sigma) -> np.ndarray:
    """Per-vertex table (7, ...): a-role (alpha, beta, sigma), cos/sin alpha, cos/sin beta."""
    return np.stack([alpha, beta, sigma, np.cos(alpha), np.sin(alpha), np.cos(beta),
                     np.sin(beta)])


def _march_diagonals(bd: BoundaryData):
    """Angles, signs, lengths and mu_abc of all panels, one anti-diagonal per step.

    Work arrays are skewed: vertex (p, q) (0-based) and the edges leaving it,
    lh[p, q] and lv[p, q], are stored at [p + q, p], so the panels p + q = d and their
    corners a, b, c, d are contiguous slices of the anti-diagonals d, d+1, d+1, d+2.
    """
    N, M = bd.N, bd.M
    V = np.full((7, N + M + 1, N + 1), np.nan)
    LH, LV = np.full((2, N + M + 1, N + 1), np.nan)
    rows = np.arange(N + 1)
    V[:, rows, rows] = _vertex_rows(*bd.left.T)                  # vertices (p, 0)
    V[:, 1:M + 1, 0] = _vertex_rows(*bd.bottom.T)                # vertices (0, q)
    LV[rows[:-1], rows[:-1]] = bd.l_left
    LH[:M, 0] = bd.l_bottom
    MU, ASUM = np.full((2, N + M - 1, N), np.nan)
    CODE = np.zeros((N + M - 1, N), dtype=int)
    with np.errstate(all="ignore"):
        for d in range(N + M - 1):
            p0, p1 = max(0, d - M + 1), min(d, N - 1) + 1
            here, up = slice(p0, p1), slice(p0 + 1, p1 + 1)
            vd, l_cd, l_bd, mu, A, code = _panel_step(
                V[:, d, here], V[:, d + 1, up], V[:, d + 1, here], LV[d, here], LH[d, here])
            V[:, d + 2, up], LV[d + 1, here], LH[d + 1, up] = vd, l_cd, l_bd
            MU[d, here], ASUM[d, here], CODE[d, here] = mu, A, code
    lh, lv = _unskew(LH, N + 1, M + 1), _unskew(LV, N + 1, M + 1)
    code = _unskew(CODE, N, M)
    if code.any():
        _raise_first_failure(code, _unskew(MU, N, M), _unskew(ASUM, N, M), lv, lh)
    alpha, beta, sigma = _unskew(V[:3], N + 1, M + 1)
    return alpha, beta, sigma, lh[:, :M], lv[:N, :], _unskew(MU, N, M)


def _unskew(arr, n, m):
    """The (..., n, m) grid [p, q] of a skewed array stored at [..., p + q, p] (a copy)."""
    *lead, s_diag, s_row = arr.strides
    view = np.lib.stride_tricks.as_strided(arr, shape=arr.shape[:-2] + (n, m),
                                           strides=(*lead, s_diag + s_row, s_diag),
                                           writeable=False)
    return view.copy()


def _panel_step(a, b, c, l_ab, l_ac):
    """The design theorem (eq:muABC, eq:SuperParam) on a batch of panels (eq:firstCheck ..
    eq:finalCheck).

    ``a``, ``b``, ``c`` are the vertex tables (7, n) of the corners, ``l_ab``, ``l_ac`` the
    known sides. Returns the table of corner d, l_cd, l_bd, mu_abc, the angle sum
    A = alpha_a + alpha_b + alpha_c and a failure code (0 ok, 1/2/3 first/second/final).
    """
    # panel angles from the role table (docs/paper.md s.1):
    # (alpha_b, beta_b) = (pi - beta, pi - alpha) of b, (alpha_c, beta_c) = (beta, alpha) of c
    alpha_a, alpha_b, alpha_c = a[_ALPHA], np.pi - b[_BETA], c[_BETA]
    A = alpha_a + alpha_b + alpha_c
    ok1 = (2 * np.pi - A > 0) & (2 * np.pi - A < np.pi)
    mu = (_mu2_cs(a[_CA], a[_SA], -a[_CB], a[_SB], -a[_SIGMA])       # mu_1^{-sigma_a}
          * _mu2_cs(-b[_CB], b[_SB], -b[_CA], b[_SA], b[_SIGMA])     # mu_2^{sigma_b}
          * _mu2_cs(c[_CB], c[_SB], c[_CA], c[_SA], c[_SIGMA]))      # mu_2^{sigma_c}
    ok2 = np.isfinite(mu) & (np.abs(np.abs(mu) - 1) > SECOND_CHECK_TOL)
    sigma_d = -np.sign(mu**2 - 1)                                    # eq:marchingFinal
    cA = np.cos(A)
    arg = sigma_d * (2 * mu - (mu**2 + 1) * cA) / (2 * mu * cA - (mu**2 + 1))
    beta_d = np.arccos(np.clip(arg, -1.0, 1.0))
    sA = np.sin(A)                                                   # eq:getSides
    l_cd = (-b[_SB] * l_ab + np.sin(alpha_a + alpha_b) * l_ac) / sA
    l_bd = (np.sin(alpha_a + alpha_c) * l_ab - c[_SB] * l_ac) / sA
    ok3 = np.isfinite(l_cd) & np.isfinite(l_bd) & (l_cd > 0) & (l_bd > 0)
    code = np.where(~ok1, 1, np.where(~ok2, 2, np.where(~ok3, 3, 0)))
    # corner d in its a-role: (pi - alpha_d, pi - beta_d) with alpha_d = 2 pi - A
    return _vertex_rows(A - np.pi, np.pi - beta_d, sigma_d), l_cd, l_bd, mu, A, code


def _raise_first_failure(code, mu, asum, lv, lh):
    """Raise MarchingError for the row-major-first failing panel."""
    p, q = divmod(int(np.flatnonzero(code)[0]), code.shape[1])
    check = _CHECKS[code[p, q] - 1]
    detail = {
        "first": f"2*pi - (alpha_a + alpha_b + alpha_c) = {float(2 * np.pi - asum[p, q])!r}",
        "second": f"mu_abc = {float(mu[p, q])!r}",
        "final": f"l_cd = {float(lv[p, q + 1])!r}, l_bd = {float(lh[p + 1, q])!r}",
    }[check]
    raise MarchingError(check, (p + 1, q + 1), detail)


def _edge_directions(alpha, beta):
    """Polar angles of all flat edges from accumulated sector angles (docs/paper.md s.4).

    Returns phi_h (N+1, M) of the edges (i, j) -> (i, j+1) and phi_v (N, M+1) of the
    edges (i, j) -> (i+1, j). The first edge points along +e1; along the bottom row the
    outgoing edge turns by pi - alpha - beta at each vertex; up a column, a panel's b->d is
    its a->c turned by alpha_a + alpha_b + pi = alpha^{ij} - beta^{(i+1)j} (mod 2 pi);
    a->b is a->c turned by alpha_a, and the last column's c->d is a->c turned by
    pi - alpha_c.
    """
    bottom = np.concatenate([[0.0], np.cumsum(np.pi - alpha[0, 1:-1] - beta[0, 1:-1])])
    steps = alpha[:-1, :-1] - beta[1:, :-1]
    phi_h = bottom + np.concatenate([np.zeros((1, bottom.size)), np.cumsum(steps, axis=0)])
    phi_v = np.concatenate([phi_h[:-1] + alpha[:-1, :-1],
                            phi_h[:-1, -1:] + np.pi - beta[:-1, -1:]], axis=1)
    return phi_h, phi_v


def _edge_vectors(length, phi):
    """Flat edge vectors, component-major: (3, ...) = length (cos phi, sin phi, 0)."""
    return np.stack([length * np.cos(phi), length * np.sin(phi), np.zeros_like(phi)])


def _assemble(Eh, Ev):
    """Vertex positions (..., N+1, M+1, 3) from component-major horizontal (3, ..., N+1, M)
    and vertical (3, ..., N, M+1) edge vectors: cumulative sums up the first column, then
    along every row."""
    P = np.zeros(Eh.shape[:-1] + (Eh.shape[-1] + 1,))
    P[..., 1:, 0] = np.cumsum(Ev[..., 0], axis=-1)
    P[..., 1:] = P[..., :1] + np.cumsum(Eh, axis=-1)
    return np.ascontiguousarray(np.moveaxis(P, 0, -1))


# --------------------------------------------------------------------------- kinematics

def fold(pat: Pattern, omega: ArrayLike) -> np.ndarray:
    """Folded vertex positions (eq:creaseInputs .. eq:finalCalc) with R^{11} = I, y^{11} = 0.

    ``omega`` (gamma_1 of vertex (1, 1)) is a scalar in [-pi, pi] -> (N+1, M+1, 3), or an
    array of K values -> (K, N+1, M+1, 3). omega = 0 is flat, |omega| = pi folded flat.
    Positions are cumulative sums of flat edge vectors rotated by the R^{ij} of a panel
    each edge bounds: horizontal edges move with the panel above (the top row with the one
    below), vertical edges with the panel to the right (the last column with the one left).
    Raises :class:`InputError` when ``pat`` is not a :class:`Pattern`, for an invalid
    omega (:func:`~rffqm_nlp.model.pattern.check_omega`), when the states need more memory than
    this machine has left, and when the pattern has no finite folded state (a vertex
    outside MV(alpha, beta): a pattern that was not marched).
    """
    check_pattern(pat, "pat")
    w, scalar = _omegas(omega)
    N, M, K = pat.N, pat.M, w.size
    check_fold_memory(N, M, K)
    phi_h, phi_v = _edge_directions(pat.alpha, pat.beta)
    Eh, Ev = _edge_vectors(pat.lh, phi_h), _edge_vectors(pat.lv, phi_v)
    Yh, Yv = np.empty((3, K, N + 1, M)), np.empty((3, K, N, M + 1))
    for p, R in enumerate(_rotation_rows(pat, w)):
        Yh[:, :, p] = _rotate(R, Eh[:, p])
        Yv[:, :, p] = _rotate(np.concatenate([R, R[:, -1:]], axis=1), Ev[:, p])
    Yh[:, :, N] = _rotate(R, Eh[:, N])
    Y = _assemble(Yh, Yv)
    check_folded(Y)
    return Y[0] if scalar else Y


def fold_angles(pat: Pattern, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Fold angles of all edges (eq:foldInitial .. eq:foldFinal); gamma > 0 is a valley.

    Returns gamma_h (N+1, M) with gamma_1^{ij} on the edge (i, j) -> (i, j+1) and gamma_v
    (N, M+1) with gamma_2^{ij} on the edge (i, j) -> (i+1, j), 0 on the boundary edges
    (first/last row of gamma_h, first/last column of gamma_v); a leading K axis for an
    array ``omega``. Raises :class:`InputError` as :func:`fold` does.
    """
    check_pattern(pat, "pat")
    w, scalar = _omegas(omega)
    check_fold_memory(pat.N, pat.M, w.size)
    k1, k2 = _fold_tangent_factors(pat)
    S, C = np.sin(w / 2)[:, None, None], _cos_half(w)[:, None, None]
    with np.errstate(all="ignore"):
        gh = 2 * np.arctan2(k1[:, :-1] * S, C)
        gv = 2 * np.arctan2(k2[:-1] * S, C)
    gh[:, [0, -1]] = 0.0
    gv[:, :, [0, -1]] = 0.0
    check_folded(gh)
    check_folded(gv)
    return (gh[0], gv[0]) if scalar else (gh, gv)


def _omegas(omega) -> tuple[np.ndarray, bool]:
    """omega validated by :func:`check_omega`, as a 1-D array (K,), and whether it was a scalar."""
    w = check_omega(omega)
    return np.atleast_1d(w), w.ndim == 0


def _fold_tangent_factors(pat: Pattern) -> tuple[np.ndarray, np.ndarray]:
    """Constants k1, k2 (N+1, M+1) with tan(gamma_1^{ij}/2) = k1 tan(omega/2) and
    tan(gamma_2^{ij}/2) = k2 tan(omega/2) at every vertex (eq:foldInitial .. eq:foldFinal).

    Bottom row: gamma_1^{1j} = -sigma^{1j} gamma_1^{1(j-1)}, gamma_2 = gamma_2bar(gamma_1);
    above: gamma_2^{ij} = sigma^{ij} gamma_2^{(i-1)j}, gamma_1 = gamma_1bar(gamma_2).
    Values on the virtual boundary creases are kept: they feed the propagation.
    """
    a, b, s = pat.alpha, pat.beta, pat.sigma
    k1_bottom = np.cumprod(np.concatenate([[1.0], -s[0, 1:]]))
    with np.errstate(all="ignore"):     # a pole gives NaN states, refused by the callers
        k2 = (-k1_bottom / _mu2(a[0], b[0], s[0])) * np.cumprod(
            np.concatenate([np.ones((1, s.shape[1])), s[1:]]), axis=0)
        k1 = -k2 / _mu1(a, b, s)
    k1[0] = k1_bottom
    return k1, k2


def _crease_rotation(t, k, S, C) -> np.ndarray:
    """R_t(gamma) of eq:localRots (t_perp typo fixed) with tan(gamma/2) = k S / C.

    ``t`` (..., 2) in-plane unit tangents, ``k`` (...) factors, ``S``, ``C`` broadcastable
    sin and cos of omega/2. cos gamma, sin gamma and 1 - cos gamma are rational in S, C.
    """
    kS = k * S
    D = C * C + kS * kS
    cg, sg, omc = (C * C - kS * kS) / D, 2 * kS * C / D, 2 * kS * kS / D
    tx, ty = t[..., 0], t[..., 1]
    R = np.empty(np.broadcast_shapes(cg.shape, tx.shape) + (3, 3))
    R[..., 0, 0] = 1 - omc * ty * ty        # tx^2 + cos g (1 - tx^2)
    R[..., 1, 1] = 1 - omc * tx * tx
    R[..., 2, 2] = cg
    R[..., 0, 1] = R[..., 1, 0] = omc * tx * ty
    R[..., 0, 2], R[..., 1, 2] = sg * ty, -sg * tx      # -sin g t_perp (x) e3
    R[..., 2, 0], R[..., 2, 1] = -sg * ty, sg * tx      # sin g e3 (x) t_perp
    return R


def _rotation_rows(pat: Pattern, w: np.ndarray):
    """Yield the deformation gradients of eq:defGrads row by row, each (K, M, 3, 3).

    R^{11} = I; bottom row R^{1j} = R^{1(j-1)} R_{t2}(-gamma_2^{1j}); above,
    R^{ij} = R^{(i-1)j} R_{t1}(gamma_1^{ij}) (one batched product per row), with t1, t2
    the flat tangents at vertex (i, j) (eq:tansLocal, t1 typo fixed).
    """
    k1, k2 = _fold_tangent_factors(pat)
    phi_h, phi_v = _edge_directions(pat.alpha, pat.beta)
    S, C = np.sin(w / 2)[:, None], _cos_half(w)[:, None]
    # R_t(-gamma) has tan(-gamma/2) = -k2 tan(omega/2)
    R = _crease_rotation(_unit(phi_v[0, :pat.M]), -k2[0, :pat.M], S, C)
    R[:, 0] = np.eye(3)
    for q in range(1, pat.M):
        R[:, q] = R[:, q - 1] @ R[:, q]
    yield R
    for p in range(1, pat.N):
        R = R @ _crease_rotation(_unit(phi_h[p]), k1[p, :pat.M], S, C)
        yield R


def _panel_rotations(pat: Pattern, w: np.ndarray) -> np.ndarray:
    """All deformation gradients R^{ij}, (K, N, M, 3, 3) (eq:defGrads)."""
    return np.stack(list(_rotation_rows(pat, w)), axis=1)


def _unit(phi):
    """In-plane unit vectors (cos phi, sin phi), shape (..., 2)."""
    return np.stack([np.cos(phi), np.sin(phi)], axis=-1)


def _rotate(R, E):
    """Component-major R E: (3, K, ...) for R (K, ..., 3, 3) and flat E (3, ...), E_z = 0."""
    return np.einsum("k...ij,j...->ik...", R[..., :2], E[:2])

