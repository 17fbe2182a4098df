"""Throughput of a 32-design sweep: serially in one process against a LocalCluster of 2
single-threaded worker processes, in the same run.

The study: sphere caps of 8 radii (a patch of side 3.2, |u|, |v| <= 1.6 / R) x both Miura
layouts x 6 x 6 and 8 x 8 panels, default options, IPOPT to its tolerance (stop_rms off).
Both runs start from an empty output folder (runs/bench_sweep/serial and .../cluster); the
cluster's wall time includes starting it. Each run also reports the CPU cores it used
(its own processes' CPU time, workers included, over its wall time) and the cores the whole
machine was busy (from /proc/stat), so that other jobs on the machine show. Prints a table
of designs per minute and the ratio, checks that both runs give the same table, and writes
studies/results/bench_sweep.md.

    python studies/bench_sweep.py [--workers 2]
    python studies/bench_sweep.py --smoke   (one design at 4 x 4 panels, 1 worker, temporary
        output)
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import time
from pathlib import Path

from common import RESULTS, ROOT, Run, add_smoke, smoke_dir, write_table
from rffqm_nlp import sweeps

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--results", type=Path, default=RESULTS)
    add_smoke(parser)
    args = parser.parse_args()
    the_study, runs = study(), ROOT / "runs" / "bench_sweep"
    if args.smoke:
        the_study = study(radii=RADII[:1], layouts=("zigzag_i",), panels=(4,))
        args.workers, runs = 1, smoke_dir("bench_sweep")
        args.results = runs / "results"
    n = len(the_study.designs())
    run = Run()
    serial = timed(the_study, "none", 1, runs / "serial")
    cluster = timed(the_study, "local", args.workers, runs / "cluster")
    a, b = serial["frame"], cluster["frame"]
    same = list(a["id"]) == list(b["id"]) and list(a["status"]) == list(b["status"])
    both = (a["status"] == "solved") & (b["status"] == "solved")
    rel = (a["rms"][both] - b["rms"][both]).abs() / a["rms"][both]
    same_iterations = int((a["iterations"][both] == b["iterations"][both]).sum())
    rate_s, rate_c = 60 * n / serial["wall"], 60 * n / cluster["wall"]
    rows = [("serial (scheduler none, this process)", serial, rate_s),
            (f"LocalCluster, {args.workers} workers x 1 thread", cluster, rate_c)]
    lines = ["# Sweep throughput (`studies/bench_sweep.py`)", "",
             f"- {run.header()} (the load includes this run's own processes)",
             f"- study: {n} designs, sphere caps (patch side {2 * HALF_SIDE:g}): "
             f"{', '.join(sorted({d.case for d in the_study.designs()}))} x "
             "layouts x pattern sizes as in `study()`; IPOPT (sequential), stop_rms off, "
             "max_iter 500; each run from an empty output folder, "
             "writing every result folder and the table after every design",
             "- wall time includes starting the cluster and its workers importing rffqm_nlp; "
             "per-design time = the design's own wall time where it ran (build + solve)",
             "- cores used: CPU seconds of the run's own processes (workers included) / wall "
             "time; machine busy: all processes, from /proc/stat; the difference is other jobs",
             "",
             "| run | wall time (s) | designs/min | mean per-design time (s) | cores used "
             "| designs/min per core used | machine busy (cores) | statuses |",
             "|---|---|---|---|---|---|---|---|"]
    for label, r, rate in rows:
        frame = r["frame"]
        statuses = ", ".join(f"{k} {v}" for k, v in frame["status"].value_counts().items())
        lines.append(f"| {label} | {r['wall']:.1f} | {rate:.1f} | {frame['time'].mean():.2f} "
                     f"| {r['own']:.2f} | {rate / r['own']:.1f} | {r['machine']:.2f} "
                     f"| {statuses} |")
    lines += ["", f"Throughput ratio cluster / serial: **{rate_c / rate_s:.2f}x** "
              f"(ideal {args.workers}x on {args.workers} free cores); per core used "
              f"{(rate_c / cluster['own']) / (rate_s / serial['own']):.2f}.", "",
              f"Same table: ids and statuses {'identical' if same else 'DIFFER'}; "
              f"{same_iterations} of {int(both.sum())} designs solved by both took the same "
              f"iterations; largest relative RMS difference {rel.max():.1e}."]
    text = "\n".join(lines) + "\n"
    write_table(args.results / "bench_sweep.md", text)


if __name__ == "__main__":
    main()
