"""Checks of a stored design: every number finite and within a float's range, every array of
its shape, and the crease pattern equal to its boundary data re-marched by the independent
NumPy model. A saved result (:meth:`rffqm_nlp.design.results.DesignResult.load`) and a FOLD
file's pattern (:func:`rffqm_nlp.io.foldfile.read_fold`) are read through them; each refusal
is one :class:`~rffqm_nlp.errors.InputError` line that names the place, never the content."""

from __future__ import annotations

import math
import re
import sys
from collections.abc import Mapping
from dataclasses import fields
from typing import Any

import numpy as np

from ..errors import InputError, MarchingError, safe_text
from ..files import describe_value, shown_name
from ..model import numpy_model
from ..model.boundary import BoundaryData
from ..model.pattern import Pattern
from ..targets.curvature import Curvature

#: Relative agreement required between a stored array and its recomputation on load.
REMARCH_RTOL = 1e-9
#: Largest deviation of ``rotation.T @ rotation`` from the identity a stored rotation may have.
ROTATION_TOL = 1e-9
#: The arrays of a stored pattern (:meth:`Pattern.to_dict`).
PATTERN_KEYS = ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")
#: Largest integer a file may hold: the largest one a float holds (bigger ones overflow it).
_FLOAT_MAX = int(sys.float_info.max)
#: Keys a message names as they are (plain names such as FOLD's "rffqm:pattern"); others
#: by their length (:func:`rffqm_nlp.files.shown_name`).
_KEY_NAME = re.compile(r"[A-Za-z0-9_.:+-]{1,40}")


def checked_pattern(d: Any, source: str, boundary: BoundaryData | None = None,
                    where: str = "pattern") -> Pattern:
    """The crease pattern stored in the table ``d`` (:meth:`Pattern.to_dict`) of the file
    ``source``, checked as a saved result's is: every array a rectangular array of finite
    numbers of its shape for the N x M panels (those of ``boundary``, else those of its
    alpha), its boundary data admissible (``boundary``, else the data it carries: the
    triples of its left column and bottom row, its left and bottom sides), and every array
    equal, to :data:`REMARCH_RTOL` relative, to those boundary data re-marched with the
    independent NumPy model (:func:`rffqm_nlp.model.numpy_model.march`). ``where`` names the
    table in the errors ("pattern", "rffqm:pattern"); each is one :class:`InputError`
    line. Returns the stored pattern."""
    if not isinstance(d, Mapping):
        raise InputError(f"{source}: {where} must be a table of the pattern's arrays, got "
                         f"{describe_value(d)}")
    stored = {key: finite(d, key, source, f"{where}.{key}") for key in PATTERN_KEYS}
    if boundary is None:
        alpha = stored["alpha"]
        if alpha.ndim != 2 or min(alpha.shape) < 2:
            raise InputError(f"{source}: {where}.alpha has shape {alpha.shape}, expected "
                             "(N+1, M+1) with N, M >= 1")
        N, M, whose = alpha.shape[0] - 1, alpha.shape[1] - 1, f"{where}.alpha's"
    else:
        N, M, whose = boundary.N, boundary.M, "the boundary's"
    shapes = {"alpha": (N + 1, M + 1), "beta": (N + 1, M + 1), "sigma": (N + 1, M + 1),
              "lh": (N + 1, M), "lv": (N, M + 1), "mu": (N, M), "X": (N + 1, M + 1, 3)}
    for key, expected in shapes.items():
        if stored[key].shape != expected:
            raise InputError(f"{source}: {where}.{key} has shape {stored[key].shape}, expected "
                             f"{expected} for {whose} {N} x {M} panels")
    if boundary is None:
        tri = np.stack([stored["alpha"], stored["beta"], stored["sigma"]], axis=-1)
        with named(source, f"{where}'s boundary data"):
            boundary = BoundaryData(tri[:, 0], tri[0, 1:], stored["lv"][:, 0],
                                    stored["lh"][0, :])
    try:
        with np.errstate(all="ignore"):     # an overflow is refused below
            marched = numpy_model.march(boundary)
    except MarchingError as exc:
        raise InputError(f"{source}: the boundary data of {where} do not march ({exc})") \
            from None
    except InputError as exc:               # a marched array that is not finite
        raise InputError(f"{source}: {where} cannot be recomputed in floating point from "
                         f"its boundary data ({exc})") from None
    for key, value in stored.items():
        agree(value, getattr(marched, key), source,
               f"{where}.{key} does not match its boundary data re-marched with the NumPy "
               "model")
    with named(source, where):
        return Pattern(**stored)


def check_numbers(value: Any, source: str) -> None:
    """Refuse, in one :class:`InputError` line naming the place, a number anywhere in
    ``value`` (a JSON document: tables, lists, numbers, strings; numpy arrays too) that is
    NaN or infinite (JSON's NaN and Infinity, or a literal such as 1e999) or an integer
    too large for a float. ``source`` names the file."""
    stack: list[tuple[Any, tuple]] = [(value, ())]
    while stack:
        item, place = stack.pop()
        if isinstance(item, (bool, np.bool_, str)) or item is None:
            continue
        if isinstance(item, (float, np.floating)):
            if not math.isfinite(item):
                raise InputError(f"{source}: {where_in(place, 'holds NaN or inf')}; every "
                                 "number must be finite")
        elif isinstance(item, (int, np.integer)):
            if abs(int(item)) > _FLOAT_MAX:
                held = 'holds ' + describe_value(item)
                raise InputError(f"{source}: {where_in(place, held)}, too large for a "
                                 "floating-point number")
        elif isinstance(item, Mapping):
            stack.extend((v, (*place, ("key", k))) for k, v in list(item.items())[::-1])
        elif isinstance(item, (list, tuple)) or (isinstance(item, np.ndarray)
                                                 and item.dtype.kind == "O"):
            stack.extend((v, (*place, ("index", i)))
                         for i, v in reversed(list(enumerate(item))))
        elif isinstance(item, np.ndarray) and item.dtype.kind in "fc":
            bad = np.argwhere(~np.isfinite(item))
            if bad.size:
                at = (*place, *(("index", int(i)) for i in bad[0]))
                raise InputError(f"{source}: {where_in(at, 'holds NaN or inf')}; every number "
                                 "must be finite")


def where_in(place: tuple, what: str) -> str:
    """``pattern.X holds NaN (at pattern.X[1][2][0])``: the innermost named key, ``what``,
    and where in the key the value is."""
    text, named = "", ""
    for kind, key in place:
        if kind == "key":
            key = key if _KEY_NAME.fullmatch(str(key)) else shown_name(key)
            text = f"{text}.{key}" if text else key
            named = text
        else:
            text = f"{text}[{key}]"
    return f"{named or 'the value'} {what}" + ("" if text == named else f" (at {text})")


class named:
    """Context manager: an :class:`InputError` raised inside comes out prefixed with
    ``source`` (and ``where``), e.g. "run/result.json: boundary: ..."."""

    def __init__(self, source: str, where: str = ""):
        self.prefix = f"{source}: {where}: " if where else f"{source}: "

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind, exc, tb) -> bool:
        if isinstance(exc, InputError) and not str(exc).startswith(self.prefix):
            exc.args = (safe_text(self.prefix + str(exc)), *exc.args[1:])
        return False


def check_rotation(rotation: np.ndarray, source: str) -> None:
    """Refuse a rotation that is not orthonormal (to ROTATION_TOL) or not proper (det +1)."""
    deviation = float(np.abs(rotation.T @ rotation - np.eye(3)).max())
    if deviation > ROTATION_TOL:
        raise InputError(f"{source}: rotation must be a rotation matrix (orthonormal to "
                         f"{ROTATION_TOL:g}), but R^T R differs from the identity by "
                         f"{deviation:.3g}")
    if np.linalg.det(rotation) < 0:
        raise InputError(f"{source}: rotation must be a proper rotation (determinant +1), "
                         "got a reflection (determinant -1)")


def stored_curvature(d: dict[str, Any], source: str, shape: tuple[int, int]) -> Curvature | None:
    """The stored curvature maps (None when the file has none), each finite and ``shape``."""
    if "curvature" not in d:
        return None
    maps = {}
    for f in fields(Curvature):
        name = f"curvature.{f.name}"
        maps[f.name] = finite(d["curvature"], f.name, source, name)
        if maps[f.name].shape != shape:
            raise InputError(f"{source}: {name} has shape {maps[f.name].shape}, expected "
                             f"{shape} (the interior of the coarse lattice)")
    return Curvature(**maps)


def stored_target_grid(d: dict[str, Any], source: str) -> np.ndarray | None:
    """The stored target samples (None when the file has none): finite, (n, m, 3), n, m >= 2."""
    if "target_grid" not in d:
        return None
    grid = finite(d, "target_grid", source)
    if grid.ndim != 3 or grid.shape[2] != 3 or min(grid.shape[:2]) < 2:
        raise InputError(f"{source}: target_grid has shape {grid.shape}, expected (n, m, 3) "
                         "with n, m >= 2")
    return grid


def required(d: Any, key: str, source: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise InputError(f"{source}: the key {key!r} is missing")
    return d[key]


def finite(d: Any, key: str, source: str, name: str | None = None) -> np.ndarray:
    """d[key] as a float array: a rectangular array of finite numbers (never strings or
    booleans converted), else InputError naming ``name`` (default ``key``)."""
    name = name or key
    if not isinstance(d, dict) or key not in d:
        raise InputError(f"{source}: the key {name!r} is missing")
    value = d[key]
    try:
        raw = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raw = None
    if raw is None or raw.dtype.kind not in "iuf":
        raise InputError(f"{source}: {name} must be a rectangular array of numbers (a cut "
                         "or ragged array?)") from None
    arr = raw.astype(float)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{source}: {name} holds NaN or inf; every value must be finite")
    return arr


def agree(stored: np.ndarray, recomputed: np.ndarray, source: str, what: str) -> None:
    """Refuse ``stored`` unless it equals ``recomputed`` (finite) to REMARCH_RTOL relative."""
    if not np.all(np.isfinite(recomputed)):
        raise InputError(f"{source}: {what.split()[0]} cannot be recomputed in floating "
                         "point (it overflows; are the side lengths too large?)")
    scale = max(float(np.abs(recomputed).max(initial=0.0)), 1e-300)
    error = float(np.abs(stored - recomputed).max(initial=0.0))
    if error > REMARCH_RTOL * scale:
        raise InputError(f"{source}: {what} (off by {error / scale:.3g} relative, allowed "
                         f"{REMARCH_RTOL:g})")
