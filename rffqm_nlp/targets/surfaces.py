"""Target surfaces by name: the namespace ``rq.surfaces`` and the ``[target]`` table.

A target is a :class:`Surface` r(u, v) (:mod:`.parametric`, which gives the conventions:
r_u, r_v, the normal, the fundamental forms, the curvatures, all by automatic
differentiation). Built-ins (:func:`names`, :func:`get`; :mod:`.builtins`) validate their
parameters and domain on construction, users add their own with :class:`Custom`
(:mod:`.custom`), and a design file's ``[target]`` table names one of either
(:func:`from_config`, :meth:`Surface.to_config`; a design file is read by
:func:`rffqm_nlp.design.load_design`), with the user's code run only behind
``--trust`` (:mod:`.user_code`). A designer's mesh or point cloud becomes a surface with
:class:`Mesh` (:mod:`.meshes`). A curvature field with no positions, :class:`Curvature`
(:mod:`.curvature_target`), is a target too, named by a [target] table of its own.

This module is the top of the targets' surfaces: it imports the pieces, and none of them
imports it.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..errors import InputError, SurfaceError
from ..files import Key, check_table, describe_value, named_path
from . import curvature_target
from .builtins import describe, get, names, target_keys
from .curvature_target import Curvature
from .custom import Custom
from .meshes import Mesh
from .parametric import (DOMAIN_KEY, Domain, Surface, check_surface, checked_value,
                         domain_list, mathlib)
from .point_sets import (MAX_GRID, grid_faces, mean_neighbour_distances, point_set_diameter,
                         refuse_points)
from .user_code import check_root, code_of, import_reference, parse_reference, resolve_reference

__all__ = ["DOMAIN_KEY", "MAX_GRID", "MESH_KEYS", "PYTHON_KEYS", "Curvature", "Custom",
           "Domain", "Mesh",
           "Surface", "check_surface", "config_of", "describe", "from_config", "get",
           "grid_faces", "mathlib", "mean_neighbour_distances", "names", "parse_reference",
           "point_set_diameter", "rebuildable", "refuse_points", "resolve_reference",
           "target_keys"]

#: The keys of a [target] table with python = ...
PYTHON_KEYS = {"python": Key("string", required=True),
               "domain": Key("list", length=2, item=DOMAIN_KEY.item, required=True,
                             hint=DOMAIN_KEY.hint)}
#: The keys of a [target] table with mesh = ... (a mesh or point cloud file: :class:`Mesh`)
MESH_KEYS = {"mesh": Key("string", required=True)}


def from_config(table: Mapping[str, Any], root: str | Path | None = None,
                trust: bool = False) -> Surface | Curvature:
    """The target of a ``[target]`` table: ``name = "..."`` plus parameters and an optional
    ``domain = [[u0, u1], [v0, v1]]``, or ``python = "file.py:function"`` (a file relative to
    ``root``, default the current folder) or ``python = "package.module:function"``, plus a
    required ``domain``, or ``mesh = "part.stl"`` (a mesh or point cloud file relative to
    ``root``: its :class:`Mesh`, by its absolute path); or a curvature target, a table with
    ``size = [Lx, Ly]`` (:func:`.curvature_target.from_config`: numbers K (and H) or kx and
    ky, or ``python`` and ``fields``).

    Code named by ``python`` runs only with ``trust=True`` (a target file from someone else
    must not run code unless asked to); without it :class:`SurfaceError` names the code.
    Without it too, a ``mesh`` must lie in ``root`` or below
    (:func:`rffqm_nlp.files.named_path`).
    Every key is checked (:func:`rffqm_nlp.files.check_table`).
    """
    if not isinstance(table, Mapping):
        raise SurfaceError(f"[target] must be a table, got {describe_value(table)}")
    root = check_root(root)
    trust = checked_value(trust, Key("bool"), "trust")
    if not rebuildable(table):
        raise SurfaceError(
            f"[target] cannot be rebuilt: the target of this result was {table.get('made_from')} "
            "and no config names it; rebuild the problem by passing the surface: "
            "DesignProblem(target=<your surface>, **result.problem['design']), or in a file "
            "name a function with python = \"file.py:function\" and domain")
    if curvature_target.is_curvature_table(table):
        return curvature_target.from_config(table, root, trust)
    if "mesh" in table:
        mesh = _checked(table, MESH_KEYS)["mesh"]
        try:
            path = named_path(root or ".", mesh, "[target] mesh", trust)
        except InputError as exc:
            raise SurfaceError(str(exc)) from None
        return Mesh(Path(os.path.abspath(path)))
    if "python" in table and "name" in table:
        raise SurfaceError("[target] takes name (a built-in surface) or python (your own "
                           "function), not both")
    if "python" in table:
        values = _checked(table, PYTHON_KEYS)
        ref = resolve_reference(values["python"], root)
        if not trust:
            raise SurfaceError(f"[target] python = \"{ref}\" {code_of(ref)}; pass --trust "
                               "(trust=True in the API) if you trust that file")
        return Custom(import_reference(ref), values["domain"], reference=ref)
    if "name" not in table:
        raise SurfaceError("the [target] table needs name = \"<surface>\" (one of "
                           f"{', '.join(names())}), python = \"file.py:function\", "
                           "mesh = \"part.stl\" or a curvature field: size = [Lx, Ly] with "
                           "K or kx and ky")
    name = checked_value(table["name"], Key("choice", choices=tuple(names())),
                         "[target] name")
    values = _checked(table, target_keys(name))
    values.pop("name")
    return get(name, values.pop("domain", None), **values)


def config_of(surface: Surface | Curvature) -> dict:
    """The ``[target]`` table of ``surface`` (:meth:`Surface.to_config`,
    :meth:`Curvature.to_config`), or, for a target that no table can name (a lambda, a
    closure, a :class:`Mesh` made from arrays), the record ``{"name", "domain",
    "rebuildable": False, "made_from"}``, which :func:`from_config` refuses with a one-line
    reason."""
    if not isinstance(surface, Curvature):
        check_surface(surface, "surface")
    try:
        return surface.to_config()
    except SurfaceError:
        pass
    if isinstance(surface, Curvature):
        made_from = "a curvature target whose fields are Python functions"
    elif isinstance(surface, Custom):
        fn = surface.fn
        made_from = (f"the Python callable {getattr(fn, '__module__', '?')}."
                     f"{getattr(fn, '__qualname__', type(fn).__name__)}")
    else:
        made_from = f"a {type(surface).__name__} made in Python, not from a file"
    return {"name": surface.name, "domain": domain_list(surface.domain),
            "rebuildable": False, "made_from": made_from}


def rebuildable(table: Mapping[str, Any]) -> bool:
    """Whether a ``[target]`` table names its surface (not a record of :func:`config_of`)."""
    if not isinstance(table, Mapping):
        raise SurfaceError(f"[target] must be a table, got {describe_value(table)}")
    return "rebuildable" not in table


def _checked(table: Mapping[str, Any], spec: dict[str, Key]) -> dict[str, Any]:
    """check_table for [target], raising SurfaceError."""
    try:
        return check_table(table, spec, "[target]")
    except InputError as exc:
        raise SurfaceError(str(exc)) from None
