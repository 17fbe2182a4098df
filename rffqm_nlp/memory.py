"""What this machine can hold: the memory still available to this process, and the one-line
refusal, before any work, of a computation whose estimate exceeds it (the design solve,
:func:`rffqm_nlp.design.problem.check_memory`; the side-length programs,
:func:`rffqm_nlp.model.lengths.check_memory`; ``rffqm march``)."""

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
#: package as the command imports them, with a margin (studies/results/march_memory.md).
COMMAND_BASE = 200e6
#: Bytes ``rffqm march`` holds at its peak per panel (the march, the fold and their JSON;
#: ``fold`` re-marches the result it reads), and per vertex and state of ``--frames`` (the
#: states as arrays, lists and JSON text), on top of :data:`COMMAND_BASE`: upper bounds,
#: with a margin, of the peaks measured (studies/results/march_memory.md).
PER_PANEL, PER_STATE = 2600.0, 450.0
#: Bytes ``rffqm render`` holds besides its states and frames (pyvista and VTK too), and
#: per pixel of each frame of folding.gif (the screenshot, its copy in the stack of frames,
#: the encoder's work): upper bounds with a margin (studies/results/march_memory.md).
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
