"""Scaling of the two transcriptions: time, iterations and peak memory against pattern size.

A bundled target (``--target``, default the sphere cap; its target file's options, with the
exact Hessian unless ``--hessian`` says otherwise) at n x n panels, run to IPOPT's
tolerance (stop_rms=None) or, with ``--stop-rms``, until a re-marched iterate fits that
well (the target files' 0.9% is what the README's main job uses),
each (size, transcription) solved by ``DesignProblem.solve()`` in a fresh subprocess
(``bench_inverse.run_child``) so its time and peak memory are its own. Runs above
``--limit-from`` panels get an IPOPT wall-time limit of ``--time-limit`` seconds; a run that
hits it is reported with its status, not dropped. The ratio column compares each
simultaneous run with the sequential run of the same size in the same run of this script.

    python studies/bench_scaling.py [--sizes 10 20 40] [--simultaneous-only 100]
        [--stop-rms 0.009] [--out studies/results/bench_scaling_stop.md]
    python studies/bench_scaling.py --target quarter_vase --hessian gauss-newton
        --sizes 10 20 --simultaneous-only 40 100 200 --stop-rms 0.009 --time-limit 1800
        --out studies/results/bench_scaling_vase.md
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import casadi as ca
import numpy as np

from bench_inverse import TARGET, run_child
from rffqm_nlp.design import HESSIANS

ROOT = Path(__file__).resolve().parent.parent


def row(r: dict, ratio: str) -> str:
    fit = r.get("fit") or {}
    rms = f"{100 * fit['rms']:.2f}%" if "rms" in fit else "-"
    return (f"| {r['n']}x{r['n']} | {r['transcription']} | {r['wall']:.1f} | "
            f"{r['build_time']:.1f} | {r['iterations']} | {r['status']} | "
            f"{r['objective']:.6g} | {rms} | {r['peak_rss_mb']:.0f} | {ratio} |")


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
    ap.add_argument("--out", type=Path,
                    default=ROOT / "studies" / "results" / "bench_scaling.md")
    args = ap.parse_args()
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    rows = []
    runs = [(n, tr) for n in args.sizes for tr in ("sequential", "simultaneous")]
    runs += [(n, "simultaneous") for n in args.simultaneous_only]
    wall: dict[int, float] = {}
    for n, tr in runs:
        limit = args.time_limit if n >= args.limit_from else None
        print(f"== {n}x{n} {tr} (time limit {limit}) ...", flush=True)
        try:
            r = run_child(n, tr, time_limit=limit, stop_rms=args.stop_rms,
                          target=args.target, hessian=args.hessian)
        except RuntimeError as exc:  # the child failed outside IPOPT (error in its stderr)
            rows.append(f"| {n}x{n} | {tr} | failed: {str(exc).splitlines()[-1][:200]} |")
            print(rows[-1], flush=True)
            continue
        ok = r["success"]
        if tr == "sequential" and ok:
            wall[n] = r["wall"]
        ratio = (f"{wall[n] / r['wall']:.2f}x" if tr == "simultaneous" and ok and n in wall
                 else "-")
        rows.append(row(r, ratio))
        print(rows[-1], flush=True)
    md = [
        "# Transcription scaling (`studies/bench_scaling.py`)",
        "",
        f"- date {time.strftime('%Y-%m-%dT%H:%M')}; {platform.machine()}, {os.cpu_count()} CPUs; "
        f"NumPy {np.__version__}, CasADi {ca.__version__}; load average (1 min) {load0:.1f} at "
        f"start, {os.getloadavg()[0]:.1f} at end; whole run {time.perf_counter() - t0:.0f} s",
        f"- problem: targets/{args.target}.toml at n x n panels, stop_rms={args.stop_rms}, "
        f"the target file's other options, hessian={args.hessian!r} "
        "(sequential: SX derivatives up to 12 x 12 panels, MX above; "
        "simultaneous: MX); one fresh subprocess per run",
        f"- IPOPT wall-time limit {args.time_limit:.0f} s for n >= {args.limit_from}; "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')} (BLAS threads of MUMPS)",
        "- wall = seconds of `prob.solve()` (start, build, solve, NumPy re-march, fit); "
        "peak RSS = VmHWM of the run's own process; speed-up = sequential wall / "
        "simultaneous wall at the same size",
        "",
        "| panels | transcription | wall [s] | build [s] | iterations | status | objective "
        "| RMS/diam | peak RSS [MB] | speed-up vs sequential |",
        "|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
    ]
    args.out.write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
