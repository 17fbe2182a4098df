"""The transcribed NLP (:class:`NLP`), the named blocks of a flat variable vector
(:class:`Layout`) and where a free correspondence's controls sit in either transcription's
design vector (:func:`controls_of`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import casadi as ca
import numpy as np

from .. import stencils


@dataclass
class NLP:
    """One transcribed NLP: min 0.5 |res(x)|^2 s.t. lbg <= g(x) <= ubg, lbx <= x <= ubx."""

    x: ca.MX
    residuals: ca.MX
    g: ca.MX
    lbg: np.ndarray
    ubg: np.ndarray
    lbx: np.ndarray
    ubx: np.ndarray
    x0: np.ndarray
    #: Function of x: the boundary data vector (angles, lengths) and omega
    unpack: ca.Function
    #: Function of x: the folded vertices (Yx, Yy, Yz)
    folded: ca.Function
    groups: dict
    #: x -> the point of the design that x's boundary data, omega, alignment (and a free
    #: correspondence's controls) define, re-marched (None where they do not march); None
    #: when every x is such a point
    project: Callable[[np.ndarray], np.ndarray | None] | None = None
    #: (local, global) symbols with x = vertcat(local, global), where the few global
    #: variables couple with every panel; see
    #: :func:`rffqm_nlp.design.solvers.ipopt.hessians.lagrangian_hessian`
    parts: tuple[ca.MX, ca.MX] | None = None
    #: diagonal D of the Levenberg-Marquardt term (:func:`.inputs.damping_weights`) of
    #: :func:`rffqm_nlp.design.solvers.ipopt.hessians.gauss_newton_hessian`
    damping_weights: np.ndarray | None = None
    #: indices in x of the design (boundary data, omega, alignment) from which the rest
    #: marches, and of every sector angle and side: see
    #: :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`
    design_index: np.ndarray | None = None
    pattern_index: np.ndarray | None = None
    #: Function of x: the target lattice (Tx, Ty, Tz), each (N+1, M+1), of a free
    #: correspondence (:class:`.correspondence.Correspondence`); None: the target lattice is fixed
    free_target: ca.Function | None = None
    #: indices in x of that correspondence's controls, Cu then Cv (each column-major)
    grid_index: np.ndarray | None = None
    #: per entry of x that is boundary data, its place along the boundary: the left edge
    #: from its top (-N) down to the corner (0), then the bottom edge (to M), a side halfway
    #: between its vertices; NaN elsewhere. The state at vertex (i, j) reads only the
    #: boundary data in [-i, j] (:mod:`rffqm_nlp.design.solvers.levenberg_marquardt` uses it to
    #: order the design)
    boundary_position: np.ndarray | None = None
    #: per entry of x that is boundary data, its class: the array (A or B at the left
    #: edge's vertices, at the bottom edge's, LV, LH) and the parity of its index along the
    #: edge, 2 x 6 classes numbered from 0 (a Miura-ori's boundary data alternate between
    #: two values along each edge); -1 elsewhere
    #: (:func:`rffqm_nlp.design.solvers.levenberg_marquardt.boundary_basis`)
    boundary_class: np.ndarray | None = None
    #: the Jacobians of the residuals and of g for
    #: :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`: assembled from local stencils
    #: (:mod:`rffqm_nlp.design.stencils`), or CasADi's of the whole graph
    #: (:class:`~rffqm_nlp.design.stencils.GraphJacobian`, an NLP of several states); None:
    #: Levenberg-Marquardt does not solve the NLP
    r_jacobian: (stencils.LocalJacobian | stencils.LiftedJacobian | stencils.GraphJacobian
                 | None) = None
    g_jacobian: stencils.LocalJacobian | stencils.GraphJacobian | None = None
    #: every folded state of an NLP of several states of one sheet
    #: (:func:`.states_nlp.several_states`), the first also ``unpack``'s omega, ``folded``
    #: and ``free_target``; () for one state
    states: tuple[StateFunctions, ...] = ()

    @property
    def objective(self) -> ca.MX:
        """f(x) = 0.5 |res(x)|^2."""
        return 0.5 * ca.sumsqr(self.residuals)

    def folded_array(self, x: np.ndarray) -> np.ndarray:
        """The folded vertices at the design vector ``x``, (2N+1, 2M+1, 3)."""
        return np.stack([c.full() for c in self.folded(x)], axis=-1)

    def target_array(self, x: np.ndarray, fixed: np.ndarray) -> np.ndarray:
        """The target lattice at ``x`` (N+1, M+1, 3): ``fixed`` (the sampled lattice, same
        shape) unless the correspondence is free."""
        if self.free_target is None:
            return fixed
        return np.stack([c.full() for c in self.free_target(x)], axis=-1)

    def with_rows(self, rows: ca.MX, lower: np.ndarray, upper: np.ndarray) -> "NLP":
        """This NLP with the constraint rows ``lower <= rows(x) <= upper`` (each (n,))
        appended to g (e.g. :func:`rffqm_nlp.design.clearance.constrain`'s); with lower < upper
        they are inequalities, which :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`
        linearises like the others."""
        jacobian = self.g_jacobian
        if isinstance(jacobian, stencils.GraphJacobian):
            jacobian = jacobian.with_rows(rows)
        elif jacobian is not None:
            n_g, n = self.g.numel(), self.x.numel()
            jacobian = jacobian.with_stencil(stencils.stencil(
                ca.Function("rows", [self.x, ca.MX.sym("p", 0)], [rows]),
                np.arange(n)[None, :], n_g + np.arange(rows.numel())[None, :]))
        return replace(self, g=ca.vertcat(self.g, rows), g_jacobian=jacobian,
                       lbg=np.concatenate([self.lbg, np.asarray(lower, dtype=float)]),
                       ubg=np.concatenate([self.ubg, np.asarray(upper, dtype=float)]))


@dataclass(frozen=True)
class StateFunctions:
    """One folded state of an NLP of several states: Functions of x giving its ``omega``
    (1 x 1), its folded vertices ``folded`` (Yx, Yy, Yz) and, with a free correspondence,
    its target lattice ``target`` (Tx, Ty, Tz) (None: the target lattice is fixed)."""

    omega: ca.Function
    folded: ca.Function
    target: ca.Function | None = None

    def omega_value(self, x: np.ndarray) -> float:
        """omega at the design vector ``x``."""
        return float(self.omega(x))

    def folded_array(self, x: np.ndarray) -> np.ndarray:
        """The folded vertices at ``x``, (2N+1, 2M+1, 3)."""
        return np.stack([c.full() for c in self.folded(x)], axis=-1)

    def target_array(self, x: np.ndarray, fixed: np.ndarray) -> np.ndarray:
        """The target lattice at ``x`` (N+1, M+1, 3): ``fixed`` unless the correspondence
        is free."""
        if self.target is None:
            return fixed
        return np.stack([c.full() for c in self.target(x)], axis=-1)


class Layout:
    """Named blocks of one flat variable vector, each reshaped to a matrix."""

    def __init__(self, shapes: dict[str, tuple[int, int]]):
        self.slices, self.shapes, k = {}, shapes, 0
        for name, (r, c) in shapes.items():
            self.slices[name] = slice(k, k + r * c)
            k += r * c
        self.size = k

    def views(self, x) -> dict:
        return {n: ca.reshape(x[self.slices[n]], *self.shapes[n]) for n in self.shapes}

    def pack(self, values: dict[str, np.ndarray]) -> np.ndarray:
        out = np.zeros(self.size)
        for n, v in values.items():
            out[self.slices[n]] = np.asarray(v, dtype=float).reshape(self.shapes[n]).ravel("F")
        return out

    def indices(self, *names: str) -> np.ndarray:
        """Flat indices of the blocks ``names``, one after the other (empty for none)."""
        return np.concatenate([np.arange(self.slices[n].start, self.slices[n].stop)
                               for n in names] + [np.zeros(0, dtype=np.int64)])

    def index(self, name: str, rows, cols) -> np.ndarray:
        """Flat indices of block ``name`` at [rows, cols] (column-major storage)."""
        r, c = self.shapes[name]
        grid = np.arange(r * c).reshape((r, c), order="F")
        return self.slices[name].start + np.atleast_1d(grid[rows, cols]).ravel()


def controls_of(x: np.ndarray, transcription: str, size: int) -> np.ndarray:
    """A free correspondence's controls (size,) in a design vector x of ``transcription``:
    the last entries in the sequential one, just before omega and the rigid alignment (the
    last 8) in the simultaneous one (the layouts of :func:`.sequential_nlp.sequential`
    and :func:`.simultaneous_nlp.simultaneous`, their ``grid_index``)."""
    x = np.asarray(x, dtype=float)
    end = x.size if transcription == "sequential" else x.size - 8
    return x[end - size:end]
