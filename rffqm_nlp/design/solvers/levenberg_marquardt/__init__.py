"""Levenberg-Marquardt on the marching manifold (``solver="levenberg-marquardt"``).

The simultaneous NLP (:func:`rffqm_nlp.design.transcription.simultaneous`) states the
marching equations c(x) = 0 as constraints, and IPOPT's iterates meet them only near the
optimum. Here every iterate is a marched design: the variables are the design d (boundary
angles and sides, omega, the rigid alignment) and every other entry of x, the state s,
follows from d by the march (:attr:`rffqm_nlp.design.transcription.NLP.project`, the CasADi
graph; the answer is re-marched with the NumPy model). The loss is then a least-squares
function of d alone, f(d) = 0.5 |r(d, s(d))|^2, and its Gauss-Newton model is exact to
first order: no constraint curvature is dropped.

Derivatives come from the simultaneous NLP's sparse Jacobians, evaluated once per accepted
point into preallocated buffers (trial points evaluate only r and g). The marching
equations are explicit (each computes one new quantity from earlier ones), so their
Jacobian in s is triangular after a permutation, found once from its sparsity (a matching
of equations to unknowns, then the longest chain of dependencies of each equation, its
level), and the state is ordered by level. The state's sensitivity S = -C_s^{-1} C_d
(n_s x n_d) then follows level by level: the unknowns of a level depend only on those of
earlier levels. One pass over the levels (:class:`.window.Window`) keeps only the rows of S
that a later level or a residual still needs (a working set that shrinks, relative to the
state, as the pattern grows; a small S, up to :data:`WHOLE_S` entries, it keeps whole) and
reduces them at once into the n_d x n_d matrices the step needs: J' J of the reduced
Jacobian J = J_d + J_s S (plus, with a free correspondence, the controls' F_T H, kept as
its factors), the gradient J' r and the metric below; a row of S at vertex (i, j) is
nonzero only in the boundary data of the vertices (0..i, 0) and (0, 0..j), so its Gram
products are taken over those columns alone. The inequality rows G_d + G_s S that a step
needs come from the sweep backwards through the levels (S' applied to their state parts),
and every row's change under a step from one forward sweep (S dd); where the pass kept S
whole, from products with it (:class:`.sensitivities.Sensitivity`).

The steps can be taken in a coarse basis of the design first, d = B u (n_u < n_d,
:func:`boundary_basis`: each class of boundary data piecewise linear between a few knots),
whose pass costs (n_u / n_d)^2 of the whole design's in its Gram matrices; where that run
ends optimal in the basis or stalls, or its loss stops falling (by less than
:data:`BASIS_STALL` of itself over the last :data:`BASIS_STALL_STEPS` steps), it goes on in
the whole design (:func:`levenberg_marquardt`).

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
last :data:`SECANT_PAIRS` accepted steps, rebuilt from zero at every iteration; in the tail
of a run (the step's QP with the same active rows over the last :data:`TAIL_STEPS`
iterations, lam below :data:`TAIL_DAMPING`) J' J + B is instead J' J updated by BFGS over
the last :data:`TAIL_PAIRS` steps toward the same structured secant conditions (positive
definite; it holds the several directions the tail's steps turn between). A step uses
it when it predicted the last step's reduction better than J' J alone did (NL2SOL's
choice), and when J' J + B + lam M is positive definite. Where the residuals do not vanish
at the optimum Gauss-Newton converges only linearly; B speeds up the end.

A start that marches but breaks a constraint (a Miura start whose sides break the minimum
length, a warm start carried from a coarser design that no move toward the reference
repairs, :func:`admissible_toward`, or a clearance round's last design with its new rows,
:mod:`rffqm_nlp.design.clearance`) is restored first: the steps are the same, whose QP then
asks the broken rows' linearisation to reach their bounds, but a trial is judged by its
largest violation alone, the loss free to rise. It is taken where it holds every constraint
(after up to :data:`CORRECTIONS` corrections, as above) or, failing that, where it (the best
such trial) brought the violation down by at least :data:`RESTORED` of what the QP asked;
lam then falls by 3, and after a trial not taken it grows by Nielsen's factor and the QP
asks the broken rows for half of their remaining way only (:func:`.steps.partial_target`:
where the QP forces the rows, a larger lam hardly shortens the step). Restoration steps give the
secant term no pair (their multipliers force the rows), and no optimality test is made
before a point holds every constraint; from there the run goes on as from an admissible
start, its optimality error scaled by the gradient there. Where no such point is reached
(lam above :data:`MAX_DAMPING`, ``max_iter``, the deadline) the run ends
"Inadmissible_Start" with the start as given and the restoration steps counted.

The run stops with status "Solve_Succeeded" when the first-order optimality conditions of
the reduced problem hold at a marched iterate (:func:`.steps.kkt_error`): the gradient J' r
less the linearised active inequalities' multipliers (of the right sign, zero where the
inequality is not active: the step's QP's, or their least-squares fit to the gradient where
it does better) is at most ``tol`` in the max norm, relative to max(1, |J' r at the start|
/ 100) as IPOPT's gradient-based scaling of the objective.

The modules, from the bottom up:

* :mod:`.levels`: the marching equations in levels, and the sweeps that apply S and S';
* :mod:`.gram`: the Gram matrices of one pass, in bands of columns;
* :mod:`.window`: the pass over the levels that gives J' J, J' r and the metric;
* :mod:`.sensitivities`: S at a point, and the point's derivatives (the linearization);
* :mod:`.manifold`: :class:`Manifold` (the NLP split into design and marched state, its
  points, their derivatives), :func:`boundary_basis`, BLAS's threads;
* :mod:`.steps`: the model, the constrained step and its QP, the optimality error;
* :mod:`.secant`: the structured secant term B and the last step's record;
* :mod:`.loop`: :func:`levenberg_marquardt`, :func:`admissible_toward`, :class:`MarchedOutcome`.

The constants below are re-exported to be read; each is used where it is defined, so a
change to one is made in its own module.
"""

from .gram import BANDS
from .interface import solve
from .loop import (BASIS_STALL, BASIS_STALL_STEPS, CORRECTIONS, DOMAIN_DAMPING, MAX_DAMPING,
                   METRIC_DAMPING, RESTORED, SUCCESS, TOWARD_REFERENCE, MarchedOutcome,
                   admissible_toward, levenberg_marquardt)
from .manifold import FEASIBLE, Manifold, boundary_basis
from .secant import SECANT_PAIRS, TAIL_DAMPING, TAIL_PAIRS, TAIL_STEPS
from .window import CHUNK_ROWS, WHOLE_S

__all__ = ["BANDS", "BASIS_STALL", "BASIS_STALL_STEPS", "CHUNK_ROWS", "CORRECTIONS",
           "DOMAIN_DAMPING", "FEASIBLE", "MAX_DAMPING", "METRIC_DAMPING", "RESTORED",
           "SECANT_PAIRS", "SUCCESS", "TAIL_DAMPING", "TAIL_PAIRS", "TAIL_STEPS",
           "TOWARD_REFERENCE", "WHOLE_S", "Manifold",
           "MarchedOutcome", "admissible_toward", "boundary_basis", "levenberg_marquardt",
           "solve"]
