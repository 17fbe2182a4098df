"""What a transcription states from a design problem and its start (:class:`Setup`): the
initial guess, the target lattice, the weights, the bounds and the held mountain-valley
pattern; and the weights D of the Levenberg-Marquardt term (:func:`damping_weights`)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np

from ...model import vertex as vx
from ...model.boundary import BoundaryData
from ...model.marching import boundary_inputs, evaluate, pattern_function
from .correspondence import Correspondence
from .curvature_loss import CurvatureLoss


@dataclass(frozen=True)
class Setup:
    """Everything a transcription needs, derived from a DesignProblem and its start."""

    boundary: BoundaryData  # the initial guess (the Miura start, or a warm start)
    omega: float
    rotation: np.ndarray  # rigid alignment of the start onto the target
    translation: np.ndarray
    target: np.ndarray  # (N+1, M+1, 3) target lattice
    spacing: float
    weights: dict
    min_angle: float
    min_length: float
    mu_margin: float
    omega_bounds: tuple[float, float]
    fixed: tuple[str, ...]
    reference: BoundaryData  # the Miura start: Tikhonov reference and MV pattern
    reference_omega: float
    correspondence: Correspondence | None = None  # None: the target lattice is fixed
    controls: np.ndarray | None = None  # a warm start's controls (None: the uniform grid's)
    curvature: CurvatureLoss | None = None  # a curvature target's loss, in place of the lattice's

    def controls0(self) -> np.ndarray:
        """The initial guess's controls of the free correspondence (2 Ku Kv,)."""
        return self.correspondence.start() if self.controls is None else self.controls

    @property
    def reference_vector(self) -> np.ndarray:
        """The Tikhonov reference: boundary data vector and omega of the Miura start."""
        return np.concatenate([self.reference.to_vector(), [self.reference_omega]])

    @cached_property
    def mu_outside(self) -> np.ndarray:
        """Per panel (column-major): is |mu_abc| above 1 at the Miura start? (held)"""
        mu0 = evaluate(pattern_function(self.reference.N, self.reference.M),
                       boundary_inputs(self.reference))[5]
        return np.abs(mu0.ravel(order="F")) > 1

    def mu_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of sign * (mu^2 - 1) with sign = +1 above 1 and -1 below."""
        out, m = self.mu_outside, self.mu_margin
        return np.where(out, (1 + m) ** 2 - 1, 1 - (1 - m) ** 2), np.full(out.size, np.inf)

    @cached_property
    def mv_sign(self) -> np.ndarray:
        """Per boundary vertex (left then bottom): the sign of :func:`vertex.mv_multiplier` at
        the Miura start (held)."""
        ang = self.reference.angles
        return np.sign(vx.mv_multiplier(ang[:, 0], ang[:, 1], self.reference.sigma))

    def boundary_mv(self, alpha: ca.MX, beta: ca.MX) -> tuple[ca.MX, np.ndarray, np.ndarray]:
        """The boundary MV assignment held: sign * mv_multiplier >= mu_margin at every
        boundary vertex (alpha, beta: N+1+M vectors, left then bottom). With the mu
        constraints this holds the M/V of every crease (no counterexample in 4,400 random
        marchable perturbations; a property test in tests/test_marching.py). Returns
        (g, lbg, ubg)."""
        g = ca.DM(self.mv_sign) * vx.mv_multiplier(alpha, beta, self.reference.sigma)
        n = self.mv_sign.size
        return g, np.full(n, self.mu_margin), np.full(n, np.inf)

    def rigid0(self) -> np.ndarray:
        """The start's alignment as the NLP's variables (q, t) (7,)."""
        return np.concatenate([quaternion_from_rotation(self.rotation), self.translation])


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """A unit quaternion (w, x, y, z) (4,) of the rotation matrix R (3, 3)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def damping_weights(setup: Setup, lengths: np.ndarray) -> np.ndarray:
    """D of :func:`rffqm_nlp.design.solvers.ipopt.hessians.gauss_newton_hessian` and of
    :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`: 1 / (s^2 n) per variable, s the
    lattice spacing for lengths and positions (``lengths`` marks them) and 1 for angles and
    quaternions, n the number of lattice points. The Levenberg-Marquardt term then weighs a
    change of one spacing or one radian like the position term (a mean over the lattice
    points) weighs an error of one spacing, whatever the target's size and the pattern's."""
    s = np.where(lengths, setup.spacing, 1.0)
    return 1.0 / (s ** 2 * setup.target.shape[0] * setup.target.shape[1])
