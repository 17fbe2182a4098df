"""The result phase: what measuring a converged design costs beside its solve.

For each bundled target (``--targets``; from ``--large-from`` panels a side on, the first
alone) at n x n panels (``--sizes``), the default converged solve (the target file's
options: ``problem.solve()``), one BLAS thread, in a fresh process (``--repeat`` times up
to ``--large-from``, once above; the fastest counts): "solve" is its wall time less the
result phase (``design.measure.result``: re-march, checks, fit, collisions, curvature).
The design it returns (pattern, omega, aligned folded state, target points) is then
measured by this revision and by the baseline (``--baseline REV``, exported with
``git archive``; default: the revision before this work, :data:`BASELINE`), each in a fresh
process, as ``measure.result`` measures it: the fit (``measure.design_fit``: the target's
diameter, the closest points of every vertex, the areas), the collision check along the
motion (``measure.collision_fields``) and the curvature maps, ``--repeat`` times with a
fresh target each (its CasADi graph built, as after a solve, nothing else), the fastest
counts. "result / solve" is the three together over the solve, the issue's goal at most
:data:`GOAL`; "same answers" compares the baseline's: the largest difference of the fit
values (relative to the larger) and whether the collision reports agree; "peak" is the
measuring process's peak RSS. Every child runs with at most ``--memory`` GB of address
space; one that runs out is reported, not waited for. ``--keep DIR`` keeps the designs
(and their solve times) in DIR and reuses those already there.

    python benchmarks/result_phase.py [--sizes 20 40 100 200] [--large-from 100]
        [--targets sphere_cap hyperboloid quarter_vase] [--baseline REV|none]
        [--repeat 3] [--memory 3] [--keep DIR] [--out docs/benchmarks/result_phase.md]
    python benchmarks/result_phase.py --smoke   (the sphere cap at 4 x 4 panels, one
        repetition, the baseline, temporary output)
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
if "PYTHONPATH" not in os.environ:  # a child given the package to measure keeps it
    sys.path.insert(0, str(ROOT))

import rffqm_nlp as rq  # noqa: E402
from common import (TARGETS, Run, add_output, export_package, fmt,  # noqa: E402
                    markdown_table, output, peak_rss_mb, ratio, run_child, target_problem,
                    write_page)

#: the revision before the result phase was made cheap (issue 43, item 3)
BASELINE = "48b2324"
GOAL = 0.10  # the result phase over the solve (issue 43)
PATTERN_FIELDS = ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")
COLUMNS = ("target", "panels", "iterations", "solve [s]", "code", "fit [s]",
           "collisions [s]", "curvature [s]", "result phase [s]", "result / solve", "goal",
           "peak [MB]", "this / baseline", "same answers")


# ------------------------------------------------------------------ children
def solve_child(target: str, n: int, repeat: int, path: str) -> dict:
    """Solve ``target`` at n x n panels ``repeat`` times (one BLAS thread); the fastest
    solve (wall time less the result phase) and its design, saved to ``path`` (.npz)."""
    from rffqm_nlp.design import measure

    spent = []
    result = measure.result

    def timed(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return result(*args, **kwargs)
        finally:
            spent.append(time.perf_counter() - t0)

    measure.result = timed
    best, res = None, None
    with threadpool_limits(1):
        for _ in range(repeat):
            problem, options = target_problem(target, n)
            spent.clear()
            t0 = time.perf_counter()
            res = problem.solve(options)
            solve = time.perf_counter() - t0 - sum(spent)
            best = solve if best is None else min(best, solve)
    np.savez(path, omega=res.omega, folded=res.folded, target_points=res.target_points,
             solve=best, iterations=res.stats.iterations,
             **{f: np.asarray(getattr(res.pattern, f)) for f in PATTERN_FIELDS})
    return {"solve": best, "iterations": res.stats.iterations}


def measure_child(target: str, n: int, repeat: int, path: str) -> dict:
    """The fit, the collision check and the curvature maps of the saved design, as
    ``measure.result`` computes them, each the fastest of ``repeat`` (a fresh target each
    time, its CasADi graph built), and their answers."""
    from rffqm_nlp.design import measure
    from rffqm_nlp.targets import shape
    from rffqm_nlp.targets.curvature import curvature_maps

    d = np.load(path)
    pattern = rq.Pattern(**{f: d[f] for f in PATTERN_FIELDS})
    omega, folded, points = float(d["omega"]), d["folded"], d["target_points"]
    times: dict[str, list[float]] = {"fit": [], "collisions": [], "curvature": []}
    with threadpool_limits(1):
        for _ in range(repeat):
            surface = target_problem(target, n)[0].target
            (u0, _), (v0, _) = surface.domain
            surface.point(u0, v0)                       # the graph a solve has built
            t0 = time.perf_counter()
            fit = measure.design_fit(folded, points, surface)
            t1 = time.perf_counter()
            report = measure.collision_fields(pattern, omega)
            t2 = time.perf_counter()
            curvature_maps(shape.coarse_grain(folded), points, surface)
            t3 = time.perf_counter()
            for key, dt in zip(times, (t1 - t0, t2 - t1, t3 - t2)):
                times[key].append(dt)
    return {**{k: min(v) for k, v in times.items()}, "fit_values": fit, "report": report,
            "peak": peak_rss_mb(), "package": str(Path(rq.__file__).parent)}


def child(mode: str, job: list, memory: float, env: dict | None = None) -> dict:
    """A child of this script (``mode``: --solve or --measure) with at most ``memory`` GB
    of address space; {"failed": the last line of its error} when it fails."""
    try:
        return run_child(__file__, mode, json.dumps(job), f"{memory:g}", env=env)
    except RuntimeError as exc:
        return {"failed": (str(exc).strip().splitlines() or ["?"])[-1][:120]}


# ------------------------------------------------------------------ the table
def agreement(row: dict, base: dict) -> str:
    """The largest relative difference of the fit values, and whether the reports agree."""
    a, b = row["fit_values"], base["fit_values"]
    worst = max(abs(a[k] - b[k]) / max(abs(a[k]), abs(b[k]), 1e-300) for k in a)
    return f"fit {worst:.1e}, report {'same' if row['report'] == base['report'] else 'DIFFERS'}"


def table(rows: list[dict]) -> list[str]:
    """One row per design and code: this revision's, then the baseline's."""
    cells = []
    for r in rows:
        for code in ("this", "baseline"):
            m = r.get(code)
            if m is None:
                continue
            name = code if code == "this" else r["baseline_rev"]
            if "failed" in m:
                cells.append([r["target"], f"{r['n']} x {r['n']}", fmt(r["iterations"], "d"),
                              fmt(r["solve"], ".3f"), name, f"failed: {m['failed']}",
                              *["-"] * (len(COLUMNS) - 6)])
                continue
            phase = m["fit"] + m["collisions"] + m["curvature"]
            share = phase / r["solve"]
            base = r.get("baseline")
            base = None if base is None or "failed" in base or code != "this" else base
            cells.append([
                r["target"], f"{r['n']} x {r['n']}", fmt(r["iterations"], "d"),
                fmt(r["solve"], ".3f"), name, fmt(m["fit"], ".3f"), fmt(m["collisions"], ".3f"),
                fmt(m["curvature"], ".4f"), fmt(phase, ".3f"), f"{100 * share:.1f}%",
                "yes" if share <= GOAL else "no", fmt(m["peak"], ".0f"),
                ratio(phase, base["fit"] + base["collisions"] + base["curvature"])
                if base else "-", agreement(m, base) if base else "-"])
    return markdown_table(COLUMNS, cells)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 40, 100, 200])
    ap.add_argument("--large-from", type=int, default=100)
    ap.add_argument("--targets", nargs="*", default=list(TARGETS), choices=TARGETS)
    ap.add_argument("--baseline", default=BASELINE, help="a git revision, or none")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--memory", type=float, default=3.0, help="GB of address space a child "
                    "may use (default: %(default)s)")
    ap.add_argument("--keep", type=Path, default=None, help="a folder for the designs; "
                    "those already there are reused with their solve times")
    add_output(ap, "result_phase")
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.targets, args.repeat = [4], ["sphere_cap"], 1
    clock = Run()
    package = None if args.baseline == "none" else export_package(args.baseline)
    folder = args.keep or Path(tempfile.mkdtemp(prefix="rffqm-result-phase-"))
    folder.mkdir(parents=True, exist_ok=True)
    rows = []
    for n in args.sizes:
        for target in args.targets[:1] if n >= args.large_from else args.targets:
            path = folder / f"{target}_{n}.npz"
            row = {"target": target, "n": n, "baseline_rev": args.baseline}
            if path.exists():
                with np.load(path) as kept:
                    row.update(solve=float(kept["solve"]), iterations=int(kept["iterations"]))
            else:
                solves = args.repeat if n < args.large_from else 1
                row.update(child("--solve", [target, n, solves, str(path)], args.memory))
            if "failed" in row:
                print(f"{target} at {n}: the solve failed: {row['failed']}", flush=True)
                continue
            job = [target, n, args.repeat, str(path)]
            row["this"] = child("--measure", job, args.memory)
            if package is not None:
                row["baseline"] = child("--measure", job, args.memory,
                                        env={"PYTHONPATH": str(package)})
            rows.append(row)
            print({k: row[k] for k in ("target", "n", "solve")},
                  {c: {k: row[c].get(k) for k in ("fit", "collisions", "curvature", "failed")}
                   for c in ("this", "baseline") if c in row}, flush=True)
    text = "\n".join([
        *clock.preamble("result_phase.py"),
        "- wall seconds, one BLAS thread, each the fastest of its repetitions; solve: "
        "`problem.solve()` less its result phase; fit, collisions, curvature: as "
        "`design.measure.result` computes them, on the design the solve returned; goal: "
        f"result / solve at most {100 * GOAL:.0f}%; this / baseline: the result phase's "
        "ratio; same answers: the largest relative difference of the fit values, and "
        "whether the collision reports agree", "",
        *table(rows)])
    write_page(output(args, "result_phase"), "The result phase", text)


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] in ("--solve", "--measure"):
        limit = int(float(sys.argv[3]) * 2 ** 30)
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
        work = solve_child if sys.argv[1] == "--solve" else measure_child
        print(json.dumps(work(*json.loads(sys.argv[2])), default=str))
    else:
        main()
