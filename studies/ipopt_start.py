"""How IPOPT's start options steer the simultaneous design NLP (`ipopt_options`).

IPOPT estimates the initial constraint multipliers by least squares from the objective
gradient and the bound multipliers, which it starts at ``bound_mult_init_val`` = 1. The
design loss has gradients of about 1e-2, so these bound multipliers dominate the estimate:
its largest equality multiplier is far above the one of a least-squares fit of the gradient
alone (the first table). The constraint curvature they weight makes the Hessian need a
large perturbation at the first iteration, which IPOPT then divides by 3 per iteration,
trying no perturbation first each time: steps stay damped for about ten iterations and
most iterations factorise the KKT system twice.

The second table solves the bundled targets with IPOPT's defaults and with the start
options that avoid this, counting factorisations from IPOPT's own output. Each run is a
fresh subprocess; stop_rms is ``common.STOP_RMS`` (0.9%; the target files' own value until
2026-12-01).

    python studies/ipopt_start.py [--sizes 20 40] [--out studies/results/ipopt_start.md]
    python studies/ipopt_start.py --smoke   (the sphere cap at 4 x 4, temporary output)
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import casadi as ca
import numpy as np

from common import (RESULTS, STOP_RMS, TARGETS, Run, add_smoke, run_child, smoke_dir,
                    solve_in_child, target_problem, write_table)

CONFIGS = {"IPOPT defaults": {}, "bound_mult_init_val 0.01": {"bound_mult_init_val": 0.01},
           "bound_mult_init_method mu-based": {"bound_mult_init_method": "mu-based"}}
#: one row of IPOPT's iteration table: iter, objective, inf_pr, inf_du, lg(mu), ||d||, lg(rg)
ITERATION = re.compile(r"^\s*(\d+)r?\s+\S+\s+\S+\s+\S+\s+\S+\s+\S+\s+(\S+)\s")


#: the solve options of every run but its ipopt_options
SOLVE = {"hessian": "exact", "solver": "ipopt", "stop_rms": STOP_RMS}


def initial_multipliers(name: str, n: int, config: str) -> dict:
    """Largest equality multiplier of IPOPT's start (max_iter = 0) and of the least-squares
    fit of the objective gradient alone."""
    from scipy.sparse.linalg import lsqr

    from rffqm_nlp.design import transcription

    prob, options = target_problem(name, n)
    options = replace(options, **SOLVE, ipopt_options=CONFIGS[config])
    nlp = prob.transcribe(options=options)
    opts = {"ipopt.max_iter": 0, "ipopt.print_level": 0, "print_time": False,
            "ipopt.sb": "yes", "ipopt.mu_strategy": "adaptive",
            "hess_lag": transcription.lagrangian_hessian(nlp),
            **{f"ipopt.{k}": v for k, v in options.ipopt_options.items()}}
    solver = ca.nlpsol("start", "ipopt", {"x": nlp.x, "f": nlp.objective, "g": nlp.g}, opts)
    sol = solver(x0=nlp.x0, lbx=nlp.lbx, ubx=nlp.ubx, lbg=nlp.lbg, ubg=nlp.ubg)
    eq = nlp.lbg == nlp.ubg
    free = nlp.lbx < nlp.ubx
    J, grad = ca.Function("d", [nlp.x], [ca.jacobian(nlp.g, nlp.x),
                                         ca.gradient(nlp.objective, nlp.x)])(nlp.x0)
    A = J.sparse().tocsr()[eq][:, free].T
    lam = lsqr(A, -grad.full().ravel()[free], atol=1e-12, btol=1e-12)[0]
    return {"ipopt": float(np.abs(sol["lam_g"].full().ravel()[eq]).max()),
            "gradient": float(np.abs(lam).max())}


def solve(name: str, n: int, config: str) -> dict:
    """One design in a fresh subprocess, IPOPT's factorisations read from its log."""
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "ipopt.out"
        r = solve_in_child(name, n, solve={**SOLVE, "trust": True, "ipopt_options": {
            **CONFIGS[config], "output_file": str(log), "file_print_level": 6}})
        out = {"status": r["status"], "iterations": r["iterations"],
               "rms": (r["fit"] or {}).get("rms"), "wall": r["wall"]}
        text = log.read_text() if log.exists() else ""  # no IPOPT run, no log
    out["factorizations"] = sum(int(m) for m in re.findall(
        r"Number of trial factorizations performed: (\d+)", text))
    regularization = {int(m.group(1)): m.group(2) for line in text.splitlines()
                      if (m := ITERATION.match(line))}
    out["first_regularization"] = regularization.get(1, "-")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 40])
    ap.add_argument("--out", type=Path, default=RESULTS / "ipopt_start.md")
    add_smoke(ap)
    args = ap.parse_args()
    targets, configs = TARGETS, list(CONFIGS)
    if args.smoke:
        args.sizes, targets, configs = [4], TARGETS[:1], configs[:1]
        args.out = smoke_dir("ipopt_start") / "ipopt_start.md"
    run = Run()
    lam_rows = []
    for name in targets:
        for config in configs:
            r = run_child(__file__, "--multipliers", name, str(args.sizes[0]), config)
            lam_rows.append(f"| {name} | {config} | {r['ipopt']:.3g} | {r['gradient']:.3g} |")
            print(lam_rows[-1], flush=True)
    rows, totals = [], {}
    for n in args.sizes:
        for name in targets:
            for config in configs:
                r = solve(name, n, config)
                rms = "-" if r["rms"] is None else f"{100 * r['rms']:.2f}%"
                rows.append(f"| {n}x{n} | {name} | {config} | {r['iterations'] or '-'} | "
                            f"{r['factorizations']} | {r['first_regularization']} | "
                            f"{r['wall']:.1f} | {r['status']} | {rms} |")
                t = totals.setdefault((n, config), [0, 0.0])
                t[0] += r["factorizations"]
                t[1] += r["wall"]
                print(rows[-1], flush=True)
    base = {n: totals[(n, "IPOPT defaults")] for n in args.sizes}
    total_rows = [f"| {n}x{n} | {config} | {f} | {w:.1f} | {base[n][1] / w:.2f}x |"
                  for (n, config), (f, w) in totals.items()]
    text = "\n".join([
        "# IPOPT start options on the simultaneous NLP (`studies/ipopt_start.py`)", "",
        f"- {run.header()}",
        "- problem: the bundled targets at n x n panels, their target files' options "
        f"(stop_rms {STOP_RMS}), exact Hessian; `ipopt_options` as named, one fresh subprocess "
        "per run", "",
        f"## Largest equality multiplier at IPOPT's start ({args.sizes[0]}x{args.sizes[0]})",
        "", "| target | options | IPOPT's estimate | least squares of the objective gradient |",
        "|---|---|---|---|", *lam_rows, "",
        "## Solves", "",
        "factorisations: IPOPT's trial factorisations of the KKT system, summed over the "
        "run; lg(rg) at iteration 1: log10 of the Hessian perturbation of the first step; "
        "wall: seconds of `prob.solve()`", "",
        "| panels | target | options | iterations | factorisations | lg(rg) at it. 1 | "
        "wall [s] | status | RMS/diam |", "|---|---|---|---|---|---|---|---|---|", *rows, "",
        "## Totals over the three targets", "",
        "| panels | options | factorisations | wall [s] | speed-up vs defaults |",
        "|---|---|---|---|---|", *total_rows, ""])
    write_table(args.out, text)


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--multipliers":
        print(json.dumps(initial_multipliers(sys.argv[2], int(sys.argv[3]), sys.argv[4])))
    else:
        main()
