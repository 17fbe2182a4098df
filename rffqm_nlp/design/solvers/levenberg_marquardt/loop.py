"""The loop of Levenberg-Marquardt on the marching manifold: :func:`levenberg_marquardt`
(a start moved toward the reference where it is not admissible, :func:`admissible_toward`;
the coarse basis first, then the whole design), the iterations of one run in one basis
(:func:`run`: restoration, then admissible steps with Nielsen's damping), and where a run
ends (:class:`MarchedOutcome`)."""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
import scipy.linalg as la

from ...transcription import NLP
from . import secant
from .manifold import FEASIBLE, Manifold
from .steps import Steps, kkt_error, linearization_error, model, partial_target

#: corrections of a step that breaks a constraint before the damping grows
CORRECTIONS = 3
#: factor of lam after a step that leaves the march's domain (a side or sector angle of
#: the re-marched pattern out of its range): unlike a step whose loss rises, it says
#: nothing of the model's quality, so Nielsen's growing factor is not applied; the first
#: step from a large Miura start leaves it for several lam (docs/decisions/scaling.md)
DOMAIN_DAMPING = 2.0
#: damping above which no step is found: the run stops with status "Stalled"
MAX_DAMPING = 1e10
#: damping below which a linearisation keeps the last metric M instead of computing it
#: (docs/decisions/levenberg-marquardt.md: the same iterations, within one or two, on the
#: bundled targets)
METRIC_DAMPING = 1e-3
#: the fractions of the way from an inadmissible start's boundary data to the reference's
#: tried in turn (:func:`admissible_toward`)
TOWARD_REFERENCE = (0.1, 0.25, 0.5, 1.0)
#: a restoration step that still breaks a constraint is taken where it brings the largest
#: violation down by at least this fraction of the part its QP asked for
RESTORED = 0.5
#: statuses of a run that ended where it should
SUCCESS = ("Solve_Succeeded", "Fit_Reached")
#: a run in a coarse basis ends, and goes on in the whole design, once its loss fell by less
#: than this fraction of itself over the last :data:`BASIS_STALL_STEPS` accepted steps: the
#: plateau before its optimality in the basis (the whole design's first step from there gains
#: 3-5% at 100 x 100); 1e-2 left earlier but took more of the whole design's dearer steps
#: (docs/decisions/levenberg-marquardt.md, 2026-12-07: "Leaving the coarse basis once its loss
#: stops falling"); 0: the basis runs to ``tol``
BASIS_STALL = 1e-3
#: the accepted steps over which :data:`BASIS_STALL` measures the fall of the loss (one
#: step's fall varies ten-fold from the next)
BASIS_STALL_STEPS = 3


@dataclass
class MarchedOutcome:
    """Where a run ended: ``x`` (a marched design, admissible), its loss, the number of
    accepted steps, the status and the optimality error (:func:`.steps.kkt_error`, scaled) at
    the last point tested (None when none was). Statuses: "Solve_Succeeded" (first-order
    optimal to ``tol``), "Fit_Reached" (``stop`` held), "Stalled" (no step lowers the
    loss), "Basis_Stalled" (the loss fell by less than :data:`BASIS_STALL` over the last
    steps, only in a coarse basis, which :func:`levenberg_marquardt` then refines),
    "Maximum_Iterations_Exceeded", "Maximum_WallTime_Exceeded", or
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


def levenberg_marquardt(nlp: NLP, x: np.ndarray, damping: float, max_iter: int,
                        deadline: float | None = None,
                        stop: Callable[[np.ndarray], bool] | None = None,
                        callback: Callable[[float, float], None] | None = None,
                        tol: float = 1e-6, manifold: Manifold | None = None,
                        reference: Callable[[], np.ndarray] | None = None) -> MarchedOutcome:
    """Minimise the simultaneous NLP's loss over marched designs, from x (re-marched first),
    to first-order optimality (status "Solve_Succeeded", see the package docstring).

    ``damping``: the first lam; ``deadline``: a ``time.perf_counter()`` after which the run
    stops; ``stop(x)``: end once it holds at an accepted iterate; ``callback(objective,
    violation)`` at the start and after every accepted step; ``tol``: of the optimality
    error; ``manifold``: ``Manifold(nlp)`` built beforehand (it holds the derivatives' build);
    ``reference``: gives an admissible point (n,), called only where x is not admissible:
    the run then starts from x's boundary data moved toward the reference's
    (:func:`admissible_toward`, ``MarchedOutcome.moved``) where a fraction of
    :data:`TOWARD_REFERENCE` is admissible. Otherwise a start that marches but breaks a
    constraint is restored (package docstring, ``MarchedOutcome.restored``); the run ends
    "Inadmissible_Start" where x does not march or the restoration fails.

    With a coarse basis (:attr:`.manifold.Manifold.coarse`) the steps are taken in it first; where
    that run ends optimal in it, stalls, or its loss stops falling (:data:`BASIS_STALL`:
    status "Basis_Stalled", never returned), the manifold is refined and the run goes on in
    the whole design from there, its optimality error scaled as the first run's, so
    "Solve_Succeeded" always means the whole design's optimality conditions; where its
    restoration failed, the run restores the start again in the whole design.
    """
    man = Manifold(nlp) if manifold is None else manifold
    x, moved = np.asarray(x, dtype=float), None
    with man.blas_threads():
        if reference is not None and man.admissible(x) is None:
            moved = admissible_toward(man, x, reference())
        out = run(man, x if moved is None else moved[0], damping, max_iter, deadline, stop,
                  callback, tol)
        if moved is not None:
            out = replace(out, moved=moved[1])
    if not man.coarse or out.status not in ("Solve_Succeeded", "Stalled", "Basis_Stalled",
                                            "Inadmissible_Start"):
        return out
    if out.status == "Inadmissible_Start" and man.marched(out.x) is None:
        return out  # a start that does not march: the whole design would not help
    man.refine()  # where the restoration failed in the basis, it restarts in the whole design
    with man.blas_threads():
        rest = run(man, out.x, damping, max_iter - out.iterations, deadline, stop, callback,
                   tol, announce=False, scale=out.scale)
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


def run(man: Manifold, x: np.ndarray, damping: float, max_iter: int, deadline: float | None,
        stop: Callable[[np.ndarray], bool] | None,
        callback: Callable[[float, float], None] | None, tol: float, announce: bool = True,
        scale: float | None = None) -> MarchedOutcome:
    """One run of :func:`levenberg_marquardt` on ``man``, in its basis (``announce``: the
    callback at the start too; ``scale``: the optimality error's, None: from the first
    gradient), a start that breaks a constraint restored first; in a coarse basis it ends
    "Basis_Stalled" where the loss stops falling (:data:`BASIS_STALL`)."""
    nlp = man.nlp
    x = np.asarray(x, dtype=float)
    p = man.marched(x)
    if p is None:
        return MarchedOutcome(x=x, objective=None, iterations=0, status="Inadmissible_Start")
    infeasibility = man.violation(p)
    restoring = infeasibility > FEASIBLE
    if callback is not None and announce:
        callback(p.objective, infeasibility)
    steps = Steps(man)
    lam, nu, it, restored, reach = float(damping), 2.0, 0, 0, 1.0
    B = np.zeros((man.basis.shape[1],) * 2)
    pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []  # (step, y, y_sharp)
    history: list[tuple[frozenset[int], float]] = []  # the last QPs' active rows and lam
    augmented, error, last, kept = False, None, None, None
    losses = [] if restoring else [p.objective]  # the last admissible points', for the stall
    status = "Maximum_Iterations_Exceeded"
    while it < max_iter:
        lin = m = None  # the last point's derivatives go before the next are built
        lin = man.linearize(p, metric=kept is None or lam >= METRIC_DAMPING)
        if lin is None:
            status = "Stalled"
            break
        m = model(man, p, lin, kept)
        kept = m.M
        if last is not None:
            pair = (last.step, *last.gradient_change(m, steps))
            pairs = (pairs + [pair])[-max(secant.SECANT_PAIRS, secant.TAIL_PAIRS):]
            B = (secant.tail_term(pairs[-secant.TAIL_PAIRS:], m.JtJ)
                 if secant.in_tail(history)
                 else secant.secant_term(pairs[-secant.SECANT_PAIRS:], man.basis.shape[1]))
        if augmented and _positive_definite(m.H + B + lam * m.M):
            m.H = m.H + B
        if not restoring:
            scale = scale or max(1.0, float(np.max(np.abs(m.grad))) / 100)
        if deadline is not None and time.perf_counter() > deadline:
            status = "Maximum_WallTime_Exceeded"
            break
        base = partial_target(m, reach) if restoring else np.zeros(m.lower.size)
        shift, corrections, first, candidate = base.copy(), 0, True, None
        while lam <= MAX_DAMPING:
            trial, step = None, steps(m, lam, shift)
            if step is not None:
                if first and not restoring:
                    error, first = kkt_error(m, steps, step) / scale, False
                    active = frozenset(step.which[step.multipliers != 0].tolist())
                    history = (history + [(active, lam)])[-secant.TAIL_STEPS:]
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
                    shift += linearization_error(man, m, steps, dd, p, trial)
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
                base = partial_target(m, reach)
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
            last = secant.Last(m, steps, step, dd, trial)
            augmented = last.augmented_predicts_better(actual, B)
        p, it = trial, it + 1
        if callback is not None:
            callback(p.objective, violation)
        if stop is not None and not restoring and stop(p.x):
            status = "Fit_Reached"
            break
        if man.coarse and not restoring and BASIS_STALL > 0:
            losses = (losses + [p.objective])[-BASIS_STALL_STEPS - 1:]
            if (len(losses) > BASIS_STALL_STEPS
                    and losses[0] - losses[-1] < BASIS_STALL * losses[-1]):
                status = "Basis_Stalled"
                break
    if restoring:  # no admissible point reached: the start as given
        return MarchedOutcome(x=x, objective=None, iterations=it, status="Inadmissible_Start",
                       restored=it)
    return MarchedOutcome(x=p.x, objective=p.objective, iterations=it, status=status,
                   kkt_error=error, scale=scale, restored=restored)


def _positive_definite(H: np.ndarray) -> bool:
    try:
        la.cho_factor(H)
    except la.LinAlgError:
        return False
    return True
