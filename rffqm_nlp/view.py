"""Interactive view of a design: one self-contained HTML page made with plotly.

The page shows, in the target's frame (every state moved by the design's rigid motion,
``rotation @ y + translation``, as :attr:`DesignResult.folded`):

* the folded pattern as one shaded Mesh3d, two triangles per panel (the split of
  :func:`rffqm_nlp.export.triangles`), coloured by the distance of each pattern vertex to
  the target surface. The target surface is taken as the bilinear patches of the target
  lattice, sampled :data:`TARGET_REFINE` times finer in each direction; a vertex's distance
  is that to the nearest sample (scipy's cKDTree);
* the creases as three Scatter3d line traces, mountain red, valley blue, boundary black
  (the colours of the SVG export), their kinds taken from the fold angle signs at the
  designed omega (:func:`rffqm_nlp.foldfile.edge_assignments`);
* the target surface, hidden until its button is pressed: the mesh of
  :func:`rffqm_nlp.results.target_mesh` (the kept ``result.target_grid``, or the surface
  rebuilt from the result's config without running code), or the target lattice when the
  target cannot be rebuilt;
* a slider through the folding motion from flat (omega = 0) to folded flat (omega = +-pi,
  the sign of the designed omega), one step labelled "designed" at the designed omega. Its
  steps restyle x, y, z (and the distances) of the mesh and crease traces; the triangle
  indices are sent once. (``Plotly.animate`` on 3D traces throws a page error.)

Coordinates and distances are rounded to :data:`SIGNIFICANT` significant digits of the
largest coordinate. plotly.js and the figure are stored gzip-compressed and
base64-encoded in the page and unpacked by the browser (``DecompressionStream``), so the
page works offline and stays small.
"""

from __future__ import annotations

import base64
import functools
import gzip
import json
import os
import uuid
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import plotly.graph_objects as go
from plotly.offline import get_plotlyjs

from . import numpy_model
from .errors import RffqmError
from .export import COLORS, triangles
from .files import write_text
from .foldfile import edge_assignments
from .pattern import motion_omegas
from .shape import distances_to
from .surfaces import Surface, grid_faces

if TYPE_CHECKING:  # results will import this module for DesignResult._repr_html_
    from .pattern import Pattern
    from .results import DesignResult

#: Significant digits (of the largest coordinate) kept in the page.
SIGNIFICANT = 4
#: Refinement of the target lattice sampled for the distances.
TARGET_REFINE = 8
#: Label of the slider step at the designed omega.
DESIGNED = "designed"
#: Traces of :func:`figure`, in order: the folded mesh, the crease kinds, the target.
TRACES = ("mesh", "M", "V", "B", "target")
_KIND_NAMES = {"M": "mountain", "V": "valley", "B": "boundary"}
_KIND_WIDTHS = {"M": 3, "V": 3, "B": 5}


# --------------------------------------------------------------------------- states
def slider_omegas(omega: float, frames: int) -> tuple[np.ndarray, int]:
    """The slider's fold parameters: ``frames`` values evenly from 0 to pi * sign(omega),
    with ``omega`` inserted in order -> ((frames + 1,), index of ``omega``)."""
    even = motion_omegas(np.pi if omega >= 0 else -np.pi, frames, minimum=2)
    at = int(np.searchsorted(np.abs(even), abs(omega)))
    return np.insert(even, at, omega), at


def states(result: DesignResult, omegas: np.ndarray) -> np.ndarray:
    """Pattern vertices at every omega in the target's frame, (K, N+1, M+1, 3)."""
    Y = numpy_model.fold(result.pattern, np.asarray(omegas, dtype=float))
    return Y @ np.asarray(result.rotation).T + np.asarray(result.translation)


def target_samples(target_points: np.ndarray, refine: int = TARGET_REFINE) -> np.ndarray:
    """The bilinear patches of the (N+1, M+1, 3) target lattice sampled ``refine`` times
    finer in each direction, (refine N + 1, refine M + 1, 3)."""
    T = np.asarray(target_points, dtype=float)
    n, m = T.shape[0] - 1, T.shape[1] - 1
    s = np.linspace(0.0, n, refine * n + 1)
    t = np.linspace(0.0, m, refine * m + 1)
    i0 = np.minimum(s.astype(int), n - 1)
    j0 = np.minimum(t.astype(int), m - 1)
    u, v = (s - i0)[:, None, None], (t - j0)[None, :, None]
    a, b = T[i0][:, j0], T[i0 + 1][:, j0]
    c, d = T[i0][:, j0 + 1], T[i0 + 1][:, j0 + 1]
    return (1 - u) * (1 - v) * a + u * (1 - v) * b + (1 - u) * v * c + u * v * d


def distances(points: np.ndarray, target_points: np.ndarray) -> np.ndarray:
    """Distance of every point (..., 3) to the target surface (see the module), (...)."""
    return distances_to(points, target_samples(target_points))


# --------------------------------------------------------------------------- creases
def _runs(mask: np.ndarray, ids: np.ndarray) -> list[np.ndarray]:
    """Vertex ids of the maximal runs of consecutive selected edges along one line; edge e
    joins ids[e] and ids[e + 1]."""
    edges = np.flatnonzero(mask)
    groups = np.split(edges, np.flatnonzero(np.diff(edges) > 1) + 1)
    return [ids[g[0]:g[-1] + 2] for g in groups if g.size]


def crease_paths(pat: Pattern, omega: float) -> dict[str, np.ndarray]:
    """For each kind "M", "V", "B": the vertex ids (row-major in (N+1, M+1)) of its creases
    as polylines, -1 between two polylines; consecutive edges of a kind along a lattice line
    form one polyline."""
    N, M = pat.N, pat.M
    kinds = edge_assignments(pat, omega)
    kh, kv = kinds[:(N + 1) * M].reshape(N + 1, M), kinds[(N + 1) * M:].reshape(N, M + 1)
    v = np.arange((N + 1) * (M + 1)).reshape(N + 1, M + 1)
    paths = {}
    for kind in ("M", "V", "B"):
        runs = [r for i in range(N + 1) for r in _runs(kh[i] == kind, v[i])]
        runs += [r for j in range(M + 1) for r in _runs(kv[:, j] == kind, v[:, j])]
        pieces = [p for r in runs for p in (r, [-1])][:-1]
        paths[kind] = np.concatenate(pieces).astype(int) if pieces else np.zeros(0, int)
    return paths


# --------------------------------------------------------------------------- figure
def _decimals(Y: np.ndarray) -> int:
    """Decimal places keeping :data:`SIGNIFICANT` digits of the largest |coordinate|."""
    scale = float(np.max(np.abs(Y))) or 1.0
    return int(SIGNIFICANT - 1 - np.floor(np.log10(scale)))


def _listed(a: np.ndarray, decimals: int) -> list:
    """``a`` rounded, as a list with None for NaN (a break in a line)."""
    return [None if x != x else x for x in np.round(a, decimals).tolist()]


def _coordinates(P: np.ndarray, paths: dict[str, np.ndarray], decimals: int) -> dict:
    """x, y, z of the mesh and crease traces for the vertices P ((N+1)(M+1), 3)."""
    xyz = {"x": [], "y": [], "z": []}
    points = [P] + [np.where(paths[k][:, None] < 0, np.nan, P[paths[k]]) for k in "MVB"]
    for pts in points:
        for axis, name in enumerate("xyz"):
            xyz[name].append(_listed(pts[:, axis], decimals))
    return xyz


def _mesh(xyz: dict, pat, intensity: list, cmax: float) -> dict:
    tri = triangles(pat.N, pat.M)
    return {"type": "mesh3d", "x": xyz["x"][0], "y": xyz["y"][0], "z": xyz["z"][0],
            "i": tri[:, 0].tolist(), "j": tri[:, 1].tolist(), "k": tri[:, 2].tolist(),
            "intensity": intensity, "cmin": 0.0, "cmax": cmax, "colorscale": "Viridis",
            "colorbar": {"title": {"text": "distance<br>to target"}},
            "flatshading": True, "name": "folded pattern", "hoverinfo": "skip",
            "lighting": {"ambient": 0.45, "diffuse": 0.8, "specular": 0.15,
                         "roughness": 0.6, "fresnel": 0.1},
            "lightposition": {"x": 3e4, "y": 6e4, "z": 1e5}}


def _creases(xyz: dict) -> list[dict]:
    return [{"type": "scatter3d", "x": xyz["x"][n], "y": xyz["y"][n], "z": xyz["z"][n],
             "mode": "lines", "name": _KIND_NAMES[k], "hoverinfo": "skip",
             "connectgaps": False, "line": {"color": COLORS[k], "width": _KIND_WIDTHS[k]}}
            for n, k in enumerate("MVB", start=1)]


def _target_shape(result: DesignResult, target: Surface | None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (k, 3) and triangles (f, 3) of the target drawn: :func:`target_mesh`, or
    the cells of the target lattice when the target cannot be rebuilt."""
    from .results import target_mesh

    try:
        mesh = target_mesh(result, target)
    except RffqmError:
        T = np.asarray(result.target_points, dtype=float)
        return T.reshape(-1, 3), grid_faces(*T.shape[:2])
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces)


def _target(vertices: np.ndarray, faces: np.ndarray, decimals: int) -> dict:
    r = np.round(vertices, decimals)
    return {"type": "mesh3d", "x": r[:, 0].tolist(), "y": r[:, 1].tolist(),
            "z": r[:, 2].tolist(), "i": faces[:, 0].tolist(), "j": faces[:, 1].tolist(),
            "k": faces[:, 2].tolist(), "name": "target", "visible": False, "opacity": 0.45,
            "color": "#9a9a9a", "hoverinfo": "skip"}


def _camera(P: np.ndarray) -> dict:
    """A camera looking at the designed vertices P (..., 3) obliquely from the +z side of
    their best-fitting plane (scene directions equal data directions at equal scales)."""
    Q = P.reshape(-1, 3) - P.reshape(-1, 3).mean(axis=0)
    _, _, Vt = np.linalg.svd(Q, full_matrices=False)
    normal = Vt[2] if Vt[2, 2] >= 0 else -Vt[2]
    eye = normal + 0.7 * Vt[0] + 0.3 * Vt[1]
    eye = 2.0 * eye / np.linalg.norm(eye)
    return {"eye": dict(zip("xyz", eye.tolist())), "up": {"x": 0, "y": 0, "z": 1}}


def _scene(Y: np.ndarray, T: np.ndarray, designed: np.ndarray) -> dict:
    """Fixed axes around every state and the target, equal scales, axes hidden, the camera
    of :func:`_camera` on the ``designed`` vertices."""
    pts = np.concatenate([Y.reshape(-1, 3), T.reshape(-1, 3)])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.02 * float(np.max(hi - lo))
    span = hi - lo + 2 * pad
    axes = {f"{a}axis": {"range": [float(lo[n] - pad), float(hi[n] + pad)], "visible": False}
            for n, a in enumerate("xyz")}
    ratio = dict(zip("xyz", (span / span.max()).tolist()))
    return {**axes, "aspectmode": "manual", "aspectratio": ratio,
            "camera": _camera(designed)}


def spec(result: DesignResult, frames: int = 24, target: Surface | None = None) -> dict:
    """The figure of ``result`` as plain plotly JSON {"data", "layout"}: the traces in the
    order of :data:`TRACES`, a slider with ``frames + 1`` steps (see :func:`slider_omegas`)
    starting at the designed state, and a button that shows and hides the target
    (``target``, or the result's: see :func:`_target_shape`)."""
    omega = float(result.omega)
    omegas, at = slider_omegas(omega, frames)
    pat = result.pattern
    Y = states(result, omegas)
    T = np.asarray(result.target_points, dtype=float)
    S, faces = _target_shape(result, target)
    decimals = _decimals(Y)
    paths = crease_paths(pat, omega)
    dist = distances(Y, T).reshape(len(omegas), -1)
    cmax = float(np.round(dist[at].max(), decimals)) or 10.0 ** -decimals
    steps = []
    for n, w in enumerate(omegas):
        xyz = _coordinates(Y[n].reshape(-1, 3), paths, decimals)
        restyle = {**xyz, "intensity": [_listed(dist[n], decimals), None, None, None]}
        steps.append({"method": "restyle", "args": [restyle, [0, 1, 2, 3]],
                      "label": DESIGNED if n == at else f"{w:.2f}", "value": f"{w:.17g}"})
    first = steps[at]["args"][0]
    data = [_mesh(first, pat, first["intensity"][0], cmax), *_creases(first),
            _target(S, faces, decimals)]
    layout = {
        "title": {"text": f"designed state: omega = {omega:.4f}", "x": 0.5},
        "scene": _scene(Y, S, Y[at]), "margin": {"l": 0, "r": 0, "t": 40, "b": 0},
        "legend": {"x": 0.01, "y": 0.9},
        "sliders": [{"active": at, "steps": steps, "pad": {"t": 10, "b": 10},
                     "currentvalue": {"prefix": "omega: "}}],
        "updatemenus": [{"type": "buttons", "x": 0.01, "y": 1.0, "xanchor": "left",
                         "showactive": True, "active": -1,  # -1: pressed, args; again: args2
                         "buttons": [{"label": "target surface", "method": "restyle",
                                      "args": [{"visible": True}, [4]],
                                      "args2": [{"visible": False}, [4]]}]}]}
    return {"data": data, "layout": layout}


def figure(result: DesignResult, frames: int = 24) -> go.Figure:
    """:func:`spec` as a validated plotly Figure (slow for large patterns: plotly copies
    every slider step; the HTML writers use :func:`spec` directly)."""
    return go.Figure(spec(result, frames))


# --------------------------------------------------------------------------- HTML
_LOADER = """(function () {
  var div = document.getElementById("%(id)s");
  function inflate(b64) {
    var bytes = Uint8Array.from(atob(b64), function (c) { return c.charCodeAt(0); });
    var stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("gzip"));
    return new Response(stream).text();
  }
  var ready = window.Plotly ? Promise.resolve() : inflate("%(plotly)s").then(function (js) {
    if (window.Plotly) { return; }
    window.PlotlyConfig = {MathJaxConfig: "local"};
    var script = document.createElement("script");
    script.text = js;
    document.head.appendChild(script);
  });
  ready.then(function () { return inflate("%(figure)s"); }).then(function (text) {
    var fig = JSON.parse(text);
    return Plotly.newPlot(div, fig.data, fig.layout, fig.config);
  }).catch(function (err) {
    div.textContent = "rffqm view: " + err;
    throw err;
  });
})();"""


def _packed(text: str) -> str:
    """``text`` gzip-compressed and base64-encoded (ASCII)."""
    return base64.b64encode(gzip.compress(text.encode("utf-8"), 6, mtime=0)).decode("ascii")


@functools.lru_cache(maxsize=1)
def _plotly_packed() -> str:
    return _packed(get_plotlyjs())


def _div(fig: dict, height: str) -> str:
    """A div and the script that loads plotly.js (unless the page has it) and draws ``fig``
    (a :func:`spec`)."""
    div_id = f"rffqm-view-{uuid.uuid4().hex[:12]}"
    config = {"responsive": True, "displaylogo": False}
    text = json.dumps({**fig, "config": config}, separators=(",", ":"), allow_nan=False)
    script = _LOADER % {"id": div_id, "plotly": _plotly_packed(), "figure": _packed(text)}
    return (f'<div id="{div_id}" class="rffqm-view" style="width:100%;height:{height}">'
            f"</div>\n<script>{script}</script>")


def repr_html(result: DesignResult, frames: int = 24) -> str:
    """The figure of ``result`` as an HTML fragment for a notebook (plotly.js inline)."""
    return _div(spec(result, frames), "640px")


def write_html(result: DesignResult, path: str | os.PathLike, frames: int = 24,
               target: Surface | None = None) -> Path:
    """Write the figure of ``result`` (:func:`spec`, with ``target``) as one self-contained
    HTML page (works offline), atomically; returns the path."""
    page = ('<!DOCTYPE html>\n<html><head><meta charset="utf-8">'
            "<title>rffqm-nlp design</title>"
            "<style>html,body{margin:0;height:100%}</style></head>\n<body>\n"
            f"{_div(spec(result, frames, target), '100vh')}\n</body></html>\n")
    return write_text(path, page)
