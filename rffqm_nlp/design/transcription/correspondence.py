"""A free correspondence between the coarse lattice and the target (docs/meshes.md): the
lattice points' surface parameters are a tensor-product B-spline of the lattice indices
whose controls are design variables (:class:`Correspondence`)."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np
from scipy.interpolate import BSpline


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


def clamped_basis(n: int, k: int) -> tuple[np.ndarray, np.ndarray]:
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
    (:func:`clamped_basis`), so the grid is U = Bu Cu Bv', V = Bu Cv Bv' for the controls
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
        (Bu, gu), (Bv, gv) = (clamped_basis(n, min(k, n)) for n in lattice)
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
        """D of :func:`.inputs.damping_weights` for the controls vector: 1 / (step^2 n), n the
        number of controls (a change of one uniform step weighs like one lattice spacing
        of a length)."""
        du, dv = self.steps
        n = self.size // 2
        return np.concatenate([np.full(n, 1 / (du ** 2 * n)), np.full(n, 1 / (dv ** 2 * n))])


def with_grid_rows(corr: Correspondence, grid: tuple[ca.MX, ca.MX], g: ca.MX,
                   lbg: np.ndarray, ubg: np.ndarray) -> tuple[ca.MX, np.ndarray, np.ndarray]:
    """(g, lbg, ubg) with the grid rows of :meth:`Correspondence.rows` appended."""
    rows, lo, hi = corr.rows(*grid)
    return ca.vertcat(g, rows), np.concatenate([lbg, lo]), np.concatenate([ubg, hi])
