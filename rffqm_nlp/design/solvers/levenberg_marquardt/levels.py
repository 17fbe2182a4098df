"""The marching equations in levels: each equation matched to its own unknown, its level
(the longest chain of dependencies before it), and the sweeps through the levels that apply
the state's sensitivity S = ds/dd and its transpose without storing it."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import maximum_bipartite_matching

from ...stencils import index_array

#: rows of W scaled at once when it is refilled (:meth:`Levels.refill`; a temporary
#: as long as their nonzeros instead of three as long as all of W's)
REFILL_ROWS = 1 << 16


class Levels:
    """The marching equations in level order, s = W_d d + W_s s with W_s strictly lower
    triangular by levels: the unknowns of level k are the state rows lo_k:hi_k and
    s_k = W_k [d; s[:lo_k]], W_k = -diag_k^-1 [C_d,k  C_s,k] (C without the own unknowns).
    The W_k share one data array, refilled from G's nonzeros at each point (:meth:`refill`).

    ``Cd`` (n_s x n_d) and ``Cs`` (n_s x n_s, without the own unknowns) are the marching
    equations in level order as patterns with data = 1 + the index of each nonzero in G's,
    ``bounds`` the (lo_k, hi_k) of each level, ``diagonal`` (n_s,) the index in G of each
    equation's own unknown. S = ds/dd is never stored: :meth:`forward` applies it to a
    block, :meth:`adjoint` its transpose, and :class:`.window.Window` accumulates its products."""

    def __init__(self, Cd: sp.csr_matrix, Cs: sp.csr_matrix, bounds: list[tuple[int, int]],
                 diagonal: np.ndarray):
        self.n_d, self.n_s = Cd.shape[1], Cs.shape[1]
        W = sp.hstack([Cd, Cs], format="csr")  # rows: equations in level order
        W.sort_indices()
        self._index = index_array(W.data - 1)  # of each nonzero in G
        self._counts = np.diff(W.indptr)
        self.data = np.zeros(W.nnz)
        W.data = self.data  # W's values: refilled with the shared array
        self.W = W
        self._diagonal = diagonal  # per equation (level order): its own unknown's index in G
        self.bounds = bounds
        self.blocks = [self.block(lo, hi, W.indices[W.indptr[lo]:W.indptr[hi]], self.n_d + lo)
                       for lo, hi in bounds]
        self._compressed()

    def block(self, lo: int, hi: int, columns: np.ndarray, width: int) -> sp.csr_matrix:
        """W_k of the level lo:hi with its nonzeros' columns given (same order as W's) and
        ``width`` columns; its data a view of the shared array, refilled with it."""
        start, stop = self.W.indptr[lo], self.W.indptr[hi]
        block = sp.csr_matrix((self.data[start:stop], columns, self.W.indptr[lo:hi + 1] - start),
                              shape=(hi - lo, width))
        block.data = self.data[start:stop]  # a view (the constructor may have copied)
        return block

    def _compressed(self) -> None:
        """Per level (the columns W_k uses, W_k' over those columns alone: CSC, the
        transpose of W_k's rows with their columns renumbered), for :meth:`adjoint`: W_k'
        applied to a level is then a product over the columns it reaches, where W_k' over
        all earlier columns would cost a pass over the whole state per level. Their data
        are views of the shared array, as the blocks', so no transposed copy is kept."""
        W, self.compressed = self.W, []
        for lo, hi in self.bounds:
            start, stop = W.indptr[lo], W.indptr[hi]
            columns, used = np.unique(W.indices[start:stop], return_inverse=True)
            T = self.block(lo, hi, index_array(used), columns.size).T
            T.data = self.data[start:stop]  # a view (the transpose may have copied)
            self.compressed.append((columns, T))

    def refill(self, G: np.ndarray) -> bool:
        """W at G's nonzeros (the constraints' Jacobian); False where an equation's own
        unknown has a zero coefficient (the march no longer determines it)."""
        diagonal = G[self._diagonal]
        if np.any(diagonal == 0):
            return False
        np.take(G, self._index, out=self.data, mode="clip")  # "raise" would buffer a copy
        scale, indptr = -1.0 / diagonal, self.W.indptr
        for lo in range(0, scale.size, REFILL_ROWS):  # W's rows scaled a block at a time
            hi = min(scale.size, lo + REFILL_ROWS)
            self.data[indptr[lo]:indptr[hi]] *= np.repeat(scale[lo:hi], self._counts[lo:hi])
        return True

    def forward(self, X: np.ndarray) -> np.ndarray:
        """S X (n_s,) or (n_s, p) for X (n_d,) or (n_d, p): the level-by-level sweep."""
        Y = np.empty((self.n_d + self.n_s,) + X.shape[1:])
        Y[:self.n_d] = X
        for (lo, hi), W in zip(self.bounds, self.blocks):
            Y[self.n_d + lo:self.n_d + hi] = W @ Y[:self.n_d + lo]
        return Y[self.n_d:]

    def adjoint(self, Y: np.ndarray) -> np.ndarray:
        """S' Y (n_d,) or (n_d, p) for Y (n_s,) or (n_s, p): the sweep backwards."""
        Z = np.zeros((self.n_d + self.n_s,) + Y.shape[1:])
        Z[self.n_d:] = Y
        for (lo, hi), (columns, T) in zip(reversed(self.bounds), reversed(self.compressed)):
            Z[columns] += T @ Z[self.n_d + lo:self.n_d + hi]
        return Z[:self.n_d]


def order_by_level(Cs: sp.csr_matrix, in_pattern: np.ndarray
                   ) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """The matching of the marching equations to their state unknowns, their levels
    (:func:`equation_levels`), and the state reordered by level: the unknowns of each
    level contiguous, in the order of its equations, those of the crease pattern first (the
    metric's rows of a level are then a slice, :class:`.window.Window`).

    ``Cs``: the marching equations' Jacobian pattern in the state (n_s x n_s, data = 1 +
    the index of each nonzero in the constraints' Jacobian); ``in_pattern`` (n_s,) bool:
    the state variables of the crease pattern. Returns the order (n_s,: the old state
    index of each new position), the equations of each level (an array each) and the
    unknown of each equation in the new order (n_s,)."""
    match = maximum_bipartite_matching(Cs, perm_type="column")
    if np.any(match < 0):
        raise RuntimeError("the marching equations are structurally singular in the state")
    Cs = Cs.tocoo()
    own = Cs.col == match[Cs.row]
    off = sp.csr_matrix((Cs.data[~own], (Cs.row[~own], Cs.col[~own])), shape=Cs.shape)
    level = equation_levels(off, match)
    later = ~in_pattern[match]  # per equation: its unknown is not the pattern's
    levels = [e[np.argsort(later[e], kind="stable")]
              for e in (np.flatnonzero(level == k) for k in range(level.max() + 1))]
    order = match[np.concatenate(levels)]  # old state index of each new position
    position = np.empty_like(order)
    position[order] = np.arange(order.size)
    return order, levels, position[match]


def equation_levels(off: sp.csr_matrix, match: np.ndarray) -> np.ndarray:
    """The level of each marching equation (n_eq,): 0 for one that uses no other
    equation's unknown, else one more than the highest level among those it uses
    (Kahn's topological order, one frontier at a time), then the chains postponed
    (:func:`postponed`). ``off``: the equations x state Jacobian pattern without each
    equation's own unknown; ``match`` (n_eq,): the unknown of each equation."""
    owner = np.empty(off.shape[1], dtype=np.int64)
    owner[match] = np.arange(off.shape[0])
    deps = sp.csr_matrix((np.ones(off.nnz), owner[off.indices], off.indptr),
                         shape=(off.shape[0], off.shape[0]))
    deps.sum_duplicates()
    users = deps.T.tocsr()  # row e: the equations that use e's unknown
    waiting = np.diff(deps.indptr)  # unknowns each equation still waits for
    level = np.full(off.shape[0], -1, dtype=np.int64)
    frontier, k = np.flatnonzero(waiting == 0), 0
    while frontier.size:
        level[frontier] = k
        used = gathered(users, frontier)[0]
        np.subtract.at(waiting, used, 1)
        frontier, k = np.unique(used[waiting[used] == 0]), k + 1
    if np.any(level < 0):
        raise RuntimeError("the marching equations are cyclic in the state")
    return postponed(level, deps, users)


def postponed(level: np.ndarray, deps: sp.csr_matrix, users: sp.csr_matrix) -> np.ndarray:
    """The levels (n_eq,) with every chain equation moved to just below its earliest user:
    an equation is a chain's when it uses at most one other equation's unknown, itself a
    chain's (a chain from the design alone). Such a chain's earliest level can lie far
    below the levels that read it, and its rows of S would wait that long in the pass's
    working set (:class:`.window.Window`): the lifted fold multiplier angles PHI of a column
    follow from the bottom edge, at levels 0 to N, while the vertices that read them come
    at about i + j. Postponing an equation with more inputs would hold those instead (the
    partial means of the sides, each over many). ``deps`` and ``users`` (n_eq x n_eq): the
    other equations each equation uses, and those that use it."""
    inputs = np.diff(deps.indptr)
    chain = inputs == 0
    by_level = np.argsort(level, kind="stable")
    bounds = np.searchsorted(level[by_level], np.arange(level.max() + 2))
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        one = by_level[lo:hi][inputs[by_level[lo:hi]] == 1]
        chain[one] = chain[deps.indices[deps.indptr[one]]]
    late = level.copy()
    for lo, hi in zip(bounds[-2::-1], bounds[:0:-1]):
        moved = by_level[lo:hi]
        moved = moved[chain[moved] & (np.diff(users.indptr)[moved] > 0)]
        if moved.size:
            used, starts = gathered(users, moved)
            late[moved] = np.minimum.reduceat(late[used], starts) - 1
    return late


def gathered(csr: sp.csr_matrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The column indices of ``rows`` of ``csr`` one after the other, and where each row's
    run starts in them (rows.size,)."""
    at, counts = positions(csr, rows)
    return csr.indices[at], np.cumsum(counts) - counts


def positions(csr: sp.csr_matrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the nonzeros of ``rows`` of ``csr`` sit in its indices and data, one row
    after the other (nnz,), and each row's count (rows.size,)."""
    starts, counts = csr.indptr[rows], np.diff(csr.indptr)[rows]
    ends = np.cumsum(counts)
    at = np.repeat(starts - ends + counts, counts) + np.arange(ends[-1] if ends.size else 0)
    return at, counts
