"""The design file: its tables [target], [design] and [solve], read into a
:class:`~rffqm_nlp.design.problem.DesignProblem` and its
:class:`~rffqm_nlp.design.options.SolveOptions`."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..files import Key, check_table, describe_value, read_toml
from ..targets import surfaces
from ..targets.meshes import is_mesh_file
from .options import SOLVE_KEYS, SolveOptions
from .problem import DESIGN_KEYS, DesignProblem
from .results import MAX_STATES

#: The tables of a design file.
TABLES = ("target", "design", "solve")
#: The tables of a design file as :func:`rffqm_nlp.files.check_table` checks them.
FILE_KEYS = {name: Key("table") for name in TABLES}
#: The keys of a state's own in a [[target]] table of a design of several states.
STATE_TABLE_KEYS = {"omega": Key("number", low=-math.pi, high=math.pi),
                    "weight": Key("number", low=0.0, low_open=True)}


def from_config(config: dict[str, Any], root: str | Path | None = None,
                trust: bool = False) -> tuple[DesignProblem, SolveOptions]:
    """The problem and the options of {"target": ..., "design": ..., "solve": ...} (the
    tables of a design file; [design] and [solve] may be missing). An unknown table or key
    is refused with the closest known name, a solve option in [design] with where it goes.
    Several [[target]] tables (a list) design one sheet for several states, each table
    with its state's optional ``omega`` (fixed) and ``weight`` (:func:`state_tables`).

    ``root``: the folder that a target's ``python = "file.py:function"`` is relative to
    (default: the current folder); ``trust``: run the code a target names
    (:func:`rffqm_nlp.targets.surfaces.from_config`), refused without it.
    """
    listed = isinstance(config, dict) and isinstance(config.get("target"), list)
    tables = check_table({k: v for k, v in config.items() if k != "target"} if listed
                         else config, FILE_KEYS, "")
    if "target" not in tables and not listed:
        raise InputError("a design needs a [target] table (name = \"<surface>\" and its "
                         "parameters, or python = \"file.py:function\" and domain)")
    design = tables.get("design", {})
    for key in design:
        if key in SOLVE_KEYS:
            raise InputError(f"[design] {key} is a solve option: move it to the [solve] table")
    design = check_table(design, DESIGN_KEYS, "[design]")
    options = SolveOptions.from_config(tables.get("solve", {}), trust)
    if not listed:
        target = surfaces.from_config(tables["target"], root=root, trust=trust)
        return DesignProblem(target=target, **design), options
    states = state_tables(config["target"])
    targets = [surfaces.from_config(table, root=root, trust=trust) for table, _, _ in states]
    omegas = [omega for _, omega, _ in states]
    weights = [weight for _, _, weight in states]
    return DesignProblem(target=targets,
                         omega=None if all(w is None for w in omegas) else omegas,
                         state_weights=None if all(w == 1.0 for w in weights) else weights,
                         **design), options


def state_tables(tables: list[Any]) -> list[tuple[dict[str, Any], float | None, float]]:
    """The [[target]] tables of a design of several states, each as (its target's table,
    its fixed omega or None, its weight): ``omega`` and ``weight`` are the state's keys
    (:data:`STATE_TABLE_KEYS`), the rest its target's."""
    if not 2 <= len(tables) <= MAX_STATES:
        raise InputError(f"[[target]] must be given 2 to {MAX_STATES} times (one per state), "
                         f"got {len(tables)}")
    out = []
    for k, table in enumerate(tables):
        if not isinstance(table, dict):
            raise InputError(f"[[target]] {k + 1} must be a table, got {describe_value(table)}")
        own = {key: table[key] for key in STATE_TABLE_KEYS if key in table}
        state = check_table(own, STATE_TABLE_KEYS, f"state {k + 1} [[target]]")
        out.append(({key: v for key, v in table.items() if key not in STATE_TABLE_KEYS},
                    state.get("omega"), state.get("weight", 1.0)))
    return out


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
