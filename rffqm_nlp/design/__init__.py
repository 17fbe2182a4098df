"""The inverse design: the declarative problem (:mod:`.problem`), its transcriptions
(:mod:`.transcription`, :mod:`.stencils`), the solvers (:mod:`.solvers`), the result
(:mod:`.results`) and the clearance rounds (:mod:`.clearance`)."""

from .problem import (DESIGN_KEYS, SOLVE_KEYS, DesignProblem, SolveOptions, check_memory,
                      from_config, load_design, memory_estimate)

__all__ = ["DESIGN_KEYS", "SOLVE_KEYS", "DesignProblem", "SolveOptions", "check_memory",
           "from_config", "load_design", "memory_estimate"]
