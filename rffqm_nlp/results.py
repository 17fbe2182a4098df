"""The outcome of an inverse design: :class:`DesignResult` with its typed :class:`Fit` and
:class:`SolveStats`, and one versioned file format, validated when read."""

from __future__ import annotations

import os
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from . import numpy_model, surfaces
from .boundary import BoundaryData
from .curvature import Curvature
from .errors import InputError, RffqmError, one_line
from .files import jsonable, read_json, write_json
from .pattern import Pattern
from .shape import coarse_grain

if TYPE_CHECKING:  # plotly is imported by the view, on use
    import plotly.graph_objects

FORMAT = "rffqm-nlp design result"
VERSION = 2
FILENAME = "result.json"
#: Relative agreement required between a stored array and its recomputation on load.
REMARCH_RTOL = 1e-9
#: Keys of a version 1 result's "design" table that version 2 keeps in "solve".
V1_SOLVE_KEYS = ("continuation", "transcription", "solver", "hessian", "damping", "max_iter",
                 "tol", "time_limit", "stop_rms", "barrier_init", "ipopt_options")
#: Samples per direction of a rebuilt target surface drawn as a mesh (:func:`target_mesh`).
TARGET_MESH = 60


@dataclass(frozen=True)
class Fit:
    """How well a design fits its target; lengths relative to the target's diameter.

    * ``rms``: RMS distance of the aligned coarse lattice to the target lattice
      (corresponding points);
    * ``rms_surface``, ``hausdorff``: RMS and largest distance of the coarse lattice to the
      target's shape (exact closest points on r(u, v) over the domain, or on the mesh of a
      :class:`~rffqm_nlp.meshes.Mesh`);
    * ``rms_surface_vertices``, ``hausdorff_vertices``: the same for every folded vertex;
    * ``coverage``: the area of the coarse lattice (two triangles per cell) over the area of
      r(u, v) over the target's domain (:func:`rffqm_nlp.shape.surface_area`);
    * ``plane_rms``: RMS distance of the target lattice to its best-fitting plane (the fit a
      flat sheet reaches, for comparison);
    * ``min_side_over_mean``: the smallest side length over the mean side length;
    * ``min_sector_angle``: the smallest sector angle (radians);
    * ``collision_free``: whether the motion from omega = 0 to the designed omega is free
      of self-contact: no flat overlap and no two panels that share no vertex touching
      (:func:`rffqm_nlp.collisions.collisions`); ``first_contact_omega``: the omega of the
      first contact, or None (not relative: radians). Both None in a result saved before
      the check.

    The three shape fits added with meshes as targets are None in a result saved before
    them (not measured).
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

    def to_dict(self) -> dict[str, float | None]:
        """{field: value}, JSON-ready (None for a shape fit not measured)."""
        return {f.name: _fit_value(f.name, getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "Fit":
        """Inverse of :meth:`to_dict`; every field without a default must be present."""
        values = {f.name: _required(d, f.name, "fit") for f in fields(cls)
                  if f.default is MISSING or d.get(f.name) is not None}
        return cls(**{name: _fit_value(name, value) for name, value in values.items()})


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
      stop_rms was reached, or IPOPT's/the Levenberg-Marquardt solver's failure status);
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
      repaired, a clearance round's start; :mod:`rffqm_nlp.reduced`);
    * ``build_time``, ``solve_time``: seconds spent building the NLPs and solvers, and the rest;
    * ``objective``: the final objective (the loss);
    * ``solver``, ``transcription``, ``hessian``: the options they ran with;
    * ``history``: per iteration, lists "iter", "objective", "inf_pr" (largest constraint
      violation) and "elapsed" (seconds since the solve started);
    * ``multistart``: None, or the record of a multistart (see
      :func:`rffqm_nlp.design.solve_multistart`).
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
        """Inverse of :meth:`to_dict`; fields with defaults may be missing."""
        values = {f.name: d[f.name] for f in fields(cls) if f.name in d}
        for f in fields(cls):
            if f.name not in values and f.default is MISSING and f.default_factory is MISSING:
                _required(d, f.name, "stats")
        return cls(**values)


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
    * ``curvature``: the :class:`~rffqm_nlp.curvature.Curvature` maps of the design and
      the target, each (N/2 - 1, M/2 - 1) (None when not computed);
    * ``target_grid``: (n, m, 3) samples of the target surface, uniform in its parameters,
      kept when ``problem["target"]`` cannot rebuild it (a lambda or closure: see
      :func:`rffqm_nlp.surfaces.config_of`), else None.

    In a notebook a result shows its interactive view (:mod:`rffqm_nlp.view`).
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

    @property
    def coarse(self) -> np.ndarray:
        """The coarse-grained folded lattice r(i, j) = y^{(2i)(2j)}, aligned to the target."""
        return coarse_grain(self.folded)

    def _repr_html_(self) -> str:
        """The interactive view in a notebook (:func:`rffqm_nlp.view.repr_html`)."""
        from .view import repr_html

        return repr_html(self)

    def view(self, frames: int = 24) -> plotly.graph_objects.Figure:
        """The interactive view as a plotly Figure (:func:`rffqm_nlp.view.figure`)."""
        from .view import figure

        return figure(self, frames)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the whole result (``curvature`` and ``target_grid`` left
        out when None)."""
        optional = {}
        if self.curvature is not None:
            optional["curvature"] = self.curvature.to_dict()
        if self.target_grid is not None:
            optional["target_grid"] = np.asarray(self.target_grid).tolist()
        return {
            "format": FORMAT, "version": VERSION,
            "boundary": self.boundary.to_dict(), "omega": self.omega,
            "pattern": self.pattern.to_dict(), "folded": self.folded.tolist(),
            "target_points": self.target_points.tolist(), "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(), "fit": self.fit.to_dict(),
            "stats": self.stats.to_dict(), "problem": jsonable(self.problem),
            "x": np.asarray(self.x).tolist(), **optional,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any], source: str = FILENAME) -> "DesignResult":
        """Inverse of :meth:`to_dict`: checks the format and version (a version 1 result is
        migrated, :func:`migrate_v1`), every array's shape and finiteness, and that the
        pattern and the folded state agree with the boundary data re-marched.
        ``source`` names the file in the errors."""
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            raise InputError(f"{source}: not a design result written by rffqm-nlp")
        try:
            if d.get("version") == 1:
                d = migrate_v1(d)
            if d.get("version") != VERSION:
                raise InputError(f"{source}: design result version {d.get('version')!r} is "
                                 f"not supported (this rffqm-nlp reads versions 1 and "
                                 f"{VERSION})")
            return _checked(d, source)
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            if isinstance(exc, RffqmError):
                raise
            raise InputError(f"{source}: broken design result ({type(exc).__name__}: "
                             f"{one_line(exc)}); run the design again") from None

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
                trust: bool = False, n: int = TARGET_MESH) -> trimesh.Trimesh:
    """The target as a triangle mesh in the target frame (that of ``result.folded``), for
    pictures: ``target`` when given, else the kept ``result.target_grid`` (two triangles per
    cell), else the surface rebuilt from ``result.problem["target"]`` (code that it names
    is run only with ``trust``). A :class:`~rffqm_nlp.meshes.Mesh` made from a triangle
    mesh gives those triangles, any other surface its n x n sample (:meth:`Surface.mesh`).

    Raises :class:`RffqmError` (one line) when the target cannot be rebuilt; draw
    ``result.target_points`` then.
    """
    if target is None and result.target_grid is not None:
        grid = np.asarray(result.target_grid, dtype=float)
        return trimesh.Trimesh(vertices=grid.reshape(-1, 3),
                               faces=surfaces.grid_faces(*grid.shape[:2]), process=False)
    if target is None:
        if not isinstance(result.problem, dict) or "target" not in result.problem:
            raise InputError("the result's problem has no [target] table to rebuild the "
                             "target from")
        target = surfaces.from_config(result.problem["target"], trust=trust)
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
    """The result of a version 2 dict, every array checked (see DesignResult.from_dict)."""
    arrays = {key: _finite(d, key, source) for key in
              ("omega", "folded", "target_points", "rotation", "translation", "x")}
    for key in ("left", "bottom", "l_left", "l_bottom"):
        _finite(_required(d, "boundary", source), key, source, f"boundary.{key}")
    bd = BoundaryData.from_dict(d["boundary"])
    pattern_d = _required(d, "pattern", source)
    stored = {key: _finite(pattern_d, key, source, f"pattern.{key}")
              for key in ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")}
    N, M = bd.N, bd.M
    shapes = {"omega": (), "folded": (N + 1, M + 1, 3),
              "target_points": (N // 2 + 1, M // 2 + 1, 3), "rotation": (3, 3),
              "translation": (3,), "pattern.alpha": (N + 1, M + 1),
              "pattern.beta": (N + 1, M + 1), "pattern.sigma": (N + 1, M + 1),
              "pattern.lh": (N + 1, M), "pattern.lv": (N, M + 1), "pattern.mu": (N, M),
              "pattern.X": (N + 1, M + 1, 3)}
    given = {**arrays, **{f"pattern.{k}": v for k, v in stored.items()}}
    for key, expected in shapes.items():
        if given[key].shape != expected:
            raise InputError(f"{source}: {key} has shape {given[key].shape}, expected {expected} "
                             f"for the boundary's {N} x {M} panels")
    if arrays["x"].ndim != 1:
        raise InputError(f"{source}: x must be a flat list of numbers, got shape "
                         f"{arrays['x'].shape}")
    pattern = numpy_model.march(bd)
    for key, value in stored.items():
        _agree(value, getattr(pattern, key), source,
               f"pattern.{key} does not match its boundary data re-marched with the NumPy model")
    omega = float(arrays["omega"])
    Y = numpy_model.fold(pattern, omega) @ arrays["rotation"].T + arrays["translation"]
    _agree(arrays["folded"], Y, source, "folded does not match the pattern folded at omega "
           "and moved by the stored rotation and translation")
    return DesignResult(
        boundary=bd, omega=omega, pattern=Pattern(**stored), folded=arrays["folded"],
        target_points=arrays["target_points"], rotation=arrays["rotation"],
        translation=arrays["translation"], fit=Fit.from_dict(_required(d, "fit", source)),
        stats=SolveStats.from_dict(_required(d, "stats", source)),
        problem=dict(_required(d, "problem", source)), x=arrays["x"],
        curvature=_curvature(d, source, (N // 2 - 1, M // 2 - 1)),
        target_grid=_target_grid(d, source))


def _curvature(d: dict[str, Any], source: str, shape: tuple[int, int]) -> Curvature | None:
    """The stored curvature maps (None when the file has none), each finite and ``shape``."""
    if "curvature" not in d:
        return None
    maps = {}
    for f in fields(Curvature):
        name = f"curvature.{f.name}"
        maps[f.name] = _finite(d["curvature"], f.name, source, name)
        if maps[f.name].shape != shape:
            raise InputError(f"{source}: {name} has shape {maps[f.name].shape}, expected "
                             f"{shape} (the interior of the coarse lattice)")
    return Curvature(**maps)


def _target_grid(d: dict[str, Any], source: str) -> np.ndarray | None:
    """The stored target samples (None when the file has none): finite, (n, m, 3), n, m >= 2."""
    if "target_grid" not in d:
        return None
    grid = _finite(d, "target_grid", source)
    if grid.ndim != 3 or grid.shape[2] != 3 or min(grid.shape[:2]) < 2:
        raise InputError(f"{source}: target_grid has shape {grid.shape}, expected (n, m, 3) "
                         "with n, m >= 2")
    return grid


def _required(d: Any, key: str, source: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise InputError(f"{source}: the key {key!r} is missing")
    return d[key]


def _finite(d: Any, key: str, source: str, name: str | None = None) -> np.ndarray:
    """d[key] as a float array: a rectangular array of finite numbers, else InputError."""
    name = name or key
    value = _required(d, key, source)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{source}: {name} must be a rectangular array of numbers (a cut "
                         "or ragged array?)") from None
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{source}: {name} holds NaN or inf; every value must be finite")
    return arr


def _agree(stored: np.ndarray, recomputed: np.ndarray, source: str, what: str) -> None:
    scale = max(float(np.abs(recomputed).max(initial=0.0)), 1e-300)
    error = float(np.abs(stored - recomputed).max(initial=0.0))
    if error > REMARCH_RTOL * scale:
        raise InputError(f"{source}: {what} (off by {error / scale:.3g} relative, allowed "
                         f"{REMARCH_RTOL:g})")
