"""The commands that need no design: ``march`` (march and fold a perturbed Miura-ori) and
``targets`` (the built-in surfaces)."""

from __future__ import annotations

from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from .. import memory
from ..files import Key, check_out_dir, check_value, replace_folder, write_json
from ..model.boundary import LAYOUTS, miura_boundary, perturb_angles
from ..model.pattern import motion_omegas
from .options import ACUTE, MAX_FRAMES, OMEGA, PANELS, PERTURB, SEED, SIDE, check_frames, check_path
from .output import quantity_table, user_errors


def targets() -> None:
    """List the built-in target surfaces with their parameters and default domains.

    Use one in a design file as [target] name = "<surface>" plus any parameters and
    domain = [[u0, u1], [v0, v1]].
    """
    from ..targets import surfaces

    table = Table(title="built-in target surfaces", show_lines=True)
    table.add_column("name", style="bold", no_wrap=True)
    table.add_column("parameters (defaults)")
    table.add_column("default domain")
    table.add_column("description")
    with user_errors():
        for name in surfaces.names():
            text = surfaces.describe(name)
            doc = text.removeprefix(f"{name}: ").split(" Parameters:")[0]
            surf = surfaces.get(name)
            params = ", ".join(f"{k} = {v:g}" for k, v in surf.params.items()) or "-"
            domain = ", ".join(f"[{a:.4g}, {b:.4g}]" for a, b in surf.domain)
            table.add_row(name, params, domain, doc)
    Console().print(table)


def march_memory(rows: int, cols: int, frames: int) -> float:
    """Bytes ``rffqm march`` needs for rows x cols panels and ``frames`` states
    (:func:`rffqm_nlp.memory.march_estimate`)."""
    return memory.march_estimate(rows, cols, frames)


def march(
    out: Path = typer.Option(Path("runs/march"), help="Output folder."),
    rows: int = typer.Option(10, help="Panel rows N, 1 to 100000."),
    cols: int = typer.Option(10, help="Panel columns M, 1 to 100000."),
    alpha0: float = typer.Option(1.2, help="Acute Miura angle (rad), in (0, pi/2)."),
    a: float = typer.Option(1.0, help="Miura side a (straight creases), 1e-6 to 1e6."),
    b: float = typer.Option(1.0, help="Miura side b (zig-zag creases), 1e-6 to 1e6."),
    layout: str = typer.Option("zigzag_j", help=f"Miura layout: {', '.join(LAYOUTS)}."),
    perturb: float = typer.Option(0.0, help="Perturb boundary angles by U(+-perturb), "
                                  "0 to pi/2 (rad)."),
    seed: int = typer.Option(0, help="Seed of the perturbation, 0 to 2^63 - 1."),
    lp: bool = typer.Option(False, help="Side lengths from the paper's LP (eq:linearP)."),
    omega: float = typer.Option(2.0, help="Fold parameter in [-pi, pi]."),
    frames: int = typer.Option(0, help="Also write K states from flat to omega, 0 (none) "
                               f"to {MAX_FRAMES}."),
    force: bool = typer.Option(False, "--force", help="Replace a non-empty output folder "
                               "(the whole folder)."),
) -> None:
    """March a (perturbed) Miura crease pattern and fold it; write the pattern and vertices."""
    from ..model import marching
    from ..model.lengths import length_spread, side_length_lp

    with user_errors():
        check_path(out, "--out", output=True)
        rows, cols = check_value(rows, PANELS, "--rows"), check_value(cols, PANELS, "--cols")
        alpha0 = check_value(alpha0, ACUTE, "--alpha0")
        a, b = check_value(a, SIDE, "--a"), check_value(b, SIDE, "--b")
        layout = check_value(layout, Key("choice", choices=tuple(LAYOUTS)), "--layout")
        perturb = check_value(perturb, PERTURB, "--perturb")
        seed = check_value(seed, SEED, "--seed")
        omega = check_value(omega, OMEGA, "--omega")
        frames = check_frames(frames, 0)
        check_out_dir(out, force)
        memory.refuse_beyond(march_memory(rows, cols, frames),
                             f"rffqm march on {rows} x {cols} panels"
                             + (f" with {frames} frames" if frames else ""),
                             "choose fewer panels" + (" or frames" if frames else ""))
        bd = miura_boundary(rows, cols, a=a, b=b, alpha0=alpha0, layout=layout)
        if perturb > 0:
            bd = perturb_angles(bd, perturb, seed)
        if lp:
            bd = side_length_lp(bd)
        pat = marching.march(bd)
        Y = marching.fold(pat, omega)
        with replace_folder(out) as tmp:
            write_json(tmp / "boundary.json", bd)
            write_json(tmp / "pattern.json", pat)
            write_json(tmp / "folded.json", {"omega": omega, "Y": Y})
            if frames:
                om = motion_omegas(omega, frames)
                write_json(tmp / "frames.json", {"omega": om, "Y": marching.fold(pat, om)})
    spread = length_spread(pat.lh, pat.lv)
    Console().print(quantity_table(f"{rows} x {cols} panels, omega = {omega:g}", [
        ("smallest side / mean", f"{spread['min_over_mean']:.4g}"),
        ("largest side / smallest", f"{spread['max_over_min']:.4g}"),
        ("smallest sector angle (rad)", f"{pat.panel_angles.min():.4g}"),
        ("output", str(out))]))
