"""``rffqm check``: self-contact of a saved design or a FOLD file along its motion, like a
linter (exit status 1 when not free)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from ..design.results import DesignResult
from ..files import Key, check_value
from .options import OMEGA, check_path
from .output import quantity_table, user_errors


#: Panel pairs listed per row of the ``check`` table before "... and n more".
CHECK_PAIRS = 8


def check_cmd(
    source: Path = typer.Argument(..., help="A saved design (its folder or result.json) or "
                                  "a FOLD file written by rffqm (.fold).", show_default=False),
    clearance: float = typer.Option(0.0, "--clearance", help="Distance (a sheet thickness, "
                                    "in the pattern's length units) that panels sharing no "
                                    "vertex must keep, from 0 (they must not touch) to "
                                    "below the pattern's shortest side."),
    omega: Optional[float] = typer.Option(None, "--omega", help="Check the motion from flat "
                                          "to this fold parameter in [-pi, pi] (default: the "
                                          "design's omega)."),
    thickness: Optional[float] = typer.Option(None, "--thickness", help="Check tapered "
                                              "panels of this thickness (in the pattern's "
                                              "length units) instead of the zero-thickness "
                                              "sheet (rffqm make's panels)."),
) -> None:
    """Check a design for self-contact, like a linter.

    Prints the panels that overlap in the flat pattern, the first omega at which two panels
    that share no vertex touch (or come closer than --clearance) while folding from flat
    to omega, and the pairs in contact there (1-based (i, j) panels). With --thickness the
    panels are the tapered solids of that thickness that ``rffqm make`` writes
    (:func:`rffqm_nlp.contact.thick.thick_collisions`: panels sharing a vertex too).
    Exit status 0 when the motion is free, 1 when it is not, 2 on bad input.
    """
    from ..contact.collisions import collisions
    from ..contact.thick import thick_collisions

    with user_errors():
        check_path(source, "SOURCE")
        om = None if omega is None else check_value(omega, OMEGA, "--omega")
        clearance = check_value(clearance, Key("number", low=0.0), "--clearance")
        pattern, designed = _design_to_check(source)
        om = designed if om is None else om
        shortest = float(min(np.min(pattern.lh), np.min(pattern.lv)))
        check_value(clearance, Key("number", low=0.0, high=shortest, high_open=True,
                                   hint="(below the pattern's shortest side)"), "--clearance")
        if thickness is None:
            report = collisions(pattern, om, clearance=clearance)
        else:
            thick = thick_collisions(pattern, om, check_value(
                thickness, Key("number", low=0.0, low_open=True), "--thickness"))
    if thickness is None:
        Console().print(_check_table(report, source))
        raise typer.Exit(0 if report.free else 1)
    Console().print(_thick_table(thick, source))
    raise typer.Exit(0 if thick.free else 1)


def _design_to_check(source: Path) -> tuple:
    """(pattern, omega) of a FOLD file (by its suffix .fold) or a saved design result."""
    if source.suffix.lower() == ".fold":
        from ..io.foldfile import read_fold

        pattern, omega, _ = read_fold(source)
        return pattern, omega
    result = DesignResult.load(source)
    return result.pattern, result.omega


def _pairs_text(pairs: list) -> str:
    """"(1, 2)-(3, 4), ..." for at most CHECK_PAIRS pairs, "none" for none."""
    if not pairs:
        return "none"
    text = ", ".join(f"({a[0]}, {a[1]})-({b[0]}, {b[1]})" for a, b in pairs[:CHECK_PAIRS])
    return text + (f" and {len(pairs) - CHECK_PAIRS} more" if len(pairs) > CHECK_PAIRS else "")


def _check_table(report, source: Path) -> Table:
    """The ``check`` summary of a :class:`~rffqm_nlp.contact.collisions.CollisionReport`."""
    first = "none" if report.first_omega is None else f"{report.first_omega:.6g}"
    return quantity_table(f"self-contact: {source}", [
        ("motion checked", f"omega from 0 to {report.omega_max:.6g}"),
        ("clearance", f"{report.clearance:g}"),
        ("panels overlapping when flat", _pairs_text(report.flat_overlaps)),
        ("first contact at omega", first),
        ("panel pairs in contact there", _pairs_text(report.pairs)),
        ("collision-free", "yes" if report.free else "no")])


def _thick_table(report, source: Path) -> Table:
    """The ``check --thickness`` summary of a
    :class:`~rffqm_nlp.contact.thick.ThickReport`."""
    first = "none" if report.first_omega is None else f"{report.first_omega:.6g}"
    return quantity_table(f"self-contact of thick panels: {source}", [
        ("motion checked", f"omega from 0 to {report.omega_max:.6g}"),
        ("thickness", f"{report.thickness:g}"),
        ("panels overlapping when flat", _pairs_text(report.far.flat_overlaps)),
        ("panel pairs sharing a vertex followed", str(report.vertex_pairs_checked)),
        ("first contact at omega", first),
        ("panel pairs in contact there", _pairs_text(report.pairs)),
        ("collision-free", "yes" if report.free else "no")])
