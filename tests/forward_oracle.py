"""The forward oracle: the paper's marching and folding as a plain per-panel Python loop.

Scalar ``math`` for every angle and length, one 3x3 NumPy matrix per panel, panels in the
paper's order (1,1), ..., (1,M), (2,1), ..., (N,M). The tests hold
:mod:`rffqm_nlp.model.numpy_model` against it, and benchmarks/forward.py times it as the
baseline; the flat pattern follows the stable accumulated-direction construction of
docs/paper.md s.4, not the printed recursion. It trusts its inputs (boundary data of
:class:`rffqm_nlp.BoundaryData`, omega in [-pi, pi]).
"""

from __future__ import annotations

import math

import numpy as np

from rffqm_nlp.model.boundary import BoundaryData
from rffqm_nlp.errors import MarchingError
from rffqm_nlp.model.pattern import Pattern

SECOND_CHECK_TOL = 1e-12
TWO_PI = 2 * math.pi


def _mu2(alpha: float, beta: float, sigma: float) -> float:
    """mu_2^sigma(alpha, beta), eq:foldAngMult."""
    return (-sigma + math.cos(alpha) * math.cos(beta) + math.sin(alpha) * math.sin(beta)) / (
        math.cos(beta) - sigma * math.cos(alpha))


def _mu1(alpha: float, beta: float, sigma: float) -> float:
    """mu_1^{-sigma}(alpha, beta) = mu_2^{-sigma}(alpha, pi - beta), eq:foldAngMult."""
    return _mu2(alpha, math.pi - beta, -sigma)


def unit(theta: float) -> np.ndarray:
    """The in-plane unit vector (cos theta, sin theta, 0)."""
    return np.array([math.cos(theta), math.sin(theta), 0.0])


def march_loop(bd: BoundaryData) -> Pattern:
    """The crease-pattern marching eq:marchingSector .. eq:finalCheck, one panel at a time."""
    N, M = bd.N, bd.M
    nan = math.nan
    alpha = [[nan] * (M + 1) for _ in range(N + 1)]
    beta = [[nan] * (M + 1) for _ in range(N + 1)]
    sigma = [[nan] * (M + 1) for _ in range(N + 1)]
    for p, (a, b, s) in enumerate(bd.left.tolist()):
        alpha[p][0], beta[p][0], sigma[p][0] = a, b, s
    for q, (a, b, s) in enumerate(bd.bottom.tolist(), start=1):
        alpha[0][q], beta[0][q], sigma[0][q] = a, b, s
    lh = [[nan] * M for _ in range(N + 1)]
    lv = [[nan] * (M + 1) for _ in range(N)]
    lh[0] = bd.l_bottom.tolist()
    for p in range(N):
        lv[p][0] = float(bd.l_left[p])
    mu = [[nan] * M for _ in range(N)]
    X = np.zeros((N + 1, M + 1, 3))
    theta_bd = [0.0] * M          # direction of b->d of the panel below, per column
    for p in range(N):
        theta_cd = 0.0            # direction of c->d of the panel to the left
        for q in range(M):
            # eq:marchingSector, eq:marchingMV (role table, docs/paper.md s.1)
            aa, ba, sa = alpha[p][q], beta[p][q], sigma[p][q]
            ab, bb, sb = math.pi - beta[p + 1][q], math.pi - alpha[p + 1][q], sigma[p + 1][q]
            ac, bc, sc = beta[p][q + 1], alpha[p][q + 1], sigma[p][q + 1]
            A = aa + ab + ac
            if not 0 < TWO_PI - A < math.pi:
                raise MarchingError("first", (p + 1, q + 1))
            m = _mu1(aa, ba, sa) * _mu2(ab, bb, sb) * _mu2(ac, bc, sc)
            if not abs(abs(m) - 1) > SECOND_CHECK_TOL:
                raise MarchingError("second", (p + 1, q + 1))
            sd = -math.copysign(1.0, m * m - 1)
            cA = math.cos(A)
            arg = sd * (2 * m - (m * m + 1) * cA) / (2 * m * cA - (m * m + 1))
            beta_d = math.acos(min(1.0, max(-1.0, arg)))
            l_ab, l_ac = lv[p][q], lh[p][q]                     # eq:marchingSides
            sA = math.sin(A)
            l_cd = (-math.sin(ab) * l_ab + math.sin(aa + ab) * l_ac) / sA
            l_bd = (math.sin(aa + ac) * l_ab - math.sin(ac) * l_ac) / sA
            if not (l_cd > 0 and l_bd > 0):
                raise MarchingError("final", (p + 1, q + 1))
            alpha[p + 1][q + 1], beta[p + 1][q + 1], sigma[p + 1][q + 1] = (
                A - math.pi, math.pi - beta_d, sd)
            lv[p][q + 1], lh[p + 1][q], mu[p][q] = l_cd, l_bd, m
            # flat positions (eq:creaseInputs and the two displays after it) with
            # accumulated edge directions
            if p == 0:
                theta = 0.0 if q == 0 else theta_cd - aa
                X[0, q + 1] = X[0, q] + l_ac * unit(theta)
            else:
                theta = theta_bd[q]
            theta_ab = theta + aa
            theta_cd = theta + math.pi - ac
            theta_bd[q] = math.remainder(theta_ab + math.pi + ab, TWO_PI)
            X[p + 1, q] = X[p, q] + l_ab * unit(theta_ab)
            X[p + 1, q + 1] = X[p + 1, q] + l_bd * unit(theta_bd[q])
    return Pattern(alpha=alpha, beta=beta, sigma=sigma, lh=lh, lv=lv, mu=mu, X=X)


def rot_about(t: np.ndarray, gamma: float) -> np.ndarray:
    """R_t(gamma) of eq:localRots for an in-plane unit tangent t, with
    t_perp = -(t.e2) e1 + (t.e1) e2 (docs/paper.md s.3)."""
    tp = np.array([-t[1], t[0], 0.0])
    e3 = np.array([0.0, 0.0, 1.0])
    tt = np.outer(t, t)
    return tt + math.cos(gamma) * (np.eye(3) - tt) + math.sin(gamma) * (
        np.outer(e3, tp) - np.outer(tp, e3))


def fold_loop(pattern: Pattern, omega: float) -> np.ndarray:
    """Folded positions (N+1, M+1, 3) by eq:foldInitial .. eq:finalCalc, panel by panel."""
    N, M = pattern.N, pattern.M
    al, be, sg, X = pattern.alpha, pattern.beta, pattern.sigma, pattern.X
    g1 = [[0.0] * (M + 1) for _ in range(N + 1)]
    g2 = [[0.0] * (M + 1) for _ in range(N + 1)]
    R = [[None] * M for _ in range(N)]
    Y = X.copy()
    for p in range(N):
        for q in range(M):
            a, b, s = float(al[p, q]), float(be[p, q]), float(sg[p, q])
            if p == 0:                                   # eq:foldInitial, eq:foldMiddle
                g1[p][q] = omega if q == 0 else -s * g1[p][q - 1]
                g2[p][q] = 2 * math.atan(-math.tan(g1[p][q] / 2) / _mu2(a, b, s))
            else:                                        # eq:foldFinal
                g2[p][q] = s * g2[p - 1][q]
                g1[p][q] = 2 * math.atan(-math.tan(g2[p][q] / 2) / _mu1(a, b, s))
            xa = X[p, q]
            t1 = (X[p, q + 1] - xa) / np.linalg.norm(X[p, q + 1] - xa)   # eq:tansLocal
            t2 = (X[p + 1, q] - xa) / np.linalg.norm(X[p + 1, q] - xa)
            if p == 0 and q == 0:                        # eq:defGrads
                R[p][q] = np.eye(3)
            elif p == 0:
                R[p][q] = R[p][q - 1] @ rot_about(t2, -g2[p][q])
            else:
                R[p][q] = R[p - 1][q] @ rot_about(t1, g1[p][q])
            ya = Y[p, q]                                 # eq:finalCalc
            for v in ((p + 1, q), (p, q + 1), (p + 1, q + 1)):
                Y[v] = ya + R[p][q] @ (X[v] - xa)
    return Y
