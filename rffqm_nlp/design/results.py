"""The outcome of an inverse design: :class:`DesignResult` with its typed :class:`Fit` and
:class:`SolveStats`, and one versioned file format, validated when read."""

from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from ..errors import InputError, RffqmError
from ..files import (Key, check_table, check_value, describe_value, jsonable, read_json,
                     write_json)
from ..model import numpy_model
from ..model.boundary import BoundaryData
from ..model.pattern import Pattern, check_omega
from ..targets import surfaces
from ..targets.curvature import Curvature
from ..targets.shape import coarse_grain
from .checks import (agree, check_numbers, check_rotation, checked_pattern, finite, named,
                     required, stored_curvature, stored_target_grid)

if TYPE_CHECKING:  # plotly is imported by the view, on use
    import plotly.graph_objects

FORMAT = "rffqm-nlp design result"
#: 3: a result may hold several states ("states"); a version 2 file is read as it is.
VERSION = 3
#: Most states of one sheet (DesignProblem's targets; a result's "states" and one more).
MAX_STATES = 8
FILENAME = "result.json"
#: Keys of a version 1 result's "design" table that version 2 keeps in "solve".
V1_SOLVE_KEYS = ("continuation", "transcription", "solver", "hessian", "damping", "max_iter",
                 "tol", "time_limit", "stop_rms", "barrier_init", "ipopt_options")
#: Samples per direction of a rebuilt target surface drawn as a mesh (:func:`target_mesh`).
TARGET_MESH = 60

#: What each key of a result's "fit" table allows (:meth:`Fit.from_dict`).
FIT_KEYS: dict[str, Key] = {
    **{name: Key("number", low=0.0, required=True)
       for name in ("rms", "rms_surface", "hausdorff", "plane_rms", "min_side_over_mean")},
    "min_sector_angle": Key("number", low=0.0, high=math.pi, required=True),
    "collision_free": Key("bool", optional=True),
    "first_contact_omega": Key("number", low=-math.pi, high=math.pi, optional=True),
    **{name: Key("number", low=0.0, optional=True)
       for name in ("rms_surface_vertices", "hausdorff_vertices", "coverage",
                    "curvature_rms", "curvature_max")},
}
#: A result's notes (DesignResult.notes).
NOTES_KEY = Key("list", item=Key("string"), most=100)
#: The lists of a solve's history, one entry per iteration.
HISTORY_KEYS: dict[str, Key] = {
    "iter": Key("list", item=Key("whole", low=0), required=True),
    "objective": Key("list", item=Key("number"), required=True),
    "inf_pr": Key("list", item=Key("number", low=0.0), required=True),
    "elapsed": Key("list", item=Key("number", low=0.0), required=True),
}
#: One start of a multistart's record (see :func:`rffqm_nlp.design.multistart.solve_multistart`).
MULTISTART_RUN_KEYS: dict[str, Key] = {
    "start": Key("whole", low=0, required=True),
    "alpha0": Key("number", low=0.0, high=math.pi, required=True),
    "omega0": Key("number", low=-math.pi, high=math.pi, required=True),
    "status": Key("string", required=True),
    "rms": Key("number", low=0.0, optional=True),
    "iterations": Key("whole", low=0, optional=True),
    "reason": Key("string", required=True),
    "time": Key("number", low=0.0, required=True),
}
#: The record of a multistart (SolveStats.multistart).
MULTISTART_KEYS: dict[str, Key] = {
    "starts": Key("whole", low=1, required=True),
    "seed": Key("whole", low=0, required=True),
    "chosen": Key("whole", low=0, required=True),
    "time": Key("number", low=0.0, required=True),
    "runs": Key("list", item=Key("table", spec=MULTISTART_RUN_KEYS), required=True),
}
#: What each key of a result's "stats" table allows (:meth:`SolveStats.from_dict`).
STATS_KEYS: dict[str, Key] = {
    "status": Key("string", required=True),
    "success": Key("bool", required=True),
    "iterations": Key("whole", low=0, required=True),
    "build_time": Key("number", low=0.0, required=True),
    "solve_time": Key("number", low=0.0, required=True),
    "objective": Key("number", required=True),
    "solver": Key("string", required=True),
    "transcription": Key("string", required=True),
    "hessian": Key("string", required=True),
    "gauss_newton_iterations": Key("whole", low=0),
    "marched_iterations": Key("whole", low=0),
    "start_moved": Key("number", low=0.0, high=1.0),
    "restoration_iterations": Key("whole", low=0),
    "history": Key("table", spec=HISTORY_KEYS),
    "multistart": Key("table", spec=MULTISTART_KEYS, optional=True),
}


@dataclass(frozen=True)
class Fit:
    """How well a design fits its target; lengths relative to the target's diameter.

    * ``rms``: RMS distance of the aligned coarse lattice to the target lattice
      (corresponding points);
    * ``rms_surface``, ``hausdorff``: RMS and largest distance of the coarse lattice to the
      target's shape (exact closest points on r(u, v) over the domain, or on the mesh of a
      :class:`~rffqm_nlp.targets.meshes.Mesh`);
    * ``rms_surface_vertices``, ``hausdorff_vertices``: the same for every folded vertex;
    * ``coverage``: the area of the coarse lattice (two triangles per cell) over the area of
      r(u, v) over the target's domain (:func:`rffqm_nlp.targets.shape.surface_area`);
    * ``plane_rms``: RMS distance of the target lattice to its best-fitting plane (the fit a
      flat sheet reaches, for comparison);
    * ``min_side_over_mean``: the smallest side length over the mean side length;
    * ``min_sector_angle``: the smallest sector angle (radians);
    * ``collision_free``: whether the motion from omega = 0 to the designed omega is free
      of self-contact: no flat overlap and no two panels that share no vertex touching
      (:func:`rffqm_nlp.contact.collisions.collisions`); ``first_contact_omega``: the omega of the
      first contact, or None (not relative: radians). Both None in a result saved before
      the check.

    * ``curvature_rms``, ``curvature_max``: the Gaussian curvature error of the coarse
      lattice's cells against the target's K (a surface's, or a curvature target's
      prescription) over the largest |K|, RMS and largest
      (:func:`rffqm_nlp.design.curvature_fit.curvature_errors`; per cell:
      :func:`~rffqm_nlp.design.curvature_fit.cell_errors` of ``result.curvature``).

    For a curvature target (:class:`~rffqm_nlp.targets.curvature_target.Curvature`), which
    prescribes no positions, ``rms``, ``rms_surface`` and ``hausdorff`` are 0 and
    ``coverage`` is over the footprint's area
    (:func:`rffqm_nlp.design.curvature_fit.curvature_target_fit`).

    The three shape fits added with meshes as targets, and the two curvature errors, are
    None in a result saved before them (not measured).
    """

    rms: float
    rms_surface: float
    hausdorff: float
    plane_rms: float
    min_side_over_mean: float
    min_sector_angle: float
    collision_free: bool | None = None
    first_contact_omega: float | None = None
    rms_surface_vertices: float | None = None
    hausdorff_vertices: float | None = None
    coverage: float | None = None
    curvature_rms: float | None = None
    curvature_max: float | None = None

    def to_dict(self) -> dict[str, float | None]:
        """{field: value}, JSON-ready (None for a shape fit not measured)."""
        return {f.name: _fit_value(f.name, getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Fit":
        """Inverse of :meth:`to_dict`, every key checked by :data:`FIT_KEYS` (a finite
        number in its range, ``collision_free`` true or false; the fields without a default
        must be present, those with one may be None or left out); else :class:`InputError`
        naming the key (``fit.rms``) and what it allows."""
        values = check_table(d, FIT_KEYS, "fit")
        return cls(**{name: value for name, value in values.items() if value is not None})


def _fit_value(name: str, value: Any) -> float | bool | None:
    """A Fit field's value as stored: None stays None, ``collision_free`` a bool (a JSON
    true or false, else InputError), every other field a float."""
    if value is None:
        return None
    if name == "collision_free":
        if not isinstance(value, (bool, np.bool_)):
            raise InputError(f"fit.collision_free must be true or false, got {value!r}")
        return bool(value)
    return float(value)


@dataclass(frozen=True)
class SolveStats:
    """How a design was solved.

    * ``status``: the solver's final status ("Solve_Succeeded", "Fit_Reached" when
      stop_rms was reached, "Closed_Form" for solver "closed-form", or IPOPT's/the
      Levenberg-Marquardt solver's failure status);
      ``success``: whether that status is a success;
    * ``iterations``: all iterations, of every solver and continuation stage;
      ``gauss_newton_iterations``: those of IPOPT with the Gauss-Newton Hessian;
      ``marched_iterations``: those of Levenberg-Marquardt on the marching manifold;
    * ``start_moved``: where a warm start broke a constraint, the fraction of the way to the
      Miura's boundary data that Levenberg-Marquardt moved it before its first step (0: it
      started from the warm start as given);
    * ``restoration_iterations``: those of ``marched_iterations`` that Levenberg-Marquardt
      took from a start that broke a constraint toward one that holds them all (the Miura
      start where ``min_length`` is above its smallest side, a warm start that no move
      repaired, a clearance round's start; :mod:`rffqm_nlp.design.solvers.levenberg_marquardt`);
    * ``build_time``, ``solve_time``: seconds spent building the NLPs and solvers, and the rest;
    * ``objective``: the final objective (the loss);
    * ``solver``, ``transcription``, ``hessian``: the options they ran with;
    * ``history``: per iteration, lists "iter", "objective", "inf_pr" (largest constraint
      violation) and "elapsed" (seconds since the solve started);
    * ``multistart``: None, or the record of a multistart (see
      :func:`rffqm_nlp.design.multistart.solve_multistart`).
    """

    status: str
    success: bool
    iterations: int
    build_time: float
    solve_time: float
    objective: float
    solver: str
    transcription: str
    hessian: str
    gauss_newton_iterations: int = 0
    marched_iterations: int = 0
    start_moved: float = 0.0
    restoration_iterations: int = 0
    history: dict[str, list[float]] = field(
        default_factory=lambda: {"iter": [], "objective": [], "inf_pr": [], "elapsed": []})
    multistart: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        """{field: value}, JSON-ready (``multistart`` left out when None)."""
        out = jsonable(asdict(self))
        if self.multistart is None:
            out.pop("multistart")
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "SolveStats":
        """Inverse of :meth:`to_dict`, every key checked by :data:`STATS_KEYS` (finite
        numbers, whole numbers >= 0, the history's four lists of one length, the multistart
        record); fields with defaults may be missing. Else :class:`InputError` naming the
        key (``stats.iterations``) and what it allows."""
        values = check_table(d, STATS_KEYS, "stats")
        if values.get("multistart") is None:
            values.pop("multistart", None)
        if "history" in values:
            history = {key: list(values["history"][key]) for key in HISTORY_KEYS}
            lengths = {len(series) for series in history.values()}
            if len(lengths) > 1:
                raise InputError("stats.history must hold lists of one length (one entry per "
                                 "iteration), got " + ", ".join(
                                     f"{key} of {len(series)}" for key, series in history.items()))
            values["history"] = history
        if "multistart" in values:
            record = dict(values["multistart"])
            record["runs"] = [dict(run) for run in record["runs"]]
            if record["chosen"] >= len(record["runs"]):
                raise InputError(f"stats.multistart.chosen must be the number of one of its "
                                 f"{len(record['runs'])} runs, got {record['chosen']}")
            values["multistart"] = record
        return cls(**values)


@dataclass(frozen=True)
class State:
    """One designed state of a sheet: its fold parameter ``omega``; ``folded`` (2N+1, 2M+1,
    3), the vertices at ``omega`` moved rigidly onto its target (``rotation @ y +
    translation``, ``rotation`` (3, 3), ``translation`` (3,)); its target lattice
    ``target_points`` (N+1, M+1, 3); its :class:`Fit`; its ``curvature`` maps and
    ``target_grid`` as :class:`DesignResult` defines them."""

    omega: float
    folded: np.ndarray
    target_points: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    fit: Fit
    curvature: Curvature | None = None
    target_grid: np.ndarray | None = None

    @property
    def coarse(self) -> np.ndarray:
        """The coarse-grained folded lattice r(i, j) = y^{(2i)(2j)}, aligned to the target."""
        return coarse_grain(self.folded)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (``curvature`` and ``target_grid`` left out when None)."""
        optional: dict[str, Any] = {}
        if self.curvature is not None:
            optional["curvature"] = self.curvature.to_dict()
        if self.target_grid is not None:
            optional["target_grid"] = np.asarray(self.target_grid).tolist()
        return {"omega": self.omega, "folded": np.asarray(self.folded).tolist(),
                "target_points": np.asarray(self.target_points).tolist(),
                "rotation": np.asarray(self.rotation).tolist(),
                "translation": np.asarray(self.translation).tolist(),
                "fit": self.fit.to_dict(), **optional}


@dataclass(frozen=True)
class DesignResult:
    """A solved design.

    * ``boundary``: the designed boundary data; ``omega``: the designed fold parameter;
    * ``pattern``: the crease pattern re-marched with the NumPy model;
    * ``folded``: (2N+1, 2M+1, 3) vertices at ``omega``, moved rigidly onto the target
      (``rotation @ y + translation``); ``rotation`` (3, 3), ``translation`` (3,);
    * ``target_points``: (N+1, M+1, 3) target lattice;
    * ``fit``: a :class:`Fit`; ``stats``: a :class:`SolveStats`;
    * ``problem``: {"target", "design", "solve"}: the problem and the options it was solved
      with, as TOML-ready tables;
    * ``x``: the solver's final design vector (for warm starts);
    * ``curvature``: the :class:`~rffqm_nlp.targets.curvature.Curvature` maps of the design and
      the target, each (N/2 - 1, M/2 - 1) (None when not computed);
    * ``target_grid``: (n, m, 3) samples of the target surface, uniform in its parameters,
      kept when ``problem["target"]`` cannot rebuild it (a lambda or closure: see
      :func:`rffqm_nlp.targets.surfaces.config_of`), else None;
    * ``notes``: sentences on the design a reader should know, e.g. for a curvature target
      whether a surface realises the prescription and where the error sits
      (:func:`rffqm_nlp.design.curvature_fit.curvature_notes`); () in a result saved before;
    * ``other_states``: the states after the first of one sheet designed for several
      targets (docs/several_states.md), each a :class:`State`; () for one target.
      ``states`` holds every state, the first being the fields above (``omega``,
      ``folded``, ``fit``, ...), which the files, pictures and makers of one state use.

    In a notebook a result shows its interactive view (:mod:`rffqm_nlp.show.view`).
    """

    boundary: BoundaryData
    omega: float
    pattern: Pattern
    folded: np.ndarray
    target_points: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    fit: Fit
    stats: SolveStats
    problem: dict[str, Any] = field(default_factory=dict)
    x: np.ndarray = field(default_factory=lambda: np.zeros(0))
    curvature: Curvature | None = None
    target_grid: np.ndarray | None = None
    notes: tuple[str, ...] = ()
    other_states: tuple[State, ...] = ()

    @property
    def coarse(self) -> np.ndarray:
        """The coarse-grained folded lattice r(i, j) = y^{(2i)(2j)}, aligned to the target."""
        return coarse_grain(self.folded)

    @property
    def states(self) -> tuple[State, ...]:
        """Every designed state: the first (this result's own omega, folded, fit, ...),
        then ``other_states``."""
        first = State(omega=self.omega, folded=self.folded, target_points=self.target_points,
                      rotation=self.rotation, translation=self.translation, fit=self.fit,
                      curvature=self.curvature, target_grid=self.target_grid)
        return (first, *self.other_states)

    def _repr_html_(self) -> str:
        """The interactive view in a notebook (:func:`rffqm_nlp.show.view.repr_html`)."""
        # up a floor, on use: a result shows itself (README), the view floor reads results
        from ..show.view import repr_html

        return repr_html(self)

    def view(self, frames: int = 24) -> plotly.graph_objects.Figure:
        """The interactive view as a plotly Figure (:func:`rffqm_nlp.show.view.figure`)."""
        # up a floor, on use, as in _repr_html_
        from ..show.view import figure

        return figure(self, frames)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the whole result: the first state's fields at the top
        (``curvature`` and ``target_grid`` left out when None), ``notes`` when there are
        any, ``states`` (the other states, :meth:`State.to_dict`) when there are any."""
        optional: dict[str, Any] = {"notes": list(self.notes)} if self.notes else {}
        if self.other_states:
            optional["states"] = [state.to_dict() for state in self.other_states]
        return {
            "format": FORMAT, "version": VERSION,
            "boundary": self.boundary.to_dict(), **self.states[0].to_dict(),
            "pattern": self.pattern.to_dict(), "stats": self.stats.to_dict(),
            "problem": jsonable(self.problem), "x": np.asarray(self.x).tolist(), **optional,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = FILENAME) -> "DesignResult":
        """Inverse of :meth:`to_dict`: checks the format and version (a version 1 result is
        migrated, :func:`migrate_v1`), that no number anywhere is NaN, infinite or too
        large for a float, every array's shape, the pattern and the folded state against
        the boundary data re-marched, omega in [-pi, pi], the rotation a proper rotation
        (orthonormal to :data:`rffqm_nlp.design.checks.ROTATION_TOL`, determinant +1)
        (:mod:`rffqm_nlp.design.checks`), and the fit and statistics key by key
        (:data:`FIT_KEYS`, :data:`STATS_KEYS`). ``source`` names the file in the errors,
        each one :class:`InputError` line."""
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise InputError(f"{source}: not a design result written by rffqm-nlp")
        try:
            check_numbers(d, source)
            if d.get("version") == 1:
                d = migrate_v1(d)
            if d.get("version") == 2:     # version 3 added "states", which it has none of
                d = {**d, "version": VERSION}
            if d.get("version") != VERSION:
                version = d.get("version")
                shown = (version if isinstance(version, int) and not isinstance(version, bool)
                         and abs(version) < 10**6 else describe_value(version))
                raise InputError(f"{source}: design result version {shown} is not supported "
                                 f"(this rffqm-nlp reads versions 1 to {VERSION})")
            return _checked(d, source)
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as exc:
            if isinstance(exc, RffqmError):
                raise
            raise InputError(f"{source}: broken design result ({type(exc).__name__} while "
                             "reading it); run the design again") from None

    def save(self, directory: str | os.PathLike) -> Path:
        """Write ``result.json`` into ``directory`` (created if needed), atomically; a
        NaN or inf anywhere is refused (:class:`InputError`) and nothing is written."""
        path = Path(directory) / FILENAME
        path.parent.mkdir(parents=True, exist_ok=True)
        write_json(path, self.to_dict())
        return path

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "DesignResult":
        """Read a result saved by :meth:`save` (a folder, or the ``result.json`` itself),
        validated as :meth:`from_dict` says; anything that is not one (no file, a FIFO, a
        device, not JSON, a broken result) is an :class:`InputError`."""
        path = Path(directory)
        if path.is_dir():
            path = path / FILENAME
        return cls.from_dict(read_json(path, "design result"), source=str(path))


def target_mesh(result: DesignResult, target: surfaces.Surface | None = None,
                trust: bool = False, n: int = TARGET_MESH, state: int = 0) -> trimesh.Trimesh:
    """The target of ``result.states[state]`` as a triangle mesh in that state's target
    frame (that of its ``folded``), for pictures: ``target`` when given, else the state's
    kept ``target_grid`` (two triangles per cell), else the surface rebuilt from
    ``result.problem["target"]`` (of a design of several states: its entry ``state``; code
    that it names is run only with ``trust``). A :class:`~rffqm_nlp.targets.meshes.Mesh`
    made from a triangle mesh gives those triangles, any other surface its n x n sample
    (:meth:`Surface.mesh`).

    Raises :class:`RffqmError` (one line) when the target cannot be rebuilt; draw the
    state's ``target_points`` then.
    """
    kept = result.target_grid if state == 0 else result.states[state].target_grid
    if target is None and kept is not None:
        grid = np.asarray(kept, dtype=float)
        return trimesh.Trimesh(vertices=grid.reshape(-1, 3),
                               faces=surfaces.grid_faces(*grid.shape[:2]), process=False)
    if target is None:
        if not isinstance(result.problem, dict) or "target" not in result.problem:
            raise InputError("the result's problem has no [target] table to rebuild the "
                             "target from")
        table = result.problem["target"]
        if isinstance(table, list):  # several states: the state's own keys are not its target's
            table = {key: value for key, value in table[state].items()
                     if key not in ("omega", "weight")}
        target = surfaces.from_config(table, trust=trust)
    if isinstance(target, surfaces.Mesh) and target.mesh is not None:
        return target.mesh.copy()  # the shape itself, not its spline
    return surfaces.Surface.mesh(target, n, n)


def migrate_v1(d: dict[str, Any]) -> dict[str, Any]:
    """A version 1 result as version 2: the solve options move from problem["design"] to
    problem["solve"]."""
    problem = dict(d.get("problem", {}))
    design = dict(problem.get("design", {}))
    solve = {key: design.pop(key) for key in V1_SOLVE_KEYS if key in design}
    return {**d, "version": 2, "problem": {**problem, "design": design, "solve": solve}}


def _checked(d: dict[str, Any], source: str) -> DesignResult:
    """The result of a version 3 dict, every array checked (see DesignResult.from_dict)."""
    for key in ("left", "bottom", "l_left", "l_bottom"):
        finite(required(d, "boundary", source), key, source, f"boundary.{key}")
    with named(source, "boundary"):
        bd = BoundaryData.from_dict(d["boundary"])
    x = finite(d, "x", source)
    if x.ndim != 1:
        raise InputError(f"{source}: x must be a flat list of numbers, got shape {x.shape}")
    pattern = checked_pattern(required(d, "pattern", source), source, boundary=bd)
    first = _checked_state(d, source, pattern)
    others = d.get("states", [])
    if not isinstance(others, list) or len(others) > MAX_STATES - 1:
        raise InputError(f"{source}: states must be a list of at most {MAX_STATES - 1} "
                         f"states, got {describe_value(others)}")
    states = tuple(_checked_state(state, f"{source}: states[{k}]", pattern)
                   for k, state in enumerate(others))
    with named(source):
        stats = SolveStats.from_dict(required(d, "stats", source))
    problem = required(d, "problem", source)
    if not isinstance(problem, dict):
        raise InputError(f"{source}: problem must be a table, got {describe_value(problem)}")
    return DesignResult(
        boundary=bd, omega=first.omega, pattern=pattern, folded=first.folded,
        target_points=first.target_points, rotation=first.rotation,
        translation=first.translation, fit=first.fit, stats=stats, problem=dict(problem),
        x=x, curvature=first.curvature, target_grid=first.target_grid,
        notes=check_value(d.get("notes", ()), NOTES_KEY, f"{source}: notes"),
        other_states=states)


def _checked_state(d: Any, source: str, pattern: Pattern) -> State:
    """One state of a result (the top of its dict, or an entry of its "states"), every
    array checked against ``pattern``: shapes, omega in [-pi, pi], a proper rotation, the
    folded state the pattern folded at omega and moved, the fit key by key."""
    if not isinstance(d, dict):
        raise InputError(f"{source} must be a table, got {describe_value(d)}")
    arrays = {key: finite(d, key, source) for key in
              ("omega", "folded", "target_points", "rotation", "translation")}
    N, M = pattern.N, pattern.M
    shapes = {"omega": (), "folded": (N + 1, M + 1, 3),
              "target_points": (N // 2 + 1, M // 2 + 1, 3), "rotation": (3, 3),
              "translation": (3,)}
    for key, expected in shapes.items():
        if arrays[key].shape != expected:
            raise InputError(f"{source}: {key} has shape {arrays[key].shape}, expected "
                             f"{expected} for the boundary's {N} x {M} panels")
    with named(source):
        omega = float(check_omega(arrays["omega"]))
    rotation = arrays["rotation"]
    check_rotation(rotation, source)
    with np.errstate(all="ignore"):         # an overflow is refused below (agree)
        Y = numpy_model.fold(pattern, omega) @ rotation.T + arrays["translation"]
    agree(arrays["folded"], Y, source, "folded does not match the pattern folded at omega "
           "and moved by the stored rotation and translation")
    with named(source):
        fit = Fit.from_dict(required(d, "fit", source))
    return State(omega=omega, folded=arrays["folded"], target_points=arrays["target_points"],
                 rotation=rotation, translation=arrays["translation"], fit=fit,
                 curvature=stored_curvature(d, source, (N // 2 - 1, M // 2 - 1)),
                 target_grid=stored_target_grid(d, source))
