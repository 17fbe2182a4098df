"""The crease pattern produced by marching (one container shared by both forward models),
the fold parameter omega's validator, :func:`check_omega`, and the omegas of a folding
motion, :func:`motion_omegas`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .boundary import BoundaryData
from .errors import InputError


def check_omega(omega: Any, name: str = "omega") -> np.ndarray:
    """The fold parameter(s) ``omega`` validated: a float array of shape () or (K,).

    ``omega`` is gamma_1 of vertex (1, 1) (eq:foldParams): a finite number, or a 1-D
    sequence of numbers, in [-pi, pi]. ``name`` is the argument or key named in the error.
    Raises :class:`InputError` (one line) otherwise.
    """
    allowed = f"{name} must be a number or a non-empty 1-D list of numbers in [-pi, pi]"
    try:
        raw = np.asarray(omega)
    except ValueError:  # ragged nested lists
        raise InputError(f"{allowed}, got a ragged list") from None
    if raw.dtype.kind not in "iuf":
        raise InputError(f"{allowed}, got {type(omega).__name__}")
    if raw.ndim > 1 or raw.size == 0:
        raise InputError(f"{allowed}, got shape {raw.shape}")
    arr = raw.astype(float)
    bad = ~np.isfinite(arr) | (np.abs(arr) > np.pi)
    if bad.any():
        raise InputError(f"{name} must lie in [-pi, pi], got {float(arr[bad].ravel()[0])!r}")
    return arr


def check_frames(frames: int, minimum: int = 1, name: str = "frames") -> int:
    """``frames``, a number of states of a folding motion, checked to be an integer (not a
    bool) of at least ``minimum``; ``name`` is the argument or option named in the error.
    Raises :class:`InputError` (one line) otherwise."""
    if (isinstance(frames, bool) or not isinstance(frames, (int, np.integer))
            or frames < minimum):
        raise InputError(f"{name} must be an integer >= {minimum}, got {frames!r}")
    return int(frames)


def motion_omegas(omega_end: float, frames: int, minimum: int = 1,
                  name: str = "frames") -> np.ndarray:
    """The fold parameters of a folding motion: ``frames`` values evenly from flat
    (omega = 0) to ``omega_end``, (frames,). ``frames`` is checked by :func:`check_frames`
    (``minimum``, ``name``), ``omega_end`` by :func:`check_omega`."""
    count = check_frames(frames, minimum, name)
    return np.linspace(0.0, float(check_omega(omega_end, "omega_end")), count)


@dataclass(frozen=True)
class Pattern:
    """A marched RFFQM crease pattern of N x M panels.

    Vertex (i, j) (1-based) is stored at ``[i-1, j-1]``.

    * ``alpha, beta, sigma`` (N+1, M+1): a-role triple of every vertex (docs/paper.md s.1);
    * ``lh`` (N+1, M): length of the horizontal edge (i, j) -> (i, j+1), i.e. l_ac of panel
      (i, j) and l_bd of panel (i-1, j);
    * ``lv`` (N, M+1): length of the vertical edge (i, j) -> (i+1, j), i.e. l_ab of panel
      (i, j) and l_cd of panel (i, j-1);
    * ``mu`` (N, M): the multiplier mu_abc of every panel (eq:muABC);
    * ``X`` (N+1, M+1, 3): flat vertex positions, x_a^{11} = 0, x_c^{11} on +e1, z = 0.
    """

    alpha: np.ndarray
    beta: np.ndarray
    sigma: np.ndarray
    lh: np.ndarray
    lv: np.ndarray
    mu: np.ndarray
    X: np.ndarray

    def __post_init__(self) -> None:
        for name in ("alpha", "beta", "sigma", "lh", "lv", "mu", "X"):
            arr = np.array(getattr(self, name), dtype=float)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def N(self) -> int:
        """Number of panel rows."""
        return self.alpha.shape[0] - 1

    @property
    def M(self) -> int:
        """Number of panel columns."""
        return self.alpha.shape[1] - 1

    @property
    def panel_angles(self) -> np.ndarray:
        """Interior angles (alpha_a, alpha_b, alpha_c, alpha_d) of every panel, (N, M, 4)."""
        a, b = self.alpha, self.beta
        return np.stack([a[:-1, :-1], np.pi - b[1:, :-1], b[:-1, 1:], np.pi - a[1:, 1:]],
                        axis=-1)

    @property
    def boundary(self) -> BoundaryData:
        """The boundary data this pattern was marched from."""
        tri = np.stack([self.alpha, self.beta, self.sigma], axis=-1)
        return BoundaryData(tri[:, 0], tri[0, 1:], self.lv[:, 0], self.lh[0, :])

    @property
    def sector_angles(self) -> np.ndarray:
        """All sector angles of the pattern: every panel's four interior angles, flattened."""
        return self.panel_angles.ravel()

    @property
    def side_lengths(self) -> np.ndarray:
        """All edge lengths of the pattern, horizontal then vertical, flattened."""
        return np.concatenate([self.lh.ravel(), self.lv.ravel()])

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {k: getattr(self, k).tolist()
                for k in ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")}

    @classmethod
    def from_dict(cls, d: dict) -> "Pattern":
        """Inverse of :meth:`to_dict`."""
        return cls(**{k: np.asarray(d[k], dtype=float)
                      for k in ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")})
