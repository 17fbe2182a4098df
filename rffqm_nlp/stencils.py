"""Sparse Jacobians assembled from local stencils.

A constraint vector g(x) whose rows are local (each a small function of a few entries of x)
is a list of :class:`Stencil`: one small CasADi Function applied to many instances,
g[rows[i]] = function(x[columns[i]], params[i]). Its Jacobian (:class:`LocalJacobian`) is
the small Function's Jacobian, mapped over the instances and scattered by the index arrays:
built in time and memory that grow like the number of instances, where CasADi's Jacobian of
the whole expression graph grows faster (docs/solvers.md, "g's Jacobian from local
stencils"). Rows whose derivatives are constant (linear rows) are given as triplets.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class Stencil:
    """g[rows[i]] = function(x[columns[i]], params[i]) for the n instances i.

    ``function``: (k,), (p,) -> (m,), a CasADi Function (SX for many instances);
    ``columns`` (n, k) and ``rows`` (n, m): integer indices into x and g;
    ``params`` (n, p): the constants of each instance.
    """

    function: ca.Function
    columns: np.ndarray
    rows: np.ndarray
    params: np.ndarray

    def __post_init__(self) -> None:
        f, n = self.function, self.columns.shape[0]
        k, p, m = f.numel_in(0), f.numel_in(1), f.numel_out(0)
        for name, arr, width in (("columns", self.columns, k), ("rows", self.rows, m),
                                 ("params", self.params, p)):
            if arr.shape != (n, width):
                raise ValueError(f"Stencil {f.name()}: {name} has shape {arr.shape}, "
                                 f"expected {(n, width)}")


def stencil(function: ca.Function, columns: np.ndarray, rows: np.ndarray,
            params: np.ndarray | None = None) -> Stencil:
    """A :class:`Stencil` with its index arrays as int64 (n, k) and (n, m) and its params
    as float (n, p) (none: p = 0)."""
    columns = np.asarray(columns, dtype=np.int64)
    n = columns.shape[0]
    params = np.zeros((n, 0)) if params is None else np.asarray(params, dtype=float)
    return Stencil(function, columns, np.asarray(rows, dtype=np.int64),
                   np.ascontiguousarray(params.reshape(n, -1)))


def repeated(function: ca.Function, columns: list[np.ndarray], rows: list[np.ndarray],
             params: list[np.ndarray] | None = None) -> Stencil:
    """A :class:`Stencil` from per-input index arrays of one common shape (e.g. a grid of
    panels): ``columns[c]`` holds input c's index in x at every instance, ``rows[o]``
    output o's row in g and ``params[q]`` param q, each flattened column-major."""
    flat = lambda arrays: np.stack([np.ravel(a, order="F") for a in arrays], axis=1)  # noqa: E731
    return stencil(function, flat(columns), flat(rows),
                   None if not params else flat(params))


def single(name: str, inputs: list, expr, columns: np.ndarray, rows: np.ndarray) -> Stencil:
    """One instance: the rows ``rows`` (m,) of g are ``expr`` (m values) of the symbols
    ``inputs`` (SX or MX, each vectorised column-major), which are x[columns]."""
    z = ca.vertcat(*(ca.vec(a) for a in inputs))
    p = (ca.SX if isinstance(z, ca.SX) else ca.MX).sym("p", 0)
    return stencil(ca.Function(name, [z, p], [expr]), np.asarray(columns)[None, :],
                   np.asarray(rows)[None, :])


@dataclass(frozen=True)
class Constant:
    """Rows with a constant Jacobian, as triplets (rows, columns, values), each (e,)."""

    rows: np.ndarray
    columns: np.ndarray
    values: np.ndarray


class _Mapped:
    """One stencil's Jacobian, mapped over its instances, evaluated into ``out`` (its
    nonzeros, instance by instance)."""

    def __init__(self, s: Stencil):
        f = s.function
        z, p = f.sx_in() if f.is_a("SXFunction") else f.mx_in()
        jac = ca.Function(f"d_{f.name()}", [z, p], [ca.jacobian(f(z, p), z)])
        colind, row = (np.array(a, dtype=np.int64) for a in jac.sparsity_out(0).get_ccs())
        col = np.repeat(np.arange(colind.size - 1), np.diff(colind))
        n = s.columns.shape[0]
        self._stencil, self._local = s, (row, col)
        self._index = s.columns
        self._z = np.zeros(s.columns.shape)
        self._p = s.params
        self._buffer, self._eval = jac.map(n).buffer()
        self._buffer.set_arg(0, memoryview(self._z))
        self._buffer.set_arg(1, memoryview(self._p))
        self.out = np.zeros(n * len(row))
        self._buffer.set_res(0, memoryview(self.out))

    def entries(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows and columns in g and x of the nonzeros of ``out`` (each (n nnz,),
        instance by instance)."""
        row, col = self._local
        return self._stencil.rows[:, row].ravel(), self._stencil.columns[:, col].ravel()

    def __call__(self, x: np.ndarray) -> None:
        np.take(x, self._index, out=self._z)
        self._eval()


class LocalJacobian:
    """The Jacobian (n_g x n_x, CSC) of the rows of ``stencils`` and ``constants``, which
    must cover every row of g once.

    :meth:`pattern` gives its sparsity with data = 1 + the index of each nonzero, and
    calling it at x its nonzeros (nnz,) in that order (what :mod:`rffqm_nlp.reduced`
    slices). The maps and the scatter are built at the first use.
    """

    def __init__(self, stencils: list[Stencil], constants: list[Constant],
                 shape: tuple[int, int]):
        self.stencils = [s for s in stencils if s.columns.shape[0]]
        self.constants, self.shape = list(constants), shape
        self._mapped: list[_Mapped] | None = None

    def with_stencil(self, s: Stencil) -> "LocalJacobian":
        """This Jacobian with the rows of ``s`` appended (their indices from n_g on)."""
        return LocalJacobian(self.stencils + [s], self.constants,
                             (self.shape[0] + s.rows.size, self.shape[1]))

    def _build(self) -> list[_Mapped]:
        if self._mapped is not None:
            return self._mapped
        n_g = self.shape[0]
        covered = np.concatenate([s.rows.ravel() for s in self.stencils]
                                 + [np.unique(c.rows) for c in self.constants])
        if covered.size != n_g or not np.array_equal(np.sort(covered), np.arange(n_g)):
            raise RuntimeError("the stencils do not cover each constraint row once")
        mapped = [_Mapped(s) for s in self.stencils]
        self._constant = np.concatenate([c.values for c in self.constants] + [np.zeros(0)])
        entries = [m.entries() for m in mapped] + [(c.rows, c.columns) for c in self.constants]
        key = np.concatenate([cols * n_g + rows for rows, cols in entries])
        del entries
        key, self._position = np.unique(key, return_inverse=True)
        col, row = np.divmod(key, n_g)
        self._pattern = sp.csc_matrix((np.arange(1, key.size + 1, dtype=float), (row, col)),
                                      shape=self.shape)
        self._pattern.sort_indices()
        self._mapped = mapped
        return mapped

    def pattern(self) -> sp.csc_matrix:
        """The sparsity, data = 1 + the index of each nonzero."""
        self._build()
        return self._pattern.copy()

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The nonzeros (nnz,) at x (n_x,)."""
        mapped = self._build()
        for m in mapped:
            m(x)
        values = np.concatenate([m.out for m in mapped] + [self._constant])
        return np.bincount(self._position, weights=values, minlength=self._pattern.nnz)


class LiftedJacobian:
    """The Jacobian (n_g x n_x) of rows f(x, u) at u = h(x), where h reads only a few
    columns of x (``columns``, k of them): J = F_x + F_u H, with F the
    :class:`LocalJacobian` ``inner`` over (x, u) (n_g x (n_x + n_u)) and H = dh/dx in those
    columns (n_u x k, dense).

    ``lift``: x -> (u (n_u,), H (n_u, k)); ``reach`` (n_u, k), bool: H's structural
    nonzeros. Where u is many intermediate values of a few variables (a free
    correspondence's target lattice of its controls), F is local and cheap to build; the
    Jacobian of f(x, h(x)) in x directly is dense in those few columns, and CasADi's build
    of it is not cheap. The same interface as LocalJacobian: :meth:`pattern` and the
    nonzeros at x.
    """

    def __init__(self, inner: LocalJacobian,
                 lift: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                 columns: np.ndarray, reach: np.ndarray):
        self.inner, self.shape = inner, (inner.shape[0], inner.shape[1] - reach.shape[0])
        self._lift, self._columns, self._reach = lift, np.asarray(columns), reach
        self._built = False

    def _build(self) -> None:
        if self._built:
            return
        n_x = self.shape[1]
        F = self.inner.pattern()
        Fx, Fu = F[:, :n_x].tocoo(), F[:, n_x:].tocsr()
        self._lifted_rows = np.flatnonzero(np.diff(Fu.indptr))  # the rows that read u
        Fu = Fu[self._lifted_rows]
        # the nonzeros of F_u H: the lifted rows' entries in the columns that they reach
        ones = sp.csr_matrix((np.ones(Fu.nnz), Fu.indices, Fu.indptr), shape=Fu.shape)
        self._reached = (ones @ self._reach.astype(float)) > 0  # (lifted rows, k)
        at_row, at_col = np.nonzero(self._reached)
        rows = np.concatenate([Fx.row, self._lifted_rows[at_row]])
        cols = np.concatenate([Fx.col, self._columns[at_col]])
        key, position = np.unique(cols * self.shape[0] + rows, return_inverse=True)
        col, row = np.divmod(key, self.shape[0])
        self._pattern = sp.csc_matrix((np.arange(1, key.size + 1, dtype=float), (row, col)),
                                      shape=self.shape)
        self._pattern.sort_indices()
        # where each of F_x's nonzeros and each reached entry of F_u H go, and which of the
        # inner Jacobian's nonzeros they read
        self._from_x = (position[:Fx.nnz], Fx.data.astype(np.int64) - 1)
        self._to_lifted = position[Fx.nnz:]
        self._Fu_index = Fu.data.astype(np.int64) - 1
        self._Fu = sp.csr_matrix((np.zeros(Fu.nnz), Fu.indices, Fu.indptr), shape=Fu.shape)
        self._built = True

    def pattern(self) -> sp.csc_matrix:
        """The sparsity, data = 1 + the index of each nonzero."""
        self._build()
        return self._pattern.copy()

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The nonzeros (nnz,) at x (n_x,)."""
        self._build()
        u, H = self._lift(x)
        values = self.inner(np.concatenate([x, u]))
        out = np.zeros(self._pattern.nnz)
        to, index = self._from_x
        out[to] = values[index]
        self._Fu.data[:] = values[self._Fu_index]
        out[self._to_lifted] += (self._Fu @ H)[self._reached]
        return out
