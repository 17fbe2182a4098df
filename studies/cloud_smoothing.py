"""How well does Mesh's smoothed spline recover a surface from a noisy point cloud, and which
smoothing weight lambda?

For each bundled surface: its 60 x 60 sample plus Gaussian noise of 0.2% of the diameter
(sigma), fitted by rffqm_nlp.targets.meshes.Mesh with several lambda (the package's default
CLOUD_SMOOTHING among them). Reported: the RMS and max distance of the fitted surface (a
30 x 30 grid over its domain) to the true surface over sigma (below 1: the fit removes
noise), the spline's RMS deviation from the noisy points over sigma (about 1: it follows the
surface, not the noise) and the fit time.

    .venv/bin/python studies/cloud_smoothing.py [--noise 0.002] [--out studies/results]
    .venv/bin/python studies/cloud_smoothing.py --smoke   (one surface, 15 x 15 points, the
        default lambda, temporary output)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import rffqm_nlp as rq
from common import RESULTS, Run, add_smoke, smoke_dir, write_table
from rffqm_nlp.targets import meshes

SURFACES = ["sphere_cap", "hyperboloid", "quarter_vase", "saddle", "torus_patch",
            "gaussian_bump"]
SMOOTHINGS = [1e-3, meshes.CLOUD_SMOOTHING, 0.1, 1.0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=0.002, help="sigma over the diameter")
    parser.add_argument("--out", type=Path, default=RESULTS)
    add_smoke(parser)
    args = parser.parse_args()
    surfaces, smoothings, side = SURFACES, SMOOTHINGS, 60
    if args.smoke:
        surfaces, smoothings, side = SURFACES[:1], [meshes.CLOUD_SMOOTHING], 15
        args.out = smoke_dir("cloud_smoothing")
    run = Run()
    lines = [f"# Point clouds with {args.noise:.1%} noise ({side} x {side} points)", "",
             "| surface | lambda | knots | RMS to surface / sigma | max / sigma | "
             "RMS to points / sigma | time (s) |", "|---|---|---|---|---|---|---|"]
    rng = np.random.default_rng(0)
    for name in surfaces:
        surface = rq.surfaces.get(name)
        sigma = args.noise * surface.diameter()
        points = surface.sample(side, side).reshape(-1, 3)
        noisy = points + rng.normal(scale=sigma, size=points.shape)
        for lam in smoothings:
            t0 = time.perf_counter()
            cloud = meshes.Mesh(noisy, smoothing=lam)
            elapsed = time.perf_counter() - t0
            dist = surface.closest_points(cloud.sample(30, 30))[2]
            dev = cloud.deviation_rms * cloud.diameter() / sigma
            mark = " (default)" if lam == meshes.CLOUD_SMOOTHING else ""
            lines.append(f"| {name} | {lam:g}{mark} | {cloud.knots} | "
                         f"{np.sqrt(np.mean(dist ** 2)) / sigma:.2f} | {dist.max() / sigma:.2f} "
                         f"| {dev:.2f} | {elapsed:.2f} |")
    lines[1:1] = ["", f"- {run.header()}"]
    text = "\n".join(lines) + "\n"
    write_table(args.out / "cloud_smoothing.md", text)


if __name__ == "__main__":
    main()
