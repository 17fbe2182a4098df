"""Pictures: matplotlib crease-pattern and convergence plots, pyvista renders and folding GIFs.

matplotlib is always available. The 3-D renders need the optional extra ``viz`` (pyvista,
imageio) and an off-screen OpenGL context: EGL or OSMesa (Debian: ``libegl1 libegl-mesa0
libgl1-mesa-dri``); :func:`rendering_available` says whether rendering works here.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from collections.abc import Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..io.export import COLORS, KIND_NAMES, draw_creases
from ..files import atomic_path
from ..io.foldfile import faces_vertices
from ..model.marching import fold
from ..model.pattern import Pattern, check_omega, motion_omegas
from ..targets.shape import distances_to

if TYPE_CHECKING:  # matplotlib and trimesh are imported where they are used
    import trimesh
    from matplotlib.axes import Axes

    from ..contact.collisions import CollisionReport
    from ..targets.curvature import Curvature

_HISTORY_KEYS = ("iter", "objective", "inf_pr")
#: A tiny off-screen render, run in a child process so a missing GL library cannot crash us.
_PROBE = """
import pyvista as pv
pv.OFF_SCREEN = True
p = pv.Plotter(off_screen=True, window_size=(32, 24))
p.add_mesh(pv.Sphere())
img = p.screenshot(return_img=True)
p.close()
assert img.shape == (24, 32, 3) and img.std() > 0, "blank image"
"""


# --------------------------------------------------------------------------- matplotlib
def plot_crease_pattern(pat: Pattern, omega: float, ax: Axes | None = None,
                        legend: bool = True) -> Axes:
    """Draw the flat crease pattern (mountain red, valley blue, boundary black) on ``ax``
    (a new figure when None); the assignments are those at ``omega``. Returns the Axes."""
    if ax is None:
        import matplotlib.pyplot as plt

        _, ax = plt.subplots(figsize=(6, 6))
    lines = draw_creases(ax, pat, omega)
    if legend:
        from matplotlib.lines import Line2D

        present = {ln.get_color() for ln in lines}
        handles = [Line2D([], [], color=c, label=KIND_NAMES[k])
                   for k, c in COLORS.items() if c in present]
        ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    return ax


def _check_history(history: Mapping[str, Sequence[float]]) -> dict[str, np.ndarray]:
    missing = [k for k in _HISTORY_KEYS if k not in history]
    if missing:
        raise InputError(f"history is missing the keys {missing}; it needs {list(_HISTORY_KEYS)}")
    out = {k: np.asarray(history[k], dtype=float).ravel() for k in _HISTORY_KEYS}
    sizes = {k: v.size for k, v in out.items()}
    if len(set(sizes.values())) != 1:
        raise InputError(f"history lists must have equal lengths, got {sizes}")
    return out


def plot_convergence(history: Mapping[str, Sequence[float]], path: str | os.PathLike) -> Path:
    """Objective and constraint violation (``inf_pr``) per iteration, log scale, to ``path``
    (format from the suffix: .png, .svg, .pdf). ``history`` maps "iter", "objective" and
    "inf_pr" to lists of equal length. Non-positive values are left out of the log plot."""
    from matplotlib.figure import Figure

    h = _check_history(history)
    fig = Figure(figsize=(6, 5), layout="constrained")
    ax_obj, ax_inf = fig.subplots(2, 1, sharex=True)
    for ax, key, label, color in ((ax_obj, "objective", "objective", "tab:blue"),
                                  (ax_inf, "inf_pr", "constraint violation", "tab:red")):
        keep = h[key] > 0
        ax.semilogy(h["iter"][keep], h[key][keep], ".-", color=color)
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    ax_inf.set_xlabel("iteration")
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, metadata=_no_date(Path(path).suffix))
    return Path(path)


def plot_curvature(curvature: Curvature, path: str | os.PathLike) -> Path:
    """The curvature maps of a :class:`~rffqm_nlp.targets.curvature.Curvature` to ``path``: a 2 x 2
    figure, design K and target K above, design H and target H below, one colour scale per
    row (shared by design and target; the H scale symmetric about 0 when H changes sign),
    each (N-1, M-1) map drawn at the interior lattice points i = 1..N-1 (down) and
    j = 1..M-1 (across)."""
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator

    rows = (("K", "Gaussian curvature K", "viridis"), ("H", "mean curvature H", "coolwarm"))
    fig = Figure(figsize=(8, 7), layout="constrained")
    axes = fig.subplots(2, 2)
    for (kind, label, cmap), row in zip(rows, axes):
        maps = [np.asarray(getattr(curvature, f"{who}_{kind}"), dtype=float)
                for who in ("design", "target")]
        lo = min(float(m.min()) for m in maps)
        hi = max(float(m.max()) for m in maps)
        if kind == "H" and lo < 0 < hi:
            lo, hi = -max(-lo, hi), max(-lo, hi)
        if hi - lo <= 1e-12 * max(abs(lo), abs(hi), 1e-300):
            lo, hi = lo - max(abs(lo), 1.0) * 0.05, hi + max(abs(hi), 1.0) * 0.05
        for ax, m, who in zip(row, maps, ("design (folded coarse lattice)", "target lattice")):
            n, k = m.shape  # lattice points 1..n along i, 1..k along j
            image = ax.imshow(m, cmap=cmap, vmin=lo, vmax=hi,
                              extent=(0.5, k + 0.5, n + 0.5, 0.5))
            ax.set_title(f"{label}: {who}", fontsize=10)
            ax.set_xlabel("j")
            ax.set_ylabel("i")
            ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        fig.colorbar(image, ax=row.tolist(), label=kind)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=100, metadata=_no_date(Path(path).suffix))
    return Path(path)


def _no_date(suffix: str) -> dict | None:
    """savefig metadata that keeps vector output free of timestamps."""
    return {".svg": {"Date": None}, ".pdf": {"CreationDate": None}}.get(suffix.lower())


# --------------------------------------------------------------------------- pyvista
def _offscreen() -> None:
    """With no display, VTK goes straight to EGL (falling back to OSMesa) instead of trying
    X: set for this process and the probe's child."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def _pyvista():
    """Import pyvista for off-screen use, or raise an ImportError naming the extra."""
    _offscreen()
    try:
        if importlib.util.find_spec("imageio") is None:  # checked here: the message names the extra
            raise ImportError("No module named 'imageio'")
        import pyvista as pv
    except ImportError as exc:
        raise ImportError("3-D rendering needs pyvista and imageio: install the 'viz' extra, "
                          f"pip install 'rffqm_nlp[viz]' ({exc})") from exc
    pv.OFF_SCREEN = True
    return pv


#: the probe's child process, started and not yet read (:func:`start_rendering_probe`)
_probe: subprocess.Popen | None = None


def start_rendering_probe() -> None:
    """Start :func:`rendering_available`'s probe, a child process, now, so that it runs
    beside other work (``rffqm design`` starts it before its solve); nothing where it is
    running, or where pyvista or imageio is missing."""
    global _probe
    if _probe is None and all(importlib.util.find_spec(m) for m in ("pyvista", "imageio")):
        _offscreen()
        _probe = subprocess.Popen([sys.executable, "-c", _PROBE], stdout=subprocess.DEVNULL,
                                  stderr=subprocess.PIPE, text=True)


@lru_cache(maxsize=1)
def rendering_available() -> tuple[bool, str]:
    """(True, "") when off-screen pyvista rendering works, else (False, reason).

    Tries one tiny render in a child process (once per session; the one
    :func:`start_rendering_probe` started, if any): a missing EGL/OSMesa library can abort
    the process instead of raising.
    """
    global _probe
    try:
        _pyvista()
    except ImportError as exc:
        return False, str(exc)
    start_rendering_probe()
    probe, _probe = _probe, None
    try:
        _, stderr = probe.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        probe.kill()
        probe.communicate()
        return False, "off-screen rendering probe timed out"
    if probe.returncode != 0:
        tail = (stderr.strip().splitlines() or ["no message"])[-1]
        return False, (f"off-screen rendering failed (exit {probe.returncode}: {tail}); "
                       "install EGL or OSMesa (Debian: libegl1 libegl-mesa0 libgl1-mesa-dri)")
    return True, ""


def _polydata(pv, Y: np.ndarray, N: int, M: int):
    """The folded vertices (N+1, M+1, 3) as a PolyData of quads a, c, d, b."""
    quads = faces_vertices(N, M)
    cells = np.hstack([np.full((len(quads), 1), 4), quads]).ravel()
    return pv.PolyData(Y.reshape(-1, 3), cells)


#: Scalar bar title of render.png with a target mesh.
TARGET_DISTANCE = "target: distance to the design"


def _add_target_mesh(pv, p, mesh, target) -> None:
    """Draw the target mesh on ``p`` coloured by each of its vertices' distance to the
    folded ``mesh`` (the design), and the design's creases as black lines over it."""
    surf = pv.wrap(target).copy()
    distance = surf.compute_implicit_distance(mesh.triangulate())["implicit_distance"]
    surf[TARGET_DISTANCE] = np.abs(distance)
    p.add_mesh(surf, scalars=TARGET_DISTANCE, cmap="viridis",
               scalar_bar_args={"title": TARGET_DISTANCE, "color": "black"})
    p.add_mesh(mesh, style="wireframe", color="black", line_width=1)


def _add_target(pv, p, mesh, target) -> np.ndarray:
    """Draw the target points ``target`` (n, 3) translucent on ``p``; return every mesh
    vertex's distance to the nearest of them."""
    pts = np.asarray(target, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise InputError(f"target must be a trimesh.Trimesh or (n, 3) points, got shape "
                         f"{pts.shape}")
    p.add_points(pts, color="gray", opacity=0.5, point_size=4)
    return distances_to(mesh.points, pts)


def _plotter(pv, size: tuple[int, int]):
    p = pv.Plotter(off_screen=True, window_size=(int(size[0]), int(size[1])))
    p.set_background("white")
    return p


def _mark_contacts(p, mesh, contacts, M: int) -> None:
    """Draw the panels of ``contacts`` (a :class:`~rffqm_nlp.contact.collisions.CollisionReport`:
    its pairs at the first contact and its flat overlaps) red, outlined in thick red."""
    panels = {(i - 1) * M + (j - 1) for pair in [*contacts.pairs, *contacts.flat_overlaps]
              for i, j in pair}
    if panels:
        cells = mesh.extract_cells(sorted(panels))
        p.add_mesh(cells, color="red", show_edges=True, edge_color="darkred", line_width=4)


def render_png(path: str | os.PathLike, pat: Pattern, omega: float,
               target: trimesh.Trimesh | np.ndarray | None = None,
               size: tuple[int, int] = (800, 600),
               contacts: CollisionReport | None = None) -> Path:
    """Render the folded state at ``omega`` to a PNG of ``size`` (width, height) pixels.

    With a ``target`` mesh (a trimesh.Trimesh in the frame of :func:`marching.fold`) the
    target is drawn coloured by its distance to the design, with the design's creases as
    lines; with target points ((n, 3), same frame) the origami is coloured by its distance
    to them, drawn translucent; otherwise the origami is coloured by height z. With
    ``contacts``, a :class:`~rffqm_nlp.contact.collisions.CollisionReport` that is not free, the
    panels in contact (at its first contact, or overlapping flat) are drawn red.
    """
    pv = _pyvista()
    import imageio.v3 as iio

    mesh = _polydata(pv, fold(pat, float(check_omega(omega))), pat.N, pat.M)
    p = _plotter(pv, size)
    try:
        if hasattr(target, "vertices") and hasattr(target, "faces"):
            _add_target_mesh(pv, p, mesh, target)
        else:
            title = "z" if target is None else "distance to target"
            mesh[title] = (mesh.points[:, 2] if target is None
                           else _add_target(pv, p, mesh, target))
            p.add_mesh(mesh, scalars=title, cmap="viridis", show_edges=True,
                       edge_color="black", scalar_bar_args={"title": title, "color": "black"})
        if contacts is not None and not contacts.free:
            _mark_contacts(p, mesh, contacts, pat.M)
        p.view_isometric()
        p.reset_camera()
        img = p.screenshot(return_img=True)
    finally:
        p.close()
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, img, extension=".png")
    return Path(path)


#: Size (width, height) in pixels of the frames of :func:`folding_gif`.
GIF_SIZE = (480, 360)


def folding_gif(path: str | os.PathLike, pat: Pattern, omega_end: float, frames: int = 24,
                size: tuple[int, int] = GIF_SIZE, duration_ms: int = 80) -> Path:
    """A looping GIF of the folding motion from flat (omega = 0) to ``omega_end``, in
    ``frames`` states, coloured by height z with one colour scale for the whole motion."""
    omegas = motion_omegas(omega_end, frames, minimum=2)
    pv = _pyvista()
    import imageio.v3 as iio

    Ys = fold(pat, omegas)
    mesh = _polydata(pv, Ys[0], pat.N, pat.M)
    mesh["z"] = Ys[0][..., 2].ravel()
    z_lo, z_hi = float(Ys[..., 2].min()), float(Ys[..., 2].max())
    zlim = (z_lo, max(z_hi, z_lo + 1e-9))
    p = _plotter(pv, size)
    images = []
    try:
        p.add_mesh(mesh, scalars="z", clim=zlim, cmap="viridis", show_edges=True,
                   edge_color="black", show_scalar_bar=False)
        p.view_isometric()
        p.reset_camera(bounds=_union_bounds(Ys))
        for Y in Ys:
            mesh.points = Y.reshape(-1, 3)
            mesh["z"] = Y[..., 2].ravel()
            p.render()
            images.append(p.screenshot(return_img=True))
    finally:
        p.close()
    with atomic_path(path) as tmp:
        iio.imwrite(tmp, np.stack(images), extension=".gif", duration=duration_ms, loop=0)
    return Path(path)


def _union_bounds(Ys: np.ndarray) -> tuple[float, ...]:
    """(xmin, xmax, ymin, ymax, zmin, zmax) over every state, so the camera never moves."""
    pts = Ys.reshape(-1, 3)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return tuple(float(v) for pair in zip(lo, hi) for v in pair)
