"""The folder of each design of a run: its row (row.json) and, when solved, its result
(result.json), written by :func:`save_outcome` and read back by :func:`completed_row`
when a re-run decides what to skip."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..design.results import DesignResult, Fit
from ..errors import RffqmError
from ..files import read_json, write_json
from .names import canonical, design_id
from .study import Design


#: Fit measures copied from DesignResult.fit into the table: the fields of Fit.
FIT_COLUMNS = tuple(f.name for f in dataclasses.fields(Fit))
#: The Fit columns that hold a flag (collision_free): nullable booleans in the table, empty
#: for a design that failed; the other Fit columns are floats.
FLAG_COLUMNS = tuple(f.name for f in dataclasses.fields(Fit) if str(f.type).startswith("bool"))
#: Outcome columns of every row, after id, name, case and the swept parameters.
OUTCOME_COLUMNS = ("status", "solver_status", "reason", *FIT_COLUMNS, "iterations", "start",
                   "build_time", "solve_time", "time", "worker", "host")
#: Columns of each state of a design of several states (docs/several_states.md), named
#: ``state{k}_{column}`` (k from 1): its omega, and from the second state on its Fit; the
#: plain Fit columns are the first state's.
STATE_COLUMNS = ("omega", *FIT_COLUMNS)
#: Statuses of finished designs that a re-run keeps; "error" and "worker_lost" are retried.
KEPT_ROW_STATUSES = ("solved", "infeasible", "failed")
DESIGNS_DIR = "designs"
ROW_FILE = "row.json"
ROW_FORMAT = "rffqm-nlp sweep row"
ROW_VERSION = 1


def states_of(config: Mapping[str, Any]) -> int:
    """The number of folded states a design's configuration asks for: one per [[target]]
    table (one for a single [target])."""
    target = config.get("target")
    return len(target) if isinstance(target, list) else 1


def state_columns(states: int) -> tuple[str, ...]:
    """The per-state columns of a design of ``states`` states (none for one state):
    ``state1_omega``, then each further state's :data:`STATE_COLUMNS`."""
    if states < 2:
        return ()
    return ("state1_omega", *(f"state{k}_{column}" for k in range(2, states + 1)
                              for column in STATE_COLUMNS))


def state_values(result: DesignResult) -> dict[str, Any]:
    """The per-state columns of ``result`` (:func:`state_columns`) with their values."""
    if len(result.states) < 2:
        return {}
    values: dict[str, Any] = {"state1_omega": result.states[0].omega}
    for k, state in enumerate(result.states[1:], start=2):
        values[f"state{k}_omega"] = state.omega
        values.update({f"state{k}_{key}": value for key, value in state.fit.to_dict().items()})
    return values


def row_columns(config: Mapping[str, Any]) -> tuple[str, ...]:
    """The columns of the row of a design of ``config``: :data:`OUTCOME_COLUMNS`, then
    its per-state columns."""
    return OUTCOME_COLUMNS + state_columns(states_of(config))


def save_outcome(folder: Path, design: Design, outcome: Mapping[str, Any]) -> dict[str, Any]:
    """Write a design's folder (result.json when solved, then row.json) and return its
    table row."""
    folder.mkdir(parents=True, exist_ok=True)
    row = {column: outcome["row"].get(column) for column in row_columns(design.config)}
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
        row = {column: record["row"][column] for column in row_columns(design.config)}
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
            if (canonical(result.problem) != canonical(design.config)
                    or result.folded.shape != (N + 1, M + 1, 3)
                    or result.fit.to_dict() != {k: row[k] for k in FIT_COLUMNS}
                    or state_values(result) != {k: row[k] for k in
                                                state_columns(states_of(design.config))}):
                return None
        except (TypeError, ValueError, AttributeError):
            return None
    return row
