"""The results table of a run: one row per finished design (:func:`table`), written as
results.parquet and as results.csv with every text cell a spreadsheet would read as a
formula made plain text (:func:`csv_frame`)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..files import atomic_path
from .outcomes import FIT_COLUMNS, FLAG_COLUMNS, OUTCOME_COLUMNS, state_columns, states_of
from .study import Design, Study

if TYPE_CHECKING:
    import pandas as pd


TABLE_NAME = "results"
#: First characters of a CSV text cell that a spreadsheet reads as a formula (OWASP's CSV
#: injection list: = + - @ tab and carriage return; also line feed and the full-width
#: = + - @ that some spreadsheets treat alike): such a cell is written with a ' before it.
CSV_FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r", "\n", "\uff1d", "\uff0b", "\uff0d",
                      "\uff20")


def table(study: Study, designs: list[Design], rows: Mapping[str, Mapping[str, Any]]
          ) -> "pd.DataFrame":
    """The results table: one row per finished design, in study order; columns id, name,
    case (when the study has cases), the swept keys, then :data:`OUTCOME_COLUMNS` and, for
    a base of several states, each state's (:func:`.outcomes.state_columns`)."""
    import pandas as pd

    swept = study.swept
    states = state_columns(states_of(study.base))
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
    columns = ["id", "name", *(["case"] if study.cases else []), *swept, *OUTCOME_COLUMNS,
               *states]
    frame = pd.DataFrame.from_records(records, columns=columns)
    for key in swept:
        frame[key] = _homogeneous(frame[key])
    for column in FIT_COLUMNS + ("build_time", "solve_time", "time") + states:
        flag = column.split("_", 1)[1] if column in states else column
        frame[column] = frame[column].astype("boolean" if flag in FLAG_COLUMNS
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
