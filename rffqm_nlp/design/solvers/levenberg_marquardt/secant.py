"""The structured secant term B of the model (Dennis, Gay & Welsch, "An adaptive nonlinear
least-squares algorithm", ACM TOMS 7, 1981; NL2SOL): an estimate of the part of the
Hessian that Gauss-Newton drops, from the change of the Lagrangian's gradient over the last
:data:`SECANT_PAIRS` accepted steps, and the record of the last step (:class:`Last`) that
gives each pair and chooses between the models."""

from __future__ import annotations

import numpy as np

from .manifold import Point
from .steps import Model, Step, Steps

#: the accepted steps whose secant pairs make up B: NL2SOL's update applied to each in turn
#: from zero at every iteration, so curvature learned far back is dropped instead of being
#: sized away with what the last steps learned (docs/decisions/levenberg-marquardt.md)
SECANT_PAIRS = 3


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
