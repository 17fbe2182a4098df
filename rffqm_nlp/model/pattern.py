"""The crease pattern produced by marching (one container shared by both forward models),
the fold parameter omega's validators, :func:`check_omega` and :func:`check_fold_angle`,
the pattern argument's, :func:`check_pattern`, and the omegas of a folding motion,
:func:`motion_omegas`."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from .. import memory
from .backend import finite_array, finite_result
from .boundary import BoundaryData
from ..errors import InputError
from ..files import Key, check_value, describe_value

#: Most states of a folding motion (:func:`check_frames`).
MAX_FRAMES = 100_000
#: Bytes per panel that a march holds at its peak (work arrays, the pattern) and per
#: vertex and state that a fold holds (rotated edges, their sums, the states), in either
#: forward model: upper bounds of what their arrays take. A call whose total exceeds the
#: memory this machine has left is refused before any work (:func:`check_march_memory`,
#: :func:`check_fold_memory`; looked up from :data:`MEMORY_CHECK_FROM` bytes on, so small
#: calls do not read /proc).
MARCH_BYTES_PER_PANEL, FOLD_BYTES_PER_STATE = 1000.0, 400.0
MEMORY_CHECK_FROM = 1e8


_COUNT = Key("whole", low=0, high=2**63)


def check_march_memory(N: int, M: int) -> None:
    """Refuse (:class:`InputError`) a march of N x M panels that this machine cannot hold."""
    N, M = check_value(N, _COUNT, "N"), check_value(M, _COUNT, "M")
    need = MARCH_BYTES_PER_PANEL * float(N) * M
    if need > MEMORY_CHECK_FROM:
        memory.refuse_beyond(need, f"a march of {N} x {M} panels", "choose fewer panels")


def check_fold_memory(N: int, M: int, states: int) -> None:
    """Refuse (:class:`InputError`) ``states`` folded states of N x M panels that this
    machine cannot hold."""
    N, M = check_value(N, _COUNT, "N"), check_value(M, _COUNT, "M")
    states = check_value(states, _COUNT, "states")
    need = FOLD_BYTES_PER_STATE * float(states) * (N + 1) * (M + 1)
    if need > MEMORY_CHECK_FROM:
        memory.refuse_beyond(need, f"{states} folded states of {N} x {M} panels",
                             "choose fewer panels or fewer omegas")


def check_folded(Y: Any) -> Any:
    """``Y``, folded states or fold angles, unless an entry is NaN or infinite: then
    :class:`InputError` (a pattern that was not marched: a vertex with sigma outside
    MV(alpha, beta), or sides too large for floating point)."""
    return finite_result(Y, "the pattern has no finite folded state: some vertex has sigma "
                            "outside MV(alpha, beta) (a fold-angle multiplier 0 or infinite) "
                            "or its sides are too large for floating point; fold a pattern "
                            "marched from admissible boundary data (rffqm_nlp.march)")


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


def check_fold_angle(omega: Any, name: str = "omega") -> float:
    """One fold parameter ``omega`` validated: a single finite number in [-pi, pi], as a
    float (:func:`check_omega`, which also takes a list, for a single state). Raises
    :class:`InputError` (one line) otherwise."""
    arr = check_omega(omega, name)
    if arr.ndim:
        raise InputError(f"{name} must be a single number in [-pi, pi], got a list of "
                         f"{arr.size} numbers")
    return float(arr)


def check_frames(frames: int, minimum: int = 1, name: str = "frames") -> int:
    """``frames``, a number of states of a folding motion, checked to be a whole number (not
    a bool) in [``minimum``, :data:`MAX_FRAMES`]; ``name`` is the argument or option named
    in the error. Raises :class:`InputError` (one line) otherwise."""
    minimum = check_value(minimum, Key("whole", low=0, high=MAX_FRAMES), "minimum")
    return check_value(frames, Key("whole", low=minimum, high=MAX_FRAMES), name)


def check_pattern(pat: Any, name: str = "pattern") -> "Pattern":
    """``pat`` if it is a :class:`Pattern`, else an :class:`InputError` naming ``name`` and
    what it got (boundary data, a dict, ...)."""
    if not isinstance(pat, Pattern):
        hint = (" (march it first: rffqm_nlp.march(bd))" if isinstance(pat, BoundaryData)
                else "")
        raise InputError(f"{name} must be a crease pattern (rffqm_nlp.Pattern){hint}, got "
                         f"{describe_value(pat)}")
    return pat


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
        arrays = {name: _field(getattr(self, name), name) for name in _FIELDS}
        alpha = arrays["alpha"]
        if alpha.ndim != 2 or min(alpha.shape) < 2:
            raise InputError(f"Pattern alpha must have shape (N+1, M+1) with N, M >= 1, got "
                             f"shape {alpha.shape}")
        N, M = alpha.shape[0] - 1, alpha.shape[1] - 1
        shapes = {"beta": (N + 1, M + 1), "sigma": (N + 1, M + 1), "lh": (N + 1, M),
                  "lv": (N, M + 1), "mu": (N, M), "X": (N + 1, M + 1, 3)}
        for name, shape in shapes.items():
            if arrays[name].shape != shape:
                raise InputError(f"Pattern {name} must have shape {shape} for the {N} x {M} "
                                 f"panels of its alpha, got shape {arrays[name].shape}")
        for name, arr in arrays.items():
            if not _holds(name, arr):     # NaN fails every comparison, so it lands here too
                _refuse(name, arr)
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @classmethod
    def _made(cls, **arrays: np.ndarray) -> "Pattern":
        """The pattern a march made from checked boundary data (float arrays of the right
        shapes and admissible values, by the march's checks): not checked again, so that a
        march costs what it did."""
        pat = object.__new__(cls)
        for name in _FIELDS:
            arr = np.array(arrays[name], dtype=float)
            arr.setflags(write=False)
            object.__setattr__(pat, name, arr)
        return pat

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
        if not isinstance(d, Mapping):
            raise InputError(f"a pattern must be a table of {', '.join(_FIELDS)}, got "
                             f"{describe_value(d)}")
        for k in _FIELDS:
            if k not in d:
                raise InputError(f"the pattern is missing the field {k!r}")
        return cls(**{k: d[k] for k in _FIELDS})


def _field(value: Any, name: str) -> np.ndarray:
    """The Pattern array ``name`` as a new float array (a NumPy array of numbers the quick
    way, anything else through :func:`finite_array` and its messages); its values are
    checked by :func:`_holds`."""
    if isinstance(value, np.ndarray) and value.dtype.kind in "iuf":
        return np.array(value, dtype=float)
    return finite_array(value, f"Pattern {name}", allowed=_FIELDS[name])


def _holds(name: str, arr: np.ndarray) -> bool:
    """Whether the Pattern array ``name`` holds admissible values: angles in [0, pi], signs
    +1 or -1, finite positive lengths, finite mu and X (a few reductions, no temporaries
    for the angles and lengths: patterns are made by every march)."""
    if name in ("alpha", "beta"):
        return bool(0.0 <= arr.min() and arr.max() <= np.pi)
    if name == "sigma":
        return bool((arr * arr == 1.0).all())
    if name in ("lh", "lv"):
        return bool(0.0 < arr.min() and arr.max() < np.inf)
    return bool(np.isfinite(arr).all())


def _refuse(name: str, arr: np.ndarray) -> None:
    """Raise the one-line error for the first entry of ``arr`` that :func:`_holds` refuses."""
    finite_array(arr, f"Pattern {name}", allowed=_FIELDS[name])      # NaN or infinity
    bad, what = {"alpha": ((arr < 0) | (arr > np.pi), "lie in [0, pi]"),
                 "beta": ((arr < 0) | (arr > np.pi), "lie in [0, pi]"),
                 "sigma": (np.abs(arr) != 1, "be +1 or -1"),
                 "lh": (arr <= 0, "be positive lengths"),
                 "lv": (arr <= 0, "be positive lengths")}[name]
    at = tuple(int(k) for k in np.unravel_index(int(np.argmax(bad)), bad.shape))
    raise InputError(f"Pattern {name} must {what}, got {arr[at]:g} at index {at}")


#: The arrays of a :class:`Pattern` and what each holds.
_FIELDS = {"alpha": "sector angles alpha (N+1, M+1) in [0, pi]",
           "beta": "sector angles beta (N+1, M+1) in [0, pi]",
           "sigma": "mountain-valley signs (N+1, M+1) of +1 or -1",
           "lh": "horizontal side lengths (N+1, M), finite and positive",
           "lv": "vertical side lengths (N, M+1), finite and positive",
           "mu": "finite multipliers mu_abc (N, M)",
           "X": "finite flat positions (N+1, M+1, 3)"}
