"""The ``rffqm`` command: thin wrappers that parse, call the library and write files.

Commands: ``design`` (inverse design of a TOML target, with live solver progress), ``sweep``
(a study of many designs, one Dask task each, on a local cluster, an existing scheduler or
serially; resumable; see :mod:`rffqm_nlp.sweeps`), ``fold``, ``export``, ``render`` and
``view`` (of a saved design result), ``check`` (self-contact of a saved design or a FOLD
file, exit 1 when not free), ``make`` (cut and score files in mm, thick panels and a lock
for a saved design), ``mechanics`` (the bar-and-hinge model of a saved design:
stiffness, modes, Poisson's ratio, loads), ``targets`` (the built-in surfaces) and ``march``
(forward marching of a perturbed Miura-ori).

Every user error (missing or bad file, unknown target, a failed marching check, an
infeasible design, a solver failure, an option out of its range, a path no file can have)
ends with a one-line red reason and exit status 2, never a traceback; every message and
every path or name the commands print goes through :func:`rffqm_nlp.errors.safe_text` (one
line, control characters escaped). Options that are not of their type at all (``--frames
abc``, a path with a NUL character) are refused by typer itself, with its message on one
line and exit status 2. Numeric options are checked by :func:`rffqm_nlp.files.check_value`
against the ranges their help says, and sizes before any work: at most :data:`MAX_FRAMES`
states for any ``--frames``, the memory estimates of ``march``, ``fold`` and ``render``
(:mod:`rffqm_nlp.memory`), and the page size of ``view`` (:func:`rffqm_nlp.show.view.check_size`).

Files are written atomically; ``design`` and ``march`` write their folder into a staging
folder next to it and replace the output folder whole only when every file succeeded
(:func:`rffqm_nlp.files.replace_folder`), so a failure or a kill leaves the complete old
folder or the complete new one.

The command group and the order of the commands are in :mod:`.group`, one module per
command or group of commands (:mod:`.design_command`, :mod:`.check_command`,
:mod:`.sweep_command`, :mod:`.result_commands`, :mod:`.forward_commands`,
:mod:`.make_command`, :mod:`.mechanics_command`), the files they
share in :mod:`.result_files`, the options' checks in :mod:`.options` and what they print in
:mod:`.output`.
"""

from __future__ import annotations

from .check_command import CHECK_PAIRS, check_cmd
from .design_command import CURVATURE_FILE, DESIGN_FORMATS, SOLVER_NAMES, design
from .forward_commands import march, march_memory, targets
from .group import app
from .make_command import make_cmd
from .mechanics_command import mechanics_cmd
from .options import (ACUTE, FRAMES, MAX_FRAMES, MAX_NAME, MAX_PATH, MAX_WORKERS, OMEGA,
                      OUT_ROOM, PANELS, PERTURB, SEED, SIDE, TRUST_HELP, VIEW_FILE,
                      check_frames, check_path)
from .output import console, quantity_table, shown, user_errors, warn, wrote
from .result_commands import export, fold_cmd, render, view_cmd
from .sweep_command import sweep_cmd

__all__ = ["ACUTE", "CHECK_PAIRS", "CURVATURE_FILE", "DESIGN_FORMATS", "FRAMES", "MAX_FRAMES",
           "MAX_NAME", "MAX_PATH", "MAX_WORKERS", "OMEGA", "OUT_ROOM", "PANELS", "PERTURB", "SEED",
           "SIDE", "SOLVER_NAMES", "TRUST_HELP", "VIEW_FILE", "app", "check_cmd", "check_frames",
           "check_path", "console", "design", "export", "fold_cmd", "make_cmd", "march",
           "march_memory", "mechanics_cmd", "quantity_table", "render", "shown", "sweep_cmd",
           "targets", "user_errors", "view_cmd", "warn", "wrote"]
