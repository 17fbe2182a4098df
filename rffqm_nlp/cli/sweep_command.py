"""``rffqm sweep``: a study of many designs (:mod:`rffqm_nlp.sweeps`), and its summary."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from .. import memory
from ..files import Key, check_out_dir, check_value
from . import output
from .options import MAX_WORKERS, TRUST_HELP, check_path
from .output import quantity_table, user_errors


def sweep_cmd(
    study: Path = typer.Argument(..., help="Study file (TOML): a base design and the "
                                 "parameters to sweep, e.g. targets/sweep_example.toml.",
                                 show_default=False),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder; an existing one is "
                             "resumed (finished designs are skipped).", show_default=False),
    scheduler: str = typer.Option("local", "--scheduler", help="'local' (a Dask cluster on "
                                  "this machine), 'none' (serially in this process) or the "
                                  "address of a running Dask scheduler (tcp://host:8786)."),
    workers: int = typer.Option(2, "--workers", help="Worker processes of the local "
                                f"cluster (one thread each), 1 to {MAX_WORKERS}."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
    trust: bool = typer.Option(False, "--trust", help=TRUST_HELP),
) -> None:
    """Run a design study: every design of STUDY as one Dask task.

    Writes into OUT: results.parquet and results.csv (one row per design: id, name, the
    swept parameters, status, reason, fit, iterations, times, worker; rewritten as each
    design finishes) and designs/ID/ (row.json, and result.json when solved, which
    fold/export/render accept). Infeasible or failed designs are rows with their status and
    reason; the command still succeeds. Re-running into OUT skips finished designs and
    recomputes broken or missing ones.
    """
    from ..sweeps import Study, run

    with user_errors():
        check_path(study, "STUDY")
        check_path(out, "--out", output=True)
        workers = check_value(workers, Key("whole", low=1, high=MAX_WORKERS), "--workers")
        if scheduler == "local":
            memory.refuse_beyond(memory.BASE * (workers + 1), f"a local cluster of {workers} "
                                 "workers", "choose fewer --workers")
        loaded = Study.load(study, trust=trust)
        check_out_dir(out, force=True)
        frame = run(loaded, out, scheduler=scheduler, workers=workers, progress=not quiet,
                    console=output.console)
    Console().print(_sweep_summary(frame, out))


def _sweep_summary(frame, out: Path) -> Table:
    """Designs per status, the best fit and the output files of a finished sweep."""
    rows = [(f"designs {status}", str(n))
            for status, n in frame["status"].value_counts().sort_index().items()]
    solved = frame[frame["status"] == "solved"]
    if len(solved):
        best = solved.loc[solved["rms"].idxmin()]
        rows.append(("best fit RMS (/ diameter)", f"{best['rms']:.3e}: {best['name']} "
                     f"(designs/{best['id']})"))
    rows.append(("table", f"{out / 'results.parquet'}, {out / 'results.csv'}"))
    return quantity_table(f"sweep: {len(frame)} designs", rows)
