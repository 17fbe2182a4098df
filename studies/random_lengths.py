"""The paper's Fig. Random: side lengths for randomly perturbed Miura angles, LP against NLP.

Boundary angles of a Miura-ori (alpha0 = 1.2, zig-zag along j) are perturbed by
U(-0.05 pi, 0.05 pi) (``rq.perturb_angles``), the mountain-valley signs kept. For the fixed
marched angles the side lengths come from

* ``LP``       the paper's linear program eq:linearP (``side_length_lp``, eps = 1e-2);
* ``max_min``  an LP (HiGHS): maximise the smallest side at mean side 1
  (``side_length_nlp``; IPOPT solved it before 2026-12-02);
* ``uniform``  IPOPT: minimise the variance of log side lengths (``side_length_nlp``);
* ``uniform>=t*/2``  the same with every side >= half the max-min optimum t* (``min_length``),
  a compromise between the two (table only).

Columns: min/mean, max/mean, max/min over all edges; sd(log) = standard deviation of the log
side lengths (the "uniform" objective is its square); "panel AR" = the smallest panel aspect
ratio, a panel's aspect ratio being its shortest over its longest side (1 for a rhombus, -> 0
for a degenerate panel). Patterns that admit no positive lengths (the LP is infeasible) are
listed as infeasible. Writes ``random_lengths.md`` and ``random_lengths.png`` (the three
crease patterns of one seed, M red, V blue, at omega = 1).

    python studies/random_lengths.py [--seeds 6] [--big-seeds 8] [--figure-seed 1]
    python studies/random_lengths.py --smoke   (one 10 x 10 seed, temporary output)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import rffqm_nlp as rq  # noqa: E402
from common import RESULTS, Run, add_smoke, smoke_dir  # noqa: E402
from rffqm_nlp.errors import InfeasibleDesign, MarchingError  # noqa: E402
from rffqm_nlp.model.lengths import length_spread, side_length_lp, side_length_nlp  # noqa: E402
from rffqm_nlp.model.marching import march  # noqa: E402
from rffqm_nlp.show.pictures import plot_crease_pattern  # noqa: E402

AMPLITUDE = 0.05 * np.pi
METHODS = ("LP", "max_min", "uniform", "uniform>=t*/2")
DRAWN = ("LP", "max_min", "uniform")
COLUMNS = ("panels", "seed", "method", "min/mean", "max/mean", "max/min", "sd(log)",
           "panel AR", "time [s]")


def fig_random(n: int, seed: int) -> rq.BoundaryData:
    return rq.perturb_angles(rq.miura_boundary(n, n), AMPLITUDE, seed)


def lengths(bd: rq.BoundaryData, method: str, t_star: float | None) -> rq.BoundaryData:
    if method == "LP":
        return side_length_lp(bd)
    if method == "uniform>=t*/2":
        return side_length_nlp(bd, "uniform", min_length=0.5 * t_star).boundary
    return side_length_nlp(bd, method).boundary


def normalised(pat: rq.Pattern) -> rq.Pattern:
    """The same pattern re-marched with lengths scaled to mean side 1 (the LP's are ~eps)."""
    scale = pat.side_lengths.mean()
    return march(pat.boundary.with_lengths(pat.boundary.lengths / scale))


def panel_aspect_ratios(pat: rq.Pattern) -> np.ndarray:
    """Shortest over longest side of every panel, (N, M)."""
    sides = np.stack([pat.lv[:, :-1], pat.lh[:-1, :], pat.lh[1:, :], pat.lv[:, 1:]])
    return sides.min(axis=0) / sides.max(axis=0)


def metrics(pat: rq.Pattern) -> dict[str, float]:
    spread = length_spread(pat.lh, pat.lv)
    return {"min/mean": spread["min_over_mean"], "max/mean": spread["max_over_mean"],
            "max/min": spread["max_over_min"], "sd(log)": float(np.std(np.log(pat.side_lengths))),
            "panel AR": float(panel_aspect_ratios(pat).min())}


def run(sizes_seeds: list[tuple[int, int]]) -> tuple[list[dict], dict]:
    rows, patterns = [], {}
    for n, seed in sizes_seeds:
        bd = fig_random(n, seed)
        t_star = None
        for method in METHODS:
            row = {"panels": f"{n}x{n}", "seed": seed, "method": method}
            t0 = time.perf_counter()
            try:
                pat = normalised(march(lengths(bd, method, t_star)))
            except InfeasibleDesign:
                row["status"] = "infeasible (no positive lengths)"
            except MarchingError as exc:
                row["status"] = f"angles fail the {exc.check} check at panel {exc.panel}"
            else:
                row.update(metrics(pat))
                if method == "max_min":
                    t_star = row["min/mean"]
                patterns[(n, seed, method)] = pat
            row["time [s]"] = time.perf_counter() - t0
            rows.append(row)
            if "status" in row:
                break  # the same angles fail for every method
    return rows, patterns


def fmt(row: dict, key: str) -> str:
    val = row.get(key, "")
    if isinstance(val, float):
        return f"{val:.2f}" if key == "time [s]" else f"{val:.3g}"
    return str(val)


def table_lines(rows: list[dict]) -> list[str]:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for row in rows:
        if "status" in row:
            cells = [fmt(row, "panels"), fmt(row, "seed"), "all", row["status"], "", "", "",
                     "", fmt(row, "time [s]")]
        else:
            cells = [fmt(row, k) for k in COLUMNS]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def summary_lines(rows: list[dict]) -> list[str]:
    """Medians over the feasible seeds of each size and method."""
    out = ["| panels | method | feasible seeds | median min/mean | median max/min | "
           "median sd(log) | median panel AR |", "|---|---|---|---|---|---|---|"]
    for size in dict.fromkeys(r["panels"] for r in rows):
        total = len({r["seed"] for r in rows if r["panels"] == size})
        for method in METHODS:
            ok = [r for r in rows if r["panels"] == size and r["method"] == method
                  and "status" not in r]
            if not ok:
                continue
            med = {k: np.median([r[k] for r in ok])
                   for k in ("min/mean", "max/min", "sd(log)", "panel AR")}
            out.append(f"| {size} | {method} | {len(ok)}/{total} | {med['min/mean']:.3g} | "
                       f"{med['max/min']:.3g} | {med['sd(log)']:.3g} | {med['panel AR']:.3g} |")
    return out


def figure(patterns: dict, n: int, seed: int, path: Path) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 5.6))
    titles = {"LP": "LP (eq:linearP)", "max_min": "NLP max-min", "uniform": "NLP uniform"}
    for ax, method in zip(axes, DRAWN):
        pat = patterns[(n, seed, method)]
        plot_crease_pattern(pat, omega=1.0, ax=ax, legend=method == DRAWN[-1])
        m = metrics(pat)
        ax.set_title(f"{titles[method]}\nmin/mean {m['min/mean']:.3g}, max/min "
                     f"{m['max/min']:.3g}, panel AR {m['panel AR']:.2f}", fontsize=11)
    fig.suptitle(f"Fig. Random, {n}x{n} panels, seed {seed}: Miura angles perturbed by "
                 "U(+-0.05 pi); each pattern scaled to mean side 1", fontsize=12)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=6, help="seeds 0..k-1 at 10x10")
    ap.add_argument("--big-seeds", type=int, default=8, help="seeds 0..k-1 at 20x20")
    ap.add_argument("--figure-seed", type=int, default=1, help="10x10 seed drawn in the PNG")
    ap.add_argument("--out", type=Path, default=RESULTS)
    add_smoke(ap)
    args = ap.parse_args()
    if args.smoke:
        args.seeds, args.big_seeds, args.figure_seed = 1, 0, 0
        args.out = smoke_dir("random_lengths")
    clock = Run()
    cases = [(10, s) for s in range(args.seeds)] + [(20, s) for s in range(args.big_seeds)]
    if args.figure_seed >= args.seeds:
        cases.append((10, args.figure_seed))
    rows, patterns = run(cases)
    lines = table_lines(rows)
    summary = summary_lines(rows)
    print("\n".join(lines))
    print()
    print("\n".join(summary))
    args.out.mkdir(parents=True, exist_ok=True)
    md = args.out / "random_lengths.md"
    md.write_text(
        "# Fig. Random: side lengths from the LP (eq:linearP) and from IPOPT\n\n"
        f"Generated by `studies/random_lengths.py`; {clock.header()}.\n\n"
        "Miura boundary angles (alpha0 = 1.2) "
        "perturbed by U(-0.05 pi, 0.05 pi); lengths normalised to mean side 1. "
        "min/mean, max/mean, max/min over all edges; sd(log) = standard deviation of log "
        "side lengths; panel AR = smallest panel aspect ratio (a panel's shortest over its "
        "longest side). uniform>=t*/2: the uniform objective with every side at least half the "
        "max-min optimum.\n\n" + "\n".join(lines) + "\n\n## Medians over the feasible seeds\n\n"
        + "\n".join(summary) + "\n")
    png = args.out / "random_lengths.png"
    figure(patterns, 10, args.figure_seed, png)
    print(f"\nwrote {md} and {png}")


if __name__ == "__main__":
    main()
