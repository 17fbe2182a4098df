"""Transcriptions of a :class:`~rffqm_nlp.design.problem.DesignProblem` into one IPOPT NLP.

A transcription turns the declarative problem into ``(x, residuals, g, bounds, x0)``:

* ``sequential``: the marching graph is a function of the boundary data (few variables,
  dense Jacobians);
* ``simultaneous``: every vertex angle and side is a variable and the marching equations are
  equality constraints, panel by panel (many variables, sparse Jacobians).

Both share the residuals of the loss (:func:`loss_residuals`), the Tikhonov term, the
inline constraints (angle bounds, multiplier margins, the boundary MV assignment, sides
against the mean side) and a free correspondence's controls (:class:`Correspondence`), so
they state the same problem. The simultaneous NLP also carries the Jacobians of its
residuals and constraints assembled from local stencils (:class:`_ConstraintStencils`),
which :mod:`rffqm_nlp.design.solvers.levenberg_marquardt` uses instead of CasADi's Jacobians of
the whole graph.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from collections.abc import Callable, Sequence

import casadi as ca
import numpy as np
from scipy.interpolate import BSpline

from ..model import numpy_model
from ..targets import shape
from . import stencils
from ..model import vertex as vx
from ..model.backend import Scalar
from ..model.boundary import BoundaryData
from ..errors import InputError
from ..model.marching import (Evaluation, boundary_inputs, crease_quaternion, evaluate,
                       folded_function, locate_failure, marched_function, panel_cell,
                       pattern_function, qmul, rotate_planar, rotated_edges)

PI = np.pi


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
    #: variables couple with every panel; see :func:`lagrangian_hessian`
    parts: tuple[ca.MX, ca.MX] | None = None
    #: diagonal D of the Levenberg-Marquardt term of :func:`gauss_newton_hessian`
    damping_weights: np.ndarray | None = None
    #: indices in x of the design (boundary data, omega, alignment) from which the rest
    #: marches, and of every sector angle and side: see
    #: :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`
    design_index: np.ndarray | None = None
    pattern_index: np.ndarray | None = None
    #: Function of x: the target lattice (Tx, Ty, Tz), each (N+1, M+1), of a free
    #: correspondence (:class:`Correspondence`); None: the target lattice is fixed
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
    #: the Jacobians of the residuals and of g assembled from local stencils
    #: (:mod:`rffqm_nlp.design.stencils`), for
    #: :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`; None: only CasADi's
    #: Jacobians of the whole graph
    r_jacobian: stencils.LocalJacobian | stencils.LiftedJacobian | None = None
    g_jacobian: stencils.LocalJacobian | None = None

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
        if jacobian is not None:
            n_g, n = self.g.numel(), self.x.numel()
            jacobian = jacobian.with_stencil(stencils.stencil(
                ca.Function("rows", [self.x, ca.MX.sym("p", 0)], [rows]),
                np.arange(n)[None, :], n_g + np.arange(rows.numel())[None, :]))
        return replace(self, g=ca.vertcat(self.g, rows), g_jacobian=jacobian,
                       lbg=np.concatenate([self.lbg, np.asarray(lower, dtype=float)]),
                       ubg=np.concatenate([self.ubg, np.asarray(upper, dtype=float)]))


def lagrangian_hessian(nlp: NLP) -> ca.Function:
    """IPOPT's ``hess_lag`` for an NLP with ``parts``: the Hessian of
    L = lam_f f + lam_g' g assembled around its few dense rows and columns.

    Omega enters every crease and the rigid alignment every lattice point, so the Hessian
    has dense rows; CasADi's star colouring of the whole Hessian grows like their degree
    squared and dominated the build of large patterns. Here only the local block is
    coloured; the global rows are the Jacobian of grad_global L (8 rows), which builds
    several times faster (studies/results/bench_build.md).
    """
    local, glob = nlp.parts

    def hessian(lam_f, lam_g):
        L = lam_f * nlp.objective + ca.dot(lam_g, nlp.g)
        grad = ca.gradient(L, glob)
        cross = ca.jacobian(grad, local)
        return ca.blockcat([[ca.hessian(L, local)[0], cross.T],
                            [cross, ca.jacobian(grad, glob)]])

    return _hess_lag(nlp, hessian)


def gauss_newton_hessian(nlp: NLP, damping: float = 0.0) -> ca.Function:
    """IPOPT's ``hess_lag`` for the damped Gauss-Newton approximation
    lam_f (J' J + damping D), J the Jacobian of the residuals, D = ``nlp.damping_weights``
    (:func:`damping_weights`).

    The constraints' curvature is dropped, so the matrix is positive semidefinite and IPOPT
    factorises the KKT system once per iteration (with the exact Hessian it first tries
    without a perturbation, finds the wrong inertia and factorises again). Most variables
    of the simultaneous NLP do not enter the loss, so J' J alone leaves them without any
    curvature: undamped, the sphere cap took huge steps and did not recover feasibility
    (docs/solvers.md).
    """
    J = ca.jacobian(nlp.residuals, nlp.x)
    JtJ = ca.mtimes(J.T, J)
    if damping > 0:
        JtJ = JtJ + ca.diag(ca.DM(damping * nlp.damping_weights))
    return _hess_lag(nlp, lambda lam_f, lam_g: lam_f * JtJ)


def damping_weights(setup: Setup, lengths: np.ndarray) -> np.ndarray:
    """D of :func:`gauss_newton_hessian`: 1 / (s^2 n) per variable, s the lattice spacing
    for lengths and positions (``lengths`` marks them) and 1 for angles and quaternions, n
    the number of lattice points. The Levenberg-Marquardt term then weighs a change of one
    spacing or one radian like the position term (a mean over the lattice points) weighs
    an error of one spacing, whatever the target's size and the pattern's."""
    s = np.where(lengths, setup.spacing, 1.0)
    return 1.0 / (s ** 2 * setup.target.shape[0] * setup.target.shape[1])


def _hess_lag(nlp: NLP, hessian) -> ca.Function:
    """The Function IPOPT's CasADi interface takes as ``hess_lag``: (x, p, lam_f, lam_g) ->
    the upper triangle of ``hessian(lam_f, lam_g)``."""
    lam_f, lam_g, p = ca.MX.sym("lam_f"), ca.MX.sym("lam_g", nlp.g.numel()), ca.MX.sym("p", 0)
    return ca.Function("nlp_hess_l", [nlp.x, p, lam_f, lam_g],
                       [ca.triu(hessian(lam_f, lam_g))],
                       ["x", "p", "lam_f", "lam_g"], ["hess_gamma_x_x"])


def rotation_from_quaternion(q: Sequence[Scalar]) -> ca.MX:
    """Rotation matrix of the (not necessarily unit) quaternion q = (w, x, y, z)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    n = w * w + x * x + y * y + z * z
    R = ca.vertcat(
        ca.horzcat(w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)),
        ca.horzcat(2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)),
        ca.horzcat(2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z))
    return R / n


def quaternion_from_rotation(R: np.ndarray) -> np.ndarray:
    """A unit quaternion (w, x, y, z) of the rotation matrix R."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(R).as_quat()
    return np.array([w, x, y, z])


def loss_residuals(r: Sequence[ca.MX], rotation: ca.MX, translation: Scalar,
                   target: np.ndarray | Sequence[ca.MX], weights: dict[str, float],
                   spacing: float) -> ca.MX:
    """Residuals of the loss for the coarse lattice r(i, j) = y^{(2i)(2j)} of the folded
    vertices, r = (rx, ry, rz) ((N+1) x (M+1) each), against the target lattice: fixed
    (an array (N+1, M+1, 3)) or, with a free correspondence, symbolic (Tx, Ty, Tz)
    ((N+1) x (M+1) each, :meth:`Correspondence.lattice`).

    * ``forms``: the paper's loss (eq:optInverse): discrete first and second fundamental forms
      of r minus the target's, at interior points, by
      the same central differences (:func:`shape.fundamental_forms`), over spacing^2;
    * ``position``: R r + t minus the target lattice over ``spacing``: the position term
      after alignment (R, t are design variables) that sees the sideways offsets of the four
      parity classes that central differences miss (docs/paper.md).

    Each group is divided by sqrt(its count) and multiplied by sqrt(weight), so a weight is
    the share of a mean square in the objective.
    """
    out = []
    fixed = isinstance(target, np.ndarray)
    if weights.get("forms", 0) > 0:
        mine = shape.fundamental_forms(r)
        theirs = shape.fundamental_forms(target)
        res = ca.vertcat(*(ca.vec(a - (ca.DM(b) if fixed else b))
                           for a, b in zip(mine, theirs))) / spacing ** 2
        out.append(np.sqrt(weights["forms"] / res.numel()) * res)
    if weights.get("position", 0) > 0:
        pts = ca.vertcat(*(ca.vec(c).T for c in r))  # 3 x n
        moved = ca.mtimes(rotation, pts) + ca.repmat(translation, 1, pts.shape[1])
        tgt = (target.transpose(1, 0, 2).reshape(-1, 3).T if fixed  # column-major, as ca.vec
               else ca.vertcat(*(ca.vec(c).T for c in target)))
        res = ca.vec(moved - tgt) / spacing
        out.append(np.sqrt(weights["position"] / pts.shape[1]) * res)
    return ca.vertcat(*out)


#: A free correspondence's (u, v) map keeps every forward difference of u along i and of v
#: along j at least this fraction of the uniform grid's step (exactly: on its controls'
#: differences, see :meth:`Correspondence.rows`), and every corner of every cell of its
#: control net an orientation at least its square, relative to the uniform net's: the map
#: neither folds over nor collapses (docs/meshes.md).
MIN_GRID_STEP = 0.5
#: The weight of a free correspondence's Tikhonov term towards the uniform grid, as a
#: fraction of the "regularization" weight (docs/meshes.md).
GRID_REGULARIZATION = 0.1
#: A free correspondence's (u, v) map is a clamped cubic tensor-product B-spline of the
#: lattice indices with at most this many controls a side, however large the pattern
#: (docs/meshes.md).
GRID_CONTROLS = 4


def _clamped_basis(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(B, g): the clamped uniform B-spline basis of degree min(3, k - 1) with k controls on
    [0, 1] at the n points i / (n - 1), B (n, k), and the controls' Greville abscissae g
    (k,), with which the spline is the identity (B @ g = i / (n - 1))."""
    p = min(3, k - 1)
    knots = np.concatenate([np.zeros(p), np.linspace(0.0, 1.0, k - p + 1), np.ones(p)])
    greville = np.array([knots[a + 1:a + p + 1].mean() for a in range(k)])
    basis = BSpline.design_matrix(np.linspace(0.0, 1.0, n), knots, p).toarray()
    return basis, greville


@dataclass(frozen=True)
class Correspondence:
    """A free correspondence (docs/meshes.md): the parameters (u_ij, v_ij) of the coarse
    lattice are a tensor-product B-spline of the lattice indices whose controls are design
    variables, and the target lattice is r(u_ij, v_ij).

    ``surface``: the target's CasADi Function (u, v) -> r (3 x 1); ``domain``: ((u0, u1),
    (v0, v1)); ``Bu`` (N+1, Ku), ``Bv`` (M+1, Kv): the bases along i and along j
    (:func:`_clamped_basis`), so the grid is U = Bu Cu Bv', V = Bu Cv Bv' for the controls
    Cu, Cv (Ku, Kv); ``gu`` (Ku,), ``gv`` (Kv,): the Greville abscissae, so the uniform grid
    (the start, and the reference of the Tikhonov term) has controls u0 + (u1 - u0) gu
    along i and v0 + (v1 - v0) gv along j. The controls' first and last rows hold u = u0
    and u1, their first and last columns v = v0 and v1: the grid's edges slide along the
    domain's edges and its corners stay, so a design spans the whole domain. Vectors of
    the controls hold Cu then Cv, each column-major (as ``ca.vec``).
    """

    surface: ca.Function
    domain: tuple[tuple[float, float], tuple[float, float]]
    Bu: np.ndarray
    Bv: np.ndarray
    gu: np.ndarray
    gv: np.ndarray

    @classmethod
    def uniform(cls, surface: ca.Function, domain: tuple, lattice: tuple[int, int],
                controls: int | None = None) -> Correspondence:
        """The correspondence of an (N+1) x (M+1) ``lattice`` with min(``controls``,
        N+1) x min(``controls``, M+1) controls (default :data:`GRID_CONTROLS`)."""
        k = GRID_CONTROLS if controls is None else controls
        (Bu, gu), (Bv, gv) = (_clamped_basis(n, min(k, n)) for n in lattice)
        return cls(surface, domain, Bu, Bv, gu, gv)

    @property
    def shape(self) -> tuple[int, int]:
        """(Ku, Kv): the controls' shape."""
        return self.Bu.shape[1], self.Bv.shape[1]

    @property
    def size(self) -> int:
        """Design variables: 2 Ku Kv."""
        return 2 * self.Bu.shape[1] * self.Bv.shape[1]

    @property
    def steps(self) -> tuple[float, float]:
        """The uniform grid's steps (du, dv)."""
        (u0, u1), (v0, v1) = self.domain
        return (u1 - u0) / (self.Bu.shape[0] - 1), (v1 - v0) / (self.Bv.shape[0] - 1)

    def _uniform(self) -> tuple[np.ndarray, np.ndarray]:
        """The uniform grid's controls (Cu0, Cv0), each (Ku, Kv)."""
        (u0, u1), (v0, v1) = self.domain
        Cu, Cv = np.meshgrid(u0 + (u1 - u0) * self.gu, v0 + (v1 - v0) * self.gv,
                             indexing="ij")
        return Cu, Cv

    def start(self) -> np.ndarray:
        """The uniform grid's controls as a vector (2 Ku Kv,)."""
        return np.concatenate([c.ravel("F") for c in self._uniform()])

    def views(self, part: np.ndarray | ca.MX) -> tuple:
        """(Cu, Cv), each (Ku, Kv), of a controls vector ``part`` (NumPy or CasADi)."""
        ku, kv = self.shape
        if isinstance(part, np.ndarray):
            return part[:ku * kv].reshape(ku, kv, order="F"), part[ku * kv:].reshape(
                ku, kv, order="F")
        return ca.reshape(part[:ku * kv], ku, kv), ca.reshape(part[ku * kv:], ku, kv)

    def grid(self, Cu: np.ndarray | ca.MX, Cv: np.ndarray | ca.MX) -> tuple:
        """The grid (U, V), each (N+1, M+1), of the controls (NumPy or CasADi)."""
        if isinstance(Cu, np.ndarray):
            return self.Bu @ Cu @ self.Bv.T, self.Bu @ Cv @ self.Bv.T
        Bu, BvT = ca.sparsify(ca.DM(self.Bu)), ca.sparsify(ca.DM(self.Bv.T))  # exact zeros
        return ca.mtimes([Bu, Cu, BvT]), ca.mtimes([Bu, Cv, BvT])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lbx, ubx) of the controls vector: the domain, the edges pinned."""
        (u0, u1), (v0, v1) = self.domain
        shape = self.shape
        lu, hu, lv, hv = (np.full(shape, b) for b in (u0, u1, v0, v1))
        hu[0, :], lu[-1, :] = u0, u1
        hv[:, 0], lv[:, -1] = v0, v1
        return (np.concatenate([lu.ravel("F"), lv.ravel("F")]),
                np.concatenate([hu.ravel("F"), hv.ravel("F")]))

    @cached_property
    def _lift(self) -> np.ndarray:
        """d vec(U) / d vec(Cu) = d vec(V) / d vec(Cv) = Bv (x) Bu, ((N+1) (M+1), Ku Kv):
        the grid is linear in the controls (column-major vectors)."""
        return np.kron(self.Bv, self.Bu)

    def target_values(self, controls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(T, H) at a controls vector (2 Ku Kv,): the target lattice T (3 n,), (Tx, Ty,
        Tz) each column-major over the n = (N+1) (M+1) points, and its Jacobian in the
        controls H (3 n, 2 Ku Kv)."""
        U, V = self.grid(*self.views(controls))
        # row vectors of n columns make CasADi evaluate the Function n times
        T, T_u, T_v = (a.full() for a in self._first(U.ravel("F")[None], V.ravel("F")[None]))
        L = self._lift
        H = np.concatenate([np.concatenate([T_u[k][:, None] * L, T_v[k][:, None] * L], axis=1)
                            for k in range(3)])
        return T.ravel(), H

    @cached_property
    def _first(self) -> ca.Function:
        """(u, v) -> (r, r_u, r_v) of the target surface."""
        u, v = ca.SX.sym("u"), ca.SX.sym("v")
        r = self.surface(u, v)
        return ca.Function("first", [u, v], [r, ca.jacobian(r, u), ca.jacobian(r, v)])

    def lattice(self, Cu: ca.MX, Cv: ca.MX) -> list[ca.MX]:
        """The target lattice (Tx, Ty, Tz) at the controls' grid, each (N+1) x (M+1)."""
        U, V = self.grid(Cu, Cv)
        n1, m1 = self.Bu.shape[0], self.Bv.shape[0]
        pts = self.surface.map(n1 * m1)(ca.vec(U).T, ca.vec(V).T)  # 3 x n
        return [ca.reshape(pts[k, :].T, n1, m1) for k in range(3)]

    def rows(self, Cu: ca.MX, Cv: ca.MX) -> tuple[ca.MX, np.ndarray, np.ndarray]:
        """(g, lbg, ubg): the controls' forward differences (of Cu along i, of Cv along
        j) over the uniform net's, at least :data:`MIN_GRID_STEP`, and the orientation of
        every cell of the control net at its four corners over the uniform net's, at least
        its square.

        The spline's derivative along i is a B-spline whose coefficients are those
        difference quotients times (u1 - u0), so every forward difference of the grid's
        U along i is at least MIN_GRID_STEP uniform steps (and of V along j)."""
        (u0, u1), (v0, v1) = self.domain
        hu, hv = np.diff(self.gu) * (u1 - u0), np.diff(self.gv) * (v1 - v0)
        ku, kv = self.shape
        steps = ca.vertcat(ca.vec((Cu[1:, :] - Cu[:-1, :]) / ca.repmat(ca.DM(hu), 1, kv)),
                           ca.vec((Cv[:, 1:] - Cv[:, :-1]) / ca.repmat(ca.DM(hv).T, ku, 1)))
        area = ca.DM(np.outer(hu, hv))
        # (u, v) of the net's cells' corners (a, b) = (i offset, j offset), each (Ku-1, Kv-1)
        c = {(a, b): (Cu[a:ku - 1 + a, b:kv - 1 + b], Cv[a:ku - 1 + a, b:kv - 1 + b])
             for a in (0, 1) for b in (0, 1)}

        def turn(p, q, o):  # orientation of the edges o -> p, o -> q
            return ((p[0] - o[0]) * (q[1] - o[1]) - (p[1] - o[1]) * (q[0] - o[0])) / area

        turns = ca.vertcat(*(ca.vec(turn(c[p], c[q], c[o])) for p, q, o in (
            ((1, 0), (0, 1), (0, 0)), ((1, 1), (0, 0), (1, 0)),
            ((0, 1), (1, 0), (1, 1)), ((0, 0), (1, 1), (0, 1)))))
        lower = np.concatenate([np.full(steps.numel(), MIN_GRID_STEP),
                                np.full(turns.numel(), MIN_GRID_STEP ** 2)])
        return ca.vertcat(steps, turns), lower, np.full(lower.size, np.inf)

    def residuals(self, Cu: ca.MX, Cv: ca.MX, weight: float) -> ca.MX:
        """The Tikhonov term towards the uniform grid's controls, in uniform steps, times
        sqrt(weight / their count)."""
        du, dv = self.steps
        Cu0, Cv0 = self._uniform()
        delta = ca.vertcat(ca.vec(Cu - ca.DM(Cu0)) / du, ca.vec(Cv - ca.DM(Cv0)) / dv)
        return np.sqrt(weight / delta.numel()) * delta

    def damping_weights(self) -> np.ndarray:
        """D of :func:`gauss_newton_hessian` for the controls vector: 1 / (step^2 n), n the
        number of controls (a change of one uniform step weighs like one lattice spacing
        of a length)."""
        du, dv = self.steps
        n = self.size // 2
        return np.concatenate([np.full(n, 1 / (du ** 2 * n)), np.full(n, 1 / (dv ** 2 * n))])


@dataclass(frozen=True)
class Setup:
    """Everything a transcription needs, derived from a DesignProblem and its start."""

    boundary: BoundaryData  # the initial guess (the Miura start, or a warm start)
    omega: float
    rotation: np.ndarray  # rigid alignment of the start onto the target
    translation: np.ndarray
    target: np.ndarray  # (N+1, M+1, 3) target lattice
    spacing: float
    weights: dict
    min_angle: float
    min_length: float
    mu_margin: float
    omega_bounds: tuple[float, float]
    fixed: tuple[str, ...]
    reference: BoundaryData  # the Miura start: Tikhonov reference and MV pattern
    reference_omega: float
    correspondence: Correspondence | None = None  # None: the target lattice is fixed
    controls: np.ndarray | None = None  # a warm start's controls (None: the uniform grid's)

    def controls0(self) -> np.ndarray:
        """The initial guess's controls of the free correspondence (2 Ku Kv,)."""
        return self.correspondence.start() if self.controls is None else self.controls

    @property
    def reference_vector(self) -> np.ndarray:
        """The Tikhonov reference: boundary data vector and omega of the Miura start."""
        return np.concatenate([self.reference.to_vector(), [self.reference_omega]])

    @cached_property
    def mu_outside(self) -> np.ndarray:
        """Per panel (column-major): is |mu_abc| above 1 at the Miura start? (held)"""
        mu0 = evaluate(pattern_function(self.reference.N, self.reference.M),
                       boundary_inputs(self.reference))[5]
        return np.abs(mu0.ravel(order="F")) > 1

    def mu_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of sign * (mu^2 - 1) with sign = +1 above 1 and -1 below."""
        out, m = self.mu_outside, self.mu_margin
        return np.where(out, (1 + m) ** 2 - 1, 1 - (1 - m) ** 2), np.full(out.size, np.inf)

    @cached_property
    def mv_sign(self) -> np.ndarray:
        """Per boundary vertex (left then bottom): the sign of :func:`vertex.mv_multiplier` at
        the Miura start (held)."""
        ang = self.reference.angles
        return np.sign(vx.mv_multiplier(ang[:, 0], ang[:, 1], self.reference.sigma))

    def boundary_mv(self, alpha: ca.MX, beta: ca.MX) -> tuple[ca.MX, np.ndarray, np.ndarray]:
        """The boundary MV assignment held: sign * mv_multiplier >= mu_margin at every
        boundary vertex (alpha, beta: N+1+M vectors, left then bottom). With the mu
        constraints this holds the M/V of every crease (no counterexample in 4,400 random
        marchable perturbations; a property test in tests/test_marching.py). Returns
        (g, lbg, ubg)."""
        g = ca.DM(self.mv_sign) * vx.mv_multiplier(alpha, beta, self.reference.sigma)
        n = self.mv_sign.size
        return g, np.full(n, self.mu_margin), np.full(n, np.inf)

    def rigid0(self) -> np.ndarray:
        return np.concatenate([quaternion_from_rotation(self.rotation), self.translation])


def _objective_residuals(setup: Setup, r, rigid, boundary_vec, grid=None) -> ca.MX:
    """Loss of the coarse lattice r (:func:`loss_residuals`), then the rows on the design
    alone (:func:`_design_residuals`). ``grid``: the controls (Cu, Cv) of a free
    correspondence (the target lattice at their grid, and their Tikhonov term), or None."""
    target = setup.target if grid is None else setup.correspondence.lattice(*grid)
    return ca.vertcat(loss_residuals(r, rotation_from_quaternion(rigid[:4]), rigid[4:], target,
                                     setup.weights, setup.spacing),
                      _design_residuals(setup, rigid, boundary_vec, grid))


def _design_residuals(setup: Setup, rigid, boundary_vec, grid=None):
    """The residuals after the loss, functions of the design alone (MX or SX): the
    quaternion normalisation, the Tikhonov term towards the Miura start, a free
    correspondence's Tikhonov term (``grid``: its controls (Cu, Cv), or None) and the
    smoothness of the boundary perturbation (lengths in units of the lattice spacing)."""
    q = rigid[:4]
    ref = setup.reference_vector
    nl = setup.reference.N + setup.reference.M
    scale = np.concatenate([np.ones(ref.size - nl - 1), np.full(nl, 1 / setup.spacing), [1.0]])
    delta = (boundary_vec - ref) * scale
    out = [ca.sumsqr(q) - 1,  # fixes the quaternion's free scale
           np.sqrt(setup.weights.get("regularization", 0) / scale.size) * delta]
    if grid is not None:
        out.append(setup.correspondence.residuals(
            *grid, GRID_REGULARIZATION * setup.weights.get("regularization", 0)))
    if setup.weights.get("smoothness", 0) > 0:
        kinks = smoothness_residuals(delta, setup.reference.N, setup.reference.M)
        out.append(np.sqrt(setup.weights["smoothness"] / kinks.numel()) * kinks)
    return ca.vertcat(*out)


def smoothness_residuals(delta: Scalar, N: int, M: int) -> Scalar:
    """Second differences of a boundary perturbation along the left and the bottom edge.

    ``delta`` follows :meth:`BoundaryData.to_vector` (alphas, betas, then l_left, l_bottom;
    a trailing omega is ignored). Angles are differenced along the left edge (N+1 vertices)
    and along the bottom edge with the corner (M+1 vertices); the lengths along each edge.
    Zero exactly when the perturbation is affine along every edge.
    """
    nv = N + 1 + M

    def second(v):
        return v[2:] - 2 * v[1:-1] + v[:-2]

    parts = []
    for k in (0, nv):  # alpha, then beta
        parts += [second(delta[k:k + N + 1]),
                  second(ca.vertcat(delta[k], delta[k + N + 1:k + nv]))]
    parts += [second(delta[2 * nv:2 * nv + N]), second(delta[2 * nv + N:2 * nv + N + M])]
    return ca.vertcat(*parts)


def sequential(setup: Setup) -> NLP:
    """The sequential transcription: x = (boundary angles, boundary lengths, omega, q, t),
    then the controls (Cu, Cv) of a free correspondence.

    The pattern and the folded state are functions of x through the marching graph; the
    inline constraints are every vertex angle in [min_angle, pi - min_angle], the multiplier
    margin of every panel, the MV assignment of every boundary vertex
    (:meth:`Setup.boundary_mv`), every side >= min_length * mean side, and a free
    correspondence's control rows (:meth:`Correspondence.rows`).
    """
    bd0 = setup.boundary
    N, M = bd0.N, bd0.M
    nv, nl = N + 1 + M, N + M
    corr = setup.correspondence
    n_grid = 0 if corr is None else corr.size
    n_fixed = 2 * nv + nl + 1 + 7
    x = ca.MX.sym("x", n_fixed + n_grid)
    groups = {"angles": slice(0, 2 * nv), "lengths": slice(2 * nv, 2 * nv + nl),
              "omega": slice(2 * nv + nl, 2 * nv + nl + 1),
              "rigid": slice(2 * nv + nl + 1, 2 * nv + nl + 8)}
    grid = None if corr is None else corr.views(x[n_fixed:])
    sig = ca.DM(bd0.sigma).T
    tri = ca.vertcat(x[:nv].T, x[nv:2 * nv].T, sig)
    lengths = x[groups["lengths"]].T
    omega = x[groups["omega"]]
    inputs = [tri[:, :N + 1], tri[:, N + 1:], lengths[:, :N], lengths[:, N:]]
    Y = folded_function(N, M).call([*inputs, omega])
    x0 = np.concatenate([bd0.to_vector(), [setup.omega], setup.rigid0()]
                        + ([] if corr is None else [setup.controls0()]))
    res = _objective_residuals(setup, shape.coarse_grain(Y), x[groups["rigid"]],
                               x[:2 * nv + nl + 1], grid)
    # Inline constraints on the marched pattern.
    alpha, beta, _, lh, lv, mu = pattern_function(N, M).call(inputs)[:6]
    sides = ca.vertcat(ca.vec(lh), ca.vec(lv))
    angles = ca.vertcat(ca.vec(alpha), ca.vec(beta))
    sign = ca.DM(np.where(setup.mu_outside, 1.0, -1.0))
    mv, lo_mv, hi_mv = setup.boundary_mv(x[:nv], x[nv:2 * nv])
    g = ca.vertcat(angles, sign * (ca.vec(mu) ** 2 - 1), mv,
                   sides / (ca.sum1(sides) / sides.numel()) - setup.min_length)
    lo_mu, hi_mu = setup.mu_bounds()
    lbg = np.concatenate([np.full(angles.numel(), setup.min_angle), lo_mu, lo_mv,
                          np.zeros(sides.numel())])
    ubg = np.concatenate([np.full(angles.numel(), PI - setup.min_angle), hi_mu, hi_mv,
                          np.full(sides.numel(), np.inf)])
    lbx = np.concatenate([np.full(2 * nv, setup.min_angle), np.full(nl, 1e-9 * setup.spacing),
                          [setup.omega_bounds[0]], np.full(7, -np.inf)])
    ubx = np.concatenate([np.full(2 * nv, PI - setup.min_angle), np.full(nl, np.inf),
                          [setup.omega_bounds[1]], np.full(7, np.inf)])
    lengths = np.zeros(n_fixed, dtype=bool)
    lengths[groups["lengths"]] = lengths[n_fixed - 3:] = True  # boundary sides, translation
    weights = damping_weights(setup, lengths)
    free_target = None
    if corr is not None:
        g, lbg, ubg = _with_grid_rows(corr, grid, g, lbg, ubg)
        lo, hi = corr.bounds()
        lbx, ubx = np.concatenate([lbx, lo]), np.concatenate([ubx, hi])
        weights = np.concatenate([weights, corr.damping_weights()])
        free_target = ca.Function("target", [x], corr.lattice(*grid))
    for name in setup.fixed:
        lbx[groups[name]] = ubx[groups[name]] = x0[groups[name]]
    unpack = ca.Function("unpack", [x], [x[:2 * nv + nl], omega])
    folded = ca.Function("folded", [x], list(Y))
    return NLP(x=x, residuals=res, g=g, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, x0=x0,
               unpack=unpack, folded=folded, groups=groups, damping_weights=weights,
               free_target=free_target,
               grid_index=None if corr is None else np.arange(n_fixed, n_fixed + n_grid))


def _with_grid_rows(corr: Correspondence, grid: tuple[ca.MX, ca.MX], g: ca.MX,
                    lbg: np.ndarray, ubg: np.ndarray) -> tuple[ca.MX, np.ndarray, np.ndarray]:
    """(g, lbg, ubg) with the grid rows of :meth:`Correspondence.rows` appended."""
    rows, lo, hi = corr.rows(*grid)
    return ca.vertcat(g, rows), np.concatenate([lbg, lo]), np.concatenate([ubg, hi])


class _Layout:
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

    def index(self, name: str, rows, cols) -> np.ndarray:
        """Flat indices of block ``name`` at [rows, cols] (column-major storage)."""
        r, c = self.shapes[name]
        grid = np.arange(r * c).reshape((r, c), order="F")
        return self.slices[name].start + np.atleast_1d(grid[rows, cols]).ravel()


class _MeanTree:
    """The mean of K sides as a tree of partial means: level 1 averages blocks of
    ``branching`` consecutive sides in the order ``order`` (a permutation of range(K),
    default as given), each further level blocks of the level below, up to one root, the
    mean. Every node is a variable and every tree equation is local.

    One equation sum(s) = K * mean would be a dense row of the constraint Jacobian, and the
    mean a dense column (it enters every side constraint); CasADi colours Jacobians in one
    direction, so that row and column together cost a sweep per side. The tree adds about
    K / (branching - 1) unknowns and a few tens of colours; a running mean (one variable per
    side) did the same with K unknowns, a noticeable share of the KKT system
    (docs/solvers.md).
    """

    def __init__(self, K: int, branching: int = 16, order: np.ndarray | None = None):
        self.levels: list[ca.DM] = []  # weights: node = sum of weight * child
        weight = np.ones(K)  # sides under each node of the level below
        rank = np.arange(K)
        if order is not None:
            rank[order] = np.arange(K)
        while weight.size > 1:
            parent = rank // branching
            rank = np.arange(parent.max() + 1)
            size = np.bincount(parent, weights=weight)
            self.levels.append(ca.DM.triplet(parent.tolist(), list(range(weight.size)),
                                             (weight / size[parent]).tolist(),
                                             size.size, weight.size))
            weight = size
        self.size = sum(W.size1() for W in self.levels)

    def residuals(self, sides, P) -> tuple:
        """(residuals, mean) for the sides and the node variables P (``size``, level by
        level, the root last)."""
        out, below, k = [], sides, 0
        for W in self.levels:
            node = P[k:k + W.size1()]
            out.append(node - ca.mtimes(W, below))
            below, k = node, k + W.size1()
        return ca.vertcat(*out), P[self.size - 1]

    def expression(self, sides: ca.MX) -> ca.MX:
        """The node values (``size``, as P) of the sides."""
        out, below = [], sides
        for W in self.levels:
            below = ca.mtimes(W, below)
            out.append(below)
        return ca.vertcat(*out)


def _sides_by_antidiagonal(N: int, M: int) -> np.ndarray:
    """The sides [vec(LH); vec(LV)] (column-major, K = (N+1) M + N (M+1)) ordered by the
    anti-diagonal i + j of their first vertex (i, j), then i: the march reaches them in
    that order, so that a partial mean of :class:`_MeanTree` waits for sides of about one
    anti-diagonal only (the Levenberg-Marquardt pass holds fewer rows,
    :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`)."""
    i = np.concatenate([np.tile(np.arange(N + 1), M), np.tile(np.arange(N), M + 1)])
    j = np.concatenate([np.repeat(np.arange(M), N + 1), np.repeat(np.arange(M + 1), N)])
    return np.lexsort((i, i + j))


def _fold_multipliers_kv(sigma: np.ndarray):
    """The constant parts of :func:`marching.fold_multipliers`: kh0 (1 x M+1) and the
    cumulative sign products down the columns, so that kv[i, j] = -kh0[j] / m2[0, j] * sp[i, j]
    and kh[i, j] = -kv[i, j] * m2[i, j]."""
    kh0 = np.concatenate([[1.0], np.cumprod(-sigma[0, 1:])])
    sp = np.vstack([np.ones((1, sigma.shape[1])), np.cumprod(sigma[1:, :], axis=0)])
    return kh0, sp


def _local_crease_quaternions(A, B, sigma: np.ndarray, TH, omega, PHI):
    """:func:`marching.crease_quaternions` with the column factors lifted and no quotient.

    The fold multiplier kv[i, j] of every vertex of column j carries 1 / m2 of the bottom
    vertex (i = 0), which would couple each crease of a column to that vertex. It is also
    infinite where that m2 vanishes (alpha = beta at sigma = +1): a point the boundary MV
    constraint excludes, but IPOPT's infeasible iterates can cross it. Lifting kv itself
    (KV[i] = sigma[i] KV[i-1]), the sphere cap and the quarter vase diverged at larger
    sizes; lifted as below, they converged (docs/solvers.md).

    PHI (N-1 x M) holds phi = atan(kv[1:N, :M]), smooth through kv = +-inf, with the local
    chain PHI[i] = sigma[i] PHI[i-1] and the bottom row from its vertex: tan(phi) = kv with
    m2 = num / den (:func:`vertex.mu2_terms`), i.e. sin(phi) num = -sigma kh0 cos(phi) den.
    Every crease multiplier is then a ratio of smooth terms, passed to
    :func:`crease_quaternion` as such: a quaternion of the same rotation up to sign (see
    :func:`_crease_quaternion_signs`), and the folded state is quadratic in it.
    Returns (qv, qh, residuals).
    """
    N, M = A.shape[0] - 1, A.shape[1] - 1
    kh0, _ = _fold_multipliers_kv(sigma)
    S, K0 = ca.DM(sigma), ca.DM(kh0).T
    num, den = vx.mu2_terms(A, B, S)
    c, s = ca.cos(omega / 2), ca.sin(omega / 2)
    theta_v = TH[:-1, :] + A[:-1, :]
    # kv[0, j] = -kh0[j] / m2[0, j] and kh[i, j] = -kv[i, j] m2[i, j] = -tan(phi) m2[i, j]
    qv = crease_quaternion(theta_v[0, 1:M], -K0[0, 1:M] * den[0, 1:M], c, s, sign=-1.0,
                           k_den=num[0, 1:M])
    qh = crease_quaternion(TH[1:N, :M], -ca.sin(PHI) * num[1:N, :M], c, s,
                           k_den=ca.cos(PHI) * den[1:N, :M])
    res = ca.vertcat(ca.vec(ca.sin(PHI[0, :]) * num[0, :M]
                            + S[1, :M] * K0[0, :M] * ca.cos(PHI[0, :]) * den[0, :M]),
                     ca.vec(PHI[1:, :] - S[2:N, :M] * PHI[:N - 2, :]))
    return qv, qh, res


def _crease_quaternion_signs(alpha, beta, sigma, phi) -> np.ndarray:
    """Per panel (N x M): the sign between the panel quaternion of
    :func:`_local_crease_quaternions` and that of :func:`marching.panel_quaternions_function`
    at numeric (alpha, beta, phi): the product of sign(k_den) of the creases crossed from
    panel (1, 1), along the bottom row and then up the column."""
    N, M = alpha.shape[0] - 1, alpha.shape[1] - 1
    num, den = vx.mu2_terms(alpha, beta, sigma)
    row = np.concatenate([[1.0], np.cumprod(np.sign(num[0, 1:M]))])
    col = np.cumprod(np.sign(np.cos(phi) * den[1:N, :M]), axis=0)
    return row * np.vstack([np.ones((1, M)), col])


def controls_of(x: np.ndarray, transcription: str, size: int) -> np.ndarray:
    """A free correspondence's controls (size,) in a design vector x of ``transcription``:
    the last entries in the sequential one, just before omega and the rigid alignment (the
    last 8) in the simultaneous one (the layouts of :func:`sequential` and
    :func:`simultaneous`, their ``grid_index``)."""
    x = np.asarray(x, dtype=float)
    end = x.size if transcription == "sequential" else x.size - 8
    return x[end - size:end]


def simultaneous(setup: Setup) -> NLP:
    """The simultaneous transcription: every vertex angle, side, edge direction, panel
    rotation (quaternion) and folded vertex is a variable, and the marching equations are
    equality constraints, panel by panel. The Jacobians stay sparse, so large patterns fit.

    Pattern: the panel cell (eq:marchingSector .. eq:getSides) maps a, b, c and l_ab, l_ac to
    d, l_cd, l_bd; the sides are stated multiplied through by the denominator of
    eq:getSides (:func:`vertex.panel_side_residuals`); with the quotient IPOPT needed far
    more iterations (docs/solvers.md).
    Kinematics: edge directions accumulate sector angles, panel quaternions multiply by
    crease quaternions (eq:defGrads), vertices add rotated edges (eq:finalCalc). The loss
    sees only the coarse lattice, but lifting every vertex keeps large designs converging:
    with the coarse lattice points alone (a smaller KKT system) a large sphere cap lost
    feasibility and did not recover (docs/solvers.md).

    Every equality row is local (a panel and its neighbours): the column factors of the fold
    multipliers are lifted (PHI, see :func:`_local_crease_quaternions`) and the mean side is
    the root of a tree of partial means (P, see :class:`_MeanTree`), so the Jacobian colours
    in a few tens of forward sweeps whatever the size. Solve it with ``mu_strategy =
    adaptive`` (or a small ``mu_init``): with IPOPT's default monotone barrier from mu = 0.1
    the barrier terms (hundreds of logs against a much smaller loss) pull this
    infeasible-path method towards square panels and long sides (measured: docs/solvers.md,
    "Cold-start barrier"), where it loses feasibility and never returns.
    """
    bd0 = setup.boundary
    N, M = bd0.N, bd0.M
    n1, m1 = N + 1, M + 1
    tree = _MeanTree(n1 * M + N * m1, order=_sides_by_antidiagonal(N, M))
    corr = setup.correspondence
    grid_blocks = {} if corr is None else {"U": corr.shape, "V": corr.shape}
    lay = _Layout({"A": (n1, m1), "B": (n1, m1), "LH": (n1, M), "LV": (N, m1),
                   "TH": (n1, m1), "Qw": (N, M), "Qx": (N, M), "Qy": (N, M), "Qz": (N, M),
                   "Yx": (n1, m1), "Yy": (n1, m1), "Yz": (n1, m1), "PHI": (N - 1, M),
                   "P": (tree.size, 1), **grid_blocks, "omega": (1, 1), "rigid": (7, 1)})
    parts = (ca.MX.sym("x", lay.size - 8), ca.MX.sym("x_global", 8))  # omega, rigid
    x = ca.vertcat(*parts)
    v = lay.views(x)
    A, B, LH, LV, TH, omega = v["A"], v["B"], v["LH"], v["LV"], v["TH"], v["omega"]
    start = numpy_model.march(bd0)
    S = ca.DM(start.sigma)
    # Pattern: one panel cell per panel, mapped.
    cell = panel_cell().map(N * M)
    row = lambda m: ca.vec(m).T  # noqa: E731 - column-major row of a panel-shaped block
    xs, ys = cell(ca.vertcat(row(A[1:, :M]), row(B[1:, :M]), row(S[1:, :M]), row(LV[:, :M])),
                  ca.vertcat(row(A[:N, :M]), row(B[:N, :M]), row(S[:N, :M]),
                             row(A[:N, 1:]), row(B[:N, 1:]), row(S[:N, 1:]), row(LH[:N, :])))
    # The sides of d without the quotient (vertex.panel_side_residuals), with the roles of
    # the panel cell: a = (i, j), b = (i+1, j), c = (i, j+1).
    sides_res = vx.panel_side_residuals(A[:N, :M], PI - B[1:, :M], B[:N, 1:], LV[:, :M],
                                        LH[:N, :], LV[:, 1:], LH[1:, :])
    march_res = ca.vec(ca.vertcat(row(A[1:, 1:]) - xs[0, :], row(B[1:, 1:]) - xs[1, :],
                                  *(row(r) for r in sides_res)))
    mu = ys[1, :].T
    # Kinematics, lifted.
    th_res = ca.vertcat(ca.vec(TH[1:, 0] - TH[:N, 0] - (A[:N, 0] - B[1:, 0])),
                        ca.vec(TH[:, 1:] - TH[:, :M] - (PI - A[:, 1:] - B[:, 1:])))
    quat = [v["Qw"], v["Qx"], v["Qy"], v["Qz"]]
    qv, qh, phi_res = _local_crease_quaternions(A, B, start.sigma, TH, omega, v["PHI"])
    prod_row1 = qmul([c[0, :M - 1] for c in quat], qv)
    prod_rows = qmul([c[:N - 1, :] for c in quat], qh)
    q_res = ca.vertcat(*(ca.vec(c[0, 1:] - p) for c, p in zip(quat, prod_row1)),
                       *(ca.vec(c[1:, :] - p) for c, p in zip(quat, prod_rows)))
    Y = [v["Yx"], v["Yy"], v["Yz"]]
    bottom, vertical = rotated_edges(quat, A, TH, LH, LV)
    y_res = ca.vertcat(*(ca.vec(c[0, 1:] - c[0, :M] - b) for c, b in zip(Y, bottom)),
                       *(ca.vec(c[1:, :] - c[:N, :] - e) for c, e in zip(Y, vertical)))
    # Boundary design vector in BoundaryData.to_vector order.
    bvec = ca.vertcat(A[:, 0], A[0, 1:].T, B[:, 0], B[0, 1:].T, LV[:, 0], LH[0, :].T, omega)
    grid = None if corr is None else (v["U"], v["V"])
    res = _objective_residuals(setup, shape.coarse_grain(Y), v["rigid"], bvec, grid)
    sides = ca.vertcat(ca.vec(LH), ca.vec(LV))
    mean_res, mean = tree.residuals(sides, v["P"])
    sign = ca.DM(np.where(setup.mu_outside, 1.0, -1.0))
    n_eq = (march_res.numel() + th_res.numel() + phi_res.numel() + q_res.numel()
            + y_res.numel() + mean_res.numel())
    nv = N + 1 + M
    mv, lo_mv, hi_mv = setup.boundary_mv(bvec[:nv], bvec[nv:2 * nv])
    g = ca.vertcat(march_res, th_res, phi_res, q_res, y_res, mean_res,
                   sign * (mu ** 2 - 1), mv, sides - setup.min_length * mean)
    lo_mu, hi_mu = setup.mu_bounds()
    lbg = np.concatenate([np.zeros(n_eq), lo_mu, lo_mv, np.zeros(sides.numel())])
    ubg = np.concatenate([np.zeros(n_eq), hi_mu, hi_mv, np.full(sides.numel(), np.inf)])
    if corr is not None:
        g, lbg, ubg = _with_grid_rows(corr, grid, g, lbg, ubg)
    block = lambda *names: np.concatenate([np.arange(lay.size)[lay.slices[n]]  # noqa: E731
                                           for n in names])
    grid_index = block("U", "V") if corr is not None else np.zeros(0, dtype=np.int64)
    project = _Projection(x, v, lay, start.sigma, tree, grid_index)
    x0 = project(lay.pack({"A": start.alpha, "B": start.beta, "LH": start.lh, "LV": start.lv,
                           "omega": setup.omega, "rigid": setup.rigid0()}))
    if x0 is None:
        raise RuntimeError("the start does not march with the CasADi graph")
    if corr is not None:
        x0[grid_index] = setup.controls0()
    lbx, ubx = np.full(lay.size, -np.inf), np.full(lay.size, np.inf)
    if corr is not None:
        lbx[grid_index], ubx[grid_index] = corr.bounds()
    for name in ("A", "B"):
        lbx[lay.slices[name]], ubx[lay.slices[name]] = setup.min_angle, PI - setup.min_angle
    for name in ("LH", "LV"):
        lbx[lay.slices[name]] = 1e-9 * setup.spacing
    lbx[lay.slices["omega"]], ubx[lay.slices["omega"]] = setup.omega_bounds
    for name in ("TH", "Qx", "Qy", "Qz", "Yx", "Yy", "Yz"):  # R^{11} = I, y^{11} = 0
        lbx[lay.index(name, 0, 0)] = ubx[lay.index(name, 0, 0)] = 0.0
    lbx[lay.index("Qw", 0, 0)] = ubx[lay.index("Qw", 0, 0)] = 1.0
    groups = {"angles": np.concatenate([lay.index(n, slice(None), 0) for n in ("A", "B")]
                                       + [lay.index(n, 0, slice(1, None)) for n in ("A", "B")]),
              "lengths": np.concatenate([lay.index("LV", slice(None), 0),
                                         lay.index("LH", 0, slice(None))]),
              "omega": lay.index("omega", 0, 0)}
    for name in setup.fixed:
        lbx[groups[name]] = ubx[groups[name]] = x0[groups[name]]
    unpack = ca.Function("unpack", [x], [bvec[:-1], omega])
    folded = ca.Function("folded", [x], Y)
    position = np.full(lay.size, np.nan)
    for name in ("A", "B"):
        position[lay.index(name, slice(None), 0)] = -np.arange(n1)
        position[lay.index(name, 0, slice(1, None))] = np.arange(1, m1)
    position[lay.index("LV", slice(None), 0)] = -(np.arange(N) + 0.5)
    position[lay.index("LH", 0, slice(None))] = np.arange(M) + 0.5
    boundary_class = np.full(lay.size, -1, dtype=np.int64)
    for kind, (name, rows, cols, index) in enumerate([
            ("A", slice(None), 0, np.arange(n1)), ("B", slice(None), 0, np.arange(n1)),
            ("A", 0, slice(1, None), np.arange(1, m1)), ("B", 0, slice(1, None), np.arange(1, m1)),
            ("LV", slice(None), 0, np.arange(N)), ("LH", 0, slice(None), np.arange(M))]):
        boundary_class[lay.index(name, rows, cols)] = 2 * kind + index % 2

    lengths = np.zeros(lay.size, dtype=bool)
    for name in ("LH", "LV", "Yx", "Yy", "Yz", "P"):
        lengths[lay.slices[name]] = True
    lengths[lay.size - 3:] = True  # the translation of the alignment, last in x
    weights = damping_weights(setup, lengths)
    free_target = None
    if corr is not None:
        weights[grid_index] = corr.damping_weights()
        free_target = ca.Function("target", [x], corr.lattice(*grid))
    design = np.concatenate([*groups.values(), block("rigid"), grid_index])
    return NLP(x=x, residuals=res, g=g, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, x0=x0,
               unpack=unpack, folded=folded, groups=groups, project=project, parts=parts,
               damping_weights=weights, design_index=design,
               pattern_index=block("A", "B", "LH", "LV"), free_target=free_target,
               boundary_position=position, boundary_class=boundary_class,
               grid_index=None if corr is None else grid_index,
               r_jacobian=_residual_jacobian(setup, lay, res.numel()),
               g_jacobian=_constraint_jacobian(setup, lay, start.sigma, tree, g.numel()))


def _constraint_jacobian(setup: Setup, lay: _Layout, sigma: np.ndarray, tree: _MeanTree,
                         n_g: int) -> stencils.LocalJacobian:
    """The Jacobian of :func:`simultaneous`'s constraints g (n_g rows, in its order),
    assembled from one stencil per kind of row (:class:`_ConstraintStencils`)."""
    return _ConstraintStencils(setup, lay, sigma, tree).jacobian(n_g)


def _residual_jacobian(setup: Setup, lay: _Layout, n_r: int
                       ) -> stencils.LocalJacobian | stencils.LiftedJacobian:
    """The Jacobian of :func:`simultaneous`'s residuals (n_r rows, in its order), assembled
    from stencils (:class:`_ResidualStencils`); with a free correspondence the target
    lattice is read as variables of its own and lifted from the controls after
    (:class:`stencils.LiftedJacobian`), so the residuals' Jacobian stays local."""
    inner = _ResidualStencils(setup, lay).jacobian(n_r)
    corr = setup.correspondence
    if corr is None:
        return inner
    controls = np.concatenate([np.arange(lay.slices[n].start, lay.slices[n].stop)
                               for n in ("U", "V")])
    return stencils.LiftedJacobian(inner, lambda x: corr.target_values(x[controls]), controls,
                                   lay.size)


class _StencilRows:
    """Rows of a vector of functions stated as stencils (:mod:`rffqm_nlp.design.stencils`), block
    after block: each block takes the next rows (:meth:`_rows`)."""

    FOLDED = ("Yx", "Yy", "Yz")

    def __init__(self, lay: _Layout):
        self.lay = lay
        self.stencils: list[stencils.Stencil] = []
        self._next = 0

    def _rows(self, *shapes) -> list[np.ndarray]:
        """The next rows: one column-major block per shape."""
        blocks = []
        for s in shapes:
            blocks.append(self._next + np.arange(np.prod(s)).reshape(s, order="F"))
            self._next += blocks[-1].size
        return blocks

    def _add(self, name: str, z: list, p: list, expr: list, columns: list, rows: list,
             params: list = ()) -> None:
        """A stencil of the expressions ``expr`` in the symbols z and p, with per-input,
        per-output and per-param index arrays of one shape (:func:`stencils.repeated`)."""
        f = ca.Function(name, [ca.vertcat(*z), ca.vertcat(*p) if p else ca.SX.sym("p", 0)],
                        [ca.vertcat(*expr)])
        self.stencils.append(stencils.repeated(f, columns, rows, list(params)))

    def _whole(self, name: str, inputs: list[ca.SX], expr: ca.SX, columns: np.ndarray
               ) -> None:
        """One instance on the variables ``columns`` (in the order of ``inputs``)."""
        self.stencils.append(stencils.single(name, inputs, expr, columns,
                                             self._rows((expr.numel(),))[0]))


class _ResidualStencils(_StencilRows):
    """The rows of :func:`_objective_residuals` as stencils: the position term at every
    lattice point (its 3 rows), the fundamental forms at every interior lattice point (its
    row in each of the 6 blocks), and the rows on the design alone
    (:func:`_design_residuals`) one instance on the alignment, the boundary vector and a
    free correspondence's controls. With a free correspondence the columns go on past x
    into the target lattice (Tx, Ty, Tz, each column-major over the lattice)."""

    def __init__(self, setup: Setup, lay: _Layout):
        super().__init__(lay)
        self.setup = setup
        N, M = lay.shapes["LV"][0], lay.shapes["LH"][1]
        self.n1, self.m1 = N // 2 + 1, M // 2 + 1
        self.free = setup.correspondence is not None

    def jacobian(self, n_r: int) -> stencils.LocalJacobian:
        weights = self.setup.weights
        if weights.get("forms", 0) > 0:
            self._forms(weights["forms"])
        if weights.get("position", 0) > 0:
            self._position(weights["position"])
        self._design()
        n_t = 3 * self.n1 * self.m1 if self.free else 0
        return stencils.LocalJacobian(self.stencils, [], (n_r, self.lay.size + n_t))

    def _points(self, i: np.ndarray, j: np.ndarray) -> list[np.ndarray]:
        """The columns of the folded lattice points (i, j) (x, y, z), then with a free
        correspondence those of the target lattice points (x, y, z)."""
        mine = [_index(self.lay, n, 2 * i, 2 * j) for n in self.FOLDED]
        if not self.free:
            return mine
        n = self.n1 * self.m1
        return mine + [self.lay.size + c * n + i + self.n1 * j for c in range(3)]

    def _forms(self, weight: float) -> None:
        """(eq:optInverse) at the interior lattice point (a, b): its 3 x 3 neighbourhood's
        forms (:func:`shape.fundamental_forms`) minus the target's, as in
        :func:`loss_residuals`; the target's are constants without a free correspondence."""
        ni, mi = self.n1 - 2, self.m1 - 2
        a, b = (k + 1 for k in _grid(ni, mi))
        offsets = [(di, dj) for dj in (-1, 0, 1) for di in (-1, 0, 1)]  # column-major 3 x 3
        around = [self._points(a + di, b + dj) for di, dj in offsets]
        blocks = [ca.SX.sym(f"r{c}", 3, 3) for c in range(6 if self.free else 3)]
        z = [ca.vec(m) for m in blocks]
        columns = [around[k][c] for c in range(len(blocks)) for k in range(9)]
        mine = shape.fundamental_forms(blocks[:3])
        if self.free:
            theirs, p, params = shape.fundamental_forms(blocks[3:]), [], []
        else:
            p = [ca.SX.sym(f"form{k}") for k in range(6)]
            theirs, params = p, list(shape.fundamental_forms(self.setup.target))
        res = ca.vertcat(*(m - t for m, t in zip(mine, theirs))) / self.setup.spacing ** 2
        self._add("forms", z, p, [np.sqrt(weight / (6 * ni * mi)) * res], columns,
                  self._rows(*[(ni, mi)] * 6), params)

    def _position(self, weight: float) -> None:
        """R r + t minus the target at every lattice point, as in :func:`loss_residuals`
        (rows 3 p + c, p the point's column-major index); the target a constant without a
        free correspondence."""
        i, j = _grid(self.n1, self.m1)
        rigid = _symbols("rigid", 7)
        y = _symbols("y", 3)
        points = self._points(i, j)
        rigid_columns = [np.full(i.shape, self.lay.slices["rigid"].start + k) for k in range(7)]
        if self.free:
            target, p, params = _symbols("t", 3), [], []
            z, columns = y + rigid + target, points[:3] + rigid_columns + points[3:]
        else:
            target = p = _symbols("t", 3)
            z, columns = y + rigid, points + rigid_columns
            params = [self.setup.target[..., c] for c in range(3)]
        moved = ca.mtimes(rotation_from_quaternion(rigid[:4]), ca.vertcat(*y))
        res = (moved + ca.vertcat(*rigid[4:]) - ca.vertcat(*target)) / self.setup.spacing
        self._add("position", z, p, [np.sqrt(weight / i.size) * res], columns,
                  list(self._rows((3, self.n1, self.m1))[0]), params)

    def _design(self) -> None:
        """The rows after the loss: one instance of :func:`_design_residuals`."""
        lay, corr = self.lay, self.setup.correspondence
        rigid = ca.SX.sym("rigid", 7)
        boundary = _boundary_columns(lay)
        bvec = ca.SX.sym("boundary", boundary.size)
        inputs = [rigid, bvec]
        columns = [np.arange(lay.slices["rigid"].start, lay.slices["rigid"].stop), boundary]
        grid = None
        if corr is not None:
            grid = tuple(ca.SX.sym(n, *corr.shape) for n in ("U", "V"))
            inputs += list(grid)
            columns += [np.arange(lay.slices[n].start, lay.slices[n].stop) for n in ("U", "V")]
        self._whole("design_residuals", inputs, _design_residuals(self.setup, rigid, bvec, grid),
                    np.concatenate(columns))


def _boundary_columns(lay: _Layout) -> np.ndarray:
    """Indices in x of the boundary design vector of :func:`simultaneous` (its ``bvec``:
    :meth:`BoundaryData.to_vector`'s order, then omega): the angles alpha and beta of the
    left vertices and then the bottom ones, the left and the bottom sides, omega."""
    N, M = lay.shapes["LV"][0], lay.shapes["LH"][1]
    left, bottom = np.arange(N + 1), np.arange(1, M + 1)
    angles = [np.concatenate([_index(lay, n, left, 0), _index(lay, n, 0, bottom)])
              for n in ("A", "B")]
    return np.concatenate([*angles, _index(lay, "LV", left[:-1], 0),
                           _index(lay, "LH", 0, bottom - 1), [lay.slices["omega"].start]])


def _index(lay: _Layout, name: str, i, j=0) -> np.ndarray:
    """Indices in x of block ``name`` of ``lay`` at (i, j) (broadcast)."""
    return lay.slices[name].start + np.asarray(i) + lay.shapes[name][0] * np.asarray(j)


def _grid(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) of an n x m grid, each (n, m)."""
    return np.meshgrid(np.arange(n), np.arange(m), indexing="ij")


def _symbols(name: str, k: int) -> list[ca.SX]:
    return [ca.SX.sym(f"{name}{c}") for c in range(k)]


class _ConstraintStencils(_StencilRows):
    """The rows of :func:`simultaneous`'s g as stencils (:mod:`rffqm_nlp.design.stencils`): the
    same equations, each on one panel's or vertex's own variables. One method per block of
    rows, called in g's order, each taking the next rows."""

    QUAT = ("Qw", "Qx", "Qy", "Qz")

    def __init__(self, setup: Setup, lay: _Layout, sigma: np.ndarray, tree: _MeanTree):
        super().__init__(lay)
        self.setup, self.sigma, self.tree = setup, sigma, tree
        self.N, self.M = sigma.shape[0] - 1, sigma.shape[1] - 1
        self.kh0, _ = _fold_multipliers_kv(sigma)
        self.constants: list[stencils.Constant] = []

    def jacobian(self, n_g: int) -> stencils.LocalJacobian:
        N, M = self.N, self.M
        march = self._rows((4, N, M))[0]
        self._edge_directions()
        self._multiplier_angles()
        self._rotations()
        self._vertices()
        sides, root = self._partial_means()
        self._cells([*march, *self._rows((N, M))])
        self._boundary_mv()
        self._sides(sides, root)
        if self.setup.correspondence is not None:
            self._grid_rows()
        return stencils.LocalJacobian(self.stencils, self.constants, (n_g, self.lay.size))

    # ------------------------------------------------------------------ helpers
    def _ix(self, name: str, i, j=0) -> np.ndarray:
        return _index(self.lay, name, i, j)

    def _omega(self, shape) -> np.ndarray:
        return np.full(shape, self.lay.slices["omega"].start)

    # ------------------------------------------------------------------ blocks of g
    def _cells(self, rows: list[np.ndarray]) -> None:
        """The panel cell (eq:marchingSector .. eq:getSides): vertex d and the sides of d
        (4 rows per panel), and the margin sign * (mu_abc^2 - 1) (``rows``: 5 blocks)."""
        N, M, S, ix = self.N, self.M, self.sigma, self._ix
        i, j = _grid(N, M)
        z, p = _symbols("z", 12), _symbols("p", 4)
        a00, b00, a10, b10, a01, b01, a11, b11, lv0, lv1, lh0, lh1 = z
        xs, ys = panel_cell()(ca.vertcat(a10, b10, p[0], lv0),
                              ca.vertcat(a00, b00, p[1], a01, b01, p[2], lh0))
        side = vx.panel_side_residuals(a00, PI - b10, b01, lv0, lh0, lv1, lh1)
        self._add("cell", z, p, [a11 - xs[0], b11 - xs[1], *side, p[3] * (ys[1] ** 2 - 1)],
                  [ix("A", i, j), ix("B", i, j), ix("A", i + 1, j), ix("B", i + 1, j),
                   ix("A", i, j + 1), ix("B", i, j + 1), ix("A", i + 1, j + 1),
                   ix("B", i + 1, j + 1), ix("LV", i, j), ix("LV", i, j + 1),
                   ix("LH", i, j), ix("LH", i + 1, j)], rows,
                  [S[1:, :M], S[:N, :M], S[:N, 1:],
                   np.where(self.setup.mu_outside, 1.0, -1.0).reshape(N, M, order="F")])

    def _edge_directions(self) -> None:
        """TH along the left column, then along the rows (linear)."""
        N, M, ix = self.N, self.M, self._ix
        left, rows = self._rows((N,), (N + 1, M))
        z = _symbols("z", 4)
        k = np.arange(N)
        self._add("theta_left", z, [], [z[0] - z[1] - (z[2] - z[3])],
                  [ix("TH", k + 1), ix("TH", k), ix("A", k), ix("B", k + 1)], [left])
        i, j = _grid(N + 1, M)
        self._add("theta", z, [], [z[0] - z[1] - (PI - z[2] - z[3])],
                  [ix("TH", i, j + 1), ix("TH", i, j), ix("A", i, j + 1), ix("B", i, j + 1)],
                  [rows])

    def _multiplier_angles(self) -> None:
        """PHI of the bottom row from its vertex, then the chain up the columns (see
        :func:`_local_crease_quaternions`)."""
        N, M, S, ix = self.N, self.M, self.sigma, self._ix
        bottom, rows = self._rows((M,), (N - 2, M))
        z, p = _symbols("z", 3), _symbols("p", 2)
        num, den = vx.mu2_terms(z[1], z[2], p[0])
        j = np.arange(M)
        self._add("phi_bottom", z, p, [ca.sin(z[0]) * num + p[1] * ca.cos(z[0]) * den],
                  [ix("PHI", 0, j), ix("A", 0, j), ix("B", 0, j)], [bottom],
                  [S[0, :M], S[1, :M] * self.kh0[:M]])
        z, p = _symbols("z", 2), _symbols("p", 1)
        i, j = _grid(N - 2, M)
        self._add("phi", z, p, [z[0] - p[0] * z[1]], [ix("PHI", i + 1, j), ix("PHI", i, j)],
                  [rows], [S[2:N, :M]])

    def _rotations(self) -> None:
        """Panel rotations (eq:defGrads): R times a crease quaternion, along the bottom row,
        then up the columns."""
        N, M, S, ix, Q = self.N, self.M, self.sigma, self._ix, self.QUAT
        bottom, rows = self._rows((M - 1, 4), (N - 1, M, 4))
        z, p = _symbols("z", 12), _symbols("p", 2)
        c, s = ca.cos(z[11] / 2), ca.sin(z[11] / 2)
        num, den = vx.mu2_terms(z[9], z[10], p[0])
        qv = crease_quaternion(z[8] + z[9], -p[1] * den, c, s, sign=-1.0, k_den=num)
        prod = qmul(z[4:8], qv)
        j = np.arange(1, M)
        self._add("rotation_bottom", z, p, [z[k] - prod[k] for k in range(4)],
                  [*(ix(n, 0, j) for n in Q), *(ix(n, 0, j - 1) for n in Q), ix("TH", 0, j),
                   ix("A", 0, j), ix("B", 0, j), self._omega(j.shape)],
                  [bottom[:, k] for k in range(4)], [S[0, 1:M], self.kh0[1:M]])
        z, p = _symbols("z", 13), _symbols("p", 1)
        c, s = ca.cos(z[12] / 2), ca.sin(z[12] / 2)
        num, den = vx.mu2_terms(z[10], z[11], p[0])
        qh = crease_quaternion(z[8], -ca.sin(z[9]) * num, c, s, k_den=ca.cos(z[9]) * den)
        prod = qmul(z[4:8], qh)
        i, j = _grid(N - 1, M)
        self._add("rotation", z, p, [z[k] - prod[k] for k in range(4)],
                  [*(ix(n, i + 1, j) for n in Q), *(ix(n, i, j) for n in Q),
                   ix("TH", i + 1, j), ix("PHI", i, j), ix("A", i + 1, j), ix("B", i + 1, j),
                   self._omega(i.shape)], [rows[..., k] for k in range(4)], [S[1:N, :M]])

    def _vertices(self) -> None:
        """Folded vertices (eq:finalCalc): the previous one plus a rotated edge, along the
        bottom row, then up the columns (the last column's edges turn with the panel on
        their left)."""
        N, M, ix, Q, Y = self.N, self.M, self._ix, self.QUAT, self.FOLDED
        bottom, rows = self._rows((M, 3), (N, M + 1, 3))
        z = _symbols("z", 12)
        edge = rotate_planar(z[6:10], z[10] * ca.cos(z[11]), z[10] * ca.sin(z[11]))
        j = np.arange(M)
        self._add("vertex_bottom", z, [], [z[k] - z[3 + k] - edge[k] for k in range(3)],
                  [*(ix(n, 0, j + 1) for n in Y), *(ix(n, 0, j) for n in Y),
                   *(ix(n, 0, j) for n in Q), ix("LH", 0, j), ix("TH", 0, j)],
                  [bottom[:, k] for k in range(3)])
        z = _symbols("z", 13)
        theta = z[11] + z[12]
        edge = rotate_planar(z[6:10], z[10] * ca.cos(theta), z[10] * ca.sin(theta))
        i, j = _grid(N, M + 1)
        panel = np.minimum(j, M - 1)
        self._add("vertex", z, [], [z[k] - z[3 + k] - edge[k] for k in range(3)],
                  [*(ix(n, i + 1, j) for n in Y), *(ix(n, i, j) for n in Y),
                   *(ix(n, i, panel) for n in Q), ix("LV", i, j), ix("TH", i, j),
                   ix("A", i, j)], [rows[..., k] for k in range(3)])

    def _partial_means(self) -> tuple[np.ndarray, int]:
        """The tree of partial means (:class:`_MeanTree`, linear); returns (the sides'
        indices in x, in the tree's order; the root's index)."""
        N, M = self.N, self.M
        sides = np.concatenate([self._ix("LH", *_grid(N + 1, M)).ravel("F"),
                                self._ix("LV", *_grid(N, M + 1)).ravel("F")])
        below, k = sides, self.lay.slices["P"].start
        levels = self.tree.levels
        for W, r in zip(levels, self._rows(*((W.size1(),) for W in levels))):
            node = np.arange(k, k + W.size1())
            w = W.sparse().tocoo()
            self.constants.append(stencils.Constant(np.concatenate([r, r[w.row]]),
                                                    np.concatenate([node, below[w.col]]),
                                                    np.concatenate([np.ones(r.size),
                                                                    -w.data])))
            below, k = node, k + W.size1()
        return sides, k - 1

    def _boundary_mv(self) -> None:
        """The boundary MV assignment (:meth:`Setup.boundary_mv`), on the boundary
        vertices' angles, left then bottom."""
        nv = self.N + 1 + self.M
        a, b = ca.SX.sym("a", nv), ca.SX.sym("b", nv)
        mv, _, _ = self.setup.boundary_mv(a, b)
        self._whole("mv", [a, b], mv, _boundary_columns(self.lay)[:2 * nv])

    def _sides(self, sides: np.ndarray, root: int) -> None:
        """Every side against min_length times the mean side (linear)."""
        r = self._rows((sides.size,))[0]
        self.constants.append(stencils.Constant(
            np.concatenate([r, r]), np.concatenate([sides, np.full(r.size, root)]),
            np.concatenate([np.ones(r.size), np.full(r.size, -self.setup.min_length)])))

    def _grid_rows(self) -> None:
        """The control rows of a free correspondence (:meth:`Correspondence.rows`)."""
        corr, lay = self.setup.correspondence, self.lay
        U, V = (ca.SX.sym(n, *corr.shape) for n in ("U", "V"))
        g, _, _ = corr.rows(U, V)
        self._whole("grid", [U, V], g, np.concatenate(
            [np.arange(lay.slices[n].start, lay.slices[n].stop) for n in ("U", "V")]))


class _Projection:
    """The simultaneous NLP's :attr:`NLP.project`: x -> the point of x's boundary data,
    omega, alignment and controls, marched and folded, through one buffered CasADi Function
    of x (:func:`marching.marched_function` and the mean tree: the solver's trial points
    are marched without the NumPy model's Python loop over anti-diagonals, and its answer
    is re-marched with that model in the end); the lifted fold multiplier angles and the
    crease quaternions' signs in NumPy.

    None where the march fails a check (:func:`marching.locate_failure`), gives other
    vertex signs than ``sigma``, the NLP's, or the point is not finite (a NaN or inf in
    x's omega, alignment or controls). The boundary data are not validated as
    :class:`BoundaryData` does: the NLP's bounds and rows are stricter (angles within
    [min_angle, pi - min_angle], sides positive, the boundary MV rows with a margin), and
    every caller judges the point by them."""

    def __init__(self, x: ca.MX, v: dict, lay: _Layout, sigma: np.ndarray, tree: _MeanTree,
                 grid_index: np.ndarray):
        N, M = sigma.shape[0] - 1, sigma.shape[1] - 1
        S = ca.DM(sigma)
        A, B, LH, LV = v["A"], v["B"], v["LH"], v["LV"]
        out = marched_function(N, M)(ca.vertcat(A[:, 0].T, B[:, 0].T, S[:, 0].T),
                                     ca.vertcat(A[0, 1:], B[0, 1:], S[0, 1:]),
                                     LV[:, 0].T, LH[0, :], v["omega"])
        lh, lv = out[3], out[4]
        nodes = tree.expression(ca.vertcat(ca.vec(lh), ca.vec(lv)))
        self._marched = Evaluation(ca.Function("project", [x], [*out, nodes]),
                                   [np.zeros(lay.size)])
        self._lay, self._sigma, self._keep = lay, sigma, np.concatenate(
            [np.arange(lay.size)[lay.slices[n]] for n in ("omega", "rigid")] + [grid_index])
        self._kh0, self._sp = _fold_multipliers_kv(sigma)

    def __call__(self, xk: np.ndarray) -> np.ndarray | None:
        self._marched.set(0, xk)
        (alpha, beta, sigma, lh, lv, mu, alpha_d, theta,
         qw, qx, qy, qz, yx, yy, yz, nodes) = self._marched.run()
        if (locate_failure(alpha_d, mu, lh, lv) is not None
                or not np.array_equal(sigma, self._sigma)):
            return None
        N, M = mu.shape
        try:
            mu2 = vx.mu2(alpha, beta, self._sigma)[0, :]
        except InputError:          # a vertex at the pole of its fold multiplier
            return None
        phi = np.arctan((-self._kh0 / mu2 * self._sp)[1:N, :M])
        signs = _crease_quaternion_signs(alpha, beta, self._sigma, phi)
        out = self._lay.pack({"A": alpha, "B": beta, "LH": lh, "LV": lv, "TH": theta,
                              "Qw": qw * signs, "Qx": qx * signs, "Qy": qy * signs,
                              "Qz": qz * signs, "Yx": yx, "Yy": yy, "Yz": yz, "PHI": phi,
                              "P": nodes})
        out[self._keep] = xk[self._keep]
        return out if np.all(np.isfinite(out)) else None
