"""Where a design's time goes: transcription, solver and Hessian, and BLAS threads.

The first table solves the bundled targets with their target files' options and
``stop_rms`` = ``common.STOP_RMS`` (0.9%; the files' own value until 2026-12-01) in each
transcription with IPOPT and the exact or the damped Gauss-Newton Hessian, and with
Levenberg-Marquardt on the marching manifold (simultaneous only; at 20 x 20 panels; at 40 x 40,
and at the ``--large`` sizes, the simultaneous transcription only),
and splits IPOPT's time (its own timing statistics) into the linear solves (factorisation
and back-solves of the KKT system, MUMPS) and the NLP function evaluations (CasADi:
objective, constraints and their derivatives). The simultaneous NLP with IPOPT and the
exact Hessian (the library's default) is the baseline of the speed-up column.

The second table solves the 40 x 40 sphere cap with one and with two OpenBLAS threads
(MUMPS's dense kernels run in CasADi's OpenBLAS) and reports wall time against CPU time.
Each run is a fresh subprocess.

    python studies/solve_cost.py [--large 100] [--out studies/results/solve_cost.md]
    python studies/solve_cost.py --smoke   (the sphere cap at 4 x 4 panels, temporary output)
    python studies/solve_cost.py --child quarter_vase 200 simultaneous gauss-newton 1800
        (one design; prints its row as JSON; the last number is the time limit in s;
        the Hessian "levenberg-marquardt" stands for that solver)
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
from pathlib import Path

from common import (RESULTS, STOP_RMS, TARGETS, Run, add_smoke, fmt, smoke_dir,
                    solve_in_child, write_table)
from rffqm_nlp.design.problem import GAUSS_NEWTON_ITERATIONS, SolveOptions

LM = "levenberg-marquardt"  # in the Hessian column: that solver (then IPOPT, exact, if needed)
CONFIGS = {20: (("simultaneous", "exact"), ("simultaneous", "gauss-newton"),
                ("simultaneous", LM), ("sequential", "exact"), ("sequential", "gauss-newton")),
           40: (("simultaneous", "exact"), ("simultaneous", "gauss-newton"),
                ("simultaneous", LM))}
#: time limit of one solve, by pattern size (larger sizes: LARGE_TIME_LIMIT)
TIME_LIMIT = {20: 120.0, 40: 120.0}
LARGE_TIME_LIMIT = 600.0
#: IPOPT's timing statistics: "<name>.....: cpu (sys: s wall: w)"
TIMING = re.compile(r"^\s*(\w[\w ]*?)\.+:\s+[\d.]+ \(sys:\s+[\d.]+ wall:\s+([\d.]+)\)")


def solve(name: str, n: int, transcription: str, hessian: str,
          time_limit: float | None = None, threads: int | None = None) -> dict:
    """One design in a fresh subprocess, with IPOPT's timing statistics read from its log
    (``time_limit``: seconds, by default :data:`TIME_LIMIT` of the size)."""
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "ipopt.out"
        options = {"transcription": transcription, "solver": LM if hessian == LM else "ipopt",
                   "hessian": "exact" if hessian == LM else hessian, "stop_rms": STOP_RMS,
                   "time_limit": time_limit or TIME_LIMIT.get(n, LARGE_TIME_LIMIT),
                   "trust": True,            # the log file is ours: IPOPT may write it
                   "ipopt_options": {"output_file": str(log), "file_print_level": 6,
                                     "file_append": "yes",  # both runs of a handover
                                     "print_timing_statistics": "yes"}}
        env = None if threads is None else {"OPENBLAS_NUM_THREADS": str(threads)}
        r = solve_in_child(name, n, solve=options, env=env)
        text = log.read_text() if log.exists() else ""  # no IPOPT run, no log
    fit = r["fit"] or {}
    out = {"status": r["status"], "iterations": r["iterations"], "build": r.get("build_time"),
           "rms": fit.get("rms"), "min_side": fit.get("min_side_over_mean"),
           "gauss_newton": r.get("gauss_newton_iterations"), "wall": r["wall"],
           "cpu_user": r["cpu_user"], "cpu_sys": r["cpu_sys"],
           "peak_gb": r["peak_rss_mb"] / 1024}
    timing: dict[str, float] = {}
    for m in filter(None, map(TIMING.match, text.splitlines())):
        timing[m.group(1)] = timing.get(m.group(1), 0.0) + float(m.group(2))
    out["linear"] = timing.get("PDSystemSolverSolveOnce")
    out["functions"] = timing.get("Function Evaluations")
    out["factorizations"] = sum(int(m) for m in re.findall(
        r"Number of trial factorizations performed: (\d+)", text))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=RESULTS / "solve_cost.md")
    ap.add_argument("--large", type=int, nargs="*", default=[],
                    help="also these n x n sizes, simultaneous transcription, every solver "
                         f"({LARGE_TIME_LIMIT:.0f} s limit each)")
    add_smoke(ap)
    args = ap.parse_args()
    run = Run()
    sizes = {**CONFIGS, **{n: CONFIGS[40] for n in args.large}}
    targets, thread_size, thread_counts = TARGETS, 40, (1, 2)
    if args.smoke:
        sizes = {4: (("simultaneous", "exact"),)}
        targets, thread_size, thread_counts = TARGETS[:1], 4, (1,)
        args.out = smoke_dir("solve_cost") / "solve_cost.md"
    rows, totals = [], {}
    for n, configs in sizes.items():
        for name in targets:
            for transcription, hessian in configs:
                r = solve(name, n, transcription, hessian)
                rms = "-" if r["rms"] is None else f"{100 * r['rms']:.2f}%"
                its = "-" if r["iterations"] is None else (
                    f"{r['iterations']}" + (f" ({r['gauss_newton']} GN)"
                                            if hessian == "gauss-newton" else ""))
                rows.append(f"| {n}x{n} | {name} | {transcription} | {hessian} | {its} | "
                            f"{r['factorizations']} | {fmt(r['build'], '.2f')} | "
                            f"{fmt(r['linear'], '.2f')} | {fmt(r['functions'], '.2f')} | "
                            f"{r['wall']:.2f} | {r['status']} | {rms} | "
                            f"{fmt(r['min_side'], '.3f')} |")
                totals.setdefault((n, transcription, hessian), []).append(r["wall"])
                print(rows[-1], flush=True)
    total_rows = [f"| {n}x{n} | {t} | {h} | {sum(w):.1f} | "
                  f"{sum(totals[(n, 'simultaneous', 'exact')]) / sum(w):.2f}x |"
                  for (n, t, h), w in totals.items()]
    thread_rows = []
    for threads in thread_counts:
        r = solve("sphere_cap", thread_size, "simultaneous", "exact", threads=threads)
        thread_rows.append(f"| {threads} | {r['iterations'] or '-'} | {r['wall']:.1f} | "
                           f"{fmt(r['linear'], '.1f')} | {r['cpu_user']:.1f} | "
                           f"{r['cpu_sys']:.1f} | {r['status']} |")
        print(thread_rows[-1], flush=True)
    text = "\n".join([
        "# Where a design's time goes (`studies/solve_cost.py`)", "",
        f"- {run.header()}",
        f"- problem: the bundled targets, their target files' options, stop_rms {STOP_RMS}, "
        f"time limit {TIME_LIMIT[20]:.0f} s ({LARGE_TIME_LIMIT:.0f} s above 40 x 40 "
        f"panels); Gauss-Newton damping {SolveOptions.damping} "
        f"for at most {GAUSS_NEWTON_ITERATIONS} iterations, then exact; one fresh "
        "subprocess per run", "",
        "## Transcription, solver and Hessian", "",
        "Hessian: IPOPT's, or levenberg-marquardt for that solver "
        "(`rffqm_nlp.design.solvers.levenberg_marquardt`; "
        "its sensitivities and QPs count in neither IPOPT column); "
        "iterations: all, in parentheses those with the Gauss-Newton Hessian; build: "
        "transcription and IPOPT solver construction; linear solves and NLP functions: "
        "IPOPT's timing statistics (wall seconds in the KKT solves and in CasADi's "
        "evaluations); wall: seconds of `prob.solve()`", "",
        "| panels | target | transcription | Hessian | iterations | factorisations | "
        "build [s] | linear solves [s] | NLP functions [s] | wall [s] | status | RMS/diam | "
        "min side/mean |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|", *rows, "",
        "| panels | transcription | Hessian | wall over the three targets [s] | speed-up vs "
        "simultaneous, exact |", "|---|---|---|---|---|", *total_rows, "",
        f"## OpenBLAS threads, {thread_size}x{thread_size} sphere cap (simultaneous, exact)",
        "",
        "CPU: user and system seconds of the whole subprocess", "",
        "| threads | iterations | wall [s] | linear solves [s] | CPU user [s] | "
        "CPU system [s] | status |", "|---|---|---|---|---|---|---|", *thread_rows, ""])
    write_table(args.out, text)


if __name__ == "__main__":
    if len(sys.argv) in (6, 7) and sys.argv[1] == "--child":
        print(json.dumps(solve(sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5],
                               *map(float, sys.argv[6:]))))
    else:
        main()
