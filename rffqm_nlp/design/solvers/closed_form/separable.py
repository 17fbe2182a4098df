"""A target's curvatures and steps along its lattice's two directions, and their best
separable approximation (docs/closed_form.md s.6).

The closed form bends the pattern along x (the lattice's i, a target's u) by kx(x) alone
and along y (j, v) by ky(y) alone, with step lengths that depend on one index each. A
target gives fields of both indices; "best" here is least squares over the lattice's
points, each point weighing the same: kx(i) is the mean of the target's curvature along
i over the points of row i, and so on.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....errors import InputError
from ....files import Key, check_value
from ....model.backend import finite_array, finite_result
from ....targets.parametric import Surface, check_surface


@dataclass(frozen=True)
class Separable:
    """The best separable approximation of the curvatures (k_u, k_v), each (N+1, M+1):
    ``kx`` (N+1,) and ``ky`` (M+1,) minimise sum (k_u[i, j] - kx[i])^2 and
    sum (k_v[i, j] - ky[j])^2 (the means over the other index); ``residual`` is the root
    mean square of what they leave out over that of (k_u, k_v) (0: separable; 1/length
    units cancel), 0 for zero fields."""

    kx: np.ndarray
    ky: np.ndarray
    residual: float


def curvatures_along_lattice(target: Surface, N: int, M: int) -> tuple[np.ndarray, np.ndarray]:
    """(k_u, k_v), each (N+1, M+1): the target's normal curvatures along its lattice's
    two directions at the points of :meth:`~rffqm_nlp.targets.parametric.Surface.lattice`
    (N, M) (uniform in parameters over the whole domain), against its normal r_u x r_v:
    k_u = L / E, k_v = N / G (1 / length). Where the parameter lines are lines of curvature
    (F = M = 0) these are the principal curvatures. Raises :class:`InputError` for a target
    that is not a surface or N, M that are not whole numbers >= 1."""
    check_surface(target, "target")
    N = check_value(N, Key("whole", low=1), "N")
    M = check_value(M, Key("whole", low=1), "M")
    u, v = target.lattice_uv(N, M)
    E, _, G, L, _, Nn = target.fundamental_forms(u[:, None], v[None, :])
    return L / E, Nn / G


def separable_curvatures(k_u: np.ndarray, k_v: np.ndarray) -> Separable:
    """The :class:`Separable` approximation of the curvature fields k_u along i and k_v
    along j, each (n, m) with n, m >= 2 (finite numbers; else :class:`InputError`)."""
    k_u = finite_array(k_u, "k_u", ndim=2, least=1)
    k_v = finite_array(k_v, "k_v", shape=k_u.shape)
    if 0 in k_u.shape:
        raise InputError(f"k_u and k_v must hold at least one row and column, got {k_u.shape}")
    with np.errstate(all="ignore"):
        kx, ky = k_u.mean(axis=1), k_v.mean(axis=0)
        left = np.concatenate([(k_u - kx[:, None]).ravel(), (k_v - ky[None, :]).ravel()])
        scale = np.sqrt(np.mean(np.concatenate([k_u.ravel(), k_v.ravel()]) ** 2))
        residual = float(np.sqrt(np.mean(left ** 2)) / scale) if scale > 0 else 0.0
    finite_result((kx, ky, residual), "the curvatures are too large for floating point")
    return Separable(kx=kx, ky=ky, residual=residual)


def lattice_steps(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(steps along i (n-1,), steps along j (m-1,)): the mean distance between neighbours
    of each pair of consecutive rows and of columns of the lattice ``points`` (n, m, 3),
    the least-squares steps of a lattice whose steps depend on one index each."""
    P = finite_array(points, "points", shape=(None, None, 3))
    if min(P.shape[:2]) < 2:
        raise InputError(f"points must be a lattice of at least 2 x 2 points, got {P.shape}")
    along_i = np.linalg.norm(P[1:] - P[:-1], axis=-1).mean(axis=1)
    along_j = np.linalg.norm(P[:, 1:] - P[:, :-1], axis=-1).mean(axis=0)
    return along_i, along_j
