"""Levenberg-Marquardt on the marching manifold (``solver="levenberg-marquardt"``).

The simultaneous NLP (:func:`rffqm_nlp.design.transcription.simultaneous`) states the marching
equations c(x) = 0 as constraints, and IPOPT's iterates meet them only near the optimum.
Here every iterate is a marched design: the variables are the design d (boundary angles and
sides, omega, the rigid alignment) and every other entry of x, the state s, follows from d
by the march (:attr:`NLP.project`, the CasADi graph; the answer is re-marched with the
NumPy model). The loss is then a least-squares function of d alone, f(d) = 0.5 |r(d,
s(d))|^2, and its Gauss-Newton model is exact to first order: no constraint curvature is
dropped.

Derivatives come from the simultaneous NLP's sparse Jacobians, evaluated once per accepted
point into preallocated buffers (trial points evaluate only r and g). The marching
equations are explicit (each computes one new quantity from earlier ones), so their
Jacobian in s is triangular after a permutation, found once from its sparsity (a matching
of equations to unknowns, then the longest chain of dependencies of each equation, its
level), and the state is ordered by level. The state's sensitivity S = -C_s^{-1} C_d
(n_s x n_d) then follows level by level: the unknowns of a level depend only on those of
earlier levels. One pass over the levels (:class:`_Window`) keeps only the rows of S that a
later level or a residual still needs (a working set that shrinks, relative to the state, as
the pattern grows; a small S, up to :data:`WHOLE_S` entries, it keeps whole) and reduces
them at once into the n_d x n_d matrices the step needs: J' J of the reduced Jacobian J =
J_d + J_s S (plus, with a free correspondence, the controls' F_T H, kept as its factors),
the gradient J' r and the metric below; a row of S at vertex (i, j) is nonzero only in the
boundary data of the vertices (0..i, 0) and (0, 0..j), so its Gram products are taken over
those columns alone. The inequality rows G_d + G_s S that a step needs come from the sweep backwards
through the levels (S' applied to their state parts), and every row's change under a step
from one forward sweep (S dd); where the pass kept S whole, from products with it
(:class:`_Sensitivity`).

The steps can be taken in a coarse basis of the design first, d = B u (n_u < n_d,
:func:`boundary_basis`: each class of boundary data piecewise linear between a few knots),
whose pass costs (n_u / n_d)^2 of the whole design's in its Gram matrices; where that run
ends optimal in the basis or stalls, it goes on in the whole design
(:func:`levenberg_marquardt`).

Each iteration solves the damped, linearised problem

    min_dd 0.5 |r + J dd|^2 + 0.5 dd' B dd + 0.5 lam dd' M dd   s.t. the inequalities, linearised,

as a small dense QP (only the rows the unconstrained step would break, and their
neighbours in slack, enter it; DAQP solves it as a least-distance problem in R dd, R the
Cholesky factor of the damped model that the unconstrained step computed), re-marches
d + dd and accepts it if the loss falls and every constraint holds; a step that breaks a
constraint is corrected (the rows shifted by their linearisation error, up to
:data:`CORRECTIONS` times) before lam grows. lam follows
Nielsen's rule (Madsen, Nielsen & Tingleff, "Methods for non-linear least squares
problems", 2004, s.3.2), except after a step whose pattern does not march (a side or a
sector angle out of its range), which only doubles it (:data:`DOMAIN_DAMPING`). The
metric M counts the change of the crease pattern: D_d plus S_p' D_p S_p over the sector
angles and sides p of every vertex, with D the weights of
:func:`rffqm_nlp.design.transcription.damping_weights` (a radian, or a lattice spacing, per
lattice point); where lam is below :data:`METRIC_DAMPING` the last point's M serves (lam M
is then a small part of the model, and the pattern moves little a step). B estimates the
part of the Hessian that Gauss-Newton drops, sum r_i Hess r_i (and the active
inequalities' curvature), by the structured secant update of
Dennis, Gay & Welsch ("An adaptive nonlinear least-squares algorithm", ACM TOMS 7, 1981;
NL2SOL), with its sizing, from the change of the Lagrangian's gradient over each of the
last :data:`SECANT_PAIRS` accepted steps, rebuilt from zero at every iteration; a step uses
it when it predicted the last step's reduction better than J' J alone did (NL2SOL's
choice), and when J' J + B + lam M is positive definite. Where the residuals do not vanish
at the optimum Gauss-Newton converges only linearly; B speeds up the end.

A start that marches but breaks a constraint (a Miura start whose sides break the minimum
length, a warm start carried from a coarser design that no move toward the reference
repairs, :func:`admissible_toward`, or a clearance round's last design with its new rows,
:mod:`rffqm_nlp.design.clearance`) is restored first: the steps are the same, whose QP then asks
the broken rows' linearisation to reach their bounds, but a trial is judged by its largest
violation alone, the loss free to rise. It is taken where it holds every constraint (after
up to :data:`CORRECTIONS` corrections, as above) or, failing that, where it (the best such
trial) brought the violation down by at least :data:`RESTORED` of what the QP asked; lam
then falls by 3, and after a trial not taken it grows by Nielsen's factor and the QP asks
the broken rows for half of their remaining way only (:func:`_partial_target`: where the
QP forces the rows, a larger lam hardly shortens the step). Restoration steps give the
secant term no pair (their multipliers force the rows), and no optimality test is made
before a point holds every constraint; from there the run goes on as from an admissible
start, its optimality error scaled by the gradient there. Where no such point is reached
(lam above :data:`MAX_DAMPING`, ``max_iter``, the deadline) the run ends
"Inadmissible_Start" with the start as given and the restoration steps counted.

The run stops with status "Solve_Succeeded" when the first-order optimality conditions of
the reduced problem hold at a marched iterate (:func:`_kkt_error`): the gradient J' r
less the linearised active inequalities' multipliers (of the right sign, zero where the
inequality is not active: the step's QP's, or their least-squares fit to the gradient where
it does better) is at most ``tol`` in the max norm, relative to max(1, |J' r at the start|
/ 100) as IPOPT's gradient-based scaling of the objective.
"""

from __future__ import annotations

import functools
import time
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass, field, replace
from typing import Callable

import casadi as ca
import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
from scipy.optimize import nnls
from scipy.sparse.csgraph import maximum_bipartite_matching
from threadpoolctl import ThreadpoolController

from ...errors import InputError
from ..stencils import Lift, LiftedJacobian, Structure, index_array
from ..transcription import NLP

#: constraint violation up to which a marched design counts as admissible
FEASIBLE = 1e-9
#: corrections of a step that breaks a constraint before the damping grows
CORRECTIONS = 3
#: factor of lam after a step that leaves the march's domain (a side or sector angle of
#: the re-marched pattern out of its range): unlike a step whose loss rises, it says
#: nothing of the model's quality, so Nielsen's growing factor is not applied; the first
#: step from a large Miura start leaves it for several lam (docs/solvers.md)
DOMAIN_DAMPING = 2.0
#: damping above which no step is found: the run stops with status "Stalled"
MAX_DAMPING = 1e10
#: entries (rows x state) of a block of rows swept back at once (:meth:`_Steps.rows`)
BLOCK = 1 << 24
#: entries (state x marching design) of S up to which the pass keeps it whole (8 MB, which
#: stays in the cache: its products are then cheaper than the sweeps; docs/solvers.md)
WHOLE_S = 1 << 20
#: rows of W scaled at once when it is refilled (:meth:`_Levels.refill`; a temporary
#: as long as their nonzeros instead of three as long as all of W's)
REFILL_ROWS = 1 << 16
#: rows of a level computed at once in the pass (:class:`_Window`): their product with
#: the working set, CHUNK_ROWS x n_u, is the pass's largest temporary
CHUNK_ROWS = 1024
#: rows gathered before one update of J' J or of the metric (:class:`_Gram`), and of one
#: band's range of columns of them
GRAM_ROWS = 1024
BAND_ROWS = 256
#: the Gram matrices' columns are cut into at most BANDS bands of at least BAND_WIDTH
#: columns (:func:`_bands`)
BANDS = 8
BAND_WIDTH = 128
#: QPs per step, each over more rows, before the step counts as failed
QP_ROUNDS = 10
#: damping below which a linearisation keeps the last metric M instead of computing it
#: (docs/solvers.md: the same iterations, within one or two, on the bundled targets)
METRIC_DAMPING = 1e-3
#: the accepted steps whose secant pairs make up B: NL2SOL's update applied to each in turn
#: from zero at every iteration, so curvature learned far back is dropped instead of being
#: sized away with what the last steps learned (docs/solvers.md)
SECANT_PAIRS = 3
#: the fractions of the way from an inadmissible start's boundary data to the reference's
#: tried in turn (:func:`admissible_toward`)
TOWARD_REFERENCE = (0.1, 0.25, 0.5, 1.0)
#: a restoration step that still breaks a constraint is taken where it brings the largest
#: violation down by at least this fraction of the part its QP asked for
RESTORED = 0.5
#: statuses of a run that ended where it should
SUCCESS = ("Solve_Succeeded", "Fit_Reached")


@dataclass
class Outcome:
    """Where a run ended: ``x`` (a marched design, admissible), its loss, the number of
    accepted steps, the status and the optimality error (:func:`_kkt_error`, scaled) at
    the last point tested (None when none was). Statuses: "Solve_Succeeded" (first-order
    optimal to ``tol``), "Fit_Reached" (``stop`` held), "Stalled" (no step lowers the
    loss), "Maximum_Iterations_Exceeded", "Maximum_WallTime_Exceeded", or
    "Inadmissible_Start" (the start, re-marched, does not march, or breaks a constraint
    and its restoration did not reach an admissible point: ``x`` is the start as given,
    ``objective`` None, ``iterations`` the restoration steps taken). ``scale``: the
    optimality error's, max(1, |J' r at the start| / 100) (None before the first model).
    ``moved``: the fraction of the way to the reference that an inadmissible start's
    boundary data were moved before the run (:func:`admissible_toward`; 0: not moved).
    ``restored``: the restoration steps (of ``iterations``) from a start that broke a
    constraint to the first admissible point (0: it started admissible)."""

    x: np.ndarray
    objective: float | None
    iterations: int
    status: str
    kkt_error: float | None = None
    scale: float | None = None
    moved: float = 0.0
    restored: int = 0

    @property
    def success(self) -> bool:
        """Optimal to tol, or the fit asked for reached."""
        return self.status in SUCCESS


@dataclass
class _Point:
    """A marched design x (n,), its residuals r (n_r,) and constraints g (n_g,)."""

    x: np.ndarray
    r: np.ndarray
    g: np.ndarray

    @property
    def objective(self) -> float:
        return 0.5 * float(self.r @ self.r)


@dataclass
class _Linearization:
    """The derivatives at a point in the design's coordinates u (n_u, the manifold's
    ``basis`` B maps them to the design, dd = B du): the sparse Jacobians of r and g split
    by design and state columns (J_design, J_state; the inequality rows' G_design,
    G_state; the design columns times B, the state columns only the n_read that any of
    them reads, :attr:`Manifold.read`), S B with S = ds/dd in those rows (``sensitivity``:
    applied to a block, and its transpose), and the reduced problem's J' J, J' r and the
    metric's B' S_p' D_p S_p B (n_u x n_u, n_u; the last None when linearised without
    it), accumulated level by level (:class:`_Window`) without storing S (unless it is
    small). With a lifted residual Jacobian (:class:`rffqm_nlp.design.stencils.LiftedJacobian`),
    J_design holds its direct part and ``lift`` the rest, F_u H, its columns numbered in u.
    Valid until the manifold linearises at the next point (the levels are refilled there)."""

    J_design: sp.csr_matrix
    J_state: sp.csr_matrix
    G_design: sp.csr_matrix
    G_state: sp.csr_matrix
    sensitivity: "_Sensitivity"
    JtJ: np.ndarray
    grad: np.ndarray
    pattern_metric: np.ndarray | None
    lift: Lift | None

    def jacobian_times(self, X: np.ndarray) -> np.ndarray:
        """Jr X (n_r,) or (n_r, p) for X (n_u,) or (n_u, p), Jr = J_design + J_state S B
        (+ F_u H) the reduced Jacobian."""
        out = self.J_design @ X + self.J_state @ self.sensitivity.forward(X)
        if self.lift is not None:
            out[self.lift.rows] += self.lift.times(X)
        return out

    def jacobian_transpose(self, w: np.ndarray) -> np.ndarray:
        """Jr' w (n_u,) for w (n_r,)."""
        out = self.J_design.T @ w + self.sensitivity.adjoint(self.J_state.T @ w)
        if self.lift is not None:
            out[self.lift.columns] += self.lift.transpose_times(w)
        return out

    def state_change(self, du: np.ndarray) -> np.ndarray:
        """(S B du)[read] (n_read,): the first-order change of the state rows read
        (:attr:`Manifold.read`) under the step du (n_u,)."""
        return self.sensitivity.forward(du)


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


class _Levels:
    """The marching equations in level order, s = W_d d + W_s s with W_s strictly lower
    triangular by levels: the unknowns of level k are the state rows lo_k:hi_k and
    s_k = W_k [d; s[:lo_k]], W_k = -diag_k^-1 [C_d,k  C_s,k] (C without the own unknowns).
    The W_k share one data array, refilled from G's nonzeros at each point (:meth:`refill`).

    ``Cd`` (n_s x n_d) and ``Cs`` (n_s x n_s, without the own unknowns) are the marching
    equations in level order as patterns with data = 1 + the index of each nonzero in G's,
    ``bounds`` the (lo_k, hi_k) of each level, ``diagonal`` (n_s,) the index in G of each
    equation's own unknown. S = ds/dd is never stored: :meth:`forward` applies it to a
    block, :meth:`adjoint` its transpose, and :class:`_Window` accumulates its products."""

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


@dataclass
class _Sensitivity:
    """S B at a point, S = ds/dd and B the design's ``basis`` (n_d x n_u), in the state
    rows ``read`` (n_read,: those the residuals' Jacobian, the inequality rows and the
    state bounds read, :attr:`Manifold.read`; no step needs the others): by the sweeps
    through the ``levels``, or by products with those rows of S B where the pass kept it
    whole (``whole``, (n_read, n_m): its marching columns ``marching``, (n_m,); S B is zero
    in the other, free, columns)."""

    levels: _Levels
    whole: np.ndarray | None
    marching: np.ndarray
    basis: sp.csr_matrix
    read: np.ndarray

    def forward(self, X: np.ndarray) -> np.ndarray:
        """(S B X)[read] (n_read,) or (n_read, p) for X (n_u,) or (n_u, p)."""
        if self.whole is None:
            return self.levels.forward(self.basis @ X)[self.read]
        return self.whole @ X[self.marching]

    def adjoint(self, Y: np.ndarray) -> np.ndarray:
        """B' S' Y (n_u,) or (n_u, p) for Y (n_read,) or (n_read, p) in the rows read."""
        if self.whole is None:
            Z = np.zeros((self.levels.n_s,) + Y.shape[1:])
            Z[self.read] = Y
            return self.basis.T @ self.levels.adjoint(Z)
        out = np.zeros((self.basis.shape[1],) + Y.shape[1:])
        out[self.marching] = self.whole.T @ Y
        return out

    def rows(self, R: sp.csr_matrix) -> np.ndarray:
        """R (S B)[read] (k, n_u) for R (k, n_read) in the rows read."""
        if self.whole is None:
            coo = R.tocoo()
            Z = np.zeros((self.levels.n_s, R.shape[0]))
            Z[self.read[coo.col], coo.row] = coo.data
            return (self.basis.T @ self.levels.adjoint(Z)).T
        out = np.zeros((R.shape[0], self.basis.shape[1]))
        out[:, self.marching] = R @ self.whole
        return out


class _Window:
    """J' J, J' r and S_p' D_p S_p of the reduced problem in one pass over the levels,
    holding only the rows of S still needed (the working set) instead of all of S.

    Each state row gets a slot in a pool (``pool`` rows) from its level until the last level
    that uses it: the marching equations of a later level, or a residual row, which is
    reduced at the level of its latest state unknown (residual rows that use no state come
    first). A slot freed is reused by a later level, except where S B has at most
    :data:`WHOLE_S` entries (``whole``): then every state row keeps its own slot, the
    residual rows are reduced at once after the last level (one product instead of one a
    level), and the pass gives S B. The pool's columns are the design's coordinates u
    (``basis`` B, n_d x n_u: dd = B du, :func:`boundary_basis`) that the march reads
    (``marching``, n_m of them: the boundary data, omega and the rigid alignment), and its
    first rows B's rows of the design variables the march reads; the lifted design variables
    (``free``, in u, n_f: a free correspondence's controls, B's identity there, which the
    march does not read) have no column: their reduced Jacobian is J_d's columns plus F_u H
    (:class:`rffqm_nlp.design.stencils.Lift`, formed once a pass).

    The pool's columns follow the boundary (``position``, (n_u,): the left edge from its
    top down to the corner, then the bottom edge; omega, the alignment and any coordinate
    without a position at the corner): the state at vertex (i, j) reads only the boundary
    data of the vertices (0..i, 0) and (0, 0..j), so every row of S B is nonzero only in a
    range of columns around the corner, about (i + j) / (N + M) of them. The rows are
    gathered by their range, cut into :func:`_bands` bands (:class:`_Gram`), so the Gram
    matrices cost about a third of the dense products' arithmetic at large sizes.

    Static: built once from the sparsity; ``J`` (n_r x (n_d + n_s), design columns then the
    state in level order) has data = 1 + the index of each nonzero in the residuals'
    Jacobian (its direct part). ``pattern`` (state rows) and ``weights`` are the metric's
    rows and their D; ``free`` (design positions, whose rows of B are their own columns')
    and ``lifted_rows`` (the residual rows F_u H reaches, in the Lift's order) are empty
    without a lift.
    """

    def __init__(self, levels: _Levels, J: sp.csr_matrix, pattern: np.ndarray,
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
        self._top, self._design_span = self._design_rows(basis[read], n_d, read)
        column = np.full(n_d + n_s, -1, dtype=np.int64)  # -> pool row (-1: a free column)
        column[read] = np.arange(read.size)
        column[n_d:] = read.size + slot
        free_column = np.full(n_d, -1, dtype=np.int64)
        free_column[free] = np.arange(free.size)
        width = read.size + self.pool
        span = self._spans(levels, self._design_span)
        edges = _bands(n_m)
        # residual rows by level, in the order of their bands: (rows, their part in the
        # pool's columns, k x width, whose data is a view of one array refilled once a pass
        # from J's nonzeros at _index, and the segments (a, b, start, stop) of one range)
        lo_r, hi_r = self._residual_spans(Jcoo, column, self._design_span, span, n_d)
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
        self._chunks = []
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
            self._chunks.append(chunks)

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

    def _spans(self, levels: _Levels, design: tuple[np.ndarray, np.ndarray]
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
        """:meth:`_spans` of the residual rows (each (n_r,)), over their entries in J
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
        bands = edges.size - 1
        return (np.searchsorted(edges, first, "right") - 1) * bands + np.searchsorted(
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
        sums = _Sums(self.marching.size, self.mid, Jf, r)
        self._reduce(-1, pool, sums)
        for k, chunks in enumerate(self._chunks):
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

    def _reduce(self, k: int, pool: np.ndarray, sums: "_Sums") -> None:
        """The residual rows reduced at level k added to the sums (in place)."""
        if k in self._residuals:
            rows, pooled, segments = self._residuals[k]
            Jm = pooled @ pool
            for a, b, start, stop in segments:
                sums.add(Jm[start:stop], rows[start:stop], a, b)


def _bands(n: int) -> np.ndarray:
    """The edges (bands + 1,) of the bands the n pool columns are cut into for the Gram
    matrices (:class:`_Gram`): one below 2 :data:`BAND_WIDTH` columns, at most
    :data:`BANDS`."""
    bands = max(1, min(BANDS, n // BAND_WIDTH))
    return np.linspace(0, n, bands + 1).round().astype(np.int64)


class _Sums:
    """The sums of one pass over the levels: the Gram matrix of the residual rows [J_m J_f
    r] (n_m marching columns, n_f free ones: ``Jf``, (n_r, n_f), J's free columns, in which
    S is zero; r (n_r,)), which holds J' J and J' r, and the metric's over the marching
    columns: one syrk each and no products of their own (with two OpenBLAS threads, separate
    products slowed the whole solve down: docs/solvers.md). In the residuals' Gram matrix
    the n_f + 1 columns of J_f and r sit at the corner's column ``mid``, inside every
    row's range of columns (:class:`_Window`)."""

    def __init__(self, n_m: int, mid: int, Jf: np.ndarray, r: np.ndarray):
        self.Jf, self.r, self.mid = Jf, r[:, None], mid
        self.extra = Jf.shape[1] + 1
        self.jacobian, self.metric = _Gram(n_m + self.extra), _Gram(n_m)

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


class _Gram:
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


class Manifold:
    """The simultaneous NLP split into its design and its marched state.

    Built once per NLP: the index sets (``state`` in the order of the levels of the
    marching equations; ``read``, the state rows that the residuals' Jacobian, the
    inequality rows or the state bounds read, positions in ``state``, and ``bounded_read``,
    the bounded state's positions in ``read``: a step needs S in those rows only, about a
    third of them at 20 x 20 panels), the levels, the CasADi Function of the residuals and
    constraints (trial points) and their Jacobians from local stencils (``nlp.r_jacobian``,
    ``nlp.g_jacobian``; accepted points). The steps are taken in the coordinates u of the
    design's ``basis`` B (n_d x n_u, dd = B du; :func:`boundary_basis` with ``knots``, the
    identity with None or where no class of boundary data has more than ``knots`` entries);
    ``coarse`` tells whether it is coarser than the identity, and :meth:`refine` makes it
    the identity.
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
        self._jacobian_r, self._jacobian_g = nlp.r_jacobian, nlp.g_jacobian
        G = self._jacobian_g.pattern().tocsr()  # data = 1 + the index of each nonzero
        pattern = np.zeros(n, dtype=bool)
        pattern[nlp.pattern_index] = True
        self._order_by_level(G, pattern)
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
                        boundary_basis(nlp.boundary_class[self.design], self._position, knots),
                        J)

    @property
    def coarse(self) -> bool:
        """Whether the basis is coarser than the identity (n_u < n_d)."""
        return self.basis.shape[1] < self.design.size

    def refine(self) -> None:
        """Make the basis the identity (the pass rebuilt for it)."""
        self._window = None  # its structures go before the new ones are built
        self._use_basis(None, self._pooled(self._jacobian_r.pattern().tocsr()))

    def _use_basis(self, basis: tuple[sp.csr_matrix, np.ndarray] | None,
                   J: sp.csr_matrix) -> None:
        """The basis (B, the position of each coordinate; None: the identity) and the pass
        for it (:class:`_Window`) over the residuals' Jacobian pattern ``J``
        (:meth:`_pooled`)."""
        if basis is None:
            basis = sp.identity(self.design.size, format="csr"), self._position
        self.basis, position = basis
        w = sp.diags(self._design_weights)
        self.design_metric = (self.basis.T @ w @ self.basis).tocsr()  # B' D_d B, sparse
        free, lifted_rows = self._lifted()
        self._window = _Window(self._sweeps, J, self.pattern, self.pattern_weights, free,
                               lifted_rows, self.basis, position)
        if self._window.whole:
            _blas()  # the libraries scanned in the build, not in the first solve

    def blas_threads(self) -> AbstractContextManager:
        """A context in which BLAS runs on one thread while the pass keeps S whole (a small
        problem, :data:`WHOLE_S`); nothing otherwise. The dense products are then too small
        to share, and OpenBLAS's threads, woken by a product with S, slowed the next small
        LAPACK call (a Cholesky factor of the model) down many times over (measured in
        docs/solvers.md)."""
        if not self._window.whole:
            return nullcontext()
        return _blas().limit(limits=1, user_api="blas")

    def _order_by_level(self, G: sp.csr_matrix, pattern: np.ndarray) -> None:
        """The matching of marching equations to state unknowns (``match``), their levels
        (:meth:`_levels`), and the state reordered by level: the unknowns of each level
        contiguous, in the order of its equations, those of the crease pattern (``pattern``,
        (n_x,) bool) first (the metric's rows of a level are then a slice, :class:`_Window`).
        ``G``: the constraints' Jacobian pattern (n_g x n_x, data = 1 + the index of each
        nonzero)."""
        Cs = G[self.eq][:, self.state].tocsr()
        match = maximum_bipartite_matching(Cs, perm_type="column")
        if np.any(match < 0):
            raise RuntimeError("the marching equations are structurally singular in the state")
        self.match = match
        Cs = Cs.tocoo()
        own = Cs.col == match[Cs.row]
        off = sp.csr_matrix((Cs.data[~own], (Cs.row[~own], Cs.col[~own])), shape=Cs.shape)
        level = self._levels(off)
        later = ~pattern[self.state[match]]  # per equation: its unknown is not the pattern's
        self.levels = [e[np.argsort(later[e], kind="stable")]
                       for e in (np.flatnonzero(level == k) for k in range(level.max() + 1))]
        order = match[np.concatenate(self.levels)]  # old state index of each new position
        self.state = self.state[order]
        position = np.empty_like(order)
        position[order] = np.arange(order.size)
        self.match = position[match]  # the unknown (state index) of each marching equation

    def _slice_jacobians(self, G: sp.csr_matrix) -> sp.csr_matrix:
        """The fixed blocks of J and G (the pattern of :meth:`_order_by_level`) and the
        marching equations by level (:class:`_Levels`); returns J's pattern for the pass
        (:meth:`_pooled`)."""
        J = self._jacobian_r.pattern().tocsr()  # with a lift, its direct part
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
        self._sweeps = _Levels(Cd, off, list(zip(sizes[:-1], sizes[1:])), diagonal)
        self._position = (np.zeros(self.design.size) if self.nlp.boundary_position is None
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
        if not isinstance(self._jacobian_r, LiftedJacobian):
            return none, none
        columns = self._jacobian_r.columns
        if np.isin(columns, self.state).any():
            raise RuntimeError("a lifted column of the residuals' Jacobian is a state variable")
        position = np.full(self.nlp.x.numel(), -1, dtype=np.int64)
        position[self.design] = np.arange(self.design.size)
        self._lift_keep = np.flatnonzero(position[columns] >= 0)
        return position[columns[self._lift_keep]], self._jacobian_r.rows

    def _levels(self, off: sp.csr_matrix) -> np.ndarray:
        """The level of each marching equation (n_eq,): 0 for one that uses no other
        equation's unknown, else one more than the highest level among those it uses
        (Kahn's topological order, one frontier at a time), then the chains postponed
        (:func:`_postponed`). ``off``: the equations x state Jacobian pattern without each
        equation's own unknown."""
        owner = np.empty(off.shape[1], dtype=np.int64)
        owner[self.match] = np.arange(off.shape[0])
        deps = sp.csr_matrix((np.ones(off.nnz), owner[off.indices], off.indptr),
                             shape=(off.shape[0], off.shape[0]))
        deps.sum_duplicates()
        users = deps.T.tocsr()  # row e: the equations that use e's unknown
        waiting = np.diff(deps.indptr)  # unknowns each equation still waits for
        level = np.full(off.shape[0], -1, dtype=np.int64)
        frontier, k = np.flatnonzero(waiting == 0), 0
        while frontier.size:
            level[frontier] = k
            used = _gathered(users, frontier)[0]
            np.subtract.at(waiting, used, 1)
            frontier, k = np.unique(used[waiting[used] == 0]), k + 1
        if np.any(level < 0):
            raise RuntimeError("the marching equations are cyclic in the state")
        return _postponed(level, deps, users)

    # ---------------------------------------------------------------- evaluation
    def point(self, x: np.ndarray) -> _Point | None:
        """r and g at a marched x; None where they are not finite."""
        r, g = self._values(x)
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(g))):
            return None
        return _Point(x=x, r=r, g=g)

    def marched(self, x: np.ndarray) -> _Point | None:
        """The point of x (n,) re-marched, whatever constraints it breaks; None where it
        does not march or is not finite."""
        marched = self.nlp.project(np.asarray(x, dtype=float))
        return None if marched is None else self.point(marched)

    def admissible(self, x: np.ndarray) -> _Point | None:
        """:meth:`marched` where it holds every constraint and bound to :data:`FEASIBLE`;
        None otherwise."""
        p = self.marched(x)
        return p if p is not None and self.violation(p) <= FEASIBLE else None

    def linearize(self, p: _Point, metric: bool = True) -> _Linearization | None:
        """The derivatives at p; None where they are not finite or the marching equations
        no longer determine their unknowns. Invalidates the last point's. ``metric``: False
        skips the damping metric's part S_p' D_p S_p (``pattern_metric`` None)."""
        (J, lift), G = self._residual_jacobian(p.x), self._jacobian_g(p.x)
        if not (np.all(np.isfinite(J)) and np.all(np.isfinite(G))):
            return None
        if lift is not None and not (np.all(np.isfinite(lift.H))
                                     and np.all(np.isfinite(lift.Fu.data))):
            return None
        if not self._sweeps.refill(G):
            return None
        G_design, G_state = self._in_basis(self._G_design(G)), self._G_state(G)
        del G  # all of g's nonzeros, not held through the pass
        reduced = self._window(J, p.r, lift, metric)
        if reduced is None:
            return None
        return _Linearization(J_design=self._in_basis(self._J_design(J)),
                              J_state=self._J_state(J), G_design=G_design, G_state=G_state,
                              sensitivity=_Sensitivity(
                                  self._sweeps,
                                  None if reduced[3] is None else reduced[3][self.read],
                                  self._window.marching, self.basis, self.read),
                              JtJ=reduced[0], grad=reduced[1], pattern_metric=reduced[2],
                              lift=lift)

    def _in_basis(self, design_columns: sp.csr_matrix) -> sp.csr_matrix:
        """Design columns (k, n_d) times the basis (k, n_u); as they are with the identity."""
        return design_columns @ self.basis if self.coarse else design_columns

    def _residual_jacobian(self, x: np.ndarray) -> tuple[np.ndarray, Lift | None]:
        """The nonzeros of the residuals' Jacobian at x (with a lift, of its direct part)
        and its lift over the design's free columns (None without one)."""
        if not isinstance(self._jacobian_r, LiftedJacobian):
            return self._jacobian_r(x), None
        J, lift = self._jacobian_r(x)
        return J, Lift(lift.rows, lift.Fu, lift.H[:, self._lift_keep], self._window.free)

    def inequalities(self, g: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The inequality rows of the reduced problem at (g, x): g's inequality rows, then
        the bounded design, then the bounded state variables."""
        return np.concatenate([g[self.ineq], x[self.design][self.bounded_design],
                               x[self.state][self.bounded_state]])

    def violation(self, p: _Point) -> float:
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
    dense matrices at (12 knots + the rest)^2 instead of n_d^2 (docs/solvers.md)."""
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


def _gathered(csr: sp.csr_matrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The column indices of ``rows`` of ``csr`` one after the other, and where each row's
    run starts in them (rows.size,)."""
    at, counts = _positions(csr, rows)
    return csr.indices[at], np.cumsum(counts) - counts


def _positions(csr: sp.csr_matrix, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the nonzeros of ``rows`` of ``csr`` sit in its indices and data, one row
    after the other (nnz,), and each row's count (rows.size,)."""
    starts, counts = csr.indptr[rows], np.diff(csr.indptr)[rows]
    ends = np.cumsum(counts)
    at = np.repeat(starts - ends + counts, counts) + np.arange(ends[-1] if ends.size else 0)
    return at, counts


def _postponed(level: np.ndarray, deps: sp.csr_matrix, users: sp.csr_matrix) -> np.ndarray:
    """The levels (n_eq,) with every chain equation moved to just below its earliest user:
    an equation is a chain's when it uses at most one other equation's unknown, itself a
    chain's (a chain from the design alone). Such a chain's earliest level can lie far
    below the levels that read it, and its rows of S would wait that long in the pass's
    working set (:class:`_Window`): the lifted fold multiplier angles PHI of a column
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
            used, starts = _gathered(users, moved)
            late[moved] = np.minimum.reduceat(late[used], starts) - 1
    return late


@dataclass
class _Model:
    """The Gauss-Newton model of the reduced problem at a point, in the basis' coordinates
    u: JtJ = Jr' Jr (Jr the reduced Jacobian, n_r x n_u, never formed), H = JtJ + B, the
    metric M (n_u, n_u), the gradient Jr' r (n_u,), and its inequalities: rows = g's
    inequality rows, then the bounded design, then the bounded state variables, each with
    its bounds minus its current value; ``known``: the rows of A (n_u,) by index swept back
    so far (:meth:`_Steps.rows`)."""

    JtJ: np.ndarray
    H: np.ndarray
    M: np.ndarray
    grad: np.ndarray
    lin: _Linearization
    lower: np.ndarray  # bounds minus current values: lower <= A dd <= upper
    upper: np.ndarray
    known: dict[int, np.ndarray] = field(default_factory=dict)


def _model(man: Manifold, p: _Point, lin: _Linearization,
           M: np.ndarray | None = None) -> _Model:
    """The model at p; its metric from ``lin``, or ``M`` (n_u, n_u) where ``lin`` has
    none (linearised without it)."""
    if lin.pattern_metric is not None:
        M = lin.pattern_metric + man.design_metric.toarray()
    if M is None:
        raise ValueError("a linearisation without the metric needs the metric to keep")
    now = man.inequalities(p.g, p.x)
    return _Model(JtJ=lin.JtJ, H=lin.JtJ, M=M, grad=lin.grad, lin=lin,
                  lower=man.lower - now, upper=man.upper - now)


@dataclass
class _Step:
    """A step dd (n_d,) and the multipliers of the QP's rows ``which`` (CasADi's sign:
    negative at a lower bound); both empty when no row entered a QP."""

    dd: np.ndarray
    which: np.ndarray
    multipliers: np.ndarray


class _Steps:
    """The constrained step of a model: the unconstrained damped step, then, while it
    breaks linearised inequalities, a QP over those rows (and the rows whose slack is within
    twice their change) until it breaks none."""

    def __init__(self, man: Manifold):
        self.man = man
        self._qps: dict[int, ca.Function] = {}

    def change(self, m: _Model, du: np.ndarray) -> np.ndarray:
        """A du for every inequality row (du (n_u,), in the basis' coordinates)."""
        ds = m.lin.state_change(du)
        return np.concatenate([m.lin.G_design @ du + m.lin.G_state @ ds,
                               (self.man.basis @ du)[self.man.bounded_design],
                               ds[self.man.bounded_read]])

    def rows(self, m: _Model, which: np.ndarray) -> np.ndarray:
        """The dense rows ``which`` of A (which.size, n_u), each swept back once per model
        (the QP rounds, the optimality test and the secant update ask for the same rows)."""
        new = np.array([i for i in which.tolist() if i not in m.known], dtype=np.int64)
        if new.size:
            m.known.update(zip(new.tolist(), self._swept(m, new)))
        return np.array([m.known[i] for i in which.tolist()]).reshape(which.size,
                                                                      self.man.basis.shape[1])

    def _swept(self, m: _Model, which: np.ndarray) -> np.ndarray:
        """The dense rows ``which`` of A (which.size, n_u): a state row's part by the
        adjoint sweep, a block of rows at a time (:data:`BLOCK`)."""
        man, lin = self.man, m.lin
        ng, nbd = man.ineq.size, man.bounded_design.size
        A = np.zeros((which.size, man.basis.shape[1]))
        g_rows = np.flatnonzero(which < ng)
        d_rows = np.flatnonzero((which >= ng) & (which < ng + nbd))
        for into, matrix, rows in ((g_rows, lin.G_design, which[g_rows]),
                                   (d_rows, man.basis, man.bounded_design[which[d_rows] - ng])):
            at, counts = _positions(matrix, rows)  # the rows' nonzeros: no sparse slicing
            np.add.at(A, (np.repeat(into, counts), matrix.indices[at]), matrix.data[at])
        s_rows = np.flatnonzero(which >= ng + nbd)
        at, counts = _positions(lin.G_state, which[g_rows])
        # the state rows' part (the g rows' G_state, then a unit row per bounded state row)
        state = sp.csr_matrix(
            (np.concatenate([lin.G_state.data[at], np.ones(s_rows.size)]),
             np.concatenate([lin.G_state.indices[at], man.bounded_read[which[s_rows] - ng - nbd]]),
             np.concatenate([[0], np.cumsum(counts), at.size + np.arange(1, s_rows.size + 1)])),
            shape=(g_rows.size + s_rows.size, man.read.size))
        into = np.concatenate([g_rows, s_rows])
        block = max(1, BLOCK // (man.state.size + man.design.size))
        for k in range(0, into.size, block):
            A[into[k:k + block]] += lin.sensitivity.rows(state[k:k + block])
        return A

    def __call__(self, m: _Model, lam: float, shift: np.ndarray) -> _Step | None:
        try:
            factor = la.cho_factor(m.H + lam * m.M, lower=False)
        except la.LinAlgError:  # B made the damped model indefinite
            return None
        dd = la.cho_solve(factor, -m.grad)
        lower, upper = m.lower + shift, m.upper - shift
        work = shift > 0
        none = np.zeros(0, dtype=np.int64)
        step = _Step(dd=dd, which=none, multipliers=np.zeros(0))
        solved = np.zeros(shift.size, dtype=bool)  # rows of the last QP: hold to its tolerance
        for _ in range(QP_ROUNDS):
            Ad = self.change(m, step.dd)
            broken = ((Ad < lower) | (Ad > upper)) & ~solved
            if not broken.any():
                return step
            work |= broken | (lower > -2 * np.abs(Ad)) | (upper < 2 * np.abs(Ad))
            which = np.flatnonzero(work)
            step = self._qp(factor[0], m.grad, which, self.rows(m, which),
                            np.maximum(lower[which], -1e20), np.minimum(upper[which], 1e20))
            if step is None:
                return None
            solved = work.copy()
        return None

    def _qp(self, R: np.ndarray, grad: np.ndarray, which: np.ndarray, A: np.ndarray,
            lba: np.ndarray, uba: np.ndarray) -> _Step | None:
        """min 0.5 dd' H dd + grad' dd s.t. lba <= A dd <= uba (A: (k, n_d)), given H = R' R
        (R: ``cho_factor``'s upper factor; only its upper triangle is read), as the
        least-distance problem in z = R dd that DAQP solves without factoring H again:
        min 0.5 |z|^2 + (R^-T grad)' z s.t. lba <= (A R^-1) z <= uba, whose multipliers are
        the QP's."""
        n = R.shape[0]
        if which.size not in self._qps:
            self._qps[which.size] = ca.conic(
                "step", "daqp", {"h": ca.Sparsity.diag(n), "a": ca.Sparsity.dense(which.size, n)},
                {"error_on_fail": False, "daqp": {"primal_tol": 0.1 * FEASIBLE}})
        qp = self._qps[which.size]
        sol = qp(h=ca.DM.eye(n), g=la.solve_triangular(R, grad, trans="T"),
                 a=la.solve_triangular(R, A.T, trans="T").T, lba=lba, uba=uba)
        if not qp.stats()["success"]:
            return None
        return _Step(dd=la.solve_triangular(R, sol["x"].full().ravel()), which=which,
                     multipliers=sol["lam_a"].full().ravel())


def _kkt_error(m: _Model, steps: _Steps, step: _Step) -> float:
    """The first-order optimality error of the reduced problem at the model's point: max of
    |grad + A_W' y| (stationarity) and of |y_i| times row i's distance to the bound it
    holds (complementarity), A_W the rows active in the step's QP, with the better of two
    multiplier estimates y of the right signs: the QP's own, and the least-squares ones
    of :func:`_least_squares_multipliers` (the QP's lag by the damped step: grad + A_W' y
    = -(H + lam M) dd)."""
    active = step.multipliers != 0
    if not active.any():  # no row active (and an empty least-squares problem: SciPy aborts)
        return float(np.max(np.abs(m.grad)))
    which, y = step.which[active], step.multipliers[active]
    A = steps.rows(m, which)
    lower_gap = np.minimum(-m.lower[which], 1e20)  # value - lower bound >= 0
    upper_gap = np.minimum(m.upper[which], 1e20)

    def error(y: np.ndarray) -> float:
        stationarity = np.max(np.abs(m.grad + A.T @ y))
        complementarity = np.maximum(np.maximum(-y, 0.0) * lower_gap,
                                     np.maximum(y, 0.0) * upper_gap)
        return float(max(stationarity, np.max(complementarity)))

    return min(error(y), error(_least_squares_multipliers(A, m.grad, np.sign(y))))


def _least_squares_multipliers(A: np.ndarray, grad: np.ndarray, sign: np.ndarray
                               ) -> np.ndarray:
    """The multipliers y (k,) of the rows A (k, n) with the signs ``sign`` (k,; CasADi's:
    negative at a lower bound) that minimise |grad + A' y| (non-negative least squares in
    sign * y)."""
    z, _ = nnls(A.T * sign, -grad)
    return sign * z


def _secant_term(pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int
                 ) -> np.ndarray:
    """B (n, n) from the secant pairs (step, y, y_sharp) of the last accepted steps, oldest
    first: :func:`_secant` applied to each in turn, from zero."""
    B = np.zeros((n, n))
    for pair in pairs:
        B = _secant(B, *pair)
    return B


def _secant(B: np.ndarray, step: np.ndarray, y: np.ndarray, y_sharp: np.ndarray) -> np.ndarray:
    """B (n_d, n_d) updated over one accepted ``step`` (n_d,) (Dennis, Gay & Welsch): ``y``
    the change of the Lagrangian's gradient, ``y_sharp`` its part that Jr' Jr does not
    model (:meth:`_Last.gradient_change`), which B step should reproduce. Unchanged where
    y' step <= 0."""
    ys = float(y @ step)
    if ys <= 0:
        return B
    sBs = float(step @ B @ step)
    if sBs != 0:
        B = B * min(1.0, abs(float(step @ y_sharp)) / abs(sBs))
    v = y_sharp - B @ step
    return B + (np.outer(v, y) + np.outer(y, v)) / ys - float(v @ step) * np.outer(y, y) / ys ** 2


def levenberg_marquardt(nlp: NLP, x: np.ndarray, damping: float, max_iter: int,
                        deadline: float | None = None,
                        stop: Callable[[np.ndarray], bool] | None = None,
                        callback: Callable[[float, float], None] | None = None,
                        tol: float = 1e-6, manifold: Manifold | None = None,
                        reference: Callable[[], np.ndarray] | None = None) -> Outcome:
    """Minimise the simultaneous NLP's loss over marched designs, from x (re-marched first),
    to first-order optimality (status "Solve_Succeeded", see the module docstring).

    ``damping``: the first lam; ``deadline``: a ``time.perf_counter()`` after which the run
    stops; ``stop(x)``: end once it holds at an accepted iterate; ``callback(objective,
    violation)`` at the start and after every accepted step; ``tol``: of the optimality
    error; ``manifold``: ``Manifold(nlp)`` built beforehand (it holds the derivatives' build);
    ``reference``: gives an admissible point (n,), called only where x is not admissible:
    the run then starts from x's boundary data moved toward the reference's
    (:func:`admissible_toward`, ``Outcome.moved``) where a fraction of
    :data:`TOWARD_REFERENCE` is admissible. Otherwise a start that marches but breaks a
    constraint is restored (module docstring, ``Outcome.restored``); the run ends
    "Inadmissible_Start" where x does not march or the restoration fails.

    With a coarse basis (:attr:`Manifold.coarse`) the steps are taken in it first; where
    that run ends optimal in it or stalls, the manifold is refined and the run goes on in
    the whole design from there, its optimality error scaled as the first run's, so
    "Solve_Succeeded" always means the whole design's optimality conditions; where its
    restoration failed, the run restores the start again in the whole design.
    """
    man = Manifold(nlp) if manifold is None else manifold
    x, moved = np.asarray(x, dtype=float), None
    with man.blas_threads():
        if reference is not None and man.admissible(x) is None:
            moved = admissible_toward(man, x, reference())
        out = _levenberg_marquardt(man, x if moved is None else moved[0], damping, max_iter,
                                   deadline, stop, callback, tol)
        if moved is not None:
            out = replace(out, moved=moved[1])
    if not man.coarse or out.status not in ("Solve_Succeeded", "Stalled",
                                            "Inadmissible_Start"):
        return out
    if out.status == "Inadmissible_Start" and man.marched(out.x) is None:
        return out  # a start that does not march: the whole design would not help
    man.refine()  # where the restoration failed in the basis, it restarts in the whole design
    with man.blas_threads():
        rest = _levenberg_marquardt(man, out.x, damping, max_iter - out.iterations, deadline,
                                    stop, callback, tol, announce=False, scale=out.scale)
    return replace(rest, iterations=out.iterations + rest.iterations, moved=out.moved,
                   restored=out.restored + rest.restored)


def admissible_toward(man: Manifold, x: np.ndarray, reference: np.ndarray
                      ) -> tuple[np.ndarray, float] | None:
    """x (n,) with its free boundary data (:attr:`NLP.boundary_class` >= 0, not fixed by
    equal bounds; omega, the alignment and any controls stay) moved toward ``reference``'s
    (n,) by each fraction t of :data:`TOWARD_REFERENCE` in turn: the first such point that
    marches and holds every constraint to :data:`FEASIBLE`, re-marched, and its t; None when
    none does (a start carried from a coarser design can break a side's minimum length that
    the Miura keeps)."""
    moved = (man.nlp.boundary_class >= 0) & (man.nlp.lbx < man.nlp.ubx)
    for t in TOWARD_REFERENCE:
        y = x.copy()
        y[moved] += t * (reference[moved] - x[moved])
        p = man.admissible(y)
        if p is not None:
            return p.x, t
    return None


def _levenberg_marquardt(man: Manifold, x: np.ndarray, damping: float, max_iter: int,
                         deadline: float | None,
                         stop: Callable[[np.ndarray], bool] | None,
                         callback: Callable[[float, float], None] | None,
                         tol: float, announce: bool = True,
                         scale: float | None = None) -> Outcome:
    """:func:`levenberg_marquardt` on ``man`` (``announce``: the callback at the start
    too; ``scale``: the optimality error's, None: from the first gradient), a start that
    breaks a constraint restored first."""
    nlp = man.nlp
    x = np.asarray(x, dtype=float)
    p = man.marched(x)
    if p is None:
        return Outcome(x=x, objective=None, iterations=0, status="Inadmissible_Start")
    infeasibility = man.violation(p)
    restoring = infeasibility > FEASIBLE
    if callback is not None and announce:
        callback(p.objective, infeasibility)
    steps = _Steps(man)
    lam, nu, it, restored, reach = float(damping), 2.0, 0, 0, 1.0
    B = np.zeros((man.basis.shape[1],) * 2)
    pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (step, y, y_sharp)
    augmented, error, last, kept = False, None, None, None
    status = "Maximum_Iterations_Exceeded"
    while it < max_iter:
        lin = m = None  # the last point's derivatives go before the next are built
        lin = man.linearize(p, metric=kept is None or lam >= METRIC_DAMPING)
        if lin is None:
            status = "Stalled"
            break
        m = _model(man, p, lin, kept)
        kept = m.M
        if last is not None:
            pairs = (pairs + [(last.step, *last.gradient_change(m, steps))])[-SECANT_PAIRS:]
            B = _secant_term(pairs, man.basis.shape[1])
        if augmented and _positive_definite(m.H + B + lam * m.M):
            m.H = m.H + B
        if not restoring:
            scale = scale or max(1.0, float(np.max(np.abs(m.grad))) / 100)
        if deadline is not None and time.perf_counter() > deadline:
            status = "Maximum_WallTime_Exceeded"
            break
        base = _partial_target(m, reach) if restoring else np.zeros(m.lower.size)
        shift, corrections, first, candidate = base.copy(), 0, True, None
        while lam <= MAX_DAMPING:
            trial, step = None, steps(m, lam, shift)
            if step is not None:
                if first and not restoring:
                    error, first = _kkt_error(m, steps, step) / scale, False
                    if error <= tol:
                        break
                dd = step.dd
                predicted = -(m.grad @ dd + 0.5 * dd @ m.H @ dd)
                xt = p.x.copy()
                xt[man.design] += man.basis @ dd
                xt = nlp.project(xt)
                trial = (None if xt is None or (predicted <= 0 and not restoring)
                         else man.point(xt))
            if trial is not None and (restoring or trial.objective < p.objective):
                violation = man.violation(trial)
                if violation <= FEASIBLE:
                    break
                if (restoring and violation < (1 - RESTORED * reach) * infeasibility
                        and (candidate is None or violation < candidate[3])):
                    candidate = (trial, step, dd, violation)  # taken unless a correction holds
                if corrections < CORRECTIONS:
                    shift += _linearization_error(man, m, steps, dd, p, trial)
                    corrections += 1
                    continue
            if candidate is not None:
                trial, step, dd, violation = candidate
                break
            if step is not None and (predicted > 0 or restoring) and xt is None:
                lam *= DOMAIN_DAMPING  # left the march's domain
            else:
                lam, nu = lam * nu, 2 * nu
            if restoring:  # a larger lam hardly shortens a step the QP forces: ask for less
                reach /= 2
                base = _partial_target(m, reach)
            shift, corrections = base.copy(), 0
        else:
            status = "Stalled"
            break
        if error is not None and error <= tol:
            status = "Solve_Succeeded"
            break
        actual = p.objective - trial.objective
        if restoring:  # the loss may rise: the step is judged by the violation alone
            infeasibility, restored, reach = violation, restored + 1, 1.0
            restoring = violation > FEASIBLE
            lam, nu = lam / 3, 2.0
            last, augmented = None, False  # its QP's multipliers force rows: no secant pair
        else:
            rho = actual / predicted
            lam, nu = lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0
            last = _Last(m, steps, step, dd, trial)
            augmented = last.augmented_predicts_better(actual, B)
        p, it = trial, it + 1
        if callback is not None:
            callback(p.objective, violation)
        if stop is not None and not restoring and stop(p.x):
            status = "Fit_Reached"
            break
    if restoring:  # no admissible point reached: the start as given
        return Outcome(x=x, objective=None, iterations=it, status="Inadmissible_Start",
                       restored=it)
    return Outcome(x=p.x, objective=p.objective, iterations=it, status=status,
                   kkt_error=error, scale=scale, restored=restored)


def _partial_target(m: _Model, reach: float) -> np.ndarray:
    """The shift of the step's inequality rows (n_rows,) that asks each row broken at the
    model's point for only ``reach`` of its way back to its bound (:meth:`_Steps.__call__`
    holds lower + shift <= A dd <= upper - shift); zero on the rows that hold."""
    gap = np.maximum(m.lower, 0.0) + np.maximum(-m.upper, 0.0)
    return -(1.0 - reach) * gap


@functools.cache
def _blas() -> ThreadpoolController:
    """The BLAS libraries this process has loaded (threadpoolctl; scanning them takes a few
    milliseconds, once)."""
    return ThreadpoolController()


def _positive_definite(H: np.ndarray) -> bool:
    try:
        la.cho_factor(H)
    except la.LinAlgError:
        return False
    return True


class _Last:
    """The model and accepted step of the last iteration, for the secant update and the
    choice between the Gauss-Newton and the augmented model (NL2SOL's rule: the one whose
    predicted reduction was nearer the actual one)."""

    def __init__(self, m: _Model, steps: _Steps, step: _Step, change: np.ndarray,
                 trial: _Point):
        self.grad, self.JtJ = m.grad, m.JtJ
        self.which, self.multipliers = step.which, step.multipliers
        self.A = steps.rows(m, step.which) if step.which.size else None
        self.step = change
        self.Jt_r = m.lin.jacobian_transpose(trial.r)  # Jr' r at the accepted point

    def gradient_change(self, m: _Model, steps: _Steps) -> tuple[np.ndarray, np.ndarray]:
        """(y, y_sharp) of :func:`_secant` at the new model m: the change of the gradient
        of the Lagrangian (the QP's multipliers held), and of its part that Jr' Jr misses."""
        y, y_sharp = m.grad - self.grad, m.grad - self.Jt_r
        if self.A is not None:
            dA = (steps.rows(m, self.which) - self.A).T @ self.multipliers
            y, y_sharp = y + dA, y_sharp + dA
        return y, y_sharp

    def augmented_predicts_better(self, actual: float, B: np.ndarray) -> bool:
        s = self.step
        gauss_newton = -(self.grad @ s + 0.5 * s @ self.JtJ @ s)
        return abs(actual - (gauss_newton - 0.5 * s @ B @ s)) < abs(actual - gauss_newton)


def _linearization_error(man: Manifold, m: _Model, steps: _Steps, dd: np.ndarray,
                         p: _Point, trial: _Point) -> np.ndarray:
    """Per inequality row broken at ``trial``: how far its linearised change A dd
    overestimated the slack gained (the second-order correction), plus a margin."""
    value = man.inequalities(trial.g, trial.x)
    actual = value - man.inequalities(p.g, p.x)
    broken = (value < man.lower - FEASIBLE) | (value > man.upper + FEASIBLE)
    error = np.abs(steps.change(m, dd) - actual) + 10 * FEASIBLE
    return np.where(broken, error, 0.0)
