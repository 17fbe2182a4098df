"""A user's own surface from a callable r(u, v): :class:`Custom`."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import casadi as ca
import numpy as np

from ..errors import SurfaceError, one_line
from ..files import Key, describe_value
from ..model import backend
from .parametric import Surface, check_domain, checked_value, domain_list
from .user_code import reference_of


class Custom(Surface):
    """A user's surface from a callable ``fn(u, v) -> (x, y, z)``.

    ``fn`` is called with CasADi SX symbols to build the AD graph, so it must use
    CasADi-compatible math: arithmetic, ``casadi.sin`` etc., or
    :func:`~rffqm_nlp.targets.parametric.mathlib` (``m = mathlib(u, v); m.sin(u)``). It is
    checked once on symbols and once on numbers (the domain's centre); a wrong result raises
    SurfaceError. ``reference`` is the ``"module:function"`` or ``"/path/file.py:function"``
    it was loaded from, if any (used by :meth:`to_config`); both are kept as attributes
    (``fn``, ``reference``).
    """

    def __init__(self, fn: Callable[[Any, Any], Any], domain: Any, name: str = "custom",
                 reference: str | None = None):
        if not callable(fn):
            raise SurfaceError(f"Custom needs a callable fn(u, v) -> (x, y, z), got "
                               f"{describe_value(fn)}")
        name = checked_value(name, Key("string"), "name")
        self.fn = fn
        self.reference = (None if reference is None else
                          checked_value(reference, Key("string", hint="(or None)"), "reference"))
        dom = check_domain(domain)
        _xyz(fn, ca.SX.sym("u"), ca.SX.sym("v"), "CasADi SX symbols", ca.SX)
        centre = (sum(dom[0]) / 2, sum(dom[1]) / 2)
        _xyz(fn, *centre, f"the numbers (u, v) = {centre}", ca.DM)
        super().__init__(name, {}, dom)

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        return _xyz(self.fn, u, v, "CasADi SX symbols", ca.SX)

    def to_config(self) -> dict:
        """``{"python": reference, "domain": ...}``: the reference it was loaded from, else
        "module:function" of an importable function."""
        ref = self.reference or reference_of(self.fn)
        if ref is None:
            raise SurfaceError(
                f"custom surface {self.name!r} was made from {self.fn!r}, which cannot be "
                f"imported by name; define it as a module-level function and use "
                f"python = \"module:function\" in the [target] table")
        return {"python": ref, "domain": domain_list(self.domain)}


def _xyz(fn: Callable, u: Any, v: Any, what: str, kind: type) -> tuple[Any, Any, Any]:
    """Call fn(u, v) and return its three components as 1x1 ``kind`` (SX or DM) matrices."""
    try:
        out = fn(u, v)
    except Exception as err:
        raise SurfaceError(
            f"the surface callable raised {type(err).__name__}: {one_line(err)} when called "
            f"with {what}; write it with CasADi-compatible math (casadi.sin, ..., or "
            f"rffqm_nlp.targets.surfaces.mathlib)") from err
    try:
        parts = ca.vertsplit(ca.vec(out)) if backend.is_casadi(out) else list(out)
        parts = [kind(p) for p in parts]
    except Exception:
        parts = None
    if parts is None or len(parts) != 3 or any(p.shape != (1, 1) for p in parts):
        raise SurfaceError(
            f"the surface callable must return three scalars (x, y, z) when called with "
            f"{what}, got {describe_value(out)}")
    if kind is ca.DM and not all(np.isfinite(float(p)) for p in parts):
        raise SurfaceError(f"the surface callable returned non-finite values (NaN or "
                           f"infinity) at {what}")
    return parts[0], parts[1], parts[2]
