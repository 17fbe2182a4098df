"""Transcriptions of a :class:`~rffqm_nlp.design.DesignProblem` into one IPOPT NLP.

A transcription turns the declarative problem into ``(x, residuals, g, bounds, x0)``:

* ``sequential``: the marching graph is a function of the boundary data (few variables,
  dense Jacobians);
* ``simultaneous``: every vertex angle and side is a variable and the marching equations are
  equality constraints, panel by panel (many variables, sparse Jacobians).

Both share the residuals of the loss (:func:`loss_residuals`) and the inline constraints
(:func:`pattern_constraints`), so they state the same problem.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from . import shape
from .boundary import BoundaryData
from .marching import folded_function

PI = np.pi


@dataclass
class NLP:
    """One transcribed NLP: min 0.5 |res(x)|^2 s.t. lbg <= g(x) <= ubg, lbx <= x <= ubx."""

    x: ca.MX
    residuals: ca.MX
    g: ca.MX
    lbg: np.ndarray
    ubg: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    x0: np.ndarray
    #: Functions of x: boundary data vector (angles, lengths), omega, quaternion, translation
    unpack: ca.Function
    #: Function of x: the folded vertices (Yx, Yy, Yz)
    folded: ca.Function
    groups: dict[str, slice]


def rotation_from_quaternion(q):
    """Rotation matrix of the (not necessarily unit) quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    n = w * w + x * x + y * y + z * z
    R = ca.vertcat(
        ca.horzcat(w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z))
    return R / n


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """A unit quaternion (w, x, y, z) of the rotation matrix R."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def loss_residuals(Y, rotation, translation, target: np.ndarray, weights: dict[str, float],
                   spacing: float):
    """Residuals of the loss for folded vertices Y = (Yx, Yy, Yz) ((2N+1) x (2M+1) each).

    * ``forms``: the paper's loss (eq:optInverse): discrete first and second fundamental forms
      of the coarse lattice r(i, j) = y^{(2i)(2j)} minus the target's, at interior points, by
      the same central differences (:func:`shape.fundamental_forms`), over spacing^2;
    * ``position``: R r + t minus the target lattice over ``spacing``: the position term
      after alignment (R, t are design variables) that sees the sideways offsets of the four
      parity classes that central differences miss (PAPER_NOTES s.8).

    Each group is divided by sqrt(its count) and multiplied by sqrt(weight), so a weight is
    the share of a mean square in the objective.
    """
    r = [c[::2, ::2] for c in Y]
    out = []
    if weights.get("forms", 0) > 0:
        mine = shape.fundamental_forms(r)
        theirs = shape.fundamental_forms(target)
        res = ca.vertcat(*(ca.vec(a - ca.DM(b)) for a, b in zip(mine, theirs))) / spacing ** 2
        out.append(np.sqrt(weights["forms"] / res.numel()) * res)
    if weights.get("position", 0) > 0:
        pts = ca.vertcat(*(ca.vec(c).T for c in r))  # 3 x n
        moved = ca.mtimes(rotation, pts) + ca.repmat(translation, 1, pts.shape[1])
        tgt = target.transpose(1, 0, 2).reshape(-1, 3).T  # column-major, as ca.vec
        res = ca.vec(moved - tgt) / spacing
        out.append(np.sqrt(weights["position"] / pts.shape[1]) * res)
    return ca.vertcat(*out)


def sequential(bd0: BoundaryData, omega0: float, rigid0: tuple[np.ndarray, np.ndarray],
               target: np.ndarray, weights: dict[str, float], spacing: float,
               angle_bounds: tuple[float, float], omega_bounds: tuple[float, float],
               fixed: tuple[str, ...], constraints) -> NLP:
    """The sequential transcription: x = (boundary angles, boundary lengths, omega, q, t)."""
    N, M = bd0.N, bd0.M
    nv, nl = N + 1 + M, N + M
    x = ca.MX.sym("x", 2 * nv + nl + 1 + 7)
    groups = {"angles": slice(0, 2 * nv), "lengths": slice(2 * nv, 2 * nv + nl),
              "omega": slice(2 * nv + nl, 2 * nv + nl + 1),
              "rigid": slice(2 * nv + nl + 1, 2 * nv + nl + 8)}
    sig = ca.DM(bd0.sigma).T
    alpha, beta = x[:nv].T, x[nv:2 * nv].T
    tri = ca.vertcat(alpha, beta, sig)
    lengths = x[groups["lengths"]].T
    omega = x[groups["omega"]]
    q, t = x[groups["rigid"]][:4], x[groups["rigid"]][4:]
    f = folded_function(N, M)
    inputs = [tri[:, :N + 1], tri[:, N + 1:], lengths[:, :N], lengths[:, N:], omega]
    Y = f.call(inputs)
    x0 = np.concatenate([bd0.to_vector(), [omega0], quaternion_from_rotation(rigid0[0]),
                         rigid0[1]])
    scale = np.concatenate([np.ones(2 * nv), np.full(nl, 1 / spacing), [1.0]])
    res = ca.vertcat(
        loss_residuals(Y, rotation_from_quaternion(q), t, target, weights, spacing),
        ca.sumsqr(q) - 1,  # fixes the quaternion's free scale
        np.sqrt(weights.get("regularization", 0) / scale.size)
        * (x[:2 * nv + nl + 1] - x0[:2 * nv + nl + 1]) * scale)
    g, lbg, ubg = constraints(inputs[:4])
    lbx = np.concatenate([np.full(2 * nv, angle_bounds[0]), np.full(nl, 1e-9 * spacing),
                          [omega_bounds[0]], np.full(7, -np.inf)])
    ubx = np.concatenate([np.full(2 * nv, angle_bounds[1]), np.full(nl, np.inf),
                          [omega_bounds[1]], np.full(7, np.inf)])
    for name in fixed:
        lbx[groups[name]] = ubx[groups[name]] = x0[groups[name]]
    unpack = ca.Function("unpack", [x], [x[:2 * nv + nl], omega, q, t])
    folded = ca.Function("folded", [x], list(Y))
    return NLP(x=x, residuals=res, g=g, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, x0=x0,
               unpack=unpack, folded=folded, groups=groups)
