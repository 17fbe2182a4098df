"""One pass over the levels of the marching equations (:class:`Window`): J' J, J' r and the
damping metric of the reduced problem, accumulated level by level from the rows of the
state's sensitivity S that a later level or a residual still needs (the working set), or
from all of S where it is small."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ...stencils import Lift
from .gram import Sums, bands
from .levels import Levels

#: entries (state x marching design) of S up to which the pass keeps it whole (8 MB, which
#: stays in the cache: its products are then cheaper than the sweeps;
#: docs/decisions/large-patterns.md)
WHOLE_S = 1 << 20
#: rows of a level computed at once in the pass (:class:`Window`): their product with
#: the working set, CHUNK_ROWS x n_u, is the pass's largest temporary
CHUNK_ROWS = 1024


class Window:
    """J' J, J' r and S_p' D_p S_p of the reduced problem in one pass over the levels,
    holding only the rows of S still needed (the working set) instead of all of S.

    Each state row gets a slot in a pool (``pool`` rows) from its level until the last level
    that uses it: the marching equations of a later level, or a residual row, which is
    reduced at the level of its latest state unknown (residual rows that use no state come
    first). A slot freed is reused by a later level, except where S B has at most
    :data:`WHOLE_S` entries (``whole``): then every state row keeps its own slot, the
    residual rows are reduced at once after the last level (one product instead of one a
    level), and the pass gives S B. The pool's columns are the design's coordinates u
    (``basis`` B, n_d x n_u: dd = B du, :func:`.manifold.boundary_basis`) that the march
    reads (``marching``, n_m of them: the boundary data, omega and the rigid alignment), and
    its first rows B's rows of the design variables the march reads; the lifted design variables
    (``free``, in u, n_f: a free correspondence's controls, B's identity there, which the
    march does not read) have no column: their reduced Jacobian is J_d's columns plus F_u H
    (:class:`rffqm_nlp.design.stencils.Lift`, formed once a pass).

    The pool's columns follow the boundary (``position``, (n_u,): the left edge from its
    top down to the corner, then the bottom edge; omega, the alignment and any coordinate
    without a position at the corner): the state at vertex (i, j) reads only the boundary
    data of the vertices (0..i, 0) and (0, 0..j), so every row of S B is nonzero only in a
    range of columns around the corner, about (i + j) / (N + M) of them (:meth:`spans`;
    ``design_span``: those of the design variables' rows). The rows are gathered by their
    range, cut into :func:`.gram.bands` bands (:class:`.gram.Gram`), so the Gram matrices
    cost about a third of the dense products' arithmetic at large sizes.

    Static: built once from the sparsity; ``J`` (n_r x (n_d + n_s), design columns then the
    state in level order) has data = 1 + the index of each nonzero in the residuals'
    Jacobian (its direct part). ``pattern`` (state rows) and ``weights`` are the metric's
    rows and their D; ``free`` (design positions, whose rows of B are their own columns')
    and ``lifted_rows`` (the residual rows F_u H reaches, in the Lift's order) are empty
    without a lift.
    """

    def __init__(self, levels: Levels, J: sp.csr_matrix, pattern: np.ndarray,
                 weights: np.ndarray, free: np.ndarray, lifted_rows: np.ndarray,
                 basis: sp.csr_matrix, position: np.ndarray):
        n_d, n_s = levels.n_d, levels.n_s
        self.levels = levels
        level = np.empty(n_s, dtype=np.int64)
        for k, (lo, hi) in enumerate(levels.bounds):
            level[lo:hi] = k
        J = J.tocsr()
        J.sort_indices()
        last = level.copy()  # the last level that uses each state row
        W = levels.W
        uses = W.indices >= n_d
        np.maximum.at(last, W.indices[uses] - n_d, level[np.repeat(
            np.arange(n_s), np.diff(W.indptr))[uses]])
        Jcoo = J.tocoo()
        state = Jcoo.col >= n_d
        at = np.full(J.shape[0], -1, dtype=np.int64)  # the level each residual row is reduced
        np.maximum.at(at, Jcoo.row[state], level[Jcoo.col[state] - n_d])
        np.maximum.at(last, Jcoo.col[state] - n_d, at[Jcoo.row[state]])
        if np.isin(free, W.indices[~uses]).any():
            raise RuntimeError("a lifted design variable is read by the marching equations")
        self.free = basis[free].indices  # in u, in the order of ``free``
        marching = np.setdiff1d(np.arange(basis.shape[1]), self.free)
        self.marching = marching[np.argsort(position[marching], kind="stable")]
        n_m = self.marching.size
        self.whole = n_s * n_m <= WHOLE_S
        slot = np.arange(n_s) if self.whole else self._slots(levels.bounds, last)
        if self.whole:  # no row of S leaves the pool: the residual rows reduced at once, last
            at[:] = len(levels.bounds) - 1
        self.pool = int(slot.max()) + 1 if n_s else 0
        self.mid = int(np.sum(position[self.marching] < 0))  # the first column at the corner
        read = np.setdiff1d(np.arange(n_d), free)  # the design the march reads
        self._top, self.design_span = self._design_rows(basis[read], n_d, read)
        column = np.full(n_d + n_s, -1, dtype=np.int64)  # -> pool row (-1: a free column)
        column[read] = np.arange(read.size)
        column[n_d:] = read.size + slot
        free_column = np.full(n_d, -1, dtype=np.int64)
        free_column[free] = np.arange(free.size)
        width = read.size + self.pool
        span = self.spans(levels, self.design_span)
        edges = bands(n_m)
        # residual rows by level, in the order of their bands: (rows, their part in the
        # pool's columns, k x width, whose data is a view of one array refilled once a pass
        # from J's nonzeros at _index, and the segments (a, b, start, stop) of one range)
        lo_r, hi_r = self._residual_spans(Jcoo, column, self.design_span, span, n_d)
        order = np.lexsort((self._band(lo_r, hi_r, edges), at))
        bounds = np.searchsorted(at[order], np.arange(-1, len(levels.bounds) + 1))
        self._residuals, index, start = {}, [], 0
        self._data = np.zeros(int((column[J.indices] >= 0).sum()))
        for k, lo, hi in zip(range(-1, len(levels.bounds)), bounds[:-1], bounds[1:]):
            if hi > lo:
                rows = order[lo:hi]
                block, block_index = self._pooled(J[rows], column, width, start)
                self._residuals[k] = (rows, block, self._segments(lo_r[rows], hi_r[rows],
                                                                  edges))
                index.append(block_index)
                start += block_index.size
        self._index = np.concatenate(index) if index else np.zeros(0, dtype=np.int64)
        # J's direct part in the free columns (n_r x n_f), data = J's nonzeros at _free_index
        own = column[Jcoo.col] < 0
        rows, cols = Jcoo.row[own], free_column[Jcoo.col[own]]
        self._free = sp.csr_matrix((np.zeros(rows.size), (rows, cols)),
                                   shape=(J.shape[0], self.free.size))
        self._free.sort_indices()
        self._free_index = (Jcoo.data[own].astype(np.int64) - 1)[np.lexsort((cols, rows))]
        self._lifted_rows = lifted_rows
        is_pattern = np.zeros(n_s, dtype=bool)
        is_pattern[pattern] = True
        root = np.zeros(n_s)
        root[pattern] = np.sqrt(weights)
        counts = [int(is_pattern[lo:hi].sum()) for lo, hi in levels.bounds]
        if any(not is_pattern[lo:lo + k].all() for (lo, _), k in zip(levels.bounds, counts)):
            raise RuntimeError("the metric's rows of a level do not come first")
        # per level, its chunks of at most CHUNK_ROWS rows lo:hi: (their pool rows: a slice
        # where S is whole, else their slots; W_k's rows lo:hi in the pool's columns, the
        # metric's rows among them: their number k (the first k), their order by band
        # (None: as they are), their roots of D in that order (k, 1) and their segments
        # (a, b, start, stop))
        top = self._top.shape[0]
        self.chunks = []
        for (lo, hi), count in zip(levels.bounds, counts):
            chunks = []
            for a in range(lo, hi, CHUNK_ROWS):
                b = min(hi, a + CHUNK_ROWS)
                k = max(0, min(b, lo + count) - a)
                band = self._band(span[0][a:a + k], span[1][a:a + k], edges)
                perm = np.argsort(band, kind="stable")
                if np.array_equal(perm, np.arange(k)):
                    perm = None
                mine = np.arange(a, a + k) if perm is None else a + perm
                into = slice(top + a, top + b) if self.whole else top + slot[a:b]
                chunks.append((into, levels.block(a, b, column[W.indices[W.indptr[a]:
                                                                         W.indptr[b]]], width),
                               k, perm, root[mine, None],
                               self._segments(span[0][mine], span[1][mine], edges)))
            self.chunks.append(chunks)

    def _design_rows(self, rows: sp.csr_matrix, n_d: int, read: np.ndarray
                     ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray]]:
        """The pool's first rows (the ``rows`` of B that the march reads, in the pool's
        columns; (k, n_m)) and the first and last pool column of each design variable's
        row (each (n_d,); the corner's for one the march does not read)."""
        place = np.full(rows.shape[1], -1, dtype=np.int64)
        place[self.marching] = np.arange(self.marching.size)
        coo = rows.tocoo()
        if np.any(place[coo.col] < 0):
            raise RuntimeError("a design variable the march reads has a lifted coordinate")
        top = np.zeros((rows.shape[0], self.marching.size))
        top[coo.row, place[coo.col]] = coo.data
        first, last = np.full(n_d, self.mid), np.full(n_d, self.mid)
        first[read], last[read] = n_d, -1
        np.minimum.at(first, read[coo.row], place[coo.col])
        np.maximum.at(last, read[coo.row], place[coo.col])
        return top, (first, last)

    def spans(self, levels: Levels, design: tuple[np.ndarray, np.ndarray]
              ) -> tuple[np.ndarray, np.ndarray]:
        """The first and last pool column (each (n_s,)) in which each state row of S B can
        be nonzero, widened to hold the corner's column ``mid``: a level's rows read the
        design (``design``: each design variable's first and last column, (n_d,)) and the
        earlier rows of their marching equations."""
        n_d, n_s, W = levels.n_d, levels.n_s, levels.W
        first, last = np.full(n_s, self.mid), np.full(n_s, self.mid)
        for lo, hi in levels.bounds:
            start, stop = W.indptr[lo], W.indptr[hi]
            a, b = self._entry_spans(W.indices[start:stop], design, (first, last), n_d)
            counts = np.diff(W.indptr[lo:hi + 1])
            has = counts > 0
            starts = (W.indptr[lo:hi] - start)[has]
            first[lo:hi][has] = np.minimum(np.minimum.reduceat(a, starts), self.mid)
            last[lo:hi][has] = np.maximum(np.maximum.reduceat(b, starts), self.mid)
        return first, last

    def _residual_spans(self, coo: sp.coo_matrix, column: np.ndarray,
                        design: tuple[np.ndarray, np.ndarray],
                        span: tuple[np.ndarray, np.ndarray], n_d: int
                        ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`spans` of the residual rows (each (n_r,)), over their entries in J
        (``coo``; ``column``: the pool row of each variable, -1 for a free one)."""
        pooled = column[coo.col] >= 0
        a, b = self._entry_spans(coo.col, design, span, n_d)
        first, last = np.full(coo.shape[0], self.mid), np.full(coo.shape[0], self.mid)
        np.minimum.at(first, coo.row[pooled], a[pooled])
        np.maximum.at(last, coo.row[pooled], b[pooled])
        return first, last

    @staticmethod
    def _entry_spans(cols: np.ndarray, design: tuple[np.ndarray, np.ndarray],
                     state: tuple[np.ndarray, np.ndarray], n_d: int
                     ) -> tuple[np.ndarray, np.ndarray]:
        """Per variable ``cols`` (indices into [design, state]): the first and last pool
        column of its row in the pool, from ``design`` ((n_d,) each) or ``state`` ((n_s,)
        each)."""
        is_design = cols < n_d
        d, k = np.minimum(cols, n_d - 1), np.maximum(cols - n_d, 0)
        return (np.where(is_design, design[0][d], state[0][k]),
                np.where(is_design, design[1][d], state[1][k]))

    @staticmethod
    def _band(first: np.ndarray, last: np.ndarray, edges: np.ndarray) -> np.ndarray:
        """The key of the range of bands that holds columns first..last, per row."""
        count = edges.size - 1
        return (np.searchsorted(edges, first, "right") - 1) * count + np.searchsorted(
            edges, last, "right") - 1

    @staticmethod
    def _segments(first: np.ndarray, last: np.ndarray, edges: np.ndarray) -> list[tuple]:
        """Rows sorted by their band key as runs (a, b, start, stop): rows start:stop hold
        their nonzeros in the columns a:b (band edges)."""
        if not first.size:
            return []
        low = np.searchsorted(edges, first, "right") - 1
        high = np.searchsorted(edges, last, "right")
        change = np.flatnonzero((np.diff(low) != 0) | (np.diff(high) != 0)) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [first.size]])
        return [(int(edges[low[i]]), int(edges[high[i]]), int(i), int(j))
                for i, j in zip(starts, stops)]

    def _pooled(self, block: sp.csr_matrix, column: np.ndarray, width: int, start: int
                ) -> tuple[sp.csr_matrix, np.ndarray]:
        """Residual rows (k, n_d + n_s) in the pool's columns (k x width), their data the
        view of ``_data`` from ``start``, and the index in J of each of its nonzeros."""
        coo = block.tocoo()
        keep = column[coo.col] >= 0
        rows, cols = coo.row[keep], column[coo.col[keep]]
        order = np.lexsort((cols, rows))  # CSR's order
        indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=block.shape[0]))])
        stop = start + rows.size
        part = sp.csr_matrix((self._data[start:stop], cols[order], indptr),
                             shape=(block.shape[0], width))
        part.data = self._data[start:stop]  # a view (the constructor may have copied)
        return part, (coo.data[keep].astype(np.int64) - 1)[order]

    @staticmethod
    def _slots(bounds: list[tuple[int, int]], last: np.ndarray) -> np.ndarray:
        """A pool slot for every state row (n_s,): the rows of level k take the slots of
        the rows whose last use was before k, then new ones."""
        slot = np.empty(last.size, dtype=np.int64)
        order = np.argsort(last, kind="stable")
        ends = np.searchsorted(last[order], np.arange(len(bounds)), "right")
        free, size, freed_to = np.zeros(0, dtype=np.int64), 0, 0
        for k, (lo, hi) in enumerate(bounds):
            if k > 0:  # rows last used at level k - 1 free their slots
                free = np.concatenate([free, slot[order[freed_to:ends[k - 1]]]])
                freed_to = ends[k - 1]
            take = min(free.size, hi - lo)
            fresh = np.arange(size, size + hi - lo - take)
            slot[lo:hi] = np.concatenate([free[:take], fresh])
            free, size = free[take:], size + fresh.size
        return slot

    def __call__(self, J: np.ndarray, r: np.ndarray, lift: Lift | None,
                 metric: bool = True) -> tuple | None:
        """(J' J, J' r, B' S_p' D_p S_p B, S B), in u, at the residuals' Jacobian nonzeros J
        (its direct part), its ``lift`` (columns in the order of ``free``) and the residuals
        r (n_r,), with the levels refilled at the same point; None where they are not
        finite. ``metric``: False skips the metric (None in its place); S B (n_s, n_m; its
        columns ``marching``) is None unless ``whole``."""
        top = self._top.shape[0]
        # [B's rows; the working set]: a row of the working set is written at its level
        # before any later level or residual reads it (the W_k read earlier levels only)
        pool = np.empty((top + self.pool, self.marching.size))
        pool[:top] = self._top
        self._data[:] = J[self._index]
        self._free.data[:] = J[self._free_index]
        Jf = self._free.toarray()  # the free columns of J (n_r, n_f): S is zero in them
        if lift is not None:
            Jf[self._lifted_rows] += lift.product()
        sums = Sums(self.marching.size, self.mid, Jf, r)
        self._reduce(-1, pool, sums)
        for k, chunks in enumerate(self.chunks):
            for into, W, mine, perm, root, segments in chunks:
                S = W @ pool
                pool[into] = S
                if metric and mine:
                    rows = S[:mine] if perm is None else S[perm]
                    for a, b, start, stop in segments:
                        sums.metric.add(a, b, rows[start:stop, a:b], scale=root[start:stop])
            self._reduce(k, pool, sums)
        out = sums.total(self.marching, self.free, metric)
        if not all(a is None or np.all(np.isfinite(a)) for a in out):
            return None
        return (*out, pool[top:] if self.whole else None)

    def _reduce(self, k: int, pool: np.ndarray, sums: Sums) -> None:
        """The residual rows reduced at level k added to the sums (in place)."""
        if k in self._residuals:
            rows, pooled, segments = self._residuals[k]
            Jm = pooled @ pool
            for a, b, start, stop in segments:
                sums.add(Jm[start:stop], rows[start:stop], a, b)
