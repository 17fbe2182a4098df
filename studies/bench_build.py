"""Build time of the simultaneous NLP: CasADi's Hessian of the Lagrangian against the one
assembled around the global variables (:func:`rffqm_nlp.transcription.lagrangian_hessian`).

The sphere cap (targets/sphere_cap.toml) at n x n panels: transcription plus
``ca.nlpsol`` with IPOPT (all derivative functions generated), each build in a fresh
subprocess. The baseline is the same NLP without ``hess_lag``, so CasADi colours the whole
Hessian, dense rows of omega and the alignment included.

    python studies/bench_build.py [--sizes 20 40 80] [--out studies/results/bench_build.md]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import casadi as ca

ROOT = Path(__file__).resolve().parent.parent
METHODS = ("casadi", "assembled")


def child(n: int, method: str) -> dict:
    import rffqm_nlp as rq

    prob = replace(rq.DesignProblem.load(ROOT / "targets" / "sphere_cap.toml"), panels=(n, n))
    start = prob.start()
    t0 = time.perf_counter()
    nlp = prob.transcribe(start)
    if method == "casadi":
        nlp.parts = None  # no hess_lag: CasADi builds the Hessian itself
    prob._solver(nlp, start, {"iter": [], "objective": [], "inf_pr": [], "elapsed": []},
                 None, False, hessian="exact", max_iter=prob.max_iter)
    return {"n": n, "method": method, "build": time.perf_counter() - t0,
            "variables": nlp.x.numel()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 40, 80])
    ap.add_argument("--out", type=Path, default=ROOT / "studies" / "results" / "bench_build.md")
    args = ap.parse_args()
    t0, load0 = time.perf_counter(), os.getloadavg()[0]
    rows = []
    for n in args.sizes:
        times = {}
        for method in METHODS:
            proc = subprocess.run([sys.executable, __file__, "--child", str(n), method],
                                  capture_output=True, text=True, check=True, cwd=ROOT)
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            times[method] = r["build"]
        rows.append(f"| {n}x{n} | {r['variables']} | {times['casadi']:.2f} | "
                    f"{times['assembled']:.2f} | {times['casadi'] / times['assembled']:.1f}x |")
        print(rows[-1], flush=True)
    md = ["# Simultaneous NLP build (`studies/bench_build.py`)", "",
          f"- date {time.strftime('%Y-%m-%dT%H:%M')}; {platform.machine()}, "
          f"{os.cpu_count()} CPUs; CasADi {ca.__version__}; load average (1 min) {load0:.1f} "
          f"at start, {os.getloadavg()[0]:.1f} at end; whole run "
          f"{time.perf_counter() - t0:.0f} s",
          "- build = seconds of transcription + `ca.nlpsol` (IPOPT, exact Hessian), one fresh "
          "subprocess each; 'casadi' = CasADi's own Hessian of the Lagrangian, 'assembled' = "
          "`transcription.lagrangian_hessian` (the default)", "",
          "| panels | variables | build, CasADi Hessian [s] | build, assembled [s] | "
          "speed-up |", "|---|---|---|---|---|", *rows, ""]
    args.out.write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(int(sys.argv[2]), sys.argv[3])))
    else:
        main()
