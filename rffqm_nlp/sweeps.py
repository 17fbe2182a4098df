"""Design studies at scale: parameter sweeps and multistart on Dask (extra ``sweep``).

A :class:`Study` is a base design problem and the parameters to vary. Its TOML file::

    base = "../targets/sphere_cap.toml"     # a design file, relative to this file; or inline:
    [target]                                # [target] / [design] / [solve] tables (keys here
    name = "sphere_cap"                     #   override the base file's; setting target.name
    [design]                                #   or target.python drops the base's target keys)
    panels = [8, 8]
    [solve]                                 # the SolveOptions, e.g.
    stop_rms = 0.012                        #   stop at 1.2% of the diameter
    multistart = 1                          #   starts per design (keep the best fit)
    [sweep]                                 # dotted keys "<table>.<key>", table one of
    "target.radius" = [3.0, 4.0]            #   target, design, solve: a list of values each
    "design.layout" = ["zigzag_i", "zigzag_j"]   # (the grid is their product);
    "design.panels" = [8, 12]               #   an integer p in design.panels means (p, p)
    [[sweep.cases]]                         # optional: explicit combinations, crossed with
    name = "small"                          #   the grid (a key may not be in both)
    "target.domain" = [[-0.3, 0.3], [-0.3, 0.3]]

With ``sample = K`` (and ``seed``) in [sweep], K designs are drawn at random instead of the
whole grid: a list of values is drawn from uniformly, ``{low = a, high = b}`` (optionally
``log = true``) uniformly in [a, b] (whole numbers for max_iter, multistart and seed); a
study of lists only draws K distinct grid points.

A study has at most :data:`MAX_DESIGNS` designs (its grid, or its sample), counted before
any of them is built (:attr:`Study.count`); a larger one, a range whose whole numbers a draw
cannot hold, or a study file of any other malformed kind is refused in one
:class:`~rffqm_nlp.errors.InputError` line that quotes nothing of the file.

Every design gets a stable ``id`` (a hash of its full configuration, defaults included) and a
readable ``name`` (its swept values). :func:`run` solves each design as one Dask task (a
:class:`~distributed.LocalCluster` of single-threaded worker processes by default, an
existing scheduler by address, or serially in this process with ``scheduler="none"``, using
the same task function :func:`solve_design`) and streams the outcomes into ``OUT``:

* ``designs/<id>/row.json``: the design's table row and configuration, written last;
* ``designs/<id>/result.json``: the :class:`~rffqm_nlp.design.results.DesignResult` of a
  solved design;
* ``results.parquet`` and ``results.csv``: one row per finished design, rewritten
  atomically as each design finishes; in the CSV every text cell that a spreadsheet would
  read as a formula is prefixed with ``'`` (:func:`csv_frame`), the Parquet file keeps the
  values as they are.

A design that is infeasible or whose solver fails is a row with its status and reason; a
design whose worker process dies (Dask's KilledWorker) is submitted again, up to
``worker_retries`` times, and then is a row with status "worker_lost". Re-running a
study into the same ``OUT`` skips every design whose folder holds a valid, matching outcome
(solved, infeasible or failed); any other folder is removed and the design recomputed.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import hashlib
import importlib.util
import itertools
import json
import logging
import math
import os
import re
import shutil
import socket
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import AbstractContextManager, contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from threadpoolctl import OpenBLASController, register, threadpool_limits

from .design.problem import FILE_KEYS, SOLVE_KEYS, DesignProblem, SolveOptions, check_memory
from .design.problem import from_config as problem_from_config
from .errors import InfeasibleDesign, InputError, RffqmError, SolverFailed, one_line
from .files import (Key, atomic_path, check_table, check_value, describe_value, named_path,
                    read_json, read_toml, shown_name, write_json)
from .targets.surfaces import resolve_reference
from .design.results import DesignResult, Fit, SolveStats

if TYPE_CHECKING:
    import pandas as pd
    from distributed import Client
    from rich.console import Console

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
#: Fit measures copied from DesignResult.fit into the table: the fields of Fit.
FIT_COLUMNS = tuple(f.name for f in dataclasses.fields(Fit))
#: The Fit columns that hold a flag (collision_free): nullable booleans in the table, empty
#: for a design that failed; the other Fit columns are floats.
FLAG_COLUMNS = tuple(f.name for f in dataclasses.fields(Fit) if str(f.type).startswith("bool"))
#: Outcome columns of every row, after id, name, case and the swept parameters.
OUTCOME_COLUMNS = ("status", "solver_status", "reason", *FIT_COLUMNS, "iterations", "start",
                   "build_time", "solve_time", "time", "worker", "host")
#: Statuses of finished designs that a re-run keeps; "error" and "worker_lost" are retried.
KEPT_ROW_STATUSES = ("solved", "infeasible", "failed")
DESIGNS_DIR = "designs"
ROW_FILE = "row.json"
TABLE_NAME = "results"
ROW_FORMAT = "rffqm-nlp sweep row"
ROW_VERSION = 1
#: Environment of local worker processes: one thread each for every numerical library.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
#: Most designs a study may have: its grid (cases x the product of the lists' lengths) or
#: its ``sample``, counted before any design is built. Every design is checked before the
#: first solve, and the table is rewritten as each design finishes (the cost of both at
#: the limit: docs/sweeps.md, "Limits").
MAX_DESIGNS = 10_000
#: Most parameters a study may vary ([sweep] keys and the cases' keys together).
MAX_PARAMETERS = 100
#: Deepest nesting of a swept value (a domain [[a, b], [c, d]] is 2 deep).
MAX_DEPTH = 8
#: Largest magnitude of a bound of a range of whole numbers (max_iter, multistart, seed):
#: every whole number up to it is a float, and a draw holds it.
MAX_WHOLE = 2 ** 53
#: Largest grid that ``sample = K`` draws its K indices from (NumPy's 64-bit integers); a
#: larger grid of lists is sampled a value of each list at a time.
MAX_INDEX = 2 ** 62
#: A case's name: 1 to 32 ASCII letters, digits, spaces (not at either end) and _ . + - =;
#: it is part of its designs' names, which messages and the progress show as they are.
CASE_NAME = re.compile(r"[A-Za-z0-9_.+=-](?:[A-Za-z0-9 _.+=-]{0,30}[A-Za-z0-9_.+=-])?")
#: First characters of a CSV text cell that a spreadsheet reads as a formula (OWASP's CSV
#: injection list: = + - @ tab and carriage return; also line feed and the full-width
#: = + - @ that some spreadsheets treat alike): such a cell is written with a ' before it.
CSV_FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r", "\n", "\uff1d", "\uff0b", "\uff0d",
                      "\uff20")
#: Longest label of a swept value in a design's name; a longer one is named by its kind.
MAX_LABEL = 60


# --------------------------------------------------------------------------- the study
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


@dataclass(frozen=True)
class Design:
    """One design of a study: ``config`` = {"target", "design", "solve"} with every default
    filled in (what :func:`solve_design` solves), ``params`` its swept values by key,
    ``case`` the name of its [[sweep.cases]] entry ("" when it has none)."""

    id: str
    name: str
    params: dict[str, Any]
    config: dict[str, Any]
    case: str = ""
    trust: bool = False

    def payload(self) -> dict[str, Any]:
        """What a task receives: plain data (CasADi objects do not pickle); ``trust``: the
        study was loaded trusting the code its target names."""
        return {"id": self.id, "name": self.name, "config": self.config, "trust": self.trust}


@dataclass(frozen=True)
class Study:
    """A base design and the parameters to vary; see the module docstring.

    ``base``: {"target": ..., "design": ..., "solve": ...} tables; ``parameters``: dotted
    key -> list of values (or :class:`Range` with ``sample``); ``cases``: explicit
    combinations (dotted key -> value, plus an optional "name"), crossed with the grid;
    ``sample``: draw this many designs instead of the grid, with ``seed``; ``source``: the
    study file, named in the errors of :meth:`designs`; ``root``: the folder that a target's
    ``python = "file.py:function"`` is relative to; ``trust``: run the code a target names
    (refused without it, see :func:`rffqm_nlp.targets.surfaces.from_config`).
    """

    base: dict[str, Any]
    parameters: dict[str, list | Range] = field(default_factory=dict)
    cases: tuple[dict[str, Any], ...] = ()
    sample: int | None = None
    seed: int = 0
    description: str = ""
    source: str = ""
    root: str = "."
    trust: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.base, Mapping):
            raise InputError(f"a study's base must be a table, got {describe_value(self.base)}")
        for table, values in self.base.items():
            if table not in TABLES:
                raise InputError(f"unknown base table {shown_name(table)}; a base has "
                                 f"{', '.join(TABLES)}")
            if not isinstance(values, Mapping):
                raise InputError(f"[{table}] must be a table, got {describe_value(values)}")
        if not isinstance(self.parameters, Mapping):
            raise InputError(f"[sweep] must be a table, got {describe_value(self.parameters)}")
        if self.sample is not None:
            check_value(self.sample, Key("whole", low=1, high=MAX_DESIGNS,
                                         hint="(the most designs a study may have)"),
                        "[sweep] sample")
        check_value(self.seed, Key("whole", low=0), "[sweep] seed")
        for key, values in self.parameters.items():
            _check_key(key)
            if isinstance(values, Range):
                if key == "design.panels":
                    raise InputError("[sweep] design.panels takes a list of sizes, not a range")
                if self.sample is None:
                    raise InputError(f"[sweep] {key} is a range {{low, high}}, which only "
                                     "sample = K draws from; give a list of values for a grid")
                if key in INTEGER_KEYS:
                    _check_whole_range(key, values)
            elif not isinstance(values, (list, tuple)) or not values:
                raise InputError(f"[sweep] {key} must be a non-empty list of values (or "
                                 f"{{low, high}} with sample = K), got "
                                 f"{describe_value(values)}; put a "
                                 f"fixed setting in the [{key.split('.')[0]}] table instead")
            else:
                for value in values:
                    _check_depth(value, f"[sweep] {key}")
        object.__setattr__(self, "parameters", {k: v if isinstance(v, Range) else list(v)
                                                for k, v in self.parameters.items()})
        if not isinstance(self.cases, (list, tuple)) or not all(
                isinstance(c, Mapping) for c in self.cases):
            raise InputError("sweep.cases must be an array of tables: [[sweep.cases]]")
        object.__setattr__(self, "cases", tuple(dict(c) for c in self.cases))
        for i, case in enumerate(self.cases):
            where = f"[[sweep.cases]] #{i + 1}"
            for key, value in case.items():
                if key == "name":
                    if not isinstance(value, str) or not CASE_NAME.fullmatch(value):
                        raise InputError(f"{where} name must be 1 to 32 ASCII letters, digits, "
                                         "spaces (not at either end) or _ . + - =, got "
                                         f"{describe_value(value)}")
                    continue
                _check_key(key, where)
                if key in self.parameters:
                    raise InputError(f"{key} is both a [sweep] parameter and set by "
                                     f"{where}; keep one")
                _check_depth(value, f"{where} {key}")
        if len(self.swept) > MAX_PARAMETERS:
            raise InputError(f"[sweep]: the study varies {len(self.swept)} parameters, more "
                             f"than the {MAX_PARAMETERS} a study may vary")
        self._check_count()

    def _check_count(self) -> None:
        """Refuse a grid of more than :data:`MAX_DESIGNS` designs, and a sample larger than
        the number of distinct designs there are to draw, before any design is built."""
        lists = {k: len(v) for k, v in self.parameters.items() if not isinstance(v, Range)}
        factors = ([f"{len(self.cases)} cases"] if self.cases else []) + [
            f"{k} ({n})" for k, n in lists.items()]
        if self.sample is None:
            count = self.grid_size()
            if count > MAX_DESIGNS:
                raise InputError(f"[sweep]: the grid has {_count_text(count)} designs "
                                 f"({' x '.join(factors)}), more than the limit of "
                                 f"{MAX_DESIGNS} designs a study may have; sweep fewer "
                                 "values, or draw some of them with sample = K")
            return
        distinct = self.grid_size()
        for key, values in self.parameters.items():
            if not isinstance(values, Range):
                continue
            if key not in INTEGER_KEYS:
                return                              # real numbers: no end of distinct draws
            whole = values.whole_numbers()
            if whole == 0:
                raise InputError(f"[sweep] {key}: the range [{values.low:g}, {values.high:g}] "
                                 "holds no whole number")
            distinct *= whole
            factors.append(f"{key} ({whole} whole numbers)")
            if distinct > self.sample:
                return
        if self.sample > distinct:
            if not any(isinstance(v, Range) for v in self.parameters.values()):
                raise InputError(f"[sweep] sample = {self.sample} but the grid has only "
                                 f"{distinct} designs; drop sample to run them all")
            raise InputError(f"[sweep] sample = {self.sample} but the study has only "
                             f"{distinct} distinct designs ({' x '.join(factors)}); widen the "
                             "ranges or lower sample")

    @property
    def count(self) -> int:
        """The number of designs: ``sample``, or the size of the grid; counted without
        building any (at most :data:`MAX_DESIGNS`)."""
        return self.grid_size() if self.sample is None else self.sample

    def grid_size(self) -> int:
        """Cases (at least one) x the product of the lists' lengths: the number of designs
        of the grid, which ``sample`` draws from when the study has no range."""
        return math.prod([len(self.cases) or 1] + [len(v) for v in self.parameters.values()
                                                   if not isinstance(v, Range)])

    # -------------------------------------------------------------- loading
    @classmethod
    def load(cls, path: str | os.PathLike, trust: bool = False) -> "Study":
        """A study from its TOML file; ``base`` and a target's ``python = "file.py:..."``
        are relative to the file; ``trust``: run the code a target names."""
        path = Path(path)
        config = read_toml(path, "study file")
        try:
            return replace(cls.from_config(config, root=path.parent, trust=trust),
                           source=str(path))
        except InputError as exc:
            raise InputError(f"{path}: {exc}") from None

    @classmethod
    def from_config(cls, config: Mapping[str, Any], root: str | os.PathLike = ".",
                    trust: bool = False) -> "Study":
        """A study from the tables of a study file (``base`` relative to ``root``)."""
        config = check_table(config, STUDY_FILE_KEYS, "")
        base: dict[str, dict] = {table: {} for table in TABLES}
        if "base" in config:
            for table, values in _base_tables(config["base"], Path(root), trust).items():
                base[table].update(values)
        for table in TABLES:
            inline = config.get(table, {})
            if table == "target" and ("name" in inline or "python" in inline):
                base["target"] = {}
            base[table].update(inline)
        spec = dict(config.get("sweep", {}))
        cases = spec.pop("cases", [])
        if not isinstance(cases, list) or not all(isinstance(c, dict) for c in cases):
            raise InputError("sweep.cases must be an array of tables: [[sweep.cases]]")
        sample = spec.pop("sample", None)
        seed = spec.pop("seed", None)
        if seed is not None and sample is None:
            raise InputError("[sweep] seed only seeds sample = K; for the seed of the multistart "
                             "perturbations set solve.seed (or sweep \"solve.seed\" = [...])")
        parameters = {key: _range_or_list(key, value) for key, value in _dotted(spec, "[sweep]")}
        named_cases = []
        for i, case in enumerate(cases):
            case = dict(case)
            name = case.pop("name", None)
            flat = dict(_dotted(case, f"[[sweep.cases]] #{i + 1}"))
            if name is not None:
                flat["name"] = name
            named_cases.append(flat)
        return cls(base=base, parameters=parameters, cases=tuple(named_cases), sample=sample,
                   seed=0 if seed is None else seed,
                   description=config.get("description", ""), root=str(root), trust=trust)

    # -------------------------------------------------------------- expansion
    @property
    def swept(self) -> list[str]:
        """The varied keys, cases' keys first, in the order given."""
        keys = [k for case in self.cases for k in case if k != "name"]
        return list(dict.fromkeys(keys + list(self.parameters)))

    def points(self) -> list[tuple[str | None, dict[str, Any]]]:
        """The overrides of each design: (case name or None, dotted key -> value), the grid
        (cases x product of the lists) or ``sample`` random draws."""
        cases = list(self.cases) or [{}]
        keys = list(self.parameters)
        ranges = any(isinstance(v, Range) for v in self.parameters.values())
        if self.sample is None:                  # at most MAX_DESIGNS (__post_init__)
            grid = [(case, dict(zip(keys, combo))) for case in cases
                    for combo in itertools.product(*(self.parameters[k] for k in keys))]
        elif not ranges and self.grid_size() <= MAX_INDEX:
            # the K indices of the grid in product order, without building the grid
            rng = np.random.default_rng(self.seed)
            grid = [self._grid_point(int(i))
                    for i in rng.choice(self.grid_size(), self.sample, replace=False)]
        else:
            rng = np.random.default_rng(self.seed)
            grid, drawn = [], set()
            for _ in range(100 * self.sample):
                case = cases[int(rng.integers(len(cases)))]
                values = {k: v.draw(rng, k in INTEGER_KEYS) if isinstance(v, Range)
                          else v[int(rng.integers(len(v)))] for k, v in self.parameters.items()}
                key = _canonical([case, values], lenient=True)
                if key not in drawn:
                    drawn.add(key)
                    grid.append((case, values))
                if len(grid) == self.sample:
                    break
            else:
                raise InputError(f"[sweep] sample = {self.sample}: only {len(grid)} distinct "
                                 f"designs in {100 * self.sample} draws; widen the ranges or "
                                 "lower sample")
        return [(case.get("name"), {**{k: v for k, v in case.items() if k != "name"}, **values})
                for case, values in grid]

    def _grid_point(self, index: int) -> tuple[dict[str, Any], dict[str, Any]]:
        """The ``index``-th (case, values) of the grid in the order of
        ``itertools.product(cases, *lists)`` (the last list varies fastest)."""
        values: dict[str, Any] = {}
        for key in reversed(list(self.parameters)):
            items = self.parameters[key]
            index, at = divmod(index, len(items))
            values[key] = items[at]
        case = self.cases[index] if self.cases else {}
        return case, {k: values[k] for k in self.parameters}

    def designs(self) -> list[Design]:
        """Every design of the study, each validated (an invalid combination raises
        :class:`InputError` naming the design); two designs that are the same problem raise."""
        try:
            return self._designs()
        except InputError as exc:
            if not self.source:
                raise
            raise InputError(f"{self.source}: {exc}") from None

    def _designs(self) -> list[Design]:
        designs: list[Design] = []
        seen: dict[str, str] = {}
        short = _short_names(self.swept)
        for case, overrides in self.points():     # names: safe pieces only (_label)
            label = " ".join(f"{short[k]}={_label(v)}" for k, v in overrides.items()
                             if case is None or k in self.parameters)
            name = " ".join(p for p in (case, label) if p) or "base"
            config = design_config(self.base, overrides, name, self.root, self.trust)
            design = Design(id=design_id(config), name=name, params=overrides, config=config,
                            case=case or "", trust=self.trust)
            if design.id in seen:
                raise InputError(f"designs '{seen[design.id]}' and '{name}' are the same "
                                 f"problem (id {design.id}); remove the duplicate value")
            seen[design.id] = name
            designs.append(design)
        return designs


def design_config(base: Mapping[str, Any], overrides: Mapping[str, Any],
                  name: str = "design", root: str | os.PathLike = ".",
                  trust: bool = False) -> dict[str, Any]:
    """The full configuration {"target", "design", "solve"} of ``base`` with the dotted
    ``overrides`` applied, every default filled in (via :class:`DesignProblem` and
    :class:`SolveOptions`), validated, and refused when this machine cannot hold its solve
    (:func:`rffqm_nlp.design.problem.check_memory`). ``name`` names the design in the errors, as it
    is: a design's name is made of safe pieces (:meth:`Study.designs`).

    Setting target.name or target.python starts the target table afresh; an integer p as
    design.panels means (p, p); ``root`` and ``trust`` as for
    :func:`rffqm_nlp.design.problem.from_config`.
    """
    tables = {table: dict(base.get(table, {})) for table in TABLES}
    if "target.name" in overrides or "target.python" in overrides:
        tables["target"] = {}
    for key, value in overrides.items():
        table, item = key.split(".", 1)
        tables[table][item] = value
    panels = tables["design"].get("panels")
    if isinstance(panels, int) and not isinstance(panels, bool):
        tables["design"]["panels"] = [panels, panels]
    try:
        problem, options = problem_from_config(tables, root, trust)
        check_memory(problem, options)
    except InputError as exc:
        raise InputError(f"design '{name}': {exc}") from None
    except (TypeError, ValueError, ArithmeticError) as exc:
        # a library's own text may quote the value: only the kind of the failure is said
        raise InputError(f"design '{name}': a value of its [target], [design] or [solve] "
                         f"table is not allowed ({type(exc).__name__}); check the values the "
                         "study sets for it") from None
    return problem.config(options)


def design_id(config: Mapping[str, Any]) -> str:
    """12 hex digits of the SHA-256 of the canonical JSON of ``config`` (keys sorted,
    integers as floats, so 4 and 4.0 give the same id)."""
    return hashlib.sha256(_canonical(config).encode()).hexdigest()[:12]


# --------------------------------------------------------------------------- one design
def solve_design(payload: Mapping[str, Any]) -> dict[str, Any]:
    """Solve one design: the task of every run, on a Dask worker or in this process.

    ``payload`` is :meth:`Design.payload`. Returns {"row": outcome columns, "result":
    DesignResult.to_dict() or None}. Never raises an :class:`Exception`: an infeasible
    design gives status "infeasible", a solver failure "failed" (with IPOPT's status), any
    other exception "error" with its type and message as the reason.

    The solve runs with one thread in every BLAS and OpenMP pool (:func:`one_thread`):
    wherever a design runs it then gives the same numbers, and workers sharing a machine do
    not oversubscribe it.
    """
    t0 = time.perf_counter()
    config = payload["config"]
    row: dict[str, Any] = {"worker": _worker_name(), "host": socket.gethostname()}
    result = None
    try:
        problem, options = problem_from_config(config, trust=bool(payload.get("trust")))
        with one_thread():
            result = problem.solve(options)
    except InfeasibleDesign as exc:
        row.update(status="infeasible", solver_status="Infeasible_Problem_Detected",
                   reason=one_line(exc))
    except SolverFailed as exc:
        row.update(status="failed", solver_status=exc.status, reason=one_line(exc),
                   **_stat_columns(exc.stats))
    except Exception as exc:  # a task turns every failure into a row
        row.update(status="error", solver_status="",
                   reason=f"{type(exc).__name__}: {one_line(exc)}")
    else:
        multistart = result.stats.multistart or {}
        row.update(status="solved", solver_status=result.stats.status, reason="",
                   **result.fit.to_dict(), **_stat_columns(result.stats),
                   start=multistart.get("chosen", 0))
    row["time"] = time.perf_counter() - t0
    return {"row": row, "result": None if result is None else result.to_dict()}


def _stat_columns(stats: SolveStats | None) -> dict[str, Any]:
    if stats is None:
        return {}
    return {"iterations": stats.iterations, "build_time": stats.build_time,
            "solve_time": stats.solve_time}


def one_thread() -> AbstractContextManager:
    """Limit every BLAS and OpenMP thread pool of this process to one thread (threadpoolctl),
    CasADi's own OpenBLAS under MUMPS included: threadpoolctl does not know that library by
    name, so it is registered here, and IPOPT's plugin is loaded first (``has_nlpsol`` loads
    it, silently when it already is) so that the library is found.

    The thread count of that OpenBLAS changes IPOPT's path in the last digits (iterations
    and fit, docs/solvers.md), so without the limit a serial run would not reproduce a
    cluster run's table.
    """
    import casadi

    _register_casadi_openblas()
    casadi.has_nlpsol("ipopt")
    return threadpool_limits(limits=1)


@functools.cache
def _register_casadi_openblas() -> None:
    class CasadiOpenBLAS(OpenBLASController):
        """The OpenBLAS that CasADi ships for its MUMPS (libcasadi-tp-openblas)."""

        filename_prefixes = ("libcasadi-tp-openblas",)

    register(CasadiOpenBLAS)


def _worker_name() -> str:
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "in-process"


# --------------------------------------------------------------------------- running
Task = Callable[[Mapping[str, Any]], dict[str, Any]]


def run(study: Study | str | os.PathLike, out: str | os.PathLike,
        scheduler: "str | Client | None" = None, workers: int = 2, progress: bool = True,
        worker_retries: int = 2, task: Task = solve_design,
        console: "Console | None" = None) -> "pd.DataFrame":
    """Run every design of ``study`` (a :class:`Study` or its TOML file) into ``out``.

    ``scheduler``: None or "local" for a LocalCluster of ``workers`` single-threaded worker
    processes; "none" to solve serially in this process; a scheduler address
    ("tcp://host:8786") or a :class:`distributed.Client` to use an existing cluster (its
    workers must import rffqm_nlp). At most one design per worker thread is in flight, so a
    dying worker takes no queued design with it; a design whose worker died is submitted
    again up to ``worker_retries`` times (on the local cluster Dask reports every death at
    once; an existing cluster first retries by its own allowed-failures setting).

    Designs already complete in ``out`` are skipped; see the module docstring for the
    files. ``progress`` shows a rich progress bar (and the Dask dashboard address when the
    cluster serves one) on ``console`` (default: stderr). ``task`` replaces
    :func:`solve_design` (same payload and return value), e.g. to inject failures in tests.
    Returns the table, one row per design in study order.
    """
    from rich.console import Console

    if not isinstance(study, Study):
        study = Study.load(study)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"workers must be a whole number >= 1, got {workers!r}")
    if isinstance(worker_retries, bool) or not isinstance(worker_retries, int) \
            or worker_retries < 0:
        raise InputError(f"worker_retries must be a whole number >= 0, got {worker_retries!r}")
    _require_extra(serial=scheduler == "none")
    console = console or Console(stderr=True)
    designs = study.designs()
    out = Path(out)
    rows: dict[str, dict[str, Any]] = {}
    pending: list[Design] = []
    for design in designs:
        row = completed_row(out / DESIGNS_DIR / design.id, design)
        if row is None:
            shutil.rmtree(out / DESIGNS_DIR / design.id, ignore_errors=True)
            pending.append(design)
        else:
            rows[design.id] = row
    (out / DESIGNS_DIR).mkdir(parents=True, exist_ok=True)
    if rows:
        write_table(out, study, designs, rows)
    if progress and rows:
        console.print(f"{len(rows)} of {len(designs)} designs already complete in {out}",
                      highlight=False)

    def finish(design: Design, outcome: Mapping[str, Any]) -> None:
        rows[design.id] = save_outcome(out / DESIGNS_DIR / design.id, design, outcome)
        write_table(out, study, designs, rows)

    if pending:
        with _progress(progress, console, len(designs), len(rows)) as advance:
            if scheduler == "none":
                for design in pending:
                    finish(design, task(design.payload()))
                    advance(design, rows[design.id])
            else:
                with _client(scheduler, workers) as client:
                    if progress:
                        _announce(client, console)
                    for design, outcome in _stream(client, pending, task, worker_retries):
                        finish(design, outcome)
                        advance(design, rows[design.id])
    return table(study, designs, rows)


def _stream(client: "Client", designs: Iterable[Design], task: Task,
            worker_retries: int) -> Iterator[tuple[Design, dict[str, Any]]]:
    """Submit the designs, at most one per worker thread at a time, and yield each
    (design, outcome) as it finishes. A design whose worker died (KilledWorker) goes to the
    front of the queue again, up to ``worker_retries`` times, and then yields status
    "worker_lost"; an error inside Dask itself yields status "error"."""
    from distributed import KilledWorker, as_completed

    queue = deque(designs)
    tries: dict[str, int] = {}
    by_key: dict[str, Design] = {}
    finished = as_completed()

    def top_up() -> None:
        """Submit designs until every live worker thread (at least one) has one."""
        capacity = max(1, sum(client.nthreads().values()))
        while queue and len(by_key) < capacity:
            design = queue.popleft()
            tries[design.id] = tries.get(design.id, 0) + 1
            future = client.submit(task, design.payload(), pure=False)
            by_key[future.key] = design
            finished.add(future)

    top_up()
    for future in finished:
        design = by_key.pop(future.key)
        try:
            outcome = future.result()
        except KilledWorker as exc:
            if tries[design.id] <= worker_retries:
                queue.appendleft(design)
                outcome = None
            else:
                outcome = {"row": {"status": "worker_lost", "solver_status": "",
                                   "reason": f"its worker process died on each of its "
                                             f"{tries[design.id]} tries ({one_line(exc)})"},
                           "result": None}
        except Exception as exc:  # never lose a row to an error outside the task
            outcome = {"row": {"status": "error", "solver_status": "",
                               "reason": f"{type(exc).__name__}: {one_line(exc)}"},
                       "result": None}
        future.release()
        top_up()
        if outcome is not None:
            yield design, outcome


@contextmanager
def _client(scheduler: "str | Client | None", workers: int) -> Iterator["Client"]:
    """A Dask client: of a new LocalCluster (None, "local") that reports a task whose worker
    died at once (allowed-failures 0) and does not profile, of the scheduler at an address,
    or the given client (left open)."""
    import dask
    from distributed import Client, LocalCluster

    if isinstance(scheduler, Client):
        yield scheduler
        return
    if scheduler in (None, "local"):
        try:
            # the workers' statistical profiler costs a share of every design's time
            with dask.config.set({"distributed.scheduler.allowed-failures": 0,
                                  "distributed.worker.profile.enabled": False}):
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1,
                                       processes=True, dashboard_address=":0",
                                       silence_logs=logging.ERROR, env=WORKER_ENV)
        except RuntimeError as exc:
            raise RffqmError(f"could not start a local Dask cluster ({one_line(exc)}); a "
                             "script that runs a sweep must call it under `if __name__ == "
                             "\"__main__\":` (worker processes import the script)") from exc
        with cluster, Client(cluster) as client:
            yield client
        return
    if not isinstance(scheduler, str):
        raise InputError(f"scheduler must be None, 'local', 'none', an address or a "
                         f"distributed.Client, got {scheduler!r}")
    try:
        client = Client(scheduler, timeout=10)
    except (OSError, ValueError) as exc:
        raise InputError(f"cannot connect to the Dask scheduler at {scheduler!r} "
                         f"({one_line(exc)}); start one with `dask scheduler`, or use "
                         "--scheduler local (a cluster on this machine) or none") from None
    with client:
        yield client


def _announce(client: "Client", console: "Console") -> None:
    """Print the cluster's size and its dashboard address (when it serves one)."""
    info = client.scheduler_info()
    threads = client.nthreads()
    console.print(f"Dask scheduler {info.get('address', '?')}: {len(threads)} workers, "
                  f"{sum(threads.values())} threads", highlight=False)
    if "dashboard" in info.get("services", {}):
        console.print(f"dashboard: {client.dashboard_link}", highlight=False)


@contextmanager
def _progress(enabled: bool, console: "Console", total: int,
              done: int) -> Iterator[Callable[[Design, Mapping[str, Any]], None]]:
    """Progress over designs; yields ``advance(design, row)``. On a terminal a rich
    progress bar with the count of each status; elsewhere (a log file) one line per
    finished design."""
    from rich.progress import (BarColumn, MofNCompleteColumn, Progress, TextColumn,
                               TimeElapsedColumn, TimeRemainingColumn)

    counts: dict[str, int] = {}
    live = enabled and console.is_terminal
    columns = (TextColumn("[bold]designs"), BarColumn(), MofNCompleteColumn(),
               TimeElapsedColumn(), TimeRemainingColumn(), TextColumn("{task.fields[counts]}"))
    with Progress(*columns, console=console, disable=not live) as bar:
        task_id = bar.add_task("designs", total=total, completed=done, counts="")

        def advance(design: Design, row: Mapping[str, Any]) -> None:
            counts[row["status"]] = counts.get(row["status"], 0) + 1
            bar.update(task_id, advance=1,
                       counts=", ".join(f"{n} {s}" for s, n in sorted(counts.items())))
            if enabled and not live:
                fit = "" if row.get("rms") is None else f", RMS {row['rms']:.3e}"
                seconds = "" if row.get("time") is None else f", {row['time']:.1f} s"
                console.print(f"[{done + sum(counts.values())}/{total}] {design.name} "
                              f"({design.id}): {row['status']}{fit}{seconds}",
                              highlight=False, markup=False)

        yield advance


# --------------------------------------------------------------------------- files
def save_outcome(folder: Path, design: Design, outcome: Mapping[str, Any]) -> dict[str, Any]:
    """Write a design's folder (result.json when solved, then row.json) and return its
    table row."""
    folder.mkdir(parents=True, exist_ok=True)
    row = {column: outcome["row"].get(column) for column in OUTCOME_COLUMNS}
    if outcome.get("result") is not None:
        DesignResult.from_dict(outcome["result"]).save(folder)
    record = {"format": ROW_FORMAT, "version": ROW_VERSION, "id": design.id,
              "name": design.name, "config": design.config, "row": row}
    write_json(folder / ROW_FILE, record)
    return row


def completed_row(folder: Path, design: Design) -> dict[str, Any] | None:
    """The saved row of ``design`` if its folder holds a complete, valid outcome of exactly
    this design: row.json of this id and configuration with a final status, and for a
    solved design a loadable result.json of the same problem and fit. Otherwise None."""
    try:
        record = read_json(folder / ROW_FILE, "row file")
        if (record.get("format") != ROW_FORMAT or record.get("version") != ROW_VERSION
                or record.get("id") != design.id or design_id(record["config"]) != design.id):
            return None
        row = {column: record["row"][column] for column in OUTCOME_COLUMNS}
    except (ValueError, KeyError, TypeError, AttributeError):   # InputError is a ValueError
        return None
    if row["status"] not in KEPT_ROW_STATUSES:
        return None
    if row["status"] == "solved":
        try:
            result = DesignResult.load(folder)
        except (RffqmError, OSError, KeyError, TypeError, ValueError, AttributeError):
            return None
        N, M = design.config["design"]["panels"]
        try:
            if (_canonical(result.problem) != _canonical(design.config)
                    or result.folded.shape != (N + 1, M + 1, 3)
                    or result.fit.to_dict() != {k: row[k] for k in FIT_COLUMNS}):
                return None
        except (TypeError, ValueError, AttributeError):
            return None
    return row


def table(study: Study, designs: list[Design], rows: Mapping[str, Mapping[str, Any]]
          ) -> "pd.DataFrame":
    """The results table: one row per finished design, in study order; columns id, name,
    case (when the study has cases), the swept keys, then :data:`OUTCOME_COLUMNS`."""
    import pandas as pd

    swept = study.swept
    records = []
    for design in designs:
        if design.id not in rows:
            continue
        record: dict[str, Any] = {"id": design.id, "name": design.name}
        if study.cases:
            record["case"] = design.case
        record.update({key: _cell(design.params.get(key)) for key in swept})
        record.update(rows[design.id])
        records.append(record)
    columns = ["id", "name", *(["case"] if study.cases else []), *swept, *OUTCOME_COLUMNS]
    frame = pd.DataFrame.from_records(records, columns=columns)
    for key in swept:
        frame[key] = _homogeneous(frame[key])
    for column in FIT_COLUMNS + ("build_time", "solve_time", "time"):
        frame[column] = frame[column].astype("boolean" if column in FLAG_COLUMNS
                                             else "float64")
    for column in ("iterations", "start"):
        frame[column] = frame[column].astype("Int64")
    return frame


def write_table(out: Path, study: Study, designs: list[Design],
                rows: Mapping[str, Mapping[str, Any]]) -> "pd.DataFrame":
    """Write results.parquet and results.csv into ``out`` atomically; return the table."""
    frame = table(study, designs, rows)
    with atomic_path(out / f"{TABLE_NAME}.parquet") as tmp:
        frame.to_parquet(tmp, index=False)
    with atomic_path(out / f"{TABLE_NAME}.csv") as tmp:
        csv_frame(frame).to_csv(tmp, index=False)
    return frame


def csv_frame(frame: "pd.DataFrame") -> "pd.DataFrame":
    """``frame`` for a CSV file: every text cell and column name that begins with one of
    :data:`CSV_FORMULA_STARTS` (after any spaces) gets a ``'`` before it, so a spreadsheet
    shows it as text instead of running it as a formula (OWASP's rule against CSV
    injection). Numbers, negative ones included, stay numbers; ``frame`` is not changed."""
    import pandas as pd

    safe = frame.copy()
    for column in safe.columns:
        cells = safe[column]
        if cells.dtype == object or isinstance(cells.dtype, pd.StringDtype):
            safe[column] = pd.Series([csv_text(cell) for cell in cells], index=cells.index,
                                     dtype=cells.dtype)
    safe.columns = [csv_text(column) for column in safe.columns]
    return safe


def csv_text(value: Any) -> Any:
    """A CSV cell: text that a spreadsheet would read as a formula with ``'`` before it,
    anything else as it is."""
    if isinstance(value, str) and (value.startswith(CSV_FORMULA_STARTS)
                                   or value.lstrip(" ").startswith(CSV_FORMULA_STARTS)):
        return "'" + value
    return value


# --------------------------------------------------------------------------- helpers
def _require_extra(serial: bool) -> None:
    """Raise with the install command when the ``sweep`` extra's packages are missing."""
    needed = ("pandas", "pyarrow") + (() if serial else ("distributed",))
    missing = [name for name in needed if importlib.util.find_spec(name) is None]
    if missing:
        raise RffqmError(f"sweeps need {', '.join(missing)}: pip install 'rffqm_nlp[sweep]'")


def _base_tables(base: Any, root: Path, trust: bool) -> dict[str, dict[str, Any]]:
    """The tables of the design file ``base`` (relative to ``root``), a target's
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
    try:
        tables = check_table(tables, FILE_KEYS, "")
    except InputError as exc:
        raise InputError(f"base file {shown}: {exc}") from None
    target = tables.get("target", {})
    if "python" in target:
        try:
            tables["target"] = {**target, "python": resolve_reference(target["python"],
                                                                      path.parent)}
        except InputError as exc:
            raise InputError(f"base file {shown}: {exc}") from None
    return tables


class _ShownPath(os.PathLike):
    """A path that opens as ``path`` and reads as ``shown`` in messages."""

    def __init__(self, path: Path, shown: str):
        self.path, self.shown = path, shown

    def __fspath__(self) -> str:
        return os.fspath(self.path)

    def __str__(self) -> str:
        return self.shown


def _check_key(key: str, where: str = "[sweep]") -> None:
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
    known = {"design": [f.name for f in dataclasses.fields(DesignProblem)
                        if f.name != "target"],
             "solve": list(SOLVE_KEYS)}.get(table)
    if known is not None and item not in known:
        close = difflib.get_close_matches(item, known, n=1)
        hint = f"did you mean {table}.{close[0]}?" if close else f"known: {', '.join(known)}"
        if table == "design" and item in SOLVE_KEYS:
            hint = f"it is a solve option: sweep \"solve.{item}\""
        raise InputError(f"{where}: unknown {table} key {shown_name(item)}; {hint}")


def _dotted(table: Mapping[str, Any], where: str) -> Iterator[tuple[str, Any]]:
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


def _range_or_list(key: str, value: Any) -> list | Range:
    if isinstance(value, dict):
        if not {"low", "high"} <= set(value) <= set(RANGE_KEYS):
            raise InputError(f"[sweep] {shown_name(key)}: a range is {{low = a, high = b}} "
                             "(optionally log = true); to sweep tables give a list of them")
        try:
            return Range(**value)
        except InputError as exc:
            raise InputError(f"[sweep] {shown_name(key)}: {exc}") from None
    return value


def _check_whole_range(key: str, values: Range) -> None:
    """Refuse a range of whole numbers with a bound beyond :data:`MAX_WHOLE`."""
    for bound, value in (("low", values.low), ("high", values.high)):
        if abs(value) > MAX_WHOLE:
            raise InputError(f"[sweep] {key}: {bound} must be a number in [-2**53, 2**53] "
                             f"(a range of whole numbers), got {describe_value(value)}")


def _check_depth(value: Any, where: str) -> None:
    """Refuse a value nested deeper than :data:`MAX_DEPTH` lists or tables."""
    level = [value]
    for _ in range(MAX_DEPTH + 1):
        level = [item for v in level if isinstance(v, (list, tuple, dict))
                 for item in (v.values() if isinstance(v, dict) else v)]
        if not level:
            return
    raise InputError(f"{where}: a value nests lists or tables more than {MAX_DEPTH} deep")


def _count_text(count: int) -> str:
    """A count of designs for a message: itself, or the power of ten it exceeds when long."""
    digits = len(str(count))
    return str(count) if digits <= 15 else f"more than 10**{digits - 1}"


def _short_names(keys: list[str]) -> dict[str, str]:
    """Each dotted key by its last part, or whole where two keys share the last part."""
    last = [k.split(".", 1)[1] for k in keys]
    return {k: (s if last.count(s) == 1 else k) for k, s in zip(keys, last)}


def _label(value: Any) -> str:
    """A swept value in a design's name (a long string by its length only: names appear in
    error messages, which never quote a file's content)."""
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value) if abs(value) < 10 ** 15 else f"({describe_value(value)})"
    if isinstance(value, list) and value and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
        text = "x".join(_label(v) for v in value)
    elif isinstance(value, (list, dict)):
        text = json.dumps(_shown_strings(value), separators=(",", ":"))
    elif isinstance(value, str):
        return shown_name(value)
    elif isinstance(value, (bool, type(None))):
        return str(value)
    else:                                    # e.g. a TOML date: by its kind
        return f"({describe_value(value)})"
    return text if len(text) <= MAX_LABEL else f"({describe_value(value)})"


def _shown_strings(value: Any) -> Any:
    """``value`` with every string (key or item) as :func:`rffqm_nlp.files.shown_name`."""
    if isinstance(value, dict):
        return {shown_name(k): _shown_strings(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_shown_strings(v) for v in value]
    if isinstance(value, str):
        return shown_name(value)
    return value if isinstance(value, (int, float, bool, type(None))) else \
        f"({describe_value(value)})"


def _cell(value: Any) -> Any:
    """A table cell: numbers, strings and booleans as they are, others as compact JSON."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return json.dumps(value, separators=(",", ":"), default=str)


def _homogeneous(column: "pd.Series") -> "pd.Series":
    """A swept column of one type (Parquet needs it): numbers as floats when ints and floats
    mix, everything as text when other types mix."""
    kinds = {type(v) for v in column if v is not None}
    if kinds <= {int, float} and len(kinds) > 1:
        return column.astype("float64")
    if len(kinds) > 1:
        return column.map(lambda v: v if v is None or isinstance(v, str)
                          else json.dumps(v, default=str))
    return column


def _canonical(config: Any, lenient: bool = False) -> str:
    """``config`` as canonical JSON (keys sorted, whole numbers as floats). ``lenient``
    (to tell raw drawn values apart): NaN allowed, any other value by its repr."""
    def norm(v: Any) -> Any:
        if isinstance(v, dict):
            return {str(k): norm(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [norm(x) for x in v]
        if isinstance(v, int) and not isinstance(v, bool):
            return float(v)
        return v

    return json.dumps(norm(config), sort_keys=True, separators=(",", ":"), allow_nan=lenient,
                      default=repr if lenient else None)
