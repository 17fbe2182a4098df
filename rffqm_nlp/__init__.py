"""rffqm-nlp: forward and inverse design of rigidly and flat-foldable quadrilateral mesh origami.

After Feng, Dang, James & Plucinsky, J. Mech. Phys. Solids (2020), doi 10.1016/j.jmps.2020.104018.

The folders are the layers (docs/architecture.md): ``model`` (boundary data, the marching,
the pattern and its folded states), ``targets`` (surfaces, meshes, shape measures),
``contact`` (self-contact along the motion), ``design`` (the inverse problem, its solvers
and its result), ``io`` (FOLD and the exporters), ``show`` (pictures and the HTML view), then
``sweeps`` and ``cli`` on top; ``errors``, ``files`` and ``memory`` are the ground floor.
"""

from __future__ import annotations

import importlib

from ._version import __version__
from .contact.collisions import CollisionReport, collisions
from .design import DesignProblem, SolveOptions, load_design
from .design.results import DesignResult, Fit, SolveStats
from .errors import (BoundaryDataError, InfeasibleDesign, InputError, MarchingError,
                     RffqmError, SolverFailed, SurfaceError)
from .model.boundary import BoundaryData, miura_boundary, perturb_angles
from .model.marching import fold, march
from .model.pattern import Pattern

#: The modules users reach as ``rq.<name>`` (README, docs), and where each lives; imported
#: on first use.
MODULES = {
    "boundary": "model.boundary", "marching": "model.marching", "vertex": "model.vertex",
    "numpy_model": "model.numpy_model", "pattern": "model.pattern", "lengths": "model.lengths",
    "surfaces": "targets.surfaces", "meshes": "targets.meshes", "shape": "targets.shape",
    "curvature": "targets.curvature", "design": "design", "results": "design.results",
    "ipopt_options": "ipopt_options", "foldfile": "io.foldfile",
    "export": "io.export", "errors": "errors", "files": "files", "memory": "memory",
    "sweeps": "sweeps", "cli": "cli",
    "model": "model", "targets": "targets", "contact": "contact", "io": "io", "show": "show",
    "mechanics": "mechanics",
    "make": "make",  # a package called as its function: rq.make(result, width="300mm")
}


def __getattr__(name: str):
    if name in MODULES:
        return importlib.import_module(f".{MODULES[name]}", __name__)
    if name == "sweep":  # rq.sweep(study, out, ...): rffqm_nlp.sweeps.run, imported on use
        return importlib.import_module(".sweeps", __name__).run
    raise AttributeError(f"module 'rffqm_nlp' has no attribute {name!r}")


__all__ = ["BoundaryData", "BoundaryDataError", "CollisionReport", "DesignProblem",
           "DesignResult", "Fit", "InfeasibleDesign", "InputError", "MarchingError", "Pattern",
           "RffqmError", "SolveOptions", "SolveStats", "SolverFailed", "SurfaceError",
           "collisions", "fold", "load_design", "march", "miura_boundary", "perturb_angles",
           "sweep", *MODULES]
