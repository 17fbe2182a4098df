"""The marching manifold: the simultaneous NLP split into its design d and its marched state
s(d) (:class:`Manifold`), the points on it and their derivatives, the coarse basis of the
design the steps can be taken in first (:func:`boundary_basis`), and BLAS's threads while
the pass keeps S whole."""

from __future__ import annotations

import functools
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass

import casadi as ca
import numpy as np
import scipy.sparse as sp
from threadpoolctl import ThreadpoolController

from ....errors import InputError
from ...stencils import Lift, LiftedJacobian, Structure
from ...transcription import NLP
from .levels import Levels, order_by_level
from .sensitivities import Linearization, Sensitivity
from .window import Window

#: constraint violation up to which a marched design counts as admissible
FEASIBLE = 1e-9


@dataclass
class Point:
    """A marched design x (n,), its residuals r (n_r,) and constraints g (n_g,)."""

    x: np.ndarray
    r: np.ndarray
    g: np.ndarray

    @property
    def objective(self) -> float:
        return 0.5 * float(self.r @ self.r)


class _Buffered:
    """A CasADi Function of x evaluated into preallocated NumPy arrays (its nonzeros)."""

    def __init__(self, function: ca.Function):
        self._buffer, self._eval = function.buffer()
        self._x = np.zeros(function.nnz_in(0))
        self._buffer.set_arg(0, memoryview(self._x))
        self.out = [np.zeros(function.nnz_out(i)) for i in range(function.n_out())]
        for i, out in enumerate(self.out):
            self._buffer.set_res(i, memoryview(out))

    def __call__(self, x: np.ndarray) -> list[np.ndarray]:
        self._x[:] = x
        self._eval()
        return [out.copy() for out in self.out]


class _Sliced:
    """A fixed submatrix of a sparse Jacobian (``block``, data = 1 + the index of each
    nonzero in the Jacobian's), refilled from the Jacobian's nonzeros; its sparsity kept
    without values (:class:`rffqm_nlp.design.stencils.Structure`)."""

    def __init__(self, block: sp.spmatrix):
        self._structure, self._index = Structure.of_pattern(block, "csr")

    def __call__(self, nonzeros: np.ndarray) -> sp.csr_matrix:
        """The block with the values ``nonzeros`` (its structure shared, not copied)."""
        return self._structure.with_values(nonzeros[self._index])


class Manifold:
    """The simultaneous NLP split into its design and its marched state.

    Built once per NLP: the index sets (``state`` in the order of the levels of the
    marching equations; ``read``, the state rows that the residuals' Jacobian, the
    inequality rows or the state bounds read, positions in ``state``, and ``bounded_read``,
    the bounded state's positions in ``read``: a step needs S in those rows only, about a
    third of them at 20 x 20 panels), the levels (``levels``: the marching equations of
    each; ``match``: the unknown of each equation, its position in ``state``;
    :func:`.levels.order_by_level`), the CasADi Function of the residuals and constraints
    (trial points) and their Jacobians from local stencils (``jacobian_r``, ``jacobian_g``:
    ``nlp.r_jacobian``, ``nlp.g_jacobian``; accepted points). The steps are taken in the
    coordinates u of the design's ``basis`` B (n_d x n_u, dd = B du; :func:`boundary_basis`
    with ``knots`` and ``position``, the place of each design variable along the boundary;
    the identity with None or where no class of boundary data has more than ``knots``
    entries); ``coarse`` tells whether it is coarser than the identity, and :meth:`refine`
    makes it the identity. ``window``: the pass over the levels in that basis
    (:class:`.window.Window`).
    """

    def __init__(self, nlp: NLP, knots: int | None = None):
        if nlp.project is None or nlp.design_index is None or nlp.r_jacobian is None:
            raise InputError("solver='levenberg-marquardt' needs the simultaneous transcription")
        self.nlp = nlp
        n = nlp.x.numel()
        fixed = nlp.lbx == nlp.ubx
        design = np.zeros(n, dtype=bool)
        design[nlp.design_index] = True
        design &= ~fixed
        self.design = np.flatnonzero(design)
        self.state = np.flatnonzero(~design & ~fixed)
        eq = nlp.lbg == nlp.ubg
        self.eq, self.ineq = np.flatnonzero(eq), np.flatnonzero(~eq)
        if self.eq.size != self.state.size:
            raise RuntimeError(f"{self.eq.size} marching equations for {self.state.size} "
                               "state variables")
        self._values = _Buffered(ca.Function("values", [nlp.x], [nlp.residuals, nlp.g]))
        self.jacobian_r, self.jacobian_g = nlp.r_jacobian, nlp.g_jacobian
        G = self.jacobian_g.pattern().tocsr()  # data = 1 + the index of each nonzero
        pattern = np.zeros(n, dtype=bool)
        pattern[nlp.pattern_index] = True
        order, self.levels, self.match = order_by_level(G[self.eq][:, self.state].tocsr(),
                                                        pattern[self.state])
        self.state = self.state[order]
        where = np.full(n, -1)
        where[self.state] = np.arange(self.state.size)
        self.pattern = where[np.flatnonzero(pattern & ~design & ~fixed)]
        weights = nlp.damping_weights
        self._design_weights = weights[self.design]
        self.pattern_weights = weights[self.state][self.pattern]
        bounded = (np.isfinite(nlp.lbx) | np.isfinite(nlp.ubx)) & ~fixed
        self.bounded_design = np.flatnonzero(bounded[self.design])
        self.bounded_state = np.flatnonzero(bounded[self.state])
        self.lower = self.inequalities(nlp.lbg, nlp.lbx)
        self.upper = self.inequalities(nlp.ubg, nlp.ubx)
        J = self._slice_jacobians(G)
        self._use_basis(None if knots is None or nlp.boundary_class is None else
                        boundary_basis(nlp.boundary_class[self.design], self.position, knots),
                        J)

    @property
    def coarse(self) -> bool:
        """Whether the basis is coarser than the identity (n_u < n_d)."""
        return self.basis.shape[1] < self.design.size

    def refine(self) -> None:
        """Make the basis the identity (the pass rebuilt for it)."""
        self.window = None  # its structures go before the new ones are built
        self._use_basis(None, self._pooled(self.jacobian_r.pattern().tocsr()))

    def _use_basis(self, basis: tuple[sp.csr_matrix, np.ndarray] | None,
                   J: sp.csr_matrix) -> None:
        """The basis (B, the position of each coordinate; None: the identity) and the pass
        for it (:class:`.window.Window`) over the residuals' Jacobian pattern ``J``
        (:meth:`_pooled`)."""
        if basis is None:
            basis = sp.identity(self.design.size, format="csr"), self.position
        self.basis, position = basis
        w = sp.diags(self._design_weights)
        self.design_metric = (self.basis.T @ w @ self.basis).tocsr()  # B' D_d B, sparse
        free, lifted_rows = self._lifted()
        self.window = Window(self._sweeps, J, self.pattern, self.pattern_weights, free,
                             lifted_rows, self.basis, position)
        if self.window.whole:
            _blas()  # the libraries scanned in the build, not in the first solve

    def blas_threads(self) -> AbstractContextManager:
        """A context in which BLAS runs on one thread while the pass keeps S whole (a small
        problem, :data:`.window.WHOLE_S`); nothing otherwise. The dense products are then
        too small to share, and OpenBLAS's threads, woken by a product with S, slowed the
        next small LAPACK call (a Cholesky factor of the model) down many times over
        (measured in docs/decisions/large-patterns.md)."""
        if not self.window.whole:
            return nullcontext()
        return _blas().limit(limits=1, user_api="blas")

    def _slice_jacobians(self, G: sp.csr_matrix) -> sp.csr_matrix:
        """The fixed blocks of J and G (the state in the order of its levels) and the
        marching equations by level (:class:`Levels`); returns J's pattern for the pass
        (:meth:`_pooled`)."""
        J = self.jacobian_r.pattern().tocsr()  # with a lift, its direct part
        Gin = G[self.ineq]
        self.read = np.union1d(np.union1d(J[:, self.state].indices, Gin[:, self.state].indices),
                               self.bounded_state)
        self.bounded_read = np.searchsorted(self.read, self.bounded_state)
        self._J_design = _Sliced(J[:, self.design])
        self._J_state = _Sliced(J[:, self.state[self.read]])
        self._G_design = _Sliced(Gin[:, self.design])
        self._G_state = _Sliced(Gin[:, self.state[self.read]])
        rows = self.eq[np.concatenate(self.levels)]  # in level order: row i owns unknown i
        Cs, Cd = G[rows][:, self.state].tocoo(), G[rows][:, self.design].tocsr()
        own = Cs.col == Cs.row
        diagonal = np.empty(Cs.shape[0], dtype=np.int64)
        diagonal[Cs.row[own]] = Cs.data[own].astype(np.int64) - 1
        off = sp.csr_matrix((Cs.data[~own], (Cs.row[~own], Cs.col[~own])), shape=Cs.shape)
        sizes = np.cumsum([0] + [rows.size for rows in self.levels])
        self._sweeps = Levels(Cd, off, list(zip(sizes[:-1], sizes[1:])), diagonal)
        self.position = (np.zeros(self.design.size) if self.nlp.boundary_position is None
                         else np.nan_to_num(self.nlp.boundary_position[self.design], nan=0.0))
        return self._pooled(J)

    def _pooled(self, J: sp.csr_matrix) -> sp.csr_matrix:
        """The residuals' Jacobian pattern (its direct part, data = 1 + the index of each
        nonzero) with the design's columns first, then the state's in level order."""
        return sp.hstack([J[:, self.design], J[:, self.state]], format="csr")

    def _lifted(self) -> tuple[np.ndarray, np.ndarray]:
        """With a lifted residual Jacobian: the design positions of its lifted columns that
        are not fixed (``_lift_keep`` indexes them among the Lift's columns) and the rows
        F_u H reaches; both empty without one."""
        none = np.zeros(0, dtype=np.int64)
        self._lift_keep = none
        if not isinstance(self.jacobian_r, LiftedJacobian):
            return none, none
        columns = self.jacobian_r.columns
        if np.isin(columns, self.state).any():
            raise RuntimeError("a lifted column of the residuals' Jacobian is a state variable")
        position = np.full(self.nlp.x.numel(), -1, dtype=np.int64)
        position[self.design] = np.arange(self.design.size)
        self._lift_keep = np.flatnonzero(position[columns] >= 0)
        return position[columns[self._lift_keep]], self.jacobian_r.rows

    # ---------------------------------------------------------------- evaluation
    def point(self, x: np.ndarray) -> Point | None:
        """r and g at a marched x; None where they are not finite."""
        r, g = self._values(x)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(g))):
            return None
        return Point(x=x, r=r, g=g)

    def marched(self, x: np.ndarray) -> Point | None:
        """The point of x (n,) re-marched, whatever constraints it breaks; None where it
        does not march or is not finite."""
        marched = self.nlp.project(np.asarray(x, dtype=float))
        return None if marched is None else self.point(marched)

    def admissible(self, x: np.ndarray) -> Point | None:
        """:meth:`marched` where it holds every constraint and bound to :data:`FEASIBLE`;
        None otherwise."""
        p = self.marched(x)
        return p if p is not None and self.violation(p) <= FEASIBLE else None

    def linearize(self, p: Point, metric: bool = True) -> Linearization | None:
        """The derivatives at p; None where they are not finite or the marching equations
        no longer determine their unknowns. Invalidates the last point's. ``metric``: False
        skips the damping metric's part S_p' D_p S_p (``pattern_metric`` None)."""
        (J, lift), G = self._residual_jacobian(p.x), self.jacobian_g(p.x)
        if not (np.all(np.isfinite(J)) and np.all(np.isfinite(G))):
            return None
        if lift is not None and not (np.all(np.isfinite(lift.H))
                                     and np.all(np.isfinite(lift.Fu.data))):
            return None
        if not self._sweeps.refill(G):
            return None
        G_design, G_state = self._in_basis(self._G_design(G)), self._G_state(G)
        del G  # all of g's nonzeros, not held through the pass
        reduced = self.window(J, p.r, lift, metric)
        if reduced is None:
            return None
        return Linearization(J_design=self._in_basis(self._J_design(J)),
                             J_state=self._J_state(J), G_design=G_design, G_state=G_state,
                             sensitivity=Sensitivity(
                                 self._sweeps,
                                 None if reduced[3] is None else reduced[3][self.read],
                                 self.window.marching, self.basis, self.read),
                             JtJ=reduced[0], grad=reduced[1], pattern_metric=reduced[2],
                             lift=lift)

    def _in_basis(self, design_columns: sp.csr_matrix) -> sp.csr_matrix:
        """Design columns (k, n_d) times the basis (k, n_u); as they are with the identity."""
        return design_columns @ self.basis if self.coarse else design_columns

    def _residual_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, Lift | None]:
        """The nonzeros of the residuals' Jacobian at x (with a lift, of its direct part)
        and its lift over the design's free columns (None without one)."""
        if not isinstance(self.jacobian_r, LiftedJacobian):
            return self.jacobian_r(x), None
        J, lift = self.jacobian_r(x)
        return J, Lift(lift.rows, lift.Fu, lift.H[:, self._lift_keep], self.window.free)

    def inequalities(self, g: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The inequality rows of the reduced problem at (g, x): g's inequality rows, then
        the bounded design, then the bounded state variables."""
        return np.concatenate([g[self.ineq], x[self.design][self.bounded_design],
                               x[self.state][self.bounded_state]])

    def violation(self, p: Point) -> float:
        """Largest violation of the constraints and bounds at p."""
        nlp = self.nlp
        return float(max(0.0, np.max(nlp.lbg - p.g), np.max(p.g - nlp.ubg),
                         np.max(nlp.lbx - p.x), np.max(p.x - nlp.ubx)))


def boundary_basis(klass: np.ndarray, position: np.ndarray, knots: int
                   ) -> tuple[sp.csr_matrix, np.ndarray] | None:
    """A coarse basis of the design, B (n_d x n_u), and the position of each coordinate
    (n_u,); None where no class has more than ``knots`` entries (B would be the identity).

    Each class of boundary data (``klass`` (n_d,) >= 0: one array along one edge, one
    parity, :attr:`rffqm_nlp.design.transcription.NLP.boundary_class`) of m > ``knots`` entries,
    ordered by their distance from the corner (``position``, (n_d,)), is piecewise linear
    in its index between ``knots`` knots spread evenly from its first entry to its last
    (a coordinate per knot: its entry's value); every other design variable is its own
    coordinate. A pattern far finer than the target's features then keeps the step's
    dense matrices at (12 knots + the rest)^2 instead of n_d^2
    (docs/decisions/levenberg-marquardt.md)."""
    if knots < 2:
        raise InputError(f"boundary knots must be at least 2, got {knots}")
    rows, cols, values, at = [], [], [], []
    coarse = False
    for c in np.unique(klass):
        members = np.flatnonzero(klass == c)
        if c < 0 or members.size <= knots:
            rows.append(members)
            cols.append(len(at) + np.arange(members.size))
            values.append(np.ones(members.size))
            at.extend(position[members])
            continue
        coarse = True
        members = members[np.argsort(np.abs(position[members]), kind="stable")]
        index = np.arange(members.size)
        knot = np.unique(np.round(np.linspace(0, members.size - 1, knots)).astype(np.int64))
        left = np.minimum(np.searchsorted(knot, index, "right") - 1, knot.size - 2)
        weight = (index - knot[left]) / (knot[left + 1] - knot[left])
        rows += [members, members]
        cols += [len(at) + left, len(at) + left + 1]
        values += [1.0 - weight, weight]
        at.extend(position[members[knot]])
    if not coarse:
        return None
    B = sp.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(klass.size, len(at)))
    B.eliminate_zeros()
    return B, np.array(at)


@functools.cache
def _blas() -> ThreadpoolController:
    """The BLAS libraries this process has loaded (threadpoolctl; scanning them takes a few
    milliseconds, once)."""
    return ThreadpoolController()
