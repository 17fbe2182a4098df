"""Mechanics of a design: the bar-and-hinge model of a pattern at a folded state, its
stiffness, modes and response to loads, and Poisson's ratio of the folding motion from the
exact derivatives of the march (docs/mechanics.md).

``rq.mechanics`` is this public face: :class:`Material` (:mod:`.material`),
:class:`BarAndHinge` (:mod:`.model`; its frame :mod:`.frame`, compatibility matrices
:mod:`.compatibility`, modes :mod:`.modes`, loads :mod:`.loads`) and the folding motion's
:func:`folding_velocity`, :func:`poisson_ratio` and :func:`poisson_map` (:mod:`.folding`).
"""

from __future__ import annotations

from .folding import folded_state, folding_velocity, poisson_map, poisson_ratio
from .loads import Response, Ties
from .material import MATERIALS, Material
from .model import BarAndHinge
from .modes import Modes

__all__ = ["MATERIALS", "BarAndHinge", "Material", "Modes", "Response", "Ties",
           "folded_state", "folding_velocity", "poisson_map", "poisson_ratio"]
