"""The ``rffqm`` command: thin wrappers that parse, call the library and write files.

Commands: ``design`` (inverse design of a TOML target, with live solver progress), ``sweep``
(a study of many designs, one Dask task each, on a local cluster, an existing scheduler or
serially; resumable; see :mod:`rffqm_nlp.sweeps`), ``fold``, ``export``, ``render`` and
``view`` (of a saved design result), ``check`` (self-contact of a saved design or a FOLD
file, exit 1 when not free), ``targets`` (the built-in surfaces) and ``march`` (forward
marching of a perturbed Miura-ori).

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
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import sys
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Iterator, Optional

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from typer.core import TyperCommand, TyperGroup

from . import memory
from .model.boundary import LAYOUTS, miura_boundary, perturb_angles
from .errors import InputError, RffqmError, one_line, safe_text
from .io.export import EXPORTERS
from .files import Key, check_out_dir, check_value, jsonable, replace_folder, write_json
from .model.pattern import motion_omegas
from .design.results import DesignResult

if TYPE_CHECKING:
    from .design.problem import DesignProblem, SolveOptions


class _OneLineErrors(TyperGroup):
    """The command group: typer's own usage errors (an option not of its type, an unknown
    option or command, a missing argument) in one line too, "error: <typer's message>
    (<command> --help)", with typer's exit status 2."""

    def main(self, *args, standalone_mode: bool = True, **kwargs):
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":    # `rffqm` alone: the help
                exc.show()
            else:
                ctx = getattr(exc, "ctx", None)
                where = f" ({ctx.command_path} --help)" if ctx is not None else ""
                console.print(f"[bold red]error:[/] {shown(exc.format_message() + where)}",
                              highlight=False, soft_wrap=True)
            sys.exit(getattr(exc, "exit_code", 2))
        except typer.Abort:
            console.print("[bold red]aborted[/]", highlight=False)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(cls=_OneLineErrors, add_completion=False, no_args_is_help=True,
                  rich_markup_mode="markdown",
                  help="Forward and inverse design of rigidly and flat-foldable origami.")
console = Console(stderr=True)

#: Folding states stored in pattern.fold and drawn in folding.gif by ``design``.
FRAMES = 24
#: The interactive view (rffqm_nlp.show.view) and the curvature maps that ``design`` writes.
VIEW_FILE = "view.html"
CURVATURE_FILE = "curvature.png"
#: Help of the --trust option of the commands that read a target file.
TRUST_HELP = ("Let the file run the code its target names (python = \"file.py:function\" or "
              "\"package.module:function\"), name files and libraries for IPOPT "
              "(output_file, hsllib, ...) and name files outside its folder; only for files "
              "you trust (docs/files_from_others.md).")
#: Formats of :data:`rffqm_nlp.io.export.EXPORTERS` that ``design`` writes.
DESIGN_FORMATS = ("fold", "svg", "pdf", "dxf", "obj", "glb")
#: Most states of any --frames (fold, render, view, march).
MAX_FRAMES = 1000
#: Most worker processes of ``sweep --scheduler local``.
MAX_WORKERS = 256
#: Longest path an argument or option takes, and longest name in it, in bytes (Linux's
#: PATH_MAX and NAME_MAX); an output's own name leaves :data:`OUT_ROOM` more for the
#: temporary names written next to it (".<name>.staging-<pid>-<token>").
MAX_PATH, MAX_NAME, OUT_ROOM = 4096, 255, 40
#: The numeric options' ranges (their help says them): the fold parameter, march's seed,
#: perturbation (radians), Miura sides and acute angle, and panels a side.
OMEGA = Key("number", low=-math.pi, high=math.pi, hint="(radians: [-pi, pi])")
SEED = Key("whole", low=0, high=2**63 - 1)
PERTURB = Key("number", low=0.0, high=math.pi / 2, hint="(radians)")
SIDE = Key("number", low=1e-6, high=1e6, hint="(a length)")
ACUTE = Key("number", low=0.0, high=math.pi / 2, low_open=True, high_open=True,
            hint="(radians)")
PANELS = Key("whole", low=1, high=100_000)


def _version(value: bool) -> None:
    if value:
        from ._version import __version__

        typer.echo(f"rffqm-nlp {__version__}")
        raise typer.Exit()


@app.callback()
def _root(version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                       help="Print the version and exit.")) -> None:
    """rffqm: forward and inverse design of rigidly and flat-foldable origami."""


# --------------------------------------------------------------------------- helpers
@contextmanager
def user_errors() -> Iterator[None]:
    """Turn the package's named errors, and the errors of a path no file can have (too
    long, a NUL character, characters the file system cannot encode), into a one-line
    reason and exit status 2."""
    try:
        yield
    except (RffqmError, OSError) as exc:
        _fail(one_line(exc))
    except ValueError as exc:
        if not _path_error(exc):
            raise
        _fail(f"a path no file can have: {one_line(exc)}")
    except KeyboardInterrupt:
        console.print("[bold red]interrupted[/]", highlight=False)
        raise typer.Exit(130) from None


def _fail(reason: str) -> None:
    console.print(f"[bold red]error:[/] {shown(reason)}", highlight=False, soft_wrap=True)
    raise typer.Exit(2) from None


def _path_error(exc: ValueError) -> bool:
    """Whether ``exc`` is what the os module raises for a path with a NUL character
    ("embedded null byte") or one it cannot encode (a lone surrogate)."""
    return (isinstance(exc, UnicodeEncodeError)
            or re.search(r"null (byte|character)", str(exc)) is not None)


def shown(text: object) -> str:
    """``text`` (a message, a path, a name from a file) as the commands print it: through
    :func:`rffqm_nlp.errors.safe_text`, rich markup escaped."""
    return escape(safe_text(str(text)))


def warn(message: str) -> None:
    """A yellow one-line warning on stderr."""
    console.print(f"[yellow]warning:[/] {shown(message)}", highlight=False, soft_wrap=True)


def wrote(*paths: Path) -> None:
    """"wrote <path> and <path>" on stderr."""
    console.print("wrote " + " and ".join(shown(p) for p in paths), highlight=False,
                  soft_wrap=True)


def check_path(path: Optional[Path], name: str, output: bool = False) -> None:
    """Refuse, in one line, a path that no file can have: with a NUL character, characters
    the file system cannot encode, longer than :data:`MAX_PATH` bytes or with a name longer
    than :data:`MAX_NAME` (an ``output`` path's own name :data:`OUT_ROOM` less). Nothing
    for None."""
    if path is None:
        return
    text = os.fspath(path)
    if "\x00" in text:
        raise InputError(f"{name} {text}: a path cannot hold a NUL character")
    try:
        raw = os.fsencode(os.path.abspath(text))
    except (UnicodeError, ValueError):
        raise InputError(f"{name} {text}: characters the file system cannot encode") from None
    names = raw.split(b"/")
    longest = max(len(part) for part in names)
    last = MAX_NAME - OUT_ROOM if output else MAX_NAME
    if len(raw) > MAX_PATH or longest > MAX_NAME or len(names[-1]) > last:
        raise InputError(f"{name} {text}: too long a path ({len(raw)} bytes, a name of "
                         f"{max(longest, len(names[-1]))}); paths take at most {MAX_PATH} "
                         f"bytes, names {MAX_NAME} (an output's {MAX_NAME - OUT_ROOM})")


def check_frames(frames: int, minimum: int, name: str = "--frames") -> int:
    """A --frames option: a whole number from ``minimum`` to :data:`MAX_FRAMES`."""
    return check_value(frames, Key("whole", low=minimum, high=MAX_FRAMES), name)


def _parse_panels(text: str) -> tuple[int, int]:
    """"8,8", "8 8" or "8x8" -> (8, 8)."""
    parts = [p for p in re.split(r"[,\sx]+", text.strip()) if p]
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise InputError(f"--panels takes two even numbers 2N 2M (or 2N,2M), got {text!r}")
    return values  # type: ignore[return-value]


class _PanelsCommand(TyperCommand):
    """A command whose ``--panels`` option takes "2N 2M" (two words) as well as "2N,2M"."""

    def parse_args(self, ctx, args: list[str]) -> list[str]:
        joined: list[str] = []
        i = 0
        while i < len(args):
            if args[i] == "--":
                joined.extend(args[i:])
                break
            if (args[i] == "--panels" and i + 2 < len(args)
                    and re.fullmatch(r"\d+", args[i + 1])
                    and re.fullmatch(r"\d+", args[i + 2])):
                joined += ["--panels", f"{args[i + 1]},{args[i + 2]}"]
                i += 3
                continue
            joined.append(args[i])
            i += 1
        return super().parse_args(ctx, joined)


def _result_folder(result: Path) -> Path:
    """The folder of a result given as its folder or as its result.json."""
    return result if result.is_dir() else result.parent


def _pattern_frame(points: np.ndarray, result: "DesignResult") -> np.ndarray:
    """Target-frame points moved into the frame of :func:`marching.fold` (the inverse of
    the alignment ``y -> rotation @ y + translation`` of ``result.folded``)."""
    return (np.asarray(points, dtype=float) - result.translation) @ result.rotation


def _target_for_render(result: "DesignResult", target=None, trust: bool = False):
    """The target of :func:`rffqm_nlp.design.results.target_mesh` moved into the pattern frame, or
    the target lattice points (with a warning) when it cannot be rebuilt (the target names
    code and ``trust`` is not given)."""
    import trimesh

    from .design.results import target_mesh

    try:
        mesh = target_mesh(result, target, trust)
    except RffqmError as exc:
        warn(f"cannot rebuild the target surface ({one_line(exc)}); drawing the target "
             "lattice points instead")
        return _pattern_frame(result.target_points.reshape(-1, 3), result)
    return trimesh.Trimesh(vertices=_pattern_frame(mesh.vertices, result), faces=mesh.faces,
                           process=False)


def _export_options(result: "DesignResult") -> dict:
    """The options every exporter is offered (FOLD takes them: its folding states and the
    target and fit as metadata)."""
    return {"frames": FRAMES,
            "metadata": {"target": result.problem.get("target", {}), "fit": result.fit}}


def _render_files(folder: Path, result: "DesignResult", omega_end: float, frames: int,
                  target=None, trust: bool = False) -> None:
    from .show import pictures as viz

    viz.render_png(folder / "render.png", result.pattern, result.omega,
                   target=_target_for_render(result, target, trust),
                   contacts=_contacts(result))
    viz.folding_gif(folder / "folding.gif", result.pattern, omega_end, frames=frames)


def _contacts(result: "DesignResult"):
    """The collision report of a design whose fit says it is not collision-free (for
    render.png to mark the panels in contact), else None."""
    from .contact.collisions import collisions

    return None if result.fit.collision_free is not False else collisions(result.pattern,
                                                                          result.omega)


# --------------------------------------------------------------------------- design
@app.command(cls=_PanelsCommand)
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
    from .show import pictures as viz
    from .design.problem import SOLVE_KEYS, check_memory, load_design

    with user_errors():
        check_path(target, "TARGET")
        check_path(out, "--out", output=True)
        if max_iter is not None:
            max_iter = check_value(max_iter, SOLVE_KEYS["max_iter"], "--max-iter")
        size = None if panels is None else _parse_panels(panels)
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
    Console().print(_summary(result, out))


#: progress label of each SolveOptions.solver
SOLVER_NAMES = {"ipopt": "IPOPT", "levenberg-marquardt": "Levenberg-Marquardt"}


def _solve(problem: "DesignProblem", options: "SolveOptions", quiet: bool) -> "DesignResult":
    """Solve, with a live progress display unless ``quiet`` (on a terminal; elsewhere, as
    in a log file, a plain line every few seconds)."""
    if quiet:
        return problem.solve(options)
    if not console.is_terminal:
        return _solve_logged(problem, options)
    from rich.progress import Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    columns = (SpinnerColumn(), TextColumn("[bold]{task.description}"),
               TextColumn("iteration {task.fields[iter]:>5} / " + str(options.max_iter)),
               TextColumn("objective {task.fields[objective]:>10}"),
               TextColumn("violation {task.fields[inf_pr]:>9}"), TimeElapsedColumn())
    N, M = problem.panels
    with Progress(*columns, console=console, transient=True) as progress:
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
            console.print(f"{SOLVER_NAMES[options.solver]} iteration {entry['iter']}: objective "
                          f"{entry['objective']:.4e}, violation {entry['inf_pr']:.2e}, "
                          f"{entry['elapsed']:.0f} s", highlight=False)

    return problem.solve(options, callback=update)


def _write_design(folder: Path, result: "DesignResult", problem: "DesignProblem") -> None:
    """Every output file of ``design`` into ``folder``."""
    from .show import view
    from .show import pictures as viz

    pat, omega = result.pattern, result.omega
    result.save(folder)
    options = _export_options(result)
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
        _render_files(folder, result, omega, FRAMES, target=problem.target)
    else:
        warn(f"render.png and folding.gif skipped: {reason}")


def quantity_table(title: str, rows: list[tuple[str, str]]) -> Table:
    """A two-column rich table of named quantities."""
    table = Table(title=shown(title))
    table.add_column("quantity")
    table.add_column("value", justify="right")
    for name, value in rows:
        table.add_row(shown(name), shown(value))
    return table


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
        ("smallest side / mean side", f"{fit.min_side_over_mean:.4g}"),
        ("smallest sector angle (rad)", f"{fit.min_sector_angle:.4g}"),
        ("collision-free from flat to omega", _collision_text(fit)),
        ("designed omega (rad)", f"{result.omega:.6g}"),
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


# --------------------------------------------------------------------------- check
#: Panel pairs listed per row of the ``check`` table before "... and n more".
CHECK_PAIRS = 8


@app.command("check")
def check_cmd(
    source: Path = typer.Argument(..., help="A saved design (its folder or result.json) or "
                                  "a FOLD file written by rffqm (.fold).", show_default=False),
    clearance: float = typer.Option(0.0, "--clearance", help="Distance (a sheet thickness, "
                                    "in the pattern's length units) that panels sharing no "
                                    "vertex must keep, from 0 (they must not touch) to "
                                    "below the pattern's shortest side."),
    omega: Optional[float] = typer.Option(None, "--omega", help="Check the motion from flat "
                                          "to this fold parameter in [-pi, pi] (default: the "
                                          "design's omega)."),
) -> None:
    """Check a design for self-contact, like a linter.

    Prints the panels that overlap in the flat pattern, the first omega at which two panels
    that share no vertex touch (or come closer than --clearance) while folding from flat
    to omega, and the pairs in contact there (1-based (i, j) panels). Exit status 0 when
    the motion is free, 1 when it is not, 2 on bad input.
    """
    from .contact.collisions import collisions

    with user_errors():
        check_path(source, "SOURCE")
        om = None if omega is None else check_value(omega, OMEGA, "--omega")
        clearance = check_value(clearance, Key("number", low=0.0), "--clearance")
        pattern, designed = _design_to_check(source)
        om = designed if om is None else om
        shortest = float(min(np.min(pattern.lh), np.min(pattern.lv)))
        check_value(clearance, Key("number", low=0.0, high=shortest, high_open=True,
                                   hint="(below the pattern's shortest side)"), "--clearance")
        report = collisions(pattern, om, clearance=clearance)
    Console().print(_check_table(report, source))
    raise typer.Exit(0 if report.free else 1)


def _design_to_check(source: Path) -> tuple:
    """(pattern, omega) of a FOLD file (by its suffix .fold) or a saved design result."""
    if source.suffix.lower() == ".fold":
        from .io.foldfile import read_fold

        pattern, omega, _ = read_fold(source)
        return pattern, omega
    result = DesignResult.load(source)
    return result.pattern, result.omega


def _pairs_text(pairs: list) -> str:
    """"(1, 2)-(3, 4), ..." for at most CHECK_PAIRS pairs, "none" for none."""
    if not pairs:
        return "none"
    text = ", ".join(f"({a[0]}, {a[1]})-({b[0]}, {b[1]})" for a, b in pairs[:CHECK_PAIRS])
    return text + (f" and {len(pairs) - CHECK_PAIRS} more" if len(pairs) > CHECK_PAIRS else "")


def _check_table(report, source: Path) -> Table:
    """The ``check`` summary of a :class:`~rffqm_nlp.contact.collisions.CollisionReport`."""
    first = "none" if report.first_omega is None else f"{report.first_omega:.6g}"
    return quantity_table(f"self-contact: {source}", [
        ("motion checked", f"omega from 0 to {report.omega_max:.6g}"),
        ("clearance", f"{report.clearance:g}"),
        ("panels overlapping when flat", _pairs_text(report.flat_overlaps)),
        ("first contact at omega", first),
        ("panel pairs in contact there", _pairs_text(report.pairs)),
        ("collision-free", "yes" if report.free else "no")])


# --------------------------------------------------------------------------- sweep
@app.command("sweep")
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
    from .sweeps import Study, run

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
                    console=console)
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


# --------------------------------------------------------------------------- fold
@app.command("fold")
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
    from .model import marching

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


# --------------------------------------------------------------------------- export
@app.command()
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
        path = out if out is not None else _result_folder(result_dir) / exporter.filename
        if path.suffix.lower() != exporter.suffix:
            raise InputError(f"--format {fmt} writes a {exporter.suffix} file, got {path}")
        exporter.write(path, result.pattern, om, **_export_options(result))
    wrote(path)


# --------------------------------------------------------------------------- render
@app.command()
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
    from .show import pictures as viz

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
        folder = out if out is not None else _result_folder(result_dir)
        check_out_dir(folder, force=True)
        omega_end = math.copysign(math.pi, result.omega)
        if folder.is_dir():
            _render_files(folder, result, omega_end, frames, trust=trust)
        else:
            with replace_folder(folder) as tmp:
                _render_files(tmp, result, omega_end, frames, trust=trust)
    wrote(folder / "render.png", folder / "folding.gif")


# --------------------------------------------------------------------------- view
@app.command("view")
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
    from .show import view

    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(out, "--out", output=True)
        frames = check_frames(frames, 2)
        result = DesignResult.load(result_dir)
        view.check_size(result.pattern.N, result.pattern.M, frames)
        path = out if out is not None else _result_folder(result_dir) / VIEW_FILE
        if path.suffix.lower() not in (".html", ".htm"):
            raise InputError(f"--out must name an .html file, got {path}")
        if not path.parent.is_dir():
            raise InputError(f"--out: no folder {path.parent} to write {path.name} into")
        view.write_html(result, path, frames=frames)
    wrote(path)


# --------------------------------------------------------------------------- targets
@app.command()
def targets() -> None:
    """List the built-in target surfaces with their parameters and default domains.

    Use one in a design file as [target] name = "<surface>" plus any parameters and
    domain = [[u0, u1], [v0, v1]].
    """
    from .targets import surfaces

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


# --------------------------------------------------------------------------- march
def march_memory(rows: int, cols: int, frames: int) -> float:
    """Bytes ``rffqm march`` needs for rows x cols panels and ``frames`` states
    (:func:`rffqm_nlp.memory.march_estimate`)."""
    return memory.march_estimate(rows, cols, frames)


@app.command()
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
    from .model import marching
    from .model.lengths import length_spread, side_length_lp

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
