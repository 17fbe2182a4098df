"""IPOPT's iteration callback for a design: the history, the best admissible iterate, and
the stop once the fit asked for is reached."""

from __future__ import annotations

import time

import casadi as ca
import numpy as np

from ...transcription import NLP


class IterationLog(ca.Callback):
    """IPOPT iteration callback: records objective and constraint violation per iteration,
    keeps the best admissible design met on the way (``best``) and asks IPOPT to stop once
    ``stop(x)`` holds at one (``reached_x``).

    An iterate is admissible when it satisfies every constraint and bound. Where it does not
    and the NLP can project it (``nlp.project``: the simultaneous transcription re-marches
    the iterate's boundary data), the projected point is judged instead, with its own
    objective: the simultaneous NLP meets its marching equations only near the optimum, but
    its earlier iterates' designs are often admissible and good (docs/decisions/ipopt.md).
    """

    #: constraint violation below which an iterate counts as feasible for ``stop``
    FEASIBLE = 1e-9

    def __init__(self, nlp: NLP, history: dict, callback, stop=None,
                 previous: "IterationLog | None" = None, t0: float | None = None):
        ca.Callback.__init__(self)
        self._stop = stop
        self.reached = False
        self.reached_x: np.ndarray | None = None
        self.reached_objective = np.nan
        # the best admissible iterate so far, of this run or of an earlier run on the same NLP
        self.best: np.ndarray | None = None if previous is None else previous.best
        self._best_objective = np.inf if previous is None else previous._best_objective
        self._nx, self._ng = nlp.x.numel(), nlp.g.numel()
        self._lbg, self._ubg = nlp.lbg, nlp.ubg
        self._lbx, self._ubx = nlp.lbx, nlp.ubx
        self._project = nlp.project
        if nlp.project is not None:
            self._fg = ca.Function("fg", [nlp.x], [nlp.objective, nlp.g])
        self._history = history
        self._callback = callback
        self._t0 = time.perf_counter() if t0 is None else t0  # "elapsed" counts from t0
        self.construct("iteration_log", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = ca.nlpsol_out(i)
        if n in ("f",):
            return ca.Sparsity.dense(1)
        if n in ("x", "lam_x"):
            return ca.Sparsity.dense(self._nx)
        if n in ("g", "lam_g"):
            return ca.Sparsity.dense(self._ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        g = np.asarray(arg[ca.nlpsol_out().index("g")]).ravel()
        viol = self._violation(g)
        entry = {"iter": len(self._history["iter"]),
                 "objective": float(arg[ca.nlpsol_out().index("f")]),
                 "inf_pr": viol, "elapsed": time.perf_counter() - self._t0}
        for key, value in entry.items():
            self._history[key].append(value)
        if self._callback is not None:
            self._callback(entry)
        x = np.asarray(arg[ca.nlpsol_out().index("x")]).ravel()
        objective = entry["objective"]
        if viol > self.FEASIBLE and self._project is not None:
            x = self._project(x)
            if x is None:
                return [int(self.reached)]
            f, g = self._fg(x)
            objective, viol = float(f), self._violation(g.full().ravel(), x)
        if viol <= self.FEASIBLE:
            if objective < self._best_objective:
                self.best, self._best_objective = x.copy(), objective
            if self._stop is not None and self._stop(x):
                self.reached, self.reached_x, self.reached_objective = True, x.copy(), objective
        return [int(self.reached)]

    def _violation(self, g: np.ndarray, x: np.ndarray | None = None) -> float:
        """Largest violation of the constraints at g (and of the bounds at x, if given)."""
        parts = [[0.0], self._lbg - g, g - self._ubg]
        if x is not None:
            parts += [self._lbx - x, x - self._ubx]
        return float(np.max(np.concatenate(parts)))
