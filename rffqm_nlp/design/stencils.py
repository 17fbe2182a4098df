"""Sparse Jacobians assembled from local stencils.

A constraint vector g(x) whose rows are local (each a small function of a few entries of x)
is a list of :class:`Stencil`: one small CasADi Function applied to many instances,
g[rows[i]] = function(x[columns[i]], params[i]). Its Jacobian (:class:`LocalJacobian`) is
the small Function's Jacobian, mapped over the instances and scattered by the index arrays:
built in time and memory that grow like the number of instances, where CasADi's Jacobian of
the whole expression graph grows faster (docs/decisions/large-patterns.md, "g's and r's
Jacobians from local stencils"). Rows whose derivatives are constant (linear rows) are
given as triplets.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np
import scipy.sparse as sp


def index_array(values: np.ndarray) -> np.ndarray:
    """Non-negative integer ``values`` (float or int) as int32 where they fit, else int64:
    the index arrays as long as a large Jacobian's nonzeros halve."""
    top = values.max() if values.size else 0
    return values.astype(np.int32 if top < np.iinfo(np.int32).max else np.int64)


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
    """A :class:`Stencil` with its index arrays (n, k) and (n, m) as :func:`index_array`
    makes them (int32 where they fit: they are kept as long as the Jacobian) and its params
    as float (n, p) (none: p = 0)."""
    columns = index_array(np.asarray(columns, dtype=np.int64))
    n = columns.shape[0]
    params = np.zeros((n, 0)) if params is None else np.asarray(params, dtype=float)
    return Stencil(function, columns, index_array(np.asarray(rows, dtype=np.int64)),
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
    ``size`` nonzeros, instance by instance; an array :meth:`bind` gives)."""

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
        self.size = n * len(row)
        self.out = np.zeros(0)

    def bind(self, out: np.ndarray) -> None:
        """Evaluate into ``out`` ((size,), contiguous) from now on."""
        if out.shape != (self.size,) or not out.flags.c_contiguous:
            raise ValueError(f"{self.size} contiguous nonzeros expected, got {out.shape}")
        self.out = out
        self._buffer.set_res(0, memoryview(out))

    def entries(self) -> tuple[np.ndarray, np.ndarray]:
        """The rows and columns in g and x of the nonzeros of ``out`` (each (n nnz,),
        instance by instance)."""
        row, col = self._local
        return self._stencil.rows[:, row].ravel(), self._stencil.columns[:, col].ravel()

    def __call__(self, x: np.ndarray) -> None:
        np.take(x, self._index, out=self._z, mode="clip")  # "raise" would buffer a copy
        self._eval()


class LocalJacobian:
    """The Jacobian (n_g x n_x, CSC) of the rows of ``stencils`` and ``constants``, which
    must cover every row of g once.

    :meth:`pattern` gives its sparsity with data = 1 + the index of each nonzero, and
    calling it at x its nonzeros (nnz,) in that order (what
    :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`
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
        # every stencil's nonzeros, then the constant ones, in one array: the weights of
        # the scatter at each point, with no copy
        mapped = [_Mapped(s) for s in self.stencils]
        constant = np.concatenate([c.values for c in self.constants] + [np.zeros(0)])
        ends = np.cumsum([0] + [m.size for m in mapped])
        self._values = np.zeros(ends[-1] + constant.size)
        self._values[ends[-1]:] = constant
        for m, start, stop in zip(mapped, ends[:-1], ends[1:]):
            m.bind(self._values[start:stop])
        entries = [m.entries() for m in mapped] + [(c.rows, c.columns) for c in self.constants]
        key = np.concatenate([cols.astype(np.int64) * n_g + rows for rows, cols in entries])
        del entries
        key, position = np.unique(key, return_inverse=True)
        self._position = index_array(position)  # as long as the instances' nonzeros
        del position
        col, row = np.divmod(key, n_g)  # key is sorted: the CSC order
        self._structure = Structure(index_array(row), np.searchsorted(
            col, np.arange(self.shape[1] + 1)), self.shape)
        self._mapped = mapped
        return mapped

    def pattern(self) -> sp.csc_matrix:
        """The sparsity, data = 1 + the index of each nonzero."""
        self._build()
        return self._structure.pattern()

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The nonzeros (nnz,) at x (n_x,)."""
        mapped = self._build()
        for m in mapped:
            m(x)
        return np.bincount(self._position, weights=self._values,
                           minlength=self._structure.nnz)


class GraphJacobian:
    """The Jacobian (n_g x n_x, CSC) of an expression ``rows`` of ``x`` by CasADi's
    differentiation of the whole graph, with :class:`LocalJacobian`'s interface
    (:meth:`pattern`, and its nonzeros at x when called; built at the first use). For an
    NLP small enough that the graph's Jacobian costs little to build (an NLP of several
    states, :func:`rffqm_nlp.design.transcription.several_states`) and whose rows are not
    stated as stencils. CasADi's sparsity is compressed by column, so its nonzeros come in
    CSC order."""

    def __init__(self, rows: ca.MX, x: ca.MX):
        self.rows, self.x = rows, x
        self.shape = (rows.numel(), x.numel())
        self._eval: Callable[[], None] | None = None

    def with_rows(self, rows: ca.MX) -> "GraphJacobian":
        """This Jacobian with the rows ``rows`` appended (their indices from n_g on)."""
        return GraphJacobian(ca.vertcat(self.rows, rows), self.x)

    def _build(self) -> None:
        if self._eval is not None:
            return
        function = ca.Function("jacobian", [self.x], [ca.jacobian(self.rows, self.x)])
        colind, row = (np.array(a, dtype=np.int64) for a in function.sparsity_out(0).get_ccs())
        self._structure = Structure(index_array(row), colind, self.shape)
        self._buffer, self._eval = function.buffer()
        self._in = np.zeros(self.shape[1])
        self._out = np.zeros(row.size)
        self._buffer.set_arg(0, memoryview(self._in))
        self._buffer.set_res(0, memoryview(self._out))

    def pattern(self) -> sp.csc_matrix:
        """The sparsity, data = 1 + the index of each nonzero."""
        self._build()
        return self._structure.pattern()

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """The nonzeros (nnz,) at x (n_x,)."""
        self._build()
        self._in[:] = x
        self._eval()
        return self._out.copy()


@dataclass(frozen=True)
class Structure:
    """A CSC (or ``fmt`` "csr") sparsity (``indices``, ``indptr``, ``shape``) kept without
    its values: a large Jacobian's pattern as :meth:`pattern` gives it costs 8 bytes a
    nonzero more."""

    indices: np.ndarray
    indptr: np.ndarray
    shape: tuple[int, int]
    fmt: str = "csc"

    @property
    def nnz(self) -> int:
        return self.indices.size

    def with_values(self, data: np.ndarray) -> sp.spmatrix:
        """The matrix of this sparsity with the values ``data`` (nnz,), sharing its index
        arrays."""
        kind = sp.csr_matrix if self.fmt == "csr" else sp.csc_matrix
        return kind((data, self.indices, self.indptr), shape=self.shape)

    @classmethod
    def of_pattern(cls, pattern: sp.spmatrix, fmt: str = "csc") -> tuple["Structure", np.ndarray]:
        """The sparsity of ``pattern`` (data = 1 + the index of each nonzero in some
        values, as :meth:`pattern` and :meth:`LocalJacobian.pattern` give it) in ``fmt``
        with sorted indices, and the index in those values of each of its nonzeros (as
        :func:`index_array` makes it): ``with_values(values[index])`` is the matrix at
        ``values``."""
        m = pattern.asformat(fmt, copy=True)
        m.sort_indices()
        return cls(m.indices, m.indptr, m.shape, fmt), index_array(m.data - 1)

    def pattern(self) -> sp.spmatrix:
        """The sparsity (a new matrix), data = 1 + the index of each nonzero."""
        return replace(self, indices=self.indices.copy(), indptr=self.indptr.copy()
                       ).with_values(np.arange(1, self.nnz + 1, dtype=float))


@dataclass(frozen=True)
class Lift:
    """The part F_u H of a :class:`LiftedJacobian` at a point: the rows that read u
    (``rows``, (m,)), their Jacobian in u (``Fu``, (m, n_u), sparse), H = dh/dx in the
    columns h reads (``H``, (n_u, k), dense) and those columns of x (``columns``, (k,)).
    Kept as factors: the product is dense in its k columns."""

    rows: np.ndarray
    Fu: sp.csr_matrix
    H: np.ndarray
    columns: np.ndarray

    def times(self, X: np.ndarray) -> np.ndarray:
        """F_u H X[columns] (m,) or (m, p), its rows' change, for X (n_x,) or (n_x, p)."""
        return self.Fu @ (self.H @ X[self.columns])

    def transpose_times(self, w: np.ndarray) -> np.ndarray:
        """(F_u H)' w[rows] (k,) or (k, p) for w (n_g,) or (n_g, p) over all rows."""
        return self.H.T @ (self.Fu.T @ w[self.rows])

    def product(self) -> np.ndarray:
        """F_u H (m, k), dense: the lifted rows' Jacobian in the columns."""
        return self.Fu @ self.H


class LiftedJacobian:
    """The Jacobian (n_g x n_x) of rows f(x, u) at u = h(x), where h reads only a few
    columns of x (``columns``, k of them): J = F_x + F_u H, with F the
    :class:`LocalJacobian` ``inner`` over (x, u) (n_g x (n_x + n_u)) and H = dh/dx in those
    columns (n_u x k, dense).

    ``lift``: x -> (u (n_u,), H (n_u, k)). Where u is many intermediate values of a few
    variables (a free correspondence's target lattice of its controls), F is local and
    cheap to build, while the Jacobian of f(x, h(x)) in x directly is dense in those few
    columns, and CasADi's build of it is not cheap. So the two parts stay apart:
    :meth:`pattern` gives F_x's sparsity (the rows' direct dependence on x) with data = 1 +
    the index of each nonzero, and calling it at x gives F_x's nonzeros in that order and
    the :class:`Lift` F_u H (what :mod:`rffqm_nlp.design.solvers.levenberg_marquardt` reduces
    without forming it).
    """

    def __init__(self, inner: LocalJacobian,
                 lift: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
                 columns: np.ndarray, n_x: int):
        self.inner, self.columns = inner, np.asarray(columns, dtype=np.int64)
        self.shape = (inner.shape[0], n_x)
        self._lift = lift
        self._built = False

    def _build(self) -> None:
        if self._built:
            return
        n_x = self.shape[1]
        F = self.inner.pattern()  # data = 1 + the index in the inner Jacobian's nonzeros
        self._structure, self._x_index = Structure.of_pattern(F[:, :n_x])
        Fu = F[:, n_x:].tocsr()
        self._lifted_rows = np.flatnonzero(np.diff(Fu.indptr))
        self._Fu, self._Fu_index = Structure.of_pattern(Fu[self._lifted_rows], "csr")
        self._built = True

    def pattern(self) -> sp.csc_matrix:
        """F_x's sparsity (n_g x n_x), data = 1 + the index of each nonzero."""
        self._build()
        return self._structure.pattern()

    @property
    def rows(self) -> np.ndarray:
        """The rows that read u (m,), in the order of the :class:`Lift`'s."""
        self._build()
        return self._lifted_rows

    def __call__(self, x: np.ndarray) -> tuple[np.ndarray, Lift]:
        """F_x's nonzeros (nnz,) and F_u H at x (n_x,)."""
        self._build()
        u, H = self._lift(x)
        values = self.inner(np.concatenate([x, u]))
        Fu = self._Fu.with_values(values[self._Fu_index])
        return values[self._x_index], Lift(self._lifted_rows, Fu, H, self.columns)
