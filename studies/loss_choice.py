"""Which loss? The paper's fundamental-form loss alone against the package's default
(positions after alignment + forms), positions alone, and the default with the smoothness
term, on the three bundled targets.

For every target (targets/*.toml, layout pinned to zigzag_i), panel count (8x8, 12x12) and
weight set, one IPOPT solve (sequential, exact Hessian, stop_rms=None, the default inline
constraints) from the same Miura start. Reported: the loss (with that run's own weights) at
start and end and its reduction, the RMS distance of the aligned coarse lattice to the target
lattice (Kabsch, relative to the target's diameter) at start and end, the same RMS after
removing each parity class's mean offset (the sideways offsets the forms loss is blind to,
docs/paper.md s.8), the paper's forms misfit (the mean square of the forms residuals, weight 1)
at start and end, iterations, time and IPOPT's status.

    python studies/loss_choice.py [--sizes 8 12] [--time-limit 60]
    python studies/loss_choice.py --smoke   (the sphere cap at 4 x 4, two weight sets,
        temporary output)
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np

from common import RESULTS, TARGETS, Run, add_smoke, smoke_dir, target_problem
from rffqm_nlp.model import numpy_model
from rffqm_nlp.targets import shape
from rffqm_nlp.design import transcription
from rffqm_nlp.model.boundary import BoundaryData
from rffqm_nlp.design.problem import DesignProblem
from rffqm_nlp.errors import RffqmError, SolverFailed
from rffqm_nlp.design.results import SolveStats

LAYOUT = "zigzag_i"
WEIGHTS = {
    "paper (forms only)": {"forms": 1.0, "position": 0.0, "regularization": 0.1},
    "default (position + 0.1 forms)": {"position": 1.0, "forms": 0.1, "regularization": 0.1},
    "position only": {"position": 1.0, "forms": 0.0, "regularization": 0.1},
    "default + smoothness 1": {"position": 1.0, "forms": 0.1, "regularization": 0.1,
                               "smoothness": 1.0},
}


def measures(prob: DesignProblem, start, x: np.ndarray) -> dict:
    """RMS fit (aligned, / diameter), parity-corrected RMS and the forms misfit of x."""
    n2, m2 = 2 * prob.N, 2 * prob.M
    nb = n2 + 1 + m2
    vec, omega = x[:2 * nb + n2 + m2], x[2 * nb + n2 + m2]
    bd = BoundaryData.from_vector(vec, start.boundary.sigma, n2, m2)
    r = numpy_model.fold(numpy_model.march(bd), omega)[::2, ::2]
    tgt = start.target_points
    diam = prob.target.diameter()
    R, t, rms = shape.kabsch(r, tgt)
    moved = r @ R.T + t
    # remove each parity class's mean offset from the target (4 translations)
    corr = moved.copy()
    for a in (0, 1):
        for b in (0, 1):
            d = tgt[a::2, b::2] - moved[a::2, b::2]
            corr[a::2, b::2] += d.reshape(-1, 3).mean(0)
    rms_par = np.sqrt(np.mean(np.sum((corr - tgt) ** 2, axis=-1)))
    forms = np.concatenate([(a - b).ravel() for a, b in
                            zip(shape.fundamental_forms(r), shape.fundamental_forms(tgt))])
    forms = forms / start.spacing ** 2
    rms_int = shape.kabsch(r[1:-1, 1:-1], tgt[1:-1, 1:-1])[2]
    ring = np.ones(r.shape[:2], bool)
    ring[1:-1, 1:-1] = False
    rms_ring = np.sqrt(np.mean(np.sum((moved - tgt)[ring] ** 2, axis=-1)))
    delta = vec - start.boundary.to_vector()
    delta[2 * nb:] /= start.spacing
    kinks = ca.evalf(transcription.smoothness_residuals(ca.DM(delta), n2, m2)).full()
    return {"rms": rms / diam, "rms_parity": rms_par / diam, "rms_interior": rms_int / diam,
            "rms_ring": rms_ring / diam, "forms": float(np.mean(forms ** 2)),
            "roughness": float(np.sqrt(np.mean(kinks ** 2)))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 12])
    ap.add_argument("--time-limit", type=float, default=60.0, help="IPOPT seconds per solve")
    ap.add_argument("--out", type=Path, default=RESULTS / "loss_choice.md")
    add_smoke(ap)
    args = ap.parse_args()
    targets, weights = TARGETS, WEIGHTS
    if args.smoke:
        args.sizes, targets = [4], TARGETS[:1]
        weights = dict(list(WEIGHTS.items())[:2])
        args.out = smoke_dir("loss_choice") / "loss_choice.md"
    run = Run()
    rows = []
    summary = {}
    for n in args.sizes:
        for name in targets:
            base, options = target_problem(name, n, layout=LAYOUT)
            options = replace(options, stop_rms=None, time_limit=args.time_limit,
                              transcription="sequential",  # measures() reads its x
                              hessian="exact", solver="ipopt")
            start = base.start()
            x0 = base.transcribe(start, options=options).x0
            m0 = measures(base, start, x0)
            for label, w in weights.items():
                prob = replace(base, weights=w)
                t0 = time.perf_counter()
                try:
                    res = prob.solve(options)
                    stats, x = res.stats, res.x
                except SolverFailed as exc:
                    if not isinstance(exc.stats, SolveStats):
                        rows.append(f"| {name} | {n}x{n} | {label} | {exc.status}: {exc} |")
                        print(rows[-1], flush=True)
                        continue
                    stats, x = exc.stats, exc.last_iterate
                except RffqmError as exc:
                    rows.append(f"| {name} | {n}x{n} | {label} | {type(exc).__name__}: {exc} |")
                    print(rows[-1], flush=True)
                    continue
                wall = time.perf_counter() - t0
                hist = stats.history["objective"]
                try:
                    m1 = measures(prob, start, np.asarray(x))
                except RffqmError as exc:
                    m1 = dict.fromkeys(m0, np.nan)
                    print(f"  last iterate does not march: {exc}")
                f0, f1 = hist[0], stats.objective
                summary[(n, name, label)] = (m0, m1, f0, f1)
                rows.append(
                    f"| {name} | {n}x{n} | {label} | {f0:.4g} | {f1:.4g} | "
                    f"{100 * (1 - f1 / f0):.1f}% | {100 * m0['rms']:.2f}% | "
                    f"**{100 * m1['rms']:.2f}%** | {100 * m1['rms_parity']:.2f}% | "
                    f"{100 * m1['rms_ring']:.2f}% | {100 * m1['rms_interior']:.2f}% | "
                    f"{m0['forms']:.3g} | {m1['forms']:.3g} ({100 * (m1['forms'] / m0['forms'] - 1):+.0f}%) | "
                    f"{m1['roughness']:.3g} | {stats.iterations} | {wall:.1f} | "
                    f"{stats.status} |")
                print(rows[-1], flush=True)
    md = [
        "# Loss choice (`studies/loss_choice.py`)",
        "",
        f"- {run.header()} (the load includes this run's own process)",
        f"- targets/*.toml, layout {LAYOUT}, stop_rms=None, IPOPT time limit "
        f"{args.time_limit:.0f} s, default constraints (min_length 0.2, min_angle 0.15, "
        "mu_margin 0.02), same Miura start for every weight set",
        "- weights: " + "; ".join(f"{k}: {v}" for k, v in weights.items()),
        "- loss: 0.5 |residuals|^2 with that run's weights (incl. the Tikhonov term), so losses "
        "of different weight sets are not comparable with each other, only their reductions",
        "- RMS/diam: RMS distance of the coarse lattice r(i,j) = y^(2i)(2j), rigidly aligned "
        "(Kabsch), to the target lattice, over the target's diameter; 'parity-corrected': the "
        "same after also removing each of the four parity classes' (i mod 2, j mod 2) mean "
        "offset (what the forms loss cannot see, docs/paper.md s.8); 'boundary ring': RMS over "
        "the outermost lattice rows and columns under the same alignment; 'interior only': "
        "Kabsch alignment and RMS over the (N-1) x (M-1) interior points, where the forms "
        "are evaluated (a boundary point enters the forms only through its neighbours' "
        "stencils, a corner only through r_uv)",
        "- forms misfit: mean square of the paper's loss residuals "
        "((S - S_hat) / spacing^2 over E, F, G, L, M, N at interior lattice points)",
        "- boundary roughness: RMS of the second differences of the boundary perturbation "
        "along each edge (angles in rad, lengths over the lattice spacing; "
        "`transcription.smoothness_residuals`), what the 'smoothness' weight penalises",
        "",
        "| target | panels | weights | loss start | loss end | loss reduction | RMS/diam start "
        "| RMS/diam end | RMS end, parity-corrected | RMS end, boundary ring | RMS end, interior "
        "only (own alignment) | forms misfit start | forms misfit end (change) "
        "| boundary roughness end | iterations | time [s] | status |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
