"""Transcriptions of a :class:`~rffqm_nlp.design.problem.DesignProblem` into one NLP.

A transcription turns the declarative problem (:class:`Setup`, :mod:`.inputs`) into an
:class:`NLP` (:mod:`.nlp`): ``(x, residuals, g, bounds, x0)``.

* :func:`sequential` (:mod:`.sequential_nlp`): the marching graph is a function of the
  boundary data (few variables, dense Jacobians);
* :func:`simultaneous` (:mod:`.simultaneous_nlp`): every vertex angle and side is a variable
  and the marching equations are equality constraints, panel by panel (many variables,
  sparse Jacobians). Its lifted variables keep every row local (:mod:`.lifting`), and it
  carries the Jacobians of its residuals and constraints assembled from local stencils
  (:mod:`.stencil_jacobians`), which :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`
  uses instead of CasADi's Jacobians of the whole graph;
* :func:`several_states` (:mod:`.states_nlp`): one crease pattern of the simultaneous
  transcription folded into several states, each with its own omega, alignment and target.

Both share the residuals of the loss and the Tikhonov terms (:mod:`.loss`; a curvature
target's loss: :mod:`.curvature_loss`), the inline
constraints (angle bounds, multiplier margins, the boundary MV assignment, sides against
the mean side) and a free correspondence's controls (:class:`Correspondence`,
:mod:`.correspondence`), so they state the same problem. IPOPT's Hessians of their
Lagrangian are IPOPT's (:mod:`rffqm_nlp.design.solvers.ipopt.hessians`).
"""

from .correspondence import GRID_CONTROLS, GRID_REGULARIZATION, MIN_GRID_STEP, Correspondence
from .curvature_loss import CurvatureLoss
from .inputs import Setup, damping_weights, quaternion_from_rotation
from .loss import loss_residuals, rotation_from_quaternion, smoothness_residuals
from .nlp import NLP, controls_of
from .sequential_nlp import sequential
from .simultaneous_nlp import simultaneous
from .states_nlp import ORIENTATIONS, oriented, several_states

__all__ = ["GRID_CONTROLS", "GRID_REGULARIZATION", "MIN_GRID_STEP", "NLP", "ORIENTATIONS",
           "Correspondence", "CurvatureLoss", "Setup", "controls_of", "damping_weights",
           "loss_residuals", "oriented", "quaternion_from_rotation",
           "rotation_from_quaternion", "sequential", "several_states", "simultaneous",
           "smoothness_residuals"]
