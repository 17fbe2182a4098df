"""The design file: its tables [target], [design] and [solve], read into a
:class:`~rffqm_nlp.design.problem.DesignProblem` and its
:class:`~rffqm_nlp.design.options.SolveOptions`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..files import Key, check_table, read_toml
from ..targets import surfaces
from ..targets.meshes import is_mesh_file
from .options import SOLVE_KEYS, SolveOptions
from .problem import DESIGN_KEYS, DesignProblem

#: The tables of a design file.
TABLES = ("target", "design", "solve")
#: The tables of a design file as :func:`rffqm_nlp.files.check_table` checks them.
FILE_KEYS = {name: Key("table") for name in TABLES}


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
    if is_mesh_file(path):
        # abspath, not resolve: a path this system cannot open (a NUL) is Mesh's to refuse
        return DesignProblem(surfaces.Mesh(Path(os.path.abspath(path)))), SolveOptions()
    return from_config(read_toml(path, "design file"), Path(path).parent, trust)
