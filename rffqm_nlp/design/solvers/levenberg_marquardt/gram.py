"""The Gram matrices of one pass over the levels (:class:`.window.Window`): J' J and J' r
of the reduced Jacobian and the damping metric S_p' D_p S_p, each a BLAS syrk of rows
gathered by their range of columns, the columns cut into bands."""

from __future__ import annotations

import numpy as np
import scipy.linalg as la

#: rows gathered before one update of J' J or of the metric (:class:`Gram`), and of one
#: band's range of columns of them
GRAM_ROWS = 1024
BAND_ROWS = 256
#: the Gram matrices' columns are cut into at most BANDS bands of at least BAND_WIDTH
#: columns (:func:`bands`)
BANDS = 8
BAND_WIDTH = 128


def bands(n: int) -> np.ndarray:
    """The edges (bands + 1,) of the bands the n pool columns are cut into for the Gram
    matrices (:class:`Gram`): one below 2 :data:`BAND_WIDTH` columns, at most
    :data:`BANDS`."""
    count = max(1, min(BANDS, n // BAND_WIDTH))
    return np.linspace(0, n, count + 1).round().astype(np.int64)


class Sums:
    """The sums of one pass over the levels: the Gram matrix of the residual rows [J_m J_f
    r] (n_m marching columns, n_f free ones: ``Jf``, (n_r, n_f), J's free columns, in which
    S is zero; r (n_r,)), which holds J' J and J' r, and the metric's over the marching
    columns: one syrk each and no products of their own (with two OpenBLAS threads, separate
    products slowed the whole solve down: docs/decisions/large-patterns.md). In the
    residuals' Gram matrix the n_f + 1 columns of J_f and r sit at the corner's column
    ``mid``, inside every row's range of columns (:class:`.window.Window`)."""

    def __init__(self, n_m: int, mid: int, Jf: np.ndarray, r: np.ndarray):
        self.Jf, self.r, self.mid = Jf, r[:, None], mid
        self.extra = Jf.shape[1] + 1
        self.jacobian, self.metric = Gram(n_m + self.extra), Gram(n_m)

    def add(self, Jm: np.ndarray, rows: np.ndarray, a: int, b: int) -> None:
        """Residual rows ``rows`` (k,): their reduced Jacobian in the marching columns Jm
        (k, n_m), nonzero only in the columns a:b (a <= mid <= b)."""
        mid = self.mid
        self.jacobian.add(a, b + self.extra, Jm[:, a:mid], self.Jf[rows], self.r[rows],
                          Jm[:, mid:b])

    def total(self, marching: np.ndarray, free: np.ndarray, metric: bool = True) -> tuple:
        """(J' J, J' r, S_p' D_p S_p) in the design's order (n_d = n_m + n_f); the last
        None without ``metric``."""
        mid, n_f = self.mid, free.size
        order = np.concatenate([marching[:mid], free, marching[mid:]])  # the Gram's, less r
        keep = np.concatenate([np.arange(mid + n_f), mid + n_f + 1 + np.arange(marching.size
                                                                               - mid)])
        gram = self.jacobian.total()
        n = order.size
        source = keep[np.argsort(order)]  # the Gram's row of each design variable
        JtJ, grad = gram[np.ix_(source, source)], gram[source, mid + n_f]
        del gram
        if not metric:
            return JtJ, grad, None
        M = np.zeros((n, n))
        M[np.ix_(marching, marching)] = self.metric.total()
        return JtJ, grad, M


class Gram:
    """A' A (n x n) of rows A added a block at a time, each block nonzero only in the
    columns a:b: gathered per range into a buffer (:data:`GRAM_ROWS` rows for the whole
    range, :data:`BAND_ROWS` for a part), each full buffer one BLAS syrk added into the
    range's diagonal block of the upper triangle."""

    def __init__(self, n: int):
        self.n = n
        self._upper = np.zeros((n, n), order="F")
        self._buffers: dict[tuple[int, int], list] = {}  # (a, b) -> [buffer, rows used]

    def add(self, a: int, b: int, *parts: np.ndarray, scale: np.ndarray | None = None
            ) -> None:
        """Add rows (k, n) nonzero only in the columns a:b, given as those columns' blocks
        side by side (k, n_i), each row times its ``scale`` (k, 1) if given."""
        k = parts[0].shape[0]
        entry = self._buffers.get((a, b))
        if entry is None:
            size = GRAM_ROWS if b - a == self.n else BAND_ROWS
            entry = self._buffers[(a, b)] = [np.empty((size, b - a)), 0]
        buffer, used = entry
        if used + k > buffer.shape[0]:
            self._flush(a, b)
            used = 0
        if k > buffer.shape[0]:
            rows = np.hstack(parts)
            self._syrk(a, b, rows if scale is None else rows * scale)
            return
        out, column = buffer[used:used + k], 0
        for part in parts:
            into = out[:, column:column + part.shape[1]]
            if scale is None:
                into[:] = part
            else:
                np.multiply(part, scale, out=into)
            column += part.shape[1]
        entry[1] = used + k

    def total(self) -> np.ndarray:
        """The symmetric sum (n, n), made in place of the upper triangle (whose lower one
        the syrks leave zero), and handed over: the Gram is spent."""
        for a, b in self._buffers:
            self._flush(a, b)
        upper, self._upper, self._buffers = self._upper, None, {}
        upper += np.triu(upper, 1).T
        return upper

    def _flush(self, a: int, b: int) -> None:
        entry = self._buffers[(a, b)]
        if entry[1]:
            self._syrk(a, b, entry[0][:entry[1]])
            entry[1] = 0

    def _syrk(self, a: int, b: int, rows: np.ndarray) -> None:
        if b - a == self.n:
            self._upper = la.blas.dsyrk(1.0, rows.T, beta=1.0, c=self._upper, trans=0,
                                        lower=0, overwrite_c=1)
        else:
            self._upper[a:b, a:b] += la.blas.dsyrk(1.0, rows.T, trans=0, lower=0)
