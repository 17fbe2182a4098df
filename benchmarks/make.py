"""Make: how long does ``rffqm make`` take on the bundled sphere cap, and what do its
files measure against the issue's goals (issue 45)?

The sphere cap (targets/sphere_cap.toml) is designed at N x N panels (default 20, the
bundled size) and saved; then, each as its own process (``rffqm`` as a user runs it,
imports included), it times

* ``export dxf``  ``rffqm export RESULT --format dxf`` (the unit-free crease DXF), the
  baseline;
* ``make``  ``rffqm make RESULT --width 300mm --thickness T --out DIR``, T 1% of the mean
  panel side at that width,

as wall and CPU seconds of the child (the smallest of ``--repeat`` runs, the two
alternated), and reports the ratio and, from the made folder, the goals: the outline's
largest distance to the flat pattern scaled to 300 mm (from cut.dxf, read by ezdxf), the
least panel volume over area times thickness, whether the thick panels stay apart from
flat to the designed state, the ties' largest relative length error against the folded
pattern and their least |d length / d omega| over the pattern's size.

    python benchmarks/make.py [--panels 20] [--repeat 3] [--out docs/benchmarks/make.md]
    python benchmarks/make.py --smoke   (4 x 4 panels, one run, temporary output)
"""

from __future__ import annotations

import argparse
import csv
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import ezdxf
import numpy as np

import rffqm_nlp as rq
from common import ROOT, Run, add_output, markdown_table, output, ratio, target_problem, write_page

COLUMNS = ("panels", "command", "wall [s]", "CPU [s]", "wall / baseline", "goal")
GOALS = ("outline error [mm]", "min volume ratio", "thick panels free",
         "tie length error (rel.)", "min abs(dL/domega) / size")


def timed(argv: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of ``rffqm argv`` run as a child process."""
    rffqm = str(Path(sys.executable).with_name("rffqm"))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([rffqm, *argv], cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode:
        raise SystemExit(f"rffqm {' '.join(argv)} failed:\n{proc.stdout[-2000:]}"
                         f"{proc.stderr[-2000:]}")
    return wall, (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)


def goals(result: rq.DesignResult, folder: Path) -> dict[str, str]:
    """The issue's goals measured on a made folder."""
    X = result.pattern.X[..., :2]
    summary = json.loads((folder / "make.json").read_text())
    scale = summary["scale_mm_per_unit"]
    P = (X - X.reshape(-1, 2).min(axis=0)) * scale
    ring = np.concatenate([P[0, :-1], P[:-1, -1], P[-1, :0:-1], P[:0:-1, 0]])
    poly = ezdxf.readfile(folder / "cut.dxf").modelspace().query("LWPOLYLINE")[0]
    drawn = np.array([p[:2] for p in poly.get_points()])
    Y = rq.numpy_model.fold(result.pattern, result.omega) * scale
    errors, rates = [], []
    with open(folder / "lock.csv") as f:
        for row in csv.DictReader(f):
            a = (int(row["i1"]) - 1, int(row["j1"]) - 1)
            b = (int(row["i2"]) - 1, int(row["j2"]) - 1)
            exact = np.linalg.norm(Y[a] - Y[b])
            errors.append(abs(float(row["length_mm"]) - exact) / exact)
            rates.append(abs(float(row["dlength_domega"])))
    return {"outline error [mm]": f"{np.abs(drawn - ring).max():.2e}",
            "min volume ratio": f"{summary['panels']['volume_over_area_times_thickness']['min']:.3f}",
            "thick panels free": str(summary["thick_check"]["free"]),
            "tie length error (rel.)": f"{max(errors):.1e}",
            "min abs(dL/domega) / size": f"{min(rates) / max(summary['size_mm']):.3f}"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--panels", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=3)
    add_output(ap, "make")
    args = ap.parse_args()
    if args.smoke:
        args.panels, args.repeat = 4, 1
    run = Run()
    problem, options = target_problem("sphere_cap", args.panels)
    result = problem.solve(options)
    work = Path(tempfile.mkdtemp(prefix="rffqm-bench-make-"))
    result.save(work / "cap")
    pat = result.pattern
    side = float(np.mean(np.r_[pat.lh.ravel(), pat.lv.ravel()]))
    thickness = 0.01 * side * 300.0 / np.ptp(pat.X[..., 0])
    make_argv = ["make", str(work / "cap"), "--width", "300mm", "--thickness",
                 f"{thickness:.6f}mm", "--out", str(work / "made"), "--force"]
    export_argv = ["export", str(work / "cap"), "--format", "dxf", "--out",
                   str(work / "crease.dxf")]
    best = {"export": (np.inf, np.inf), "make": (np.inf, np.inf)}
    for _ in range(args.repeat):
        for name, argv in (("export", export_argv), ("make", make_argv)):
            wall, cpu = timed(argv)
            best[name] = (min(best[name][0], wall), min(best[name][1], cpu))
    n = f"{args.panels} x {args.panels}"
    rows = [[n, "rffqm export --format dxf (baseline)", f"{best['export'][0]:.2f}",
             f"{best['export'][1]:.2f}", "1.00", ""],
            [n, f"rffqm make --width 300mm --thickness {thickness:.3f}mm",
             f"{best['make'][0]:.2f}", f"{best['make'][1]:.2f}",
             ratio(best["make"][0], best["export"][0]), "< 10 s"]]
    measured = goals(result, work / "made")
    text = "\n".join([
        *run.preamble("make.py"),
        f"- the sphere cap designed at {n} panels ({result.stats.status}, RMS "
        f"{result.fit.rms:.4f}, omega {result.omega:.4f}); wall and CPU seconds of the "
        f"child process, the smallest of {args.repeat} runs each, the two commands "
        "alternated", "", *markdown_table(COLUMNS, rows), "",
        "The goals, measured on the made folder (thickness 1% of the mean panel side):", "",
        *markdown_table(("goal", "measured", "wanted"),
                        [[g, measured[g], w] for g, w in zip(
                            GOALS, ("<= 0.05", ">= 0.7", "True", "<= 1e-9", ">= 0.05"))])])
    write_page(output(args, "make"), "Make", text)


if __name__ == "__main__":
    main()
