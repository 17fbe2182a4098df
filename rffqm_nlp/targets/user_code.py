"""The user's own code a ``[target]`` table names (``python = "file.py:function"`` or
``"package.module:function"``): parsing and resolving the reference, and running it, which
:func:`rffqm_nlp.targets.surfaces.from_config` does only with ``trust=True`` (``--trust``)."""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import re
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import SurfaceError, one_line
from ..files import describe_value


def check_root(root: Any) -> Path | None:
    """A folder argument: None, a string or a path."""
    if root is not None and not isinstance(root, (str, Path)):
        raise SurfaceError(f"root must be a folder (a string or a path) or None, got "
                           f"{describe_value(root)}")
    return None if root is None else Path(root)


def reference_of(fn: Callable) -> str | None:
    """``"module:qualname"`` if that module, already imported, holds ``fn`` itself, else
    None."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", "")
    if not module or "<" in qualname or module not in sys.modules:
        return None
    try:
        found = _attribute(sys.modules[module], qualname, f"{module}:{qualname}")
    except SurfaceError:
        return None
    return f"{module}:{qualname}" if found is fn else None


#: A Python name path (``package.module``, ``function``, ``Class.method``).
_DOTTED = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")
#: A Python file: a path ending in .py, without control characters or colons.
_PY_FILE = re.compile(r"[^\x00-\x1f\x7f:]+\.py")
_REFERENCE_FORMS = ('"file.py:function" (a Python file, relative to the target file) or '
                    '"package.module:function" (an installed module)')


def parse_reference(ref: Any) -> tuple[str, str, str]:
    """("file" or "module", the file or module, the function's name) of a target's
    ``python = ...``; :class:`SurfaceError` for anything of neither form."""
    where, sep, qualname = ref.rpartition(":") if isinstance(ref, str) else ("", "", "")
    if sep and len(ref) <= 300 and _DOTTED.fullmatch(qualname):
        if _PY_FILE.fullmatch(where):
            return "file", where, qualname
        if _DOTTED.fullmatch(where):
            return "module", where, qualname
    raise SurfaceError(f"[target] python must have the form {_REFERENCE_FORMS}, got "
                       f"{describe_value(ref)}")


def resolve_reference(ref: Any, root: str | Path | None = None) -> str:
    """``ref`` with a file made absolute (relative to ``root``, default the current folder);
    a module reference unchanged."""
    kind, where, qualname = parse_reference(ref)
    root = check_root(root)
    if kind == "module":
        return ref
    return f"{Path(root or '.').joinpath(where).absolute()}:{qualname}"


def code_of(ref: str) -> str:
    """What loading ``ref`` (resolved) runs, for the messages."""
    kind, where, qualname = parse_reference(ref)
    if kind == "file":
        return f"would run the Python file {where} (all of it) and call {qualname}"
    return f"would import the installed module {where} (running its code) and call {qualname}"


def import_reference(ref: str) -> Callable:
    """The function of a resolved ``ref``: the file run as a module of its own
    (:func:`importlib.util.spec_from_file_location`), or the module imported by name."""
    kind, where, qualname = parse_reference(ref)
    if kind == "file":
        return _attribute(_run_file(Path(where)), qualname, ref)
    try:
        module = importlib.import_module(where)
    except Exception as err:
        raise SurfaceError(f"[target] python: cannot import the module {where} "
                           f"({type(err).__name__}: {one_line(err)}); check it is installed "
                           "or use python = \"file.py:function\"") from err
    return _attribute(module, qualname, ref)


def _run_file(path: Path) -> Any:
    """The module made by running the Python file ``path``, registered under a name of its
    own (so dataclasses and pickling inside it work)."""
    if not path.is_file():
        raise SurfaceError(f"[target] python: no such Python file {path} (a file is relative "
                           "to the target file)")
    name = "rffqm_target_" + hashlib.sha256(str(path).encode()).hexdigest()[:16]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as err:
        del sys.modules[name]
        raise SurfaceError(f"[target] python: running {path} raised {type(err).__name__}: "
                           f"{one_line(err)}") from err
    return module


def _attribute(obj: Any, qualname: str, ref: str) -> Callable:
    """``obj.<qualname>``, which must be callable."""
    for attr in qualname.split("."):
        if not hasattr(obj, attr):
            raise SurfaceError(f"[target] python: {ref} has no function {qualname}; check "
                               "the name is spelled right")
        obj = getattr(obj, attr)
    if not callable(obj):
        raise SurfaceError(f"[target] python: {qualname} of {ref} is not a function")
    return obj
