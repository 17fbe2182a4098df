"""The assembly sheet, assembly.pdf: a first page with the whole pattern, a small picture of the folded shape and what to do; then the pattern at 1:1 with
every crease numbered (its row in fold_angles.csv), tiled to pages of the paper (A4 or
Letter, portrait) when it is larger than one, each tile marked with its place.

Crease k (1-based, the order of fold_angles.csv) is labelled "k" at its midpoint, in
red for a mountain and blue for a valley (the colours of the cut files).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..files import atomic_path
from ..io.export import COLORS, triangles
from .options import PAPERS
from .sheet import Sheet

#: The margin of a page around the printed area (mm).
MARGIN = 10.0
#: Font size of the crease numbers (points).
LABEL_POINTS = 4.0
_MM = 1 / 25.4


def tiles(size: tuple[float, float], paper: str) -> tuple[int, int, float, float]:
    """(columns, rows, tile width, tile height) of the 1:1 pages of a sheet of ``size``
    (mm) on ``paper``: tiles of the printable area (the page less :data:`MARGIN`)."""
    w, h = (p - 2 * MARGIN for p in PAPERS[paper])
    return max(1, math.ceil(size[0] / w - 1e-9)), max(1, math.ceil(size[1] / h - 1e-9)), w, h


def _draw_creases(ax, sheet: Sheet, outline: np.ndarray,
                  window: tuple[float, float, float, float] | None = None) -> None:
    """The outline and the creases on ``ax``; with ``window`` (x0, y0, width, height, mm)
    the numbers of the creases whose middle lies in it."""
    from matplotlib.collections import LineCollection

    ax.plot(outline[:, 0], outline[:, 1], color=COLORS["B"], linewidth=0.6)
    for kind in ("M", "V"):
        mine = sheet.kinds == kind
        ax.add_collection(LineCollection(sheet.segments[mine], colors=COLORS[kind],
                                         linewidths=0.4))
    if window is not None:
        x0, y0, w, h = window
        middle = sheet.segments.mean(axis=1)
        inside = ((middle[:, 0] >= x0) & (middle[:, 0] < x0 + w) & (middle[:, 1] >= y0)
                  & (middle[:, 1] < y0 + h))
        for k in np.flatnonzero(inside):
            ax.text(middle[k, 0], middle[k, 1], str(k + 1), fontsize=LABEL_POINTS,
                    color=COLORS[sheet.kinds[k]], ha="center", va="center")


def _folded_picture(ax, Y: np.ndarray, N: int, M: int) -> None:
    """The folded state Y (N+1, M+1, 3) as shaded triangles on a 3-D axes."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    V = Y.reshape(-1, 3)
    tri = V[triangles(N, M)]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    shade = 0.45 + 0.5 * np.abs(normal @ np.array([0.3, 0.4, 0.87]))
    ax.add_collection3d(Poly3DCollection(tri, facecolors=np.c_[shade * 0.55, shade * 0.7,
                                                                 shade * 0.9],
                                         linewidths=0.0))
    lo, hi = V.min(axis=0), V.max(axis=0)
    centre, half = (lo + hi) / 2, (hi - lo).max() / 2
    for axis, c in zip("xyz", centre):
        getattr(ax, f"set_{axis}lim")(c - half, c + half)
    ax.set_box_aspect((1, 1, 1))
    ax.set_axis_off()


def _overview(sheet: Sheet, outline: np.ndarray, Y: np.ndarray, N: int, M: int,
              paper: str, notes: list[str]):
    """The first page: the whole pattern, the folded shape, the notes."""
    from matplotlib.figure import Figure

    pw, ph = PAPERS[paper]
    fig = Figure(figsize=(pw * _MM, ph * _MM))
    W, H = sheet.size
    box_w, box_h = pw - 2 * MARGIN, ph * 0.55
    fit = min(box_w / W, box_h / H)
    ax = fig.add_axes((MARGIN / pw, 1 - (MARGIN + H * fit) / ph, W * fit / pw, H * fit / ph))
    ax.set_xlim(0, W)
    ax.set_ylim(0, H)
    ax.set_aspect("equal")
    ax.set_axis_off()
    _draw_creases(ax, sheet, outline)
    ax3 = fig.add_axes((MARGIN / pw, 0.05, 0.4, 0.3), projection="3d")
    _folded_picture(ax3, Y, N, M)
    fig.text(0.5, 0.33, "\n".join(notes), fontsize=7, va="top", family="monospace")
    return fig


def _tile_page(sheet: Sheet, outline: np.ndarray, paper: str, col: int, row: int,
               layout: tuple[int, int, float, float]):
    """One 1:1 page: the tile (col, row) of the pattern, with its crease numbers."""
    from matplotlib.figure import Figure

    cols, rows, w, h = layout
    pw, ph = PAPERS[paper]
    fig = Figure(figsize=(pw * _MM, ph * _MM))
    ax = fig.add_axes((MARGIN / pw, MARGIN / ph, w / pw, h / ph))
    x0, y0 = col * w, row * h
    ax.set_xlim(x0, x0 + w)
    ax.set_ylim(y0, y0 + h)
    ax.set_axis_off()
    _draw_creases(ax, sheet, outline, (x0, y0, w, h))
    ax.plot([x0, x0 + w, x0 + w, x0, x0], [y0, y0, y0 + h, y0 + h, y0], color="#999999",
            linewidth=0.3, linestyle=":")
    fig.text(MARGIN / pw, 1 - MARGIN / 2 / ph, f"tile column {col + 1} of {cols}, row "
             f"{row + 1} of {rows} (rows from the bottom); 1:1, mm; join along the dotted "
             "frame", fontsize=6, va="center")
    return fig


def write_assembly(path: Path, sheet: Sheet, outline: np.ndarray, Y: np.ndarray, N: int,
                   M: int, paper: str, notes: list[str]) -> Path:
    """assembly.pdf (see the module): ``outline`` (k, 2) the cut outline (mm), ``Y``
    (N+1, M+1, 3) the designed state, ``notes`` the first page's lines."""
    from matplotlib.backends.backend_pdf import PdfPages

    layout = tiles(sheet.size, paper)
    cols, rows = layout[:2]
    notes = [*notes, f"pages 2-{cols * rows + 1}: the pattern at 1:1 on {cols} x {rows} "
             f"{paper.upper()} pages" if cols * rows > 1 else
             "page 2: the pattern at 1:1"]
    with atomic_path(path) as tmp:
        with PdfPages(tmp, metadata={"CreationDate": None}) as pdf:
            pdf.savefig(_overview(sheet, outline, Y, N, M, paper, notes))
            for row in range(rows):
                for col in range(cols):
                    pdf.savefig(_tile_page(sheet, outline, paper, col, row, layout))
    return path
