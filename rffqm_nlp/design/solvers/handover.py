"""The default order of the solvers on one NLP (:func:`solve`): Levenberg-Marquardt on the
marching manifold, handing over to IPOPT only where it stalls or reaches no admissible
point; IPOPT alone with solver "ipopt"."""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..options import LM
from ..transcription import NLP
from . import ipopt, levenberg_marquardt
from .context import Outcome, Run


def solve(nlp: NLP, x: np.ndarray, run: Run, *, panels: tuple[int, int], warm: bool,
          reference: Callable[[], np.ndarray] | None = None) -> Outcome:
    """Solve ``nlp`` from ``x`` (n,) with ``run.options.solver``: Levenberg-Marquardt, then
    IPOPT from its last point where it stalls, or from ``x`` where it reached no
    admissible point (from a start that breaks a constraint: moved toward ``reference()``
    where given, else restored); IPOPT alone with solver "ipopt". ``panels``: the
    pattern's, for IPOPT's options; ``warm``: ``x`` is near an optimum."""
    if run.options.solver == LM:
        marched = levenberg_marquardt.solve(nlp, x, run, reference=reference)
        if marched is not None and marched.status != "Stalled":
            return marched
        if marched is not None:
            return ipopt.solve(nlp, marched.x, run, panels=panels, warm=True,
                               best=marched.best)
    return ipopt.solve(nlp, x, run, panels=panels, warm=warm)
