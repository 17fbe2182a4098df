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

The study file and its checks are in :mod:`.schema` and :mod:`.limits`, the study and its
designs in :mod:`.study` (named by :mod:`.names`), one design's solve in :mod:`.task`, the
run in :mod:`.running`, the designs' folders in :mod:`.outcomes` and the table in
:mod:`.results_table`.
"""

from __future__ import annotations

from .limits import MAX_DEPTH, MAX_DESIGNS, MAX_INDEX, MAX_LABEL, MAX_PARAMETERS, MAX_WHOLE
from .names import design_id
from .outcomes import (DESIGNS_DIR, FIT_COLUMNS, FLAG_COLUMNS, KEPT_ROW_STATUSES,
                       OUTCOME_COLUMNS, ROW_FILE, ROW_FORMAT, ROW_VERSION, STATE_COLUMNS,
                       completed_row, save_outcome, state_columns)
from .results_table import CSV_FORMULA_STARTS, TABLE_NAME, csv_frame, csv_text, table, write_table
from .running import WORKER_ENV, Task, run
from .schema import (CASE_NAME, INTEGER_KEYS, RANGE_KEYS, STUDY_FILE_KEYS, SWEEP_CONTROLS,
                     TABLES, Range)
from .study import Design, Study, design_config
from .task import one_thread, solve_design

__all__ = ["CASE_NAME", "CSV_FORMULA_STARTS", "DESIGNS_DIR", "FIT_COLUMNS", "FLAG_COLUMNS",
           "INTEGER_KEYS", "KEPT_ROW_STATUSES", "MAX_DEPTH", "MAX_DESIGNS", "MAX_INDEX",
           "MAX_LABEL", "MAX_PARAMETERS", "MAX_WHOLE", "OUTCOME_COLUMNS", "RANGE_KEYS",
           "ROW_FILE", "ROW_FORMAT", "ROW_VERSION", "STATE_COLUMNS", "STUDY_FILE_KEYS",
           "SWEEP_CONTROLS",
           "TABLES", "TABLE_NAME", "WORKER_ENV", "Design", "Range", "Study", "Task",
           "completed_row", "csv_frame", "csv_text", "design_config", "design_id",
           "one_thread", "run", "save_outcome", "solve_design", "state_columns", "table",
           "write_table"]
