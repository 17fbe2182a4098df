"""Collisions: the self-contact check against one march-and-fold of 100 states (issue 20).

For N x N panels (default 20 and 100) and two patterns, a Miura-ori (alpha0 = 1.2,
a = b = 1) and the same with boundary angles perturbed (``rq.perturb_angles``, the first
seed from 0 whose pattern marches with the Miura lengths, amplitude ``--amplitude``), it
times in one run

* ``march+fold``  ``numpy_model.fold(numpy_model.march(bd), np.linspace(0, omega*, 100))``,
  the baseline;
* ``collisions``  ``collisions(pattern, omega*)`` on the marched pattern,

and reports their ratio (the issue's goal: at most 2 at 100 x 100), and
* ``one fit``  the same check with one affine fit of the whole pattern's displacements in
  the broad phase (the path below ``contact.broad.MIN_TILES`` tiles), against the tiles' fits
  it uses from that many tiles on (docs/collisions.md); "same" says whether both gave the
  same report.

The same rows follow for the paper's Fig. Random recipe at 10 x 10 (Miura angles +-0.1 pi,
the side-length LP; ``--lp-seeds``), whose very unequal side lengths made slow cases, and,
with ``--solved N[,N...]``, for the sphere cap (targets/sphere_cap.toml) solved once at each
N x N panels to 0.9% RMS/diameter (``stop_rms = 0.009``), at its designed omega.

Every row also gives the check's peak memory: the ``tracemalloc`` peak of one more
``collisions`` call (untimed; NumPy's arrays are traced), over what was held before it.

Times are CPU seconds of this process (``time.process_time``), so other jobs on a shared
machine do not count; each is the smallest of ``--repeat`` runs (both sides of a ratio
alike, their runs alternated), since a loaded machine still slows a process down (shared
caches and memory).

    python benchmarks/collisions.py [--sizes 20,100] [--omega 2.0] [--amplitude 0.001]
        [--lp-seeds 11,16,36] [--repeat 3] [--solved 100,200]
        [--out docs/benchmarks/collisions.md]
    python benchmarks/collisions.py --smoke   (4 x 4 panels, one LP seed, one run, the
        solved sphere cap at 4 x 4, temporary output)
"""

from __future__ import annotations

import argparse
import importlib
import math
import time
import tracemalloc
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

import rffqm_nlp as rq
from common import STOP_RMS, Run, add_output, markdown_table, output, target_problem, write_page
from rffqm_nlp import MarchingError, collisions
from rffqm_nlp.model.numpy_model import fold, march

#: the broad phase, whose tile constants (TILE, MIN_TILES) the "one fit" rows change
broad = importlib.import_module("rffqm_nlp.contact.broad")
COLUMNS = ("panels", "pattern", "omega*", "march+fold [s]", "collisions [s]", "ratio",
           "one fit [s]", "one fit / tiles", "same", "check peak [MB]", "free", "first_omega")


def perturbed(n: int, amplitude: float) -> tuple[rq.BoundaryData, int]:
    """A Miura boundary of n x n panels with perturbed angles that marches, and its seed."""
    miura = rq.miura_boundary(n, n, alpha0=1.2)
    for seed in range(200):
        bd = rq.perturb_angles(miura, amplitude * np.pi, seed)
        try:
            march(bd)
        except MarchingError:
            continue
        return bd, seed
    raise SystemExit(f"no seed in 0..199 marches at {n} x {n}; lower --amplitude")


def cpu(f, repeat: int):
    """(result, smallest CPU seconds over ``repeat`` runs) of f()."""
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.process_time()
        out = f()
        best = min(best, time.process_time() - t)
    return out, best


def peak_mb(f) -> str:
    """The tracemalloc peak of f() in MB, over what was traced before, for a table cell."""
    tracemalloc.start()
    try:
        f()
        return f"{tracemalloc.get_traced_memory()[1] / 1e6:.1f}"
    finally:
        tracemalloc.stop()


@contextmanager
def one_fit():
    """The broad phase with one affine fit for the whole pattern, however many tiles."""
    saved = broad.MIN_TILES
    broad.MIN_TILES = math.inf
    try:
        yield
    finally:
        broad.MIN_TILES = saved


def first(rep) -> str:
    """The report's first contact for a table cell."""
    return "-" if rep.first_omega is None else f"{rep.first_omega:.4f}"


def row(n: int, name: str, bd: rq.BoundaryData, omega: float, repeat: int) -> dict:
    """One table row: the timings on the same pattern, their runs alternated (so that
    the sides of each ratio see the same load)."""
    pat = march(bd)
    t_fold = t_col = t_one = np.inf
    for _ in range(repeat):
        _, t = cpu(lambda: fold(march(bd), np.linspace(0, omega, 100)), 1)
        t_fold = min(t_fold, t)
        rep, t = cpu(lambda: collisions(pat, omega), 1)
        t_col = min(t_col, t)
        with one_fit():
            rep_one, t = cpu(lambda: collisions(pat, omega), 1)
        t_one = min(t_one, t)
    return {"panels": f"{n} x {n}", "pattern": name, "omega*": f"{omega:g}",
            "march+fold [s]": f"{t_fold:.2f}", "collisions [s]": f"{t_col:.2f}",
            "ratio": f"{t_col / t_fold:.1f}", "one fit [s]": f"{t_one:.2f}",
            "one fit / tiles": f"{t_one / t_col:.2f}", "same": str(rep == rep_one),
            "check peak [MB]": peak_mb(lambda: collisions(pat, omega)),
            "free": str(rep.free), "first_omega": first(rep)}


def solved(n: int) -> tuple[rq.BoundaryData, float]:
    """The sphere cap solved at n x n panels to 0.9% RMS/diameter: its boundary data and
    designed omega."""
    problem, options = target_problem("sphere_cap", n)
    res = problem.solve(replace(options, stop_rms=STOP_RMS))
    print(f"solved {n} x {n}: {res.stats.status}, rms {res.fit.rms:.4f}, "
          f"omega {res.omega:.4f}", flush=True)
    return res.boundary, float(res.omega)


def random_recipe(seed: int) -> rq.BoundaryData:
    """The paper's Fig. Random recipe at 10 x 10: Miura angles +-0.1 pi, the side-length LP."""
    bd = rq.perturb_angles(rq.miura_boundary(10, 10), 0.1 * np.pi, seed)
    return rq.lengths.side_length_lp(bd)


def table(rows: list[dict]) -> list[str]:
    """The lines of the Markdown table of the rows."""
    return markdown_table(COLUMNS, [[r[c] for c in COLUMNS] for r in rows])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="20,100")
    ap.add_argument("--omega", type=float, default=2.0)
    ap.add_argument("--amplitude", type=float, default=0.001, help="perturbation / pi")
    ap.add_argument("--lp-seeds", default="11,16,36")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--solved", default=None,
                    help="also the sphere cap solved at these many panels a side (a,b,...)")
    add_output(ap, "collisions")
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.lp_seeds, args.repeat, args.solved = "4", "11", 1, "4"
    run = Run()
    cases = []  # (panels, pattern, boundary data, omega*)
    for n in (int(s) for s in args.sizes.split(",")):
        bd, seed = perturbed(n, args.amplitude)
        cases += [(n, "Miura", rq.miura_boundary(n, n, alpha0=1.2), args.omega),
                  (n, f"perturbed {args.amplitude:g} pi, seed {seed}", bd, args.omega)]
    cases += [(10, f"Fig. Random, LP sides, seed {s}", random_recipe(int(s)), args.omega)
              for s in args.lp_seeds.split(",")]
    cases += [(n, "sphere cap, solved to 0.9%", *solved(n))
              for n in (int(s) for s in (args.solved.split(",") if args.solved else ()))]
    rows = []
    for n, name, bd, omega in cases:
        rows.append(row(n, name, bd, omega, args.repeat))
        print(table(rows[-1:])[-1], flush=True)
    text = "\n".join([
        *run.preamble("collisions.py"),
        f"- CPU seconds of one process, the smallest of {args.repeat} runs each (the two "
        "sides of a ratio alternated); march+fold: `fold(march(bd), linspace(0, omega*, "
        "100))`, the baseline; collisions: `collisions(pattern, omega*)` (clearance 0, tol "
        "1e-4); ratio: collisions / march+fold; check peak: the tracemalloc peak of one more "
        "collisions call; one fit: the check with one affine fit of the displacements in the "
        f"broad phase instead of one per {broad.TILE} x {broad.TILE}-panel tile (used "
        f"from {broad.MIN_TILES} tiles on), same: the same report. Goal (issue 20): ratio "
        "<= 2 at 100 x 100", "", *table(rows)])
    write_page(output(args, "collisions"), "Collisions", text)


if __name__ == "__main__":
    main()
