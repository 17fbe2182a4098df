"""Where a design's time goes: transcription, solver and Hessian, and BLAS threads.

The first table solves the bundled targets with their target files' options (stop_rms
0.9%) in each transcription with IPOPT and the exact or the damped Gauss-Newton Hessian,
and with Levenberg-Marquardt on the marching manifold (simultaneous only; at 20 x 20
panels; at 40 x 40, and at the ``--large`` sizes, the simultaneous transcription only),
and splits IPOPT's time (its own timing statistics) into the linear solves (factorisation
and back-solves of the KKT system, MUMPS) and the NLP function evaluations (CasADi:
objective, constraints and their derivatives). The simultaneous NLP with IPOPT and the
exact Hessian (the library's default) is the baseline of the speed-up column.

The second table solves the 40 x 40 sphere cap with one and with two OpenBLAS threads
(MUMPS's dense kernels run in CasADi's OpenBLAS) and reports wall time against CPU time.
Each run is a fresh subprocess.

    python studies/solve_cost.py [--large 100] [--out studies/results/solve_cost.md]
    python studies/solve_cost.py --child quarter_vase 200 simultaneous gauss-newton 1800
        (one design; prints its row as JSON; the last number is the time limit in s;
        the Hessian "levenberg-marquardt" stands for that solver)
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import casadi as ca

from bench_inverse import fmt
from rffqm_nlp.design import GAUSS_NEWTON_ITERATIONS, DesignProblem

ROOT = Path(__file__).resolve().parent.parent
TARGETS = ("sphere_cap", "hyperboloid", "quarter_vase")
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


def child(name: str, n: int, transcription: str, hessian: str,
          time_limit: float | None = None) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "ipopt.out"
        solver = LM if hessian == LM else "ipopt"
        prob = replace(DesignProblem.load(ROOT / "targets" / f"{name}.toml"),
                       panels=(n, n), transcription=transcription, solver=solver,
                       hessian="exact" if hessian == LM else hessian,
                       time_limit=time_limit or TIME_LIMIT.get(n, LARGE_TIME_LIMIT),
                       ipopt_options={"output_file": str(log), "file_print_level": 6,
                                      "file_append": "yes",  # both runs of a handover
                                      "print_timing_statistics": "yes"})
        t0 = time.perf_counter()
        try:
            res = prob.solve()
            out = {"status": res.stats["status"], "iterations": res.stats["iterations"],
                   "build": res.stats["build_time"], "rms": res.fit["rms"],
                   "min_side": res.fit["min_side_over_mean"],
                   "gauss_newton": res.stats["gauss_newton_iterations"]}
        except Exception as exc:  # a failed run is a result here
            out = {"status": type(exc).__name__, "iterations": None, "build": None,
                   "rms": None, "min_side": None, "gauss_newton": None}
        out["wall"] = time.perf_counter() - t0
        text = log.read_text() if log.exists() else ""  # no IPOPT run, no log
    timing: dict[str, float] = {}
    for m in filter(None, map(TIMING.match, text.splitlines())):
        timing[m.group(1)] = timing.get(m.group(1), 0.0) + float(m.group(2))
    out["linear"] = timing.get("PDSystemSolverSolveOnce")
    out["functions"] = timing.get("Function Evaluations")
    out["factorizations"] = sum(int(m) for m in re.findall(
        r"Number of trial factorizations performed: (\d+)", text))
    usage = resource.getrusage(resource.RUSAGE_SELF)
    out["cpu_user"], out["cpu_sys"] = usage.ru_utime, usage.ru_stime
    out["peak_gb"] = usage.ru_maxrss / 2 ** 20  # kB on Linux
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "studies" / "results" / "solve_cost.md")
    ap.add_argument("--large", type=int, nargs="*", default=[],
                    help="also these n x n sizes, simultaneous transcription, every solver "
                         f"({LARGE_TIME_LIMIT:.0f} s limit each)")
    args = ap.parse_args()
    t0, load0 = time.perf_counter(), os.getloadavg()[0]

    def run(*argv: str, threads: int | None = None) -> dict:
        env = dict(os.environ)
        if threads is not None:
            env["OPENBLAS_NUM_THREADS"] = str(threads)
        proc = subprocess.run([sys.executable, __file__, "--child", *argv], capture_output=True,
                              text=True, check=True, cwd=ROOT, env=env)
        return json.loads(proc.stdout.strip().splitlines()[-1])

    rows, totals = [], {}
    sizes = {**CONFIGS, **{n: CONFIGS[40] for n in args.large}}
    for n, configs in sizes.items():
        for name in TARGETS:
            for transcription, hessian in configs:
                r = run(name, str(n), transcription, hessian)
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
    for threads in (1, 2):
        r = run("sphere_cap", "40", "simultaneous", "exact", threads=threads)
        thread_rows.append(f"| {threads} | {r['iterations'] or '-'} | {r['wall']:.1f} | "
                           f"{fmt(r['linear'], '.1f')} | {r['cpu_user']:.1f} | "
                           f"{r['cpu_sys']:.1f} | {r['status']} |")
        print(thread_rows[-1], flush=True)
    text = "\n".join([
        "# Where a design's time goes (`studies/solve_cost.py`)", "",
        f"- date {time.strftime('%Y-%m-%dT%H:%M')}; {platform.machine()}, {os.cpu_count()} "
        f"CPUs; CasADi {ca.__version__}; load average (1 min) {load0:.1f} at start, "
        f"{os.getloadavg()[0]:.1f} at end; whole run {time.perf_counter() - t0:.0f} s",
        "- problem: the bundled targets, their target files' options (stop_rms 0.9%), "
        f"time limit {TIME_LIMIT[20]:.0f} s ({LARGE_TIME_LIMIT:.0f} s above 40 x 40 "
        f"panels); Gauss-Newton damping {DesignProblem.damping} "
        f"for at most {GAUSS_NEWTON_ITERATIONS} iterations, then exact; one fresh "
        "subprocess per run", "",
        "## Transcription, solver and Hessian", "",
        "Hessian: IPOPT's, or levenberg-marquardt for that solver (`rffqm_nlp.reduced`; "
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
        "## OpenBLAS threads, 40x40 sphere cap (simultaneous, exact)", "",
        "CPU: user and system seconds of the whole subprocess", "",
        "| threads | iterations | wall [s] | linear solves [s] | CPU user [s] | "
        "CPU system [s] | status |", "|---|---|---|---|---|---|---|", *thread_rows, ""])
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    if len(sys.argv) in (6, 7) and sys.argv[1] == "--child":
        print(json.dumps(child(sys.argv[2], int(sys.argv[3]), sys.argv[4], sys.argv[5],
                               *map(float, sys.argv[6:]))))
    else:
        main()
