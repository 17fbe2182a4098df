"""Cut and score files at true scale: SVG, DXF and PDF with the layers CUT, MOUNTAIN and
VALLEY, a mirrored back-side file, and the table of fold angles.

Every file is in millimetres. The SVG has ``width``/``height`` in mm and a viewBox of the
same numbers, so a user unit is a millimetre; y points down there, so a point (x, y) of
the sheet (:mod:`.sheet`, y up) is drawn at (x, H - y), H the sheet's height. The DXF
(R2010) has ``$INSUNITS`` = 4 (millimetres) and keeps (x, y). The PDF's page is the sheet
at 1:1 (points of 1/72 inch). The CUT layer holds the outline (offset by half the kerf),
MOUNTAIN and VALLEY the perforated creases, one path (SVG) or one group of LINEs per
crease. The back-side files show the sheet turned over about its vertical axis (x ->
W - x): a crease that is a mountain seen from the front is a valley seen from the back,
so their MOUNTAIN layer holds the front's valleys and their VALLEY layer its mountains;
a process that scores one face scores a layer of cut.* on the front and the same layer of
cut_back.* on the back.
"""

from __future__ import annotations

import csv
import io
import math
import os
from pathlib import Path

import numpy as np

from ..files import atomic_path, write_text
from ..io.export import COLORS
from .options import MakeOptions
from .sheet import Sheet, cut_outline, dashes

#: Layers of the cut files: name -> (edge kind of :data:`rffqm_nlp.io.export.COLORS`,
#: DXF colour number: 7 white/black, 1 red, 5 blue).
LAYERS = {"CUT": ("B", 7), "MOUNTAIN": ("M", 1), "VALLEY": ("V", 5)}
#: Stroke width of every line (mm): a hairline that laser software reads as a cut.
STROKE = 0.1
#: The columns of fold_angles.csv.
FOLD_ANGLE_COLUMNS = ("i1", "j1", "i2", "j2", "length_mm", "assignment", "angle_deg")
_SVG_NS = ('xmlns="http://www.w3.org/2000/svg" '
           'xmlns:inkscape="http://www.inkscape.org/namespaces/inkscape"')


class Drawing:
    """The lines of the cut files (mm, y up): ``outline`` (k, 2) closed; ``creases``
    {"MOUNTAIN": [...], "VALLEY": [...]}: per crease its label and its dashes (n, 2, 2);
    ``size`` (width, height)."""

    def __init__(self, sheet: Sheet, options: MakeOptions, back: bool = False):
        self.size = sheet.size
        self.outline = cut_outline(sheet, options.kerf)
        cuts = dashes(sheet, options.dash, options.gap, options.corner_relief)
        self.creases: dict[str, list[tuple[str, np.ndarray]]] = {"MOUNTAIN": [],
                                                                 "VALLEY": []}
        for ends, kind, segs in zip(sheet.ends, sheet.kinds, cuts):
            layer = "MOUNTAIN" if (kind == "M") != back else "VALLEY"
            label = "crease-{}-{}-{}-{}".format(*ends)
            self.creases[layer].append((label, self._placed(segs, back)))
        self.outline = self._placed(self.outline, back)
        if back:
            self.outline = self.outline[::-1]

    def _placed(self, xy: np.ndarray, back: bool) -> np.ndarray:
        """Points as the front (x, y) or the back (W - x, y) sees them."""
        if not back:
            return xy
        out = xy.copy()
        out[..., 0] = self.size[0] - out[..., 0]
        return out


def _num(x: float) -> str:
    return f"{x:.6f}".rstrip("0").rstrip(".") if x != 0 else "0"


def svg_text(drawing: Drawing) -> str:
    """The SVG of a drawing (see the module)."""
    W, H = drawing.size
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<svg {_SVG_NS} version="1.1" width="{_num(W)}mm" height="{_num(H)}mm" '
             f'viewBox="0 0 {_num(W)} {_num(H)}">',
             "<title>rffqm-nlp cut file (mm)</title>"]

    def xy(p):
        return f"{_num(p[0])} {_num(H - p[1])}"

    for layer, (kind, _) in LAYERS.items():
        lines.append(f'<g id="{layer}" inkscape:groupmode="layer" inkscape:label="{layer}" '
                     f'fill="none" stroke="{COLORS[kind]}" stroke-width="{_num(STROKE)}">')
        if layer == "CUT":
            ring = drawing.outline
            lines.append('<path id="outline" d="M ' + " L ".join(xy(p) for p in ring[:-1])
                         + ' Z"/>')
        else:
            for label, segs in drawing.creases[layer]:
                d = " ".join(f"M {xy(a)} L {xy(b)}" for a, b in segs)
                lines.append(f'<path id="{label}" d="{d}"/>')
        lines.append("</g>")
    lines.append("</svg>")
    return "\n".join(lines) + "\n"


def write_svg(path: str | os.PathLike, drawing: Drawing) -> Path:
    """Write :func:`svg_text` atomically."""
    return write_text(path, svg_text(drawing))


def write_dxf(path: str | os.PathLike, drawing: Drawing) -> Path:
    """The DXF of a drawing (R2010, $INSUNITS mm): the outline as a closed LWPOLYLINE on
    CUT, each dash a LINE on its crease's layer."""
    import ezdxf

    doc = ezdxf.new("R2010", units=4)
    doc.header["$MEASUREMENT"] = 1
    for layer, (_, color) in LAYERS.items():
        doc.layers.add(layer, color=color)
    msp = doc.modelspace()
    msp.add_lwpolyline([tuple(p) for p in drawing.outline[:-1]], close=True,
                       dxfattribs={"layer": "CUT"})
    for layer, creases in drawing.creases.items():
        for _, segs in creases:
            for a, b in segs:
                msp.add_line(tuple(a), tuple(b), dxfattribs={"layer": layer})
    with atomic_path(path) as tmp:
        doc.saveas(tmp)
    return Path(path)


def write_pdf(path: str | os.PathLike, drawing: Drawing) -> Path:
    """The PDF of a drawing: one page the size of the sheet, drawn 1:1."""
    from matplotlib.figure import Figure

    W, H = drawing.size
    fig = Figure(figsize=(W / 25.4, H / 25.4))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    ax.set_xlim(0, W)
    ax.set_ylim(0, H)
    width = STROKE * 72 / 25.4
    ax.plot(drawing.outline[:, 0], drawing.outline[:, 1], color=COLORS["B"],
            linewidth=width)
    for layer, creases in drawing.creases.items():
        color = COLORS[LAYERS[layer][0]]
        segs = [s for _, group in creases for s in group]
        if segs:
            from matplotlib.collections import LineCollection

            ax.add_collection(LineCollection(segs, colors=color, linewidths=width))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="pdf", metadata={"CreationDate": None})
    return Path(path)


def fold_angle_rows(sheet: Sheet) -> list[tuple]:
    """One row per crease: (i1, j1, i2, j2, length_mm, assignment, angle_deg), the fold
    angle at the designed state in degrees, valley positive."""
    return [(*map(int, ends), float(length), str(kind), math.degrees(float(angle)))
            for ends, length, kind, angle in zip(sheet.ends, sheet.lengths, sheet.kinds,
                                                 sheet.angles)]


def csv_text(columns: tuple[str, ...], rows: list[tuple]) -> str:
    """A CSV table: a header, then the rows (floats with 17 significant digits)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        writer.writerow([repr(v) if isinstance(v, float) else v for v in row])
    return buffer.getvalue()


def write_cut_files(folder: Path, sheet: Sheet, options: MakeOptions) -> list[Path]:
    """cut.svg, cut.dxf, cut.pdf, cut_back.svg, cut_back.dxf and fold_angles.csv into
    ``folder``; their paths."""
    front, back = Drawing(sheet, options), Drawing(sheet, options, back=True)
    return [write_svg(folder / "cut.svg", front), write_dxf(folder / "cut.dxf", front),
            write_pdf(folder / "cut.pdf", front),
            write_svg(folder / "cut_back.svg", back), write_dxf(folder / "cut_back.dxf", back),
            write_text(folder / "fold_angles.csv",
                       csv_text(FOLD_ANGLE_COLUMNS, fold_angle_rows(sheet)))]
