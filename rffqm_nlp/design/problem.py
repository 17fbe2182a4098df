"""Inverse design (the paper's section "Discussion on the inverse problem", docs/paper.md).

:class:`DesignProblem` states what is designed: a target surface, a 2N x 2M pattern whose
coarse lattice r(i, j) = y^{(2i)(2j)} should match the target lattice, the Miura
mountain-valley assignment held fixed, the inline manufacturability constraints and the loss.
:class:`SolveOptions` states how: the solver, the transcription, IPOPT's Hessian and the
limits. :meth:`DesignProblem.solve` transcribes the problem
(:mod:`rffqm_nlp.design.transcription`), runs Levenberg-Marquardt on the marching manifold
(:mod:`rffqm_nlp.design.solvers.levenberg_marquardt`) and/or IPOPT, re-marches the answer with the
independent NumPy
model and returns a :class:`~rffqm_nlp.design.results.DesignResult`. A design file has the tables
[target], [design] and [solve] (:func:`load_design`). Measurements of the solvers and
options: docs/solvers.md.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Callable

import casadi as ca
import numpy as np

from . import clearance
from .. import memory
from ..model import numpy_model
from .solvers import levenberg_marquardt as reduced
from ..targets import shape
from ..targets import surfaces
from . import transcription
from ..model.boundary import LAYOUTS, BoundaryData, miura_boundary, refine
from ..contact.collisions import collisions
from ..targets.curvature import curvature_maps
from ..errors import (BoundaryDataError, InfeasibleDesign, InputError, MarchingError,
                     SolverFailed, one_line, raise_for_ipopt)
from ..files import Key, check_table, check_value, describe_value, read_toml, unknown_key
from ..ipopt_options import INT_MAX, NO_OPTION_FILE, check_ipopt_options
from ..model.pattern import Pattern
from .results import DesignResult, Fit, SolveStats

PI = np.pi
DEFAULT_WEIGHTS = {"position": 1.0, "forms": 0.1, "regularization": 0.1, "smoothness": 0.0}
TRANSCRIPTIONS = ("sequential", "simultaneous")
LM = "levenberg-marquardt"
SOLVERS = ("ipopt", LM)
HESSIANS = ("gauss-newton", "exact", "limited-memory")
GROUPS = ("angles", "lengths", "omega")
#: What the target lattice is (DesignProblem.correspondence, docs/meshes.md).
CORRESPONDENCES = ("lattice", "free")
#: The tables of a design file.
TABLES = ("target", "design", "solve")
#: IPOPT options that a SolveOptions field (or solve's ``verbose``) sets, and that setting.
IPOPT_FIELDS = {"max_iter": "SolveOptions.max_iter", "tol": "SolveOptions.tol",
                "max_wall_time": "SolveOptions.time_limit",
                "hessian_approximation": "SolveOptions.hessian",
                "print_level": "solve(verbose=...)"}
#: Largest sequential pattern (panels) whose NLP is expanded to SX; see SolveOptions.expand.
SX_MAX_PANELS = 144
#: IPOPT's barrier from a cold start. The loss is small against the many log-barrier terms,
#: so IPOPT's default (monotone from mu = 0.1) first solves a different problem (angles near
#: pi/2, long sides): the simultaneous transcription loses feasibility there and never
#: recovers, the sequential one needs more iterations. "adaptive" suits the simultaneous
#: NLP; for the sequential one it found a worse local minimum of a small sphere cap, which
#: a small mu_init does not (docs/solvers.md).
COLD_BARRIER = {"sequential": {"ipopt.mu_init": 1e-3},
                "simultaneous": {"ipopt.mu_strategy": "adaptive"}}
#: Most iterations of the damped Gauss-Newton Hessian before the exact one takes over (see
#: SolveOptions.ipopt_phases).
GAUSS_NEWTON_ITERATIONS = 30
#: SolveOptions.boundary_knots' default: knots per class of boundary data of the coarse
#: basis in which Levenberg-Marquardt starts (docs/solvers.md)
BOUNDARY_KNOTS = 32
#: IPOPT statuses after which the exact Hessian does not take over from Gauss-Newton (nor
#: does it after stop_rms is reached).
HANDOVER_STOP_STATUSES = ("Solve_Succeeded", "Maximum_WallTime_Exceeded")

#: Most starts of a multistart solve and most stages of a continuation: each is a whole
#: solve (a study of many designs is a sweep, docs/sweeps.md).
MAX_STARTS = 1000
MAX_STAGES = 100

#: What each key of a design file's [design] table (and each DesignProblem field but the
#: target) allows; checked by :func:`rffqm_nlp.files.check_table`.
DESIGN_KEYS = {
    "panels": Key("list", length=2, item=Key("whole", low=4, even=True), hint="(2N, 2M)"),
    "layout": Key("choice", choices=LAYOUTS),
    "alpha0": Key("number", low=0.0, high=PI / 2, low_open=True, high_open=True),
    "omega0": Key("number", low=-PI, high=PI),
    "min_angle": Key("number", low=0.0, high=PI / 4, high_open=True),
    "mu_margin": Key("number", low=0.0, high=1.0, high_open=True),
    "min_length": Key("number", low=0.0),
    "min_clearance": Key("number", low=0.0),
    "omega_bounds": Key("list", length=2, item=Key("number", low=-PI, high=PI),
                        hint="([low, high])"),
    "fix": Key("list", item=Key("choice", choices=GROUPS)),
    "weights": Key("table", spec={name: Key("number", low=0.0) for name in DEFAULT_WEIGHTS}),
    "correspondence": Key("choice", choices=CORRESPONDENCES),
}
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
}
#: The tables of a design file as :func:`rffqm_nlp.files.check_table` checks them.
FILE_KEYS = {name: Key("table") for name in TABLES}
#: Samples per direction of the target kept in a result whose target config cannot rebuild
#: it (DesignResult.target_grid), for its pictures.
TARGET_GRID = 41


@dataclass(frozen=True)
class Start:
    """The Miura start and the target lattice placed to match it."""

    boundary: BoundaryData
    omega: float
    target_points: np.ndarray
    spacing: float
    rotation: np.ndarray
    translation: np.ndarray


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
      studies/results/bench_default_solve.md;
    * ``transcription``: "simultaneous" (all pattern and kinematic quantities as variables,
      the marching equations as sparse equality constraints) or "sequential" (the marching
      graph as a function of the boundary data; IPOPT only). Both state the same NLP;
    * ``hessian``: IPOPT's Hessian, "exact", "gauss-newton" or "limited-memory" (L-BFGS).
      "gauss-newton" is J^T J of the residuals plus ``damping`` times a diagonal
      Levenberg-Marquardt term (:func:`rffqm_nlp.design.transcription.gauss_newton_hessian`), for
      at most :data:`GAUSS_NEWTON_ITERATIONS` iterations, after which the exact Hessian
      takes over from the last iterate and its multipliers unless ``stop_rms`` was reached
      or IPOPT stopped with a status of :data:`HANDOVER_STOP_STATUSES`
      (:meth:`ipopt_phases`);
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
      re-marched (see :class:`_IterationLog`);
    * ``barrier_init``: IPOPT's initial barrier parameter with small bound pushes (None:
      :data:`COLD_BARRIER` from a cold start, 1e-6 from a warm start);
    * ``ipopt_options``: further IPOPT options by name (e.g. {"bound_mult_init_val": 0.01}),
      applied last; checked against IPOPT's table of options
      (:func:`rffqm_nlp.ipopt_options.check_ipopt_options`; nothing is built). Options that
      a field above sets (:data:`IPOPT_FIELDS`) are refused, and so, unless ``trust``, are
      the options that name a file or a library ("output_file", "hsllib", ...) and the
      linear solvers loaded from a library at run time ("ma27", ...);
    * ``trust``: allow those options (the caller's word, as ``--trust``; never read from a
      [solve] table, and not saved with the options);
    * ``multistart``: solve from this many starting Miuras and keep the best fit
      (:func:`solve_multistart`); ``seed``: the seed of their perturbations;
    * ``boundary_knots``: Levenberg-Marquardt steps first in a coarse basis of the boundary
      data, each of its 12 classes (A, B at either edge, LV, LH; each parity) piecewise
      linear between at most this many knots
      (:func:`rffqm_nlp.design.solvers.levenberg_marquardt.boundary_basis`),
      then, unless ``stop_rms`` was reached there, in the whole design from its end; 0: the
      whole design from the start. Patterns up to about 2 x ``boundary_knots`` panels a side
      have no coarser basis.
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

    def ipopt_phases(self, done: int) -> list[tuple[str, int]]:
        """(Hessian, iteration limit) of each IPOPT run of one solve stage, ``done``
        iterations having been spent already.

        With ``hessian = "gauss-newton"`` the damped Gauss-Newton runs first, for at most
        :data:`GAUSS_NEWTON_ITERATIONS`; unless it reaches stop_rms or converges, the exact
        Hessian takes over from its last iterate and multipliers. On its own it converges
        only linearly, and its last iterates may fail the re-march check.
        """
        left = self.max_iter - done
        if self.hessian != "gauss-newton":
            return [(self.hessian, left)]
        first = min(GAUSS_NEWTON_ITERATIONS, left)
        return [("gauss-newton", first)] + ([("exact", left - first)] if left > first else [])

    def expand(self, panels: tuple[int, int]) -> bool:
        """Expand the NLP to SX (fast evaluation, costly derivative build) or keep MX.

        The sequential NLP is dense: its SX Hessian's build grows fast with the pattern, so
        only patterns up to :data:`SX_MAX_PANELS` panels are expanded. The simultaneous
        NLP's time goes to the linear solver, not to evaluations, so it stays MX
        (docs/solvers.md).
        """
        return self.transcription == "sequential" and panels[0] * panels[1] <= SX_MAX_PANELS

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


@dataclass(frozen=True)
class DesignProblem:
    """Which RFFQM pattern, perturbed from a Miura-ori, folds into ``target``?

    Parameters (all with defaults chosen so designs are manufacturable):

    * ``panels``: (2N, 2M) panels, both even; the coarse lattice is (N+1) x (M+1);
    * ``layout``, ``alpha0``, ``omega0``: the starting Miura-ori (docs/paper.md); its side
      lengths are chosen so that its coarse lattice at ``omega0`` has the target lattice's
      mean spacings. The default layout "zigzag_i" (zig-zag along the target's u) needs far
      fewer iterations than "zigzag_j" on the bundled targets (docs/solvers.md);
    * ``min_angle``: every sector angle in [min_angle, pi - min_angle] (this also keeps the
      first check, eq:firstCheck, away from its limits);
    * ``mu_margin``: |mu_abc| of every panel stays on its starting side of 1 by this margin
      (second check, eq:secondCheck, so sigma_d never flips), and the multiplier of every
      boundary vertex that vanishes where its sigma leaves MV(alpha, beta) keeps its sign,
      at least this large (:func:`rffqm_nlp.model.vertex.mv_multiplier`): the MV pattern of the
      Miura is held at every crease;
    * ``min_length``: every side >= min_length times the mean side (replaces the LP);
    * ``min_clearance``: a sheet thickness, in the target's length units: panels that share
      no vertex stay at least this far apart in the designed state (0: not asked; see
      :mod:`rffqm_nlp.design.clearance`). Whether the motion up to the designed state is free of
      self-contact is reported in ``result.fit.collision_free`` either way;
    * ``omega_bounds``: bounds of the fold parameter;
    * ``fix``: groups held at their start, among "angles", "lengths", "omega";
    * ``weights``: loss weights, "forms" (the paper's fundamental-form loss) and "position"
      (lattice positions after a rigid alignment that is part of the NLP), see
      :func:`rffqm_nlp.design.transcription.loss_residuals`; "regularization" (Tikhonov, towards
      the Miura start) and "smoothness" (second differences of the boundary perturbation
      along each edge, :func:`rffqm_nlp.design.transcription.smoothness_residuals`; default 0);
      missing keys count as 0;
    * ``correspondence``: "free" (the default: the lattice's (u, v) are a smooth map of
      the lattice indices whose few controls are design variables, kept in the domain and
      from folding over, :class:`rffqm_nlp.design.transcription.Correspondence`) or "lattice"
      (the target lattice is r on the uniform grid of the domain); "free" fits the shape
      closer for a few more iterations, measured in docs/meshes.md.

    How it is solved is a :class:`SolveOptions`, given to :meth:`solve`.
    """

    target: surfaces.Surface
    panels: tuple[int, int] = (20, 20)
    layout: str = "zigzag_i"
    alpha0: float = 1.1
    omega0: float = 2.0
    min_angle: float = 0.15
    mu_margin: float = 0.02
    min_length: float = 0.2
    min_clearance: float = 0.0
    omega_bounds: tuple[float, float] = (0.05, PI - 0.05)
    fix: tuple[str, ...] = ()
    weights: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_WEIGHTS))
    correspondence: str = "free"

    def __post_init__(self) -> None:
        if not isinstance(self.target, surfaces.Surface):
            raise InputError("target must be a surface from rq.surfaces (get, Custom, load), "
                             f"got {describe_value(self.target)}")
        values = check_table({f.name: getattr(self, f.name) for f in fields(self)
                              if f.name != "target"}, DESIGN_KEYS, "[design]")
        values["weights"] = {**dict.fromkeys(DEFAULT_WEIGHTS, 0.0), **values["weights"]}
        for name, value in values.items():
            object.__setattr__(self, name, value)
        if not any(self.weights.values()):
            raise InputError("[design] weights must not all be zero: give position, forms, "
                             "regularization or smoothness a positive weight")
        lo, hi = self.omega_bounds
        if not lo < hi or not lo <= self.omega0 <= hi:
            raise InputError(f"[design] omega_bounds and omega0 need omega_bounds[0] <= omega0 "
                             f"<= omega_bounds[1] with omega_bounds[0] < omega_bounds[1], got "
                             f"omega0 = {self.omega0:g}, omega_bounds = [{lo:g}, {hi:g}]")

    @property
    def N(self) -> int:
        """Coarse lattice rows (the pattern has 2N panel rows)."""
        return self.panels[0] // 2

    @property
    def M(self) -> int:
        """Coarse lattice columns (the pattern has 2M panel columns)."""
        return self.panels[1] // 2

    # ------------------------------------------------------------------ start
    def start(self) -> Start:
        """The starting Miura and the target lattice.

        The target lattice spans the target's whole domain; the Miura's vertical and
        horizontal sides are scaled so that its coarse lattice at omega0 has the same mean
        neighbour distances along i and along j; both are then aligned (Kabsch).
        """
        N, M = self.N, self.M
        unit = miura_boundary(2 * N, 2 * M, 1.0, 1.0, self.alpha0, self.layout)
        coarse = shape.coarse_grain(numpy_model.fold(numpy_model.march(unit), self.omega0))
        target_points = self.target.lattice(N, M)
        s_i, s_j = surfaces.mean_neighbour_distances(coarse)
        t_i, t_j = surfaces.mean_neighbour_distances(target_points)
        bd = unit.with_lengths(np.concatenate([unit.l_left * t_i / s_i,
                                               unit.l_bottom * t_j / s_j]))
        coarse = shape.coarse_grain(numpy_model.fold(numpy_model.march(bd), self.omega0))
        R, t, _ = shape.kabsch(coarse, target_points)
        return Start(boundary=bd, omega=self.omega0, target_points=target_points,
                     spacing=0.5 * (t_i + t_j), rotation=R, translation=t)

    def transcribe(self, start: Start | None = None, weights: dict[str, float] | None = None,
                   initial: DesignResult | None = None,
                   options: SolveOptions | None = None) -> transcription.NLP:
        """The NLP of this problem in the transcription of ``options`` (default
        :class:`SolveOptions`: the simultaneous one).

        ``weights`` override the problem's; ``initial`` (a result of this problem, in
        either transcription, at these panels or fewer: :meth:`carried`) replaces the Miura
        as the initial guess, while the Miura stays the Tikhonov reference and fixes the
        mountain-valley pattern; with a free correspondence, its map too when it was solved
        with one on the same domain (:meth:`_initial_controls`).
        """
        start = start or self.start()
        guess, corr = start, self._correspondence()
        controls = None
        if initial is not None:
            guess = self.carried(initial, start)
            controls = self._initial_controls(initial, corr)
        setup = transcription.Setup(
            boundary=guess.boundary, omega=guess.omega, rotation=guess.rotation,
            translation=guess.translation, target=start.target_points, spacing=start.spacing,
            weights=weights or self.weights, min_angle=self.min_angle,
            min_length=self.min_length, mu_margin=self.mu_margin,
            omega_bounds=self.omega_bounds, fixed=self.fix, reference=start.boundary,
            reference_omega=start.omega, correspondence=corr, controls=controls)
        return getattr(transcription, (options or SolveOptions()).transcription)(setup)

    def carried(self, initial: DesignResult, start: Start | None = None) -> Start:
        """``initial``, a result of this problem at these panels or fewer, as a start of
        this problem: as it is at the same panels; from fewer, its boundary data carried to
        these panels (:func:`rffqm_nlp.model.boundary.refine`, coarse-to-fine) with its omega, and
        aligned to the target lattice anew. ``start``: this problem's (default
        :meth:`start`). Raises :class:`InputError` when ``initial`` has more panels, another
        layout, alpha0 or omega0, or when its carried pattern does not march."""
        start = start or self.start()
        n, m = initial.boundary.N, initial.boundary.M
        if (n, m) == self.panels:
            return replace(start, boundary=initial.boundary, omega=initial.omega,
                           rotation=initial.rotation, translation=initial.translation)
        if n > self.panels[0] or m > self.panels[1]:
            raise InputError(f"the initial guess has {n} x {m} panels, more than the problem's "
                             f"{self.panels[0]} x {self.panels[1]}: give a result of as many "
                             f"panels or fewer")
        theirs = initial.problem.get("design", {})
        for name in ("layout", "alpha0", "omega0"):
            if name in theirs and theirs[name] != getattr(self, name):
                raise InputError(f"the initial guess of {n} x {m} panels has [design] {name} "
                                 f"= {theirs[name]!r}, the problem {getattr(self, name)!r}: "
                                 f"a coarser design is carried over from the same Miura-ori")
        reference = replace(self, panels=(n, m)).start().boundary
        try:
            boundary = refine(initial.boundary, reference, start.boundary)
            lattice = shape.coarse_grain(numpy_model.fold(numpy_model.march(boundary),
                                                          initial.omega))
        except (BoundaryDataError, MarchingError) as exc:
            raise InputError(f"the initial guess of {n} x {m} panels, carried to "
                             f"{self.panels[0]} x {self.panels[1]}, does not march: "
                             f"{one_line(exc)}") from exc
        R, t, _ = shape.kabsch(lattice, start.target_points)
        return replace(start, boundary=boundary, omega=initial.omega, rotation=R,
                       translation=t)

    def _initial_controls(self, initial: DesignResult,
                          corr: transcription.Correspondence | None) -> np.ndarray | None:
        """The controls of ``initial``'s free correspondence (read from its design vector,
        :func:`rffqm_nlp.design.transcription.controls_of`) when this problem has one of the same
        size and they lie within its bounds (the domain, the edges pinned); else None (the
        map starts uniform)."""
        design, solve = (initial.problem.get(k, {}) for k in ("design", "solve"))
        if corr is None or design.get("correspondence") != "free":
            return None
        controls = transcription.controls_of(
            initial.x, _transcription_of(solve), corr.size)
        lower, upper = corr.bounds()
        if controls.size != corr.size or np.any(controls < lower) or np.any(controls > upper):
            return None
        return controls

    def _correspondence(self) -> transcription.Correspondence | None:
        """The free correspondence from the uniform grid (None with "lattice")."""
        if self.correspondence != "free":
            return None
        return transcription.Correspondence.uniform(
            self.target.casadi_function(), self.target.domain, (self.N + 1, self.M + 1))

    def grid(self, result: DesignResult) -> tuple[np.ndarray, np.ndarray] | None:
        """The grid (U, V), each (N+1, M+1), of a free correspondence at ``result`` (a
        result of this problem, read from its design vector); None with "lattice"."""
        corr = self._correspondence()
        if corr is None:
            return None
        controls = transcription.controls_of(
            result.x, _transcription_of(result.problem["solve"]), corr.size)
        return corr.grid(*corr.views(controls))

    # ------------------------------------------------------------------ solve
    def solve(self, options: SolveOptions | None = None, *,
              callback: Callable[[dict], None] | None = None,
              warm_start: DesignResult | None = None, verbose: bool = False,
              **overrides: Any) -> DesignResult:
        """Solve the design with ``options`` (default :class:`SolveOptions`), with any
        SolveOptions field overridden by name (``solve(solver="ipopt")``).

        ``callback`` receives {"iter", "objective", "inf_pr", "elapsed"} every iteration
        ("elapsed": seconds since the solve started).
        ``warm_start``: a result of this problem at these panels or fewer to start from
        instead of the Miura (a coarser design carried to these panels, coarse-to-fine:
        :meth:`carried`; the Miura stays the Tikhonov reference and the mountain-valley
        pattern; a free correspondence's map is kept, see :meth:`transcribe`); where it
        breaks a constraint, solver "levenberg-marquardt" starts from its free boundary
        data moved part or all of the way toward the Miura's (``stats.start_moved``,
        :func:`rffqm_nlp.design.solvers.levenberg_marquardt.admissible_toward`), or where no such
        point holds every
        constraint restores the warm start itself (``stats.restoration_iterations``), and
        IPOPT starts from it where that fails too.
        ``verbose``: IPOPT prints its iterations.
        With ``options.multistart`` > 1 see :func:`solve_multistart`.
        Raises :class:`InputError` before any work when the solve needs more memory than
        this machine has available (:func:`check_memory`),
        :class:`InfeasibleDesign` when the constraints cannot hold, :class:`SolverFailed`
        (with the solver's status, the statistics, the last iterate and the best admissible
        one) otherwise, status "non_finite" when the solve ended with a
        NaN or inf in the design, the objective or the fit.
        """
        options = _with_overrides(options, overrides)
        check_memory(self, options)
        if options.multistart != 1:
            return solve_multistart(self, options, callback=callback, warm_start=warm_start,
                                    verbose=verbose)
        self._check_reachable()
        start = self.start()
        record = _Record(callback=callback, verbose=verbose)
        x = None
        for stage, factor in enumerate(options.continuation):
            t1 = time.perf_counter()
            nlp = self.transcribe(start, self._stage_weights(factor),
                                  warm_start if x is None else None, options)
            record.build_time += time.perf_counter() - t1
            reference = (self._miura_point(start, options, record)
                         if warm_start is not None and x is None else None)
            outcome = self._solve_stage(nlp, start, options, record, nlp.x0 if x is None else x,
                                        warm=warm_start is not None or stage > 0,
                                        reference=reference)
            x = outcome.x
            if not outcome.success or outcome.status == "Fit_Reached":
                break
        stats = record.stats(options, outcome)
        if not outcome.success:
            _raise_failure(nlp, outcome, stats, record.iterations)
        if self.min_clearance > 0:
            nlp, outcome = self._keep_clearance(nlp, start, options, record, outcome)
            stats = record.stats(options, outcome)
        return self._result(nlp, start, outcome.x, stats, options)

    def _keep_clearance(self, nlp: transcription.NLP, start: Start, options: SolveOptions,
                        record: "_Record", outcome: "_Outcome"
                        ) -> tuple[transcription.NLP, "_Outcome"]:
        """Re-solve, warm-started, with clearance rows on the pairs of panels closer than
        about min_clearance (:mod:`rffqm_nlp.design.clearance`), refreshed each round, until the
        re-marched design keeps min_clearance. Raises SolverFailed (status
        "clearance_not_met") when a round fails or brings the closest pair no farther."""
        pairs = np.zeros((0, 2), dtype=np.int64)
        reached, stage_nlp = -np.inf, nlp
        for _ in range(clearance.ROUNDS):
            state = _marched(nlp, start, outcome.x, 2 * self.N, 2 * self.M)
            if state is None:
                break
            near, worst = clearance.closest(*state, self.min_clearance)
            if worst.distance >= self.min_clearance:
                return stage_nlp, outcome
            if worst.distance <= reached:
                break
            reached = worst.distance
            pairs = np.unique(np.concatenate([pairs, near]), axis=0)
            stage_nlp = clearance.constrain(nlp, *state, pairs, self.min_clearance)
            limited = replace(options, max_iter=min(
                options.max_iter, record.iterations + clearance.ROUND_ITERATIONS))
            trial = self._solve_stage(stage_nlp, start, limited, record, outcome.x, warm=True)
            if not trial.success:
                break
            outcome = trial
        state = _marched(nlp, start, outcome.x, 2 * self.N, 2 * self.M)
        worst = (clearance.closest(*state, self.min_clearance)[1] if state is not None
                 else clearance.Closest(None, float("nan")))
        where = ("" if worst.pair is None else
                 f": in the last design solved, panels {worst.pair[0]} and {worst.pair[1]} "
                 f"are {worst.distance:.4g} apart")
        raise SolverFailed(
            f"min_clearance = {self.min_clearance:g} is not met at the designed state{where}; "
            "lower min_clearance, or lower omega_bounds[1] (a design folded less keeps its "
            "layers farther apart)", status="clearance_not_met",
            stats=record.stats(options, outcome), last_iterate=outcome.x)

    def _check_reachable(self) -> None:
        if self.min_length >= 1:
            raise InfeasibleDesign(
                f"min_length = {self.min_length} asks every side to be at least the mean side, "
                "which only equal sides satisfy; choose min_length < 1 (default 0.2)")

    def _stage_weights(self, factor: float) -> dict[str, float]:
        """The loss weights of a continuation stage: regularization times ``factor``."""
        return dict(self.weights, regularization=factor * self.weights["regularization"])

    def _solve_stage(self, nlp: transcription.NLP, start: Start, options: SolveOptions,
                     record: "_Record", x: np.ndarray, warm: bool,
                     reference: Callable[[], np.ndarray] | None = None) -> "_Outcome":
        """One continuation stage from x: Levenberg-Marquardt (with that solver), then
        IPOPT when it stalls or reaches no admissible point (from a start that breaks a
        constraint: moved toward ``reference()`` where given,
        :func:`rffqm_nlp.design.solvers.levenberg_marquardt.admissible_toward`, else restored)."""
        if options.solver == LM:
            marched = self._solve_levenberg_marquardt(nlp, start, options, record, x, reference)
            if marched is not None and marched.status != "Stalled":
                return marched
            if marched is not None:
                return self._solve_ipopt(nlp, start, options, record, marched.x, True,
                                         marched.best)
        return self._solve_ipopt(nlp, start, options, record, x, warm, None)

    def _solve_levenberg_marquardt(self, nlp: transcription.NLP, start: Start,
                                   options: SolveOptions, record: "_Record", x: np.ndarray,
                                   reference: Callable[[], np.ndarray] | None = None
                                   ) -> "_Outcome | None":
        """Levenberg-Marquardt on the marching manifold
        (:mod:`rffqm_nlp.design.solvers.levenberg_marquardt`) from x (or, where x breaks a
        constraint, x moved toward ``reference()``, or restored), every
        step recorded; None when it reached no admissible point (its restoration steps, if
        any, counted), unless the iterations or the time ran out in the restoration
        (:meth:`_restoration_cut_short`)."""
        deadline = None if options.time_limit is None else record.t0 + options.time_limit
        t1 = time.perf_counter()
        manifold = reduced.Manifold(nlp, options.boundary_knots or None)  # like IPOPT's build
        record.build_time += time.perf_counter() - t1
        out = reduced.levenberg_marquardt(
            nlp, x, options.damping, options.max_iter - record.iterations, deadline=deadline,
            stop=self._fit_reached(nlp, start, options), callback=record.log,
            tol=options.tol, manifold=manifold, reference=reference)
        record.iterations += out.iterations
        record.marched_iterations += out.iterations
        record.restoration_iterations += out.restored
        if out.status == "Inadmissible_Start":
            return self._restoration_cut_short(options, record, x, deadline)
        record.start_moved = out.moved or record.start_moved  # later stages start admissible
        status = out.status
        if status == "Stalled" and record.iterations >= options.max_iter:
            status = "Maximum_Iterations_Exceeded"
        return _Outcome(x=out.x, status=status, success=out.success,
                        objective=out.objective, best=out.x)

    @staticmethod
    def _restoration_cut_short(options: SolveOptions, record: "_Record", x: np.ndarray,
                               deadline: float | None) -> "_Outcome | None":
        """Where Levenberg-Marquardt reached no admissible point: a failure with its status
        when ``max_iter`` or ``time_limit`` ran out during its restoration (no admissible
        point to report as the best; IPOPT would have nothing left), else None (IPOPT
        starts from x)."""
        if record.iterations >= options.max_iter:
            status = "Maximum_Iterations_Exceeded"
        elif deadline is not None and time.perf_counter() > deadline:
            status = "Maximum_WallTime_Exceeded"
        else:
            return None
        return _Outcome(x=x, status=status, success=False, objective=None, best=None)

    def _solve_ipopt(self, nlp: transcription.NLP, start: Start, options: SolveOptions,
                     record: "_Record", x: np.ndarray, warm: bool,
                     best: np.ndarray | None) -> "_Outcome":
        """IPOPT from x: one run per phase of :meth:`SolveOptions.ipopt_phases`, each later
        run handed the last one's iterate and multipliers (:func:`_handover`)."""
        multipliers: dict[str, Any] = {}
        log = None
        for hessian, max_iter in options.ipopt_phases(record.iterations):
            outcome, log = self._ipopt_run(nlp, start, options, record, x, hessian, max_iter,
                                           warm=warm or bool(multipliers), best=best,
                                           multipliers=multipliers, previous=log)
            x, best = outcome.x, outcome.best
            multipliers = _handover(outcome)
            if multipliers is None:
                break
        return outcome

    def _ipopt_run(self, nlp: transcription.NLP, start: Start, options: SolveOptions,
                   record: "_Record", x: np.ndarray, hessian: str, max_iter: int, warm: bool,
                   best: np.ndarray | None, multipliers: dict[str, Any],
                   previous: "_IterationLog | None") -> tuple["_Outcome", "_IterationLog"]:
        """One IPOPT run with ``hessian`` for at most ``max_iter`` iterations."""
        t1 = time.perf_counter()
        solver, log = self._ipopt_solver(
            nlp, start, options, record, hessian=hessian, max_iter=max_iter,
            elapsed=t1 - record.t0, warm=warm, multipliers=bool(multipliers),
            previous=previous if multipliers else None)
        record.build_time += time.perf_counter() - t1
        sol = solver(x0=x, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg, **multipliers)
        stats = dict(solver.stats())
        record.iterations += int(stats["iter_count"])
        if hessian == "gauss-newton":
            record.gauss_newton_iterations += int(stats["iter_count"])
        if log.reached:
            outcome = _Outcome(x=log.reached_x, status="Fit_Reached", success=True,
                               objective=log.reached_objective, best=log.best, sol=sol)
        else:
            outcome = _Outcome(x=sol["x"].full().ravel(), status=stats["return_status"],
                               success=bool(stats["success"]), objective=float(sol["f"]),
                               best=log.best, sol=sol)
        if outcome.best is None:
            outcome = replace(outcome, best=best)
        return outcome, log

    def _ipopt_solver(self, nlp: transcription.NLP, start: Start, options: SolveOptions,
                      record: "_Record", hessian: str, max_iter: int, elapsed: float = 0.0,
                      warm: bool = False, multipliers: bool = False, previous=None):
        opts: dict[str, Any] = {
            "ipopt.max_iter": max_iter, "ipopt.tol": options.tol,
            "ipopt.constr_viol_tol": 1e-9, "ipopt.print_level": 5 if record.verbose else 0,
            "print_time": record.verbose, "ipopt.sb": "yes",
            "expand": options.expand(self.panels), **NO_OPTION_FILE}
        if options.time_limit is not None:
            opts["ipopt.max_wall_time"] = max(options.time_limit - elapsed, 1e-3)
        if warm or options.barrier_init is not None:
            # near an optimum a small barrier keeps IPOPT from wandering off
            mu_init = 1e-6 if options.barrier_init is None else options.barrier_init
            opts.update({"ipopt.mu_init": mu_init, "ipopt.bound_push": 1e-9,
                         "ipopt.bound_frac": 1e-9})
        else:
            opts.update(COLD_BARRIER[options.transcription])
        if multipliers:
            opts["ipopt.warm_start_init_point"] = "yes"
        opts.update({f"ipopt.{name}": value for name, value in options.ipopt_options.items()})
        if hessian == "limited-memory":
            opts["ipopt.hessian_approximation"] = "limited-memory"
        elif hessian == "gauss-newton":
            opts["hess_lag"] = transcription.gauss_newton_hessian(nlp, options.damping)
        elif nlp.parts is not None:
            opts["hess_lag"] = transcription.lagrangian_hessian(nlp)
        log = _IterationLog(nlp, record.history, record.callback,
                            self._fit_reached(nlp, start, options), previous,
                            t0=time.perf_counter() - elapsed)
        opts["iteration_callback"] = log
        solver = ca.nlpsol("design", "ipopt", {"x": nlp.x, "f": nlp.objective, "g": nlp.g},
                           opts)
        solver._iteration_log = log  # keep the callback alive as long as the solver
        return solver, log

    def _miura_point(self, start: Start, options: SolveOptions,
                     record: "_Record") -> Callable[[], np.ndarray]:
        """The Miura start's point (n,) of the NLP, transcribed when first asked for (its
        time counted as build time): where a warm start breaks a constraint, Levenberg-
        Marquardt moves its boundary data toward it."""

        def point() -> np.ndarray:
            t1 = time.perf_counter()
            x = self.transcribe(start, options=options).x0
            record.build_time += time.perf_counter() - t1
            return x

        return point

    def _fit_reached(self, nlp: transcription.NLP, start: Start, options: SolveOptions):
        """For ``stop_rms``: does the aligned coarse lattice at x fit the target well enough?"""
        if options.stop_rms is None:
            return None
        limit = options.stop_rms * self.target.diameter()

        def reached(x: np.ndarray) -> bool:
            coarse = shape.coarse_grain(nlp.folded_array(x))
            return shape.kabsch(coarse, nlp.target_array(x, start.target_points))[2] <= limit

        return reached

    def _result(self, nlp: transcription.NLP, start: Start, x: np.ndarray,
                stats: SolveStats, options: SolveOptions) -> DesignResult:
        """Re-march the solution with the NumPy model, check it, measure the fit."""
        _require_finite({"the design vector": x, "the objective": stats.objective}, stats, x)
        vec, omega = (np.asarray(v.full()).ravel() for v in nlp.unpack(x))
        omega = float(omega[0])
        bd = BoundaryData.from_vector(vec, start.boundary.sigma, 2 * self.N, 2 * self.M)
        try:
            pattern = numpy_model.march(bd)
        except MarchingError as exc:
            raise SolverFailed(f"the solution fails re-marching with the NumPy model: {exc}",
                               status="remarch_failed", stats=stats, last_iterate=x) from exc
        Y = numpy_model.fold(pattern, omega)
        Y_graph = nlp.folded_array(x)
        scale = np.abs(Y).max()
        if np.abs(Y - Y_graph).max() > 1e-8 * scale:
            raise SolverFailed("the NumPy re-march disagrees with the CasADi graph by "
                               f"{np.abs(Y - Y_graph).max():.3g}", status="remarch_mismatch",
                               stats=stats, last_iterate=x)
        self._check_constraints(pattern, stats, x)
        target_points = nlp.target_array(x, start.target_points)
        R, t, _ = shape.kabsch(shape.coarse_grain(Y), target_points)
        folded = Y @ R.T + t
        fit = Fit(**design_fit(folded, target_points, self.target),
                  min_side_over_mean=float(pattern.side_lengths.min()
                                           / pattern.side_lengths.mean()),
                  min_sector_angle=float(pattern.sector_angles.min()))
        _require_finite({"the folded state": folded,
                         "the fit": [v for v in fit.to_dict().values() if v is not None]},
                        stats, x)
        fit = replace(fit, **collision_fields(pattern, omega))
        problem = self.config(options)
        grid = (None if surfaces.rebuildable(problem["target"])
                else self.target.sample(TARGET_GRID, TARGET_GRID))
        return DesignResult(boundary=bd, omega=omega, pattern=pattern, folded=folded,
                            target_points=target_points, rotation=R, translation=t,
                            fit=fit, stats=stats, problem=problem, x=x,
                            curvature=curvature_maps(shape.coarse_grain(folded),
                                                     target_points, self.target),
                            target_grid=grid)

    def _check_constraints(self, pattern, stats: SolveStats, x: np.ndarray) -> None:
        tol = 1e-6
        sides = pattern.side_lengths
        worst_angle = float(np.min(np.concatenate([pattern.alpha.ravel(), pattern.beta.ravel(),
                                                   PI - pattern.alpha.ravel(),
                                                   PI - pattern.beta.ravel()])))
        problems = []
        if worst_angle < self.min_angle - tol:
            problems.append(f"a sector angle of {worst_angle:.6g} < min_angle")
        if sides.min() < self.min_length * sides.mean() * (1 - tol):
            problems.append(f"a side of {sides.min() / sides.mean():.6g} x mean < min_length")
        if problems:
            raise SolverFailed("the solution violates its constraints on re-marching: "
                               + "; ".join(problems), status="constraint_violation",
                               stats=stats, last_iterate=x)

    # ------------------------------------------------------------------ configuration
    def to_config(self) -> dict[str, Any]:
        """The problem as TOML-ready tables: {"target": ..., "design": ...}. A target that no
        table can name (a lambda, a closure, a Mesh made from arrays) is recorded as not
        rebuildable (:func:`rffqm_nlp.targets.surfaces.config_of`)."""
        design = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "target"}
        design.update(weights=dict(self.weights), panels=list(self.panels),
                      omega_bounds=list(self.omega_bounds), fix=list(self.fix))
        return {"target": surfaces.config_of(self.target), "design": design}

    def config(self, options: SolveOptions) -> dict[str, Any]:
        """{"target", "design", "solve"}: this problem solved with ``options``."""
        return {**self.to_config(), "solve": options.to_config()}


def from_config(config: dict[str, Any], root: str | Path | None = None,
                trust: bool = False) -> tuple[DesignProblem, SolveOptions]:
    """The problem and the options of {"target": ..., "design": ..., "solve": ...} (the
    tables of a design file; [design] and [solve] may be missing). An unknown table or key
    is refused with the closest known name, a solve option in [design] with where it goes.

    ``root``: the folder that a target's ``python = "file.py:function"`` is relative to
    (default: the current folder); ``trust``: run the code a target names
    (:func:`rffqm_nlp.targets.surfaces.from_config`), refused without it.
    """
    tables = check_table(config, FILE_KEYS, "")
    if "target" not in tables:
        raise InputError("a design needs a [target] table (name = \"<surface>\" and its "
                         "parameters, or python = \"file.py:function\" and domain)")
    design = tables.get("design", {})
    for key in design:
        if key in SOLVE_KEYS:
            raise InputError(f"[design] {key} is a solve option: move it to the [solve] table")
    design = check_table(design, DESIGN_KEYS, "[design]")
    options = SolveOptions.from_config(tables.get("solve", {}), trust)
    target = surfaces.from_config(tables["target"], root=root, trust=trust)
    return DesignProblem(target=target, **design), options


def load_design(path: str | Path, trust: bool = False) -> tuple[DesignProblem, SolveOptions]:
    """The problem and the options of a design file (TOML with the tables [target],
    [design] and [solve]), e.g. ``problem, options = load_design("targets/sphere_cap.toml")``.

    A target's ``python = "file.py:function"`` is relative to the file's folder; the code a
    target names runs only with ``trust=True`` (for files you trust).

    A file whose suffix names a format trimesh reads (:func:`rffqm_nlp.targets.meshes.is_mesh_file`:
    OBJ, STL, PLY, OFF, GLB, XYZ, ...) is a mesh or point cloud: its
    :class:`~rffqm_nlp.targets.meshes.Mesh` (by its resolved path) with the default design and
    solve options."""
    from ..targets.meshes import is_mesh_file  # here: meshes imports surfaces, which imports Mesh

    if is_mesh_file(path):
        # abspath, not resolve: a path this system cannot open (a NUL) is Mesh's to refuse
        return DesignProblem(surfaces.Mesh(Path(os.path.abspath(path)))), SolveOptions()
    return from_config(read_toml(path, "design file"), Path(path).parent, trust)


# ---------------------------------------------------------------------- memory
#: The memory model of :func:`memory_estimate` (bytes), fitted to the peaks measured on the
#: sphere cap, quarter vase and hyperboloid up to 500 x 500 panels, from above where a fit
#: would fall short (docs/solvers.md, "Memory estimate"): what every run holds
#: (:data:`rffqm_nlp.memory.BASE`) plus this per panel for each path ("sequential",
#: "simultaneous": IPOPT's transcriptions with MUMPS' factor; "levenberg-marquardt": the
#: NLP, its Jacobians from stencils and their blocks by level) ...
MEMORY_PER_PANEL = {"levenberg-marquardt": 18.5e3, "simultaneous": 190e3, "sequential": 250e3}
#: ... the sequential NLP's derivative build on top ...
MEMORY_SEQUENTIAL_BUILD = 700e6
#: ... for Levenberg-Marquardt with a free correspondence this per panel more (the
#: residuals' Jacobian reads the target lattice; fitted to the peaks in docs/solvers.md) ...
MEMORY_FREE_PER_PANEL = 1e3
#: ... and for Levenberg-Marquardt the working set of its sensitivity: about
#: WORKING_SET * (P + Q) rows (the marched unknowns a later level still needs,
#: :class:`rffqm_nlp.design.solvers.levenberg_marquardt._Window`, as measured in docs/solvers.md,
# and the identity
#: over the 3 (P + Q) design variables) by those design variables, 8 bytes each ...
WORKING_SET = 22
#: ... and its dense design x design matrices held at once (J'J, the metric, the secant
#: term, the damped matrix and its factor, the last iteration's, the step QP's copy):
#: counted in design/solvers/levenberg_marquardt.py, not fitted.
DESIGN_MATRICES = 10


def memory_estimate(problem: DesignProblem, options: SolveOptions | None = None) -> int:
    """Bytes that solving ``problem`` with ``options`` needs at its peak (a model fitted to
    measurements, see :data:`MEMORY_PER_PANEL`; a multistart solves one start at a time).

    For P x Q panels: Levenberg-Marquardt needs memory.BASE + MEMORY_PER_PANEL * P Q + 8 *
    WORKING_SET * (P + Q) * n_d + 8 * DESIGN_MATRICES * n_d ** 2, for n_d = 3 (P + Q)
    design variables, or with ``stop_rms`` and ``boundary_knots`` k the coarse basis'
    6 (min(k, P / 2) + min(k, Q / 2)) coordinates (a run that does not reach stop_rms in
    the coarse basis goes on in the whole design: then n_d's memory), and with a free
    correspondence (:class:`rffqm_nlp.design.transcription.Correspondence`)
    MEMORY_FREE_PER_PANEL * P Q more and its 2 Ku Kv controls (at most 2 GRID_CONTROLS^2)
    in n_d; IPOPT needs
    memory.BASE + MEMORY_PER_PANEL[transcription] * P Q (plus MEMORY_SEQUENTIAL_BUILD for
    the sequential transcription)."""
    options = options or SolveOptions()
    P, Q = (float(p) for p in problem.panels)
    if options.solver == LM:
        design = 3.0 * (P + Q)
        if options.stop_rms is not None and options.boundary_knots:
            knots = options.boundary_knots
            design = min(design, 6.0 * (min(knots, P / 2) + min(knots, Q / 2)))
        per_panel = MEMORY_PER_PANEL[LM]
        if problem.correspondence == "free":
            k = transcription.GRID_CONTROLS
            design += 2.0 * min(k, P / 2 + 1) * min(k, Q / 2 + 1)
            per_panel += MEMORY_FREE_PER_PANEL
        working_set = 8.0 * WORKING_SET * (P + Q) * design
        need = (memory.BASE + per_panel * P * Q + working_set
                + 8.0 * DESIGN_MATRICES * design ** 2)
    else:
        need = memory.BASE + MEMORY_PER_PANEL[options.transcription] * P * Q
        if options.transcription == "sequential":
            need += MEMORY_SEQUENTIAL_BUILD
    return int(min(need, 2.0 ** 62))


def check_memory(problem: DesignProblem, options: SolveOptions | None = None) -> None:
    """Refuse, before any work, a solve that needs more memory (:func:`memory_estimate`)
    than this machine has available (:func:`rffqm_nlp.memory.available`): one
    :class:`InputError` line with the estimate and the limit."""
    options = options or SolveOptions()
    P, Q = problem.panels
    memory.refuse_beyond(memory_estimate(problem, options),
                         f"[design] panels = [{P}, {Q}] with solver {options.solver}",
                         "choose fewer panels")


def collision_fields(pattern: Pattern, omega: float) -> dict[str, Any]:
    """Fit's ``collision_free`` and ``first_contact_omega`` of ``pattern`` folding from 0 to
    ``omega`` (:func:`rffqm_nlp.contact.collisions.collisions`)."""
    report = collisions(pattern, omega)
    return {"collision_free": report.free, "first_contact_omega": report.first_omega}


def _marched(nlp: transcription.NLP, start: Start, x: np.ndarray, rows: int,
             cols: int) -> tuple[Any, float] | None:
    """The pattern and omega of x's boundary data re-marched with the NumPy model, or None
    when they do not march."""
    vec, omega = (np.asarray(v.full()).ravel() for v in nlp.unpack(x))
    try:
        bd = BoundaryData.from_vector(vec, start.boundary.sigma, rows, cols)
        return numpy_model.march(bd), float(omega[0])
    except (InputError, MarchingError):
        return None


def design_fit(folded: np.ndarray, target_points: np.ndarray,
               target: surfaces.Surface) -> dict[str, float]:
    """Fit measures of an aligned folded state (2N+1, 2M+1, 3) against the target lattice
    (N+1, M+1, 3) and the target's shape (:func:`rffqm_nlp.targets.shape.shape_fit`), relative to
    the target's diameter, as :class:`~rffqm_nlp.design.results.Fit` defines them (all but the
    pattern's side and angle measures)."""
    diameter = target.diameter()
    coarse = shape.coarse_grain(folded)
    rms = float(np.sqrt(np.mean(np.sum((coarse - target_points) ** 2, axis=-1))))
    pts = target_points.reshape(-1, 3)
    plane = np.linalg.svd(pts - pts.mean(0), compute_uv=False)[-1] / np.sqrt(len(pts))
    return {"rms": rms / diameter, "plane_rms": float(plane / diameter),
            **shape.shape_fit(folded, target)}


# ---------------------------------------------------------------------- solve steps
@dataclass
class _Record:
    """What a solve has done so far, over its stages and solvers: the iteration history
    (lists "iter", "objective", "inf_pr", "elapsed"), the counts and the build time."""

    callback: Callable[[dict], None] | None = None
    verbose: bool = False
    t0: float = field(default_factory=time.perf_counter)
    history: dict[str, list] = field(
        default_factory=lambda: {"iter": [], "objective": [], "inf_pr": [], "elapsed": []})
    iterations: int = 0
    gauss_newton_iterations: int = 0
    marched_iterations: int = 0
    build_time: float = 0.0
    start_moved: float = 0.0
    restoration_iterations: int = 0

    def log(self, objective: float, violation: float) -> None:
        """Record one iteration (of Levenberg-Marquardt; IPOPT's: :class:`_IterationLog`)."""
        entry = {"iter": len(self.history["iter"]), "objective": objective,
                 "inf_pr": violation, "elapsed": time.perf_counter() - self.t0}
        for key, value in entry.items():
            self.history[key].append(value)
        if self.callback is not None:
            self.callback(entry)

    def stats(self, options: SolveOptions, outcome: "_Outcome") -> SolveStats:
        """The statistics of a solve that ended with ``outcome``."""
        objective = np.nan if outcome.objective is None else float(outcome.objective)
        return SolveStats(
            status=outcome.status, success=outcome.success, iterations=self.iterations,
            build_time=self.build_time,
            solve_time=time.perf_counter() - self.t0 - self.build_time, objective=objective,
            solver=options.solver, transcription=options.transcription,
            hessian=options.hessian, gauss_newton_iterations=self.gauss_newton_iterations,
            marched_iterations=self.marched_iterations, start_moved=self.start_moved,
            restoration_iterations=self.restoration_iterations, history=self.history)


@dataclass(frozen=True)
class _Outcome:
    """How a solver run ended: its last point ``x``, status, success, objective, the best
    admissible point met (``best``) and IPOPT's solution (``sol``; None when only
    Levenberg-Marquardt ran)."""

    x: np.ndarray
    status: str
    success: bool
    objective: float | None
    best: np.ndarray | None
    sol: dict | None = None


def _handover(outcome: _Outcome) -> dict[str, Any] | None:
    """The multipliers that the next IPOPT phase (the exact Hessian after Gauss-Newton)
    starts from, or None when the run is done: stop_rms reached or a status of
    :data:`HANDOVER_STOP_STATUSES`."""
    if outcome.status == "Fit_Reached" or outcome.status in HANDOVER_STOP_STATUSES:
        return None
    return {"lam_g0": outcome.sol["lam_g"], "lam_x0": outcome.sol["lam_x"]}


def _raise_failure(nlp: transcription.NLP, outcome: _Outcome, stats: SolveStats,
                   iterations: int) -> None:
    """The named error of an unsuccessful solve."""
    if outcome.sol is None:
        raise SolverFailed(
            f"the marched Levenberg-Marquardt solve did not finish the design: status "
            f"{outcome.status} after {iterations} iterations; raise max_iter or time_limit",
            status=outcome.status, stats=stats, last_iterate=outcome.x,
            best_iterate=outcome.best)
    raise_for_ipopt(
        outcome.status, iterations, "the design",
        f"{_violation_report(nlp, outcome.sol)}; relax min_length, min_angle or mu_margin",
        "raise max_iter or time_limit, or relax tol", stats, outcome.x, outcome.best)


def _require_finite(values: dict[str, Any], stats: SolveStats, x: np.ndarray) -> None:
    """Raise SolverFailed (status "non_finite") when any of ``values`` holds NaN or inf."""
    bad = [name for name, value in values.items()
           if not np.all(np.isfinite(np.asarray(value, dtype=float)))]
    if bad:
        raise SolverFailed(f"the solve ended with NaN or inf in {' and '.join(bad)}; no design "
                           "is returned (check the weights and the target)",
                           status="non_finite", stats=stats, last_iterate=x)


def _transcription_of(solve: dict[str, Any]) -> str:
    """The transcription a [solve] table names (its default where it names none), read
    without the rest of the table: a result's design vector is laid out by it."""
    return check_value(solve.get("transcription", SolveOptions.transcription),
                       SOLVE_KEYS["transcription"], "[solve] transcription")


def _with_overrides(options: SolveOptions | None, overrides: dict[str, Any]) -> SolveOptions:
    """``options`` (default SolveOptions()) with SolveOptions fields given by name."""
    if options is not None and not isinstance(options, SolveOptions):
        raise InputError(f"options must be a SolveOptions, got {describe_value(options)}")
    for key in overrides:
        if key not in SOLVE_KEYS:
            raise InputError(f"solve(): {unknown_key(key, SOLVE_KEYS, '[solve]')}")
    return replace(options or SolveOptions(), **overrides)


def _violation_report(nlp: transcription.NLP, sol) -> str:
    g = sol["g"].full().ravel()
    viol = np.maximum(nlp.lbg - g, g - nlp.ubg)
    return f"largest constraint violation {viol.max():.3g} at constraint {int(viol.argmax())}"


class _IterationLog(ca.Callback):
    """IPOPT iteration callback: records objective and constraint violation per iteration,
    keeps the best admissible design met on the way (``best``) and asks IPOPT to stop once
    ``stop(x)`` holds at one (``reached_x``).

    An iterate is admissible when it satisfies every constraint and bound. Where it does not
    and the NLP can project it (``nlp.project``: the simultaneous transcription re-marches
    the iterate's boundary data), the projected point is judged instead, with its own
    objective: the simultaneous NLP meets its marching equations only near the optimum, but
    its earlier iterates' designs are often admissible and good (docs/solvers.md).
    """

    #: constraint violation below which an iterate counts as feasible for ``stop``
    FEASIBLE = 1e-9

    def __init__(self, nlp: transcription.NLP, history: dict, callback, stop=None,
                 previous: "_IterationLog | None" = None, t0: float | None = None):
        ca.Callback.__init__(self)
        self._stop = stop
        self.reached = False
        self.reached_x: np.ndarray | None = None
        self.reached_objective = np.nan
        # the best admissible iterate so far, of this run or of an earlier run on the same NLP
        self.best: np.ndarray | None = None if previous is None else previous.best
        self._best_objective = np.inf if previous is None else previous._best_objective
        self._nx, self._ng = nlp.x.numel(), nlp.g.numel()
        self._lbg, self._ubg = nlp.lbg, nlp.ubg
        self._lbx, self._ubx = nlp.lbx, nlp.ubx
        self._project = nlp.project
        if nlp.project is not None:
            self._fg = ca.Function("fg", [nlp.x], [nlp.objective, nlp.g])
        self._history = history
        self._callback = callback
        self._t0 = time.perf_counter() if t0 is None else t0  # "elapsed" counts from t0
        self.construct("iteration_log", {})

    def get_n_in(self):
        return ca.nlpsol_n_out()

    def get_n_out(self):
        return 1

    def get_name_in(self, i):
        return ca.nlpsol_out(i)

    def get_name_out(self, i):
        return "ret"

    def get_sparsity_in(self, i):
        n = ca.nlpsol_out(i)
        if n in ("f",):
            return ca.Sparsity.dense(1)
        if n in ("x", "lam_x"):
            return ca.Sparsity.dense(self._nx)
        if n in ("g", "lam_g"):
            return ca.Sparsity.dense(self._ng)
        return ca.Sparsity(0, 0)

    def eval(self, arg):
        g = np.asarray(arg[ca.nlpsol_out().index("g")]).ravel()
        viol = self._violation(g)
        entry = {"iter": len(self._history["iter"]),
                 "objective": float(arg[ca.nlpsol_out().index("f")]),
                 "inf_pr": viol, "elapsed": time.perf_counter() - self._t0}
        for key, value in entry.items():
            self._history[key].append(value)
        if self._callback is not None:
            self._callback(entry)
        x = np.asarray(arg[ca.nlpsol_out().index("x")]).ravel()
        objective = entry["objective"]
        if viol > self.FEASIBLE and self._project is not None:
            x = self._project(x)
            if x is None:
                return [int(self.reached)]
            f, g = self._fg(x)
            objective, viol = float(f), self._violation(g.full().ravel(), x)
        if viol <= self.FEASIBLE:
            if objective < self._best_objective:
                self.best, self._best_objective = x.copy(), objective
            if self._stop is not None and self._stop(x):
                self.reached, self.reached_x, self.reached_objective = True, x.copy(), objective
        return [int(self.reached)]

    def _violation(self, g: np.ndarray, x: np.ndarray | None = None) -> float:
        """Largest violation of the constraints at g (and of the bounds at x, if given)."""
        parts = [[0.0], self._lbg - g, g - self._ubg]
        if x is not None:
            parts += [self._lbx - x, x - self._ubx]
        return float(np.max(np.concatenate(parts)))


# ---------------------------------------------------------------------- multistart
#: Half-widths (radians) of the uniform perturbations of alpha0 and omega0 of the starts
#: 1, 2, ... of a multistart; the perturbed values are clipped into their valid ranges.
MULTISTART_SPREAD = {"alpha0": 0.3, "omega0": 0.6}


def multistart_starts(problem: DesignProblem, starts: int, seed: int) -> list[tuple[float, float]]:
    """(alpha0, omega0) of each start of a multistart: the problem's own first, then
    ``starts - 1`` seeded uniform perturbations by :data:`MULTISTART_SPREAD`, clipped to
    alpha0 in [min_angle + 0.05, pi/2 - 0.05] and omega0 inside ``omega_bounds`` (5% of
    their width away from each end)."""
    starts = check_value(starts, SOLVE_KEYS["multistart"], "[solve] multistart")
    seed = check_value(seed, SOLVE_KEYS["seed"], "[solve] seed")
    rng = np.random.default_rng(seed)
    lo, hi = problem.omega_bounds
    margin = 0.05 * (hi - lo)
    alpha = np.clip(problem.alpha0 + rng.uniform(-1, 1, starts - 1) * MULTISTART_SPREAD["alpha0"],
                    problem.min_angle + 0.05, PI / 2 - 0.05)
    omega = np.clip(problem.omega0 + rng.uniform(-1, 1, starts - 1) * MULTISTART_SPREAD["omega0"],
                    lo + margin, hi - margin)
    return [(problem.alpha0, problem.omega0)] + [(float(a), float(w)) for a, w in zip(alpha, omega)]


def solve_multistart(problem: DesignProblem, options: SolveOptions, *,
                     callback: Callable[[dict], None] | None = None,
                     warm_start: DesignResult | None = None,
                     verbose: bool = False) -> DesignResult:
    """Solve ``problem`` from each of the ``options.multistart`` starts of
    :func:`multistart_starts` (seeded by ``options.seed``); keep the best.

    A start that ends in :class:`InfeasibleDesign` or :class:`SolverFailed` is recorded and
    skipped; the result is the successful start with the smallest fit.rms, with the
    problem and options as asked (``result.problem``) and ``result.stats.multistart`` =
    {"starts", "seed", "chosen" (index of the kept start), "time" (all starts, s), "runs":
    one entry per start with alpha0, omega0, status, rms (None when it failed), iterations,
    time and reason}. When every start fails, raises :class:`InfeasibleDesign` if all were
    infeasible, else :class:`SolverFailed` with the status of the first failed solve.
    """
    if warm_start is not None:
        raise InputError("multistart and warm_start exclude each other: a warm start replaces "
                         "the starting Miuras that multistart varies")
    t0 = time.perf_counter()
    single = replace(options, multistart=1)
    runs: list[dict[str, Any]] = []
    errors: list[InfeasibleDesign | SolverFailed] = []
    best: tuple[int, DesignResult] | None = None
    for k, (alpha0, omega0) in enumerate(multistart_starts(problem, options.multistart,
                                                           options.seed)):
        t1 = time.perf_counter()
        run: dict[str, Any] = {"start": k, "alpha0": alpha0, "omega0": omega0}
        try:
            res = replace(problem, alpha0=alpha0, omega0=omega0).solve(
                single, callback=callback, verbose=verbose)
        except (InfeasibleDesign, SolverFailed) as exc:
            errors.append(exc)
            run.update(status=getattr(exc, "status", "") or "Infeasible_Problem_Detected",
                       rms=None, iterations=None, reason=one_line(exc))
        else:
            run.update(status=res.stats.status, rms=res.fit.rms,
                       iterations=res.stats.iterations, reason="")
            if best is None or res.fit.rms < best[1].fit.rms:
                best = (k, res)
        run["time"] = time.perf_counter() - t1
        runs.append(run)
    if best is None:
        statuses = ", ".join(sorted({r["status"] for r in runs}))
        message = (f"all {options.multistart} starts of the multistart failed ({statuses}); "
                   f"the problem's own start: {one_line(errors[0])}")
        failed = [e for e in errors if isinstance(e, SolverFailed)]
        if not failed:
            raise InfeasibleDesign(message) from errors[0]
        raise SolverFailed(message, status=failed[0].status, stats=failed[0].stats,
                           last_iterate=failed[0].last_iterate,
                           best_iterate=failed[0].best_iterate) from failed[0]
    chosen, res = best
    stats = replace(res.stats, multistart={
        "starts": options.multistart, "seed": options.seed, "chosen": chosen,
        "time": time.perf_counter() - t0, "runs": runs})
    return replace(res, stats=stats, problem=problem.config(options))
