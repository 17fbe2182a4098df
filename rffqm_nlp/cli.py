"""The ``rffqm`` command: thin wrappers that parse, call the library and write files."""

from __future__ import annotations

import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from .boundary import LAYOUTS, miura_boundary, perturb_angles
from .errors import RffqmError

app = typer.Typer(add_completion=False, no_args_is_help=True,
                  help="Forward and inverse design of rigidly and flat-foldable origami.")
console = Console(stderr=True)


@app.callback()
def _root() -> None:
    """rffqm: forward and inverse design of rigidly and flat-foldable origami."""


@contextmanager
def user_errors() -> Iterator[None]:
    """Turn the package's named errors into a one-line reason and exit status 2."""
    try:
        yield
    except (RffqmError, OSError) as exc:
        console.print(f"[bold red]error:[/] {exc}", highlight=False, soft_wrap=True)
        raise typer.Exit(2) from None


def prepare_out(out: Path, force: bool) -> None:
    """Create the output folder; refuse a non-empty one without ``force``."""
    if out.exists() and any(out.iterdir()) and not force:
        raise FileExistsError(f"{out} exists and is not empty; pass --force to overwrite")
    out.mkdir(parents=True, exist_ok=True)


def write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to a temporary file beside ``path``, then rename it into place."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@app.command()
def march(
    out: Path = typer.Option(Path("runs/march"), help="Output folder."),
    rows: int = typer.Option(10, min=1, help="Panel rows N."),
    cols: int = typer.Option(10, min=1, help="Panel columns M."),
    alpha0: float = typer.Option(1.2, help="Acute Miura angle (rad)."),
    a: float = typer.Option(1.0, help="Miura side a (straight creases)."),
    b: float = typer.Option(1.0, help="Miura side b (zig-zag creases)."),
    layout: str = typer.Option("zigzag_j", help=f"Miura layout: {', '.join(LAYOUTS)}."),
    perturb: float = typer.Option(0.0, min=0.0, help="Perturb boundary angles by U(+-perturb)."),
    seed: int = typer.Option(0, help="Seed of the perturbation."),
    lp: bool = typer.Option(False, help="Side lengths from the paper's LP (eq:linearP)."),
    omega: float = typer.Option(2.0, help="Fold parameter in [-pi, pi]."),
    frames: int = typer.Option(0, min=0, help="Also write K states from flat to omega."),
    force: bool = typer.Option(False, help="Overwrite a non-empty output folder."),
) -> None:
    """March a (perturbed) Miura crease pattern and fold it; write the pattern and vertices."""
    from . import marching
    from .lengths import length_spread, side_length_lp

    with user_errors():
        bd = miura_boundary(rows, cols, a=a, b=b, alpha0=alpha0, layout=layout)
        if perturb > 0:
            bd = perturb_angles(bd, perturb, seed)
        if lp:
            bd = side_length_lp(bd)
        pat = marching.march(bd)
        Y = marching.fold(pat, omega)
        prepare_out(out, force)
        write_atomic(out / "boundary.json", json.dumps(bd.to_dict()).encode())
        write_atomic(out / "pattern.json", json.dumps(pat.to_dict()).encode())
        write_atomic(out / "folded.json", json.dumps({"omega": omega, "Y": Y.tolist()}).encode())
        if frames:
            om = np.linspace(0.0, omega, frames)
            states = marching.fold(pat, om)
            write_atomic(out / "frames.json",
                         json.dumps({"omega": om.tolist(), "Y": states.tolist()}).encode())
    spread = length_spread(pat.lh, pat.lv)
    table = Table(title=f"{rows} x {cols} panels, omega = {omega:g}")
    table.add_column("quantity")
    table.add_column("value", justify="right")
    table.add_row("smallest side / mean", f"{spread['min_over_mean']:.4g}")
    table.add_row("largest side / smallest", f"{spread['max_over_min']:.4g}")
    table.add_row("smallest sector angle (rad)", f"{pat.panel_angles.min():.4g}")
    table.add_row("output", str(out))
    Console().print(table)
