"""What this machine can hold, and the one memory model of the package.

The memory still available to this process (:func:`available`), the one-line refusal, before
any work, of a computation whose estimate exceeds it (:func:`refuse_beyond`), and every
estimate: the design solve (:func:`design_estimate`, used by
:func:`rffqm_nlp.design.check_memory`), the side-length programs (:func:`lengths_estimate`,
used by :func:`rffqm_nlp.model.lengths.check_memory`) and the commands ``rffqm march``,
``fold`` and ``render``. Each estimate is a model fitted, from above, to peaks measured on
this project's machines (docs/decisions/memory.md, docs/benchmarks/march_memory.md).
"""

from __future__ import annotations

import os
from pathlib import Path

from .errors import InputError

#: bytes every run holds besides its own data (Python, NumPy, SciPy, CasADi and the package):
#: the base of each memory model
BASE = 150e6


def available() -> int | None:
    """Bytes this process can still use: /proc/meminfo's MemAvailable (else the free
    physical pages), lowered to what a cgroup (v2) memory limit leaves; None if unknown."""
    have = None
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    have = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    if have is None:
        try:
            have = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
        except (ValueError, OSError, AttributeError):
            return None
    try:
        limit = Path("/sys/fs/cgroup/memory.max").read_text().strip()
        used = int(Path("/sys/fs/cgroup/memory.current").read_text())
        if limit != "max":
            have = min(have, int(limit) - used)
    except (OSError, ValueError):
        pass
    return max(have, 0)


def gigabytes(size: float) -> str:
    """A size in GB for a message: "0.35", "22", "4.1e5"."""
    gb = size / 1e9
    if gb < 1000:
        return f"{gb:.2g}"
    mantissa, exponent = f"{gb:.1e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def refuse_beyond(need: float, what: str, remedy: str) -> None:
    """Raise one :class:`InputError` line, "<what> needs about X GB; this machine has Y GB
    available; <remedy>", when ``need`` bytes exceed :func:`available` (nothing when it is
    unknown)."""
    have = available()
    if have is not None and need > have:
        raise InputError(f"{what} needs about {gigabytes(need)} GB; this machine has "
                         f"{gigabytes(have)} GB available; {remedy}")


# --------------------------------------------------------------------------- estimates
#: Bytes ``rffqm march`` and ``fold`` hold besides their data: Python, NumPy, SciPy and the
#: package as the command imports them, with a margin (docs/benchmarks/march_memory.md).
COMMAND_BASE = 200e6
#: Bytes ``rffqm march`` holds at its peak per panel (the march, the fold and their JSON;
#: ``fold`` re-marches the result it reads), and per vertex and state of ``--frames`` (the
#: states as arrays, lists and JSON text), on top of :data:`COMMAND_BASE`: upper bounds,
#: with a margin, of the peaks measured (docs/benchmarks/march_memory.md).
PER_PANEL, PER_STATE = 2600.0, 450.0
#: Bytes ``rffqm render`` holds besides its states and frames (pyvista and VTK too), and
#: per pixel of each frame of folding.gif (the screenshot, its copy in the stack of frames,
#: the encoder's work): upper bounds with a margin (docs/benchmarks/march_memory.md).
RENDER_BASE, GIF_PER_PIXEL = 600e6, 14.0


def march_estimate(rows: int, cols: int, frames: int) -> float:
    """Bytes ``rffqm march`` needs for rows x cols panels and ``frames`` states."""
    return (COMMAND_BASE + PER_PANEL * float(rows) * cols
            + PER_STATE * float(frames) * (rows + 1) * (cols + 1))


def states_estimate(N: int, M: int, states: int) -> float:
    """Bytes ``rffqm fold`` needs to write ``states`` folded states of a saved design of
    N x M panels."""
    return march_estimate(N, M, states)


def gif_estimate(N: int, M: int, frames: int, size: tuple[int, int]) -> float:
    """Bytes ``rffqm render`` needs for a folding.gif of ``frames`` states of N x M panels,
    ``size`` (width, height) pixels each."""
    return (RENDER_BASE - COMMAND_BASE + march_estimate(N, M, frames)
            + GIF_PER_PIXEL * float(size[0]) * size[1] * frames)


# --------------------------------------------------------------------------- side lengths
#: Bytes per unit of N M (N + M) (the dense maps: every side by the boundary lengths) that
#: each side-length program holds at its peak, on top of :data:`BASE`: "lp" HiGHS' LPs
#: (:func:`rffqm_nlp.model.lengths.side_length_lp` and the max-min of
#: :func:`rffqm_nlp.model.lengths.side_length_nlp`), "nlp" IPOPT's "uniform" NLP
LENGTHS_PER_UNIT = {"lp": 230.0, "nlp": 1500.0}


def lengths_estimate(N: int, M: int, program: str) -> float:
    """Bytes that a side-length ``program`` ("lp" or "nlp") needs for N x M panels:
    BASE + LENGTHS_PER_UNIT[program] N M (N + M)."""
    return BASE + LENGTHS_PER_UNIT[program] * float(N) * M * (N + M)


# --------------------------------------------------------------------------- the design
#: Bytes per panel that a design solve holds, on top of :data:`BASE`, for each path
#: ("sequential", "simultaneous": IPOPT's transcriptions with MUMPS' factor;
#: "levenberg-marquardt": the NLP, its Jacobians from stencils and their blocks by level),
#: fitted to the peaks measured on the sphere cap, quarter vase and hyperboloid up to
#: 500 x 500 panels ...
DESIGN_PER_PANEL = {"levenberg-marquardt": 18.5e3, "simultaneous": 190e3, "sequential": 250e3}
#: ... the sequential NLP's derivative build on top ...
SEQUENTIAL_BUILD = 700e6
#: ... for Levenberg-Marquardt with a free correspondence this per panel more (the
#: residuals' Jacobian reads the target lattice) ...
FREE_PER_PANEL = 1e3
#: ... and for Levenberg-Marquardt the working set of its sensitivity: about
#: WORKING_SET * (P + Q) rows (the marched unknowns a later level still needs, and the
#: identity over the design variables) by the design variables, 8 bytes each ...
WORKING_SET = 22
#: ... and its dense design x design matrices held at once (J'J, the metric, the secant
#: term, the damped matrix and its factor, the last iteration's, the step QP's copy):
#: counted in the solver, not fitted.
DESIGN_MATRICES = 10


def design_estimate(panels: tuple[int, int], path: str, design: float = 0.0,
                    free: bool = False) -> float:
    """Bytes that a design solve of P x Q ``panels`` needs at its peak on ``path``
    ("levenberg-marquardt", or IPOPT's transcription "simultaneous" or "sequential").

    Levenberg-Marquardt: BASE + (DESIGN_PER_PANEL + FREE_PER_PANEL if ``free``) P Q
    + 8 WORKING_SET (P + Q) n_d + 8 DESIGN_MATRICES n_d^2, for n_d = ``design`` variables;
    IPOPT: BASE + DESIGN_PER_PANEL[path] P Q (+ SEQUENTIAL_BUILD for "sequential")."""
    P, Q = (float(p) for p in panels)
    per_panel = DESIGN_PER_PANEL[path]
    if path != "levenberg-marquardt":
        return BASE + per_panel * P * Q + (SEQUENTIAL_BUILD if path == "sequential" else 0.0)
    per_panel += FREE_PER_PANEL if free else 0.0
    return (BASE + per_panel * P * Q + 8.0 * WORKING_SET * (P + Q) * design
            + 8.0 * DESIGN_MATRICES * design ** 2)
