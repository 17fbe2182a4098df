"""Which parametrization of a disk-topology mesh that is no graph over its plane? The
package's conformal map onto a rectangle (rffqm_nlp.targets.meshes, for a patch with four corners)
and its scipy LSCM (for one without) against libigl's LSCM (same two pinned vertices),
libigl's harmonic map with the boundary on a circle, and Tutte's uniform-weight map (the
package's fallback).

For each bundled surface on a domain that makes it no graph over its best-fit plane, meshed
at 61 x 61: the time of the map, the conformal distortion (area-weighted mean and max over
the faces of sigma_1 / sigma_2, the singular values of the map's Jacobian from the face to
the plane), the share of the mesh's area inside the inscribed domain rectangle (what a
design can cover), and the largest distance of a 20 x 20 lattice of the fitted Mesh to the
original surface over its diameter (for the package's own maps).

    .venv/bin/python studies/mesh_parametrization.py [--n 61] [--out studies/results]
    .venv/bin/python studies/mesh_parametrization.py --smoke   (one surface at 11 x 11,
        temporary output)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

import rffqm_nlp as rq
from common import RESULTS, Run, add_smoke, smoke_dir, write_table
from rffqm_nlp.targets import meshes

CASES = [("cylinder", ((-2.0, 2.0), (-1.5, 1.5))),
         ("sphere_cap", ((-1.3, 1.3), (-1.3, 1.3))),
         ("torus_patch", ((-1.2, 1.2), (0.0, 3.1))),
         ("hyperboloid", ((-0.8, 0.8), (-1.6, 1.6)))]


def _igl_lscm(mesh):
    import igl
    loop = meshes._boundary_loop(mesh)
    pts = mesh.vertices[loop]
    i = int(np.argmax(np.linalg.norm(pts - pts[0], axis=1)))
    j = int(np.argmax(np.linalg.norm(pts - pts[i], axis=1)))
    b = np.array([loop[i], loop[j]], dtype=np.int64)
    bc = np.array([[0.0, 0.0], [np.linalg.norm(pts[i] - pts[j]), 0.0]])
    return igl.lscm(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64), b, bc)[0]


def _igl_harmonic(mesh):
    import igl
    loop = meshes._boundary_loop(mesh)
    seg = np.linalg.norm(np.diff(mesh.vertices[np.r_[loop, loop[:1]]], axis=0), axis=1)
    angle = 2 * np.pi * np.r_[0.0, np.cumsum(seg)[:-1]] / seg.sum()
    bc = np.c_[np.cos(angle), np.sin(angle)]
    return igl.harmonic(np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64),
                        loop.astype(np.int64), bc, 1)


METHODS = {"conformal rectangle (package)": meshes.conformal_rectangle,
           "scipy LSCM (package, no four corners)": meshes._lscm, "libigl LSCM": _igl_lscm,
           "libigl harmonic (circle)": _igl_harmonic, "Tutte (package fallback)": meshes._tutte}


def distortion(mesh, uv: np.ndarray) -> tuple[float, float, int]:
    """(area-weighted mean, max of sigma_1/sigma_2, flipped faces) of the map uv."""
    grad, area = meshes._local_gradients(mesh)
    jac = np.einsum("mkd,mke->mde", grad, uv[mesh.faces])  # (m, 2 local, 2 uv)
    sv = np.linalg.svd(jac, compute_uv=False)
    ratio = sv[:, 0] / np.maximum(sv[:, 1], 1e-300)
    flipped = int((meshes._signed_areas(mesh.faces, uv) <= 0).sum())
    return float(ratio @ area / area.sum()), float(ratio.max()), flipped


def coverage(mesh, uv: np.ndarray) -> float:
    """Share of the mesh's area whose faces' parameter centroids lie in the inscribed domain."""
    uv = meshes.align(uv)
    dom = meshes.inscribed_rectangle(uv, meshes._polygon_mask(uv[meshes._boundary_loop(mesh)]))
    c = uv[mesh.faces].mean(axis=1)
    inside = ((c[:, 0] >= dom[0][0]) & (c[:, 0] <= dom[0][1])
              & (c[:, 1] >= dom[1][0]) & (c[:, 1] <= dom[1][1]))
    return float(mesh.area_faces[inside].sum() / mesh.area)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=61, help="mesh vertices per direction")
    parser.add_argument("--out", type=Path, default=RESULTS)
    add_smoke(parser)
    args = parser.parse_args()
    cases = CASES
    if args.smoke:
        args.n, cases, args.out = 11, CASES[:1], smoke_dir("mesh_parametrization")
    run = Run()
    rows = []
    for name, dom in cases:
        surface = rq.surfaces.get(name, domain=dom)
        mesh = meshes._clean(surface.mesh(args.n, args.n).vertices,
                             surface.mesh(args.n, args.n).faces, name)
        meshes._check_disk(mesh, name)
        for label, fn in METHODS.items():
            t0 = time.perf_counter()
            uv = fn(mesh)
            elapsed = time.perf_counter() - t0
            mean, worst, flipped = distortion(mesh, uv)
            rows.append((name, label, elapsed, mean, worst, flipped, coverage(mesh, uv)))
        fitted = meshes.Mesh(mesh)
        lattice = surface.closest_points(fitted.lattice(20, 20))[2].max() / surface.diameter()
        rows.append((name, f"Mesh() used: {fitted.parametrization}", float("nan"),
                     float("nan"), float("nan"), 0, float(lattice)))
    lines = [f"# Parametrization of non-graph meshes ({args.n} x {args.n} vertices)", "",
             f"- {run.header()}", "",
             "| surface (domain) | map | time (s) | distortion mean | distortion max | "
             "flipped | area in domain |", "|---|---|---|---|---|---|---|"]
    for name, label, elapsed, mean, worst, flipped, cov in rows:
        if label.startswith("Mesh()"):
            lines.append(f"| {name} | {label} | | | | | lattice error {cov:.1e} of diam. |")
        else:
            lines.append(f"| {name} | {label} | {elapsed:.3f} | {mean:.3f} | {worst:.2f} | "
                         f"{flipped} | {cov:.1%} |")
    text = "\n".join(lines) + "\n"
    write_table(args.out / "mesh_parametrization.md", text)


if __name__ == "__main__":
    main()
