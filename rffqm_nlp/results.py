"""The outcome of an inverse design: :class:`DesignResult`, with one versioned file format."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .boundary import BoundaryData
from .errors import InputError
from .files import atomic_path, jsonable
from .pattern import Pattern

FORMAT = "rffqm-nlp design result"
VERSION = 1
FILENAME = "result.json"


@dataclass(frozen=True)
class DesignResult:
    """A solved design.

    * ``boundary``: the designed boundary data; ``omega``: the designed fold parameter;
    * ``pattern``: the crease pattern re-marched with the NumPy model;
    * ``folded``: (2N+1, 2M+1, 3) vertices at ``omega``, moved rigidly onto the target
      (``rotation @ y + translation``);
    * ``target_points``: (N+1, M+1, 3) target lattice;
    * ``fit``: RMS and Hausdorff distances (relative to the target's diameter), the
      best-fitting plane's RMS for comparison, the smallest side over the mean side and the
      smallest sector angle;
    * ``stats``: iterations, build and solve time, IPOPT status, objective history;
    * ``problem``: the problem's settings (target configuration included) as a dict;
    * ``x``: the solver's final design vector (for warm starts).
    """

    boundary: BoundaryData
    omega: float
    pattern: Pattern
    folded: np.ndarray
    target_points: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    fit: dict[str, float]
    stats: dict[str, Any]
    problem: dict[str, Any] = field(default_factory=dict)
    x: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def coarse(self) -> np.ndarray:
        """The coarse-grained folded lattice r(i, j) = y^{(2i)(2j)}, aligned to the target."""
        return self.folded[::2, ::2]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary of the whole result."""
        return {
            "format": FORMAT, "version": VERSION,
            "boundary": self.boundary.to_dict(), "omega": self.omega,
            "pattern": self.pattern.to_dict(), "folded": self.folded.tolist(),
            "target_points": self.target_points.tolist(), "rotation": self.rotation.tolist(),
            "translation": self.translation.tolist(), "fit": self.fit,
            "stats": jsonable(self.stats), "problem": jsonable(self.problem),
            "x": np.asarray(self.x).tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> "DesignResult":
        """Inverse of :meth:`to_dict`; checks the format and version."""
        if d.get("format") != FORMAT:
            raise InputError("not a design result written by rffqm-nlp")
        if d.get("version") != VERSION:
            raise InputError(f"design result version {d.get('version')!r} is not supported "
                             f"(this rffqm-nlp reads version {VERSION})")
        return cls(
            boundary=BoundaryData.from_dict(d["boundary"]), omega=float(d["omega"]),
            pattern=Pattern.from_dict(d["pattern"]), folded=np.asarray(d["folded"]),
            target_points=np.asarray(d["target_points"]), rotation=np.asarray(d["rotation"]),
            translation=np.asarray(d["translation"]), fit=dict(d["fit"]),
            stats=dict(d["stats"]), problem=dict(d["problem"]), x=np.asarray(d["x"]))

    def save(self, directory: str | os.PathLike) -> Path:
        """Write ``result.json`` into ``directory`` (created if needed), atomically."""
        path = Path(directory) / FILENAME
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            tmp.write_text(json.dumps(self.to_dict()))
        return path

    @classmethod
    def load(cls, directory: str | os.PathLike) -> "DesignResult":
        """Read a result saved by :meth:`save` (a folder, or the ``result.json`` itself)."""
        path = Path(directory)
        if path.is_dir():
            path = path / FILENAME
        try:
            with open(path) as fh:
                data = json.load(fh)
        except FileNotFoundError:
            raise InputError(f"no design result at {path}") from None
        except json.JSONDecodeError as exc:
            raise InputError(f"{path} is not valid JSON: {exc}") from None
        return cls.from_dict(data)
