"""How a design problem is solved: :class:`SolveOptions`, the [solve] table of a design file.

The options of every solver sit in one flat table, so that a design file names them
without knowing which solver reads which; each solver reads its own
(:mod:`rffqm_nlp.design.solvers`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

from ..errors import InputError
from ..files import Key, check_table, check_value, describe_value, unknown_key
from ..ipopt_options import INT_MAX, check_ipopt_options

TRANSCRIPTIONS = ("sequential", "simultaneous")
LM = "levenberg-marquardt"
#: The closed form as a method of its own: the starting design is the result.
CLOSED_FORM = "closed-form"
SOLVERS = ("ipopt", LM, CLOSED_FORM)
HESSIANS = ("gauss-newton", "exact", "limited-memory")
#: The designs a solve can start from (SolveOptions.start).
STARTS = ("miura", "closed-form")
#: IPOPT options that a SolveOptions field (or solve's ``verbose``) sets, and that setting.
IPOPT_FIELDS = {"max_iter": "SolveOptions.max_iter", "tol": "SolveOptions.tol",
                "max_wall_time": "SolveOptions.time_limit",
                "hessian_approximation": "SolveOptions.hessian",
                "print_level": "solve(verbose=...)"}
#: SolveOptions.boundary_knots' default: knots per class of boundary data of the coarse
#: basis in which Levenberg-Marquardt starts (docs/decisions/levenberg-marquardt.md)
BOUNDARY_KNOTS = 32
#: Most starts of a multistart solve and most stages of a continuation: each is a whole
#: solve (a study of many designs is a sweep, docs/sweeps.md).
MAX_STARTS = 1000
MAX_STAGES = 100

#: What each key of a [solve] table (and each SolveOptions field) allows.
SOLVE_KEYS = {
    "solver": Key("choice", choices=SOLVERS),
    "transcription": Key("choice", choices=TRANSCRIPTIONS),
    "hessian": Key("choice", choices=HESSIANS),
    "damping": Key("number", low=0.0),
    "continuation": Key("list", least=1, most=MAX_STAGES,
                        item=Key("number", low=0.0, low_open=True)),
    "max_iter": Key("whole", low=1, high=INT_MAX),
    "tol": Key("number", low=0.0, low_open=True),
    "time_limit": Key("number", low=0.0, low_open=True, optional=True),
    "stop_rms": Key("number", low=0.0, low_open=True, optional=True),
    "barrier_init": Key("number", low=0.0, low_open=True, optional=True),
    "ipopt_options": Key("table", hint="of IPOPT options by name"),
    "multistart": Key("whole", low=1, high=MAX_STARTS),
    "seed": Key("whole", low=0, high=2**63 - 1),
    "boundary_knots": Key("whole", low=0, hint="(0: the whole design from the start)"),
    "start": Key("choice", choices=STARTS),
}


@dataclass(frozen=True)
class SolveOptions:
    """How a :class:`DesignProblem` is solved (the [solve] table of a design file).

    * ``solver``: "levenberg-marquardt" (the default) or "ipopt". Levenberg-Marquardt runs
      on the marching manifold (:mod:`rffqm_nlp.design.solvers.levenberg_marquardt`, simultaneous
      transcription only):
      its variables are the boundary data, omega and the alignment, every iterate is
      re-marched, so every iterate is an admissible design (after restoration steps from a
      start that breaks a constraint), and the inequalities enter each step linearised (a
      small QP). It stops at ``stop_rms``, or where the reduced problem's optimality
      conditions hold to ``tol`` (status "Solve_Succeeded"); only when it stalls, or its
      restoration fails, does IPOPT (with ``hessian``) finish. Measured against IPOPT in
      docs/benchmarks/default_solve.md; "closed-form" returns the closed form itself
      (:func:`rffqm_nlp.design.solvers.closed_form.closed_form_start`, or for a curvature
      target :func:`rffqm_nlp.design.solvers.closed_form.prescribed_start`), measured, with
      no optimiser (docs/curvature_targets.md);
    * ``transcription``: "simultaneous" (all pattern and kinematic quantities as variables,
      the marching equations as sparse equality constraints) or "sequential" (the marching
      graph as a function of the boundary data; IPOPT only). Both state the same NLP;
    * ``hessian``: IPOPT's Hessian, "exact", "gauss-newton" or "limited-memory" (L-BFGS).
      "gauss-newton" is J^T J of the residuals plus ``damping`` times a diagonal
      Levenberg-Marquardt term
      (:func:`rffqm_nlp.design.solvers.ipopt.hessians.gauss_newton_hessian`), for at most
      :data:`rffqm_nlp.design.solvers.ipopt.GAUSS_NEWTON_ITERATIONS` iterations, after
      which the exact Hessian takes over from the last iterate and its multipliers unless
      ``stop_rms`` was reached or IPOPT stopped with a status of
      :data:`rffqm_nlp.design.solvers.ipopt.HANDOVER_STOP_STATUSES`
      (:func:`rffqm_nlp.design.solvers.ipopt.phases`);
    * ``damping``: weight of the Levenberg-Marquardt term of "gauss-newton", and the first
      damping of solver "levenberg-marquardt" (then adapted every step; must be > 0);
    * ``continuation``: multipliers of the regularization weight for successive solves, each
      warm-started from the last (e.g. (10, 1): first stay close to the Miura, then let the
      fit improve; the default is one solve);
    * ``max_iter``, ``tol``, ``time_limit`` (seconds): the limits, over all solvers and
      stages (``tol``: IPOPT's, and that of Levenberg-Marquardt's optimality error);
    * ``stop_rms``: stop as soon as the aligned coarse lattice is within this RMS distance
      of the target lattice (a fraction of the target's diameter) with every constraint
      holding (status "Fit_Reached"); None runs to the solver's tolerance. With the
      simultaneous transcription IPOPT's iterates are judged by their boundary data
      re-marched (see :class:`rffqm_nlp.design.solvers.ipopt.iteration_log.IterationLog`);
    * ``barrier_init``: IPOPT's initial barrier parameter with small bound pushes (None:
      :data:`rffqm_nlp.design.solvers.ipopt.COLD_BARRIER` from a cold start, 1e-6 from a
      warm start);
    * ``ipopt_options``: further IPOPT options by name (e.g. {"bound_mult_init_val": 0.01}),
      applied last; checked against IPOPT's table of options
      (:func:`rffqm_nlp.ipopt_options.check_ipopt_options`; nothing is built). Options that
      a field above sets (:data:`IPOPT_FIELDS`) are refused, and so, unless ``trust``, are
      the options that name a file or a library ("output_file", "hsllib", ...) and the
      linear solvers loaded from a library at run time ("ma27", ...);
    * ``trust``: allow those options (the caller's word, as ``--trust``; never read from a
      [solve] table, and not saved with the options);
    * ``multistart``: solve from this many starting Miuras and keep the best fit
      (:func:`rffqm_nlp.design.multistart.solve_multistart`); ``seed``: the seed of their
      perturbations;
    * ``boundary_knots``: Levenberg-Marquardt steps first in a coarse basis of the boundary
      data, each of its 12 classes (A, B at either edge, LV, LH; each parity) piecewise
      linear between at most this many knots
      (:func:`rffqm_nlp.design.solvers.levenberg_marquardt.boundary_basis`),
      then, unless ``stop_rms`` was reached there, in the whole design from its end; 0: the
      whole design from the start. Patterns up to about 2 x ``boundary_knots`` panels a side
      have no coarser basis;
    * ``start``: the design the solve starts from, which is also the reference of the
      regularization: "miura" (the default), the Miura-ori of the problem scaled and aligned
      to the target lattice (:meth:`DesignProblem.start`), or "closed-form", the
      alternating perturbation of that Miura for the target's curvatures along the pattern's
      two directions (:func:`rffqm_nlp.design.solvers.closed_form.closed_form_start`; where
      the target's curvatures ask too much of it, the Miura). A ``warm_start`` replaces
      either as the initial guess. Measured in docs/benchmarks/closed_form.md. A curvature
      target always starts from its closed form (the Miura where that fails).
    """

    solver: str = LM
    transcription: str = "simultaneous"
    hessian: str = "exact"
    damping: float = 0.03
    continuation: tuple[float, ...] = (1.0,)
    max_iter: int = 1000
    tol: float = 1e-6
    time_limit: float | None = None
    stop_rms: float | None = None
    barrier_init: float | None = None
    ipopt_options: dict[str, str | int | float] = field(default_factory=dict)
    multistart: int = 1
    seed: int = 0
    boundary_knots: int = BOUNDARY_KNOTS
    start: str = "miura"
    trust: bool = False

    def __post_init__(self) -> None:
        values = check_table({f.name: getattr(self, f.name) for f in fields(self)
                              if f.name != "trust"}, SOLVE_KEYS, "[solve]")
        object.__setattr__(self, "trust", check_value(self.trust, Key("bool"), "trust"))
        for name, value in values.items():
            object.__setattr__(self, name, value)
        if self.solver == LM and self.transcription != "simultaneous":
            raise InputError("[solve] solver 'levenberg-marquardt' marches the simultaneous "
                             "NLP's design; use transcription 'simultaneous'")
        if self.boundary_knots == 1:
            raise InputError("[solve] boundary_knots must be 0 (the whole design from the "
                             "start) or at least 2 (knots a class), got 1")
        if self.solver == LM and not self.damping > 0:
            raise InputError("[solve] damping must be > 0 with solver 'levenberg-marquardt' "
                             f"(its first damping), got {self.damping:g}")
        object.__setattr__(self, "ipopt_options", check_ipopt_options(
            self.ipopt_options, IPOPT_FIELDS, self.trust))

    def to_config(self) -> dict[str, Any]:
        """The options as a TOML-ready [solve] table (unset optional values and ``trust``
        left out)."""
        out = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "trust"}
        out.update(continuation=list(self.continuation), ipopt_options=dict(self.ipopt_options))
        return {k: v for k, v in out.items() if v is not None}

    @classmethod
    def from_config(cls, table: dict[str, Any], trust: bool = False) -> "SolveOptions":
        """Options from a [solve] table; an unknown key is refused with the closest known.
        ``trust``: the table's ipopt_options may name files and libraries."""
        return cls(**check_table(table, SOLVE_KEYS, "[solve]"), trust=trust)


def with_overrides(options: SolveOptions | None, overrides: dict[str, Any]) -> SolveOptions:
    """``options`` (default SolveOptions()) with SolveOptions fields given by name."""
    if options is not None and not isinstance(options, SolveOptions):
        raise InputError(f"options must be a SolveOptions, got {describe_value(options)}")
    for key in overrides:
        if key not in SOLVE_KEYS:
            raise InputError(f"solve(): {unknown_key(key, SOLVE_KEYS, '[solve]')}")
    return replace(options or SolveOptions(), **overrides)


def transcription_of(solve: dict[str, Any]) -> str:
    """The transcription a [solve] table names (its default where it names none), read
    without the rest of the table: a result's design vector is laid out by it."""
    return check_value(solve.get("transcription", SolveOptions.transcription),
                       SOLVE_KEYS["transcription"], "[solve] transcription")
