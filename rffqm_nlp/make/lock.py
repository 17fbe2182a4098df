"""A lock at the designed shape: ties between two vertices and crease stops.

An RFFQM pattern folds with one degree of freedom, omega, so one stop that fixes any
quantity changing with omega holds the whole sheet. A tie holds the distance between two
vertices; it blocks the motion best where that distance changes fastest with omega:
d|y_p - y_q|/d omega = (y_p - y_q) . (dy_p/d omega - dy_q/d omega) / |y_p - y_q|, with
dY/d omega exact, by forward differentiation of the folding graph (eq:defGrads ..
eq:finalCalc; :func:`rffqm_nlp.mechanics.folding.folded_state`), the distances from the
NumPy model's folded state.

Candidates (:func:`tie_candidates`) are the pairs of boundary vertices (a tie across the
sheet, installed from its edge) whose straight segment meets no panel but at its ends;
:func:`lock_ties` recommends ``count`` of them, fastest first, each with two vertices not
used by a tie already chosen and at least :data:`SPREAD` away in direction from those
(when enough are). A crease stop (:func:`crease_stops`) holds one fold angle gamma:
tan(gamma/2) = k tan(omega/2) (docs/paper.md s.2, k from
:func:`rffqm_nlp.model.marching.fold_multipliers`), so d gamma/d omega =
k (1 + tan^2(omega/2)) / (1 + k^2 tan^2(omega/2)); the creases whose angle changes fastest
are recommended. Thick tapered panels are themselves stops against folding on: their
bevels meet at the designed state (:mod:`rffqm_nlp.contact.thick`).

Every function returns plain data (vertex pairs, lengths and rates), in the pattern's
units or, with ``scale`` (mm per unit), in millimetres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..files import Key, check_value
from ..io.export import triangles
from ..mechanics.folding import folded_state
from ..model.marching import fold_multipliers
from ..model.numpy_model import fold, fold_angles
from ..model.pattern import Pattern, check_fold_angle, check_pattern
from .sheet import boundary_ring

#: Smallest angle (radians) between the directions of two recommended ties.
SPREAD = math.radians(30)
#: Most candidates (fastest first) whose segments are tested against the sheet.
SEGMENT_CHECKS = 400


@dataclass(frozen=True)
class Tie:
    """A tie between vertices (i1, j1) and (i2, j2) (1-based): its ``length`` at the
    designed state and ``dlength_domega`` (per radian), in the pattern's units or mm."""

    i1: int
    j1: int
    i2: int
    j2: int
    length: float
    dlength_domega: float


@dataclass(frozen=True)
class Stop:
    """A crease stop on the crease (i1, j1)-(i2, j2) (1-based): its ``length``, its fold
    angle ``angle`` (radians, valley positive) at the designed state and
    ``dangle_domega`` (radians per radian)."""

    i1: int
    j1: int
    i2: int
    j2: int
    length: float
    angle: float
    dangle_domega: float


def _checked(pattern, omega, scale) -> tuple[Pattern, float, float]:
    check_pattern(pattern, "pattern")
    omega = check_fold_angle(omega, "omega")
    scale = check_value(scale, Key("number", low=0, low_open=True,
                                   hint="(mm per pattern unit)"), "scale")
    return pattern, omega, scale


def pair_rates(Y: np.ndarray, dY: np.ndarray, p: np.ndarray, q: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    """Distances (n,) between the vertices p and q (flat indices, (n,) each) of the state Y
    (V, 3), and their derivatives (n,) for the velocities dY (V, 3)."""
    d = Y[p] - Y[q]
    length = np.linalg.norm(d, axis=1)
    return length, np.einsum("nk,nk->n", d, dY[p] - dY[q]) / length


def _boundary_pairs(N: int, M: int) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of boundary vertices that are not neighbours on the boundary, as flat
    indices (n,) each."""
    ring = boundary_ring(np.arange((N + 1) * (M + 1)).reshape(N + 1, M + 1, 1))[:, 0]
    a, b = np.triu_indices(len(ring), 2)
    keep = ~((a == 0) & (b == len(ring) - 1))
    return ring[a[keep]], ring[b[keep]]


def segments_clear(Y: np.ndarray, tri: np.ndarray, p: np.ndarray, q: np.ndarray
                   ) -> np.ndarray:
    """Whether each segment from vertex p to vertex q ((n,) flat indices) of the state Y
    (V, 3) meets none of the triangles ``tri`` (T, 3) but those with p or q as a corner
    (n,) (Moller-Trumbore, a hit strictly inside the segment)."""
    A, B, C = Y[tri[:, 0]], Y[tri[:, 1]], Y[tri[:, 2]]
    e1, e2 = B - A, C - A
    out = np.ones(len(p), bool)
    for n, (a, b) in enumerate(zip(p, q)):
        d = Y[b] - Y[a]
        h = np.cross(d, e2)
        det = np.einsum("tk,tk->t", e1, h)
        ok = np.abs(det) > 1e-14
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = Y[a] - A
        u = inv * np.einsum("tk,tk->t", s, h)
        qv = np.cross(s, e1)
        v = inv * (d @ qv.T)
        t = inv * np.einsum("tk,tk->t", e2, qv)
        mine = np.any((tri == a) | (tri == b), axis=1)
        hit = ok & ~mine & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9) & (t < 1 - 1e-9)
        out[n] = not hit.any()
    return out


def tie_candidates(pattern: Pattern, omega: float, scale: float = 1.0) -> list[Tie]:
    """The tie candidates (see the module), fastest |d length / d omega| first: at most
    :data:`SEGMENT_CHECKS` of them, those whose segment meets no panel."""
    pattern, omega, scale = _checked(pattern, omega, scale)
    N, M = pattern.N, pattern.M
    Y, dY = (a.reshape(-1, 3) for a in folded_state(pattern, omega))
    p, q = _boundary_pairs(N, M)
    length, rate = pair_rates(Y, dY, p, q)
    order = np.argsort(-np.abs(rate), kind="stable")[:SEGMENT_CHECKS]
    clear = segments_clear(Y, triangles(N, M), p[order], q[order])
    return [Tie(int(p[k] // (M + 1) + 1), int(p[k] % (M + 1) + 1), int(q[k] // (M + 1) + 1),
                int(q[k] % (M + 1) + 1), float(length[k] * scale), float(rate[k] * scale))
            for k in order[clear]]


def lock_ties(pattern: Pattern, omega: float, count: int = 3, scale: float = 1.0
              ) -> list[Tie]:
    """``count`` recommended ties (see the module), fastest first."""
    count = check_value(count, Key("whole", low=1, high=20), "count")
    candidates = tie_candidates(pattern, omega, scale)
    Y = fold(pattern, check_fold_angle(omega, "omega"))
    chosen: list[Tie] = []
    for spread in (True, False):
        for tie in candidates:
            if len(chosen) == count:
                return chosen
            if tie in chosen or not _compatible(tie, chosen, Y, spread):
                continue
            chosen.append(tie)
    return chosen


def _compatible(tie: Tie, chosen: list[Tie], Y: np.ndarray, spread: bool) -> bool:
    """Whether ``tie`` shares no vertex with the ``chosen`` ones and, with ``spread``, runs
    at least :data:`SPREAD` away from each of their directions in the state Y."""
    ends = {(tie.i1, tie.j1), (tie.i2, tie.j2)}
    d = _direction(tie, Y)
    for other in chosen:
        if ends & {(other.i1, other.j1), (other.i2, other.j2)}:
            return False
        if spread and abs(float(d @ _direction(other, Y))) > math.cos(SPREAD):
            return False
    return True


def _direction(tie: Tie, Y: np.ndarray) -> np.ndarray:
    d = Y[tie.i2 - 1, tie.j2 - 1] - Y[tie.i1 - 1, tie.j1 - 1]
    return d / np.linalg.norm(d)


def crease_stops(pattern: Pattern, omega: float, count: int = 3, scale: float = 1.0
                 ) -> list[Stop]:
    """The ``count`` creases whose fold angle changes fastest with omega at the designed
    state (see the module), fastest first; lengths in the pattern's units or mm."""
    pattern, omega, scale = _checked(pattern, omega, scale)
    count = check_value(count, Key("whole", low=1, high=20), "count")
    gh, gv = fold_angles(pattern, omega)
    kh, kv = (np.asarray(k) for k in fold_multipliers(pattern.alpha, pattern.beta,
                                                      pattern.sigma))
    tan = math.tan(omega / 2)
    rows = []
    for gamma, k, step in ((gh, kh[:, :-1], (0, 1)), (gv, kv[:-1, :], (1, 0))):
        rate = k * (1 + tan * tan) / (1 + k * k * tan * tan)
        for i, j in zip(*np.nonzero(gamma)):
            a, b = (i + 1, j + 1), (i + 1 + step[0], j + 1 + step[1])
            length = np.linalg.norm(pattern.X[b[0] - 1, b[1] - 1] - pattern.X[i, j])
            rows.append(Stop(*map(int, a), *map(int, b), float(length * scale),
                             float(gamma[i, j]),
                             float(rate[i, j])))
    rows.sort(key=lambda s: -abs(s.dangle_domega))
    return rows[:count]
