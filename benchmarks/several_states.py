"""Several states of one sheet: which pairs of shapes can one RFFQM sheet take, and how
closely (docs/several_states.md)?

Pairs of Monge patches z(x, y): a cap z = k (x^2 + y^2) / 2 at two depths (k = 0.3 and a
growing second k), and a cylinder z = k x^2 / 2 (k = 0.3) with a cap of growing k. The
first shape spans [-1, 1]^2; the second spans the footprint that the first's Miura-ori
start takes at omega 1.4 (:data:`SECOND_OMEGA`): a sheet folded into the first at omega0
= 2.0 must shrink or grow that much to reach the second at 1.4, and a shape of the same
size could only be reached at about the same fold. Each pair is designed as one sheet of
two states (the default solve); the baseline is each shape designed alone, the closest
any sheet of these panels comes to it. A ratio near 1 means the shared sheet costs that
state nothing.

    python benchmarks/several_states.py [--panels 12] [--out ...]
    python benchmarks/several_states.py --smoke   (one pair at 8 x 8 panels)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from common import Run, add_output, fmt, markdown_table, output, ratio, write_page  # noqa: E402
import rffqm_nlp as rq  # noqa: E402

COLUMNS = ("pair", "state", "omega", "RMS / diameter, two states", "RMS alone",
           "two states / alone", "time two states (s)", "time alone (s)", "status")
#: The footprint [-1, 1]^2 of every first shape.
FOOTPRINT = ((-1.0, 1.0), (-1.0, 1.0))
#: The fold at which the first shape's Miura-ori start spans the second shape's footprint.
SECOND_OMEGA = 1.4
#: The pairs: (name, (kind, k) of the first shape, (kind, k) of the second).
PAIRS = [(f"cap 0.3 / cap {k:g}", ("cap", 0.3), ("cap", k)) for k in (0.15, 0.45, 0.6, 0.9)]
PAIRS += [(f"cylinder 0.3 / cap {k:g}", ("cylinder", 0.3), ("cap", k)) for k in (0.15, 0.3, 0.6)]


def shape(kind: str, k: float, footprint=FOOTPRINT) -> rq.surfaces.Surface:
    """A cap z = k (x^2 + y^2) / 2 or a cylinder z = k x^2 / 2 over ``footprint``."""
    if kind == "cap":
        return rq.surfaces.Custom(lambda x, y: (x, y, 0.5 * k * (x * x + y * y)), footprint,
                                  name=f"cap {k:g}")
    return rq.surfaces.Custom(lambda x, y: (x, y, 0.5 * k * x * x), footprint,
                              name=f"cylinder {k:g}")


def second_footprint(first: rq.surfaces.Surface, panels: tuple[int, int]) -> tuple:
    """The footprint ((-a, a), (-b, b)) that the Miura-ori start of ``first`` spans at
    :data:`SECOND_OMEGA`: [-1, 1]^2 scaled by its coarse lattice's mean spacings there over
    those at omega0, along i (x) and along j (y)."""
    start = rq.DesignProblem(target=first, panels=panels).start()
    pattern = rq.numpy_model.march(start.boundary)
    spacing = [rq.surfaces.mean_neighbour_distances(rq.shape.coarse_grain(
        rq.numpy_model.fold(pattern, w))) for w in (start.omega, SECOND_OMEGA)]
    a, b = (later / now for later, now in zip(spacing[1], spacing[0]))
    return ((-a, a), (-b, b))


def timed(problem: rq.DesignProblem) -> tuple[rq.DesignResult | None, float, str]:
    """(result or None, seconds, status or the error's first line) of the default solve."""
    t0 = time.perf_counter()
    try:
        result = problem.solve()
    except rq.RffqmError as exc:
        return None, time.perf_counter() - t0, str(exc).splitlines()[0][:80]
    return result, time.perf_counter() - t0, result.stats.status


def rows_of(name: str, first: tuple, second: tuple, panels: tuple[int, int],
            alone: dict) -> list[list[str]]:
    """The two rows (one per state) of a pair; ``alone`` caches each shape's own design."""
    shapes = [shape(*first)]
    shapes.append(shape(*second, footprint=second_footprint(shapes[0], panels)))
    second = (*second, "second")  # the cache's key: the same kind at the second footprint
    for spec, surface in zip((first, second), shapes):
        if spec not in alone:
            alone[spec] = timed(rq.DesignProblem(target=surface, panels=panels))
    two, seconds, status = timed(rq.DesignProblem(target=shapes, panels=panels))
    rows = []
    for k, spec in enumerate((first, second)):
        single, single_time, _ = alone[spec]
        state = None if two is None else two.states[k]
        rms = None if state is None else state.fit.rms
        base = None if single is None else single.fit.rms
        rows.append([name, str(k + 1), fmt(None if state is None else state.omega, ".3f"),
                     fmt(rms, ".2e"), fmt(base, ".2e"), ratio(rms, base, ".2f"),
                     fmt(seconds, ".1f"), fmt(single_time, ".1f"), status])
        print(" | ".join(rows[-1]), flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--panels", type=int, default=12, help="panels a side (even)")
    add_output(parser, "several_states")
    args = parser.parse_args()
    run = Run()
    panels = (8, 8) if args.smoke else (args.panels, args.panels)
    alone: dict = {}
    rows = []
    for name, first, second in PAIRS[:1] if args.smoke else PAIRS:
        rows += rows_of(name, first, second, panels, alone)
    lines = [*run.preamble("several_states.py"),
             f"- {panels[0]} x {panels[1]} panels, the default solve (one BLAS thread as "
             "set by the caller); baseline: each shape designed alone; one run each", "",
             *markdown_table(COLUMNS, rows)]
    write_page(output(args, "several_states"), "Several states of one sheet",
               "\n".join(lines))


if __name__ == "__main__":
    main()
