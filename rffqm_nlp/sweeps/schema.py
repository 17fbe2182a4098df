"""What a study file may hold: its tables, the swept keys "<table>.<key>", random ranges
(:class:`Range`) and the base design file it names; every refusal one
:class:`~rffqm_nlp.errors.InputError` line that quotes nothing of the file."""

from __future__ import annotations

import difflib
import math
import os
import re
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..design import DESIGN_KEYS, SOLVE_KEYS
from ..design.schema import FILE_KEYS, state_tables
from ..errors import InputError
from ..files import Key, check_table, check_value, describe_value, named_path, read_toml, shown_name
from ..targets.surfaces import resolve_reference
from .limits import MAX_DEPTH, MAX_WHOLE


#: Tables a swept key may address ("<table>.<key>").
TABLES = ("target", "design", "solve")
#: What each top-level key of a study file allows (the tables' keys: DesignProblem's,
#: SolveOptions' and :meth:`Study.from_config`).
STUDY_FILE_KEYS = {"base": Key("string"), "description": Key("string"),
                   **{table: Key("table") for table in (*TABLES, "sweep")}}
#: Keys of [sweep] that control the expansion rather than name a parameter.
SWEEP_CONTROLS = ("sample", "seed", "cases")
#: Keys of a random range {low, high, log}.
RANGE_KEYS = ("low", "high", "log")
#: Swept keys that take whole numbers (a range draws whole numbers for them).
INTEGER_KEYS = ("solve.max_iter", "solve.multistart", "solve.seed")
#: A case's name: 1 to 32 ASCII letters, digits, spaces (not at either end) and _ . + - =;
#: it is part of its designs' names, which messages and the progress show as they are.
CASE_NAME = re.compile(r"[A-Za-z0-9_.+=-](?:[A-Za-z0-9 _.+=-]{0,30}[A-Za-z0-9_.+=-])?")


@dataclass(frozen=True)
class Range:
    """A random parameter for ``sample = K``: uniform in [low, high] (log-uniform with
    ``log``); whole numbers for the keys of :data:`INTEGER_KEYS`."""

    low: float
    high: float
    log: bool = False

    def __post_init__(self) -> None:
        low = check_value(self.low, Key("number"), "low")
        high = check_value(self.high, Key("number", low=low, hint="(low <= high)"), "high")
        if check_value(self.log, Key("bool"), "log"):
            check_value(low, Key("number", low=0, low_open=True, hint="(a log range)"), "low")
        elif not math.isfinite(high - low):
            raise InputError(f"high - low must be a finite number, got {high:g} - {low:g}; "
                             "choose a narrower range")

    def whole_numbers(self) -> int:
        """How many whole numbers the range holds (what a draw for a key of
        :data:`INTEGER_KEYS` can give)."""
        return max(0, math.floor(self.high) - math.ceil(self.low) + 1)

    def draw(self, rng: np.random.Generator, integer: bool = False) -> float | int:
        """One value drawn from this range (a whole number in it when ``integer``)."""
        if integer:
            low, high = math.ceil(self.low), math.floor(self.high)
            if low > high:
                raise InputError(f"the range [{self.low}, {self.high}] holds no whole number")
            if self.log:
                value = math.exp(rng.uniform(math.log(low), math.log(high)))
                return min(max(int(round(value)), low), high)
            return int(rng.integers(low, high, endpoint=True))
        if self.log:
            return float(math.exp(rng.uniform(math.log(self.low), math.log(self.high))))
        return float(rng.uniform(self.low, self.high))


def base_tables(base: Any, root: Path, trust: bool) -> dict[str, Any]:
    """The tables of the design file ``base`` (relative to ``root``; its "target" a list of
    tables where it has several [[target]] tables), a target's
    ``python = "file.py:..."`` made relative to that file. Anything but the path of a .toml
    file inside ``root`` (anywhere with ``trust``, :func:`rffqm_nlp.files.named_path`) is
    refused before it is opened; no message quotes the file's content."""
    path = named_path(root, base, "base", trust)
    if path.suffix != ".toml":
        raise InputError(f"base must name a design file ending in .toml, got "
                         f"{describe_value(base)}")
    shown = shown_name(path.name)           # the path itself is the study file's content
    try:
        exists = path.exists()
    except (OSError, ValueError):           # a name too long for the system
        raise InputError(f"base must name a design file, got {describe_value(base)}, which "
                         "is no path this system can open") from None
    if not exists:
        raise InputError(f"base: no such design file {shown} ({describe_value(base)}; "
                         "paths are relative to the study file)")
    try:
        tables = read_toml(_ShownPath(path, shown), "base file")
    except InputError as exc:                # names the file by _ShownPath's str
        raise InputError(str(exc)) from None
    several = tables.get("target") if isinstance(tables.get("target"), list) else None
    try:
        tables = check_table({k: v for k, v in tables.items() if k != "target"} if several
                             else tables, FILE_KEYS, "")
        if several:
            state_tables(several)  # 2 to MAX_STATES tables, each state's omega and weight
        targets = [dict(t) for t in several] if several else [dict(tables.get("target", {}))]
    except InputError as exc:
        raise InputError(f"base file {shown}: {exc}") from None
    for target in targets:
        if "python" in target:
            try:
                target["python"] = resolve_reference(target["python"], path.parent)
            except InputError as exc:
                raise InputError(f"base file {shown}: {exc}") from None
    tables["target"] = targets if several else targets[0]
    return tables


class _ShownPath(os.PathLike):
    """A path that opens as ``path`` and reads as ``shown`` in messages."""

    def __init__(self, path: Path, shown: str):
        self.path, self.shown = path, shown

    def __fspath__(self) -> str:
        return os.fspath(self.path)

    def __str__(self) -> str:
        return self.shown


def check_key(key: str, where: str = "[sweep]") -> None:
    """Refuse ``key`` unless it is "<table>.<key>" with a table of :data:`TABLES`, a plain
    name (:func:`~rffqm_nlp.files.shown_name` shows it as it is: it appears in messages,
    designs' names and the table's columns) and, for design and solve, a known key."""
    if not isinstance(key, str):
        raise InputError(f"{where}: {describe_value(key)} is not a parameter; name one as "
                         f"\"<table>.<key>\"")
    table, _, item = key.partition(".")
    if table not in TABLES or not item or "." in item or shown_name(item) != item:
        raise InputError(f"{where}: {shown_name(key)} is not a parameter; name one as "
                         f"\"<table>.<key>\" with table one of {', '.join(TABLES)} (e.g. "
                         "\"target.radius\", \"design.panels\", \"solve.seed\")")
    known = {"design": list(DESIGN_KEYS), "solve": list(SOLVE_KEYS)}.get(table)
    if known is not None and item not in known:
        close = difflib.get_close_matches(item, known, n=1)
        hint = f"did you mean {table}.{close[0]}?" if close else f"known: {', '.join(known)}"
        if table == "design" and item in SOLVE_KEYS:
            hint = f"it is a solve option: sweep \"solve.{item}\""
        raise InputError(f"{where}: unknown {table} key {shown_name(item)}; {hint}")


def dotted(table: Mapping[str, Any], where: str) -> Iterator[tuple[str, Any]]:
    """(dotted key, value) of a [sweep] or case table, accepting both "target.radius" = ...
    and the nested form TOML makes of an unquoted target.radius = ..."""
    for key, value in table.items():
        if "." in key:
            yield key, value
        elif key in TABLES and isinstance(value, dict):
            for item, inner in value.items():
                yield f"{key}.{item}", inner
        else:
            raise InputError(f"{where}: {shown_name(key)} is not a parameter; name one as "
                             f"\"<table>.<key>\" with table one of {', '.join(TABLES)}"
                             + (f" (controls: {', '.join(SWEEP_CONTROLS)})"
                                if where == "[sweep]" else ""))


def range_or_list(key: str, value: Any) -> list | Range:
    if isinstance(value, dict):
        if not {"low", "high"} <= set(value) <= set(RANGE_KEYS):
            raise InputError(f"[sweep] {shown_name(key)}: a range is {{low = a, high = b}} "
                             "(optionally log = true); to sweep tables give a list of them")
        try:
            return Range(**value)
        except InputError as exc:
            raise InputError(f"[sweep] {shown_name(key)}: {exc}") from None
    return value


def check_whole_range(key: str, values: Range) -> None:
    """Refuse a range of whole numbers with a bound beyond :data:`MAX_WHOLE`."""
    for bound, value in (("low", values.low), ("high", values.high)):
        if abs(value) > MAX_WHOLE:
            raise InputError(f"[sweep] {key}: {bound} must be a number in [-2**53, 2**53] "
                             f"(a range of whole numbers), got {describe_value(value)}")


def check_depth(value: Any, where: str) -> None:
    """Refuse a value nested deeper than :data:`MAX_DEPTH` lists or tables."""
    level = [value]
    for _ in range(MAX_DEPTH + 1):
        level = [item for v in level if isinstance(v, (list, tuple, dict))
                 for item in (v.values() if isinstance(v, dict) else v)]
        if not level:
            return
    raise InputError(f"{where}: a value nests lists or tables more than {MAX_DEPTH} deep")
