"""The options the commands share and how they are checked before any work: paths no file
can have (:func:`check_path`), the numeric ranges their help says, --frames
(:func:`check_frames`) and --panels "2N 2M" (:class:`PanelsCommand`)."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Optional

from typer.core import TyperCommand

from ..errors import InputError
from ..files import Key, check_value


#: Folding states stored in pattern.fold and drawn in folding.gif by ``design``.
FRAMES = 24
#: The interactive view (rffqm_nlp.show.view) and the curvature maps that ``design`` writes.
VIEW_FILE = "view.html"
#: Help of the --trust option of the commands that read a target file.
TRUST_HELP = ("Let the file run the code its target names (python = \"file.py:function\" or "
              "\"package.module:function\"), name files and libraries for IPOPT "
              "(output_file, hsllib, ...) and name files outside its folder; only for files "
              "you trust (docs/files_from_others.md).")
#: Most states of any --frames (fold, render, view, march).
MAX_FRAMES = 1000
#: Most worker processes of ``sweep --scheduler local``.
MAX_WORKERS = 256
#: Longest path an argument or option takes, and longest name in it, in bytes (Linux's
#: PATH_MAX and NAME_MAX); an output's own name leaves :data:`OUT_ROOM` more for the
#: temporary names written next to it (".<name>.staging-<pid>-<token>").
MAX_PATH, MAX_NAME, OUT_ROOM = 4096, 255, 40
#: The numeric options' ranges (their help says them): the fold parameter, march's seed,
#: perturbation (radians), Miura sides and acute angle, and panels a side.
OMEGA = Key("number", low=-math.pi, high=math.pi, hint="(radians: [-pi, pi])")
SEED = Key("whole", low=0, high=2**63 - 1)
PERTURB = Key("number", low=0.0, high=math.pi / 2, hint="(radians)")
SIDE = Key("number", low=1e-6, high=1e6, hint="(a length)")
ACUTE = Key("number", low=0.0, high=math.pi / 2, low_open=True, high_open=True,
            hint="(radians)")
PANELS = Key("whole", low=1, high=100_000)


def check_path(path: Optional[Path], name: str, output: bool = False) -> None:
    """Refuse, in one line, a path that no file can have: with a NUL character, characters
    the file system cannot encode, longer than :data:`MAX_PATH` bytes or with a name longer
    than :data:`MAX_NAME` (an ``output`` path's own name :data:`OUT_ROOM` less). Nothing
    for None."""
    if path is None:
        return
    text = os.fspath(path)
    if "\x00" in text:
        raise InputError(f"{name} {text}: a path cannot hold a NUL character")
    try:
        raw = os.fsencode(os.path.abspath(text))
    except (UnicodeError, ValueError):
        raise InputError(f"{name} {text}: characters the file system cannot encode") from None
    names = raw.split(b"/")
    longest = max(len(part) for part in names)
    last = MAX_NAME - OUT_ROOM if output else MAX_NAME
    if len(raw) > MAX_PATH or longest > MAX_NAME or len(names[-1]) > last:
        raise InputError(f"{name} {text}: too long a path ({len(raw)} bytes, a name of "
                         f"{max(longest, len(names[-1]))}); paths take at most {MAX_PATH} "
                         f"bytes, names {MAX_NAME} (an output's {MAX_NAME - OUT_ROOM})")


def check_frames(frames: int, minimum: int, name: str = "--frames") -> int:
    """A --frames option: a whole number from ``minimum`` to :data:`MAX_FRAMES`."""
    return check_value(frames, Key("whole", low=minimum, high=MAX_FRAMES), name)


def parse_panels(text: str) -> tuple[int, int]:
    """"8,8", "8 8" or "8x8" -> (8, 8)."""
    parts = [p for p in re.split(r"[,\sx]+", text.strip()) if p]
    try:
        values = tuple(int(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 2:
        raise InputError(f"--panels takes two even numbers 2N 2M (or 2N,2M), got {text!r}")
    return values  # type: ignore[return-value]


class PanelsCommand(TyperCommand):
    """A command whose ``--panels`` option takes "2N 2M" (two words) as well as "2N,2M"."""

    def parse_args(self, ctx, args: list[str]) -> list[str]:
        joined: list[str] = []
        i = 0
        while i < len(args):
            if args[i] == "--":
                joined.extend(args[i:])
                break
            if (args[i] == "--panels" and i + 2 < len(args)
                    and re.fullmatch(r"\d+", args[i + 1])
                    and re.fullmatch(r"\d+", args[i + 2])):
                joined += ["--panels", f"{args[i + 1]},{args[i + 2]}"]
                i += 3
                continue
            joined.append(args[i])
            i += 1
        return super().parse_args(ctx, joined)
