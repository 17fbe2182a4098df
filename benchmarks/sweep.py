"""Sweep: the throughput of a 32-design sweep on a LocalCluster of 2 single-threaded worker
processes, against the same sweep run serially in one process in the same run.

The study: sphere caps of 8 radii (a patch of side 3.2, |u|, |v| <= 1.6 / R) x both Miura
layouts x 6 x 6 and 8 x 8 panels, default options, IPOPT to its tolerance (stop_rms off).
Both runs start from an empty output folder (runs/bench_sweep/serial and .../cluster); the
cluster's wall time includes starting it. Each run also reports the CPU cores it used
(its own processes' CPU time, workers included, over its wall time) and the cores the whole
machine was busy (from /proc/stat), so that other jobs on the machine show. Prints a table
of designs per minute and their ratio to the serial run's, checks that both runs give the
same table, and writes docs/benchmarks/sweep.md.

    python benchmarks/sweep.py [--workers 2] [--out docs/benchmarks/sweep.md]
    python benchmarks/sweep.py --smoke   (one design at 4 x 4 panels, 1 worker, temporary
        output)
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import time
from pathlib import Path

import rffqm_nlp as rq
from common import ROOT, Run, add_output, markdown_table, output, smoke_dir, write_page

sweeps = rq.sweeps

RADII = (2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 8.0)
HALF_SIDE = 1.6
#: the solver of the recorded results: IPOPT, sequential transcription, to its tolerance
#: (stop_rms unset)
SOLVE = {"solver": "ipopt", "transcription": "sequential", "max_iter": 500}


def study(radii=RADII, layouts=("zigzag_i", "zigzag_j"), panels=(6, 8)) -> sweeps.Study:
    """The designs: radii (cases with their domains) x layouts x pattern sizes (32 by
    default)."""
    cases = [{"name": f"R={R:g}", "target.radius": R,
              "target.domain": [[-HALF_SIDE / R, HALF_SIDE / R]] * 2} for R in radii]
    return sweeps.Study(base={"target": {"name": "sphere_cap"}, "solve": dict(SOLVE)},
                        parameters={"design.layout": list(layouts),
                                    "design.panels": list(panels)},
                        cases=cases)


def machine_busy() -> float:
    """CPU seconds the whole machine has been busy since boot (all cores; /proc/stat)."""
    fields = [float(x) for x in Path("/proc/stat").read_text().split("\n")[0].split()[1:]]
    idle = fields[3] + fields[4]  # idle + iowait
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def own_cpu() -> float:
    """CPU seconds of this process and its finished children (the cluster's workers)."""
    return sum(resource.getrusage(who).ru_utime + resource.getrusage(who).ru_stime
               for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))


def timed(the_study: sweeps.Study, scheduler: str, workers: int, out: Path) -> dict:
    """Wall time, cores used (own and whole machine) and table of the study run with
    ``scheduler`` into the emptied folder ``out``."""
    shutil.rmtree(out, ignore_errors=True)
    t0, cpu0, busy0 = time.perf_counter(), own_cpu(), machine_busy()
    frame = sweeps.run(the_study, out, scheduler=scheduler, workers=workers)
    wall = time.perf_counter() - t0
    return {"wall": wall, "own": (own_cpu() - cpu0) / wall,
            "machine": (machine_busy() - busy0) / wall, "frame": frame}


COLUMNS = ("run", "wall time (s)", "designs/min", "/ serial", "mean per-design time (s)",
           "cores used", "designs/min per core used", "machine busy (cores)", "statuses")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    add_output(parser, "sweep")
    args = parser.parse_args()
    the_study, runs = study(), ROOT / "runs" / "benchmarks" / "sweep"
    if args.smoke:
        the_study = study(radii=RADII[:1], layouts=("zigzag_i",), panels=(4,))
        args.workers, runs = 1, smoke_dir("sweep")
    n = len(the_study.designs())
    run = Run()
    serial = timed(the_study, "none", 1, runs / "serial")
    cluster = timed(the_study, "local", args.workers, runs / "cluster")
    a, b = serial["frame"], cluster["frame"]
    same = list(a["id"]) == list(b["id"]) and list(a["status"]) == list(b["status"])
    both = (a["status"] == "solved") & (b["status"] == "solved")
    rel = (a["rms"][both] - b["rms"][both]).abs() / a["rms"][both]
    same_iterations = int((a["iterations"][both] == b["iterations"][both]).sum())
    rate_s = 60 * n / serial["wall"]
    cells = []
    for label, r in (("serial (scheduler none, this process)", serial),
                     (f"LocalCluster, {args.workers} workers x 1 thread", cluster)):
        frame, rate = r["frame"], 60 * n / r["wall"]
        statuses = ", ".join(f"{k} {v}" for k, v in frame["status"].value_counts().items())
        cells.append([label, f"{r['wall']:.1f}", f"{rate:.1f}", f"{rate / rate_s:.2f}",
                      f"{frame['time'].mean():.2f}", f"{r['own']:.2f}",
                      f"{rate / r['own']:.1f}", f"{r['machine']:.2f}", statuses])
    lines = [*run.preamble("sweep.py"),
             f"- study: {n} designs, sphere caps (patch side {2 * HALF_SIDE:g}): "
             f"{', '.join(sorted({d.case for d in the_study.designs()}))} x "
             "layouts x pattern sizes as in `study()`; IPOPT (sequential), stop_rms off, "
             "max_iter 500; each run from an empty output folder, "
             "writing every result folder and the table after every design",
             "- wall time includes starting the cluster and its workers importing rffqm_nlp; "
             "per-design time = the design's own wall time where it ran (build + solve)",
             "- cores used: CPU seconds of the run's own processes (workers included) / wall "
             "time; machine busy: all processes, from /proc/stat, the load of this run "
             f"included; the difference is other jobs; ideal / serial: {args.workers} on "
             f"{args.workers} free cores", "",
             *markdown_table(COLUMNS, cells), "",
             f"Same table: ids and statuses {'identical' if same else 'DIFFER'}; "
             f"{same_iterations} of {int(both.sum())} designs solved by both took the same "
             f"iterations; largest relative RMS difference {rel.max():.1e}."]
    write_page(output(args, "sweep"), "Sweep", "\n".join(lines))


if __name__ == "__main__":
    main()
