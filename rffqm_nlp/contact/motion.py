"""Contact along the folding motion: the first omega at which two panels come too close.

* Along the motion: omega is sampled on a coarse grid (steps of at most ``MAX_STEP``); on
  a step [w0, w1] a candidate pair (:func:`~rffqm_nlp.contact.broad.coarse_rows`) is
  certified clear when (d(w0) + d(w1) - m) / 2 > clearance, where d is the panel distance
  and m bounds how far the pair's distance can change over the step: SAFETY times the
  largest relative displacement of a vertex of one panel against a vertex of the other
  between w0 and w1 (:func:`pair_bound`; a rigid motion's displacement is affine on a
  panel, so its extreme is at a vertex; the 16 vertex pairs are compared), or SAFETY
  times the largest displacement of a vertex of one panel in the frame of the other
  (:func:`frame_bound`; origin at its corner a, axes along its edge a -> b and its
  normal), whichever is smaller: in its own frame a panel is still and the other moves
  rigidly, so the distance changes by at most that. Both are computed only after a
  coarser bound, the centres' relative displacement plus each panel's largest vertex
  displacement about its centre, has failed to certify the step, the frame bound first
  (it certifies nearly all the pairs that get this far: panels turning together, and
  panels hinged across a very thin panel, as in side-length LP patterns, which stay
  close while their far corners move a lot but hardly move in one another's frame), the
  vertex pairs only where it has not. Distances are first bounded from below cheaply
  (:func:`~rffqm_nlp.contact.narrow.lower_bound`): at a step's start, and at its end
  only where the start's bound less m does not clear the clearance (d >= d(w0) - m all
  over the step, which then certifies it: most pairs get one bound a state, as the start
  of their next step, with no sort to find the rows that share a state); a half step
  takes its parent's distance at the end it shares with it and a cheap bound at the
  midpoint. The exact distance is computed only where those bounds do not certify the
  step, and only an exact distance reports a contact.
* Uncertified pairs are followed into the halves of the step (one batched fold per
  level) until they are certified, touch at a sample (d <= clearance), or the step is
  shorter than ``tol``; contacts after the earliest one found are dropped on the way.
  The earliest sample in contact lies within ``tol`` after the true first contact.
* Fast steps: a coarse step over which the sheet moves far from one affine map (its
  median reach above ``SPLIT_REACH`` panel radii; a designed pattern bends fast near
  flat) is halved before its broad phase, its halves likewise (:func:`steps`), while
  longer than ``tol``. The halves are those the refinement would follow, at the same
  midpoints, so the samples, and with every certificate sound the report, stay the
  same; the pairs within reach shrink like the square of a step's motion.
* Memory and order: the coarse steps are taken in order, a step's rows refined as the
  broad phase gives them (in batches of at most ``ROWS`` rows), and no step that starts
  after the earliest contact found is looked at. The result does not depend on the order
  or the batches: a pair in contact at a sample is found by every row that has that
  sample, and only rows that start after the earliest contact found are dropped.
* Guarantee and its assumptions: no contact is missed provided that within one step the
  path of every vertex relative to another, and of every vertex in the frame of another
  panel, is at most SAFETY times its chord (smooth motion on short steps; the second,
  added with the frame bound, is of the same kind as the first). A pair whose distance
  dips below the clearance only between two samples less than ``tol`` apart may be
  missed (a near miss shorter than ``tol`` in omega).
"""

from __future__ import annotations

import numpy as np

from . import broad
from .broad import SAFETY
from .narrow import distance, lower_bound
from .panels import Geometry, PanelPair, States
from .vectors import dot, most, norm

#: Largest coarse step in omega.
MAX_STEP = 0.1

#: A step whose median reach (:func:`~rffqm_nlp.contact.broad.reach`) exceeds this many
#: median panel radii is halved before its broad phase: its motion is far from one affine
#: map (a sheet bending fast, as a designed pattern does near flat), and the pairs within
#: its reaches grow like their square, two halves' like half of it.
SPLIT_REACH = 2.0

#: Panel pairs per batch of the bounds and distances along the motion (their temporaries,
#: 64 kB each, stay in cache; smaller batches pay NumPy's call overhead once more per op).
BATCH = 8192


def first_contact(geo: Geometry, w_max: float, clearance: float,
                  tol: float) -> tuple[float | None, list[PanelPair]]:
    """The earliest |omega| in [0, |w_max|] with two panels within ``clearance``, signed
    like ``w_max`` (None when there is none), and the panel pairs in contact there. The
    steps in order (:func:`steps`), their rows refined as the broad phase gives them, once
    at least ROWS are held (or at the end); no step that starts after the earliest contact
    found is looked at."""
    sign = -1.0 if w_max < 0 else 1.0
    W = abs(w_max)
    n_steps = max(1, int(np.ceil(W / MAX_STEP)))
    st = States(geo, sign, np.linspace(0.0, W, n_steps + 1))
    found, held = _Contact(geo), []
    for s in (s for a in range(n_steps) for s in steps(geo, st, a, a + 1, clearance, tol)):
        if st.omegas[s.a] > found.best:
            break
        for chunk in broad.coarse_rows(geo, st, s):
            held.append(chunk)
            if sum(len(rows) for rows, _ in held) >= broad.ROWS:
                _refine(st, *_joined(held), clearance, tol, found)
                held = []
    if held:
        _refine(st, *_joined(held), clearance, tol, found)
    if not np.isfinite(found.best):
        return None, []
    return sign * float(found.best) if found.best > 0 else 0.0, found.pairs


def steps(geo: Geometry, st: States, a: int, b: int, clearance: float, tol: float):
    """The step from state ``a`` to state ``b`` of ``st``, in order, as the broad phase's
    steps (:class:`~rffqm_nlp.contact.broad.Step`): halved (its midpoint state added to
    ``st``) while its reaches are far (SPLIT_REACH) and it is longer than ``tol``, the
    halves likewise. The halves are the ones :func:`_refine` would follow, so the samples
    that can report a contact stay the same."""
    s = broad.step(geo, st, a, b, clearance)
    w = st.omegas
    if not (s.far(SPLIT_REACH) and w[b] - w[a] > tol):
        yield s
        return
    mid = int(st.index(np.array([(w[a] + w[b]) / 2]))[0])
    yield from steps(geo, st, a, mid, clearance, tol)
    yield from steps(geo, st, mid, b, clearance, tol)


def _joined(chunks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Chunks (rows (n, 4), bounds (n,)) put together."""
    return np.concatenate([r for r, _ in chunks]), np.concatenate([m for _, m in chunks])


class _Contact:
    """The earliest contact found so far: its |omega| ``best`` (inf: none) and the panel
    pairs in contact there (1-based labels, sorted)."""

    def __init__(self, geo: Geometry):
        self.geo, self.best, self.pairs = geo, np.inf, []

    def record(self, w: np.ndarray, hit: np.ndarray, p: np.ndarray, q: np.ndarray) -> None:
        """Take the pairs p, q (n,) in contact (``hit`` (n,) bool) at the |omega| w (n,)
        into account."""
        if not hit.any() or w[hit].min() > self.best:
            return
        w_hit = w[hit].min()
        at = hit & (w == w_hit)
        new = [self.geo.label(a, b) for a, b in zip(p[at], q[at])]
        self.pairs = sorted(set(new + (self.pairs if w_hit == self.best else [])))
        self.best = w_hit


def _refine(st: States, rows: np.ndarray, m: np.ndarray, clearance: float, tol: float,
            found: _Contact) -> None:
    """Follow the rows (n, 4) = (state a, state b, p, q), with upper bounds m (n,) on the
    change of their distance (inf: none yet), into the halves of their steps until each
    is certified clear, in contact at a sample, or shorter than ``tol``; contacts go to
    ``found``, rows that start after its earliest contact are dropped. In batches of at
    most ROWS rows (a stack of the halves still to follow, each with lower bounds on its
    distance at both ends: its parent's exact distance at the end it shares with it, the
    cheap bound at the midpoint)."""
    stack = [(rows, m, None)]
    while stack:
        rows, m, ends = stack.pop()
        if len(rows) > broad.ROWS:
            stack.append((rows[broad.ROWS:], m[broad.ROWS:],
                          None if ends is None else ends[broad.ROWS:]))
            rows, m = rows[:broad.ROWS], m[:broad.ROWS]
            ends = None if ends is None else ends[:broad.ROWS]
        omegas = np.asarray(st.omegas)
        keep = omegas[rows[:, 0]] <= found.best
        rows, m = rows[keep], m[keep]
        if not rows.size:
            continue
        ia, ib, p, q = rows.T
        wa, wb = omegas[ia], omegas[ib]
        da, db = (_end_bounds(st, rows, m, clearance) if ends is None
                  else (ends[keep, 0].copy(), ends[keep, 1].copy()))
        loose = (da + db - m) / 2 <= clearance      # m so far an upper bound (inf: none)
        for bound in (frame_bound, pair_bound):      # m is SAFETY times the smaller at last
            new = SAFETY * in_batches(bound, st, ia[loose], ib[loose], p[loose], q[loose])
            m[loose] = new if bound is frame_bound else np.minimum(m[loose], new)
            loose &= (da + db - m) / 2 <= clearance
        exact = (da + db - m) / 2 <= clearance
        k = int(exact.sum())
        d = per_state(distance, st, np.concatenate([ia[exact], ib[exact]]),
                      np.tile(p[exact], 2), np.tile(q[exact], 2))
        da[exact], db[exact] = d[:k], d[k:]
        for w_s, d_s in ((wa, da), (wb, db)):
            found.record(w_s, exact & (d_s <= clearance), p, q)
        open_ = ((da + db - m) / 2 <= clearance) & (da > clearance) & (wb - wa > tol)
        if open_.any():
            halves = _split(rows[open_], st)
            n = int(open_.sum())
            mid = in_batches(lower_bound, st, halves[:n, 1], halves[:n, 2], halves[:n, 3])
            ends = np.concatenate([np.stack([da[open_], mid], axis=1),
                                   np.stack([mid, db[open_]], axis=1)])
            stack.append((halves, np.full(len(halves), np.inf), ends))


def _end_bounds(st: States, rows: np.ndarray, m: np.ndarray,
                clearance: float) -> tuple[np.ndarray, np.ndarray]:
    """Lower bounds (da, db) (n,) on the distances of the rows' (n, 4) pairs at the start
    and the end of their steps, m (n,) the rows' bounds on the change of the distance over
    the step: at the start the cheap bound (:func:`~rffqm_nlp.contact.narrow.lower_bound`);
    at the end da - m where that exceeds the clearance (the distance changes by at most m
    over the step, so da - m bounds it all over the step, and (da + db - m) / 2 >= da - m
    certifies it), else the cheap bound there."""
    ia, ib, p, q = rows.T
    da = in_batches(lower_bound, st, ia, p, q)
    db = da - m
    k = np.flatnonzero(~(db > clearance))  # a NaN bound goes to the cheap bound too
    db[k] = in_batches(lower_bound, st, ib[k], p[k], q[k])
    return da, db


def pair_bound(st: States, ia: np.ndarray, ib: np.ndarray, p: np.ndarray,
               q: np.ndarray) -> np.ndarray:
    """The largest displacement (n,) of a vertex of q relative to a vertex of p (16 vertex
    pairs) from state ia to state ib (all (n,))."""
    Pa, Pb, Qa, Qb = (st.quads(s, x) for s, x in ((ia, p), (ib, p), (ia, q), (ib, q)))
    dP, dQ = Pb - Pa, Qb - Qa                                        # (n, 4, 3)
    return most(norm(dQ[:, None] - dP[:, :, None]).reshape(-1, 16))


def frame_bound(st: States, ia: np.ndarray, ib: np.ndarray, p: np.ndarray,
                q: np.ndarray) -> np.ndarray:
    """The largest displacement (n,) of a vertex of one panel in the frame of the other
    (:func:`~rffqm_nlp.contact.panels.frames`; 4 vertices, both ways, the smaller) from
    state ia to state ib (all (n,))."""
    Pa, Pb, Qa, Qb = (st.quads(s, x) for s, x in ((ia, p), (ib, p), (ia, q), (ib, q)))
    m = np.full(len(p), np.inf)
    for A, B, C, D, x in ((Pa, Pb, Qa, Qb, p), (Qa, Qb, Pa, Pb, q)):   # C, D in A's frame
        La, Lb = _local(A, st.frames(ia, x), C), _local(B, st.frames(ib, x), D)
        m = np.minimum(m, most(norm(Lb - La)))
    return m


def _local(A: np.ndarray, frame: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Coordinates (n, 4, 3) of the points B (n, 4, 3) in the frames (n, 3, 3) (rows the
    axes) of the panels with corners A (n, 4, 3), origin at their corner a."""
    r = B - A[:, :1]
    return np.stack([dot(r, frame[:, None, k]) for k in range(3)], axis=-1)


def per_state(f, st: States, s: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """f(st, s, p, q) (n,) computed once for each distinct (state, pair) among the n
    (s, p, q all (n,)), in batches of ``BATCH`` (their temporaries stay in cache)."""
    P = st.geo.N * st.geo.M
    first, inv = _distinct((s * P + p) * P + q)
    s, p, q = s[first], p[first], q[first]
    out = [f(st, s[k:k + BATCH], p[k:k + BATCH], q[k:k + BATCH])
           for k in range(0, len(s), BATCH)]
    return np.concatenate(out or [np.zeros(0)])[inv]


def in_batches(f, st: States, *index: np.ndarray) -> np.ndarray:
    """f(st, *index) (n,) for the index arrays (all (n,)), in batches of ``BATCH``."""
    n = len(index[0])
    out = [f(st, *(x[k:k + BATCH] for x in index)) for k in range(0, n, BATCH)]
    return np.concatenate(out or [np.zeros(0)])


def _distinct(code: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (u,) of one occurrence of each distinct value of ``code`` (n,) and the
    index (n,) of every entry's value among them (by sorting)."""
    order = np.argsort(code, kind="stable")
    c = code[order]
    new = np.ones(len(c), dtype=bool)
    new[1:] = c[1:] != c[:-1]
    inv = np.empty(len(c), dtype=np.int64)
    inv[order] = np.cumsum(new) - 1
    return order[new], inv


def _split(rows: np.ndarray, st: States) -> np.ndarray:
    """Halve the steps of ``rows`` (n, 4): the child rows (2n, 4), the n first halves
    (a, mid) then the n second (mid, b), the midpoint states not yet in ``st`` added to
    it."""
    first, inv = _distinct(rows[:, 0] * len(st.omegas) + rows[:, 1])
    w = np.asarray(st.omegas)
    mid = st.index((w[rows[first, 0]] + w[rows[first, 1]]) / 2)[inv]
    left = np.stack([rows[:, 0], mid, rows[:, 2], rows[:, 3]], axis=1)
    right = np.stack([mid, rows[:, 1], rows[:, 2], rows[:, 3]], axis=1)
    return np.concatenate([left, right])
