"""The inverse design: the declarative problem (:mod:`.problem`), how it is solved
(:mod:`.options`, :mod:`.solve`, :mod:`.multistart`), the design file (:mod:`.schema`),
its transcriptions (:mod:`.transcription`, :mod:`.stencils`), the solvers (:mod:`.solvers`),
the result (:mod:`.results`, measured by :mod:`.measure`) and the clearance rounds
(:mod:`.clearance`)."""

from .measure import TARGET_GRID
from .multistart import multistart_starts, solve_multistart
from .options import SOLVE_KEYS, SolveOptions
from .problem import DESIGN_KEYS, DesignProblem, Start
from .schema import from_config, load_design
from .solve import check_memory, memory_estimate

__all__ = ["DESIGN_KEYS", "SOLVE_KEYS", "TARGET_GRID", "DesignProblem", "SolveOptions",
           "Start", "check_memory", "from_config", "load_design", "memory_estimate",
           "multistart_starts", "solve_multistart"]
