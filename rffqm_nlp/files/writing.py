"""Single files written atomically (a temporary file in the target folder, then
:func:`os.replace`), and JSON without NaN."""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


FILE_MODE = 0o666 & ~_umask()
DIR_MODE = 0o777 & ~_umask()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (same suffix); on success move it onto ``path``.

    On an exception the temporary file is removed and ``path`` is left untouched.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=path.suffix)
    os.close(fd)
    try:
        yield Path(tmp)
        os.chmod(tmp, FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def jsonable(value: Any) -> Any:
    """``value`` with numpy arrays and scalars as lists and Python numbers, and objects with
    a ``to_dict`` method (Pattern, Fit, ...) as their dicts, recursively (mapping keys as
    strings); :class:`InputError` for anything JSON cannot hold."""
    if hasattr(value, "to_dict"):
        return jsonable(value.to_dict())
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if value is None or isinstance(value, (str, int, float, bool)):
        return value
    raise InputError(f"{value!r} ({type(value).__name__}) cannot be stored in JSON; use "
                     "numbers, strings, booleans, lists, dicts or numpy arrays")


def _non_finite(value: Any, where: str) -> str | None:
    """The place (``fit.rms``, ``history[3]``) of the first NaN or infinity in a
    :func:`jsonable` value, or None."""
    if isinstance(value, float) and not math.isfinite(value):
        return where or "the value"
    items = (value.items() if isinstance(value, dict)
             else enumerate(value) if isinstance(value, list) else ())
    for key, item in items:
        place = f"{where}[{key}]" if isinstance(key, int) else (f"{where}.{key}" if where
                                                                  else str(key))
        if found := _non_finite(item, place):
            return found
    return None


def write_json(path: str | os.PathLike, obj: Any, indent: int | None = None) -> Path:
    """Write ``obj`` (after :func:`jsonable`) as JSON to ``path`` atomically; returns the path.

    No file holds NaN or infinity: such a value raises :class:`InputError` naming where it
    is (e.g. ``fit.rms``), and nothing is written.
    """
    data = jsonable(obj)
    try:
        text = json.dumps(data, indent=indent, allow_nan=False)
    except ValueError:
        raise InputError(f"cannot write {path}: {_non_finite(data, '')} is not a finite "
                         "number (NaN or infinity); no file holds one") from None
    return write_text(path, text)
