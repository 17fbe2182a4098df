"""The paper's Fig. InverseExamples: a spherical cap, a hyperboloid and a quarter vase.

For each bundled target: the target surface with its lattice, the optimised folded state and
the flat crease pattern (M red, V blue), saved as PNG, and a table of panels, loss at start
and end, RMS/diameter, Hausdorff/diameter, the best plane's RMS, smallest side/mean, smallest
sector angle, iterations and time.

    python studies/inverse_examples.py [--panels 20] [--out studies/results] [--full]
        (to 0.9%, ``stop_rms`` = ``common.STOP_RMS``; ``--full``: to convergence)
    python studies/inverse_examples.py --smoke   (the sphere cap at 4 x 4, temporary output)
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from common import (RESULTS, STOP_RMS, TARGETS, Run, add_smoke, smoke_dir,  # noqa: E402
                    target_problem)
from rffqm_nlp.show import pictures as viz  # noqa: E402
from rffqm_nlp.design.problem import DesignProblem  # noqa: E402
from rffqm_nlp.errors import RffqmError  # noqa: E402


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
    viz.plot_crease_pattern(res.pattern, res.omega, ax=ax)
    ax.set_title("crease pattern")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--panels", type=int, default=20, help="2N = 2M panels")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--targets", default=",".join(TARGETS))
    parser.add_argument("--full", action="store_true",
                        help="solve to convergence (by default the solve stops at stop_rms = "
                             "common.STOP_RMS, 0.9%%, as in the recorded table)")
    add_smoke(parser)
    args = parser.parse_args()
    if args.smoke:
        args.panels, args.targets, args.out = 4, TARGETS[0], smoke_dir("inverse_examples")
    run = Run()
    args.out.mkdir(parents=True, exist_ok=True)
    header = ("| target | panels | loss start | loss end | RMS/diam | Hausdorff/diam | plane RMS/diam "
              "| min side/mean | min angle | iterations | time (s) | status |")
    rows = [header, "|" + "---|" * 12]
    for name in args.targets.split(","):
        prob, options = target_problem(name, args.panels)
        if not args.full:
            options = replace(options, stop_rms=STOP_RMS)
        t0 = time.perf_counter()
        try:
            res = prob.solve(options)
        except RffqmError as exc:
            rows.append(f"| {name} | {args.panels} | | | | | | | | | "
                        f"{time.perf_counter() - t0:.1f} | {type(exc).__name__}: {exc} |")
            print(rows[-1], flush=True)
            continue
        elapsed = time.perf_counter() - t0
        hist = res.stats.history["objective"]
        fit = res.fit
        rows.append(f"| {name} | {args.panels} | {hist[0]:.4g} | {res.stats.objective:.4g} "
                    f"| {100 * fit.rms:.2f}% | {100 * fit.hausdorff:.2f}% "
                    f"| {100 * fit.plane_rms:.2f}% | {fit.min_side_over_mean:.3f} "
                    f"| {fit.min_sector_angle:.3f} | {res.stats.iterations} "
                    f"| {elapsed:.1f} | {res.stats.status} |")
        print(rows[-1], flush=True)
        figure(name, prob, res, args.out / f"inverse_{name}.png")
    table = "\n".join([f"- {run.header()}", "", *rows])
    (args.out / f"inverse_examples_{args.panels}.md").write_text(table + "\n")
    print(table)


if __name__ == "__main__":
    main()
