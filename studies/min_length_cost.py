"""What the inline side-length constraint costs: fit and iterations against min_length.

The sphere cap (targets/sphere_cap.toml) at 8x8 and 12x12 panels, stop_rms=None, default
weights and other constraints; every side >= min_length x the mean side for min_length in
{0.05, 0.1, 0.2, 0.3, 0.4, 0.5} (0.2 is the package default) and, beyond the brief, 0.6,
0.7, 0.8. Both Miura layouts: zigzag_i (the package default since 945512b) and zigzag_j (the
earlier default, whose optimum at 8x8 sits on the min_length = 0.2 bound). One IPOPT solve
per case from the layout's Miura start. Writes studies/results/min_length_cost.md
and studies/results/min_length_cost.png.

    python studies/min_length_cost.py [--sizes 8 12] [--time-limit 60]
    python studies/min_length_cost.py --smoke   (4 x 4, one layout, two bounds, temporary
        output)
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from common import RESULTS, Run, add_smoke, smoke_dir, target_problem  # noqa: E402
from rffqm_nlp.errors import InfeasibleDesign, SolverFailed  # noqa: E402
from rffqm_nlp.design.results import SolveStats  # noqa: E402

LAYOUTS = ("zigzag_i", "zigzag_j")
MIN_LENGTHS = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 12])
    ap.add_argument("--time-limit", type=float, default=60.0, help="IPOPT seconds per solve")
    ap.add_argument("--out", type=Path, default=RESULTS)
    add_smoke(ap)
    args = ap.parse_args()
    layouts, min_lengths = LAYOUTS, MIN_LENGTHS
    if args.smoke:
        args.sizes, layouts, min_lengths = [4], LAYOUTS[:1], (0.1, 0.2)
        args.out = smoke_dir("min_length_cost")
    run = Run()
    base, options = target_problem("sphere_cap", args.sizes[0])
    options = replace(options, stop_rms=None, time_limit=args.time_limit,
                      transcription="sequential", hessian="exact", solver="ipopt")
    rows, data, plane = [], {}, np.nan
    for layout, n in [(lay, n) for lay in layouts for n in args.sizes]:
        for ml in min_lengths:
            prob = replace(base, panels=(n, n), min_length=ml, layout=layout)
            t0 = time.perf_counter()
            entry = {"ml": ml, "rms": np.nan, "iters": np.nan}
            try:
                res = prob.solve(options)
                f, st = res.fit, res.stats
                entry.update(rms=f.rms, iters=st.iterations)
                plane = 100 * f.plane_rms
                rows.append(
                    f"| {layout} | {n}x{n} | {ml:.2f} | **{100 * f.rms:.2f}%** | "
                    f"{100 * f.rms_surface:.2f}% | {100 * f.hausdorff:.2f}% | "
                    f"{f.min_side_over_mean:.3f} | {f.min_sector_angle:.3f} | "
                    f"{st.history['objective'][0]:.4g} | {st.objective:.4g} | "
                    f"{st.iterations} | {time.perf_counter() - t0:.1f} | {st.status} |")
            except (SolverFailed, InfeasibleDesign) as exc:
                st = getattr(exc, "stats", None)
                iterations = st.iterations if isinstance(st, SolveStats) else None
                entry.update(iters=np.nan if iterations is None else iterations)
                rows.append(f"| {layout} | {n}x{n} | {ml:.2f} | - | - | - | - | - | - | - | "
                            f"{'-' if iterations is None else iterations} | "
                            f"{time.perf_counter() - t0:.1f} | "
                            f"{type(exc).__name__}: {getattr(exc, 'status', '') or exc} |")
            data.setdefault((layout, n), []).append(entry)
            print(rows[-1], flush=True)
    # plot
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for (layout, n), entries in data.items():
        ml = [e["ml"] for e in entries]
        style = "-" if layout == "zigzag_i" else "--"
        ax1.plot(ml, [100 * e["rms"] for e in entries], "o" + style, label=f"{layout}, {n}x{n}")
        line, = ax2.plot(ml, [e["iters"] for e in entries], "s" + style,
                         label=f"{layout}, {n}x{n}")
        failed = [e for e in entries if not np.isfinite(e["rms"])]
        ax2.plot([e["ml"] for e in failed], [e["iters"] for e in failed], "x", ms=12, mew=2.5,
                 color="k", label="IPOPT failed" if failed and not ax2.lines[:-1] else None)
    ax1.axvline(0.2, color="0.6", ls=":", lw=1)
    ax2.axvline(0.2, color="0.6", ls=":", lw=1)
    ax1.set_xlabel("min_length (smallest side / mean side)")
    ax1.set_ylabel("RMS / diameter [%]")
    ax1.set_title("sphere cap: fit vs side-length bound")
    ax1.set_ylim(bottom=0)
    ax2.set_xlabel("min_length (smallest side / mean side)")
    ax2.set_ylabel("IPOPT iterations")
    ax2.set_title("iterations (x: IPOPT failed, no fit)")
    ax2.set_ylim(bottom=0)
    for a in (ax1, ax2):
        a.grid(alpha=0.3)
        a.legend()
    fig.tight_layout()
    args.out.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out / "min_length_cost.png", dpi=110)
    plt.close(fig)
    md = [
        "# Cost of the side-length constraint (`studies/min_length_cost.py`)",
        "",
        f"- {run.header()} (the load includes this run's own process)",
        f"- targets/sphere_cap.toml, layouts {', '.join(layouts)}, stop_rms=None, default weights "
        f"{base.weights}, min_angle {base.min_angle}, mu_margin {base.mu_margin}; IPOPT "
        f"(sequential, exact Hessian) with a {args.time_limit:.0f} s limit; constraint: every "
        "side >= min_length x mean side (the package default is 0.2; 0.6-0.8 go beyond the "
        "brief); the constraint is active where min side/mean equals min_length",
        "- RMS/diam: aligned coarse lattice vs target lattice; surface RMS and Hausdorff: "
        "distance of the coarse lattice to the target surface; all over the target's diameter"
        f" (a flat sheet: plane RMS {plane:.2f}%)",
        "",
        "| layout | panels | min_length | RMS/diam | surface RMS/diam | Hausdorff/diam | min side/mean "
        "| min sector angle | loss start | loss end | iterations | time [s] | status |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "![fit and iterations against min_length](min_length_cost.png)",
        "",
    ]
    (args.out / "min_length_cost.md").write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
