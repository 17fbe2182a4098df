"""The two transcriptions side by side: the three bundled targets, 8-16 panels a side, both
Miura layouts, each solved to IPOPT's tolerance (stop_rms=None) by the sequential and the
simultaneous NLP from the same Miura start, in one process, one after the other (one BLAS
thread, CasADi's OpenBLAS included). Reports status, iterations, objective, RMS/diameter
and wall time of ``DesignProblem.solve()`` (build included), and the sequential /
simultaneous time ratio.
Writes studies/results/compare_transcriptions.md.

    python studies/compare_transcriptions.py [--sizes 8 12 16] [--time-limit 60]
    python studies/compare_transcriptions.py --smoke   (the sphere cap at 4 x 4, one layout,
        temporary output)
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

from common import RESULTS, TARGETS, Run, add_smoke, smoke_dir, target_problem, write_table
from rffqm_nlp.design.problem import DesignProblem, SolveOptions
from rffqm_nlp.errors import RffqmError
from rffqm_nlp.sweeps import one_thread

LAYOUTS = ("zigzag_i", "zigzag_j")
TRANSCRIPTIONS = ("sequential", "simultaneous")


def solve(prob: DesignProblem, options: SolveOptions) -> dict:
    t0 = time.perf_counter()
    try:
        res = prob.solve(options)
    except RffqmError as exc:
        return {"status": type(exc).__name__ + ": " + str(exc).split(";")[0][:60],
                "wall": time.perf_counter() - t0}
    return {"status": res.stats.status, "iterations": res.stats.iterations,
            "objective": res.stats.objective, "rms": res.fit.rms,
            "wall": time.perf_counter() - t0}


def cell(r: dict) -> str:
    if "objective" not in r:
        return f"{r['status']} | - | - | - | {r['wall']:.1f}"
    return (f"{r['status']} | {r['iterations']} | {r['objective']:.6g} | "
            f"{100 * r['rms']:.2f}% | {r['wall']:.1f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[8, 12, 16])
    ap.add_argument("--time-limit", type=float, default=60.0, help="IPOPT seconds per solve")
    ap.add_argument("--out", type=Path, default=RESULTS / "compare_transcriptions.md")
    add_smoke(ap)
    args = ap.parse_args()
    targets, layouts = TARGETS, LAYOUTS
    if args.smoke:
        args.sizes, targets, layouts = [4], TARGETS[:1], LAYOUTS[:1]
        args.out = smoke_dir("compare_transcriptions") / "compare_transcriptions.md"
    run = Run()
    rows = []
    with one_thread():  # CasADi's OpenBLAS under MUMPS included
        for name in targets:
            for n in args.sizes:
                for layout in layouts:
                    prob, options = target_problem(name, n, layout=layout)
                    options = replace(options, stop_rms=None, time_limit=args.time_limit,
                                      hessian="exact", solver="ipopt")
                    seq, sim = (solve(prob, replace(options, transcription=tr))
                                for tr in TRANSCRIPTIONS)
                    ratio = (f"{seq['wall'] / sim['wall']:.1f}x"
                             if "objective" in seq and "objective" in sim else "-")
                    rows.append(f"| {name} | {n}x{n} | {layout} | {cell(seq)} | {cell(sim)} "
                                f"| {ratio} |")
                    print(rows[-1], flush=True)
    header = [
        "# Sequential against simultaneous transcription (`studies/compare_transcriptions.py`)",
        "",
        f"- {run.header()}; one BLAS thread",
        f"- targets/*.toml at n x n panels, both layouts, stop_rms=None, default options, "
        f"IPOPT time limit {args.time_limit:g} s per solve; time = wall time of "
        "`DesignProblem.solve()` including the build; ratio = sequential time / simultaneous "
        "time (both converged)",
        "",
        "| target | panels | layout | seq. status | seq. it | seq. objective | seq. RMS/diam "
        "| seq. time [s] | sim. status | sim. it | sim. objective | sim. RMS/diam "
        "| sim. time [s] | ratio |",
        "|" + "---|" * 14,
    ]
    text = "\n".join(header + rows) + "\n"
    write_table(args.out, text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
