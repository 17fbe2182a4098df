"""Scale: time and peak memory of the default solver (Levenberg-Marquardt) against size.

A bundled target (``--target``, default the sphere cap) at n x n panels for each of
``--sizes``, solved to ``--stop-rms`` (default 0.9% RMS/diameter, ``common.STOP_RMS``), each
run ``DesignProblem.solve()`` in a fresh subprocess so that its time and peak memory are its
own. With ``--previous REV`` the code of that git revision solves the same problems in the
same run, at the sizes of ``--previous-sizes`` (those where it fits in memory);
``--correspondence`` sets the design's (default: the target file's). A size whose
memory estimate (``design.memory_estimate``) exceeds what the machine has is reported as
refused, not run. The table gives the log-log slopes of wall time and of peak memory
between consecutive sizes, against the number of panels n^2.

    python studies/scale.py [--sizes 20 40 100 200] [--previous REV --previous-sizes 20 40 100]
        [--target sphere_cap] [--correspondence lattice] [--stop-rms 0.009] [--time-limit 3600]
        [--out studies/results/scale.md]
    python studies/scale.py --smoke   (4 and 8 panels, temporary output)
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

from common import (RESULTS, STOP_RMS, TARGETS, Run, add_smoke, export_package, fmt,
                    smoke_dir, solve_in_child, target_problem, write_table)
from rffqm_nlp.design import problem as design
from rffqm_nlp.errors import InputError, one_line


def run(target: str, n: int, stop_rms: float, time_limit: float,
        package: Path | None, overrides: dict) -> dict:
    """One solve in a fresh process (``package``: the exported code of an earlier
    revision, None for this one; ``overrides``: [design] keys); refused without running when
    this revision's :func:`rffqm_nlp.design.problem.check_memory` refuses it with the child's
    options (the target file's, stopping at ``stop_rms``)."""
    if package is None:
        problem, options = target_problem(target, n, **overrides)
        try:
            design.check_memory(problem, replace(options, stop_rms=stop_rms))
        except InputError as exc:
            return {"n": n, "status": f"refused: {one_line(exc)}", "wall": None,
                    "peak_rss_mb": None}
    env = None if package is None else {"PYTHONPATH": str(package)}
    return solve_in_child(target, n, design=overrides or None,
                          solve={"stop_rms": stop_rms, "time_limit": time_limit}, env=env)


def slope(a: dict | None, b: dict, key: str) -> str:
    """d log(b[key]) / d log(n^2) between the runs a and b."""
    if a is None or not a.get(key) or not b.get(key):
        return "-"
    return f"{math.log(b[key] / a[key]) / math.log(b['n'] ** 2 / a['n'] ** 2):.2f}"


def table(rows: list[dict]) -> list[str]:
    lines = ["| code | panels | status | iterations | build [s] | wall [s] | RMS/diam | "
             "peak RSS [MB] | slope of wall | slope of memory |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    last: dict[str, dict | None] = {}
    for r in rows:
        fit = r.get("fit") or {}
        ok = r.get("wall") is not None
        before = last.get(r["code"])
        lines.append(
            f"| {r['code']} | {r['n']} x {r['n']} | {r['status']} | "
            f"{fmt(r.get('iterations'), 'd')} | {fmt(r.get('build_time'), '.1f')} | "
            f"{fmt(r.get('wall'), '.1f')} | "
            f"{fmt(100 * fit['rms'] if 'rms' in fit else None, '.2f')}% | "
            f"{fmt(r.get('peak_rss_mb'), '.0f')} | "
            f"{slope(before, r, 'wall') if ok else '-'} | "
            f"{slope(before, r, 'peak_rss_mb') if ok else '-'} |")
        if ok:
            last[r["code"]] = r
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 40, 100, 200])
    ap.add_argument("--previous", default=None)
    ap.add_argument("--previous-sizes", type=int, nargs="*", default=[20, 40, 100])
    ap.add_argument("--target", default="sphere_cap", choices=TARGETS)
    ap.add_argument("--correspondence", default=None, choices=["free", "lattice"])
    ap.add_argument("--stop-rms", type=float, default=STOP_RMS)
    ap.add_argument("--time-limit", type=float, default=3600.0)
    ap.add_argument("--out", type=Path, default=RESULTS / "scale.md")
    add_smoke(ap)
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.previous = [4, 8], None
        args.out = smoke_dir("scale") / "scale.md"
    clock = Run()
    packages = {"this": None}
    if args.previous:
        packages[args.previous] = export_package(args.previous)
    overrides = {} if args.correspondence is None else {"correspondence": args.correspondence}
    rows = []
    for n in args.sizes:
        for code, package in packages.items():
            if package is not None and n not in args.previous_sizes:
                continue
            r = run(args.target, n, args.stop_rms, args.time_limit, package, overrides)
            r.update(code=code, n=n)
            rows.append(r)
            print({k: r.get(k) for k in ("code", "n", "status", "iterations", "wall",
                                         "peak_rss_mb")}, flush=True)
    rows.sort(key=lambda r: (r["code"] != "this", r["n"]))
    text = "\n".join([
        f"# Scale: {args.target} to {100 * args.stop_rms:.1f}% RMS/diameter"
        + ("" if not overrides else f", {args.correspondence} correspondence"), "",
        clock.header(), "",
        "Command: `" + " ".join(["python studies/scale.py", *sys.argv[1:]]) + "`", "",
        "code: this revision, or the revision named. wall: seconds of `prob.solve()` "
        "(transcription, derivative build, solve, re-march and fit); peak RSS: the run's own "
        "process; slopes: d log / d log(panels) from the size above.", "",
        *table(rows), ""])
    write_table(args.out, text)


if __name__ == "__main__":
    main()
