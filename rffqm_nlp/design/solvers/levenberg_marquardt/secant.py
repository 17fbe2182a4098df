"""The structured secant term B of the model (Dennis, Gay & Welsch, "An adaptive nonlinear
least-squares algorithm", ACM TOMS 7, 1981; NL2SOL): an estimate of the part of the
Hessian that Gauss-Newton drops, from the change of the Lagrangian's gradient over the last
:data:`SECANT_PAIRS` accepted steps (:func:`secant_term`), or, in the tail of a run (the
same rows active over the last :data:`TAIL_STEPS` steps, the damping below
:data:`TAIL_DAMPING`), from BFGS updates of the point's J' J over the last
:data:`TAIL_PAIRS` (:func:`tail_term`); and the record of the last step (:class:`Last`) that
gives each pair and chooses between the models."""

from __future__ import annotations

import numpy as np

from .manifold import Point
from .steps import Model, Step, Steps

#: the accepted steps whose secant pairs make up B: NL2SOL's update applied to each in turn
#: from zero at every iteration, so curvature learned far back is dropped instead of being
#: sized away with what the last steps learned (docs/decisions/levenberg-marquardt.md)
SECANT_PAIRS = 3
#: the accepted steps whose pairs make up B in the tail (:func:`tail_term`): at 100 x 100
#: the tail's steps turn between directions where the Lagrangian's curvature is a tenth of
#: J' J's and twice it, more than three pairs hold; 8 is the one value tried in the tail
#: (docs/decisions/levenberg-marquardt.md, 2026-12-07: "The tail's secant term")
TAIL_PAIRS = 8
#: the tail: the step's QP has had the same active rows (at least one) at this many
#: iterations in a row, ...; 3 took the 100 x 100 sphere cap to 66 iterations (6: 73; 101
#: before) but switched at the 20 x 20 hyperboloid's end, where the last three steps' term
#: already converged fast (19 iterations against 16); 6 took no more iterations than before
#: on the bundled targets at 20 and 40 panels a side
TAIL_STEPS = 6
#: ... each with its first trial's damping below this (the same value as the metric's
#: threshold, :data:`.loop.METRIC_DAMPING`: lam M is then a small part of the model)
TAIL_DAMPING = 1e-3


def secant_term(pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]], n: int
                ) -> np.ndarray:
    """B (n, n) from the secant pairs (step, y, y_sharp) of the last accepted steps, oldest
    first: :func:`secant_update` applied to each in turn, from zero."""
    B = np.zeros((n, n))
    for pair in pairs:
        B = secant_update(B, *pair)
    return B


def secant_update(B: np.ndarray, step: np.ndarray, y: np.ndarray, y_sharp: np.ndarray
                  ) -> np.ndarray:
    """B (n_d, n_d) updated over one accepted ``step`` (n_d,) (Dennis, Gay & Welsch): ``y``
    the change of the Lagrangian's gradient, ``y_sharp`` its part that Jr' Jr does not
    model (:meth:`Last.gradient_change`), which B step should reproduce. Unchanged where
    y' step <= 0."""
    ys = float(y @ step)
    if ys <= 0:
        return B
    sBs = float(step @ B @ step)
    if sBs != 0:
        B = B * min(1.0, abs(float(step @ y_sharp)) / abs(sBs))
    v = y_sharp - B @ step
    return B + (np.outer(v, y) + np.outer(y, v)) / ys - float(v @ step) * np.outer(y, y) / ys ** 2


def in_tail(history: list[tuple[frozenset[int], float]]) -> bool:
    """Whether a run is in its tail: the last :data:`TAIL_STEPS` entries of ``history``
    (per iteration, the rows active in the first trial step's QP and that trial's damping)
    have the same, non-empty, active rows and a damping below :data:`TAIL_DAMPING`."""
    last = history[-TAIL_STEPS:]
    return (len(last) == TAIL_STEPS and bool(last[0][0])
            and all(rows == last[0][0] and lam < TAIL_DAMPING for rows, lam in last))


def tail_term(pairs: list[tuple[np.ndarray, np.ndarray, np.ndarray]], JtJ: np.ndarray
              ) -> np.ndarray:
    """B (n, n) such that JtJ + B is the point's J' J (n, n) updated by BFGS over each secant
    pair (step s, y, y_sharp) in turn, oldest first, toward JtJ s + y_sharp (the structured
    secant condition of :func:`secant_update`); a pair with s' (JtJ s + y_sharp) <= 0 (or
    s' H s <= 0) is skipped, so JtJ + B stays positive definite where JtJ is."""
    H = JtJ.copy()
    for step, _, y_sharp in pairs:
        y = JtJ @ step + y_sharp
        Hs = H @ step
        sy, sHs = float(step @ y), float(step @ Hs)
        if sy <= 0 or sHs <= 0:
            continue
        H = H - np.outer(Hs, Hs) / sHs + np.outer(y, y) / sy
    return H - JtJ


class Last:
    """The model and accepted step of the last iteration, for the secant update and the
    choice between the Gauss-Newton and the augmented model (NL2SOL's rule: the one whose
    predicted reduction was nearer the actual one)."""

    def __init__(self, m: Model, steps: Steps, step: Step, change: np.ndarray,
                 trial: Point):
        self.grad, self.JtJ = m.grad, m.JtJ
        self.which, self.multipliers = step.which, step.multipliers
        self.A = steps.rows(m, step.which) if step.which.size else None
        self.step = change
        self.Jt_r = m.lin.jacobian_transpose(trial.r)  # Jr' r at the accepted point

    def gradient_change(self, m: Model, steps: Steps) -> tuple[np.ndarray, np.ndarray]:
        """(y, y_sharp) of :func:`secant_update` at the new model m: the change of the
        gradient of the Lagrangian (the QP's multipliers held), and of its part that Jr' Jr
        misses."""
        y, y_sharp = m.grad - self.grad, m.grad - self.Jt_r
        if self.A is not None:
            dA = (steps.rows(m, self.which) - self.A).T @ self.multipliers
            y, y_sharp = y + dA, y_sharp + dA
        return y, y_sharp

    def augmented_predicts_better(self, actual: float, B: np.ndarray) -> bool:
        s = self.step
        gauss_newton = -(self.grad @ s + 0.5 * s @ self.JtJ @ s)
        return abs(actual - (gauss_newton - 0.5 * s @ B @ s)) < abs(actual - gauss_newton)
