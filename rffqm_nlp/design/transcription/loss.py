"""The objective of the design NLP: the loss of the coarse lattice against the target
(eq:optInverse, :func:`loss_residuals`), then the rows on the design alone: the
quaternion's norm, the Tikhonov terms and the smoothness of the boundary perturbation
(:func:`design_residuals`)."""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from ...model.backend import Scalar
from ...targets import shape
from . import correspondence
from .curvature_loss import curvature_residuals
from .inputs import Setup


def rotation_from_quaternion(q: Sequence[Scalar]) -> ca.MX:
    """Rotation matrix of the (not necessarily unit) quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    n = w * w + x * x + y * y + z * z
    R = ca.vertcat(
        ca.horzcat(w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z))
    return R / n


def loss_residuals(r: Sequence[ca.MX], rotation: ca.MX, translation: Scalar,
                   target: np.ndarray | Sequence[ca.MX], weights: dict[str, float],
                   spacing: float) -> ca.MX:
    """Residuals of the loss for the coarse lattice r(i, j) = y^{(2i)(2j)} of the folded
    vertices, r = (rx, ry, rz) ((N+1) x (M+1) each), against the target lattice: fixed
    (an array (N+1, M+1, 3)) or, with a free correspondence, symbolic (Tx, Ty, Tz)
    ((N+1) x (M+1) each, :meth:`.correspondence.Correspondence.lattice`).

    * ``forms``: the paper's loss (eq:optInverse): discrete first and second fundamental forms
      of r minus the target's, at interior points, by
      the same central differences (:func:`shape.fundamental_forms`), over spacing^2;
    * ``position``: R r + t minus the target lattice over ``spacing``: the position term
      after alignment (R, t are design variables) that sees the sideways offsets of the four
      parity classes that central differences miss (docs/paper.md).

    Each group is divided by sqrt(its count) and multiplied by sqrt(weight), so a weight is
    the share of a mean square in the objective.
    """
    out = []
    fixed = isinstance(target, np.ndarray)
    if weights.get("forms", 0) > 0:
        mine = shape.fundamental_forms(r)
        theirs = shape.fundamental_forms(target)
        res = ca.vertcat(*(ca.vec(a - (ca.DM(b) if fixed else b))
                           for a, b in zip(mine, theirs))) / spacing ** 2
        out.append(np.sqrt(weights["forms"] / res.numel()) * res)
    if weights.get("position", 0) > 0:
        pts = ca.vertcat(*(ca.vec(c).T for c in r))  # 3 x n
        moved = ca.mtimes(rotation, pts) + ca.repmat(translation, 1, pts.shape[1])
        tgt = (target.transpose(1, 0, 2).reshape(-1, 3).T if fixed  # column-major, as ca.vec
               else ca.vertcat(*(ca.vec(c).T for c in target)))
        res = ca.vec(moved - tgt) / spacing
        out.append(np.sqrt(weights["position"] / pts.shape[1]) * res)
    return ca.vertcat(*out)


def objective_residuals(setup: Setup, r, rigid, boundary_vec, grid=None) -> ca.MX:
    """Loss of the coarse lattice r (:func:`loss_residuals`, or a curvature target's
    :func:`.curvature_loss.curvature_residuals`), then the rows on the design alone
    (:func:`design_residuals`). ``grid``: the controls (Cu, Cv) of a free correspondence
    (the target lattice at their grid, and their Tikhonov term), or None."""
    return ca.vertcat(state_residuals(setup, r, rigid, grid),
                      design_residuals(setup, rigid, boundary_vec, grid))


def state_residuals(setup: Setup, r, rigid, grid=None, lattice=None) -> ca.MX:
    """The loss of one folded state's coarse lattice r against its target: a curvature
    target's :func:`.curvature_loss.curvature_residuals`, else :func:`loss_residuals`
    after the alignment ``rigid`` (q, t) (7,), against the target lattice ``lattice``
    (Tx, Ty, Tz) where given, else at the controls ``grid`` (Cu, Cv) of a free
    correspondence, else the fixed one (``grid`` None)."""
    if setup.curvature is not None:
        return curvature_residuals(r, setup.curvature)
    target = (lattice if lattice is not None else setup.target if grid is None
              else setup.correspondence.lattice(*grid))
    return loss_residuals(r, rotation_from_quaternion(rigid[:4]), rigid[4:], target,
                          setup.weights, setup.spacing)


def design_residuals(setup: Setup, rigid, boundary_vec, grid=None):
    """The residuals after the loss, functions of the design alone (MX or SX): the
    quaternion normalisation, the Tikhonov term towards the Miura start, a free
    correspondence's Tikhonov term (``grid``: its controls (Cu, Cv), or None) and the
    smoothness of the boundary perturbation (lengths in units of the lattice spacing)."""
    q = rigid[:4]
    ref = setup.reference_vector
    nl = setup.reference.N + setup.reference.M
    scale = np.concatenate([np.ones(ref.size - nl - 1), np.full(nl, 1 / setup.spacing), [1.0]])
    delta = (boundary_vec - ref) * scale
    out = [ca.sumsqr(q) - 1,  # fixes the quaternion's free scale
           np.sqrt(setup.weights.get("regularization", 0) / scale.size) * delta]
    if grid is not None:
        out.append(setup.correspondence.residuals(
            *grid, correspondence.GRID_REGULARIZATION * setup.weights.get("regularization", 0)))
    if setup.weights.get("smoothness", 0) > 0:
        kinks = smoothness_residuals(delta, setup.reference.N, setup.reference.M)
        out.append(np.sqrt(setup.weights["smoothness"] / kinks.numel()) * kinks)
    return ca.vertcat(*out)


def smoothness_residuals(delta: Scalar, N: int, M: int) -> Scalar:
    """Second differences of a boundary perturbation along the left and the bottom edge.

    ``delta`` follows :meth:`BoundaryData.to_vector` (alphas, betas, then l_left, l_bottom;
    a trailing omega is ignored). Angles are differenced along the left edge (N+1 vertices)
    and along the bottom edge with the corner (M+1 vertices); the lengths along each edge.
    Zero exactly when the perturbation is affine along every edge.
    """
    nv = N + 1 + M

    def second(v):
        return v[2:] - 2 * v[1:-1] + v[:-2]

    parts = []
    for k in (0, nv):  # alpha, then beta
        parts += [second(delta[k:k + N + 1]),
                  second(ca.vertcat(delta[k], delta[k + N + 1:k + nv]))]
    parts += [second(delta[2 * nv:2 * nv + N]), second(delta[2 * nv + N:2 * nv + N + M])]
    return ca.vertcat(*parts)
