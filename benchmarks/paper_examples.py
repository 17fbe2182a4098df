"""Paper examples: the paper's Fig. InverseExamples, a spherical cap, a hyperboloid and a
quarter vase.

For each bundled target: the target surface with its lattice, the optimised folded state and
the flat crease pattern (M red, V blue), saved as PNG beside the page
(paper_examples_<target>.png), and a table of panels, loss at start and end, RMS/diameter,
Hausdorff/diameter, the best plane's RMS (the baseline: the closest a flat sheet comes) and
the fit's ratio to it, smallest side/mean, smallest sector angle, iterations and time.

    python benchmarks/paper_examples.py [--panels 20] [--full]
        [--out docs/benchmarks/paper_examples.md]
        (to 0.9%, ``stop_rms`` = ``common.STOP_RMS``; ``--full``: to convergence)
    python benchmarks/paper_examples.py --smoke   (the sphere cap at 4 x 4, temporary output)
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from common import (STOP_RMS, TARGETS, Run, add_output, markdown_table,  # noqa: E402
                    output, target_problem, write_page)
from rffqm_nlp import DesignProblem, RffqmError  # noqa: E402
from rffqm_nlp.show import pictures  # noqa: E402

COLUMNS = ("target", "panels", "loss start", "loss end", "RMS/diam", "Hausdorff/diam",
           "plane RMS/diam", "RMS / plane", "min side/mean", "min angle", "iterations",
           "time (s)", "status")


def figure(name: str, prob: DesignProblem, res, path: Path) -> None:
    """Target with its lattice | folded state on the target | flat crease pattern."""
    fig = plt.figure(figsize=(15, 5))
    surf = prob.target.sample(40, 40)
    lattice = res.target_points
    ax = fig.add_subplot(1, 3, 1, projection="3d")
    ax.plot_surface(*(surf[..., k] for k in range(3)), color="0.8", alpha=0.5, linewidth=0)
    ax.scatter(*(lattice[..., k].ravel() for k in range(3)), color="k", s=8)
    ax.set_title(f"{name}: target and lattice")
    ax = fig.add_subplot(1, 3, 2, projection="3d")
    Y = res.folded
    ax.plot_surface(*(surf[..., k] for k in range(3)), color="0.85", alpha=0.3, linewidth=0)
    ax.plot_surface(*(Y[..., k] for k in range(3)), color="tab:orange", edgecolor="k",
                    linewidth=0.2, alpha=0.9)
    ax.set_title(f"folded, omega = {res.omega:.3f}, RMS {100 * res.fit.rms:.2f}% of diameter")
    for a in fig.axes:
        a.set_box_aspect((1, 1, 1))
        a.set_axis_off()
    ax = fig.add_subplot(1, 3, 3)
    pictures.plot_crease_pattern(res.pattern, res.omega, ax=ax)
    ax.set_title("crease pattern")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def row(name: str, panels: int, full: bool, pages: Path) -> list[str]:
    """Design one target at panels x panels, draw its figure into ``pages`` and return its
    table row."""
    prob, options = target_problem(name, panels)
    if not full:
        options = replace(options, stop_rms=STOP_RMS)
    t0 = time.perf_counter()
    try:
        res = prob.solve(options)
    except RffqmError as exc:
        return [name, str(panels), *["-"] * 9, f"{time.perf_counter() - t0:.1f}",
                f"{type(exc).__name__}: {exc}"]
    elapsed = time.perf_counter() - t0
    fit = res.fit
    figure(name, prob, res, pages / f"paper_examples_{name}.png")
    return [name, str(panels), f"{res.stats.history['objective'][0]:.4g}",
            f"{res.stats.objective:.4g}", f"{fit.rms:.2%}", f"{fit.hausdorff:.2%}",
            f"{fit.plane_rms:.2%}", f"{fit.rms / fit.plane_rms:.2f}",
            f"{fit.min_side_over_mean:.3f}", f"{fit.min_sector_angle:.3f}",
            str(res.stats.iterations), f"{elapsed:.1f}", res.stats.status]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--panels", type=int, default=20, help="2N = 2M panels")
    parser.add_argument("--targets", default=",".join(TARGETS))
    parser.add_argument("--full", action="store_true",
                        help="solve to convergence (by default the solve stops at stop_rms = "
                             "common.STOP_RMS, 0.9%%, as in the recorded table)")
    add_output(parser, "paper_examples")
    args = parser.parse_args()
    if args.smoke:
        args.panels, args.targets = 4, TARGETS[0]
    run = Run()
    page = output(args, "paper_examples")
    page.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for name in args.targets.split(","):
        rows.append(row(name, args.panels, args.full, page.parent))
        print(markdown_table(COLUMNS, rows[-1:])[-1], flush=True)
    stop = "to convergence" if args.full else f"to stop_rms = {STOP_RMS}"
    text = "\n".join([
        *run.preamble("paper_examples.py"),
        f"- each target file's options, {stop}; RMS / plane: the fit over the best plane's "
        "(the closest a flat sheet comes, measured in the same run)", "",
        *markdown_table(COLUMNS, rows), "",
        *(f"![{name}](paper_examples_{name}.png)" for name in args.targets.split(","))])
    write_page(page, "Paper examples", text)


if __name__ == "__main__":
    main()
