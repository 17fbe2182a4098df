"""Mechanics of a design: how long the bar-and-hinge model's stiffness and modes take, and
how exact the folding mode is, from 20 to 100 panels a side.

For N x N panels (default 20, 50, 100) of a Miura-ori (alpha0 = 1.1, a = 1, b = 1.3) and the
same with boundary angles perturbed by 0.01 pi and side-length LP lengths, folded at
omega = 1.3, on a 300 mm wide polypropylene sheet, it times in one run

* ``march+fold``: the NumPy march and one fold (the baseline of the ratio),
* ``model``: ``BarAndHinge`` (the frame, the fold and the exact folding velocity),
* ``stiffness``: ``model.stiffness()``, the sparse K = R^T C R + J^T diag(k) J,
* ``modes``: ``model.modes(12)``, shift-invert Lanczos on one sparse factorisation,
* ``solve``: ``model.solve(gravity=True)`` on the four corners,

and reports ||R v||/||v|| of the exact folding velocity v, the zero modes, the softest
non-rigid eigenvalue and the folding mode's stiffness over the largest eigenvalue. The
goal (issue 46): stiffness and modes of 100 x 100 under 10 s. Wall-clock seconds, one run
each, on a machine shared with other jobs (the load is in the header).

With ``--merlin DIR`` (a folder holding MERLIN2's PrepareData.m, GlobalK_fast_ver.m,
FoldKe.m, Ogden.m and EnhancedLinear.m, e.g. from the MIT-licensed
Daraio-lab/RoboticSurface_SciRob_LiuK) and GNU Octave on the PATH, it also builds MERLIN2's
N4B5 stiffness of a small Miura (uniform bar area, bending and folding stiffness per length,
its own 1e-5 I removed) and compares it with R^T diag(E A/L) R + J^T diag(k L) J from this
package's rigidity matrix and hinge Jacobian: an independent implementation of the same
bar-and-hinge model.

    .venv/bin/python benchmarks/mechanics.py [--sizes 20,50,100] [--merlin DIR]
    .venv/bin/python benchmarks/mechanics.py --smoke
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import rffqm_nlp as rq  # noqa: E402
from common import Run, add_output, fmt, markdown_table, output, ratio, write_page  # noqa: E402
from rffqm_nlp.mechanics import BarAndHinge, Material  # noqa: E402

OMEGA, WIDTH = 1.3, 0.3
GOAL_SIZE, GOAL_TIME = 100, 10.0
COLUMNS = ("panels", "pattern", "dofs", "march+fold [s]", "model [s]", "stiffness [s]",
           "modes [s]", "stiffness+modes / march+fold", "solve [s]", "Rv / v (2-norms)",
           "zero modes", "softest / largest", "folding / largest")


def pattern(n: int, perturbed: bool):
    bd = rq.miura_boundary(n, n, a=1.0, b=1.3, alpha0=1.1, layout="zigzag_j")
    if perturbed:
        bd = rq.lengths.side_length_lp(rq.perturb_angles(bd, 0.01 * np.pi, seed=0))
    return bd


def timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def row(n: int, perturbed: bool, sheet: Material) -> list[str]:
    bd = pattern(n, perturbed)
    (_, base) = timed(lambda: rq.numpy_model.fold(rq.numpy_model.march(bd), OMEGA))
    pat = rq.numpy_model.march(bd)
    model, t_model = timed(lambda: BarAndHinge(pat, OMEGA, sheet, width=WIDTH))
    _, t_stiff = timed(model.stiffness)
    modes, t_modes = timed(lambda: model.modes(12))
    _, t_solve = timed(lambda: model.solve(gravity=True))
    v = model.velocity
    residual = np.linalg.norm(model.rigidity_matrix() @ v) / np.linalg.norm(v)
    softest = modes.values[modes.zero_count] / modes.largest
    return [f"{n} x {n}", "perturbed 0.01 pi, LP" if perturbed else "Miura",
            str(3 * (n + 1) ** 2), fmt(base, ".3f"), fmt(t_model, ".2f"), fmt(t_stiff, ".2f"),
            fmt(t_modes, ".2f"), ratio(t_stiff + t_modes, base, ".0f"), fmt(t_solve, ".2f"),
            fmt(residual, ".1e"), str(modes.zero_count), fmt(softest, ".2e"),
            fmt(modes.folding / modes.largest, ".2e")]


# ------------------------------------------------------------------ MERLIN2 comparison
MERLIN_SCRIPT = """
addpath('{merlin}');
Node = dlmread('{work}/node.txt');
quads = dlmread('{work}/panels.txt');
Panel = num2cell(quads, 2);
opt = struct('ModelType', 'N4B5', 'Abar', {area}, 'Kb', {kb}, 'Kf', {kf},
             'BarCM', @(Ex) Ogden(Ex, {E}));
[truss, angles] = PrepareData(Node, Panel, [], [], opt);
[~, K] = GlobalK_fast_ver(zeros(3 * size(Node, 1), 1), Node, truss, angles);
K = K - 1e-5 * speye(size(K, 1));
[i, j, k] = find(K);
dlmwrite('{work}/K.txt', [i, j, k], 'precision', 17);
"""


def merlin_stiffness(model: BarAndHinge, merlin: Path, area: float, kb: float, kf: float,
                     E: float) -> sp.csr_matrix:
    """MERLIN2's N4B5 stiffness of ``model``'s state under Octave (uniform bar area, bending
    and folding stiffness per length)."""
    N, M = model.N, model.M
    node = np.arange((N + 1) * (M + 1)).reshape(N + 1, M + 1) + 1
    quads = np.stack([node[:-1, :-1], node[:-1, 1:], node[1:, 1:], node[1:, :-1]],
                     -1).reshape(-1, 4)                                 # a, c, d, b
    with tempfile.TemporaryDirectory() as work:
        np.savetxt(f"{work}/node.txt", model.positions, delimiter=",", fmt="%.17g")
        np.savetxt(f"{work}/panels.txt", quads, delimiter=",", fmt="%d")
        script = MERLIN_SCRIPT.format(merlin=merlin.resolve(), work=work, area=area, kb=kb,
                                      kf=kf, E=E)
        Path(f"{work}/run.m").write_text(script)
        subprocess.run(["octave", "--no-gui", "--quiet", f"{work}/run.m"], check=True,
                       capture_output=True, timeout=600)
        i, j, k = np.loadtxt(f"{work}/K.txt", delimiter=",", ndmin=2).T
    n = 3 * len(model.positions)
    return sp.csr_matrix((k, (i.astype(int) - 1, j.astype(int) - 1)), shape=(n, n))


def ours(model: BarAndHinge, area: float, kb: float, kf: float, E: float) -> sp.csr_matrix:
    """The same N4B5 model from this package's rigidity matrix and hinge Jacobian."""
    R, J = model.rigidity_matrix(), model.hinge_jacobian()
    h = model.frame.hinges
    length = np.linalg.norm(model.positions[h[:, 1]] - model.positions[h[:, 0]], axis=1)
    k = np.where(np.arange(len(h)) < model.N * model.M, kb, kf) * length
    return (R.T @ sp.diags(E * area / model.bar_lengths()) @ R + J.T @ sp.diags(k) @ J).tocsr()


def merlin_rows(merlin: Path, sizes: list[tuple[int, int]]) -> list[list[str]]:
    rows = []
    E, area, kb, kf = 1e6, 0.1, 2.0, 0.2
    sheet = Material(E, 0.3, 1e-3, 0.0)
    for N, M in sizes:
        for perturbed in (False, True):
            bd = rq.miura_boundary(N, M, a=1.0, b=1.3, alpha0=1.1, layout="zigzag_j")
            if perturbed:
                bd = rq.lengths.side_length_lp(rq.perturb_angles(bd, 0.02 * np.pi, seed=2))
            model = BarAndHinge(rq.numpy_model.march(bd), OMEGA, sheet)
            (K_m, t_m) = timed(lambda: merlin_stiffness(model, merlin, area, kb, kf, E))
            (K_o, t_o) = timed(lambda: ours(model, area, kb, kf, E))
            diff = abs(K_m - K_o).max() / abs(K_o).max()
            rows.append([f"{N} x {M}", "perturbed 0.02 pi, LP" if perturbed else "Miura",
                         str(K_o.shape[0]), fmt(diff, ".1e"), fmt(t_m, ".2f"),
                         fmt(t_o, ".3f")])
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", default="20,50,100", help="panels a side (default %(default)s)")
    parser.add_argument("--merlin", type=Path, default=None,
                        help="a folder with MERLIN2's .m files: compare under GNU Octave")
    add_output(parser, "mechanics")
    args = parser.parse_args()
    sizes = [4, 6] if args.smoke else [int(s) for s in args.sizes.split(",")]
    run = Run()
    sheet = Material.named("polypropylene")
    rows = [row(n, perturbed, sheet) for n in sizes for perturbed in (False, True)]
    lines = [*run.preamble("mechanics.py"), "",
             f"Sheet: polypropylene (E 1.5 GPa, nu 0.42, t 0.5 mm, crease stiffness "
             f"{sheet.fold_stiffness:.3g} N m/rad per m), {WIDTH * 1e3:.0f} mm wide, omega "
             f"{OMEGA}; wall-clock seconds, one run each. Goal (issue 46): stiffness + modes "
             f"of {GOAL_SIZE} x {GOAL_SIZE} under {GOAL_TIME:g} s.", "",
             *markdown_table(COLUMNS, rows)]
    if args.merlin is not None and shutil.which("octave"):
        lines += ["", "MERLIN2 (GNU Octave) against this package, N4B5, uniform bar area "
                  "0.1, E 1e6, bending 2 and folding 0.2 per length, at omega 1.3: the largest "
                  "entry of |K_MERLIN2 - K| over the largest of |K|.", "",
                  *markdown_table(("panels", "pattern", "dofs", "max dK / max K",
                                   "MERLIN2 [s]", "this package [s]"),
                                  merlin_rows(args.merlin, [(2, 2), (4, 6)] if args.smoke
                                              else [(4, 6), (10, 10)]))]
    write_page(output(args, "mechanics"), "Mechanics", "\n".join(lines))


if __name__ == "__main__":
    main()
