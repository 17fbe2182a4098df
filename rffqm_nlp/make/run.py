"""From a design to the files that make it: :func:`make` computes everything (the sheet at
its size, the thick panels and their check along the motion, the lock) and
:meth:`Made.write` writes the folder whole.

The folder holds cut.svg, cut.dxf, cut.pdf, cut_back.svg, cut_back.dxf, fold_angles.csv
(:mod:`.cut_files`), assembly.pdf (:mod:`.assembly`), panels.stl, panels_flat.stl,
panels.glb (:mod:`.solids`), lock.csv, stops.csv, lock.stl (:mod:`.parts`) and
make.json (the options and what was measured).
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..contact.thick import ThickReport, thick_collisions
from ..design.results import DesignResult
from ..errors import InputError
from ..files import check_out_dir, replace_folder, write_json
from ..model.numpy_model import fold
from .assembly import write_assembly
from .cut_files import write_cut_files
from .lock import Stop, Tie, crease_stops, lock_ties
from .options import MakeOptions, make_options, read_make_table
from .parts import write_lock_files
from .sheet import Sheet, cut_outline
from .solids import Solids, build_solids, write_panels

#: The summary file of a made folder.
SUMMARY = "make.json"


@dataclass(frozen=True)
class Made:
    """A design ready to make (all lengths in mm).

    ``result`` the design; ``options`` (:class:`~.options.MakeOptions`); ``sheet`` the
    flat pattern at its size (:class:`~.sheet.Sheet`); ``solids`` the thick panels
    (:class:`~.solids.Solids`); ``thick`` their check from flat to the designed state
    (:class:`~rffqm_nlp.contact.thick.ThickReport`, in the pattern's units); ``ties`` and
    ``stops`` the lock (:mod:`.lock`); ``files`` the names :meth:`write` wrote.
    """

    result: DesignResult
    options: MakeOptions
    sheet: Sheet
    solids: Solids
    thick: ThickReport
    ties: list[Tie]
    stops: list[Stop]
    files: list[str] = field(default_factory=list)

    @property
    def scale(self) -> float:
        """Millimetres per unit of the pattern."""
        return self.sheet.scale

    def summary(self) -> dict[str, Any]:
        """What make.json holds: the options, the size, the thick panels' volumes and
        check, the lock."""
        ratios = self.solids.volume_ratios
        return {"options": self.options.to_dict(), "scale_mm_per_unit": self.scale,
                "size_mm": list(self.sheet.size), "creases": len(self.sheet.kinds),
                "panels": {"side": "back" if self.solids.side < 0 else "front",
                           "thickness_mm": self.solids.thickness,
                           "volume_over_area_times_thickness": {
                               "min": float(ratios.min()), "mean": float(ratios.mean())}},
                "thick_check": self.thick.to_dict(),
                "ties": [vars(t) for t in self.ties], "stops": [vars(s) for s in self.stops],
                "omega": self.result.omega}

    def write_into(self, folder: str | os.PathLike) -> list[Path]:
        """Write every file (see the module) into the existing ``folder``, each
        atomically; their paths."""
        folder = Path(folder)
        result, sheet = self.result, self.sheet
        pat, omega = result.pattern, result.omega
        origin = pat.X[..., :2].reshape(-1, 2).min(axis=0)
        notes = _notes(self)
        paths = [*write_cut_files(folder, sheet, self.options),
                 write_assembly(folder / "assembly.pdf", sheet,
                                cut_outline(sheet, self.options.kerf),
                                fold(pat, omega) * self.scale, pat.N, pat.M,
                                self.options.paper, notes),
                 *write_panels(folder, self.solids, pat, omega, self.scale, origin),
                 *write_lock_files(folder, self.ties, self.stops, self.options.thickness)]
        paths.append(write_json(folder / SUMMARY, self.summary(), indent=1))
        return paths

    def write(self, out: str | os.PathLike, force: bool = False) -> Made:
        """Write the folder ``out`` whole (:func:`rffqm_nlp.files.replace_folder`): new
        or empty, or replaced when ``force``; returns this with its ``files``."""
        out = Path(out)
        check_out_dir(out, force)
        with replace_folder(out) as tmp:
            paths = self.write_into(tmp)
        return Made(**{**vars(self), "files": [p.name for p in paths]})


def _notes(made: Made) -> list[str]:
    """The first page's lines of assembly.pdf."""
    o, (W, H) = made.options, made.sheet.size
    lines = [f"sheet {W:.1f} x {H:.1f} mm, {made.scale:.4g} mm per pattern unit; "
             f"thickness {o.thickness:g} mm; process {o.process}",
             f"{len(made.sheet.kinds)} creases numbered as in fold_angles.csv "
             "(red mountain, blue valley)",
             "fold every crease to its angle_deg; the designed shape is reached when the "
             "lock fits:"]
    lines += [f"  tie ({t.i1},{t.j1})-({t.i2},{t.j2}): {t.length:.2f} mm" for t in made.ties]
    return lines


def _result(result: Any) -> DesignResult:
    if isinstance(result, DesignResult):
        return result
    if isinstance(result, (str, os.PathLike)):
        return DesignResult.load(result)
    raise InputError("result must be a DesignResult or the folder of a saved one, got "
                     f"a {type(result).__name__}")


def make(result: DesignResult | str | os.PathLike, out: str | os.PathLike | None = None, *,
         config: str | os.PathLike | None = None, force: bool = False,
         **options: Any) -> Made:
    """Make a design: its sheet at a physical size, thick panels that fold, a lock.

    ``result``: a :class:`~rffqm_nlp.design.results.DesignResult` or the folder of a saved
    one; ``config``: a TOML file with a [make] table; ``options``: the keys of
    :data:`~.options.MAKE_KEYS` (width, height or scale; thickness; process; kerf, dash,
    gap, corner_relief, hinge_gap; side; paper; ties), lengths in mm or as "300mm"; they
    override the table's. With ``out`` the files are written there (a new or empty
    folder, or replaced whole when ``force``). Returns :class:`Made`. Every refusal is one
    :class:`~rffqm_nlp.errors.InputError` line.
    """
    result = _result(result)
    table = read_make_table(config) if config is not None else None
    opts = make_options(table, **options)
    pat, omega = result.pattern, result.omega
    extent = tuple(np.ptp(pat.X[..., :2].reshape(-1, 2), axis=0))
    sheet = Sheet.of(pat, omega, opts.mm_per_unit(extent))
    scale = sheet.scale
    solids = build_solids(pat, omega, scale, opts.thickness, opts.side, opts.hinge_gap)
    thick = thick_collisions(pat, omega, opts.thickness / scale, side=solids.side)
    count = opts.ties
    made = Made(result, opts, sheet, solids, thick, lock_ties(pat, omega, count, scale),
                crease_stops(pat, omega, count, scale))
    return made if out is None else made.write(out, force)
