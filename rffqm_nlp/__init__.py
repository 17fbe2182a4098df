"""rffqm-nlp: forward and inverse design of rigidly and flat-foldable quadrilateral mesh origami.

After Feng, Dang, James & Plucinsky, J. Mech. Phys. Solids (2020), doi 10.1016/j.jmps.2020.104018.
"""

from __future__ import annotations

import importlib
import importlib.metadata

__version__ = importlib.metadata.version("rffqm_nlp")  # before the imports (foldfile reads it)

from .boundary import BoundaryData, miura_boundary, perturb_angles
from .errors import (BoundaryDataError, InfeasibleDesign, InputError, MarchingError,
                     RffqmError, SolverFailed, SurfaceError)
from .pattern import Pattern
from .marching import fold, march
from .design import DesignProblem, SolveOptions, load_design
from .results import DesignResult, Fit, SolveStats
from .collisions import CollisionReport, collisions

_SUBMODULES = ("numpy_model", "marching", "vertex", "boundary", "pattern", "backend", "errors",
               "lengths", "surfaces", "meshes", "shape", "curvature", "design", "transcription",
               "reduced", "stencils", "clearance", "results", "files", "foldfile", "export",
               "viz", "view", "cli", "sweeps", "memory", "ipopt_options")


def __getattr__(name: str):
    if name in _SUBMODULES:
        return importlib.import_module(f".{name}", __name__)
    if name == "sweep":  # rq.sweep(study, out, ...): rffqm_nlp.sweeps.run, imported on use
        return importlib.import_module(".sweeps", __name__).run
    raise AttributeError(f"module 'rffqm_nlp' has no attribute {name!r}")


__all__ = ["BoundaryData", "BoundaryDataError", "CollisionReport", "DesignProblem",
           "DesignResult", "Fit", "InfeasibleDesign", "InputError", "MarchingError", "Pattern",
           "RffqmError", "SolveOptions", "SolveStats", "SolverFailed", "SurfaceError",
           "collisions", "fold", "load_design", "march", "miura_boundary", "perturb_angles",
           "sweep", *_SUBMODULES]
