"""Clearance at the designed state: ``DesignProblem(min_clearance=c)`` (a sheet thickness).

Panels that share no vertex must stay at least c apart in the designed folded state.
:func:`rffqm_nlp.design.problem.DesignProblem.solve` meets this by inline constraints on the pairs
that come close, refreshed as the design moves (docs/collisions.md):

* Near pairs: the collision broad phase and exact panel distances
  (:func:`rffqm_nlp.contact.collisions.near_pairs`) at the re-marched designed state; every pair
  closer than c (1 + :data:`MARGIN`) is constrained, and stays so in later rounds.
* Rows: for each constrained pair a separating axis u (unit, a smooth function of the
  folded vertices: a panel's normal, the normalised cross product of an edge of each
  panel, or a panel's in-plane edge normal; the candidates of the separating-axis test),
  chosen with its sign s where the pair's gap along it is largest at the current state,
  and the rows s u . (y_k - y_l) >= c (1 + :data:`ROW_MARGIN`) for the vertices y_k of
  one panel and y_l of the other (vertices that project alike dropped). A unit axis
  gap is a lower bound of the Euclidean distance of two convex panels, so rows that hold
  keep the pair at least c apart (conservative when the closest features are two
  corners or a corner and an edge).
* The rows are appended to the NLP's constraints
  (:meth:`rffqm_nlp.design.transcription.NLP.with_rows`),
  written in the NLP's folded vertices (variables of the simultaneous transcription).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from .. import memory
from ..model.backend import finite_array
from ..model.boundary import check_size
from ..contact.collisions import near_pairs
from ..errors import InputError
from ..files import Key, check_value, describe_value
from ..model.numpy_model import fold
from ..model.pattern import Pattern, check_fold_angle, check_pattern
from .transcription import NLP

#: Pairs closer than min_clearance (1 + MARGIN) are constrained.
MARGIN = 0.5
#: The rows ask for min_clearance (1 + ROW_MARGIN), so the re-marched design (within the
#: solver's tolerance of the NLP's point) keeps min_clearance.
ROW_MARGIN = 1e-4
#: Outer rounds (solve, find near pairs, constrain, re-solve) at most ...
ROUNDS = 6
#: ... iterations of each round's solve at most ...
ROUND_ITERATIONS = 150
#: ... and pairs newly constrained in a round at most (the closest ones).
ROUND_PAIRS = 100
#: Smallest sine between two edges whose cross product is a candidate axis.
MIN_SINE = 0.1
#: Panel edges by corner (a, b, c, d) = (0, 1, 2, 3): a-b, a-c, b-d, c-d.
EDGES = ((0, 1), (0, 2), (1, 3), (2, 3))
#: A clearance: a distance >= 0 (a sheet thickness).
_CLEARANCE = Key("number", low=0.0, hint="(a distance)")


@dataclass(frozen=True)
class Closest:
    """The closest pair of panels that share no vertex at a state: 1-based ``pair``
    ((i, j), (k, l)) and its ``distance`` (inf and None when no pair is within reach)."""

    pair: tuple[tuple[int, int], tuple[int, int]] | None
    distance: float


def closest(pattern: Pattern, omega: float, clearance: float) -> tuple[np.ndarray, Closest]:
    """The pairs (n, 2) (0-based panel indices p = (i-1) M + (j-1)) closer than
    ``clearance`` (1 + MARGIN) in ``pattern`` folded at ``omega``, the closest first and at
    most :data:`ROUND_PAIRS` of them, and the closest pair. Raises :class:`InputError` for
    arguments of other kinds (``omega`` one number in [-pi, pi], ``clearance`` >= 0)."""
    check_pattern(pattern, "pattern")
    omega = check_fold_angle(omega)
    clearance = check_value(clearance, _CLEARANCE, "clearance")
    pairs, dist = near_pairs(pattern, fold(pattern, omega), clearance * (1 + MARGIN))
    order = np.argsort(dist, kind="stable")
    order = order[dist[order] < clearance * (1 + MARGIN)][:ROUND_PAIRS]
    if not order.size:
        return np.zeros((0, 2), dtype=np.int64), Closest(None, float("inf"))
    p, q = (int(v) for v in pairs[order[0]])
    M = pattern.M
    return pairs[order], Closest(((p // M + 1, p % M + 1), (q // M + 1, q % M + 1)),
                                 float(dist[order[0]]))


def constrain(nlp: NLP, pattern: Pattern, omega: float, pairs: np.ndarray,
              clearance: float) -> NLP:
    """``nlp`` with the clearance rows of ``pairs`` (n, 2), their axes chosen at ``pattern``
    folded at ``omega`` (see the module docstring). ``pairs`` are 0-based panel indices of
    two distinct panels each; :class:`InputError` for arguments of other kinds."""
    if not isinstance(nlp, NLP):
        raise InputError(f"nlp must be the design's NLP (rffqm_nlp.design.transcription.NLP), got "
                         f"{describe_value(nlp)}")
    check_pattern(pattern, "pattern")
    omega = check_fold_angle(omega)
    clearance = check_value(clearance, _CLEARANCE, "clearance")
    P = pattern.N * pattern.M
    pairs = finite_array(pairs, "pairs", shape=(None, 2), allowed=f"an (n, 2) array of panel "
                         f"indices in [0, {P})")
    if (np.any(pairs != np.round(pairs)) or np.any(pairs < 0) or np.any(pairs >= P)
            or np.any(pairs[:, 0] == pairs[:, 1])):
        raise InputError(f"pairs must hold two distinct whole panel indices in [0, {P}) "
                         "per row")
    pairs = pairs.astype(np.int64)
    corners = panel_corners(pattern.N, pattern.M)
    V = fold(pattern, omega).reshape(-1, 3)
    Yx, Yy, Yz = nlp.folded(nlp.x)
    Ys = ca.horzcat(ca.vec(Yx.T), ca.vec(Yy.T), ca.vec(Yz.T))        # (V, 3), row-major
    rows = []
    for p, q in pairs:
        kind, sign = choose_axis(V[corners[p]], V[corners[q]])
        P = Ys[corners[p].tolist(), :]
        Q = Ys[corners[q].tolist(), :]
        rows.append(sign * _candidates()[kind](P, Q))
    g = ca.vertcat(*rows)
    return nlp.with_rows(g, np.full(g.numel(), clearance * (1 + ROW_MARGIN)),
                         np.full(g.numel(), np.inf))


def panel_corners(N: int, M: int) -> np.ndarray:
    """Flat (row-major) vertex indices (N M, 4) of the corners a, b, c, d of every panel,
    panels numbered p = (i-1) M + (j-1). N, M as :func:`rffqm_nlp.model.boundary.check_size`;
    :class:`InputError` when the indices need more memory than this machine has left."""
    N, M = check_size(N, M)
    need = 64.0 * N * M
    if need > 1e8:
        memory.refuse_beyond(need, f"the corners of {N} x {M} panels", "choose fewer panels")
    i, j = np.divmod(np.arange(N * M), M)
    a = i * (M + 1) + j
    return np.stack([a, a + M + 1, a + 1, a + M + 2], axis=1)


def choose_axis(P: np.ndarray, Q: np.ndarray) -> tuple[int, float]:
    """The candidate axis (an index into :func:`_candidates`) and sign (+1 or -1) with the
    largest gap between panels P and Q (4, 3 corners a, b, c, d each, finite numbers)."""
    P = finite_array(P, "P", shape=(4, 3), allowed="the corners (4, 3) of a panel")
    Q = finite_array(Q, "Q", shape=(4, 3), allowed="the corners (4, 3) of a panel")
    best, choice = -np.inf, (0, 1.0)
    for kind, fn in enumerate(_candidates()):
        if not _well_posed(kind, P, Q):
            continue
        values = np.asarray(fn(P, Q)).ravel()
        for sign in (1.0, -1.0):
            gap = float(np.min(sign * values))
            if gap > best:
                best, choice = gap, (kind, sign)
    return choice


def _well_posed(kind: int, P: np.ndarray, Q: np.ndarray) -> bool:
    """Whether candidate ``kind`` is smooth here: an edge-edge axis needs the two edges at a
    sine of at least MIN_SINE."""
    layout = _layout()[kind]
    if layout[0] != "edges":
        return True
    (e0, e1), (f0, f1) = layout[1], layout[2]
    u, v = P[e1] - P[e0], Q[f1] - Q[f0]
    return np.linalg.norm(np.cross(u, v)) >= MIN_SINE * np.linalg.norm(u) * np.linalg.norm(v)


@lru_cache(maxsize=1)
def _layout() -> list[tuple]:
    """The candidate axes: ("normal_p",), ("normal_q",), ("edges", edge of P, edge of Q),
    ("in_p", edge of P), ("in_q", edge of Q)."""
    return ([("normal_p",), ("normal_q",)]
            + [("edges", e, f) for e in EDGES for f in EDGES]
            + [("in_p", e) for e in EDGES] + [("in_q", f) for f in EDGES])


@lru_cache(maxsize=1)
def _candidates() -> list[ca.Function]:
    """One CasADi Function per candidate axis u: (P, Q) (4, 3 each) -> the rows
    u . (Q_k - P_l) over the corners k of Q and l of P that project distinctly."""
    P, Q = ca.SX.sym("P", 4, 3), ca.SX.sym("Q", 4, 3)
    p = [P[k, :].T for k in range(4)]
    q = [Q[k, :].T for k in range(4)]
    n_p = ca.cross(p[3] - p[0], p[2] - p[1])
    n_q = ca.cross(q[3] - q[0], q[2] - q[1])
    out = []
    for index, layout in enumerate(_layout()):
        kind = layout[0]
        pv, qv = list(range(4)), list(range(4))
        if kind == "normal_p":
            u, pv = n_p, [0]
        elif kind == "normal_q":
            u, qv = n_q, [0]
        elif kind == "edges":
            (e0, e1), (f0, f1) = layout[1], layout[2]
            u = ca.cross(p[e1] - p[e0], q[f1] - q[f0])
            pv.remove(e1)
            qv.remove(f1)
        elif kind == "in_p":
            e0, e1 = layout[1]
            u = ca.cross(n_p, p[e1] - p[e0])
            pv.remove(e1)
        else:
            f0, f1 = layout[1]
            u = ca.cross(n_q, q[f1] - q[f0])
            qv.remove(f1)
        u = u / ca.norm_2(u)
        rows = ca.vertcat(*[ca.dot(u, q[k] - p[m]) for k in qv for m in pv])
        out.append(ca.Function(f"clearance_axis{index}", [P, Q], [rows]))
    return out

