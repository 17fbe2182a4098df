"""What this machine can hold: the memory still available to this process, and the one-line
refusal, before any work, of a computation whose estimate exceeds it (the design solve,
:func:`rffqm_nlp.design.check_memory`; the side-length programs,
:func:`rffqm_nlp.lengths.check_memory`; ``rffqm march``)."""

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
