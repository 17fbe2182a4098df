"""The options of making a design: a physical size, a thickness, a process and its
parameters, checked in one place (:data:`MAKE_KEYS`, :func:`make_options`).

Lengths are millimetres: a number, or a string with a unit, "300mm", "30 cm", "0.5 mm",
"12in" (:data:`UNITS`; "300" is 300 mm). The sheet's size is given by one of ``width`` (the flat pattern's
extent along x), ``height`` (along y) or ``scale`` (millimetres per unit of the pattern);
without any of them the width is :data:`DEFAULT_WIDTH`. The process (``laser``,
``cutter``, ``print``) fills in the parameters not given (:data:`PROCESSES`).
"""

from __future__ import annotations

import math
import os
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..files import Key, check_table, check_value, describe_value, read_toml

#: Millimetres per unit of the lengths a string may give.
UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
#: A length: a number, spaces, a unit of :data:`UNITS` (millimetres without one).
_LENGTH = re.compile(r"\s*([0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*(mm|cm|m|in)?\s*")
#: The width of the flat pattern when no size is given (mm).
DEFAULT_WIDTH = 300.0
#: Largest length any option takes (mm): a 10 m sheet.
MAX_LENGTH = 10_000.0
#: The parameters each process fills in when not given (mm): laser and cutter perforate
#: the creases (dashes and gaps, a corner relief at each vertex), print leaves a hinge gap
#: between the printed panels.
PROCESSES: dict[str, dict[str, float]] = {
    "laser": {"kerf": 0.0, "dash": 3.0, "gap": 1.0, "corner_relief": 1.0, "hinge_gap": 0.0},
    "cutter": {"kerf": 0.0, "dash": 2.0, "gap": 1.0, "corner_relief": 1.5, "hinge_gap": 0.0},
    "print": {"kerf": 0.0, "dash": 3.0, "gap": 1.0, "corner_relief": 1.0, "hinge_gap": 0.4},
}
#: Paper sizes of the assembly sheet (mm, portrait).
PAPERS = {"a4": (210.0, 297.0), "letter": (215.9, 279.4)}

_LENGTH_KEY = Key("scalar", hint='(millimetres: a number or "300mm", "30cm", "12in")')
#: What each key of a [make] table (and each option of ``make``) allows.
MAKE_KEYS: dict[str, Key] = {
    "width": _LENGTH_KEY, "height": _LENGTH_KEY,
    "scale": Key("number", low=0, low_open=True, hint="(millimetres per pattern unit)"),
    "thickness": _LENGTH_KEY,
    "process": Key("choice", choices=tuple(PROCESSES)),
    **{name: _LENGTH_KEY for name in ("kerf", "dash", "gap", "corner_relief", "hinge_gap")},
    "side": Key("choice", choices=("auto", "back", "front")),
    "paper": Key("choice", choices=tuple(PAPERS)),
    "ties": Key("whole", low=1, high=20),
}
#: Lengths that must be positive (the others may be 0).
_POSITIVE = ("width", "height", "thickness", "dash", "gap")


@dataclass(frozen=True)
class MakeOptions:
    """Checked options of :func:`rffqm_nlp.make.make` (every length in mm).

    ``width``, ``height``, ``scale``: the one given (the others None); ``thickness`` of the
    sheet or panels; ``process`` and its parameters: ``kerf`` (the cut's width: the
    outline is offset out by half of it), ``dash`` and ``gap`` (the perforation of the
    creases), ``corner_relief`` (uncut length at both ends of every crease), ``hinge_gap``
    (the gap left between neighbouring thick panels at their hinge); ``side`` of the
    material ("auto", "back", "front"); ``paper`` of the assembly sheet; ``ties``: how many
    lock ties to recommend.
    """

    width: float | None = None
    height: float | None = None
    scale: float | None = None
    thickness: float = 0.5
    process: str = "laser"
    kerf: float = 0.0
    dash: float = 3.0
    gap: float = 1.0
    corner_relief: float = 1.0
    hinge_gap: float = 0.0
    side: str = "auto"
    paper: str = "a4"
    ties: int = 3

    def to_dict(self) -> dict[str, Any]:
        """The options as a [make] table (None left out)."""
        return {k: v for k, v in asdict(self).items() if v is not None}

    def mm_per_unit(self, extent: tuple[float, float]) -> float:
        """Millimetres per pattern unit, for a flat pattern of ``extent`` (x, y) units."""
        if self.scale is not None:
            return self.scale
        if self.height is not None:
            return self.height / extent[1]
        return (self.width if self.width is not None else DEFAULT_WIDTH) / extent[0]


def length(value: Any, name: str, positive: bool = False) -> float:
    """``value`` (a number of mm, or a string "300mm", "0.5 cm", "12in") in millimetres,
    at most :data:`MAX_LENGTH`, above 0 if ``positive`` (else at least 0); else one
    :class:`InputError` line naming ``name``."""
    name = check_value(name, Key("string"), "name")
    positive = check_value(positive, Key("bool"), "positive")
    value = check_value(value, _LENGTH_KEY, name)
    if isinstance(value, str):
        match = _LENGTH.fullmatch(value)
        if match is None:
            raise InputError(f"{name} must be a length: a number of millimetres or a number "
                             f"with a unit ({', '.join(UNITS)}), e.g. \"300mm\"; got "
                             f"{describe_value(value)}")
        value = float(match[1]) * UNITS[match[2] or "mm"]
    return check_value(value, Key("number", low=0.0, low_open=positive, high=MAX_LENGTH,
                                  hint="(millimetres)"), name)


def make_options(table: dict[str, Any] | None = None, where: str = "[make]",
                 **options: Any) -> MakeOptions:
    """:class:`MakeOptions` from a [make] table and keyword ``options`` (these win; None
    means not given), every key checked by :data:`MAKE_KEYS` and every length by
    :func:`length`; at most one of width, height and scale; the process's parameters
    (:data:`PROCESSES`) where not given. ``where`` names the table in messages."""
    where = check_value(where, Key("string"), "where")
    given = dict(check_table({} if table is None else table, MAKE_KEYS, where))
    given.update(check_table({k: v for k, v in options.items() if v is not None},
                             MAKE_KEYS, "make"))
    sizes = [k for k in ("width", "height", "scale") if given.get(k) is not None]
    if len(sizes) > 1:
        raise InputError(f"give one of width, height and scale, got {' and '.join(sizes)}")
    process = given.get("process", "laser")
    values = {**PROCESSES[process], **given, "process": process}
    for name in ("width", "height", "thickness", "kerf", "dash", "gap", "corner_relief",
                 "hinge_gap"):
        if name in values:
            values[name] = length(values[name], name, positive=name in _POSITIVE)
    return MakeOptions(**values)


def read_make_table(path: str | os.PathLike) -> dict[str, Any]:
    """The [make] table of a TOML file (a file of only that table, or a design file with
    one besides its own); :class:`InputError` when it has none."""
    data = read_toml(Path(path))
    table = data.get("make")
    if not isinstance(table, dict):
        raise InputError(f"{path} has no [make] table")
    return table


def finite_scale(scale: float, extent: tuple[float, float]) -> float:
    """``scale`` (mm per unit) when it gives the flat pattern a finite size within
    :data:`MAX_LENGTH` on both axes; else :class:`InputError`."""
    size = max(extent) * scale
    if not (math.isfinite(size) and 0 < size <= MAX_LENGTH):
        raise InputError(f"the sheet would be {size:.3g} mm across; sizes up to "
                         f"{MAX_LENGTH:g} mm are made")
    return scale
