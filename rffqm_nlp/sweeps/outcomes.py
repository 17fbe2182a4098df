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
#: Statuses of finished designs that a re-run keeps; "error" and "worker_lost" are retried.
KEPT_ROW_STATUSES = ("solved", "infeasible", "failed")
DESIGNS_DIR = "designs"
ROW_FILE = "row.json"
ROW_FORMAT = "rffqm-nlp sweep row"
ROW_VERSION = 1


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
            if (canonical(result.problem) != canonical(design.config)
                    or result.folded.shape != (N + 1, M + 1, 3)
                    or result.fit.to_dict() != {k: row[k] for k in FIT_COLUMNS}):
                return None
        except (TypeError, ValueError, AttributeError):
            return None
    return row
