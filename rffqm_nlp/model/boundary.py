"""Boundary data of the marching algorithm (eq:inputMarching), Miura-ori data, perturbations.

Vertex (i, j) is 1-based as in the paper; every vertex carries its a-role triple
(alpha, beta, sigma): alpha is the sector angle of its upper-right panel, beta that of its
upper-left panel, sigma its mountain-valley sign (docs/paper.md s.1).

Boundary data:

* ``left``     (N+1, 3): (alpha, beta, sigma) of the left vertices (i, 1), i = 1..N+1;
* ``bottom``   (M, 3):   (alpha, beta, sigma) of the bottom vertices (1, j), j = 2..M+1;
* ``l_left``   (N,):     l_ab of the panels (i, 1), i.e. the left side lengths;
* ``l_bottom`` (M,):     l_ac of the panels (1, j), i.e. the bottom side lengths.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from .backend import finite_array
from ..errors import BoundaryDataError, InputError
from ..files import Key, check_value, describe_value

Layout = Literal["zigzag_j", "zigzag_i"]
LAYOUTS: tuple[str, ...] = ("zigzag_j", "zigzag_i")

#: |cos(beta) - sigma cos(alpha)| below this means sigma is not in MV(alpha, beta).
MV_TOL = 1e-10
#: Most panels along one side of a pattern that the API takes (N, M): the boundary data
#: of N x M panels are small, but its march holds every panel, and a side of 100,000
#: already needs far more memory than a workstation has for anything but a thin strip.
MAX_SIDE = 100_000
#: Largest seed of the random perturbations (the [solve] seed's bound).
MAX_SEED = 2**63 - 1

_SIDE = Key("whole", low=1, high=MAX_SIDE, hint="(panels)")
_SEED = Key("whole", low=0, high=MAX_SEED, hint="(or None)")
_ANGLE = Key("number")
_ACUTE = Key("number", low=0.0, high=np.pi / 2, low_open=True, high_open=True,
             hint="(an acute angle, radians)")
_LENGTH = Key("number", low=0.0, low_open=True, hint="(a length)")
_LAYOUT = Key("choice", choices=LAYOUTS)


def check_size(N: Any, M: Any) -> tuple[int, int]:
    """(N, M), a pattern's panel rows and columns, checked: whole numbers in
    [1, :data:`MAX_SIDE`]; else one :class:`InputError` line naming N or M."""
    return check_value(N, _SIDE, "N"), check_value(M, _SIDE, "M")


def check_boundary(bd: Any, name: str = "bd") -> "BoundaryData":
    """``bd`` if it is :class:`BoundaryData`, else an :class:`InputError` naming ``name``
    and what it got (a Pattern, a dict, ...)."""
    if not isinstance(bd, BoundaryData):
        raise InputError(f"{name} must be boundary data (rffqm_nlp.BoundaryData, e.g. from "
                         f"miura_boundary), got {describe_value(bd)}")
    return bd


def mv_set(alpha: float, beta: float, tol: float = MV_TOL) -> tuple[int, ...]:
    """The admissible mountain-valley signs MV(alpha, beta) of Theorem 2.1 (eq:foldParams).

    ``alpha``, ``beta`` finite numbers (radians), ``tol`` >= 0; else :class:`InputError`."""
    alpha = check_value(alpha, _ANGLE, "alpha")
    beta = check_value(beta, _ANGLE, "beta")
    tol = check_value(tol, Key("number", low=0.0), "tol")
    return _mv_set(alpha, beta, tol)


def _mv_set(alpha: float, beta: float, tol: float = MV_TOL) -> tuple[int, ...]:
    return tuple(s for s in (1, -1) if abs(np.cos(beta) - s * np.cos(alpha)) > tol)


@dataclass(frozen=True)
class BoundaryData:
    """Input data of the marching algorithm (eq:inputMarching), validated on construction."""

    left: np.ndarray
    bottom: np.ndarray
    l_left: np.ndarray
    l_bottom: np.ndarray

    def __post_init__(self) -> None:
        left = _as_float_array(self.left, "left")
        bottom = _as_float_array(self.bottom, "bottom")
        l_left = _as_float_array(self.l_left, "l_left")
        l_bottom = _as_float_array(self.l_bottom, "l_bottom")
        if left.ndim != 2 or left.shape[1] != 3 or left.shape[0] < 2:
            raise InputError(f"left must have shape (N+1, 3) with N >= 1, got {left.shape}")
        if bottom.ndim != 2 or bottom.shape[1] != 3 or bottom.shape[0] < 1:
            raise InputError(f"bottom must have shape (M, 3) with M >= 1, got {bottom.shape}")
        n, m = left.shape[0] - 1, bottom.shape[0]
        if l_left.shape != (n,):
            raise InputError(f"l_left must have shape (N,) = ({n},), got {l_left.shape}")
        if l_bottom.shape != (m,):
            raise InputError(f"l_bottom must have shape (M,) = ({m},), got {l_bottom.shape}")
        verts = [((i + 1, 1), row) for i, row in enumerate(left)]
        verts += [((1, j + 2), row) for j, row in enumerate(bottom)]
        for vertex, (a, b, s) in verts:
            _check_vertex(vertex, a, b, s)
        for name, arr, where in (("l_left", l_left, "l_ab of panel ({k}, 1)"),
                                 ("l_bottom", l_bottom, "l_ac of panel (1, {k})")):
            for k, val in enumerate(arr, start=1):
                if not np.isfinite(val) or val <= 0:
                    raise BoundaryDataError(
                        f"{name}[{k - 1}] = {float(val)!r} ({where.format(k=k)}) must be a "
                        "finite positive length", vertex=None, value=val)
        for name, arr in (("left", left), ("bottom", bottom), ("l_left", l_left),
                          ("l_bottom", l_bottom)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def N(self) -> int:
        """Number of panel rows."""
        return self.left.shape[0] - 1

    @property
    def M(self) -> int:
        """Number of panel columns."""
        return self.bottom.shape[0]

    @property
    def sigma(self) -> np.ndarray:
        """Mountain-valley signs of the boundary vertices, left then bottom, (N+1+M,)."""
        return np.concatenate([self.left[:, 2], self.bottom[:, 2]])

    @property
    def angles(self) -> np.ndarray:
        """(alpha, beta) of the boundary vertices, left then bottom, (N+1+M, 2)."""
        return np.concatenate([self.left[:, :2], self.bottom[:, :2]])

    @property
    def lengths(self) -> np.ndarray:
        """Boundary side lengths ell = (l_ab^{11..N1}, l_ac^{11..1M}) of eq:linearP."""
        return np.concatenate([self.l_left, self.l_bottom])

    def to_vector(self) -> np.ndarray:
        """Flat design vector: alphas, betas (left then bottom), then lengths (l_left, l_bottom)."""
        ang = self.angles
        return np.concatenate([ang[:, 0], ang[:, 1], self.lengths])

    @classmethod
    def from_vector(cls, x: np.ndarray, sigma: np.ndarray, N: int, M: int) -> "BoundaryData":
        """Inverse of :meth:`to_vector`, with the boundary signs ``sigma`` (N+1+M,)."""
        N, M = check_size(N, M)
        nv = N + 1 + M
        x = finite_array(x, "x", shape=(2 * nv + N + M,),
                         allowed=f"a design vector of {2 * nv + N + M} finite numbers")
        sigma = finite_array(sigma, "sigma", shape=(nv,),
                             allowed=f"{nv} mountain-valley signs (+1 or -1)")
        tri = np.column_stack([x[:nv], x[nv:2 * nv], sigma])
        return cls(left=tri[: N + 1], bottom=tri[N + 1:], l_left=x[2 * nv: 2 * nv + N],
                   l_bottom=x[2 * nv + N:])

    def with_lengths(self, lengths: np.ndarray) -> "BoundaryData":
        """The same angles with new boundary lengths ell (N+M,)."""
        lengths = finite_array(lengths, "lengths", shape=(self.N + self.M,),
                               allowed=f"N + M = {self.N + self.M} finite positive lengths")
        return BoundaryData(self.left, self.bottom, lengths[: self.N], lengths[self.N:])

    def to_dict(self) -> dict:
        """JSON-ready dictionary (lists of floats)."""
        return {k: getattr(self, k).tolist() for k in ("left", "bottom", "l_left", "l_bottom")}

    @classmethod
    def from_dict(cls, d: dict) -> "BoundaryData":
        """Inverse of :meth:`to_dict`."""
        if not isinstance(d, Mapping):
            raise InputError(f"boundary data must be a table of left, bottom, l_left and "
                             f"l_bottom, got {describe_value(d)}")
        fields = ("left", "bottom", "l_left", "l_bottom")
        for k in fields:
            if k not in d:
                raise InputError(f"boundary data is missing the field {k!r}")
        return cls(**{k: d[k] for k in fields})


def _as_float_array(x, name: str) -> np.ndarray:
    """``x`` as a (new) float array of real numbers (NaN and infinity pass: the vertex
    and side checks name them where they are)."""
    if isinstance(x, (str, bytes, Mapping)) or x is None:
        raise InputError(f"{name} must be an array of numbers, got {describe_value(x)}")
    try:
        raw = np.asarray(x)
    except (TypeError, ValueError, OverflowError, RecursionError):
        raise InputError(f"{name} must be an array of numbers, got a ragged or mixed "
                         "list") from None
    if raw.dtype.kind not in "iuf":
        raise InputError(f"{name} must be an array of numbers, got "
                         f"{'booleans' if raw.dtype.kind == 'b' else describe_value(x)}")
    return np.array(raw, dtype=float)


def _check_vertex(vertex: tuple[int, int], a: float, b: float, s: float) -> None:
    for name, val in (("alpha", a), ("beta", b)):
        if not np.isfinite(val) or not 0.0 < val < np.pi:
            raise BoundaryDataError(
                f"boundary vertex {vertex}: {name} = {float(val)!r} must lie in (0, pi)",
                vertex=vertex, value=val)
    if s not in (1.0, -1.0):
        raise BoundaryDataError(f"boundary vertex {vertex}: sigma = {float(s)!r} must be +1 "
                                "or -1", vertex=vertex, value=s)
    if abs(a - np.pi / 2) < MV_TOL and abs(b - np.pi / 2) < MV_TOL:
        raise BoundaryDataError(
            f"boundary vertex {vertex}: (alpha, beta) = (pi/2, pi/2) admits no rigid folding "
            "(Theorem 2.1)", vertex=vertex, value=(a, b))
    if int(s) not in _mv_set(a, b):
        raise BoundaryDataError(
            f"boundary vertex {vertex}: sigma = {int(s):+d} is not in MV(alpha, beta) = "
            f"{_mv_set(a, b)} for (alpha, beta) = ({float(a)!r}, {float(b)!r}) "
            "(eq:foldParams)", vertex=vertex, value=s)


def miura_vertex(i: int, j: int, alpha0: float, layout: Layout) -> tuple[float, float, float]:
    """(alpha, beta, sigma) of vertex (i, j) (1-based) of a Miura-ori (docs/paper.md s.6)."""
    check_value(i, Key("whole", low=1), "i")
    check_value(j, Key("whole", low=1), "j")
    alpha0 = check_value(alpha0, _ACUTE, "alpha0")
    layout = check_value(layout, _LAYOUT, "layout")
    return _miura_vertex(i, j, alpha0, layout)


def _miura_vertex(i: int, j: int, alpha0: float, layout: str) -> tuple[float, float, float]:
    if layout == "zigzag_j":
        ang = alpha0 if j % 2 == 1 else np.pi - alpha0
        return ang, ang, -1.0
    if layout == "zigzag_i":
        ang = alpha0 if i % 2 == 1 else np.pi - alpha0
        return ang, np.pi - ang, 1.0
    raise InputError(f"layout must be one of {LAYOUTS}, got {layout!r}")


def miura_boundary(N: int, M: int, a: float = 1.0, b: float = 1.0, alpha0: float = 1.2,
                   layout: Layout = "zigzag_j") -> BoundaryData:
    """Boundary data of an N x M Miura-ori with sides a (straight) and b (zig-zag).

    ``layout="zigzag_j"``: the zig-zag runs along j (alpha = beta, sigma = -1, l_ab = a,
    l_ac = b); ``"zigzag_i"``: along i (beta = pi - alpha, sigma = +1, l_ab = b, l_ac = a).
    N and M are whole numbers in [1, :data:`MAX_SIDE`], a and b finite positive lengths,
    alpha0 in (0, pi/2); anything else raises :class:`InputError` naming the argument.
    """
    N, M = check_size(N, M)
    alpha0 = check_value(alpha0, _ACUTE, "alpha0")
    a, b = check_value(a, _LENGTH, "a"), check_value(b, _LENGTH, "b")
    layout = check_value(layout, _LAYOUT, "layout")
    left = np.array([_miura_vertex(i, 1, alpha0, layout) for i in range(1, N + 2)])
    bottom = np.array([_miura_vertex(1, j, alpha0, layout) for j in range(2, M + 2)])
    l_ab, l_ac = (a, b) if layout == "zigzag_j" else (b, a)
    return BoundaryData(left, bottom, np.full(N, float(l_ab)), np.full(M, float(l_ac)))


def perturb_angles(bd: BoundaryData, amplitude: float = 0.05 * np.pi,
                   seed: int | np.random.Generator | None = None) -> BoundaryData:
    """Boundary angles perturbed by U(-amplitude, amplitude), signs and lengths kept.

    This is the paper's Fig. Random input (amplitude 0.05 pi around a Miura-ori). Raises
    :class:`BoundaryDataError` if a perturbed vertex leaves the admissible set,
    :class:`InputError` for arguments of the wrong kind: ``bd`` not BoundaryData,
    ``amplitude`` not a finite number >= 0, ``seed`` neither None, a whole number in
    [0, 2^63 - 1] nor a numpy Generator.
    """
    check_boundary(bd)
    amplitude = abs(check_value(amplitude, Key("number", low=0.0, hint="(an angle, radians)"),
                                "amplitude"))  # -0.0 passes the check; NumPy's uniform refuses it
    if seed is not None and not isinstance(seed, np.random.Generator):
        seed = check_value(seed, _SEED, "seed")
    rng = np.random.default_rng(seed)
    left = bd.left.copy()
    bottom = bd.bottom.copy()
    left[:, :2] += rng.uniform(-amplitude, amplitude, size=left[:, :2].shape)
    bottom[:, :2] += rng.uniform(-amplitude, amplitude, size=bottom[:, :2].shape)
    return BoundaryData(left, bottom, bd.l_left, bd.l_bottom)


def refine(design: BoundaryData, reference: BoundaryData,
           finer: BoundaryData) -> BoundaryData:
    """The boundary data of the Miura-ori ``finer`` carrying ``design``, a pattern designed
    from the Miura-ori ``reference`` of its own size, N x M panels, to finer's N_f x M_f
    (N_f >= N, M_f >= M; coarse-to-fine, docs/solvers.md, "Coarse-to-fine").

    Along each edge, each class (alpha, beta or the sides; one parity of the index, as a
    Miura-ori alternates) is interpolated linearly at the same place along the edge (vertex
    i at i / N, a side at its middle): the angles' deviations from ``reference`` scaled by
    the ratio of the panels along that edge (N / N_f on the left edge, M / M_f on the bottom
    one), the sides as ratios to ``reference``'s; the mountain-valley signs are finer's.
    Unscaled deviations add up over r times the panels and do not march; scaled, the start
    lies closest to the coarse design's shape among the factors measured in
    docs/decisions/scaling.md.
    Raises :class:`InputError` unless both Miuras have design's layout and finer is at least
    as large, :class:`BoundaryDataError` where a carried vertex leaves the admissible set.
    """
    for name, value in (("design", design), ("reference", reference), ("finer", finer)):
        check_boundary(value, name)
    N, M, N_f, M_f = design.N, design.M, finer.N, finer.M
    if (reference.N, reference.M) != (N, M) or N_f < N or M_f < M:
        raise InputError(f"refine carries a design of N x M panels to N_f x M_f >= N x M with "
                         f"a reference of N x M, got the design {N} x {M}, the reference "
                         f"{reference.N} x {reference.M} and the finer Miura {N_f} x {M_f}")
    if not (np.array_equal(design.sigma[:2], reference.sigma[:2])
            and np.array_equal(reference.sigma[:2], finer.sigma[:2])):
        raise InputError("refine needs the design, its reference and the finer Miura-ori in "
                         "one layout (the same mountain-valley signs at the corner)")
    left, bottom = finer.left.copy(), finer.bottom.copy()
    for ours, ref, out, n, n_f, first in [(design.left, reference.left, left, N, N_f, 0),
                                          (design.bottom, reference.bottom, bottom, M, M_f, 1)]:
        for col in (0, 1):
            out[:, col] += (n / n_f) * _carried(ours[:, col] - ref[:, col], n, n_f,
                                                out.shape[0], first)
    l_left = finer.l_left * _carried(design.l_left / reference.l_left, N, N_f, N_f, 0.5)
    l_bottom = finer.l_bottom * _carried(design.l_bottom / reference.l_bottom, M, M_f, M_f, 0.5)
    return BoundaryData(left, bottom, l_left, l_bottom)


def _carried(values: np.ndarray, n: int, n_f: int, size: int, first: float) -> np.ndarray:
    """``values`` (k,) along an edge of n panels, entry k at (k + first) / n, interpolated
    per parity of k at the ``size`` places (k + first) / n_f of an edge of n_f panels."""
    out = np.empty(size)
    for parity in (0, 1):
        ours, theirs = np.arange(parity, values.size, 2), np.arange(parity, size, 2)
        out[theirs] = np.interp((theirs + first) / n_f, (ours + first) / n, values[ours])
    return out
