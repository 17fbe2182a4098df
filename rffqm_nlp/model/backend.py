"""NumPy or CasADi: the one dispatch for formulas written once for both.

The vertex formulas (vertex.py), the target surfaces (surfaces.py) and the discrete shape
measures (shape.py) are each written once and evaluated on NumPy arrays (and Python numbers)
or on CasADi SX/MX symbols and DM matrices. :func:`math_for` returns the namespace of math
functions for its arguments, CasADi's as soon as one argument is a CasADi object:

    m = math_for(u, v)
    x = m.sqrt(u * u + v * v) * m.cos(v)

Both namespaces have the same names: ``sin, cos, tan, atan, atan2, sqrt, exp, log, sinh,
cosh, tanh, fabs, where, pi``; ``where(cond, a, b)`` is ``numpy.where`` or ``casadi.if_else``.
Users reach :func:`math_for` as ``rffqm_nlp.targets.surfaces.mathlib``.

The checks of a public function's numeric arguments live here too: :func:`finite_array`
(an array of finite real numbers of a given shape), :func:`check_formula_args` (the
arguments of a formula written once for both) and :func:`finite_result` (a numeric result
that came out NaN or infinite raises instead of being returned).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np

from ..errors import InputError
from ..files import describe_value

#: A value the formulas written once for both take and return: a Python or NumPy number, a
#: NumPy array, or a CasADi SX/MX symbol or DM matrix.
Scalar = Any
#: The CasADi matrix types: symbols (SX, MX) and numeric matrices (DM).
CASADI_TYPES = (ca.SX, ca.MX, ca.DM)

NUMPY = SimpleNamespace(sin=np.sin, cos=np.cos, tan=np.tan, atan=np.arctan, atan2=np.arctan2,
                        sqrt=np.sqrt, exp=np.exp, log=np.log, sinh=np.sinh, cosh=np.cosh,
                        tanh=np.tanh, fabs=np.abs, where=np.where, pi=math.pi)

CASADI = SimpleNamespace(sin=ca.sin, cos=ca.cos, tan=ca.tan, atan=ca.atan, atan2=ca.atan2,
                         sqrt=ca.sqrt, exp=ca.exp, log=ca.log, sinh=ca.sinh, cosh=ca.cosh,
                         tanh=ca.tanh, fabs=ca.fabs, where=ca.if_else, pi=math.pi)


def is_casadi(*args: Any) -> bool:
    """Whether any argument is a CasADi SX, MX or DM matrix."""
    return any(isinstance(a, CASADI_TYPES) for a in args)


def math_for(*args: Any) -> SimpleNamespace:
    """The math namespace for ``args``: :data:`CASADI` if any is a CasADi object, else
    :data:`NUMPY` (NumPy arrays, Python and NumPy numbers)."""
    return CASADI if is_casadi(*args) else NUMPY


# --------------------------------------------------------------------------- arguments
def _check_error_class(error: Any) -> None:
    """The checker's own argument: InputError or one of its subclasses."""
    if not (isinstance(error, type) and issubclass(error, InputError)):
        raise InputError("error must be InputError or one of its subclasses")


def finite_array(value: Any, name: str, *, shape: tuple[int | None, ...] | None = None,
                 ndim: int | None = None, least: int = 0, allowed: str = "",
                 finite: bool = True, error: type[InputError] = InputError) -> np.ndarray:
    """``value`` as a float array of real, finite numbers: a number, a (nested) list or a
    NumPy array of them. ``shape`` (None for any length of that axis) or ``ndim`` fixes its
    dimensions, ``least`` the smallest number of entries. Anything else raises ``error``
    (:class:`InputError` or a subclass), one line naming ``name`` and what is allowed
    (``allowed``, e.g. "points of shape (k, 3)", else said from ``shape``): booleans,
    strings, None, mappings, ragged lists, complex and object arrays, NaN and infinity. A
    value is never quoted, only its kind (:func:`rffqm_nlp.files.describe_value`).
    ``finite=False`` lets NaN and infinity through (where they carry a meaning)."""
    _check_error_class(error)
    if not (shape is None or (isinstance(shape, tuple) and all(
            s is None or (isinstance(s, int) and not isinstance(s, bool) and s >= 0)
            for s in shape))) or not (ndim is None or type(ndim) is int) \
            or type(least) is not int:
        raise InputError("finite_array takes shape as a tuple of sizes (None for any), ndim "
                         "and least as whole numbers")
    what = allowed or _array_words(shape, ndim)
    if isinstance(value, (str, bytes, Mapping)) or value is None or is_casadi(value):
        raise error(f"{name} must be {what}, got {describe_value(value)}")
    try:
        raw = np.asarray(value)
    except (ValueError, TypeError, OverflowError, RecursionError):
        raise error(f"{name} must be {what}, got a ragged or mixed list") from None
    if raw.dtype.kind not in "iuf":
        got = ("booleans" if raw.dtype.kind == "b" else "complex numbers"
               if raw.dtype.kind == "c" else describe_value(value) if raw.ndim == 0
               else f"{describe_value(value)} holding something other than numbers (or a "
               "whole number too large for a float)")
        raise error(f"{name} must be {what}, got {got}")
    if shape is not None and (raw.ndim != len(shape) or any(
            want is not None and have != want for have, want in zip(raw.shape, shape))):
        raise error(f"{name} must be {what}, got shape {raw.shape}")
    if ndim is not None and raw.ndim != ndim:
        raise error(f"{name} must be {what}, got shape {raw.shape}")
    if raw.size < least:
        raise error(f"{name} must be {what} with at least {least} "
                    f"{'entry' if least == 1 else 'entries'}, got shape {raw.shape}")
    arr = raw.astype(float)
    bad = ~np.isfinite(arr) if finite else np.zeros((), dtype=bool)
    if bad.any():
        where = np.unravel_index(int(np.argmax(bad)), arr.shape) if arr.ndim else ()
        at = f" at index {tuple(int(i) for i in where)}" if arr.ndim else ""
        raise error(f"{name} must be {what}, got {float(arr[bad].flat[0]):g}{at}")
    return arr


def _array_words(shape: tuple[int | None, ...] | None, ndim: int | None) -> str:
    if shape is not None:
        if not shape:
            return "a finite number"
        letters = iter("nmkl")
        dims = ", ".join(next(letters, "n") if s is None else str(s) for s in shape)
        return f"an array of finite numbers of shape ({dims}{',' if len(shape) == 1 else ''})"
    if ndim is not None:
        return f"a {ndim}-D array of finite numbers"
    return "a finite number or an array of finite numbers"


def check_formula_args(**args: Any) -> bool:
    """Check the arguments of a formula written once for both (:func:`math_for`): each a
    CasADi SX/MX/DM matrix, or a finite real number or array, the numeric ones broadcasting
    together; an argument named ``sigma`` (a mountain-valley sign) is +1 or -1 where it is
    numeric. Returns whether any argument is a CasADi object (then the result is a graph
    and is not checked further). Raises :class:`InputError` naming the argument."""
    shapes = []
    for name, value in args.items():
        if is_casadi(value):
            continue
        arr = finite_array(value, name)
        if name.startswith("sigma") and not np.all(np.abs(arr) == 1):
            bad = float(arr[np.abs(arr) != 1].flat[0])
            raise InputError(f"{name} must be +1 or -1 (a mountain-valley sign), got {bad:g}")
        shapes.append((name, arr.shape))
    try:
        np.broadcast_shapes(*(s for _, s in shapes))
    except ValueError:
        raise InputError(f"{', '.join(n for n, _ in shapes)} must broadcast together, got "
                         f"shapes {', '.join(str(s) for _, s in shapes)}") from None
    return is_casadi(*args.values())


def finite_result(value: Any, what: str) -> Any:
    """``value`` (a number, an array or a tuple of them) unless some entry is NaN or
    infinite; then :class:`InputError` "<what>" (which says why the inputs have no finite
    result). CasADi values pass unchecked."""
    parts = value if isinstance(value, tuple) else (value,)
    for part in parts:
        if is_casadi(part):
            continue
        try:
            finite = np.all(np.isfinite(part))
        except (TypeError, ValueError):
            raise InputError(f"finite_result checks numbers and arrays of numbers, got "
                             f"{describe_value(part)}") from None
        if not finite:
            raise InputError(what)
    return value
