"""Forward speed: the march and the fold, CasADi graph and NumPy model, against the per-panel
Python loop.

For N x N panels (default 10, 100, 300, 1000) it times, in one run,

* ``march``        the crease pattern from boundary data,
* ``fold``         one folded state (omega = 0.5),
* ``fold (K w)``   K folded states (default K = 100 omegas in [-pi, pi]),

for the CasADi graph of :mod:`rffqm_nlp.model.marching` (graph build = first call of
``pattern_function`` / ``fold_function`` with every lru_cache of the module cleared;
evaluation = best of ``--repeat`` calls of ``march`` / ``fold``), the NumPy model
:mod:`rffqm_nlp.model.numpy_model`, and the per-panel loop of ``tests/forward_oracle.py``.
The input is a Miura-ori (alpha0 = 1.2, a = b = 1) with boundary angles perturbed by
1e-3*pi, or the largest smaller amplitude that still marches with Miura lengths.

Loop-baseline cells whose estimate (per-panel cost of the last measured size, or K times
one fold) exceeds ``--budget`` seconds are skipped and reported with the estimate. Cells
slower than 5 s are timed once. The K-omega fold runs in chunks of at most ~1e7 vertices
per chunk to bound memory. Times are CPU seconds of this (single-threaded) process by
default, so other jobs on a shared machine do not inflate them; ``--clock wall`` for
wall-clock time (both are logged). The table is printed and written into
docs/benchmarks/forward.md.

    python benchmarks/forward.py [--sizes 10,100] [--repeat 3] [--omegas 100]
        [--clock cpu|wall] [--budget 60] [--out docs/benchmarks/forward.md]
    python benchmarks/forward.py --smoke   (4 x 4 panels, one call per timing, 4 omegas,
        temporary output)
"""

from __future__ import annotations

import argparse
import gc
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import rffqm_nlp as rq  # noqa: E402
from common import Run, add_output, markdown_table, output, write_page  # noqa: E402
from rffqm_nlp.model import marching as mg  # noqa: E402
from rffqm_nlp.model import numpy_model as nm  # noqa: E402
from tests.forward_oracle import fold_loop, march_loop  # noqa: E402

AMPLITUDES = (1e-3, 5e-4, 2e-4, 1e-4, 5e-5, 2e-5, 1e-5, 1e-6)   # times pi
OMEGA = 0.5
LONG = 5.0                 # a call slower than this is not repeated
CHUNK_VERTICES = 10**7     # vertices per chunk of the K-omega fold
GOAL_SIZE, GOAL_TIME = 1000, 2.0
SPEEDUP_SIZE, SPEEDUP = 300, 10.0
PATHS = ("casadi", "numpy", "loop")


@dataclass
class Cell:
    """One timing: ``time`` measured (on the chosen clock; ``wall`` is the wall-clock time),
    or skipped with an estimate ``est``."""

    time: float | None = None
    est: float | None = None
    wall: float | None = None

    @property
    def value(self) -> float | None:
        return self.time if self.time is not None else self.est

    def text(self) -> str:
        if self.time is not None:
            return fmt_time(self.time)
        if self.est is not None:
            return f"skipped (est. {fmt_time(self.est)} s)"
        return "-"


def fmt_time(t: float) -> str:
    if t >= 100:
        return f"{t:.0f}"
    if t >= 10:
        return f"{t:.1f}"
    if t >= 0.1:
        return f"{t:.2f}"
    if t >= 1e-3:
        return f"{t:.4f}"
    return f"{t:.2e}"


CLOCK_TEXT = {
    "cpu": "CPU seconds of this process (time.process_time; all three paths are single-"
           "threaded, so this is the wall time of an otherwise idle machine and is not inflated "
           "by other jobs on this shared 2-core machine)",
    "wall": "wall-clock seconds (time.perf_counter)"}
#: "cpu" (time.process_time of this single-threaded process; robust on a shared machine)
#: or "wall" (time.perf_counter); set from --clock.
CLOCK = "cpu"


def best_of(fn, repeat: int):
    """(Cell with the best times, last result) of ``repeat`` calls; a call > LONG s is not
    repeated."""
    best_cpu = best_wall = math.inf
    out = None
    for _ in range(repeat):
        out = None
        gc.collect()
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        best_cpu, best_wall = min(best_cpu, cpu), min(best_wall, wall)
        if wall > LONG:
            break
    return Cell(time=best_cpu if CLOCK == "cpu" else best_wall, wall=best_wall), out


def clear_casadi_caches() -> None:
    """Empty every lru_cache of rffqm_nlp.model.marching (pattern/fold functions, their parts)."""
    for obj in vars(mg).values():
        if callable(getattr(obj, "cache_clear", None)):
            obj.cache_clear()
    gc.collect()


def boundary(n: int) -> tuple[rq.BoundaryData, float]:
    """The perturbed Miura of n x n panels with the largest listed amplitude that marches."""
    base = rq.miura_boundary(n, n)
    for amp in AMPLITUDES:
        bd = rq.perturb_angles(base, amp * np.pi, seed=0)
        try:
            nm.march(bd)
        except rq.MarchingError:
            continue
        return bd, amp
    raise RuntimeError(f"no listed amplitude marches at {n} x {n}")


def chunked_fold(fold, pat, omegas: np.ndarray) -> np.ndarray:
    """fold(pat, chunk) over chunks of omegas into one (K, N+1, M+1, 3) array."""
    K = omegas.size
    chunk = max(1, min(K, CHUNK_VERTICES // ((pat.N + 1) * (pat.M + 1))))
    Y = np.empty((K, pat.N + 1, pat.M + 1, 3))
    for k in range(0, K, chunk):
        Y[k:k + chunk] = fold(pat, omegas[k:k + chunk])
    return Y


def loop_fold_many(pat, omegas: np.ndarray) -> np.ndarray:
    Y = np.empty((omegas.size,) + pat.X.shape)
    for k, w in enumerate(omegas):
        Y[k] = fold_loop(pat, float(w))
    return Y


def rel_diff(a: np.ndarray, b: np.ndarray, scale: float) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / scale)


class Bench:
    def __init__(self, args):
        self.repeat = args.repeat
        self.budget = args.budget
        self.model_budget = args.model_budget
        self.K = args.omegas
        self.omegas = np.linspace(-np.pi, np.pi, self.K)
        self.cells: dict[tuple[int, str, str], Cell] = {}
        self.build: dict[tuple[int, str], Cell] = {}
        self.diff: dict[tuple[int, str], float] = {}
        self.amplitude: dict[int, float] = {}
        self.loop_rate: dict[str, float] = {}     # seconds per panel of the loop baseline

    def log(self, msg: str) -> None:
        print(msg, flush=True)

    # ---------------------------------------------------------------- estimates
    def estimate(self, n: int, op: str, path: str) -> float:
        """Estimated time of a cell: K x one fold for the K-omega fold; for the loop the
        per-panel cost of the last measured size (calibrated on 20 x 20 if none)."""
        if op == "fold_many":
            one = self.cells.get((n, "fold", path))
            per = one.value if one is not None and one.value is not None else (
                self.estimate(n, "fold", path))
            return self.K * per
        if path != "loop":
            return 0.0
        if op not in self.loop_rate:
            bd, _ = boundary(20)
            c_m, pat = best_of(lambda: march_loop(bd), 3)
            c_f, _ = best_of(lambda: fold_loop(pat, OMEGA), 3)
            self.loop_rate.setdefault("march", c_m.time / 400)
            self.loop_rate.setdefault("fold", c_f.time / 400)
        return self.loop_rate[op] * n * n

    def measure(self, n: int, op: str, path: str, fn):
        """Time fn into the cell (n, op, path) unless its estimate exceeds the budget."""
        est = self.estimate(n, op, path)
        if est > (self.budget if path == "loop" else self.model_budget):
            self.cells[(n, op, path)] = Cell(est=est)
            self.log(f"  {path:8s} {op:10s} skipped (est. {est:.0f} s)")
            return None
        cell, out = best_of(fn, self.repeat)
        self.cells[(n, op, path)] = cell
        if path == "loop" and op in ("march", "fold"):
            self.loop_rate[op] = cell.time / (n * n)
        self.log(f"  {path:8s} {op:10s} {cell.time:9.4f} s (wall {cell.wall:.4f} s)")
        return out

    def measure_build(self, n: int, op: str, make) -> None:
        clear_casadi_caches()
        cell, _ = best_of(make, 1)
        self.build[(n, op)] = cell
        self.log(f"  casadi   build {op:4s} {cell.time:9.4f} s (wall {cell.wall:.4f} s)")

    # ---------------------------------------------------------------- one size
    def run_size(self, n: int) -> None:
        bd, amp = boundary(n)
        self.amplitude[n] = amp
        self.log(f"{n} x {n} panels, perturbation {amp:g}*pi")
        results = {}
        # CasADi graph: build (lru_caches cleared), then evaluation
        self.measure_build(n, "march", lambda: mg.pattern_function(n, n))
        self.measure_build(n, "fold", lambda: mg.fold_function(n, n))
        mg.pattern_function(n, n)
        # The three paths: CasADi graph, NumPy model, per-panel loop
        for path, march, fold, fold_many in (
                ("casadi", mg.march, mg.fold, lambda p: chunked_fold(mg.fold, p, self.omegas)),
                ("numpy", nm.march, nm.fold, lambda p: chunked_fold(nm.fold, p, self.omegas)),
                ("loop", march_loop, fold_loop, lambda p: loop_fold_many(p, self.omegas))):
            pat = self.measure(n, "march", path, lambda: march(bd))
            if pat is None:
                for op in ("fold", "fold_many"):
                    self.cells[(n, op, path)] = Cell(est=self.estimate(n, op, path))
                continue
            Y = self.measure(n, "fold", path, lambda pat=pat: fold(pat, OMEGA))
            Ym = self.measure(n, "fold_many", path, lambda pat=pat: fold_many(pat))
            results[path] = (pat.X, Y, None if Ym is None else Ym[[0, -1]])
            del pat, Y, Ym
            gc.collect()
        # agreement with the NumPy model, relative to the pattern size
        scale = float(np.abs(results["numpy"][0]).max())
        for path in ("casadi", "loop"):
            if path in results:
                self.diff[(n, path)] = max(
                    rel_diff(a, b, scale) for a, b in zip(results[path], results["numpy"])
                    if a is not None and b is not None)
        self.log("  max |difference| / max|X| vs NumPy: " + ", ".join(
            f"{p} {self.diff[(n, p)]:.1e}" for p in ("casadi", "loop") if (n, p) in self.diff))
        clear_casadi_caches()

    # ---------------------------------------------------------------- reporting
    OPS = (("march", "march"), ("fold", "fold (1 omega)"), ("fold_many", None),
           ("march+fold", "march + fold"))

    def cell(self, n: int, op: str, path: str) -> Cell:
        if op == "march+fold":
            a, b = self.cells.get((n, "march", path)), self.cells.get((n, "fold", path))
            if a is None or b is None or a.value is None or b.value is None:
                return Cell()
            if a.time is not None and b.time is not None:
                return Cell(time=a.time + b.time)
            return Cell(est=a.value + b.value)
        return self.cells.get((n, op, path), Cell())

    def speedup(self, n: int, op: str, path: str) -> str:
        loop, this = self.cell(n, op, "loop"), self.cell(n, op, path)
        if loop.value is None or this.time is None:
            return "-"
        ratio = loop.value / this.time
        return f"{ratio:.1f}x" if loop.time is not None else f"~{ratio:.0f}x (est.)"

    def build_time(self, n: int, op: str) -> float | None:
        ops = {"march": ("march",), "fold": ("fold",), "march+fold": ("march", "fold")}
        if op not in ops or any((n, o) not in self.build for o in ops[op]):
            return None
        return sum(self.build[(n, o)].time for o in ops[op])

    def rows(self, sizes):
        header = ["panels", "operation", "CasADi build [s]", "CasADi eval [s]", "NumPy [s]",
                  "loop [s]", "speed-up CasADi", "speed-up NumPy", "max rel. diff"]
        rows = []
        for n in sizes:
            for op, label in self.OPS:
                label = label or f"fold ({self.K} omegas)"
                build = self.build_time(n, op)
                diff = ("" if op != "march+fold" else
                        ", ".join(f"{p}: {self.diff[(n, p)]:.0e}" for p in ("casadi", "loop")
                                  if (n, p) in self.diff))
                rows.append([f"{n}x{n}", label, "-" if build is None else fmt_time(build),
                             self.cell(n, op, "casadi").text(), self.cell(n, op, "numpy").text(),
                             self.cell(n, op, "loop").text(), self.speedup(n, op, "casadi"),
                             self.speedup(n, op, "numpy"), diff])
        return header, rows

    def goals(self, sizes) -> list[str]:
        out = []
        if GOAL_SIZE in sizes:
            totals = {p: self.cell(GOAL_SIZE, "march+fold", p) for p in ("casadi", "numpy")}
            walls = {p: sum(self.cells[(GOAL_SIZE, o, p)].wall for o in ("march", "fold"))
                     for p in totals}
            fastest = min(totals, key=lambda p: totals[p].time)
            t = totals[fastest].time
            build = self.build_time(GOAL_SIZE, "march+fold")
            out.append(
                f"Goal 1 (march + fold of {GOAL_SIZE}x{GOAL_SIZE} under {GOAL_TIME:g} s with the "
                f"fastest path): {'HOLDS' if t < GOAL_TIME else 'DOES NOT HOLD'} - fastest is "
                f"{fastest} with {t:.2f} s {CLOCK} time ({walls[fastest]:.2f} s wall). CasADi: "
                f"{totals['casadi'].time:.2f} s evaluation ({walls['casadi']:.2f} s wall), "
                f"{totals['casadi'].time + build:.1f} s including the one-off graph build of "
                f"{build:.1f} s; NumPy: {totals['numpy'].time:.2f} s ({walls['numpy']:.2f} s "
                "wall).")
        else:
            out.append(f"Goal 1: not measured ({GOAL_SIZE}x{GOAL_SIZE} not in --sizes).")
        if SPEEDUP_SIZE in sizes:
            parts, ok = [], {}
            for path in ("casadi", "numpy"):
                ratios = {}
                for op in ("march", "fold", "march+fold"):
                    loop, this = self.cell(SPEEDUP_SIZE, op, "loop"), self.cell(SPEEDUP_SIZE, op,
                                                                               path)
                    if loop.time is not None and this.time is not None:
                        ratios[op] = loop.time / this.time
                ok[path] = bool(ratios) and all(r >= SPEEDUP for r in ratios.values())
                parts.append(f"{path}: " + ", ".join(f"{op} {r:.1f}x" for op, r in ratios.items()))
            verdict = " / ".join(
                f"{p} {'HOLDS' if ok[p] else 'DOES NOT HOLD'}" for p in ("casadi", "numpy"))
            fm = self.cell(SPEEDUP_SIZE, "fold_many", "loop")
            extra = ""
            if fm.time is None and fm.est is not None:
                extra = (f" The {self.K}-omega loop fold was skipped (est. {fm.est:.0f} s); its "
                         "speed-ups are estimates.")
            out.append(f"Goal 2 (>= {SPEEDUP:g}x faster than the per-panel loop at "
                       f"{SPEEDUP_SIZE}x{SPEEDUP_SIZE}, for march, fold and both): {verdict} - "
                       + "; ".join(parts) + "." + extra)
        else:
            out.append(f"Goal 2: not measured ({SPEEDUP_SIZE}x{SPEEDUP_SIZE} not in --sizes).")
        return out

    def markdown(self, sizes, meta: list[str]) -> str:
        """The run's notes, its table and the goals."""
        header, rows = self.rows(sizes)
        lines = [*meta, "", *markdown_table(header, rows), "", "Goals:", ""]
        lines += [f"- {g}" for g in self.goals(sizes)]
        return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", default="10,100,300,1000",
                        help="comma-separated N of the N x N patterns (default 10,100,300,1000)")
    parser.add_argument("--repeat", type=int, default=3, help="calls per timing (best is kept)")
    parser.add_argument("--omegas", type=int, default=100, help="K of the K-omega fold")
    parser.add_argument("--budget", type=float, default=60.0,
                        help="skip loop-baseline cells estimated to take longer (seconds)")
    parser.add_argument("--model-budget", type=float, default=300.0,
                        help="skip CasADi/NumPy cells estimated to take longer (seconds)")
    parser.add_argument("--clock", choices=("cpu", "wall"), default="cpu",
                        help="process CPU time (default; robust on a shared machine) or wall")
    add_output(parser, "forward")
    args = parser.parse_args(argv)
    if args.smoke:
        args.sizes, args.repeat, args.omegas = "4", 1, 4
    sizes = [int(s) for s in args.sizes.split(",") if s.strip()]
    global CLOCK
    CLOCK = args.clock
    bench = Bench(args)
    run = Run()
    for n in sizes:
        bench.run_size(n)
    meta = [
        *run.preamble("forward.py"),
        "- input: Miura-ori (alpha0 = 1.2, a = b = 1, Miura lengths), boundary angles perturbed "
        "(seed 0) by " + ", ".join(f"{bench.amplitude[n]:g}*pi at {n}x{n}" for n in sizes)
        + " (the largest of 1e-3*pi, 5e-4*pi, ... that marches)",
        f"- times are {CLOCK_TEXT[CLOCK]}, best of {args.repeat} calls (single call if "
        f"> {LONG:g} s wall); fold at omega = {OMEGA}; the {args.omegas}-omega fold "
        f"(linspace(-pi, pi)) runs in chunks of <= {CHUNK_VERTICES:.0e} vertices",
        "- CasADi build: first call of pattern_function / fold_function with the lru_caches "
        "cleared (one-off per size); CasADi eval: marching.march / marching.fold (DM conversion "
        "included); the K-omega fold builds its map inside fold",
        f"- loop: tests/forward_oracle.py (per-panel Python); loop cells estimated above "
        f"{args.budget:g} s (model cells: {args.model_budget:g} s) are skipped (estimate: "
        "per-panel cost of the last measured size, or K x one fold); speed-up = loop time / "
        "model time (est. = against the estimate)",
        "- max rel. diff: max |X or Y - NumPy model| / max |X| over the march, fold and first/"
        "last omega of the K-omega fold",
    ]
    write_page(output(args, "forward"), "Forward speed", bench.markdown(sizes, meta))


if __name__ == "__main__":
    main()
