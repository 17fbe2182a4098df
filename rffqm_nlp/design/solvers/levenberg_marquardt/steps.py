"""The steps of Levenberg-Marquardt on the marching manifold: the Gauss-Newton model of the
reduced problem at a point (:class:`Model`), the constrained damped step (:class:`Steps`:
the unconstrained step, then a small dense QP over the linearised inequality rows it
breaks), the first-order optimality error (:func:`kkt_error`), and the shifts of the rows
that correct a step (:func:`linearization_error`) or ask a restoration step for part of
the way (:func:`partial_target`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import casadi as ca
import numpy as np
import scipy.linalg as la
import scipy.sparse as sp
from scipy.optimize import nnls

from .levels import positions
from .manifold import FEASIBLE, Manifold, Point
from .sensitivities import Linearization

#: entries (rows x state) of a block of rows swept back at once (:meth:`Steps.rows`)
BLOCK = 1 << 24
#: QPs per step, each over more rows, before the step counts as failed
QP_ROUNDS = 10


@dataclass
class Model:
    """The Gauss-Newton model of the reduced problem at a point, in the basis' coordinates
    u: JtJ = Jr' Jr (Jr the reduced Jacobian, n_r x n_u, never formed), H = JtJ + B, the
    metric M (n_u, n_u), the gradient Jr' r (n_u,), and its inequalities: rows = g's
    inequality rows, then the bounded design, then the bounded state variables, each with
    its bounds minus its current value; ``known``: the rows of A (n_u,) by index swept back
    so far (:meth:`Steps.rows`)."""

    JtJ: np.ndarray
    H: np.ndarray
    M: np.ndarray
    grad: np.ndarray
    lin: Linearization
    lower: np.ndarray  # bounds minus current values: lower <= A dd <= upper
    upper: np.ndarray
    known: dict[int, np.ndarray] = field(default_factory=dict)


def model(man: Manifold, p: Point, lin: Linearization,
          M: np.ndarray | None = None) -> Model:
    """The model at p; its metric from ``lin``, or ``M`` (n_u, n_u) where ``lin`` has
    none (linearised without it)."""
    if lin.pattern_metric is not None:
        M = lin.pattern_metric + man.design_metric.toarray()
    if M is None:
        raise ValueError("a linearisation without the metric needs the metric to keep")
    now = man.inequalities(p.g, p.x)
    return Model(JtJ=lin.JtJ, H=lin.JtJ, M=M, grad=lin.grad, lin=lin,
                 lower=man.lower - now, upper=man.upper - now)


@dataclass
class Step:
    """A step dd (n_d,) and the multipliers of the QP's rows ``which`` (CasADi's sign:
    negative at a lower bound); both empty when no row entered a QP."""

    dd: np.ndarray
    which: np.ndarray
    multipliers: np.ndarray


class Steps:
    """The constrained step of a model: the unconstrained damped step, then, while it
    breaks linearised inequalities, a QP over those rows (and the rows whose slack is within
    twice their change) until it breaks none."""

    def __init__(self, man: Manifold):
        self.man = man
        self._qps: dict[int, ca.Function] = {}

    def change(self, m: Model, du: np.ndarray) -> np.ndarray:
        """A du for every inequality row (du (n_u,), in the basis' coordinates)."""
        ds = m.lin.state_change(du)
        return np.concatenate([m.lin.G_design @ du + m.lin.G_state @ ds,
                               (self.man.basis @ du)[self.man.bounded_design],
                               ds[self.man.bounded_read]])

    def rows(self, m: Model, which: np.ndarray) -> np.ndarray:
        """The dense rows ``which`` of A (which.size, n_u), each swept back once per model
        (the QP rounds, the optimality test and the secant update ask for the same rows)."""
        new = np.array([i for i in which.tolist() if i not in m.known], dtype=np.int64)
        if new.size:
            m.known.update(zip(new.tolist(), self.swept(m, new)))
        return np.array([m.known[i] for i in which.tolist()]).reshape(which.size,
                                                                      self.man.basis.shape[1])

    def swept(self, m: Model, which: np.ndarray) -> np.ndarray:
        """The dense rows ``which`` of A (which.size, n_u): a state row's part by the
        adjoint sweep, a block of rows at a time (:data:`BLOCK`)."""
        man, lin = self.man, m.lin
        ng, nbd = man.ineq.size, man.bounded_design.size
        A = np.zeros((which.size, man.basis.shape[1]))
        g_rows = np.flatnonzero(which < ng)
        d_rows = np.flatnonzero((which >= ng) & (which < ng + nbd))
        for into, matrix, rows in ((g_rows, lin.G_design, which[g_rows]),
                                   (d_rows, man.basis, man.bounded_design[which[d_rows] - ng])):
            at, counts = positions(matrix, rows)  # the rows' nonzeros: no sparse slicing
            np.add.at(A, (np.repeat(into, counts), matrix.indices[at]), matrix.data[at])
        s_rows = np.flatnonzero(which >= ng + nbd)
        at, counts = positions(lin.G_state, which[g_rows])
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

    def __call__(self, m: Model, lam: float, shift: np.ndarray) -> Step | None:
        try:
            factor = la.cho_factor(m.H + lam * m.M, lower=False)
        except la.LinAlgError:  # B made the damped model indefinite
            return None
        dd = la.cho_solve(factor, -m.grad)
        lower, upper = m.lower + shift, m.upper - shift
        work = shift > 0
        none = np.zeros(0, dtype=np.int64)
        step = Step(dd=dd, which=none, multipliers=np.zeros(0))
        solved = np.zeros(shift.size, dtype=bool)  # rows of the last QP: hold to its tolerance
        for _ in range(QP_ROUNDS):
            Ad = self.change(m, step.dd)
            broken = ((Ad < lower) | (Ad > upper)) & ~solved
            if not broken.any():
                return step
            work |= broken | (lower > -2 * np.abs(Ad)) | (upper < 2 * np.abs(Ad))
            which = np.flatnonzero(work)
            step = self.qp(factor[0], m.grad, which, self.rows(m, which),
                           np.maximum(lower[which], -1e20), np.minimum(upper[which], 1e20))
            if step is None:
                return None
            solved = work.copy()
        return None

    def qp(self, R: np.ndarray, grad: np.ndarray, which: np.ndarray, A: np.ndarray,
           lba: np.ndarray, uba: np.ndarray) -> Step | None:
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
        solver = self._qps[which.size]
        sol = solver(h=ca.DM.eye(n), g=la.solve_triangular(R, grad, trans="T"),
                     a=la.solve_triangular(R, A.T, trans="T").T, lba=lba, uba=uba)
        if not solver.stats()["success"]:
            return None
        return Step(dd=la.solve_triangular(R, sol["x"].full().ravel()), which=which,
                    multipliers=sol["lam_a"].full().ravel())


def kkt_error(m: Model, steps: Steps, step: Step) -> float:
    """The first-order optimality error of the reduced problem at the model's point: max of
    |grad + A_W' y| (stationarity) and of |y_i| times row i's distance to the bound it
    holds (complementarity), A_W the rows active in the step's QP, with the better of two
    multiplier estimates y of the right signs: the QP's own, and the least-squares ones
    of :func:`least_squares_multipliers` (the QP's lag by the damped step: grad + A_W' y
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

    return min(error(y), error(least_squares_multipliers(A, m.grad, np.sign(y))))


def least_squares_multipliers(A: np.ndarray, grad: np.ndarray, sign: np.ndarray
                              ) -> np.ndarray:
    """The multipliers y (k,) of the rows A (k, n) with the signs ``sign`` (k,; CasADi's:
    negative at a lower bound) that minimise |grad + A' y| (non-negative least squares in
    sign * y)."""
    z, _ = nnls(A.T * sign, -grad)
    return sign * z


def partial_target(m: Model, reach: float) -> np.ndarray:
    """The shift of the step's inequality rows (n_rows,) that asks each row broken at the
    model's point for only ``reach`` of its way back to its bound (:meth:`Steps.__call__`
    holds lower + shift <= A dd <= upper - shift); zero on the rows that hold."""
    gap = np.maximum(m.lower, 0.0) + np.maximum(-m.upper, 0.0)
    return -(1.0 - reach) * gap


def linearization_error(man: Manifold, m: Model, steps: Steps, dd: np.ndarray,
                        p: Point, trial: Point) -> np.ndarray:
    """Per inequality row broken at ``trial``: how far its linearised change A dd
    overestimated the slack gained (the second-order correction), plus a margin."""
    value = man.inequalities(trial.g, trial.x)
    actual = value - man.inequalities(p.g, p.x)
    broken = (value < man.lower - FEASIBLE) | (value > man.upper + FEASIBLE)
    error = np.abs(steps.change(m, dd) - actual) + 10 * FEASIBLE
    return np.where(broken, error, 0.0)
