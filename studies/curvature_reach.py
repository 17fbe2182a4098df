"""Which Gaussian curvature can a pattern of a given size reach? A sweep over sphere caps
(K > 0) and saddles (K < 0) of several curvatures against the pattern size.

Every target is a patch of the same size, side L = 4 (arc length for the sphere cap, the
projected side for the saddle): a sphere cap of radius R over the angles |u|, |v| <= 2 / R,
and the saddle z = (u^2 - v^2) / (2R) over |u|, |v| <= 2, both with K = +-1/R^2 at the
centre. The dimensionless curvature is K L^2 at the centre. Each target is designed at
8 x 8, 12 x 12 and 16 x 16 panels with the default options, IPOPT run to its tolerance
(stop_rms off, max_iter 500; no wall-time limit, so that the outcome does not depend on
the machine's load), all designs one sweep (:mod:`rffqm_nlp.sweeps`) on a 2-worker
LocalCluster, the largest patterns submitted first.

Writes studies/results/curvature_reach.png (K L^2 against the achieved RMS fit, one line
per pattern size, with the best plane's RMS for comparison) and curvature_reach.md; the
per-design results go to --out (resumable: a second run only redoes missing designs).

    python studies/curvature_reach.py [--out runs/curvature_reach] [--scheduler local]
    python studies/curvature_reach.py --smoke   (one radius at 4 x 4 panels, serial,
        temporary output)
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from common import RESULTS, ROOT, Run, add_smoke, smoke_dir  # noqa: E402
from rffqm_nlp import sweeps  # noqa: E402
from rffqm_nlp.targets import surfaces

SIDE = 4.0
RADII = (1.5, 2.0, 3.0, 5.0)
PANELS = [8, 12, 16]
# the solver and transcription of the recorded results (IPOPT to its tolerance: stop_rms
# unset; the package defaults are now Levenberg-Marquardt, simultaneous)
BASE = {"solve": {"solver": "ipopt", "max_iter": 500, "transcription": "sequential"}}


def cases(radii: tuple[float, ...] = RADII) -> list[dict]:
    """One [[sweep.cases]] entry per target: sphere caps and saddles of each radius."""
    half = SIDE / 2
    out = []
    for R in radii:
        out.append({"name": f"sphere R={R:g}", "target.name": "sphere_cap",
                    "target.radius": R, "target.domain": [[-half / R, half / R]] * 2})
        out.append({"name": f"saddle R={R:g}", "target.name": "saddle", "target.a": R,
                    "target.b": R, "target.domain": [[-half, half]] * 2})
    return out


def curvature(row: pd.Series) -> float:
    """K L^2 at the centre of the row's target."""
    R = row["target.radius"] if row["case"].startswith("sphere") else row["target.a"]
    sign = 1.0 if row["case"].startswith("sphere") else -1.0
    return sign * SIDE ** 2 / R ** 2


def plane_rms(target: dict) -> float:
    """RMS distance of the target's 9 x 9 lattice (that of 16 x 16 panels) to its best plane,
    relative to the diameter: the fit a flat sheet reaches."""
    surface = surfaces.from_config(target)
    pts = surface.lattice(8, 8).reshape(-1, 3)
    smallest = np.linalg.svd(pts - pts.mean(0), compute_uv=False)[-1]
    return float(smallest / math.sqrt(len(pts)) / surface.diameter())


def figure(frame: pd.DataFrame, path: Path, panels: list[int]) -> None:
    """K L^2 against the RMS fit: one line per pattern size, failures marked at the top."""
    fig, ax = plt.subplots(figsize=(8, 5))
    top = 1.3 * frame["plane"].max() * 100
    for size, group in frame.groupby("panels"):
        group = group.sort_values("K L^2")
        for shape, part in group.groupby(group["K L^2"] > 0):
            solved = part[part["status"] == "solved"]
            ax.plot(solved["K L^2"], 100 * solved["rms"], "o-", color=f"C{panels.index(size)}",
                    label=f"{size} x {size} panels" if shape else None)
            failed = part[part["status"] != "solved"]
            ax.plot(failed["K L^2"], [top] * len(failed), "x", color=f"C{panels.index(size)}",
                    markersize=9)
    plane = frame.drop_duplicates("case").sort_values("K L^2")
    for shape, part in plane.groupby(plane["K L^2"] > 0):
        ax.plot(part["K L^2"], 100 * part["plane"], "--", color="0.5",
                label="best plane" if shape else None)
    ax.axvline(0, color="0.8", linewidth=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("K L^2 at the centre (saddles < 0 < sphere caps), patch side L = 4")
    ax.set_ylabel("RMS distance to the target lattice (% of diameter)")
    ax.set_title("Reachable Gaussian curvature against pattern size (x: no solution)")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def markdown(frame: pd.DataFrame, header: list[str], panels: list[int]) -> str:
    """One line per target, one column per pattern size: RMS (or the status), iterations,
    time; and whether each design's motion is collision-free."""
    lines = header + ["", "| target | K L^2 | best plane RMS | "
                      + " | ".join(f"{p} x {p}: RMS, it., time" for p in panels)
                      + f" | collision-free ({', '.join(f'{p} x {p}' for p in panels)}) |",
                      "|---|---|---|" + "---|" * (len(panels) + 1)]
    for case, group in frame.groupby("case", sort=False):
        cells = []
        for p in panels:
            row = group[group["panels"] == p].iloc[0]
            if row["status"] == "solved":
                cells.append(f"{100 * row['rms']:.2f}% ({row['iterations']}, "
                             f"{row['time']:.0f} s)")
            else:
                cells.append(f"{row['status']}: {row['solver_status']} ({row['time']:.0f} s)")
        first = group.iloc[0]
        free = ", ".join(collision_free(group[group["panels"] == p].iloc[0]) for p in panels)
        lines.append(f"| {case} | {first['K L^2']:+.2f} | {100 * first['plane']:.2f}% | "
                     + " | ".join(cells) + f" | {free} |")
    return "\n".join(lines) + "\n"


def collision_free(row: pd.Series) -> str:
    """"yes", "no (first contact at omega w)", "-" for a design that failed, "?" for one
    solved before the check existed (fit.collision_free)."""
    if row["status"] != "solved":
        return "-"
    if pd.isna(row["collision_free"]):
        return "?"
    if row["collision_free"]:
        return "yes"
    w = row["first_contact_omega"]
    return "no" if pd.isna(w) else f"no (omega {w:.2f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "runs" / "curvature_reach")
    parser.add_argument("--results", type=Path, default=RESULTS)
    parser.add_argument("--scheduler", default="local", help="local, none or an address")
    parser.add_argument("--workers", type=int, default=2)
    add_smoke(parser)
    args = parser.parse_args()
    panels, radii = PANELS, RADII
    if args.smoke:
        panels, radii, args.scheduler = [4], RADII[-1:], "none"
        args.out = smoke_dir("curvature_reach")
        args.results = args.out / "results"
    study = sweeps.Study(base=BASE, parameters={"design.panels": panels[::-1]},
                         cases=cases(radii))
    run = Run()
    frame = sweeps.run(study, args.out, scheduler=args.scheduler, workers=args.workers)
    frame["panels"] = frame["design.panels"].astype(int)
    frame["K L^2"] = frame.apply(curvature, axis=1)
    targets = {d.id: d.config["target"] for d in study.designs()}
    frame["plane"] = [plane_rms(targets[i]) for i in frame["id"]]
    args.results.mkdir(parents=True, exist_ok=True)
    figure(frame, args.results / "curvature_reach.png", panels)
    header = ["# Reachable Gaussian curvature (`studies/curvature_reach.py`)", "",
              f"- {run.header()}; {len(frame)} designs (scheduler {args.scheduler}, "
              f"{args.workers} workers; designs found complete in --out are not re-timed)",
              f"- targets: patches of side L = {SIDE:g}: sphere caps of radius R over angles "
              f"|u|, |v| <= {SIDE / 2:g}/R, saddles z = (u^2 - v^2)/(2R) over |u|, |v| <= "
              f"{SIDE / 2:g}; K L^2 at the centre = +-{SIDE ** 2:g}/R^2",
              "- design: defaults (layout zigzag_i, alpha0 1.1, omega0 2.0, min_length 0.2, "
              "min_angle 0.15); IPOPT (sequential), stop_rms off, max_iter 500; RMS = distance "
              "to the target lattice / target diameter; time = wall time of the design on its "
              "worker (build + solve); collision-free: the motion from flat to the designed "
              "omega has no two panels that share no vertex touching (fit.collision_free, "
              "docs/collisions.md)",
              "- ![plot](curvature_reach.png)"]
    text = markdown(frame, header, panels)
    (args.results / "curvature_reach.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
