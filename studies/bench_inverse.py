"""Inverse-design benchmark: IPOPT with exact derivatives against L-BFGS-B with finite
differences on the same loss, and the sequential against the simultaneous transcription.

Part A (same problem, same start, same loss): the sphere cap (targets/sphere_cap.toml) at
8x8 and 12x12 panels, stop_rms=None, the target lattice fixed (``correspondence =
"lattice"``: the loss the NumPy objective below states).

* IPOPT: the package's ``DesignProblem.solve()`` (sequential transcription, exact Hessian,
  inline constraints), run in a fresh subprocess per case so that its peak memory and time
  are its own.
* L-BFGS-B: ``scipy.optimize.minimize(method="L-BFGS-B")`` with 2-point finite-difference
  gradients on a NumPy objective of the same loss, written here from the package's NumPy
  forward model (numpy_model.march + fold, coarse-graining, fundamental forms, aligned
  positions, quaternion normalisation, Tikhonov term). Bounds: the NLP's lbx/ubx (boundary
  angles, lengths, omega); the inequality constraints (every sector angle, the multiplier
  margins, the sides against the mean side) are dropped. A marching failure (or invalid
  boundary data) inside the objective returns LARGE. Time budget per case: --budget s.

The NumPy objective is checked against the CasADi one, 0.5 * sumsqr(nlp.residuals), at the
start and at IPOPT's answer (relative difference must be <= 1e-10).

Part B: sequential vs simultaneous transcription at 8x8 and 12x12 (time, iterations,
status, peak RSS of the subprocess).

Part C: IPOPT (sequential) alone at 20x20 (--ipopt-only), in the part B table.

    python studies/bench_inverse.py [--sizes 8 12] [--budget 120] [--ipopt-only 20]
    python studies/bench_inverse.py --smoke   (4 x 4 panels, a 1 s budget, temporary output)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import casadi as ca
import numpy as np
from scipy.optimize import minimize

from common import RESULTS, Run, add_smoke, fmt, smoke_dir, solve_in_child, target_problem
from rffqm_nlp.model import numpy_model
from rffqm_nlp.targets import shape
from rffqm_nlp.model.boundary import BoundaryData
from rffqm_nlp.design.problem import DesignProblem, SolveOptions
from rffqm_nlp.errors import RffqmError

TARGET = "sphere_cap"  # a bundled target file, targets/<TARGET>.toml
LARGE = 1e6  # objective value of a boundary vector that does not march
FEASIBLE = 1e-9  # constraint violation of a feasible IPOPT iterate (design._IterationLog)
LAYOUT = "zigzag_i"  # pinned (the package default and the bundled targets' since 945512b)
#: Part A compares the sequential NLP with IPOPT and the exact Hessian, to its tolerance
SOLVE = {"solver": "ipopt", "transcription": "sequential", "hessian": "exact",
         "stop_rms": None}


#: the target lattice fixed, as in the NumPy objective (its loss has no free correspondence)
DESIGN = {"correspondence": "lattice"}


def problem(n: int, layout: str) -> DesignProblem:
    return target_problem(TARGET, n, layout=layout, **DESIGN)[0]


def run_ipopt(n: int, layout: str, transcription: str = "sequential", **solve) -> dict:
    """One IPOPT solve of the n x n sphere cap in a fresh subprocess."""
    return solve_in_child(TARGET, n, {"layout": layout, **DESIGN},
                          {**SOLVE, "transcription": transcription, **solve})


# ------------------------------------------------------------------ the NumPy objective
class NumpyLoss:
    """0.5 |residuals|^2 of transcription.sequential, from the NumPy forward model.

    x = (alphas, betas (left then bottom), lengths, omega, quaternion (w,x,y,z), t)."""

    def __init__(self, prob: DesignProblem):
        st = prob.start()
        self.prob, self.start = prob, st
        self.n2, self.m2 = 2 * prob.N, 2 * prob.M
        self.sigma = st.boundary.sigma
        self.ref = np.concatenate([st.boundary.to_vector(), [st.omega]])
        nl = self.n2 + self.m2
        self.nb = self.ref.size  # boundary vector + omega
        self.scale = np.concatenate([np.ones(self.nb - nl - 1), np.full(nl, 1 / st.spacing),
                                     [1.0]])
        self.target = st.target_points
        self.target_forms = shape.fundamental_forms(self.target)
        self.w = prob.weights
        self.spacing = st.spacing
        self.mu_outside = np.abs(numpy_model.march(st.boundary).mu) > 1
        self.evals = self.failures = 0

    def pattern(self, x):
        bd = BoundaryData.from_vector(x[:self.nb - 1], self.sigma, self.n2, self.m2)
        return numpy_model.march(bd)

    def residuals(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        pat = self.pattern(x)
        omega = x[self.nb - 1]
        q, t = x[self.nb:self.nb + 4], x[self.nb + 4:self.nb + 7]
        r = numpy_model.fold(pat, omega)[::2, ::2]
        out = []
        sp = self.spacing
        if self.w.get("forms", 0) > 0:
            res = np.concatenate([(a - b).ravel() for a, b in
                                  zip(shape.fundamental_forms(r), self.target_forms)]) / sp ** 2
            out.append(np.sqrt(self.w["forms"] / res.size) * res)
        if self.w.get("position", 0) > 0:
            R = rotation_from_quaternion(q)
            res = ((r.reshape(-1, 3) @ R.T + t - self.target.reshape(-1, 3)) / sp).ravel()
            out.append(np.sqrt(self.w["position"] / (res.size / 3)) * res)
        out.append([q @ q - 1.0])
        out.append(np.sqrt(self.w.get("regularization", 0) / self.scale.size)
                   * (x[:self.nb] - self.ref) * self.scale)
        return np.concatenate([np.ravel(o) for o in out])

    def __call__(self, x: np.ndarray) -> float:
        self.evals += 1
        try:
            with np.errstate(all="ignore"):
                res = self.residuals(x)
            f = 0.5 * float(res @ res)
        except RffqmError:
            self.failures += 1
            return LARGE
        if not np.isfinite(f):
            self.failures += 1
            return LARGE
        return f

    def report(self, x: np.ndarray) -> dict:
        """Constraint measures and fit of x (the constraints L-BFGS-B did not see)."""
        prob = self.prob
        try:
            pat = self.pattern(x)
        except RffqmError as exc:
            return {"marches": False, "error": str(exc)}
        sides = pat.side_lengths
        ang = np.concatenate([pat.alpha.ravel(), pat.beta.ravel()])
        sign = np.where(self.mu_outside, 1.0, -1.0)
        m = prob.mu_margin
        lo_mu = np.where(self.mu_outside, (1 + m) ** 2 - 1, 1 - (1 - m) ** 2)
        Y = numpy_model.fold(pat, x[self.nb - 1])
        rms = shape.kabsch(Y[::2, ::2], self.target)[2] / prob.target.diameter()
        return {"marches": True, "min_side_over_mean": float(sides.min() / sides.mean()),
                "min_vertex_angle": float(min(ang.min(), np.pi - ang.max())),
                "min_sector_angle": float(pat.sector_angles.min()),
                "mu_margin_violation": float(max(0.0, (lo_mu - sign * (pat.mu ** 2 - 1)).max())),
                "mv_held": bool(np.all((np.abs(pat.mu) > 1) == self.mu_outside)),
                "rms": float(rms)}


def rotation_from_quaternion(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q
    n = q @ q
    return np.array([[w * w + x * x - y * y - z * z, 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), w * w - x * x + y * y - z * z, 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z]]
                    ) / n


class Budget(Exception):
    pass


def run_lbfgsb(loss: NumpyLoss, x0, lbx, ubx, budget: float) -> dict:
    """L-BFGS-B from x0 with FD gradients; records (elapsed, best loss so far) per evaluation."""
    trace_t, trace_f = [], []
    best = {"f": np.inf, "x": np.array(x0)}
    t0 = time.perf_counter()

    def fun(x):
        if time.perf_counter() - t0 > budget:
            raise Budget
        f = loss(x)
        if f < best["f"]:
            best["f"], best["x"] = f, np.array(x)
        trace_t.append(time.perf_counter() - t0)
        trace_f.append(best["f"])
        return f

    bounds = [(None if not np.isfinite(a) else a, None if not np.isfinite(b) else b)
              for a, b in zip(lbx, ubx)]
    status = "budget exhausted"
    nit = [0]

    def count(*_):
        nit[0] += 1

    try:
        r = minimize(fun, x0, method="L-BFGS-B", bounds=bounds, callback=count,
                     options={"maxiter": 10 ** 6, "maxfun": 10 ** 8, "ftol": 1e-15,
                              "gtol": 1e-10, "maxcor": 20})
        status = f"stopped at {time.perf_counter() - t0:.0f} s: {r.message}"
    except Budget:
        pass
    return {"t": np.array(trace_t), "f": np.array(trace_f), "best_f": best["f"],
            "best_x": best["x"], "wall": time.perf_counter() - t0, "status": status,
            "nit": nit[0], "evals": loss.evals, "failures": loss.failures}


def first_time(t, f, level):
    hit = np.flatnonzero(np.asarray(f) <= level)
    return float(np.asarray(t)[hit[0]]) if hit.size else None


# ------------------------------------------------------------------ main
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[8, 12])
    ap.add_argument("--budget", type=float, default=120.0, help="L-BFGS-B seconds per case")
    ap.add_argument("--sim-time", type=float, default=90.0,
                    help="IPOPT time limit of the simultaneous transcription")
    ap.add_argument("--ipopt-only", type=int, nargs="*", default=[20],
                    help="extra sizes for IPOPT (sequential) alone")
    ap.add_argument("--layout", default=LAYOUT, help="Miura layout of the start")
    ap.add_argument("--out", type=Path, default=RESULTS / "bench_inverse.md")
    add_smoke(ap)
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.budget, args.sim_time, args.ipopt_only = [4], 1.0, 20.0, []
        args.out = smoke_dir("bench_inverse") / "bench_inverse.md"
    layout = args.layout
    run = Run()
    checks, rows_a, rows_b = [], [], []
    seq_runs = {}
    for n in args.sizes:
        print(f"== {n}x{n}: IPOPT (sequential) ...", flush=True)
        ip = run_ipopt(n, layout)
        seq_runs[n] = ip
        prob = problem(n, layout)
        nlp = prob.transcribe(options=SolveOptions(**SOLVE))
        f_ca = ca.Function("f", [nlp.x], [0.5 * ca.sumsqr(nlp.residuals)])
        loss = NumpyLoss(prob)
        h = ip["history"]
        obj, inf = np.array(h["objective"]), np.array(h["inf_pr"])
        feas = np.flatnonzero(inf <= FEASIBLE)
        k_best = int(feas[np.argmin(obj[feas])])
        x_ip = np.array(ip["x"])
        label_ip = "IPOPT answer"
        if not ip["success"]:
            # the last iterate is not IPOPT's best: re-run to the best feasible iterate
            print(f"   IPOPT {ip['status']}; re-running to its best feasible iterate {k_best}",
                  flush=True)
            again = run_ipopt(n, layout, max_iter=max(k_best, 1))
            x_ip = np.array(again["x"])
            label_ip = f"IPOPT iterate {k_best} (best feasible)"
        f_ip = float(obj[k_best])
        # objective check
        for where, x in (("start", nlp.x0), (label_ip, x_ip)):
            a, b = float(f_ca(x)), loss(x)
            rel = abs(a - b) / abs(a)
            checks.append(f"| {n}x{n} | {where} | {a:.15g} | {b:.15g} | {rel:.2e} | "
                          f"{'ok' if rel <= 1e-10 else 'FAIL'} |")
            print(checks[-1], flush=True)
            assert rel <= 1e-10, "NumPy and CasADi objectives disagree"
        f0 = float(f_ca(nlp.x0))
        t_eval = time.perf_counter()
        for _ in range(20):
            loss(nlp.x0)
        t_eval = (time.perf_counter() - t_eval) / 20
        loss.evals = loss.failures = 0
        ip_rep = loss.report(x_ip)
        # IPOPT's time to reach a loss: the child's wall time minus the time after that
        # iteration (history elapsed counts from the callback's creation, inside the build)
        level = f_ip * 1.01
        t_ip = ip["wall"] - (h["elapsed"][-1] - np.array(h["elapsed"]))
        obj_feas = np.minimum.accumulate(np.where(inf <= FEASIBLE, obj, np.inf))
        t_ip_hit = first_time(t_ip, obj_feas, level)
        print(f"== {n}x{n}: L-BFGS-B (budget {args.budget:.0f} s, {x_ip.size} variables, "
              f"one objective {1e3 * t_eval:.2f} ms) ...", flush=True)
        lb = run_lbfgsb(loss, nlp.x0, nlp.lbx, nlp.ubx, args.budget)
        lb_rep = loss.report(lb["best_x"])
        t_lb_hit = first_time(lb["t"], lb["f"], level)
        t_lb_exact = first_time(lb["t"], lb["f"], f_ip)
        if t_lb_hit is not None:
            ratio = f"{t_lb_hit / t_ip_hit:.1f}x"
        elif lb["status"].startswith("stopped"):
            ratio = "never (stopped above IPOPT's loss)"
        else:
            ratio = f"> {args.budget / t_ip_hit:.0f}x (budget)"
        t_ip_at_lb = first_time(t_ip, obj_feas, lb["best_f"])
        rows_a.append(
            f"| {n}x{n} | IPOPT exact (seq.) | {x_ip.size} | {f0:.4g} | {f_ip:.4g} | "
            f"{fmt(t_ip_hit, '.1f')} | {ip['wall']:.1f} ({ip['build_time']:.1f} build) | - | "
            f"{ip['iterations']} it. | {ip['status']} | "
            f"yes | {ip_rep['min_side_over_mean']:.3f} | {ip_rep['min_vertex_angle']:.3f} | "
            f"{ip_rep['mu_margin_violation']:.1e} | {100 * ip_rep['rms']:.2f}% | - |")
        marches = (f"yes; {lb['failures']}/{lb['evals']} evals failed to march"
                   if lb_rep["marches"] else "NO")
        rows_a.append(
            f"| {n}x{n} | L-BFGS-B, FD grad. (bounds only) | {x_ip.size} | {f0:.4g} | "
            f"{lb['best_f']:.4g} | {fmt(t_lb_hit, '.1f', 'not reached')}"
            f"{'' if t_lb_exact is None else f' ({t_lb_exact:.1f} to IPOPT loss)'} | "
            f"{lb['wall']:.1f} | {fmt(t_ip_at_lb, '.1f')} | {lb['evals']} evals, "
            f"{lb['nit']} it. | "
            f"{lb['status']} | {marches} | "
            f"{lb_rep.get('min_side_over_mean', float('nan')):.3f} | "
            f"{lb_rep.get('min_vertex_angle', float('nan')):.3f} | "
            f"{lb_rep.get('mu_margin_violation', float('nan')):.1e} | "
            f"{100 * lb_rep.get('rms', float('nan')):.2f}% | "
            f"{ratio} |")
        print("\n".join(rows_a[-2:]), flush=True)
    # Part B: transcriptions
    for n in args.sizes:
        for tr in ("sequential", "simultaneous"):
            if tr == "sequential":
                r = seq_runs[n]
            else:
                print(f"== {n}x{n}: IPOPT simultaneous (time limit {args.sim_time:.0f} s) ...",
                      flush=True)
                r = run_ipopt(n, layout, tr, time_limit=args.sim_time)
            h = r["history"]
            obj, inf = np.array(h["objective"]), np.array(h["inf_pr"])
            feas = inf <= 1e-6
            best = f"{obj[feas].min():.4g}" if feas.any() else "none feasible"
            nx = len(r["x"]) if r["x"] is not None else "?"
            rows_b.append(f"| {n}x{n} | {tr} | {nx} | {r['wall']:.1f} | {r['build_time']:.1f} | "
                          f"{r['iterations']} | {r['status']} | {r['objective']:.4g} | {best} | "
                          f"{inf[-1]:.1e} | {r['rss0_mb']:.0f} | {r['peak_rss_mb']:.0f} |")
            print(rows_b[-1], flush=True)
    for n in args.ipopt_only:
        print(f"== {n}x{n}: IPOPT (sequential) only ...", flush=True)
        r = run_ipopt(n, layout)
        h = r["history"]
        obj, inf = np.array(h["objective"]), np.array(h["inf_pr"])
        feas = inf <= 1e-6
        rows_b.append(f"| {n}x{n} | sequential | {len(r['x'])} | {r['wall']:.1f} | "
                      f"{r['build_time']:.1f} | {r['iterations']} | {r['status']} | "
                      f"{r['objective']:.4g} | {obj[feas].min():.4g} | {inf[-1]:.1e} | "
                      f"{r['rss0_mb']:.0f} | {r['peak_rss_mb']:.0f} |")
        print(rows_b[-1], flush=True)
    md = [
        "# Inverse-design benchmark (`studies/bench_inverse.py`)",
        "",
        f"- {run.header()} (the load includes this run's own processes)",
        f"- problem: targets/sphere_cap.toml at 2N x 2N panels, layout {layout}, stop_rms=None, "
        "default weights "
        f"{problem(4, layout).weights}, min_length 0.2, min_angle 0.15, mu_margin 0.02; same Miura start "
        "(prob.start()) and same x0 for both methods",
        "- IPOPT: `prob.solve()` (sequential transcription, exact Hessian, MUMPS, inline "
        "constraints), one fresh subprocess per run; total time = wall seconds of "
        "`prob.solve()` (start, build, solve, NumPy re-march and fit); 'time to loss' = the same "
        "clock at the first feasible iterate within 1% of the loss IPOPT reached (for L-BFGS-B: "
        "its first objective evaluation at or below that loss)",
        "- L-BFGS-B: scipy.optimize.minimize(method='L-BFGS-B'), 2-point finite-difference "
        "gradients (scipy default step), maxcor 20, ftol 1e-15, gtol 1e-10, on a NumPy objective "
        "of the same loss (numpy_model.march + fold, coarse lattice, fundamental forms, aligned "
        "positions, quaternion normalisation, Tikhonov term); bounds = the NLP's lbx/ubx "
        "(boundary angles in [0.15, pi-0.15], lengths > 0, omega in [0.05, pi-0.05]); the "
        "inline inequality constraints (all sector angles, multiplier margins = MV pattern "
        f"held, sides >= 0.2 x mean) are DROPPED; a boundary vector that does not march "
        f"returns {LARGE:g}; budget {args.budget:.0f} s per case; loss = best loss evaluated",
        "- if IPOPT fails, its reached loss is its best feasible iterate, whose x is recovered "
        "by re-running IPOPT with max_iter = that iteration (deterministic)",
        "",
        "## Objective check: NumPy objective vs CasADi 0.5*sumsqr(nlp.residuals)",
        "",
        "| panels | point | CasADi | NumPy | rel. diff | <= 1e-10 |",
        "|---|---|---|---|---|---|",
        *checks,
        "",
        "## IPOPT (exact derivatives) vs L-BFGS-B (finite differences), same loss",
        "",
        "| panels | method | variables | loss start | loss reached | time to IPOPT loss +1% [s] "
        "| total time [s] | IPOPT's time to L-BFGS-B's best loss [s] | work | status | marches | min side/mean (>= 0.2) "
        "| min vertex angle (>= 0.15) | mu-margin violation | RMS/diam | L-BFGS-B / IPOPT time |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows_a,
        "",
        "## Transcriptions: sequential vs simultaneous (IPOPT, exact Hessian)",
        "",
        f"Simultaneous runs have max_iter 1000 and a {args.sim_time:.0f} s wall-time limit. "
        "RSS = resident set size of the run's own subprocess (VmHWM of /proc/self/status): "
        "high-water mark after imports, and the peak of the whole run.",
        "",
        "| panels | transcription | variables | wall [s] | build [s] | iterations | status "
        "| final loss | best loss at a feasible iterate (inf_pr <= 1e-6) | final inf_pr "
        "| RSS after import [MB] | peak RSS [MB] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows_b,
        "",
    ]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(md))
    print("\n".join(md))


if __name__ == "__main__":
    main()
