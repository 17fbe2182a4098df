"""``rffqm make``: the files that make a saved design, at a physical size, into a folder
replaced whole (docs/make.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from rich.console import Console

from ..design.results import DesignResult
from ..files import check_out_dir, replace_folder
from .options import FRAMES, VIEW_FILE, check_path
from .output import quantity_table, user_errors, warn

_LENGTH = "a length in mm: 300, 300mm, 30cm or 12in"


def make_cmd(
    result_dir: Path = typer.Argument(..., help="Folder of a saved design (result.json).",
                                      show_default=False),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder (must be new or empty "
                             "unless --force, which replaces it whole).", show_default=False),
    width: Optional[str] = typer.Option(None, "--width", help="The flat pattern's extent "
                                        f"along x, {_LENGTH} (default 300mm)."),
    height: Optional[str] = typer.Option(None, "--height", help="Its extent along y instead, "
                                         f"{_LENGTH}."),
    scale: Optional[float] = typer.Option(None, "--scale", help="Millimetres per pattern "
                                          "unit instead of a width or height."),
    thickness: Optional[str] = typer.Option(None, "--thickness", help="The sheet's or "
                                            f"panels' thickness, {_LENGTH} (default 0.5mm)."),
    process: Optional[str] = typer.Option(None, "--process", help="laser, cutter or print: "
                                          "fills in the parameters not given (default "
                                          "laser)."),
    kerf: Optional[str] = typer.Option(None, "--kerf", help="The cut's width; the outline "
                                       f"is offset out by half of it ({_LENGTH})."),
    dash: Optional[str] = typer.Option(None, "--dash", help="Length of a crease's cuts."),
    gap: Optional[str] = typer.Option(None, "--gap", help="Uncut length between them."),
    corner_relief: Optional[str] = typer.Option(None, "--corner-relief", help="Uncut "
                                                "length at both ends of every crease."),
    hinge_gap: Optional[str] = typer.Option(None, "--hinge-gap", help="Gap between "
                                            "neighbouring thick panels at their hinge."),
    side: Optional[str] = typer.Option(None, "--side", help="The panels' material: auto, "
                                       "back or front of the zero-thickness surface."),
    paper: Optional[str] = typer.Option(None, "--paper", help="a4 or letter: the pages of "
                                        "assembly.pdf."),
    ties: Optional[int] = typer.Option(None, "--ties", help="Lock ties to recommend, 1 to "
                                       "20 (default 3)."),
    config: Optional[Path] = typer.Option(None, "--config", help="A TOML file with a [make] "
                                          "table of these options (the options given here "
                                          "win)."),
    force: bool = typer.Option(False, "--force", help="Replace a non-empty output folder "
                               "(the whole folder)."),
) -> None:
    """Make a saved design: cut files in millimetres, thick panels that fold, a lock.

    Writes into OUT: cut.svg, cut.dxf, cut.pdf (layers CUT, MOUNTAIN, VALLEY at true
    scale, perforated creases), cut_back.svg and cut_back.dxf (the sheet turned over),
    fold_angles.csv, assembly.pdf, panels.stl, panels_flat.stl and panels.glb (tapered
    thick panels), lock.csv, stops.csv and lock.stl (the lock), make.json (the options and
    the checks) and view.html (the view with the lock's ties).
    """
    from ..make import make
    from ..show import view

    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(out, "--out", output=True)
        check_path(config, "--config")
        result = DesignResult.load(result_dir)
        made = make(result, config=config, width=width, height=height, scale=scale,
                    thickness=thickness, process=process, kerf=kerf, dash=dash, gap=gap,
                    corner_relief=corner_relief, hinge_gap=hinge_gap, side=side,
                    paper=paper, ties=ties)
        check_out_dir(out, force)
        pat = result.pattern
        frames = min(FRAMES, view.max_frames(pat.N, pat.M))
        with replace_folder(out) as tmp:
            made.write_into(tmp)
            if frames >= 2:
                view.write_html(result, tmp / VIEW_FILE, frames=frames, ties=made.ties)
    if not made.thick.free:
        warn(f"the {made.options.thickness:g} mm panels collide at omega "
             f"{made.thick.first_omega:.4g} before the designed state (make.json: "
             "thick_check); choose a thinner sheet")
    Console().print(_summary(made, out))


def _summary(made, out: Path):
    ratios = made.solids.volume_ratios
    W, H = made.sheet.size
    rows = [("sheet (mm)", f"{W:.2f} x {H:.2f}"),
            ("mm per pattern unit", f"{made.scale:.6g}"),
            ("creases", str(len(made.sheet.kinds))),
            ("thickness (mm), side", f"{made.options.thickness:g}, "
                                     f"{'back' if made.solids.side < 0 else 'front'}"),
            ("panel volume / (area x thickness): min, mean",
             f"{ratios.min():.3f}, {ratios.mean():.3f}"),
            ("thick panels free from flat to the design", "yes" if made.thick.free else "no")]
    rows += [(f"tie ({t.i1}, {t.j1})-({t.i2}, {t.j2})",
              f"{t.length:.2f} mm, {t.dlength_domega:+.1f} mm/rad") for t in made.ties]
    return quantity_table(f"make: {out}", rows + [("output", str(out))])
