"""Vector arithmetic over short axes, written out by component for the contact checks.

NumPy's reductions over a short axis (length 3 or 4) are several times slower than the
same sums, minima and maxima spelt out; every function here takes and returns arrays of
any leading shape and does nothing else.
"""

from __future__ import annotations

import numpy as np


def dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (length 3), broadcast."""
    return u[..., 0] * v[..., 0] + u[..., 1] * v[..., 1] + u[..., 2] * v[..., 2]


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Cross products over the last axis (length 3), broadcast."""
    u0, u1, u2, v0, v1, v2 = u[..., 0], u[..., 1], u[..., 2], v[..., 0], v[..., 1], v[..., 2]
    return np.stack([u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0], axis=-1)


def norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms over the last axis (length 3)."""
    return np.sqrt(dot(v, v))


def column_norm(v: np.ndarray) -> np.ndarray:
    """Euclidean norms over the first axis (length 3) of v (3, ...): the lengths of vectors
    stored as the rows of a table, one column per panel."""
    return np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def least(x: np.ndarray) -> np.ndarray:
    """Minimum over the (short) last axis, elementwise over its entries."""
    out = x[..., 0]
    for k in range(1, x.shape[-1]):
        out = np.minimum(out, x[..., k])
    return out


def most(x: np.ndarray) -> np.ndarray:
    """Maximum over the (short) last axis, elementwise over its entries."""
    out = x[..., 0]
    for k in range(1, x.shape[-1]):
        out = np.maximum(out, x[..., k])
    return out


def least_of(xs: list[np.ndarray]) -> np.ndarray:
    """Elementwise minimum of the arrays xs (all of one shape)."""
    out = xs[0]
    for x in xs[1:]:
        out = np.minimum(out, x)
    return out


def most_of(xs: list[np.ndarray]) -> np.ndarray:
    """Elementwise maximum of the arrays xs (all of one shape)."""
    out = xs[0]
    for x in xs[1:]:
        out = np.maximum(out, x)
    return out
