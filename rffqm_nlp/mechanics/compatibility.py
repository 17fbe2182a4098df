"""Compatibility matrices of a bar-and-hinge frame at given node positions: the rigidity
matrix of the bars and the Jacobian of the hinges' fold angles.

Both are sparse with three columns per node, x, y, z in that order: node n's columns are
3n, 3n+1, 3n+2. Positions are (n_nodes, 3) in any length unit.

* Bar e from node a to node b: its elongation rate is d_e . (u_a - u_b) with d_e the unit
  vector from b to a, so the rigidity matrix row holds d_e at a and -d_e at b (one row per
  bar, dimensionless).
* Hinge (a, b, p, q) (axis a -> b, wings p and q): the dihedral angle theta in (0, 2 pi) is
  pi where the two triangles (a, b, p) and (a, b, q) are coplanar; its gradient is the
  classical one of Bekker's bending element as Liu and Paulino (Proc. R. Soc. A 473, 2017)
  write it. The fold angle of the hinge is rho = theta - pi: positive where the hinge
  folds as a valley, the convention of :func:`rffqm_nlp.numpy_model.fold_angles`
  (eq:MVAngles) for the hinges of :mod:`.frame` (wing p right of the axis seen from +z in
  the flat pattern).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def rigidity_matrix(P: np.ndarray, bars: np.ndarray) -> sp.csr_matrix:
    """The bars' compatibility matrix (n_bars, 3 n_nodes): row e gives bar e's elongation
    rate for node velocities u (3 n_nodes,) ordered node by node, x, y, z."""
    d = P[bars[:, 0]] - P[bars[:, 1]]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rows = np.repeat(np.arange(len(bars)), 6)
    cols = (3 * bars[:, [0, 0, 0, 1, 1, 1]] + np.array([0, 1, 2, 0, 1, 2])).ravel()
    return sp.csr_matrix((np.concatenate([d, -d], axis=1).ravel(), (rows, cols)),
                         shape=(len(bars), 3 * len(P)))


def bar_lengths(P: np.ndarray, bars: np.ndarray) -> np.ndarray:
    """The lengths of the bars (n_bars,), in the unit of ``P``."""
    return np.linalg.norm(P[bars[:, 0]] - P[bars[:, 1]], axis=1)


def fold_angles(P: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """The fold angle rho = theta - pi in (-pi, pi] of every hinge (n_hinges,): 0 where its
    two triangles are coplanar, positive for a valley (see the module docstring)."""
    axis, r_p, r_q, m, n = _hinge_vectors(P, hinges)
    unit = axis / np.linalg.norm(axis, axis=1, keepdims=True)
    sin = np.einsum("ij,ij->i", np.cross(m, n), unit)
    return np.arctan2(-sin, -np.einsum("ij,ij->i", m, n))


def hinge_jacobian(P: np.ndarray, hinges: np.ndarray) -> sp.csr_matrix:
    """The Jacobian of the hinges' fold angles rho = theta - pi (n_hinges, 3 n_nodes)."""
    axis, r_p, r_q, m, n = _hinge_vectors(P, hinges)
    length2 = np.einsum("ij,ij->i", axis, axis)
    length = np.sqrt(length2)[:, None]
    d_p = length * m / np.einsum("ij,ij->i", m, m)[:, None]
    d_q = -length * n / np.einsum("ij,ij->i", n, n)[:, None]
    s_p = (np.einsum("ij,ij->i", r_p, axis) / length2)[:, None]
    s_q = (np.einsum("ij,ij->i", r_q, axis) / length2)[:, None]
    d_a = (s_p - 1) * d_p - s_q * d_q
    d_b = -s_p * d_p + (s_q - 1) * d_q
    values = np.concatenate([d_a, d_b, d_p, d_q], axis=1)
    rows = np.repeat(np.arange(len(hinges)), 12)
    cols = (3 * np.repeat(hinges, 3, axis=1) + np.tile([0, 1, 2], 4)).ravel()
    return sp.csr_matrix((values.ravel(), (rows, cols)), shape=(len(hinges), 3 * len(P)))


def _hinge_vectors(P: np.ndarray, hinges: np.ndarray):
    """axis = x_b - x_a, r_p = x_p - x_a, r_q = x_b - x_q, m = r_p x axis, n = axis x r_q,
    each (n_hinges, 3), in Liu and Paulino's notation (r_kj, r_ij, r_kl, m, n)."""
    a, b, p, q = (P[hinges[:, k]] for k in range(4))
    axis, r_p, r_q = b - a, p - a, b - q
    return axis, r_p, r_q, np.cross(r_p, axis), np.cross(axis, r_q)
