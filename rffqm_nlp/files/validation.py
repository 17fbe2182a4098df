"""Validation of the tables read from TOML (and of the same values given through the API):
a :class:`Key` says what a key allows, :func:`check_table` checks a table against a dict of
Keys, and every refusal is one :class:`InputError` line naming the key (``[design]
panels``) and what it allows, never quoting a string longer than a short name.
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import InputError


#: Names from a file that an error message may repeat: short, plain identifiers.
_SAFE_NAME = re.compile(r"[A-Za-z0-9_.+-]{1,32}")


@dataclass(frozen=True)
class Key:
    """How one value is checked (:func:`check_value`); a table's keys map to Keys
    (:func:`check_table`).

    ``kind`` is one of

    * "number": a finite number (int or float, never a boolean), as a float, within ``low``
      and ``high`` (exclusive where ``low_open``/``high_open``);
    * "whole": a whole number within ``low`` and ``high``, even if ``even``, as an int;
    * "choice": one of the strings ``choices``;
    * "bool": true or false; "string": a string; "scalar": a finite number or a string;
    * "list": a list (or tuple) of values each checked by ``item``, with exactly ``length``
      or at least ``least`` and at most ``most`` of them, as a tuple;
    * "table": a table checked by ``spec`` (:func:`check_table`), or, without ``spec``, whose
      every value ``item`` checks, as a dict.

    ``optional``: None is allowed too (in a file: the key left out); ``required``:
    :func:`check_table` refuses a table without this key; ``hint``: said after what is
    allowed, e.g. "(2N, 2M)".
    """

    kind: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    even: bool = False
    choices: tuple[str, ...] = ()
    item: "Key | None" = None
    length: int | None = None
    least: int = 0
    most: int | None = None
    spec: "Mapping[str, Key] | None" = None
    optional: bool = False
    required: bool = False
    hint: str = ""

    def allowed(self) -> str:
        """What this key allows, in words (e.g. "a finite number in (0, 1.5708)")."""
        text = {"number": "a finite number", "bool": "true or false", "string": "a string",
                "scalar": "a finite number or a string",
                "choice": "one of " + ", ".join(repr(c) for c in self.choices)}.get(self.kind)
        if self.kind == "whole":
            text = "an even whole number" if self.even else "a whole number"
        if self.kind == "list":
            count = (_items(self.length) if self.length is not None
                     else f"{self.least} to {_items(self.most)}" if self.most is not None
                     else f"at least {_items(self.least)}" if self.least else "items")
            text = f"a list of {count}" + (f", each {self.item.allowed()}" if self.item else "")
        if self.kind == "table":
            text = ("a table of " + ", ".join(self.spec) if self.spec else "a table" + (
                f" whose values are each {self.item.allowed()}" if self.item else ""))
        text += self._bounds()
        if self.optional:
            text += " or None (leave the key out)"
        return f"{text} {self.hint}" if self.hint else text

    def _bounds(self) -> str:
        if self.kind not in ("number", "whole"):
            return ""
        lo, hi = self.low, self.high
        if lo is not None and hi is not None:
            return (f" in {'(' if self.low_open else '['}{lo:g}, {hi:g}"
                    f"{')' if self.high_open else ']'}")
        if lo is not None:
            return f" {'>' if self.low_open else '>='} {lo:g}"
        if hi is not None:
            return f" {'<' if self.high_open else '<='} {hi:g}"
        return ""


def _items(count: int) -> str:
    return f"{count} item" if count == 1 else f"{count} items"


def describe_value(value: Any) -> str:
    """A value for an error message: its type, the number itself for numbers, a string only
    when it is a short plain name (so no message quotes a file's content)."""
    if value is None:
        return "None"
    if isinstance(value, (bool, np.bool_)):
        return f"{'true' if value else 'false'} (a boolean)"
    if isinstance(value, (int, np.integer)):
        value = int(value)
        if abs(value) < 10**15:
            return f"the whole number {value}"
        if abs(value).bit_length() < 14000:          # str() refuses over 4300 digits
            return f"a whole number of {len(str(abs(value)))} digits"
        digits = int(abs(value).bit_length() * math.log10(2)) + 1
        return f"a whole number of about {digits} digits"
    if isinstance(value, (float, np.floating)):
        return f"the number {float(value):g}"
    if isinstance(value, str):
        return (f"the string {value!r}" if _SAFE_NAME.fullmatch(value)
                else f"a string of {len(value)} characters")
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return describe_value(value.item())
    if isinstance(value, (list, tuple, np.ndarray)):
        return f"a list of {_items(len(value))}"
    if isinstance(value, Mapping):
        return "a table"
    return f"a {type(value).__name__}"


def key_name(where: str, key: Any) -> str:
    """How a key is named in messages: ``[design]`` at the top of a file, ``[design] panels``
    in a table, ``[design] weights.position`` further down."""
    key = shown_name(key)
    if not where:
        return f"[{key}]"
    return f"{where} {key}" if where.endswith("]") else f"{where}.{key}"


def shown_name(key: Any) -> str:
    """A key (or another name from a file) for a message: itself when it is a short plain
    name, else only its length."""
    key = str(key)
    return key if _SAFE_NAME.fullmatch(key) else f"(a name of {len(key)} characters)"


def unknown_key(key: Any, known: Iterable[str] | Mapping[str, Key], where: str,
                is_table: bool = False) -> str:
    """The message for ``key`` (not in ``known``) in the table ``where`` ("" for the top of a
    file, where ``known`` Keys of kind "table" are named as [table]): the key and the
    closest known one, else every known one."""
    def named(name: str) -> str:
        table = not isinstance(known, Mapping) or known[name].kind == "table"
        return f"[{name}]" if not where and table else name

    names = list(known)
    close = difflib.get_close_matches(str(key), names, n=1)
    hint = (f"did you mean {named(close[0])}?" if close
            else "known: " + ", ".join(named(name) for name in names))
    if where:
        return f"unknown key {key_name(where, key)}; {hint}"
    what = (f"unknown table {key_name('', key)}" if is_table
            else f"unknown key {shown_name(key)} at the top of the file")
    return f"{what}; {hint}"


def check_table(table: Any, spec: Mapping[str, Key], where: str) -> dict[str, Any]:
    """The keys of ``table`` checked by ``spec`` (:func:`check_value`), each converted; no
    defaults are filled in. ``where`` names the table ("[design]"; "" for the tables of a
    file). An unknown key is refused naming the closest known one, and so is a table
    missing a required key; every refusal is one :class:`InputError` line naming the key
    and what it allows."""
    if not isinstance(table, Mapping):
        raise InputError(f"{where or 'the file'} must be a table, got {describe_value(table)}")
    for key in table:
        if key not in spec:
            raise InputError(unknown_key(key, spec, where, isinstance(table[key], Mapping)))
    for key, rule in spec.items():
        if rule.required and key not in table:
            raise InputError(f"{where or 'the file'} needs {shown_name(key)}: "
                             f"{rule.allowed()}")
    return {key: check_value(value, spec[key], key_name(where, key) if where or
                             spec[key].kind == "table" else shown_name(key))
            for key, value in table.items()}


def check_value(value: Any, key: Key, name: str, error: type[InputError] = InputError) -> Any:
    """``value`` checked against ``key`` and converted (floats, ints, tuples, dicts); else
    an ``error`` (:class:`InputError` or a subclass, e.g. SurfaceError) "<name> must be
    <what is allowed>, got <what it is>"."""
    if error is not InputError:
        try:
            return check_value(value, key, name)
        except InputError as exc:
            raise error(str(exc)) from None
    if not isinstance(key, Key):
        raise InputError(f"key must be a rffqm_nlp.files.Key, got {describe_value(key)}")
    if value is None and key.optional:
        return None
    if isinstance(value, np.ndarray) and value.ndim == 0:      # an API caller's NumPy scalar
        value = value.item()
    checked = _CHECKS[key.kind](value, key, name)
    if checked is _REFUSED:
        hint = ""
        if key.kind == "choice" and isinstance(value, str):
            close = difflib.get_close_matches(value, key.choices, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
        raise InputError(f"{name} must be {key.allowed()}, got {describe_value(value)}{hint}")
    return checked


_REFUSED = object()


def _check_number(value: Any, key: Key, name: str) -> Any:
    if isinstance(value, (bool, np.bool_)) or not isinstance(
            value, (int, float, np.integer, np.floating)):
        return _REFUSED
    try:
        number = float(value)
    except OverflowError:
        return _REFUSED
    return number if math.isfinite(number) and _within(number, key) else _REFUSED


def _check_whole(value: Any, key: Key, name: str) -> Any:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        return _REFUSED
    value = int(value)
    if (key.even and value % 2) or not _within(value, key):
        return _REFUSED
    return value


def _within(value: float, key: Key) -> bool:
    if key.low is not None and (value <= key.low if key.low_open else value < key.low):
        return False
    return key.high is None or (value < key.high if key.high_open else value <= key.high)


def _check_list(value: Any, key: Key, name: str) -> Any:
    if isinstance(value, np.ndarray) and value.ndim == 1:
        value = value.tolist()
    if not isinstance(value, (list, tuple)):
        return _REFUSED
    if ((key.length is not None and len(value) != key.length) or len(value) < key.least
            or (key.most is not None and len(value) > key.most)):
        return _REFUSED
    if key.item is None:
        return tuple(value)
    return tuple(check_value(v, key.item, f"{name}[{i}]") for i, v in enumerate(value))


def _check_table(value: Any, key: Key, name: str) -> Any:
    if not isinstance(value, Mapping):
        return _REFUSED
    if key.spec is not None:
        return check_table(value, key.spec, name)
    for k in value:
        if not isinstance(k, str):
            raise InputError(f"{name} takes names as keys, got {describe_value(k)}")
    if key.item is None:
        return dict(value)
    return {k: check_value(v, key.item, key_name(name, k)) for k, v in value.items()}


_CHECKS: dict[str, Callable[[Any, Key, str], Any]] = {
    "number": _check_number,
    "whole": _check_whole,
    "choice": lambda v, k, n: v if isinstance(v, str) and v in k.choices else _REFUSED,
    "bool": lambda v, k, n: bool(v) if isinstance(v, (bool, np.bool_)) else _REFUSED,
    "string": lambda v, k, n: v if isinstance(v, str) else _REFUSED,
    "scalar": lambda v, k, n: (v if isinstance(v, str) else _check_whole(v, Key("whole"), n)
                               if isinstance(v, (int, np.integer))
                               else _check_number(v, Key("number"), n)),
    "list": _check_list,
    "table": _check_table,
}
