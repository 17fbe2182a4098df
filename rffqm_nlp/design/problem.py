"""Inverse design (the paper's section "Discussion on the inverse problem", docs/paper.md): the
declarative problem.

:class:`DesignProblem` states what is designed: a target surface, a 2N x 2M pattern whose
coarse lattice r(i, j) = y^{(2i)(2j)} should match the target lattice, the Miura
mountain-valley assignment held fixed, the inline manufacturability constraints and the loss;
:meth:`DesignProblem.transcribe` states it as an NLP (:mod:`rffqm_nlp.design.transcription`).
How it is solved is a :class:`~rffqm_nlp.design.options.SolveOptions`;
:meth:`DesignProblem.solve` hands both to :mod:`rffqm_nlp.design.solve`, which returns a
:class:`~rffqm_nlp.design.results.DesignResult`. A design file has the tables [target],
[design] and [solve] (:mod:`rffqm_nlp.design.schema`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, Callable

import numpy as np

from ..errors import BoundaryDataError, InfeasibleDesign, InputError, MarchingError, one_line
from ..files import Key, check_table, describe_value
from ..model import numpy_model
from ..model.boundary import LAYOUTS, BoundaryData, miura_boundary, refine
from ..targets import shape, surfaces
from ..targets.curvature_target import Curvature
from . import transcription
from .options import SolveOptions, transcription_of, with_overrides
from .results import MAX_STATES, DesignResult
from .solve import solve

PI = np.pi
DEFAULT_WEIGHTS = {"position": 1.0, "forms": 0.1, "regularization": 0.1, "smoothness": 0.0}
#: The weights of a problem whose target is a :class:`Curvature` (docs/curvature_targets.md).
CURVATURE_WEIGHTS = {"curvature": 1.0, "size": 1.0, "regularization": 0.01, "smoothness": 0.0}
GROUPS = ("angles", "lengths", "omega")
#: What the target lattice is (DesignProblem.correspondence, docs/meshes.md).
CORRESPONDENCES = ("lattice", "free")

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
    "weights": Key("table", spec={name: Key("number", low=0.0)
                                  for name in {**DEFAULT_WEIGHTS, **CURVATURE_WEIGHTS}}),
    "correspondence": Key("choice", choices=CORRESPONDENCES),
}
#: The options of each state of a problem of several targets (DesignProblem's ``omega`` and
#: ``state_weights``; a design file's ``omega`` and ``weight`` in each [[target]] table).
STATE_KEYS = {
    "omega": Key("list", item=Key("number", low=-PI, high=PI, optional=True), least=2,
                 most=MAX_STATES, hint="(one per target; None: designed)"),
    "state_weights": Key("list", item=Key("number", low=0.0, low_open=True), least=2,
                         most=MAX_STATES, hint="(one per target)"),
}
#: Fields of DesignProblem that no [design] key names: the target(s) and the states' options.
NOT_DESIGN_KEYS = ("target", "other_targets", *STATE_KEYS)

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
class DesignProblem:
    """Which RFFQM pattern, perturbed from a Miura-ori, folds into ``target``?

    ``target``: a surface (:mod:`rffqm_nlp.targets.surfaces`: a built-in, a Custom, a Mesh)
    whose lattice the coarse lattice should match, or a curvature field
    (:class:`~rffqm_nlp.targets.curvature_target.Curvature`) whose curvatures it should
    have over a footprint of its size (docs/curvature_targets.md); or a list of 2 to
    :data:`~rffqm_nlp.design.results.MAX_STATES` of them: one sheet whose folded state at
    omega_k fits target k, each state with its own alignment (docs/several_states.md).
    ``targets`` holds them all, ``target`` then the first and ``other_targets`` the rest
    (``target=[A, B]`` is ``target=A, other_targets=(B,)``). With several targets:
    ``omega``, one per target, fixes omega_k where it is a number within ``omega_bounds``
    (None: designed), and
    ``state_weights`` (default all 1) multiply each state's loss.

    Parameters (all with defaults chosen so designs are manufacturable):

    * ``panels``: (2N, 2M) panels, both even; the coarse lattice is (N+1) x (M+1);
    * ``layout``, ``alpha0``, ``omega0``: the starting Miura-ori (docs/paper.md); its side
      lengths are chosen so that its coarse lattice at ``omega0`` has the target lattice's
      mean spacings. The default layout "zigzag_i" (zig-zag along the target's u) needs far
      fewer iterations than "zigzag_j" on the bundled targets (docs/decisions/design-problem.md);
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
      missing keys count as 0. A curvature target has "curvature" (its cells' curvatures
      against the prescription) and "size" (its lines' lengths against the footprint's)
      in place of "position" and "forms" (:data:`CURVATURE_WEIGHTS`,
      :mod:`rffqm_nlp.design.transcription.curvature_loss`);
    * ``correspondence``: "free" (the default: the lattice's (u, v) are a smooth map of
      the lattice indices whose few controls are design variables, kept in the domain and
      from folding over, :class:`rffqm_nlp.design.transcription.Correspondence`) or "lattice"
      (the target lattice is r on the uniform grid of the domain); "free" fits the shape
      closer for a few more iterations, measured in docs/meshes.md. A curvature target has
      no positions and no correspondence.

    How it is solved is a :class:`SolveOptions`, given to :meth:`solve`.
    """

    target: surfaces.Surface | Curvature
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
    omega: tuple[float | None, ...] | None = None
    state_weights: tuple[float, ...] | None = None
    other_targets: tuple[surfaces.Surface | Curvature, ...] = ()

    def __post_init__(self) -> None:
        self._check_targets()
        values = check_table({f.name: getattr(self, f.name) for f in fields(self)
                              if f.name not in NOT_DESIGN_KEYS}, DESIGN_KEYS, "[design]")
        values["weights"] = self._weights_of(values["weights"])
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
        for k, omega in enumerate(self.omega or ()):
            if omega is not None and not lo <= omega <= hi:
                raise InputError(f"omega[{k}] = {omega:g} lies outside omega_bounds = "
                                 f"[{lo:g}, {hi:g}]: fix it within them, or widen them")

    def _check_targets(self) -> None:
        """Set ``target`` (the first) and ``other_targets`` (the rest) from the target or
        list of targets given, and check the states' options (:data:`STATE_KEYS`)."""
        given = self.target
        listed = isinstance(given, Sequence) and not isinstance(given, (str, bytes))
        if listed and self.other_targets:
            raise InputError("give the targets either as target=[A, B, ...] or as target=A, "
                             "other_targets=(B, ...), not both")
        if not isinstance(self.other_targets, Sequence):
            raise InputError(f"other_targets must be a list of targets, got "
                             f"{describe_value(self.other_targets)}")
        targets = tuple(given) if listed else (given, *self.other_targets)
        several = len(targets) > 1
        if listed and not 2 <= len(targets) <= MAX_STATES or len(targets) > MAX_STATES:
            raise InputError(f"target must be one target or a list of 2 to {MAX_STATES} "
                             f"targets (one per state), got a list of {len(targets)}")
        for k, target in enumerate(targets):
            if not isinstance(target, (surfaces.Surface, Curvature)):
                where = f"target[{k}]" if several else "target"
                raise InputError(f"{where} must be a surface from rq.surfaces (get, Custom, "
                                 "Mesh, load) or a curvature field (rq.surfaces.Curvature), "
                                 f"got {describe_value(target)}")
        object.__setattr__(self, "target", targets[0])
        object.__setattr__(self, "other_targets", targets[1:])
        options = check_table({name: getattr(self, name) for name in STATE_KEYS
                               if getattr(self, name) is not None}, STATE_KEYS, "DesignProblem")
        for name, value in options.items():
            if len(value) != len(targets):
                raise InputError(f"{name} needs one entry per target ({len(targets)}), got "
                                 f"{len(value)}" + ("" if several else
                                                    "; a problem of one target fixes omega "
                                                    "with omega0 and fix = ['omega']"))
            object.__setattr__(self, name, value)

    @property
    def targets(self) -> tuple[surfaces.Surface | Curvature, ...]:
        """Every target, one per state."""
        return (self.target, *self.other_targets)

    @property
    def several(self) -> bool:
        """Does the problem design one sheet for several targets?"""
        return len(self.targets) > 1

    def state_options(self, k: int) -> tuple[float | None, float]:
        """(fixed omega or None, weight) of state k."""
        omega = None if self.omega is None else self.omega[k]
        return omega, 1.0 if self.state_weights is None else self.state_weights[k]

    def weights_of(self, target: surfaces.Surface | Curvature,
                   weights: dict[str, float] | None = None) -> dict[str, float]:
        """The loss weights of a state whose target is ``target``: ``weights`` (default the
        problem's), which are those of the first target's kind, where ``target`` is of that
        kind (surface or curvature), else that kind's defaults with their regularization."""
        weights = self.weights if weights is None else weights
        curvature = isinstance(target, Curvature)
        if curvature == isinstance(self.target, Curvature):
            return weights
        defaults = CURVATURE_WEIGHTS if curvature else DEFAULT_WEIGHTS
        return {**defaults, "regularization": weights["regularization"]}

    def _weights_of(self, given: dict[str, float]) -> dict[str, float]:
        """The weights of this problem's target kind, missing ones 0: a surface's
        (:data:`DEFAULT_WEIGHTS`' names) or a curvature target's (:data:`CURVATURE_WEIGHTS`'),
        the other kind's defaults replaced by this kind's; a positive weight of the other
        kind is refused."""
        curvature = isinstance(self.target, Curvature)
        names, other = ((CURVATURE_WEIGHTS, DEFAULT_WEIGHTS) if curvature
                        else (DEFAULT_WEIGHTS, CURVATURE_WEIGHTS))
        if given == other:
            given = names
        foreign = sorted(k for k, v in given.items() if k not in names and v > 0)
        if foreign:
            raise InputError(f"[design] weights {', '.join(foreign)} do not apply to "
                             f"{'a curvature' if curvature else 'a surface'} target; its "
                             f"weights are {', '.join(names)}")
        return {**dict.fromkeys(names, 0.0), **{k: v for k, v in given.items() if k in names}}

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
        guess, corr = start, self.correspondence_of()
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
            reference_omega=start.omega, correspondence=corr, controls=controls,
            curvature=(transcription.CurvatureLoss.of(self.target, self.N, self.M,
                                                      weights or self.weights)
                       if isinstance(self.target, Curvature) else None))
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
        # the coarse design's deviations from its Miura-ori go onto this problem's Miura-ori
        # (whatever design ``start`` holds: the closed form is a start of its own)
        coarse_miura = replace(self, panels=(n, m)).start().boundary
        try:
            boundary = refine(initial.boundary, coarse_miura, self.start().boundary)
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
            initial.x, transcription_of(solve), corr.size)
        lower, upper = corr.bounds()
        if controls.size != corr.size or np.any(controls < lower) or np.any(controls > upper):
            return None
        return controls

    def correspondence_of(self, target: surfaces.Surface | Curvature | None = None,
                          swap: bool = False, controls: int | None = None
                          ) -> transcription.Correspondence | None:
        """The free correspondence from the uniform grid onto ``target`` (default the
        problem's first), of the lattice's shape ((M+1, N+1) with ``swap``, whose
        transpose lies on the pattern: :func:`rffqm_nlp.design.transcription.oriented`),
        with ``controls`` a side (default
        :data:`~rffqm_nlp.design.transcription.GRID_CONTROLS`); None with "lattice", and
        for a curvature target, which prescribes no positions."""
        target = self.target if target is None else target
        if self.correspondence != "free" or isinstance(target, Curvature):
            return None
        shape = (self.M + 1, self.N + 1) if swap else (self.N + 1, self.M + 1)
        return transcription.Correspondence.uniform(target.casadi_function(), target.domain,
                                                    shape, controls)

    def grid(self, result: DesignResult) -> tuple[np.ndarray, np.ndarray] | None:
        """The grid (U, V), each (N+1, M+1), of a free correspondence at ``result`` (a
        result of this problem, read from its design vector); None with "lattice". A
        design of several states has a grid per state and is refused."""
        if self.several:
            raise InputError("grid() reads the one grid of a design of one state; this "
                             "problem has several targets")
        corr = self.correspondence_of()
        if corr is None:
            return None
        controls = transcription.controls_of(
            result.x, transcription_of(result.problem["solve"]), corr.size)
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
        With ``options.multistart`` > 1 see
        :func:`rffqm_nlp.design.multistart.solve_multistart`; how it is solved:
        :mod:`rffqm_nlp.design.solve`.
        Raises :class:`InputError` before any work when the solve needs more memory than
        this machine has available (:func:`rffqm_nlp.design.solve.check_memory`),
        :class:`InfeasibleDesign` when the constraints cannot hold, :class:`SolverFailed`
        (with the solver's status, the statistics, the last iterate and the best admissible
        one) otherwise, status "non_finite" when the solve ended with a
        NaN or inf in the design, the objective or the fit.
        """
        return solve(self, with_overrides(options, overrides), callback=callback,
                     warm_start=warm_start, verbose=verbose)

    def check_reachable(self) -> None:
        """Raise :class:`InfeasibleDesign` when no pattern can meet the constraints
        whatever the solver does."""
        if self.min_length >= 1:
            raise InfeasibleDesign(
                f"min_length = {self.min_length} asks every side to be at least the mean side, "
                "which only equal sides satisfy; choose min_length < 1 (default 0.2)")

    def stage_weights(self, factor: float) -> dict[str, float]:
        """The loss weights of a continuation stage: regularization times ``factor``."""
        return dict(self.weights, regularization=factor * self.weights["regularization"])

    # ------------------------------------------------------------------ configuration
    def to_config(self) -> dict[str, Any]:
        """The problem as TOML-ready tables: {"target": ..., "design": ...}. A target that no
        table can name (a lambda, a closure, a Mesh made from arrays) is recorded as not
        rebuildable (:func:`rffqm_nlp.targets.surfaces.config_of`)."""
        design = {f.name: getattr(self, f.name) for f in fields(self)
                  if f.name not in NOT_DESIGN_KEYS}
        design.update(weights=dict(self.weights), panels=list(self.panels),
                      omega_bounds=list(self.omega_bounds), fix=list(self.fix))
        if not self.several:
            return {"target": surfaces.config_of(self.target), "design": design}
        targets = []
        for k, target in enumerate(self.targets):
            omega, weight = self.state_options(k)
            targets.append({**surfaces.config_of(target),
                            **({} if omega is None else {"omega": omega}),
                            **({} if weight == 1.0 else {"weight": weight})})
        return {"target": targets, "design": design}

    def config(self, options: SolveOptions) -> dict[str, Any]:
        """{"target", "design", "solve"}: this problem solved with ``options``."""
        return {**self.to_config(), "solve": options.to_config()}
