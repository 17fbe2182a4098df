"""The derivatives of the marching manifold at a point: the state's sensitivity S = ds/dd
in the state rows a step reads (:class:`Sensitivity`), and the reduced problem's Jacobian,
J' J, J' r and damping metric built from it (:class:`Linearization`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ...stencils import Lift
from .levels import Levels


@dataclass
class Sensitivity:
    """S B at a point, S = ds/dd and B the design's ``basis`` (n_d x n_u), in the state
    rows ``read`` (n_read,: those the residuals' Jacobian, the inequality rows and the
    state bounds read, :attr:`.manifold.Manifold.read`; no step needs the others): by the
    sweeps through the ``levels``, or by products with those rows of S B where the pass kept
    it whole (``whole``, (n_read, n_m): its marching columns ``marching``, (n_m,); S B is
    zero in the other, free, columns)."""

    levels: Levels
    whole: np.ndarray | None
    marching: np.ndarray
    basis: sp.csr_matrix
    read: np.ndarray

    def forward(self, X: np.ndarray) -> np.ndarray:
        """(S B X)[read] (n_read,) or (n_read, p) for X (n_u,) or (n_u, p)."""
        if self.whole is None:
            return self.levels.forward(self.basis @ X)[self.read]
        return self.whole @ X[self.marching]

    def adjoint(self, Y: np.ndarray) -> np.ndarray:
        """B' S' Y (n_u,) or (n_u, p) for Y (n_read,) or (n_read, p) in the rows read."""
        if self.whole is None:
            Z = np.zeros((self.levels.n_s,) + Y.shape[1:])
            Z[self.read] = Y
            return self.basis.T @ self.levels.adjoint(Z)
        out = np.zeros((self.basis.shape[1],) + Y.shape[1:])
        out[self.marching] = self.whole.T @ Y
        return out

    def rows(self, R: sp.csr_matrix) -> np.ndarray:
        """R (S B)[read] (k, n_u) for R (k, n_read) in the rows read."""
        if self.whole is None:
            coo = R.tocoo()
            Z = np.zeros((self.levels.n_s, R.shape[0]))
            Z[self.read[coo.col], coo.row] = coo.data
            return (self.basis.T @ self.levels.adjoint(Z)).T
        out = np.zeros((R.shape[0], self.basis.shape[1]))
        out[:, self.marching] = R @ self.whole
        return out


@dataclass
class Linearization:
    """The derivatives at a point in the design's coordinates u (n_u, the manifold's
    ``basis`` B maps them to the design, dd = B du): the sparse Jacobians of r and g split
    by design and state columns (J_design, J_state; the inequality rows' G_design,
    G_state; the design columns times B, the state columns only the n_read that any of
    them reads, :attr:`.manifold.Manifold.read`), S B with S = ds/dd in those rows
    (``sensitivity``: applied to a block, and its transpose), and the reduced problem's
    J' J, J' r and the metric's B' S_p' D_p S_p B (n_u x n_u, n_u; the last None when
    linearised without it), accumulated level by level (:class:`.window.Window`) without
    storing S (unless it is small). With a lifted residual Jacobian
    (:class:`rffqm_nlp.design.stencils.LiftedJacobian`), J_design holds its direct part and
    ``lift`` the rest, F_u H, its columns numbered in u. Valid until the manifold linearises
    at the next point (the levels are refilled there)."""

    J_design: sp.csr_matrix
    J_state: sp.csr_matrix
    G_design: sp.csr_matrix
    G_state: sp.csr_matrix
    sensitivity: Sensitivity
    JtJ: np.ndarray
    grad: np.ndarray
    pattern_metric: np.ndarray | None
    lift: Lift | None

    def jacobian_times(self, X: np.ndarray) -> np.ndarray:
        """Jr X (n_r,) or (n_r, p) for X (n_u,) or (n_u, p), Jr = J_design + J_state S B
        (+ F_u H) the reduced Jacobian."""
        out = self.J_design @ X + self.J_state @ self.sensitivity.forward(X)
        if self.lift is not None:
            out[self.lift.rows] += self.lift.times(X)
        return out

    def jacobian_transpose(self, w: np.ndarray) -> np.ndarray:
        """Jr' w (n_u,) for w (n_r,)."""
        out = self.J_design.T @ w + self.sensitivity.adjoint(self.J_state.T @ w)
        if self.lift is not None:
            out[self.lift.columns] += self.lift.transpose_times(w)
        return out

    def state_change(self, du: np.ndarray) -> np.ndarray:
        """(S B du)[read] (n_read,): the first-order change of the state rows read
        (:attr:`.manifold.Manifold.read`) under the step du (n_u,)."""
        return self.sensitivity.forward(du)
