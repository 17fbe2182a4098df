"""Shared geometry helpers for the tests (independent of the package's marching code)."""

from __future__ import annotations

import numpy as np
from hypothesis import assume, strategies as st


def fit_is_finite(fit) -> bool:
    """Whether every measure of a :class:`rffqm_nlp.Fit` that was measured is finite."""
    return bool(np.all(np.isfinite([v for v in fit.to_dict().values()
                                    if v is not None and not isinstance(v, bool)])))


def panel_distances(P: np.ndarray) -> np.ndarray:
    """Four sides and two diagonals of every panel of a vertex lattice, (6, N, M)."""
    a, b, c, d = P[:-1, :-1], P[1:, :-1], P[:-1, 1:], P[1:, 1:]
    pairs = [(a, b), (a, c), (b, d), (c, d), (a, d), (b, c)]
    return np.stack([np.linalg.norm(x - y, axis=-1) for x, y in pairs])


def panel_rotations(X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Rotation of every panel taking its flat corners X to folded corners Y, (N, M, 3, 3)."""
    def frame(P):
        e1 = P[:-1, 1:] - P[:-1, :-1]
        e2 = P[1:, :-1] - P[:-1, :-1]
        n = np.cross(e1, e2)
        return np.stack([e1, e2, n], axis=-1)
    return frame(Y) @ np.linalg.inv(frame(X))


@st.composite
def admissible_vertex(draw, margin: float = 0.05):
    """(alpha, beta, sigma) with angles in (margin, pi - margin) and sigma in MV with margin."""
    a = draw(st.floats(margin, np.pi - margin))
    b = draw(st.floats(margin, np.pi - margin))
    options = [s for s in (1.0, -1.0) if abs(np.cos(b) - s * np.cos(a)) > margin]
    assume(options)
    return a, b, draw(st.sampled_from(options))
