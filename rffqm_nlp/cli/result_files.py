"""The files several commands make of a saved design: the exporters' options
(:func:`export_options`), render.png and folding.gif (:func:`render_files`) with the target
drawn in the pattern's frame (:func:`target_for_render`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import RffqmError, one_line
from .options import FRAMES
from .output import warn

if TYPE_CHECKING:
    from ..design.results import DesignResult


def result_folder(result: Path) -> Path:
    """The folder of a result given as its folder or as its result.json."""
    return result if result.is_dir() else result.parent


def _pattern_frame(points: np.ndarray, result: "DesignResult") -> np.ndarray:
    """Target-frame points moved into the frame of :func:`marching.fold` (the inverse of
    the alignment ``y -> rotation @ y + translation`` of ``result.folded``)."""
    return (np.asarray(points, dtype=float) - result.translation) @ result.rotation


def target_for_render(result: "DesignResult", target=None, trust: bool = False):
    """The target of :func:`rffqm_nlp.design.results.target_mesh` moved into the pattern frame, or
    the target lattice points (with a warning) when it cannot be rebuilt (the target names
    code and ``trust`` is not given)."""
    import trimesh

    from ..design.results import target_mesh

    try:
        mesh = target_mesh(result, target, trust)
    except RffqmError as exc:
        warn(f"cannot rebuild the target surface ({one_line(exc)}); drawing the target "
             "lattice points instead")
        return _pattern_frame(result.target_points.reshape(-1, 3), result)
    return trimesh.Trimesh(vertices=_pattern_frame(mesh.vertices, result), faces=mesh.faces,
                           process=False)


def export_options(result: "DesignResult") -> dict:
    """The options every exporter is offered (FOLD takes them: its folding states and the
    target and fit as metadata). A design of several states folds to the farthest of its
    states on the first's side of the flat state, with every state's omega among the
    frames, and adds "states": each state's omega and fit."""
    metadata = {"target": result.problem.get("target", {}), "fit": result.fit}
    if not result.other_states:
        return {"frames": FRAMES, "metadata": metadata}
    from ..model.pattern import motion_omegas

    side = [state.omega for state in result.states
            if np.sign(state.omega) == np.sign(result.omega)]
    frames = np.array(sorted(np.union1d(motion_omegas(max(side, key=abs), FRAMES), side),
                             key=abs))
    return {"frames": frames, "metadata": {
        **metadata, "states": [{"omega": state.omega, "fit": state.fit}
                               for state in result.states]}}


def render_files(folder: Path, result: "DesignResult", omega_end: float, frames: int,
                  target=None, trust: bool = False) -> None:
    from ..show import pictures as viz

    viz.render_png(folder / "render.png", result.pattern, result.omega,
                   target=target_for_render(result, target, trust),
                   contacts=_contacts(result))
    viz.folding_gif(folder / "folding.gif", result.pattern, omega_end, frames=frames)


def _contacts(result: "DesignResult"):
    """The collision report of a design whose fit says it is not collision-free (for
    render.png to mark the panels in contact), else None."""
    from ..contact.collisions import collisions

    return None if result.fit.collision_free is not False else collisions(result.pattern,
                                                                          result.omega)
