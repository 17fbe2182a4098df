"""How well does Mesh's smoothed spline recover a surface from a noisy point cloud, and which
smoothing weight lambda?

For each bundled surface: its 60 x 60 sample plus Gaussian noise of 0.2% of the diameter
(sigma), fitted by rffqm_nlp.meshes.Mesh with several lambda (the package's default
CLOUD_SMOOTHING among them). Reported: the RMS and max distance of the fitted surface (a
30 x 30 grid over its domain) to the true surface over sigma (below 1: the fit removes
noise), the spline's RMS deviation from the noisy points over sigma (about 1: it follows the
surface, not the noise) and the fit time.

    .venv/bin/python studies/cloud_smoothing.py [--noise 0.002] [--out studies/results]
"""

from __future__ import annotations

import argparse
import datetime
import os
import time
from pathlib import Path

import numpy as np

import rffqm_nlp as rq
from rffqm_nlp import meshes

SURFACES = ["sphere_cap", "hyperboloid", "quarter_vase", "saddle", "torus_patch",
            "gaussian_bump"]
SMOOTHINGS = [1e-3, meshes.CLOUD_SMOOTHING, 0.1, 1.0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=0.002, help="sigma over the diameter")
    parser.add_argument("--out", type=Path, default=Path("studies/results"))
    args = parser.parse_args()
    lines = [f"# Point clouds with {args.noise:.1%} noise ({datetime.date.today()}, 60 x 60 "
             f"points, load {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs)", "",
             "| surface | lambda | knots | RMS to surface / sigma | max / sigma | "
             "RMS to points / sigma | time (s) |", "|---|---|---|---|---|---|---|"]
    rng = np.random.default_rng(0)
    for name in SURFACES:
        surface = rq.surfaces.get(name)
        sigma = args.noise * surface.diameter()
        points = surface.sample(60, 60).reshape(-1, 3)
        noisy = points + rng.normal(scale=sigma, size=points.shape)
        for lam in SMOOTHINGS:
            t0 = time.perf_counter()
            cloud = meshes.Mesh(noisy, smoothing=lam)
            elapsed = time.perf_counter() - t0
            dist = surface.closest_points(cloud.sample(30, 30))[2]
            dev = cloud.deviation_rms * cloud.diameter() / sigma
            mark = " (default)" if lam == meshes.CLOUD_SMOOTHING else ""
            lines.append(f"| {name} | {lam:g}{mark} | {cloud.knots} | "
                         f"{np.sqrt(np.mean(dist ** 2)) / sigma:.2f} | {dist.max() / sigma:.2f} "
                         f"| {dev:.2f} | {elapsed:.2f} |")
    text = "\n".join(lines) + "\n"
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "cloud_smoothing.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
