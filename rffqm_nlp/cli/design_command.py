"""``rffqm design``: solve the inverse problem of a target with live progress, print the
fit and write every output file into a folder replaced whole."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Optional

import typer
from rich.console import Console
from rich.table import Table

from ..files import check_out_dir, check_value, replace_folder
from ..io.export import EXPORTERS
from . import output
from .options import FRAMES, TRUST_HELP, VIEW_FILE, check_path, parse_panels
from .output import quantity_table, user_errors, warn
from .result_files import export_options, render_files

if TYPE_CHECKING:
    from ..design import DesignProblem, SolveOptions
    from ..design.results import DesignResult


CURVATURE_FILE = "curvature.png"
#: Formats of :data:`rffqm_nlp.io.export.EXPORTERS` that ``design`` writes.
DESIGN_FORMATS = ("fold", "svg", "pdf", "dxf", "obj", "glb")


def design(
    target: Path = typer.Argument(..., help="Design file (TOML) with [target], [design] "
                                  "and [solve] tables, e.g. targets/sphere_cap.toml; or a "
                                  "mesh or point cloud file (OBJ, STL, PLY, OFF, GLB, XYZ: "
                                  "any format trimesh reads) designed with the default "
                                  "options.",
                                  show_default=False),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder (must be new or empty "
                             "unless --force, which replaces it whole).", show_default=False),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No live progress display."),
    force: bool = typer.Option(False, "--force", help="Replace a non-empty output folder "
                               "(the whole folder: files not written by this run are "
                               "removed)."),
    max_iter: Optional[int] = typer.Option(None, "--max-iter", help="Iteration limit, a "
                                           "whole number from 1 to 2^31 - 1 (overrides "
                                           "the file's max_iter)."),
    panels: Optional[str] = typer.Option(None, "--panels", metavar="2N 2M",
                                         help="Pattern size, two even numbers >= 4: "
                                         "'--panels 20 20' or '--panels 20,20' (overrides "
                                         "the file's panels; 20 20 for a mesh file)."),
    trust: bool = typer.Option(False, "--trust", help=TRUST_HELP),
) -> None:
    """Design a crease pattern that folds into the target surface of TARGET.

    TARGET is a design file, or a mesh or point cloud (one patch of disk topology,
    rq.surfaces.Mesh, docs/meshes.md) designed with the default design and solve options.

    Solves the inverse problem with the file's [solve] options (Levenberg-Marquardt on the
    marching manifold by default, or IPOPT; live progress: iteration, objective, constraint
    violation, elapsed time), prints the fit, and writes into OUT: result.json (the saved
    result), pattern.fold (24 states from flat to the designed omega), crease.svg/.pdf/.dxf,
    folded.obj/.glb, view.html (the interactive view, as ``rffqm view``), render.png (the
    target mesh coloured by its distance to the design) and folding.gif (when off-screen
    rendering works), convergence.png and curvature.png (the Gaussian and mean curvature
    of the folded coarse lattice and of the target). Meshes, FOLD frames and pictures are
    in the pattern's frame (x_a^11 = 0); result.json and view.html hold the folded state
    aligned onto the target.
    """
    from ..show import pictures as viz
    from ..design import SOLVE_KEYS, check_memory, load_design

    with user_errors():
        check_path(target, "TARGET")
        check_path(out, "--out", output=True)
        if max_iter is not None:
            max_iter = check_value(max_iter, SOLVE_KEYS["max_iter"], "--max-iter")
        size = None if panels is None else parse_panels(panels)
        problem, options = load_design(target, trust=trust)
        if size is not None:
            problem = dataclasses.replace(problem, panels=size)
        if max_iter is not None:
            options = dataclasses.replace(options, max_iter=max_iter)
        check_memory(problem, options)     # sizes this machine cannot hold: before any work
        check_out_dir(out, force)          # before the solve: never waste a long solve
        viz.start_rendering_probe()        # beside the solve, for render.png and folding.gif
        result = _solve(problem, options, quiet)
        with replace_folder(out) as tmp:
            _write_design(tmp, result, problem)
    console = Console()
    console.print(_summary(result, out))
    for note in result.notes:
        console.print(output.shown(note))


#: progress label of each SolveOptions.solver
SOLVER_NAMES = {"ipopt": "IPOPT", "levenberg-marquardt": "Levenberg-Marquardt"}


def _solve(problem: "DesignProblem", options: "SolveOptions", quiet: bool) -> "DesignResult":
    """Solve, with a live progress display unless ``quiet`` (on a terminal; elsewhere, as
    in a log file, a plain line every few seconds)."""
    if quiet:
        return problem.solve(options)
    if not output.console.is_terminal:
        return _solve_logged(problem, options)
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    columns = (SpinnerColumn(), TextColumn("[bold]{task.description}"),
               TextColumn("iteration {task.fields[iter]:>5} / " + str(options.max_iter)),
               TextColumn("objective {task.fields[objective]:>10}"),
               TextColumn("violation {task.fields[inf_pr]:>9}"), TimeElapsedColumn())
    N, M = problem.panels
    with Progress(*columns, console=output.console, transient=True) as progress:
        task = progress.add_task(f"building the {N} x {M} NLP", iter="-", objective="-",
                                 inf_pr="-")

        def update(entry: dict) -> None:
            progress.update(task, description=SOLVER_NAMES[options.solver], iter=entry["iter"],
                            objective=f"{entry['objective']:.4e}",
                            inf_pr=f"{entry['inf_pr']:.2e}")

        return problem.solve(options, callback=update)


def _solve_logged(problem: "DesignProblem", options: "SolveOptions",
                  every: float = 10.0) -> "DesignResult":
    """Solve, printing one progress line at most every ``every`` seconds."""
    last = [-every]

    def update(entry: dict) -> None:
        if entry["elapsed"] - last[0] >= every:
            last[0] = entry["elapsed"]
            output.console.print(f"{SOLVER_NAMES[options.solver]} iteration {entry['iter']}: "
                                 f"objective {entry['objective']:.4e}, violation "
                                 f"{entry['inf_pr']:.2e}, {entry['elapsed']:.0f} s",
                                 highlight=False)

    return problem.solve(options, callback=update)


def _write_design(folder: Path, result: "DesignResult", problem: "DesignProblem") -> None:
    """Every output file of ``design`` into ``folder``."""
    from ..show import view
    from ..show import pictures as viz

    pat, omega = result.pattern, result.omega
    result.save(folder)
    options = export_options(result)
    for fmt in DESIGN_FORMATS:
        EXPORTERS[fmt].write(folder / EXPORTERS[fmt].filename, pat, omega, **options)
    frames = min(FRAMES, view.max_frames(pat.N, pat.M))
    if frames >= 2:
        if frames < FRAMES:
            warn(f"view.html has {frames + 1} slider states instead of {FRAMES + 1}: a page "
                 f"holds at most {view.MAX_POINTS} vertex positions")
        view.write_html(result, folder / VIEW_FILE, frames=frames, target=problem.target)
    else:
        warn(f"view.html skipped: {pat.N} x {pat.M} panels are more than a page holds "
             f"({view.MAX_POINTS} vertex positions in 3 states)")
    viz.plot_convergence(result.stats.history, folder / "convergence.png")
    if result.curvature is not None:
        viz.plot_curvature(result.curvature, folder / CURVATURE_FILE)
    ok, reason = viz.rendering_available()
    if ok:
        render_files(folder, result, omega, FRAMES, target=problem.target)
    else:
        warn(f"render.png and folding.gif skipped: {reason}")


def _summary(result: "DesignResult", out: Path) -> Table:
    fit, stats = result.fit, result.stats
    return quantity_table(f"design: {result.pattern.N} x {result.pattern.M} panels", [
        ("fit RMS to the target lattice (/ diameter)", f"{fit.rms:.3e}"),
        ("fit RMS to the target surface (/ diameter)", f"{fit.rms_surface:.3e}"),
        ("Hausdorff distance (/ diameter)", f"{fit.hausdorff:.3e}"),
        ("all vertices: RMS, max to the surface (/ diameter)",
         f"{fit.rms_surface_vertices:.3e}, {fit.hausdorff_vertices:.3e}"),
        ("coverage (lattice area / target area)", f"{fit.coverage:.4g}"),
        ("best plane RMS, for comparison (/ diameter)", f"{fit.plane_rms:.3e}"),
        *([("curvature error: RMS, max per cell (/ max |K|)",
            f"{fit.curvature_rms:.3e}, {fit.curvature_max:.3e}")]
          if fit.curvature_rms is not None else []),
        ("smallest side / mean side", f"{fit.min_side_over_mean:.4g}"),
        ("smallest sector angle (rad)", f"{fit.min_sector_angle:.4g}"),
        ("collision-free from flat to omega", _collision_text(fit)),
        ("designed omega (rad)", f"{result.omega:.6g}"),
        *[(f"state {k + 1}: omega (rad), RMS to lattice, to surface (/ diameter)",
           f"{state.omega:.6g}, {state.fit.rms:.3e}, {state.fit.rms_surface:.3e}"
           + ("" if state.fit.collision_free else "; not collision-free"))
          for k, state in enumerate(result.states) if result.other_states],
        ("iterations", str(stats.iterations)),
        ("time (s)", f"{stats.build_time + stats.solve_time:.1f} "
                     f"(build {stats.build_time:.1f})"),
        ("status", stats.status),
        ("output", str(out))])


def _collision_text(fit) -> str:
    """"yes", "no: first contact at omega w" or "no: panels overlap when flat" (a Fit's
    collision check), "not checked" for a result saved before the check."""
    if fit.collision_free is None:
        return "not checked"
    if fit.collision_free:
        return "yes"
    if fit.first_contact_omega is None:
        return "no: panels overlap when flat (rffqm check)"
    return f"no: first contact at omega {fit.first_contact_omega:.4g} (rffqm check)"
