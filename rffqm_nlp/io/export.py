"""Files other tools open: SVG/PDF/DXF crease patterns, OBJ/PLY/GLB folded meshes, and the
one registry :data:`EXPORTERS` (with FOLD) that ``rffqm export`` and ``rffqm design`` use.

Edges, faces and vertices are numbered as in the FOLD file (:mod:`rffqm_nlp.io.foldfile`).
Every file is written atomically (:func:`rffqm_nlp.files.atomic_path`), and only from finite
coordinates that the file's number type holds (64-bit floats; 32-bit floats in PLY and
GLB): anything else is refused in one :class:`InputError` line and nothing is written.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..files import atomic_path
from .foldfile import (CREATOR, FLOAT32_MAX, FLOAT64_MAX, check_coordinates, finite_pattern,
                       edge_assignments, edges_vertices, faces_vertices, write_fold)
from ..model.marching import fold
from ..model.pattern import Pattern, check_fold_angle

if TYPE_CHECKING:  # matplotlib and trimesh are imported where they are used
    import trimesh
    from matplotlib.axes import Axes
    from matplotlib.lines import Line2D

#: Stroke colours of the 2-D writers, as Origami Simulator expects on SVG import.
COLORS: dict[str, str] = {"M": "#ff0000", "V": "#0000ff", "B": "#000000"}
#: The name of each kind of edge (the legends of the pictures and the view).
KIND_NAMES: dict[str, str] = {"M": "mountain", "V": "valley", "B": "boundary"}
#: DXF layer and ACI colour of every kind (1 red, 5 blue, 7 white/black).
DXF_LAYERS: dict[str, tuple[str, int]] = {"M": ("MOUNTAIN", 1), "V": ("VALLEY", 5),
                                          "B": ("BOUNDARY", 7)}
#: Mesh formats of :func:`write_mesh`, by file suffix.
MESH_FORMATS = {".obj": "obj", ".ply": "ply", ".glb": "glb"}
#: The number type of each mesh format's coordinates: (largest value, name).
MESH_NUMBERS = {"obj": (FLOAT64_MAX, "a 64-bit float"),
                "ply": (FLOAT32_MAX, "the 32-bit float of a PLY file"),
                "glb": (FLOAT32_MAX, "the 32-bit float of a GLB file")}


@contextlib.contextmanager
def _refusing(path: str | os.PathLike) -> Iterator[None]:
    """An :class:`InputError` raised inside says "cannot write ``path``: ..." (once)."""
    try:
        yield
    except InputError as exc:
        if str(exc).startswith("cannot write "):
            raise
        raise InputError(f"cannot write {path}: {exc}") from None


# --------------------------------------------------------------------------- 2-D drawings
def crease_segments(pat: Pattern, omega: float) -> list[tuple[np.ndarray, np.ndarray, str]]:
    """Every edge of the flat pattern as (p0, p1, kind), p 2-D, kind in {"M", "V", "B"};
    :class:`InputError` for a pattern that is not finite."""
    xy = finite_pattern(pat).X[..., :2].reshape(-1, 2)
    kinds = edge_assignments(pat, omega)
    return [(xy[a].copy(), xy[b].copy(), str(k))
            for (a, b), k in zip(edges_vertices(pat.N, pat.M), kinds)]


def draw_creases(ax: Axes, pat: Pattern, omega: float, linewidth: float = 1.0) -> list[Line2D]:
    """Draw every edge of the flat pattern on a matplotlib ``ax``: one Line2D per edge,
    mountain red, valley blue, boundary black; equal aspect, no axes. Returns the lines."""
    lines = []
    for p0, p1, kind in crease_segments(pat, omega):
        (line,) = ax.plot([p0[0], p1[0]], [p0[1], p1[1]], color=COLORS[kind],
                          linewidth=linewidth, solid_capstyle="round", clip_on=False)
        lines.append(line)
    ax.set_aspect("equal")
    ax.set_axis_off()
    return lines


def _crease_figure(pat: Pattern, omega: float, width_in: float = 8.0):
    """A bare figure (no background, no axes) of the pattern, sized to its aspect ratio;
    :class:`InputError` when its extent is not a finite positive size."""
    from matplotlib.figure import Figure

    xy = finite_pattern(pat).X[..., :2].reshape(-1, 2)
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    with np.errstate(all="ignore"):
        span = hi - lo
        pad = 0.02 * span.max()
        size = span + 2 * pad
        height = width_in * size[1] / size[0]
    check_coordinates([*(lo - pad), *(hi + pad), *size, height],
                      "the flat pattern's drawing bounds and size")
    if not (np.all(size > 0) and height > 0):
        raise InputError("the flat pattern has no extent to draw")
    fig = Figure(figsize=(width_in, height))
    fig.patch.set_visible(False)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.patch.set_visible(False)
    draw_creases(ax, pat, omega)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    return fig


def write_svg(path: str | os.PathLike, pat: Pattern, omega: float) -> Path:
    """Crease pattern as SVG: one ``<path>`` per edge, stroke #ff0000 mountain, #0000ff
    valley, #000000 boundary (Origami Simulator's import colours). Deterministic output."""
    import matplotlib

    with _refusing(path):
        fig = _crease_figure(pat, omega)
    with matplotlib.rc_context({"svg.hashsalt": CREATOR, "svg.fonttype": "none"}), \
            atomic_path(path) as tmp:
        fig.savefig(tmp, format="svg", metadata={"Date": None})
    return Path(path)


def write_pdf(path: str | os.PathLike, pat: Pattern, omega: float) -> Path:
    """Crease pattern as PDF, styled as :func:`write_svg`."""
    with _refusing(path):
        fig = _crease_figure(pat, omega)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="pdf", metadata={"CreationDate": None})
    return Path(path)


def write_dxf(path: str | os.PathLike, pat: Pattern, omega: float) -> Path:
    """Crease pattern as DXF (R2010, unitless): one LINE per edge on the layer MOUNTAIN (red),
    VALLEY (blue) or BOUNDARY (white/black), for laser cutters and CAD."""
    import ezdxf

    with _refusing(path):
        segments = crease_segments(pat, omega)
    doc = ezdxf.new("R2010", units=0)
    for layer, color in DXF_LAYERS.values():
        doc.layers.add(layer, color=color)
    msp = doc.modelspace()
    for p0, p1, kind in segments:
        msp.add_line(tuple(p0), tuple(p1), dxfattribs={"layer": DXF_LAYERS[kind][0]})
    with atomic_path(path) as tmp:
        doc.saveas(tmp)
    return Path(path)


# --------------------------------------------------------------------------- meshes
def triangles(N: int, M: int) -> np.ndarray:
    """Every panel split along its diagonal a-d into (a, c, d) and (a, d, b), (2NM, 3);
    counter-clockwise in the flat pattern, so normals point to its +e3 side."""
    q = faces_vertices(N, M)  # a, c, d, b
    return np.stack([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], axis=1).reshape(-1, 3)


def folded_mesh(pat: Pattern, omega: float) -> trimesh.Trimesh:
    """The folded state at ``omega`` as a ``trimesh.Trimesh`` ((N+1)(M+1) vertices, 2NM
    triangles, vertex order of the FOLD file); :class:`InputError` for a pattern or folded
    coordinates that are not finite."""
    import trimesh

    om = check_fold_angle(omega)
    Y = check_coordinates(fold(finite_pattern(pat), om),
                          f"the folded coordinates at omega {om:g}")
    return trimesh.Trimesh(vertices=Y.reshape(-1, 3), faces=triangles(pat.N, pat.M),
                           process=False)


def write_mesh(path: str | os.PathLike, pat: Pattern, omega: float) -> Path:
    """Write the folded mesh as .obj, .ply (binary) or .glb (binary glTF) by the suffix;
    coordinates that the format's numbers cannot hold (:data:`MESH_NUMBERS`: 32-bit floats
    in PLY and GLB) are refused in one :class:`InputError` line, and nothing is written."""
    suffix = Path(path).suffix.lower()
    if suffix not in MESH_FORMATS:
        raise InputError(f"mesh format {suffix!r} not supported; use one of "
                         f"{sorted(MESH_FORMATS)}")
    limit, number = MESH_NUMBERS[MESH_FORMATS[suffix]]
    with _refusing(path):
        mesh = folded_mesh(pat, omega)
        check_coordinates(mesh.vertices, "the folded coordinates", limit=limit, number=number)
    with atomic_path(path) as tmp:
        mesh.export(tmp, file_type=MESH_FORMATS[suffix])
    return Path(path)


# --------------------------------------------------------------------------- registry
@dataclass(frozen=True)
class Exporter:
    """One export format: its default file name and its writer.

    ``writer(path, pattern, omega, **options)`` writes the file and returns its path;
    ``options`` names the keyword options it takes (FOLD's ``frames`` and ``metadata``).
    """

    filename: str
    writer: Callable[..., Path]
    options: tuple[str, ...] = ()

    @property
    def suffix(self) -> str:
        """The file suffix of the format, e.g. ".svg"."""
        return Path(self.filename).suffix

    def write(self, path: str | os.PathLike, pattern: Pattern, omega: float,
              **options) -> Path:
        """Write ``pattern`` at ``omega`` to ``path``; of ``options`` only those this format
        takes are passed on."""
        return self.writer(path, pattern, omega,
                           **{k: v for k, v in options.items() if k in self.options})


#: Every export format by name: FOLD, the crease patterns and the folded meshes.
EXPORTERS: dict[str, Exporter] = {
    "fold": Exporter("pattern.fold", write_fold, ("frames", "metadata")),
    "svg": Exporter("crease.svg", write_svg),
    "pdf": Exporter("crease.pdf", write_pdf),
    "dxf": Exporter("crease.dxf", write_dxf),
    "obj": Exporter("folded.obj", write_mesh),
    "ply": Exporter("folded.ply", write_mesh),
    "glb": Exporter("folded.glb", write_mesh),
}
