"""Could the Levenberg-Marquardt step be found matrix-free? The conditioning of the reduced
problem, and conjugate gradients with and without preconditioners.

At the Miura start of a bundled target (marched, as the solver's first iterate) with n x n
panels: the dense Gauss-Newton model of :mod:`rffqm_nlp.design.solvers.levenberg_marquardt` (J' J
and the metric M =
D_d + S_p' D_p S_p from one pass over the levels) at the target file's first damping lam.
Reported:

* the cost of one dense pass (``Manifold.linearize``) against one matrix-free product
  (J' J + lam M) v by one forward and one adjoint sweep, and the largest deviation of that
  product from the dense one (relative);
* the spectrum of H = J' J + lam M (largest, smallest, condition number) and of M^-1 H
  (the same, and its 5th largest: the top few are outliers);
* conjugate gradients on H dd = -J' r from dd = 0: the share of the exact step's model
  reduction after 20 and after 50 iterations, with no preconditioner, the diagonal lam D_d,
  Jacobi (H's diagonal) and the metric M itself (dense: the yardstick a cheap
  preconditioner would have to approach).

    .venv/bin/python studies/reduced_conditioning.py [--sizes 20 40 100]
        [--targets sphere_cap] [--out studies/results/reduced_conditioning.md]
    .venv/bin/python studies/reduced_conditioning.py --smoke   (6 x 6, temporary output)
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Callable

import numpy as np
import scipy.linalg as la

from common import RESULTS, TARGETS, Run, add_smoke, smoke_dir, target_problem, write_table
from rffqm_nlp.design.solvers import levenberg_marquardt as reduced

#: CG iterations after which the model reduction is reported
CHECKPOINTS = (20, 50)


def matrix_free_product(man: reduced.Manifold, lin, V: np.ndarray, lam: float) -> np.ndarray:
    """(J' J + lam M) V (n_d, p) for V (n_d, p) by one forward sweep (S V) and one adjoint
    sweep, M = D_d + S_p' D_p S_p (and a free correspondence's F_u H, its lift)."""
    levels = lin.sensitivity.levels  # S in every state row (a step reads only ``read``)
    SV = levels.forward(V)
    JV = lin.J_design @ V + lin.J_state @ SV[man.read]
    if lin.lift is not None:
        JV[lin.lift.rows] += lin.lift.times(V)
    Y = np.zeros_like(SV)
    Y[man.read] = lin.J_state.T @ JV
    Y[man.pattern] += lam * man.pattern_weights[:, None] * SV[man.pattern]
    out = lin.J_design.T @ JV + levels.adjoint(Y) + lam * man.design_metric @ V
    if lin.lift is not None:
        out[lin.lift.columns] += lin.lift.transpose_times(JV)
    return out


def cg_reduction(H: np.ndarray, b: np.ndarray, solve: Callable[[np.ndarray], np.ndarray],
                 iterations: int) -> list[float]:
    """Preconditioned CG on H x = b from 0 (``solve`` applies the preconditioner's inverse):
    the model's reduction -q(x_k), q(x) = 0.5 x' H x - b' x, after each iteration k."""
    x, r = np.zeros_like(b), b.copy()
    z = solve(r)
    d, rz, out = z.copy(), float(r @ z), []
    for _ in range(iterations):
        Hd = H @ d
        if rz <= 0 or float(d @ Hd) <= 0:  # converged (or broken down): x stays
            out.append(out[-1] if out else 0.0)
            continue
        a = rz / float(d @ Hd)
        x += a * d
        r -= a * Hd
        z = solve(r)
        rz, previous = float(r @ z), rz
        d = z + (rz / previous) * d
        out.append(-(0.5 * float(x @ H @ x) - float(b @ x)))
    return out


def measure(target: str, n: int) -> dict:
    """One target at n x n panels: the costs, spectra and CG reductions of the docstring."""
    problem, options = target_problem(target, n)
    nlp = problem.transcribe(options=options)
    man = reduced.Manifold(nlp)
    p = man.point(nlp.project(nlp.x0))
    t0 = time.perf_counter()
    lin = man.linearize(p)
    dense_pass = time.perf_counter() - t0
    m = reduced._model(man, p, lin)
    lam = options.damping
    H = m.JtJ + lam * m.M
    v = np.random.default_rng(0).standard_normal((H.shape[0], 1))
    t0 = time.perf_counter()
    Hv = matrix_free_product(man, lin, v, lam)
    product = time.perf_counter() - t0
    deviation = float(np.abs(Hv - H @ v).max() / np.abs(H @ v).max())
    eig = la.eigvalsh(H)
    metric_eig = la.eigvalsh(H, m.M)
    b = -m.grad
    exact = -0.5 * float(b @ la.solve(H, b))  # q at the exact step
    D = lam * man.design_metric.diagonal()
    factor = la.cho_factor(m.M)
    preconditioners = {"none": lambda r: r, "lam D_d": lambda r: r / D,
                       "Jacobi": lambda r: r / np.diag(H),
                       "M (dense)": lambda r: la.cho_solve(factor, r)}
    shares = {}
    for name, solve in preconditioners.items():
        reduction = cg_reduction(H, b, solve, max(CHECKPOINTS))
        shares[name] = [reduction[k - 1] / -exact for k in CHECKPOINTS]
    return {"target": target, "n": n, "n_d": H.shape[0], "lam": lam, "dense_pass": dense_pass,
            "product": product, "deviation": deviation, "eig": (eig[-1], eig[0]),
            "metric_eig": (metric_eig[-1], metric_eig[-5], metric_eig[0]), "shares": shares}


def table(rows: list[dict]) -> list[str]:
    names = list(rows[0]["shares"]) if rows else []
    head = ("| target | panels | n_d | dense pass [s] | product [s] | product deviation | "
            "H: largest, smallest, cond | M^-1 H: largest, 5th, smallest | "
            + " | ".join(f"CG {name}: {CHECKPOINTS[0]} / {CHECKPOINTS[1]}" for name in names)
            + " |")
    lines = [head, "|" + "---|" * (8 + len(names))]
    for r in rows:
        big, small = r["eig"]
        top, fifth, least = r["metric_eig"]
        lines.append(
            f"| {r['target']} | {r['n']} x {r['n']} | {r['n_d']} | {r['dense_pass']:.3f} | "
            f"{r['product']:.4f} | {r['deviation']:.1e} | {big:.2g}, {small:.2g}, "
            f"{big / small:.2g} | {top:.2g}, {fifth:.2g}, {least:.2g} | "
            + " | ".join(" / ".join(f"{s:.3f}" for s in r["shares"][name]) for name in names)
            + " |")
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="*", default=[20, 40, 100])
    parser.add_argument("--targets", nargs="*", default=["sphere_cap"], choices=TARGETS)
    parser.add_argument("--out", type=Path, default=RESULTS / "reduced_conditioning.md")
    add_smoke(parser)
    args = parser.parse_args()
    if args.smoke:
        args.sizes = [6]
        args.out = smoke_dir("reduced_conditioning") / "reduced_conditioning.md"
    run = Run()
    rows = [measure(target, n) for target in args.targets for n in args.sizes]
    text = "\n".join([
        "# The reduced problem's conditioning: could the step be found matrix-free?", "",
        run.header(), "",
        "Command: `python studies/reduced_conditioning.py "
        + " ".join(["--sizes", *map(str, args.sizes), "--targets", *args.targets]) + "`", "",
        "At the marched Miura start, lam = the target file's damping. dense pass: one "
        "`Manifold.linearize` (J'J, metric, gradient); product: one (J'J + lam M) v by a "
        "forward and an adjoint sweep, and its largest deviation from the dense product "
        "(relative). CG: the share of the exact step's model reduction after "
        f"{CHECKPOINTS[0]} / {CHECKPOINTS[1]} iterations with each preconditioner.", "",
        *table(rows), ""])
    write_table(args.out, text)


if __name__ == "__main__":
    main()
