"""The softest modes of a stiffness matrix by sparse shift-invert Lanczos
(:func:`scipy.sparse.linalg.eigsh`), never a dense eigensolver, and the folding mode's own
stiffness beside them.

A mode is a zero mode when its eigenvalue is at most :data:`ZERO` times the largest
eigenvalue. The folding mode's stiffness is the Rayleigh quotient of the exact folding
velocity after its rigid-body part is removed (rigid motions cost nothing), so it compares
with the eigenvalues of the non-rigid modes: it is at least the softest of them, and equal
to it when the folding mode is the softest non-rigid mode.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, eigsh, splu

#: An eigenvalue at most this times the largest one counts as zero.
ZERO = 1e-12
#: The shift-invert shift: minus this times the largest eigenvalue (K - sigma I is then
#: positive definite and its factorisation well defined with zero modes present).
SHIFT = 1e-10
#: Relative accuracy of the largest eigenvalue's Lanczos estimate: it only scales the zero
#: test, which a 1% error does not move.
LARGEST_TOL = 1e-2


@dataclass(frozen=True)
class Modes:
    """The k softest modes of a bar-and-hinge model.

    * ``values`` (k,): eigenvalues in N/m, ascending (vectors of unit Euclidean norm over
      all 3 n_nodes displacements, in metres);
    * ``vectors`` (3 n_nodes, k): the modes, node by node, x, y, z;
    * ``largest``: the largest eigenvalue (N/m);
    * ``zero_count``: how many values are at most :data:`ZERO` * ``largest``;
    * ``folding``: the folding mode's own stiffness (N/m), the Rayleigh quotient of the
      exact folding velocity without its rigid-body part;
    * ``folding_overlap``: the part of that velocity (without its rigid-body part, unit
      length) in the span of the modes up to the softest non-rigid one (the zero modes
      included): 1 when the folding mode is that mode, near 0 when another is softer;
    * ``softer_than_folding``: how many of the k computed non-rigid modes are softer than
      the folding mode by more than 0.1% (0 where the folding mode is the softest
      non-rigid mode; when it equals the computed non-rigid modes, more may be softer).
    """

    values: np.ndarray
    vectors: np.ndarray
    largest: float
    zero_count: int
    folding: float
    folding_overlap: float
    softer_than_folding: int

    @property
    def relative(self) -> np.ndarray:
        """The values over the largest eigenvalue (k,)."""
        return self.values / self.largest


def rigid_motions(P: np.ndarray) -> np.ndarray:
    """An orthonormal basis (3 n_nodes, 6) of the rigid motions of nodes at ``P``
    (n_nodes, 3): three translations and three rotations about the centroid."""
    n = len(P)
    r = P - P.mean(axis=0)
    basis = np.zeros((n, 3, 6))
    basis[:, :, :3] = np.eye(3)
    for k in range(3):
        basis[:, :, 3 + k] = np.cross(np.eye(3)[k], r)
    q, _ = np.linalg.qr(basis.reshape(3 * n, 6))
    return q


def deformation(velocity: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``velocity`` (3 n_nodes,) without its rigid-body part (:func:`rigid_motions`)."""
    rigid = rigid_motions(P)
    return velocity - rigid @ (rigid.T @ velocity)


def folding_energy(K: sp.spmatrix, velocity: np.ndarray, P: np.ndarray) -> float:
    """The folding mode's own stiffness (N/m): the Rayleigh quotient of ``velocity``
    (3 n_nodes,) without its rigid-body part, under ``K``; nodes at ``P`` (n_nodes, 3)."""
    deform = deformation(velocity, P)
    return float(deform @ (K @ deform) / (deform @ deform))


def factorized(A: sp.spmatrix):
    """The sparse LU factorisation of the symmetric ``A`` (SuperLU in its symmetric mode,
    minimum-degree ordering of A^T + A, diagonal pivots): its ``solve`` gives A^-1 b."""
    return splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                options={"SymmetricMode": True})


def largest_eigenvalue(K: sp.spmatrix) -> float:
    """The largest eigenvalue of the symmetric positive semidefinite ``K`` (Lanczos)."""
    value = eigsh(K, k=1, which="LA", tol=LARGEST_TOL, return_eigenvectors=False)
    return float(value[0])


def softest_modes(K: sp.spmatrix, k: int, velocity: np.ndarray, P: np.ndarray) -> Modes:
    """The ``k`` softest modes of ``K`` (3 n_nodes square, N/m) by shift-invert Lanczos,
    with the folding mode of ``velocity`` (3 n_nodes,) compared (:class:`Modes`); ``P``
    (n_nodes, 3) are the node positions (for the rigid motions)."""
    largest = largest_eigenvalue(K)
    shift = SHIFT * largest
    lu = factorized(K + shift * sp.identity(K.shape[0]))
    inverse = LinearOperator(K.shape, matvec=lu.solve, dtype=float)
    values, vectors = eigsh(K, k=k, sigma=-shift, which="LM", OPinv=inverse)
    order = np.argsort(values)
    values, vectors = values[order], vectors[:, order]
    zero = int(np.sum(values <= ZERO * largest))
    deform = deformation(velocity, P)
    folding = float(deform @ (K @ deform) / (deform @ deform))
    overlap, softer = 0.0, 0
    if k > 6:
        # the eigenspace up to the softest non-rigid eigenvalue (the zero modes included)
        low = values <= values[6] + max(1e-6 * values[6], ZERO * largest)
        overlap = float(np.linalg.norm(vectors[:, low].T @ deform) / np.linalg.norm(deform))
        softer = int(np.sum(values[max(zero, 6):] < folding * (1 - 1e-3)))
    return Modes(values, vectors, largest, zero, folding, overlap, softer)
