"""Scaling of the transcriptions and solvers: time, iterations and peak memory against size.

A bundled target (``--target``, default the sphere cap; its target file's options, with
IPOPT and the exact Hessian unless ``--hessian`` says otherwise) at n x n panels, run to
IPOPT's tolerance (stop_rms=None) or, with ``--stop-rms``, until a re-marched iterate fits
that well (``--stop-rms 0.009``: ``common.STOP_RMS``, the target files' own value until
2026-12-01). Two methods per
size: the sequential and the simultaneous transcription with IPOPT, or, with ``--solver
levenberg-marquardt``, IPOPT and Levenberg-Marquardt on the marching manifold, both on the
simultaneous NLP. ``--simultaneous-only`` sizes run the second method only. Each run is
``DesignProblem.solve()`` in a fresh subprocess (``common.solve_in_child``) so its time
and peak memory are its own. Runs above ``--limit-from`` panels get a wall-time limit of
``--time-limit`` seconds; a run that hits it is reported with its status, not dropped. The
ratio column compares the second method with the first at the same size in the same run.

    python studies/bench_scaling.py [--sizes 10 20 40] [--simultaneous-only 100]
        [--stop-rms 0.009] [--out studies/results/bench_scaling_stop.md]
    python studies/bench_scaling.py --target quarter_vase --hessian gauss-newton
        --sizes 10 20 --simultaneous-only 40 100 200 --stop-rms 0.009 --time-limit 1800
        --out studies/results/bench_scaling_vase.md
    python studies/bench_scaling.py --solver levenberg-marquardt --sizes 10 20 40 100
        --simultaneous-only 200 --stop-rms 0.009 --time-limit 3600
        --out studies/results/bench_scaling_lm.md
    python studies/bench_scaling.py --smoke   (4 x 4 panels, temporary output)
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from common import RESULTS, ROOT, Run, add_smoke, fmt, smoke_dir, solve_in_child
from rffqm_nlp.design.problem import HESSIANS, SOLVERS

TARGET = "sphere_cap"
LAYOUT = "zigzag_i"


def label(transcription: str, solver: str) -> str:
    return transcription if solver == "ipopt" else f"{transcription}, {solver}"


def row(r: dict, ratio: str) -> str:
    fit = r.get("fit") or {}
    rms = f"{100 * fit['rms']:.2f}%" if "rms" in fit else "-"
    return (f"| {r['n']}x{r['n']} | {label(r['transcription'], r['solver'])} | "
            f"{r['wall']:.1f} | "
            f"{fmt(r.get('build_time'), '.1f')} | {r['iterations']} | {r['status']} | "
            f"{fmt(r.get('objective'), '.6g')} | {rms} | {r['peak_rss_mb']:.0f} | {ratio} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[10, 20, 40])
    ap.add_argument("--simultaneous-only", type=int, nargs="*", default=[100])
    ap.add_argument("--time-limit", type=float, default=300.0)
    ap.add_argument("--limit-from", type=int, default=40)
    ap.add_argument("--stop-rms", type=float, default=None)
    ap.add_argument("--target", default=TARGET,
                    choices=sorted(p.stem for p in (ROOT / "targets").glob("*.toml")))
    ap.add_argument("--hessian", default="exact", choices=HESSIANS)
    ap.add_argument("--solver", default="ipopt", choices=SOLVERS)
    ap.add_argument("--out", type=Path, default=RESULTS / "bench_scaling.md")
    add_smoke(ap)
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.simultaneous_only = [4], []
        args.out = smoke_dir("bench_scaling") / "bench_scaling.md"
    run = Run()
    rows = []
    methods = ((("sequential", "ipopt"), ("simultaneous", "ipopt")) if args.solver == "ipopt"
               else (("simultaneous", "ipopt"), ("simultaneous", args.solver)))
    runs = [(n, m) for n in args.sizes for m in methods]
    runs += [(n, methods[1]) for n in args.simultaneous_only]
    wall: dict[int, float] = {}
    for n, (tr, solver) in runs:
        limit = args.time_limit if n >= args.limit_from else None
        print(f"== {n}x{n} {label(tr, solver)} (time limit {limit}) ...", flush=True)
        try:
            r = solve_in_child(args.target, n, {"layout": LAYOUT},
                               {"transcription": tr, "time_limit": limit,
                                "stop_rms": args.stop_rms, "hessian": args.hessian,
                                "solver": solver})
        except RuntimeError as exc:  # the child failed outside the solver (see its stderr)
            rows.append(f"| {n}x{n} | {label(tr, solver)} | failed: "
                        f"{str(exc).splitlines()[-1][:200]} |")
            print(rows[-1], flush=True)
            continue
        ok, second = r["success"], (tr, solver) == methods[1]
        if not second and ok:
            wall[n] = r["wall"]
        ratio = f"{wall[n] / r['wall']:.2f}x" if second and ok and n in wall else "-"
        rows.append(row(r, ratio))
        print(rows[-1], flush=True)
    md = [
        "# Transcription scaling (`studies/bench_scaling.py`)",
        "",
        f"- {run.header()}",
        f"- problem: targets/{args.target}.toml at n x n panels, stop_rms={args.stop_rms}, "
        f"the target file's other options, hessian={args.hessian!r} (IPOPT) "
        "(sequential: SX derivatives up to 12 x 12 panels, MX above; "
        "simultaneous: MX); one fresh subprocess per run",
        f"- wall-time limit {args.time_limit:.0f} s for n >= {args.limit_from}; "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')} (BLAS threads of MUMPS)",
        "- wall = seconds of `prob.solve()` (start, build, solve, NumPy re-march, fit); "
        f"peak RSS = VmHWM of the run's own process; speed-up = {label(*methods[0])} wall / "
        f"{label(*methods[1])} wall at the same size",
        "",
        "| panels | method | wall [s] | build [s] | iterations | status | objective "
        f"| RMS/diam | peak RSS [MB] | speed-up vs {label(*methods[0])} |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
