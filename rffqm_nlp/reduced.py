"""Levenberg-Marquardt on the marching manifold (``SolveOptions(solver="levenberg-marquardt")``).

The simultaneous NLP (:func:`rffqm_nlp.transcription.simultaneous`) states the marching
equations c(x) = 0 as constraints, and IPOPT's iterates meet them only near the optimum.
Here every iterate is a marched design: the variables are the design d (boundary angles and
sides, omega, the rigid alignment) and every other entry of x, the state s, follows from d
by the march (the NumPy model, :attr:`NLP.project`). The loss is then a least-squares
function of d alone, f(d) = 0.5 |r(d, s(d))|^2, and its Gauss-Newton model is exact to
first order: no constraint curvature is dropped.

Derivatives come from the simultaneous NLP's sparse Jacobians. The marching equations are
explicit (each computes one new quantity from earlier ones), so their Jacobian in s is
triangular after a permutation, found once from its sparsity (a matching of equations to
unknowns and a topological order), and the state's sensitivity S = -C_s^{-1} C_d costs a
sparse triangular solve per design variable. The reduced residuals have the Jacobian
J_d + J_s S, the inequalities (sector angles, multiplier margins, boundary MV assignment,
sides against the mean side, bounds) the rows G_d + G_s S.

Each iteration solves the damped, linearised problem

    min_dd 0.5 |r + J dd|^2 + 0.5 lam dd' M dd   s.t. the inequalities, linearised,

as a small dense QP (DAQP; only the rows the unconstrained step would break, and their
neighbours in slack, enter it), re-marches d + dd and accepts it if the loss falls and every
constraint holds; a step that breaks a constraint is corrected (the rows shifted by their
linearisation error, up to :data:`CORRECTIONS` times) before lam grows. lam follows
Nielsen's rule (Madsen, Nielsen & Tingleff, "Methods for non-linear least squares
problems", 2004, s.3.2). The metric M counts the change of the crease pattern: D_d plus
S_p' D_p S_p over the sector angles and sides p of every vertex, with D the weights of
:func:`rffqm_nlp.transcription.damping_weights` (a radian, or a lattice spacing, per
lattice point); this metric took fewer iterations than the whole state or a diagonal
(docs/solvers.md).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from graphlib import TopologicalSorter
from typing import Callable

import casadi as ca
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import maximum_bipartite_matching
from scipy.sparse.linalg import splu

from .errors import InputError
from .transcription import NLP

#: constraint violation up to which a marched design counts as admissible
FEASIBLE = 1e-9
#: corrections of a step that breaks a constraint before the damping grows
CORRECTIONS = 3
#: damping above which no step is found: the run stops with status "Stalled"
MAX_DAMPING = 1e10
#: an accepted step that lowers the loss by less than this fraction ends the run
#: ("Stalled"): from there, IPOPT's Newton steps converge faster
MIN_DECREASE = 1e-4
#: rows of S per block of the metric's product
ROWS = 65536
#: QPs per step, each over more rows, before the step counts as failed
QP_ROUNDS = 10
#: design columns per triangular solve (SuperLU solves a few right-hand sides at a time
#: fastest, docs/solvers.md)
BLOCK = 16


@dataclass
class Outcome:
    """Where a run ended: ``x`` (a marched design, admissible), its loss, the number of
    accepted steps and the status: "Fit_Reached" (``stop`` held), "Stalled" (no step
    lowers the loss enough), "Maximum_Iterations_Exceeded", "Maximum_WallTime_Exceeded",
    or "Inadmissible_Start" (the start, re-marched, breaks a constraint or does not march:
    no step was taken, ``x`` is the start as given and ``objective`` None)."""

    x: np.ndarray
    objective: float | None
    iterations: int
    status: str


@dataclass
class _Point:
    """A marched design and the linearisation of the reduced problem there."""

    x: np.ndarray
    r: np.ndarray
    g: np.ndarray
    J: sp.csc_matrix
    G: sp.csr_matrix

    @property
    def objective(self) -> float:
        return 0.5 * float(self.r @ self.r)


class Manifold:
    """The simultaneous NLP split into its design and its marched state.

    Built once per NLP: the index sets, the triangular order of the marching equations and
    the CasADi Function of the residuals, the constraints and their Jacobians.
    """

    def __init__(self, nlp: NLP):
        if nlp.project is None or nlp.design_index is None:
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
        self._functions = ca.Function(
            "linearization", [nlp.x],
            [nlp.residuals, ca.jacobian(nlp.residuals, nlp.x), nlp.g, ca.jacobian(nlp.g, nlp.x)])
        where = np.full(n, -1)
        where[self.state] = np.arange(self.state.size)
        pattern = np.zeros(n, dtype=bool)
        pattern[nlp.pattern_index] = True
        self.pattern = where[np.flatnonzero(pattern & ~design & ~fixed)]
        weights = nlp.damping_weights
        self.design_weights = weights[self.design]
        self.pattern_weights = weights[self.state][self.pattern]
        bounded = (np.isfinite(nlp.lbx) | np.isfinite(nlp.ubx)) & ~fixed
        self.bounded_design = np.flatnonzero(bounded[self.design])
        self.bounded_state = np.flatnonzero(bounded[self.state])
        self.lower = self.inequalities(nlp.lbg, nlp.lbx)
        self.upper = self.inequalities(nlp.ubg, nlp.ubx)
        self._order: tuple[np.ndarray, np.ndarray] | None = None

    # ---------------------------------------------------------------- linearisation
    def point(self, x: np.ndarray) -> _Point | None:
        """The NLP's functions at a marched x; None where they are not finite."""
        r, J, g, G = self._functions(x)
        r, g = r.full().ravel(), g.full().ravel()
        if not (np.all(np.isfinite(r)) and np.all(np.isfinite(g))):
            return None
        return _Point(x=x, r=r, g=g, J=J.sparse().tocsc(), G=G.sparse().tocsr())

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

    def _triangular_order(self, C: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
        """(rows, columns) of C (marching equations x state) in an order that makes it
        lower triangular: each equation matched to the unknown it computes, equations
        sorted so that every one comes after those whose unknowns it uses."""
        match = maximum_bipartite_matching(C, perm_type="column")
        if np.any(match < 0):
            raise RuntimeError("the marching equations are structurally singular in the state")
        P = C[:, match].tocsr()  # the unknown of equation i in column i
        deps = {i: set(P.indices[P.indptr[i]:P.indptr[i + 1]].tolist()) - {i}
                for i in range(P.shape[0])}
        rows = np.fromiter(TopologicalSorter(deps).static_order(), dtype=int,
                           count=P.shape[0])
        return rows, match[rows]

    def sensitivity(self, p: _Point) -> np.ndarray | None:
        """S = ds/dd (state x design, dense) at p, from C_s S = -C_d; None where C_s is
        singular (a marching equation that no longer determines its unknown)."""
        G = p.G[self.eq]
        Cs, Cd = G[:, self.state].tocsr(), G[:, self.design].tocsr()
        if self._order is None:
            self._order = self._triangular_order(Cs)
        rows, cols = self._order
        try:
            lu = splu(Cs[rows][:, cols].tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0)
        except RuntimeError:  # SuperLU: "Factor is exactly singular"
            return None
        Cd = Cd[rows].tocsc()
        S = np.empty((self.state.size, self.design.size))
        for k in range(0, self.design.size, BLOCK):
            S[cols, k:k + BLOCK] = -lu.solve(Cd[:, k:k + BLOCK].toarray())
        return S if np.all(np.isfinite(S)) else None


@dataclass
class _Model:
    """The damped Gauss-Newton model of the reduced problem at a point, and its
    inequalities: rows = g's inequality rows, then the bounded design, then the bounded
    state variables, each with its current value and bounds."""

    H: np.ndarray
    M: np.ndarray
    grad: np.ndarray
    S: np.ndarray
    G_design: sp.csr_matrix
    G_state: sp.csr_matrix
    lower: np.ndarray  # bounds minus current values: lower <= A dd <= upper
    upper: np.ndarray


def _model(man: Manifold, p: _Point) -> _Model | None:
    S = man.sensitivity(p)
    if S is None:
        return None
    J = p.J
    Jr = J[:, man.design].toarray() + J[:, man.state] @ S
    M = np.diag(man.design_weights)
    for k in range(0, man.pattern.size, ROWS):  # S_p' D_p S_p without a copy of S_p
        Sp = S[man.pattern[k:k + ROWS]] * np.sqrt(man.pattern_weights[k:k + ROWS])[:, None]
        M += Sp.T @ Sp
    Gin = p.G[man.ineq]
    now = man.inequalities(p.g, p.x)
    return _Model(H=Jr.T @ Jr, M=M, grad=Jr.T @ p.r,
                  S=S, G_design=Gin[:, man.design].tocsr(), G_state=Gin[:, man.state].tocsr(),
                  lower=man.lower - now, upper=man.upper - now)


class _Steps:
    """The constrained step of a model: the unconstrained damped Gauss-Newton step, then,
    while it breaks linearised inequalities, a QP over those rows (and the rows whose
    slack is within twice their change) until it breaks none."""

    def __init__(self, man: Manifold):
        self.man = man
        self._qps: dict[int, ca.Function] = {}

    def change(self, m: _Model, dd: np.ndarray) -> np.ndarray:
        """A dd for every inequality row."""
        ds = m.S @ dd
        return np.concatenate([m.G_design @ dd + m.G_state @ ds,
                               dd[self.man.bounded_design], ds[self.man.bounded_state]])

    def rows(self, m: _Model, which: np.ndarray) -> np.ndarray:
        """The dense rows ``which`` of A."""
        man = self.man
        ng, nbd = man.ineq.size, man.bounded_design.size
        A = np.zeros((which.size, man.design.size))
        g_rows = which < ng
        gi = which[g_rows]
        A[g_rows] = m.G_design[gi].toarray() + m.G_state[gi] @ m.S
        d_rows = (which >= ng) & (which < ng + nbd)
        A[np.flatnonzero(d_rows), man.bounded_design[which[d_rows] - ng]] = 1.0
        s_rows = which >= ng + nbd
        A[s_rows] = m.S[man.bounded_state[which[s_rows] - ng - nbd]]
        return A

    def __call__(self, m: _Model, lam: float, shift: np.ndarray) -> np.ndarray | None:
        H = m.H + lam * m.M
        dd = np.linalg.solve(H, -m.grad)
        lower, upper = m.lower + shift, m.upper - shift
        work = shift > 0
        solved = np.zeros(shift.size, dtype=bool)  # rows of the last QP: hold to its tolerance
        for _ in range(QP_ROUNDS):
            Ad = self.change(m, dd)
            broken = ((Ad < lower) | (Ad > upper)) & ~solved
            if not broken.any():
                return dd
            work |= broken | (lower > -2 * np.abs(Ad)) | (upper < 2 * np.abs(Ad))
            which = np.flatnonzero(work)
            qp = self._qp(which.size)
            sol = qp(h=H, g=m.grad, a=self.rows(m, which), lba=np.maximum(lower[which], -1e20),
                     uba=np.minimum(upper[which], 1e20))
            if not qp.stats()["success"]:
                return None
            dd, solved = sol["x"].full().ravel(), work.copy()
        return None

    def _qp(self, rows: int) -> ca.Function:
        if rows not in self._qps:
            n = self.man.design.size
            self._qps[rows] = ca.conic("step", "daqp", {"h": ca.Sparsity.dense(n, n),
                                                        "a": ca.Sparsity.dense(rows, n)},
                                       {"error_on_fail": False,
                                        "daqp": {"primal_tol": 0.1 * FEASIBLE}})
        return self._qps[rows]


def levenberg_marquardt(nlp: NLP, x: np.ndarray, damping: float, max_iter: int,
                        deadline: float | None = None,
                        stop: Callable[[np.ndarray], bool] | None = None,
                        callback: Callable[[float, float], None] | None = None) -> Outcome:
    """Minimise the simultaneous NLP's loss over marched designs, from x (re-marched first).

    ``damping``: the first lam; ``deadline``: a ``time.perf_counter()`` after which the run
    stops; ``stop(x)``: end once it holds at an accepted iterate; ``callback(objective,
    violation)`` at the start and after every accepted step.
    """
    man = Manifold(nlp)
    start = nlp.project(np.asarray(x, dtype=float))
    p = None if start is None else man.point(start)
    if p is None or man.violation(p) > FEASIBLE:
        return Outcome(x=np.asarray(x, dtype=float), objective=None, iterations=0,
                       status="Inadmissible_Start")
    if callback is not None:
        callback(p.objective, man.violation(p))
    steps = _Steps(man)
    lam, nu, it = float(damping), 2.0, 0
    status = "Maximum_Iterations_Exceeded"
    while it < max_iter:
        if deadline is not None and time.perf_counter() > deadline:
            status = "Maximum_WallTime_Exceeded"
            break
        m = _model(man, p)
        if m is None:
            status = "Stalled"
            break
        shift = np.zeros(m.lower.size)
        corrections = 0
        while lam <= MAX_DAMPING:
            trial, dd = None, steps(m, lam, shift)
            if dd is not None:
                predicted = -(m.grad @ dd + 0.5 * dd @ m.H @ dd)
                xt = p.x.copy()
                xt[man.design] += dd
                xt = nlp.project(xt)
                trial = None if xt is None or predicted <= 0 else man.point(xt)
            if trial is not None and trial.objective < p.objective:
                violation = man.violation(trial)
                if violation <= FEASIBLE:
                    break
                if corrections < CORRECTIONS:
                    shift += _linearization_error(man, m, steps, dd, p, trial)
                    corrections += 1
                    continue
            lam, nu = lam * nu, 2 * nu
            shift[:], corrections = 0.0, 0
        else:
            status = "Stalled"
            break
        del m  # its sensitivities (GBs for large patterns) before the next model's
        rho = (p.objective - trial.objective) / predicted
        lam, nu = lam * max(1 / 3, 1 - (2 * rho - 1) ** 3), 2.0
        decrease = (p.objective - trial.objective) / p.objective
        p, it = trial, it + 1
        if callback is not None:
            callback(p.objective, violation)
        if stop is not None and stop(p.x):
            status = "Fit_Reached"
            break
        if decrease < MIN_DECREASE:
            status = "Stalled"
            break
    return Outcome(x=p.x, objective=p.objective, iterations=it, status=status)


def _linearization_error(man: Manifold, m: _Model, steps: _Steps, dd: np.ndarray,
                         p: _Point, trial: _Point) -> np.ndarray:
    """Per inequality row broken at ``trial``: how far its linearised change A dd
    overestimated the slack gained (the second-order correction), plus a margin."""
    value = man.inequalities(trial.g, trial.x)
    actual = value - man.inequalities(p.g, p.x)
    broken = (value < man.lower - FEASIBLE) | (value > man.upper + FEASIBLE)
    error = np.abs(steps.change(m, dd) - actual) + 10 * FEASIBLE
    return np.where(broken, error, 0.0)
