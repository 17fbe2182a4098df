"""Interactive view of a design: one self-contained HTML page made with plotly.

The page shows, in the target's frame (every state moved by the design's rigid motion,
``rotation @ y + translation``, as :attr:`DesignResult.folded`):

* the folded pattern as one shaded Mesh3d, two triangles per panel (the split of
  :func:`rffqm_nlp.io.export.triangles`), coloured by the distance of each pattern vertex to
  the target surface. The target surface is taken as the bilinear patches of the target
  lattice, sampled :data:`TARGET_REFINE` times finer in each direction (fewer times where
  that would make more than :data:`MAX_SAMPLES` samples: :func:`refinement`); a vertex's
  distance is that to the nearest sample (scipy's cKDTree). The colour scale runs from 0
  to the largest distance of the designed state, whose every distance is this one. So are
  those of the other states within the colour scale, unless it spans more than
  :data:`SCALE_STEPS` sample spacings (a design far from its target): then they are to
  every s-th sample, too large by at most 1/:data:`SCALE_STEPS` of the scale
  (:func:`scale_stride`). A vertex of another state beyond the scale, drawn in its top
  colour whatever its distance, gets the distance to the nearest of at most
  :data:`FAR_SAMPLES` samples (a sub-lattice) instead: an upper bound (the times, before
  and after: docs/benchmarks/march_memory.md);
* the creases as three Scatter3d line traces, mountain red, valley blue, boundary black
  (the colours of the SVG export), their kinds taken from the fold angle signs at the
  designed omega (:func:`rffqm_nlp.io.foldfile.edge_assignments`);
* the target surface, hidden until its button is pressed: the mesh of
  :func:`rffqm_nlp.design.results.target_mesh` (the kept ``result.target_grid``, or the surface
  rebuilt from the result's config without running code), or the target lattice when the
  target cannot be rebuilt;
* a slider through the folding motion from flat (omega = 0) to folded flat (omega = +-pi,
  the sign of the designed omega), one step labelled "designed" at the designed omega (and,
  for a design of several states, one labelled "state k" at each further state's). Its
  steps restyle x, y, z (and the distances) of the mesh and crease traces; the triangle
  indices are sent once. (``Plotly.animate`` on 3D traces throws a page error.)

Sizes are bounded before any work (:func:`check_size`): the page holds at most
:data:`MAX_POINTS` vertex positions (slider states times pattern vertices). Before the
distances, coordinates must lie within :data:`MAX_COORDINATE` and the folded states span
at least :data:`MIN_RELATIVE_EXTENT` of their largest coordinate (else floating point
cannot draw them). Anything else is one :class:`~rffqm_nlp.errors.InputError` line.

Coordinates and distances are rounded to :data:`SIGNIFICANT` significant digits of the
largest coordinate, or of the folded states' extent when that keeps more decimals (a
design far from the origin). plotly.js and the figure are stored gzip-compressed and
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
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import plotly.graph_objects as go
from plotly.offline import get_plotlyjs
from scipy.spatial import cKDTree

from ..model import numpy_model
from ..errors import InputError, RffqmError
from ..io.export import COLORS, KIND_NAMES, triangles
from ..files import Key, check_value, write_text
from ..io.foldfile import edge_assignments
from ..model.pattern import motion_omegas
from ..targets.surfaces import Surface, grid_faces
from .ties import add_ties, tie_ids

if TYPE_CHECKING:  # results will import this module for DesignResult._repr_html_
    from ..model.pattern import Pattern
    from ..design.results import DesignResult

#: Significant digits (of the largest coordinate) kept in the page.
SIGNIFICANT = 4
#: Refinement of the target lattice sampled for the distances.
TARGET_REFINE = 8
#: Most samples of the target (:func:`refinement`).
MAX_SAMPLES = 2_000_000
#: Most target samples that the distances of vertices beyond the colour scale are measured
#: to (see the module).
FAR_SAMPLES = 1024
#: The other states' distances within the colour scale are measured to samples no farther
#: apart than the scale over this (see the module).
SCALE_STEPS = 64
#: Most vertex positions (slider states times pattern vertices) in one page
#: (:func:`check_size`): 25 states of a 315 x 315 design (its time and memory:
#: docs/benchmarks/march_memory.md).
MAX_POINTS = 2_500_000
#: Largest |coordinate| the page draws (distances of such points stay finite).
MAX_COORDINATE = 1e150
#: Smallest extent of the folded states, relative to their largest |coordinate|, that the
#: page draws (finer shapes are lost to floating point).
MIN_RELATIVE_EXTENT = 1e-11
#: Label of the slider step at the designed omega.
DESIGNED = "designed"
#: Traces of :func:`figure`, in order: the folded mesh, the crease kinds, the target.
TRACES = ("mesh", "M", "V", "B", "target")
_KIND_WIDTHS = {"M": 3, "V": 3, "B": 5}


# --------------------------------------------------------------------------- sizes
def check_size(N: int, M: int, frames: int) -> int:
    """``frames`` (a whole number >= 2) unless the page of N x M panels with ``frames + 1``
    slider states would hold more than :data:`MAX_POINTS` vertex positions: then one
    :class:`InputError` line saying how many ``frames`` fit. Cheap: call it before any
    work."""
    frames = check_value(frames, Key("whole", low=2), "frames")
    vertices = (int(N) + 1) * (int(M) + 1)
    if (frames + 1) * vertices > MAX_POINTS:
        most = max_frames(N, M)
        fit = (f"choose --frames {most} or fewer" if most >= 2
               else "a design this large has no view")
        raise InputError(f"the view of {N} x {M} panels with {frames + 1} states would hold "
                         f"{(frames + 1) * vertices} vertex positions, more than the "
                         f"{MAX_POINTS} a page holds; {fit}")
    return frames


def max_frames(N: int, M: int) -> int:
    """The most ``frames`` the view of N x M panels takes (:data:`MAX_POINTS`); below 2
    when it has no view."""
    return MAX_POINTS // ((int(N) + 1) * (int(M) + 1)) - 1


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


def distances(points: np.ndarray, target_points: np.ndarray,
              within: float | None = None) -> np.ndarray:
    """Distance of every point (..., 3) to the target surface (see the module), (...): to
    the nearest of :func:`target_samples` (:func:`refinement`). With ``within``, a point
    farther than ``within`` gets the distance to the nearest of :func:`far_samples`
    instead (an upper bound of its distance, so larger than ``within`` too), found without
    searching every sample."""
    if within is not None:
        within = check_value(within, Key("number", low=0.0), "within")
    samples = _samples(target_points)
    P = np.asarray(points, dtype=float)
    if P.shape[-1:] != (3,) or not np.all(np.isfinite(P)):
        raise InputError(f"points must be finite points of shape (..., 3), got shape {P.shape}")
    tree = _tree(samples.reshape(-1, 3))
    if within is None:
        d = _finite(tree.query(P.reshape(-1, 3))[0])
    else:
        d = _nearest(tree, samples, P.reshape(-1, 3), within)
    return d.reshape(P.shape[:-1])


def _finite(d: np.ndarray) -> np.ndarray:
    """Distances ``d`` unless one overflowed."""
    if not np.all(np.isfinite(d)):
        raise InputError("the distances overflow: the points are too far from the target "
                         "for floating point")
    return d


def refinement(target_points: np.ndarray) -> int:
    """The refinement of the (n, m, 3) target lattice whose samples the distances are to:
    :data:`TARGET_REFINE`, or the largest that keeps to :data:`MAX_SAMPLES` samples (at
    least 1)."""
    n, m = np.shape(target_points)[0] - 1, np.shape(target_points)[1] - 1
    refine = TARGET_REFINE
    while refine > 1 and (refine * n + 1) * (refine * m + 1) > MAX_SAMPLES:
        refine -= 1
    return refine


def _samples(target_points: np.ndarray) -> np.ndarray:
    """:func:`target_samples` (:func:`refinement`) of a target lattice of finite points."""
    samples = target_samples(target_points, refinement(target_points))
    if not np.all(np.isfinite(samples)):
        raise InputError("the target lattice must hold finite points")
    return samples


def far_samples(samples: np.ndarray, most: int = FAR_SAMPLES) -> np.ndarray:
    """At most ``most`` of the (n, m, 3) ``samples``, (k, 3): every s-th row and column and
    the last ones, s the smallest stride that keeps to ``most``."""
    n, m = samples.shape[:2]
    stride = max(1, int(np.sqrt(n * m / most)))
    while len(_every(n, stride)) * len(_every(m, stride)) > most and stride < max(n, m):
        stride += 1
    return samples[np.ix_(_every(n, stride), _every(m, stride))].reshape(-1, 3)


def _tree(points: np.ndarray) -> cKDTree:
    """A k-d tree of the points (k, 3) for nearest-point queries from afar. Sliding
    midpoint splits into uncompacted nodes, 64 points a leaf: the same answers as
    cKDTree's defaults, 15 to 40 times faster for points away from a surface's samples
    (docs/benchmarks/march_memory.md)."""
    return cKDTree(points, leafsize=64, balanced_tree=False, compact_nodes=False)


def _every(n: int, stride: int) -> np.ndarray:
    return np.unique(np.r_[np.arange(0, n, stride), n - 1])


def _nearest(tree: cKDTree, samples: np.ndarray, P: np.ndarray, within: float) -> np.ndarray:
    """Distances of the points P (k, 3) to the samples of ``tree`` (``samples`` (n, m, 3))
    for those within ``within``, to :func:`far_samples` for the others."""
    d = tree.query(P, distance_upper_bound=within)[0]
    far = ~np.isfinite(d)
    if far.any():
        d[far] = _tree(far_samples(samples)).query(P[far])[0]
    return _finite(d)


def state_distances(Y: np.ndarray, target_points: np.ndarray, at: int,
                    slack: float = 0.0) -> np.ndarray:
    """Distances of the vertices of the states Y (K, ..., 3) to the target, (K, n), as the
    module says: those of state ``at`` (the designed one) to the nearest sample; those of
    the other states within the colour scale (the largest of these plus ``slack``, its top
    rounded up) to the nearest of every s-th sample, s the largest stride whose spacing
    keeps to 1/:data:`SCALE_STEPS` of the scale (s = 1, every sample, unless the
    scale spans more than that many sample spacings); beyond, as :func:`distances` with
    ``within``."""
    samples = _samples(target_points)
    tree = _tree(samples.reshape(-1, 3))
    P = np.asarray(Y, dtype=float).reshape(len(Y), -1, 3)
    designed = _finite(tree.query(P[at])[0])
    top = float(designed.max()) + slack
    others = np.delete(np.arange(len(P)), at)
    d = np.empty(P.shape[:2])
    d[at] = designed
    if others.size:
        stride = scale_stride(samples, top)
        if stride > 1:
            n, m = samples.shape[:2]
            tree = _tree(samples[np.ix_(_every(n, stride), _every(m, stride))].reshape(-1, 3))
        d[others] = _nearest(tree, samples, P[others].reshape(-1, 3),
                             top).reshape(len(others), -1)
    return d


def scale_stride(samples: np.ndarray, scale: float) -> int:
    """The largest stride s >= 1 such that each of the (n, m, 3) ``samples`` lies within
    ``scale`` / :data:`SCALE_STEPS` of one of every s-th sample in each direction (and the
    last): s times the largest distance of two neighbouring samples at most that."""
    step = max(float(np.max(np.linalg.norm(np.diff(samples, axis=a), axis=-1), initial=0.0))
               for a in (0, 1))
    if step <= 0:
        return 1
    return max(1, min(int(scale / (SCALE_STEPS * step)), max(samples.shape[:2])))


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
    """Decimal places keeping :data:`SIGNIFICANT` digits of the largest |coordinate|, or of
    the extent of Y when that keeps more."""
    scale = float(np.max(np.abs(Y))) or 1.0
    extent = _extent(Y) or scale
    return int(SIGNIFICANT - 1 - np.floor(np.log10(min(scale, extent))))


def _extent(Y: np.ndarray) -> float:
    """The largest side of the box around the points Y (..., 3)."""
    pts = Y.reshape(-1, 3)
    return float(np.max(pts.max(axis=0) - pts.min(axis=0)))


def _rounded(a: np.ndarray, decimals: int) -> np.ndarray:
    """``a`` rounded to ``decimals`` places, or left as it is where rounding overflows (a
    number too large for that many decimals has none to round)."""
    a = np.asarray(a, dtype=float)
    with np.errstate(over="ignore", invalid="ignore"):
        r = np.round(a, decimals)
    return np.where(np.isfinite(r) | np.isnan(a), r, a)


def _listed(a: np.ndarray, decimals: int) -> list:
    """``a`` rounded, as a list with None for NaN (a break in a line)."""
    return [None if x != x else x for x in _rounded(a, decimals).tolist()]


def _check_coordinates(Y: np.ndarray, *others: np.ndarray) -> None:
    """Refuse, in one line, states Y (and the target's points ``others``) with a coordinate
    beyond :data:`MAX_COORDINATE`, or states spanning less than :data:`MIN_RELATIVE_EXTENT`
    of their largest coordinate."""
    largest = max(float(np.max(np.abs(a))) if np.size(a) else 0.0 for a in (Y, *others))
    if not largest <= MAX_COORDINATE:
        raise InputError(f"the view draws coordinates up to {MAX_COORDINATE:g} in size; this "
                         f"design and its target reach {largest:.3g}")
    scale = float(np.max(np.abs(Y)))
    if not _extent(Y) > MIN_RELATIVE_EXTENT * scale:
        raise InputError(f"the folded states span {_extent(Y):.3g} at coordinates of "
                         f"{scale:.3g}: too small a shape that far from the origin for "
                         "floating point to draw")


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
             "mode": "lines", "name": KIND_NAMES[k], "hoverinfo": "skip",
             "connectgaps": False, "line": {"color": COLORS[k], "width": _KIND_WIDTHS[k]}}
            for n, k in enumerate("MVB", start=1)]


def _target_shape(result: DesignResult, target: Surface | None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (k, 3) and triangles (f, 3) of the target drawn: :func:`target_mesh`, or
    the cells of the target lattice when the target cannot be rebuilt."""
    from ..design.results import target_mesh

    try:
        mesh = target_mesh(result, target)
    except RffqmError:
        T = np.asarray(result.target_points, dtype=float)
        return T.reshape(-1, 3), grid_faces(*T.shape[:2])
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces)


def _target(vertices: np.ndarray, faces: np.ndarray, decimals: int) -> dict:
    r = _rounded(vertices, decimals)
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


def spec(result: DesignResult, frames: int = 24, target: Surface | None = None,
         ties: Sequence | None = None) -> dict:
    """The figure of ``result`` as plain plotly JSON {"data", "layout"}: the traces in the
    order of :data:`TRACES`, a slider with ``frames + 1`` steps (see :func:`slider_omegas`)
    starting at the designed state (of a design of several states the first; each further
    state on the same side of the flat state has a step of its own, labelled "state k" and
    drawn in the first state's frame), and a button that shows and hides the target
    (``target``, or the result's: see :func:`_target_shape`); with ``ties`` (the lock's
    vertex pairs, :mod:`rffqm_nlp.show.ties`) a last trace of them. Sizes and coordinates
    are checked as the module says (:func:`check_size` first, before any work)."""
    omega = float(result.omega)
    pat = result.pattern
    others = [(float(state.omega), f"state {k + 2}")
              for k, state in enumerate(result.other_states)
              if np.sign(state.omega) == np.sign(omega)]
    check_size(pat.N, pat.M, frames + len(others))
    omegas, at = slider_omegas(omega, frames)
    labels = {}
    for w, label in others:  # a design's further states on the slider, in the first's frame
        k = int(np.searchsorted(np.abs(omegas), abs(w)))
        omegas = np.insert(omegas, k, w)
        at += k <= at
        labels = {(n + (n >= k)): text for n, text in labels.items()} | {k: label}
    Y = states(result, omegas)
    T = np.asarray(result.target_points, dtype=float)
    S, faces = _target_shape(result, target)
    _check_coordinates(Y, T, S)
    decimals = _decimals(Y)
    paths = crease_paths(pat, omega)
    dist = state_distances(Y, T, at, slack=10.0 ** -decimals)
    cmax = float(_rounded(dist[at].max(), decimals)) or 10.0 ** -decimals
    steps = []
    for n, w in enumerate(omegas):
        xyz = _coordinates(Y[n].reshape(-1, 3), paths, decimals)
        restyle = {**xyz, "intensity": [_listed(dist[n], decimals), None, None, None]}
        steps.append({"method": "restyle", "args": [restyle, [0, 1, 2, 3]],
                      "label": DESIGNED if n == at else labels.get(n, f"{w:.2f}"),
                      "value": f"{w:.17g}"})
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
    fig = {"data": data, "layout": layout}
    if ties:
        add_ties(fig, Y.reshape(len(Y), -1, 3), tie_ids(ties, pat.N, pat.M), at,
                 lambda a: _listed(a, decimals))
    return fig


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
               target: Surface | None = None, ties: Sequence | None = None) -> Path:
    """Write the figure of ``result`` (:func:`spec`, with ``target`` and ``ties``) as one
    self-contained HTML page (works offline), atomically; returns the path."""
    return write_figure(spec(result, frames, target, ties), path)


def write_figure(fig: dict, path: str | os.PathLike, title: str = "rffqm-nlp design") -> Path:
    """Write a figure {"data", "layout"} as one self-contained HTML page titled ``title``
    (works offline), atomically; returns the path."""
    page = ('<!DOCTYPE html>\n<html><head><meta charset="utf-8">'
            f"<title>{title}</title>"
            "<style>html,body{margin:0;height:100%}</style></head>\n<body>\n"
            f"{_div(fig, '100vh')}\n</body></html>\n")
    return write_text(path, page)
