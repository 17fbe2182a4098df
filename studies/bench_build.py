"""Build time of the simultaneous NLP: CasADi's Hessian of the Lagrangian against the one
assembled around the global variables (:func:`rffqm_nlp.design.transcription.lagrangian_hessian`).

The sphere cap (targets/sphere_cap.toml) at n x n panels: transcription plus
``ca.nlpsol`` with IPOPT (all derivative functions generated), each build in a fresh
subprocess. The baseline is the same NLP without ``hess_lag``, so CasADi colours the whole
Hessian, dense rows of omega and the alignment included.

    python studies/bench_build.py [--sizes 20 40 80] [--out studies/results/bench_build.md]
    python studies/bench_build.py --smoke   (4 x 4 panels, temporary output)
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import casadi as ca

from common import RESULTS, Run, add_smoke, run_child, smoke_dir, target_problem
from rffqm_nlp.design import transcription

METHODS = ("casadi", "assembled")


def child(n: int, method: str) -> dict:
    """Seconds to transcribe the n x n sphere cap (simultaneous) and build its IPOPT solver
    with the exact Hessian: CasADi's own, or the assembled one (as DesignProblem.solve)."""
    prob, options = target_problem("sphere_cap", n)
    start = prob.start()
    t0 = time.perf_counter()
    nlp = prob.transcribe(start, options=options)
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "expand": False}
    if method == "assembled":
        opts["hess_lag"] = transcription.lagrangian_hessian(nlp)
    ca.nlpsol("design", "ipopt", {"x": nlp.x, "f": nlp.objective, "g": nlp.g}, opts)
    return {"n": n, "method": method, "build": time.perf_counter() - t0,
            "variables": nlp.x.numel()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 40, 80])
    ap.add_argument("--out", type=Path, default=RESULTS / "bench_build.md")
    add_smoke(ap)
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.out = [4], smoke_dir("bench_build") / "bench_build.md"
    run = Run()
    rows = []
    for n in args.sizes:
        times = {}
        for method in METHODS:
            r = run_child(__file__, "--child", str(n), method)
            times[method] = r["build"]
        rows.append(f"| {n}x{n} | {r['variables']} | {times['casadi']:.2f} | "
                    f"{times['assembled']:.2f} | {times['casadi'] / times['assembled']:.1f}x |")
        print(rows[-1], flush=True)
    md = ["# Simultaneous NLP build (`studies/bench_build.py`)", "",
          f"- {run.header()}",
          "- build = seconds of transcription + `ca.nlpsol` (IPOPT, exact Hessian), one fresh "
          "subprocess each; 'casadi' = CasADi's own Hessian of the Lagrangian, 'assembled' = "
          "`transcription.lagrangian_hessian` (the default)", "",
          "| panels | variables | build, CasADi Hessian [s] | build, assembled [s] | "
          "speed-up |", "|---|---|---|---|---|", *rows, ""]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        print(json.dumps(child(int(sys.argv[2]), sys.argv[3])))
    else:
        main()
