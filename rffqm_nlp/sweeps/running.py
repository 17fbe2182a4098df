"""Running a study (:func:`run`): every design one task, on a Dask cluster (local, or an
existing scheduler) or serially in this process, streamed into the output folder with a
progress display; finished designs are skipped on a re-run."""

from __future__ import annotations

import importlib.util
import logging
import os
import shutil
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..errors import InputError, RffqmError, one_line
from .outcomes import DESIGNS_DIR, completed_row, save_outcome
from .results_table import table, write_table
from .study import Design, Study
from .task import solve_design

if TYPE_CHECKING:
    import pandas as pd
    from distributed import Client
    from rich.console import Console


#: Environment of local worker processes: one thread each for every numerical library.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
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

    Designs already complete in ``out`` are skipped; see :mod:`rffqm_nlp.sweeps` for the
    files. ``progress shows a rich progress bar (and the Dask dashboard address when the
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


def _require_extra(serial: bool) -> None:
    """Raise with the install command when the ``sweep`` extra's packages are missing."""
    needed = ("pandas", "pyarrow") + (() if serial else ("distributed",))
    missing = [name for name in needed if importlib.util.find_spec(name) is None]
    if missing:
        raise RffqmError(f"sweeps need {', '.join(missing)}: pip install 'rffqm_nlp[sweep]'")
