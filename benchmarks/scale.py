"""Scale: time and peak memory of the default solve (Levenberg-Marquardt) against size.

A bundled target (``--target``, default the sphere cap) at n x n panels for each of
``--sizes``, solved to ``--stop-rms`` (default 0.9% RMS/diameter, ``common.STOP_RMS``), each
run ``DesignProblem.solve()`` in a fresh subprocess so that its time and peak memory are its
own. The baseline solves the same problems in the same run at the sizes of
``--baseline-sizes`` (those where it fits in time and memory): IPOPT (``--baseline ipopt``,
the default: the same options with ``solver = "ipopt"``), or the code of a git revision
(``--baseline REV``), or none. ``--correspondence`` sets the design's (default: the target
file's). A size whose memory estimate (``rq.design.memory_estimate``) exceeds what the
machine has is reported as refused, not run. The table gives the log-log slopes of wall time
and of peak memory between consecutive sizes, against the number of panels n^2, and this
code's wall time and memory over the baseline's.

    python benchmarks/scale.py [--sizes 20 40 100 200] [--baseline ipopt|none|REV]
        [--baseline-sizes 20 40] [--target sphere_cap] [--correspondence lattice]
        [--stop-rms 0.009] [--time-limit 3600] [--out docs/benchmarks/scale.md]
    python benchmarks/scale.py --smoke   (4 and 6 panels, IPOPT at 4, temporary output)
"""

from __future__ import annotations

import argparse
import math
from dataclasses import replace
from pathlib import Path

from common import (STOP_RMS, TARGETS, Run, add_output, export_package, fmt, markdown_table,
                    output, ratio, solve_in_child, target_problem, write_page)
from rffqm_nlp import InputError, design
from rffqm_nlp.errors import one_line

COLUMNS = ("code", "panels", "status", "iterations", "build [s]", "wall [s]", "RMS/diam",
           "peak RSS [MB]", "slope of wall", "slope of memory", "wall / baseline",
           "memory / baseline")


def run(target: str, n: int, solve: dict, package: Path | None, overrides: dict) -> dict:
    """One solve in a fresh process (``solve``: [solve] keys; ``package``: the exported code
    of an earlier revision, None for this one; ``overrides``: [design] keys); refused without
    running when this revision's ``design.check_memory`` refuses it with the child's
    options."""
    if package is None:
        problem, options = target_problem(target, n, **overrides)
        try:
            design.check_memory(problem, replace(options, **solve))
        except InputError as exc:
            return {"n": n, "status": f"refused: {one_line(exc)}", "wall": None,
                    "peak_rss_mb": None}
    env = None if package is None else {"PYTHONPATH": str(package)}
    return solve_in_child(target, n, design=overrides or None, solve=solve, env=env)


def slope(a: dict | None, b: dict, key: str) -> str:
    """d log(b[key]) / d log(n^2) between the runs a and b."""
    if a is None or not a.get(key) or not b.get(key):
        return "-"
    return f"{math.log(b[key] / a[key]) / math.log(b['n'] ** 2 / a['n'] ** 2):.2f}"


def table(rows: list[dict]) -> list[str]:
    """The results table: this code's rows, then the baseline's; the slopes from the size
    above in the same code, the ratios to the baseline at the same size."""
    base = {r["n"]: r for r in rows if r["code"] != "this"}
    cells, last = [], {}
    for r in rows:
        fit = r.get("fit") or {}
        ok = r.get("wall") is not None
        before, other = last.get(r["code"]), base.get(r["n"], {}) if r["code"] == "this" else {}
        cells.append([
            r["code"], f"{r['n']} x {r['n']}", r["status"], fmt(r.get("iterations"), "d"),
            fmt(r.get("build_time"), ".1f"), fmt(r.get("wall"), ".1f"),
            fmt(100 * fit["rms"] if "rms" in fit else None, ".2f") + "%",
            fmt(r.get("peak_rss_mb"), ".0f"),
            slope(before, r, "wall") if ok else "-",
            slope(before, r, "peak_rss_mb") if ok else "-",
            ratio(r.get("wall"), other.get("wall")),
            ratio(r.get("peak_rss_mb"), other.get("peak_rss_mb"))])
        if ok:
            last[r["code"]] = r
    return markdown_table(COLUMNS, cells)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="*", default=[20, 40, 100, 200])
    ap.add_argument("--baseline", default="ipopt", help="ipopt, none, or a git revision")
    ap.add_argument("--baseline-sizes", type=int, nargs="*", default=[20, 40])
    ap.add_argument("--target", default="sphere_cap", choices=TARGETS)
    ap.add_argument("--correspondence", default=None, choices=["free", "lattice"])
    ap.add_argument("--stop-rms", type=float, default=STOP_RMS)
    ap.add_argument("--time-limit", type=float, default=3600.0)
    add_output(ap, "scale")
    args = ap.parse_args()
    if args.smoke:
        args.sizes, args.baseline, args.baseline_sizes = [4, 6], "ipopt", [4]
    clock = Run()
    solve = {"stop_rms": args.stop_rms, "time_limit": args.time_limit}
    codes: dict[str, tuple[Path | None, dict]] = {"this": (None, solve)}
    if args.baseline == "ipopt":
        codes["ipopt"] = (None, {**solve, "solver": "ipopt"})
    elif args.baseline != "none":
        codes[args.baseline] = (export_package(args.baseline), solve)
    overrides = {} if args.correspondence is None else {"correspondence": args.correspondence}
    rows = []
    for n in args.sizes:
        for code, (package, options) in codes.items():
            if code != "this" and n not in args.baseline_sizes:
                continue
            r = run(args.target, n, options, package, overrides)
            r.update(code=code, n=n)
            rows.append(r)
            print({k: r.get(k) for k in ("code", "n", "status", "iterations", "wall",
                                         "peak_rss_mb")}, flush=True)
    rows.sort(key=lambda r: (r["code"] != "this", r["n"]))
    text = "\n".join([
        *clock.preamble("scale.py"),
        f"- {args.target} to {100 * args.stop_rms:.1f}% RMS/diameter"
        + ("" if not overrides else f", {args.correspondence} correspondence")
        + "; code: this revision, `ipopt` (this revision with IPOPT), or the revision named. "
        "wall: seconds of `prob.solve()` (transcription, derivative build, solve, re-march "
        "and fit); peak RSS: the run's own process; slopes: d log / d log(panels) from the "
        "size above; ratios: this code over the baseline at the same size", "",
        *table(rows)])
    write_page(output(args, "scale"), "Scale", text)


if __name__ == "__main__":
    main()
