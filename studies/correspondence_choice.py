"""Which correspondence fits the shape better at equal panels: the fixed target lattice
(``correspondence = "lattice"``: r on the uniform grid of the domain) or the free one
(``"free"``, the default: the lattice's (u, v) a B-spline map of the lattice indices whose
controls are design variables, docs/meshes.md)?

Each bundled target (targets/<name>.toml) and two mesh targets (the hyperboloid's and the
quarter vase's surface over its domain written as a 61 x 61 ``grid.obj``, as in
studies/bench_mesh_targets.py, the target replaced by ``rq.surfaces.Mesh(file)``) is designed
at 20 x 20 panels with the target file's [design] and [solve] tables in both modes, solved to
convergence (no ``stop_rms``). Reported: the Fit's shape distances over the diameter
(``rms_surface``, ``hausdorff``: the folded coarse lattice to the shape;
``rms_surface_vertices``: every folded vertex), ``coverage``, the iterations, the solve's
wall time, the status, and for the free mode the grid's smallest forward difference over
the uniform step (the bound is ``transcription.MIN_GRID_STEP``).

A second table solves the bundled targets in the free mode with the Tikhonov weight of the
grid (``transcription.GRID_REGULARIZATION``, a fraction of the "regularization" weight) at
three values, the middle one the package's, and with the map's controls a side
(``transcription.GRID_CONTROLS``) at three values, the first the package's; another table
compares the modes on the bundled targets at 8, 12, 16 and 30 panels a side. The last
measures the cost per iteration against size: the sphere cap at 20, 40 and 60 panels a
side, four iterations of the default solver in each mode (build and solve time), each in a
fresh process; with ``--previous REV`` the code at that git revision runs the same right
after, and the table gives the ratio.

    .venv/bin/python studies/correspondence_choice.py [--panels 20] [--previous REV]
        [--out studies/results]
    .venv/bin/python studies/correspondence_choice.py --smoke   (sphere_cap, 8 x 8 panels,
        no mesh target, temporary output)
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

import rffqm_nlp as rq
from bench_mesh_targets import grid_obj
from common import (RESULTS, ROOT, TARGETS, Run, add_smoke, export_package, fmt, smoke_dir,
                    solve_in_child, target_problem, write_table)
from rffqm_nlp.design import transcription

MODES = ("lattice", "free")
#: the mesh targets: bundled targets whose surface is written as grid.obj
MESH_TARGETS = ("hyperboloid", "quarter_vase")
#: the grid's Tikhonov weights of the second table, as multiples of the package's
GRID_WEIGHTS = (0.1, 1.0, 10.0)
#: the map's controls a side in the second table
CONTROLS = (4, 6, 8)
#: panels a side of the table of other sizes (the bundled targets, both modes)
FIT_SIZES = (8, 12, 16, 30)
#: panels a side and iterations of the last table
SIZES, ITERATIONS = (20, 40, 60), 4


def grid_steps(problem: rq.DesignProblem, result: rq.DesignResult) -> float | None:
    """The free grid's smallest forward difference (u along i, v along j) over the uniform
    step, from the result's design vector (None for the lattice mode)."""
    grid = problem.grid(result)
    if grid is None:
        return None
    (u0, u1), (v0, v1) = problem.target.domain
    U, V = grid
    return float(min((np.diff(U, axis=0) * problem.N / (u1 - u0)).min(),
                     (np.diff(V, axis=1) * problem.M / (v1 - v0)).min()))


def solve(label: str, problem: rq.DesignProblem, options: rq.SolveOptions) -> dict:
    """One design's row."""
    t0 = time.perf_counter()
    try:
        result = problem.solve(options)
    except rq.SolverFailed as exc:
        return {"target": label, "mode": problem.correspondence, "status": exc.status,
                "time": time.perf_counter() - t0}
    fit = result.fit
    return {"target": label, "mode": problem.correspondence, "status": result.stats.status,
            "time": time.perf_counter() - t0, "iterations": result.stats.iterations,
            "rms_surface": fit.rms_surface, "hausdorff": fit.hausdorff,
            "rms_surface_vertices": fit.rms_surface_vertices, "coverage": fit.coverage,
            "min_step": grid_steps(problem, result)}


def iteration_cost(n: int, mode: str, code: str, package: Path) -> dict:
    """ITERATIONS iterations of the sphere cap at n x n panels in a fresh process importing
    the package from ``package``: build and solve seconds per iteration."""
    row = solve_in_child("sphere_cap", n, design={"correspondence": mode},
                         solve={"max_iter": ITERATIONS}, env={"PYTHONPATH": str(package)})
    its = max(row["iterations"] or 0, 1)  # Maximum_Iterations_Exceeded, as asked
    return {"n": n, "mode": mode, "code": code, "iterations": row["iterations"],
            "build": row["build_time"], "solve": row["solve_time"],
            "per_iteration": row["solve_time"] / its}


def cost_table(rows: list[dict]) -> str:
    lines = ["", f"## Cost per iteration against size (sphere_cap, {ITERATIONS} iterations)",
             "", "| panels | mode | code | iterations | build (s) | solve (s) | "
             "solve per iteration (s) | this / previous, per iteration |", "|---|---|---|---|---|---|---|---|"]
    this = {(r["n"], r["mode"]): r["per_iteration"] for r in rows if r["code"] == "this"}
    for r in rows:
        ratio = (None if r["code"] == "this" else this[(r["n"], r["mode"])] / r["per_iteration"])
        lines.append(f"| {r['n']} | {r['mode']} | {r['code']} | {r['iterations']} | "
                     f"{r['build']:.1f} | {r['solve']:.1f} | {r['per_iteration']:.2f} | "
                     f"{fmt(ratio, '.2f')} |")
    return "\n".join(lines) + "\n"


def designs(names: tuple[str, ...], meshes: tuple[str, ...], n: int, folder: Path):
    """(label, problem, options) of every target, the mesh targets' files in ``folder``."""
    for name in names:
        problem, options = target_problem(name, n)
        yield name, problem, options
    for name in meshes:
        problem, options = target_problem(name, n)
        sub = folder / name
        sub.mkdir(parents=True, exist_ok=True)
        path = grid_obj(problem.target, sub)
        yield f"{name} grid.obj", replace(problem, target=rq.surfaces.Mesh(path)), options


def pct(value: float | None) -> str:
    return "-" if value is None else f"{100 * value:.3f}%"


def main_table(rows: list[dict], run: Run, n: int) -> str:
    lines = [f"# Correspondence: fixed lattice against free, {n} x {n} panels\n", run.header()
             + f"; OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}",
             "", "Shape distances over the diameter; free / lattice: the free mode's "
             "rms_surface over the lattice mode's.", "",
             "| target | mode | rms_surface | hausdorff | rms_surface_vertices | coverage | "
             "iterations | time (s) | min grid step | free / lattice | status |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    lattice = {r["target"]: r for r in rows if r["mode"] == "lattice"}
    for r in rows:
        base = lattice.get(r["target"], {}).get("rms_surface")
        ratio = (None if r["mode"] != "free" or base is None or "rms_surface" not in r
                 else r["rms_surface"] / base)
        lines.append(
            f"| {r['target']} | {r['mode']} | {pct(r.get('rms_surface'))} | "
            f"{pct(r.get('hausdorff'))} | {pct(r.get('rms_surface_vertices'))} | "
            f"{fmt(r.get('coverage'), '.4f')} | {fmt(r.get('iterations'), 'd')} | "
            f"{r['time']:.1f} | {fmt(r.get('min_step'), '.2f')} | {fmt(ratio, '.2f')} | "
            f"{r['status']} |")
    return "\n".join(lines) + "\n"


def weight_table(rows: list[dict]) -> str:
    lines = ["", "## The grid's Tikhonov weight and controls (free mode)", "",
             f"GRID_REGULARIZATION = {transcription.GRID_REGULARIZATION:g} x the factor "
             "(of the \"regularization\" weight); controls: GRID_CONTROLS (the package's: "
             f"{transcription.GRID_CONTROLS}).", "",
             "| target | factor | controls | rms_surface | rms_surface_vertices | iterations | "
             "time (s) | min grid step | status |", "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['target']} | {r['factor']:g} | {r['controls']} | "
                     f"{pct(r.get('rms_surface'))} | "
                     f"{pct(r.get('rms_surface_vertices'))} | "
                     f"{fmt(r.get('iterations'), 'd')} | {r['time']:.1f} | "
                     f"{fmt(r.get('min_step'), '.2f')} | {r['status']} |")
    return "\n".join(lines) + "\n"


def sizes_table(rows: list[dict]) -> str:
    lines = ["", "## Other sizes (bundled targets)", "",
             "| target | panels | rms_surface lattice | free | free / lattice | iterations "
             "lattice | free | time (s) lattice | free |", "|---|---|---|---|---|---|---|---|---|"]
    for lat, free in zip(rows[::2], rows[1::2]):
        ratio = (free["rms_surface"] / lat["rms_surface"]
                 if "rms_surface" in lat and "rms_surface" in free else None)
        lines.append(f"| {lat['target']} | {lat['n']} | {pct(lat.get('rms_surface'))} | "
                     f"{pct(free.get('rms_surface'))} | {fmt(ratio, '.2f')} | "
                     f"{fmt(lat.get('iterations'), 'd')} | {fmt(free.get('iterations'), 'd')} | "
                     f"{lat['time']:.1f} | {free['time']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--panels", type=int, default=20)
    parser.add_argument("--previous", default=None,
                        help="a git revision whose cost per iteration is measured too")
    parser.add_argument("--out", type=Path, default=RESULTS)
    add_smoke(parser)
    args = parser.parse_args(argv)
    names, meshes, n, out, factors = TARGETS, MESH_TARGETS, args.panels, args.out, GRID_WEIGHTS
    if args.smoke:
        names, meshes, n, out, factors = ("sphere_cap",), (), 8, smoke_dir("correspondence"), ()
    sizes = () if args.smoke else SIZES
    run = Run()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, problem, options in designs(names, meshes, n, Path(folder)):
            for mode in MODES:
                rows.append(solve(label, replace(problem, correspondence=mode), options))
                print(rows[-1], file=sys.stderr, flush=True)
    weights = []
    base, controls = transcription.GRID_REGULARIZATION, transcription.GRID_CONTROLS
    settings = ([(factor, controls) for factor in factors]
                + [(1.0, k) for k in CONTROLS if k != controls and factors])
    try:
        for name in names:
            problem, options = target_problem(name, n, correspondence="free")
            for factor, k in settings:
                transcription.GRID_REGULARIZATION = base * factor
                transcription.GRID_CONTROLS = k
                weights.append({**solve(name, problem, options), "factor": factor,
                                "controls": k})
                print(weights[-1], file=sys.stderr, flush=True)
    finally:
        transcription.GRID_REGULARIZATION, transcription.GRID_CONTROLS = base, controls
    others = [{**solve(name, *target_problem(name, size, correspondence=mode)), "n": size}
              for name in names for size in (() if args.smoke else FIT_SIZES) for mode in MODES]
    codes = {"this": ROOT}
    if args.previous and sizes:
        codes[f"previous ({args.previous})"] = export_package(args.previous)
    costs = [iteration_cost(size, mode, code, package)
             for size in sizes for mode in MODES for code, package in codes.items()]
    text = (main_table(rows, run, n) + (weight_table(weights) if weights else "")
            + (sizes_table(others) if others else "")
            + (cost_table(costs) if costs else ""))
    write_table(out / "correspondence_choice.md", text)


if __name__ == "__main__":
    main()
