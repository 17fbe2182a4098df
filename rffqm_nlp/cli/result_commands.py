"""The commands on a saved design: ``fold`` (its folded vertices as JSON), ``export``,
``render`` (render.png and folding.gif) and ``view`` (the interactive HTML page)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Optional

import typer

from .. import memory
from ..design.results import DesignResult
from ..errors import InputError, RffqmError
from ..files import check_out_dir, check_value, jsonable, replace_folder, write_json
from ..io.export import EXPORTERS
from ..model.pattern import motion_omegas
from .options import FRAMES, MAX_FRAMES, OMEGA, VIEW_FILE, check_frames, check_path
from .output import user_errors, wrote
from .result_files import export_options, render_files, result_folder


def fold_cmd(
    result_dir: Path = typer.Argument(..., help="Folder of a saved design (result.json).",
                                      show_default=False),
    omega: Optional[float] = typer.Option(None, help="One fold parameter in [-pi, pi]."),
    frames: Optional[int] = typer.Option(None, help="K states from flat to the designed "
                                         f"omega, 1 to {MAX_FRAMES}."),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="JSON file to write "
                                       "(default: print to stdout)."),
    aligned: bool = typer.Option(False, "--aligned", help="Move the states rigidly onto the "
                                 "target (the frame of result.folded) instead of the pattern "
                                 "frame."),
) -> None:
    """Folded vertices of a saved design at one omega (--omega) or K omegas (--frames).

    Writes JSON {"omega": w or [w...], "frame": "pattern" or "target", "Y": ...} with Y of
    shape (2N+1, 2M+1, 3), or (K, 2N+1, 2M+1, 3) for --frames.
    """
    from ..model import marching

    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(out, "--out", output=True)
        if (omega is None) == (frames is None):
            raise InputError("give exactly one of --omega W or --frames K")
        if frames is not None:
            frames = check_frames(frames, 1)
        else:
            omega = check_value(omega, OMEGA, "--omega")
        result = DesignResult.load(result_dir)
        pat = result.pattern
        memory.refuse_beyond(memory.states_estimate(pat.N, pat.M, frames or 1),
                             f"rffqm fold of {pat.N} x {pat.M} panels"
                             + (f" in {frames} states" if frames else ""),
                             "choose fewer --frames" if frames else "choose a smaller design")
        om = motion_omegas(result.omega, frames) if frames is not None else omega
        Y = marching.fold(result.pattern, om)
        if aligned:
            Y = Y @ result.rotation.T + result.translation
        data = {"omega": om, "frame": "target" if aligned else "pattern",
                "designed_omega": result.omega, "Y": Y}
        if out is None:
            typer.echo(json.dumps(jsonable(data), allow_nan=False))
        else:
            write_json(out, data)
            wrote(out)


def export(
    result_dir: Path = typer.Argument(..., help="Folder of a saved design (result.json).",
                                      show_default=False),
    format: str = typer.Option(..., "--format", "-f", help="One of "
                               f"{', '.join(EXPORTERS)}.", show_default=False),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="File to write (default: "
                                       "RESULT_DIR/pattern.fold, crease.<fmt> or "
                                       "folded.<fmt>)."),
    omega: Optional[float] = typer.Option(None, help="Fold parameter (default: the designed "
                                          "omega)."),
) -> None:
    """Export a saved design: FOLD, a crease pattern (SVG, DXF, PDF) or a mesh (OBJ, PLY, GLB).

    Crease assignments and meshes are those at omega; the FOLD file holds 24 states from
    flat to omega.
    """
    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(out, "--out", output=True)
        fmt = format.lower().lstrip(".")
        if fmt not in EXPORTERS:
            raise InputError(f"unknown format {format!r}; choose one of "
                             f"{', '.join(EXPORTERS)}")
        exporter = EXPORTERS[fmt]
        om = None if omega is None else check_value(omega, OMEGA, "--omega")
        result = DesignResult.load(result_dir)
        om = result.omega if om is None else om
        path = out if out is not None else result_folder(result_dir) / exporter.filename
        if path.suffix.lower() != exporter.suffix:
            raise InputError(f"--format {fmt} writes a {exporter.suffix} file, got {path}")
        exporter.write(path, result.pattern, om, **export_options(result))
    wrote(path)


def render(
    result_dir: Path = typer.Argument(..., help="Folder of a saved design (result.json).",
                                      show_default=False),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="Output folder (default: "
                                       "RESULT_DIR)."),
    frames: int = typer.Option(FRAMES, help=f"States in folding.gif, 2 to {MAX_FRAMES}."),
    trust: bool = typer.Option(False, "--trust", help="Rebuild a target that names code "
                               "(python = ...) by running that code; without it such a "
                               "target is drawn as its lattice points."),
) -> None:
    """Render a saved design: render.png (the designed state with the target) and
    folding.gif (the whole motion, from flat to folded flat).

    Into an existing folder (the result's, by default) each file is written atomically and
    nothing else changes; a new folder appears complete or not at all.
    """
    from ..show import pictures as viz

    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(out, "--out", output=True)
        frames = check_frames(frames, 2)
        result = DesignResult.load(result_dir)
        pat = result.pattern
        memory.refuse_beyond(memory.gif_estimate(pat.N, pat.M, frames, viz.GIF_SIZE),
                             f"rffqm render of {pat.N} x {pat.M} panels in {frames} states",
                             "choose fewer --frames")
        ok, reason = viz.rendering_available()
        if not ok:
            raise RffqmError(f"cannot render: {reason}")
        folder = out if out is not None else result_folder(result_dir)
        check_out_dir(folder, force=True)
        omega_end = math.copysign(math.pi, result.omega)
        if folder.is_dir():
            render_files(folder, result, omega_end, frames, trust=trust)
        else:
            with replace_folder(folder) as tmp:
                render_files(tmp, result, omega_end, frames, trust=trust)
    wrote(folder / "render.png", folder / "folding.gif")


def view_cmd(
    result_dir: Path = typer.Argument(..., help="Folder of a saved design (result.json).",
                                      show_default=False),
    out: Optional[Path] = typer.Option(None, "--out", "-o", help="HTML file to write "
                                       "(default: RESULT_DIR/view.html)."),
    frames: int = typer.Option(FRAMES, help="Slider states from flat to folded flat (the "
                               f"designed state is added), 2 to {MAX_FRAMES}; states times "
                               "pattern vertices at most rffqm_nlp.show.view.MAX_POINTS (2.5 "
                               "million)."),
) -> None:
    """Write the interactive view of a saved design: one self-contained HTML page (plotly,
    works offline) with the folded pattern coloured by its distance to the target, its
    mountain and valley creases, a button for the target surface and a slider through the
    folding motion from flat to folded flat, the designed state marked.

    The colours of vertices farther from the target than the designed state's farthest
    (the top of the colour scale) come from a bounded search, an upper bound of their
    distance (rffqm_nlp.show.view).
    """
    from ..show import view

    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(out, "--out", output=True)
        frames = check_frames(frames, 2)
        result = DesignResult.load(result_dir)
        view.check_size(result.pattern.N, result.pattern.M, frames)
        path = out if out is not None else result_folder(result_dir) / VIEW_FILE
        if path.suffix.lower() not in (".html", ".htm"):
            raise InputError(f"--out must name an .html file, got {path}")
        if not path.parent.is_dir():
            raise InputError(f"--out: no folder {path.parent} to write {path.name} into")
        view.write_html(result, path, frames=frames)
    wrote(path)
