"""The study: a base design and the parameters to vary (:class:`Study`), checked whole when it
is made, loaded from its TOML file, and expanded into its designs (:class:`Design`, each
with its full configuration, :func:`design_config`)."""

from __future__ import annotations

import itertools
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..design import check_memory
from ..design import from_config as problem_from_config
from ..errors import InputError
from ..files import Key, check_table, check_value, describe_value, read_toml, shown_name
from .limits import MAX_DESIGNS, MAX_INDEX, MAX_PARAMETERS
from .names import canonical, design_id, short_names, value_label
from .schema import (CASE_NAME, INTEGER_KEYS, STUDY_FILE_KEYS, TABLES, Range, base_tables,
                     check_depth, check_key, check_whole_range, dotted, range_or_list)


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
    """A base design and the parameters to vary; see :mod:`rffqm_nlp.sweeps`.

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
            several = table == "target" and isinstance(values, list)
            if not isinstance(values, Mapping) and not (
                    several and all(isinstance(v, Mapping) for v in values)):
                raise InputError(f"[{table}] must be a table, got {describe_value(values)}")
        if not isinstance(self.parameters, Mapping):
            raise InputError(f"[sweep] must be a table, got {describe_value(self.parameters)}")
        if self.sample is not None:
            check_value(self.sample, Key("whole", low=1, high=MAX_DESIGNS,
                                         hint="(the most designs a study may have)"),
                        "[sweep] sample")
        check_value(self.seed, Key("whole", low=0), "[sweep] seed")
        for key, values in self.parameters.items():
            check_key(key)
            self._check_several(key, "[sweep]")
            if isinstance(values, Range):
                if key == "design.panels":
                    raise InputError("[sweep] design.panels takes a list of sizes, not a range")
                if self.sample is None:
                    raise InputError(f"[sweep] {key} is a range {{low, high}}, which only "
                                     "sample = K draws from; give a list of values for a grid")
                if key in INTEGER_KEYS:
                    check_whole_range(key, values)
            elif not isinstance(values, (list, tuple)) or not values:
                raise InputError(f"[sweep] {key} must be a non-empty list of values (or "
                                 f"{{low, high}} with sample = K), got "
                                 f"{describe_value(values)}; put a "
                                 f"fixed setting in the [{key.split('.')[0]}] table instead")
            else:
                for value in values:
                    check_depth(value, f"[sweep] {key}")
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
                check_key(key, where)
                self._check_several(key, where)
                if key in self.parameters:
                    raise InputError(f"{key} is both a [sweep] parameter and set by "
                                     f"{where}; keep one")
                check_depth(value, f"{where} {key}")
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

    def _check_several(self, key: str, where: str) -> None:
        """Refuse a target key where the base designs one sheet for several targets (its
        [[target]] tables are its states; docs/several_states.md)."""
        if key.startswith("target.") and isinstance(self.base.get("target"), list):
            raise InputError(f"{where}: {shown_name(key)} sets a target, and the base has "
                             f"{len(self.base['target'])} [[target]] tables (one sheet for "
                             "several states); a study of it sweeps [design] and [solve] keys")

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
        base: dict[str, Any] = {table: {} for table in TABLES}
        if "base" in config:
            for table, values in base_tables(config["base"], Path(root), trust).items():
                if isinstance(values, list):  # several [[target]] tables: the states
                    base[table] = values
                else:
                    base[table].update(values)
        for table in TABLES:
            inline = config.get(table, {})
            if isinstance(base[table], list):
                if inline:
                    raise InputError("[target] cannot be set by a study whose base has "
                                     f"{len(base[table])} [[target]] tables (one sheet for "
                                     "several states); change them in the base file")
                continue
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
        parameters = {key: range_or_list(key, value) for key, value in dotted(spec, "[sweep]")}
        named_cases = []
        for i, case in enumerate(cases):
            case = dict(case)
            name = case.pop("name", None)
            flat = dict(dotted(case, f"[[sweep.cases]] #{i + 1}"))
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
                key = canonical([case, values], lenient=True)
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
        short = short_names(self.swept)
        for case, overrides in self.points():     # names: safe pieces only (value_label)
            label = " ".join(f"{short[k]}={value_label(v)}" for k, v in overrides.items()
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
    (:func:`rffqm_nlp.design.check_memory`). ``name`` names the design in the errors, as it
    is: a design's name is made of safe pieces (:meth:`Study.designs`).

    Setting target.name or target.python starts the target table afresh; an integer p as
    design.panels means (p, p); ``root`` and ``trust`` as for
    :func:`rffqm_nlp.design.from_config`.
    """
    tables: dict[str, Any] = {table: dict(base.get(table, {})) for table in TABLES
                              if not isinstance(base.get(table), list)}
    if isinstance(base.get("target"), list):  # the states of one sheet (docs/several_states.md)
        tables["target"] = [dict(target) for target in base["target"]]
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


def _count_text(count: int) -> str:
    """A count of designs for a message: itself, or the power of ten it exceeds when long."""
    digits = len(str(count))
    return str(count) if digits <= 15 else f"more than 10**{digits - 1}"
