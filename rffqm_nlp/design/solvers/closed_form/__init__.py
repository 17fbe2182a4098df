"""The closed-form alternating perturbation of a Miura-ori for prescribed curvatures along
the pattern's two directions, after the idea of Sardas, Moshe & Maor (2024; their code is
AlonSardas/RFFQMOrigami), derived in this project's conventions (docs/closed_form.md).

* :mod:`.cell`: the exact relations of one cell (curvature per gradient of the
  perturbation, the turning angle as a function of the perturbation);
* :mod:`.alternating`: :func:`closed_form_boundary`, the boundary data for kx(x), ky(y);
* :mod:`.separable`: a target's curvatures and steps along its lattice, and their best
  separable approximation;
* :mod:`.start`: :func:`closed_form_start`, the closed form as the start of a
  :class:`~rffqm_nlp.design.problem.DesignProblem`'s solve.

Nothing here imports :mod:`rffqm_nlp.design.problem` at run time, so the problem and the
solve may import this package.
"""

from .alternating import ClosedForm, CurvatureField, closed_form_boundary, transposed, zigzag_fold
from .cell import first_order_gains, straight_gain, zigzag_gain
from .separable import Separable, curvatures_along_lattice, lattice_steps, separable_curvatures
from .start import closed_form_design, closed_form_start

__all__ = ["ClosedForm", "CurvatureField", "Separable", "closed_form_boundary",
           "closed_form_design", "closed_form_start", "curvatures_along_lattice",
           "first_order_gains", "lattice_steps", "separable_curvatures", "straight_gain",
           "transposed", "zigzag_fold", "zigzag_gain"]
