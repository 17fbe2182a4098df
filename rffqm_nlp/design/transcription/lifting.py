"""The lifted variables that keep every row of the simultaneous NLP local: the mean side
as the root of a tree of partial means (:class:`MeanTree`), and the fold multipliers'
column factors as angles PHI (:func:`local_crease_quaternions`)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...model import vertex as vx
from ...model.marching import crease_quaternion


class MeanTree:
    """The mean of K sides as a tree of partial means: level 1 averages blocks of
    ``branching`` consecutive sides in the order ``order`` (a permutation of range(K),
    default as given), each further level blocks of the level below, up to one root, the
    mean. Every node is a variable and every tree equation is local.

    One equation sum(s) = K * mean would be a dense row of the constraint Jacobian, and the
    mean a dense column (it enters every side constraint); CasADi colours Jacobians in one
    direction, so that row and column together cost a sweep per side. The tree adds about
    K / (branching - 1) unknowns and a few tens of colours; a running mean (one variable per
    side) did the same with K unknowns, a noticeable share of the KKT system
    (docs/decisions/ipopt.md).
    """

    def __init__(self, K: int, branching: int = 16, order: np.ndarray | None = None):
        self.levels: list[ca.DM] = []  # weights: node = sum of weight * child
        weight = np.ones(K)  # sides under each node of the level below
        rank = np.arange(K)
        if order is not None:
            rank[order] = np.arange(K)
        while weight.size > 1:
            parent = rank // branching
            rank = np.arange(parent.max() + 1)
            size = np.bincount(parent, weights=weight)
            self.levels.append(ca.DM.triplet(parent.tolist(), list(range(weight.size)),
                                             (weight / size[parent]).tolist(),
                                             size.size, weight.size))
            weight = size
        self.size = sum(W.size1() for W in self.levels)

    def residuals(self, sides, P) -> tuple:
        """(residuals, mean) for the sides and the node variables P (``size``, level by
        level, the root last)."""
        out, below, k = [], sides, 0
        for W in self.levels:
            node = P[k:k + W.size1()]
            out.append(node - ca.mtimes(W, below))
            below, k = node, k + W.size1()
        return ca.vertcat(*out), P[self.size - 1]

    def expression(self, sides: ca.MX) -> ca.MX:
        """The node values (``size``, as P) of the sides."""
        out, below = [], sides
        for W in self.levels:
            below = ca.mtimes(W, below)
            out.append(below)
        return ca.vertcat(*out)


def sides_by_antidiagonal(N: int, M: int) -> np.ndarray:
    """The sides [vec(LH); vec(LV)] (column-major, K = (N+1) M + N (M+1)) ordered by the
    anti-diagonal i + j of their first vertex (i, j), then i: the march reaches them in
    that order, so that a partial mean of :class:`MeanTree` waits for sides of about one
    anti-diagonal only (the Levenberg-Marquardt pass holds fewer rows,
    :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`)."""
    i = np.concatenate([np.tile(np.arange(N + 1), M), np.tile(np.arange(N), M + 1)])
    j = np.concatenate([np.repeat(np.arange(M), N + 1), np.repeat(np.arange(M + 1), N)])
    return np.lexsort((i, i + j))


def fold_multipliers_kv(sigma: np.ndarray):
    """The constant parts of :func:`marching.fold_multipliers`: kh0 (1 x M+1) and the
    cumulative sign products down the columns, so that kv[i, j] = -kh0[j] / m2[0, j] * sp[i, j]
    and kh[i, j] = -kv[i, j] * m2[i, j]."""
    kh0 = np.concatenate([[1.0], np.cumprod(-sigma[0, 1:])])
    sp = np.vstack([np.ones((1, sigma.shape[1])), np.cumprod(sigma[1:, :], axis=0)])
    return kh0, sp


def local_crease_quaternions(A, B, sigma: np.ndarray, TH, omega, PHI):
    """:func:`marching.crease_quaternions` with the column factors lifted and no quotient.

    The fold multiplier kv[i, j] of every vertex of column j carries 1 / m2 of the bottom
    vertex (i = 0), which would couple each crease of a column to that vertex. It is also
    infinite where that m2 vanishes (alpha = beta at sigma = +1): a point the boundary MV
    constraint excludes, but IPOPT's infeasible iterates can cross it. Lifting kv itself
    (KV[i] = sigma[i] KV[i-1]), the sphere cap and the quarter vase diverged at larger
    sizes; lifted as below, they converged (docs/decisions/ipopt.md).

    PHI (N-1 x M) holds phi = atan(kv[1:N, :M]), smooth through kv = +-inf, with the local
    chain PHI[i] = sigma[i] PHI[i-1] and the bottom row from its vertex: tan(phi) = kv with
    m2 = num / den (:func:`vertex.mu2_terms`), i.e. sin(phi) num = -sigma kh0 cos(phi) den.
    Every crease multiplier is then a ratio of smooth terms, passed to
    :func:`crease_quaternion` as such: a quaternion of the same rotation up to sign (see
    :func:`crease_quaternion_signs`), and the folded state is quadratic in it.
    Returns (qv, qh, residuals).
    """
    N, M = A.shape[0] - 1, A.shape[1] - 1
    kh0, _ = fold_multipliers_kv(sigma)
    S, K0 = ca.DM(sigma), ca.DM(kh0).T
    num, den = vx.mu2_terms(A, B, S)
    c, s = ca.cos(omega / 2), ca.sin(omega / 2)
    theta_v = TH[:-1, :] + A[:-1, :]
    # kv[0, j] = -kh0[j] / m2[0, j] and kh[i, j] = -kv[i, j] m2[i, j] = -tan(phi) m2[i, j]
    qv = crease_quaternion(theta_v[0, 1:M], -K0[0, 1:M] * den[0, 1:M], c, s, sign=-1.0,
                           k_den=num[0, 1:M])
    qh = crease_quaternion(TH[1:N, :M], -ca.sin(PHI) * num[1:N, :M], c, s,
                           k_den=ca.cos(PHI) * den[1:N, :M])
    res = ca.vertcat(ca.vec(ca.sin(PHI[0, :]) * num[0, :M]
                            + S[1, :M] * K0[0, :M] * ca.cos(PHI[0, :]) * den[0, :M]),
                     ca.vec(PHI[1:, :] - S[2:N, :M] * PHI[:N - 2, :]))
    return qv, qh, res


def crease_quaternion_signs(alpha, beta, sigma, phi) -> np.ndarray:
    """Per panel (N x M): the sign between the panel quaternion of
    :func:`local_crease_quaternions` and that of :func:`marching.panel_quaternions_function`
    at numeric (alpha, beta, phi): the product of sign(k_den) of the creases crossed from
    panel (1, 1), along the bottom row and then up the column."""
    N, M = alpha.shape[0] - 1, alpha.shape[1] - 1
    num, den = vx.mu2_terms(alpha, beta, sigma)
    row = np.concatenate([[1.0], np.cumprod(np.sign(num[0, 1:M]))])
    col = np.cumprod(np.sign(np.cos(phi) * den[1:N, :M]), axis=0)
    return row * np.vstack([np.ones((1, M)), col])
