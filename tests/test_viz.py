"""Pictures: matplotlib plots and pyvista renders (off-screen rendering must work: a
machine without EGL or OSMesa fails these tests with the reason)."""

from __future__ import annotations

import sys

import imageio.v3 as iio
import matplotlib
import numpy as np
import pytest
import trimesh

import rffqm_nlp as rq
from rffqm_nlp.model import marching
from rffqm_nlp.show import pictures as viz
from rffqm_nlp.io import export
from rffqm_nlp.errors import InputError

matplotlib.use("Agg")
OMEGA = 1.3


@pytest.fixture(scope="module")
def pat():
    return marching.march(rq.miura_boundary(4, 5))


@pytest.fixture(scope="module")
def rendering():
    ok, reason = viz.rendering_available()
    if not ok:
        pytest.fail(f"off-screen rendering is needed: {reason}")


# --------------------------------------------------------------------------- matplotlib
def test_plot_crease_pattern(pat):
    import matplotlib.pyplot as plt

    ax = viz.plot_crease_pattern(pat, OMEGA)
    try:
        colours = [ln.get_color() for ln in ax.lines]
        assert len(colours) == len(export.crease_segments(pat, OMEGA))
        assert set(colours) == set(export.COLORS.values())
        assert [t.get_text() for t in ax.get_legend().get_texts()] == [
            "mountain", "valley", "boundary"]
    finally:
        plt.close(ax.figure)


def test_plot_crease_pattern_on_given_axes(pat):
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    assert viz.plot_crease_pattern(pat, OMEGA, ax=ax, legend=False) is ax
    assert ax.get_legend() is None and ax.get_aspect() == 1.0


@pytest.mark.parametrize("suffix", [".png", ".svg", ".pdf"])
def test_plot_convergence(tmp_path, suffix):
    history = {"iter": [0, 1, 2, 3], "objective": [1.0, 0.1, 1e-3, 1e-5],
               "inf_pr": [1.0, 1e-2, 0.0, 1e-9]}
    path = viz.plot_convergence(history, tmp_path / f"conv{suffix}")
    data = path.read_bytes()
    assert len(data) > 1000
    if suffix == ".png":
        img = iio.imread(path)
        assert img.std() > 0


def test_plot_convergence_rejects_bad_history(tmp_path):
    with pytest.raises(InputError, match="inf_pr"):
        viz.plot_convergence({"iter": [0], "objective": [1.0]}, tmp_path / "c.png")
    with pytest.raises(InputError, match="equal lengths"):
        viz.plot_convergence({"iter": [0, 1], "objective": [1.0], "inf_pr": [1.0]},
                             tmp_path / "c.png")


def test_missing_pyvista_names_the_extra(monkeypatch, pat, tmp_path):
    monkeypatch.setitem(sys.modules, "pyvista", None)
    with pytest.raises(ImportError, match="viz"):
        viz.render_png(tmp_path / "x.png", pat, OMEGA)


# --------------------------------------------------------------------------- pyvista
def test_a_probe_started_ahead_is_the_one_rendering_available_reads(monkeypatch):
    """start_rendering_probe starts the child once; rendering_available (asked afresh)
    waits for that child, reads its answer and starts none of its own; a failing child's
    last stderr line is the reason."""
    started = []
    real = viz.subprocess.Popen
    monkeypatch.setattr(viz.subprocess, "Popen", lambda *a, **kw: started.append(a) or real(
        *a, **kw))
    monkeypatch.setattr(viz, "_probe", None)
    viz.rendering_available.cache_clear()
    try:
        viz.start_rendering_probe()
        viz.start_rendering_probe()
        assert len(started) == 1 and viz._probe is not None
        assert viz.rendering_available() == (True, "")
        assert len(started) == 1 and viz._probe is None
        viz.rendering_available.cache_clear()
        monkeypatch.setattr(viz, "_PROBE", "raise SystemExit('no GL here')")
        ok, reason = viz.rendering_available()
        assert not ok and "exit 1: no GL here" in reason and len(started) == 2
    finally:
        viz.rendering_available.cache_clear()


def _check_image(path, size):
    img = iio.imread(path)
    assert img.shape[:2] == (size[1], size[0])
    assert img.reshape(-1, img.shape[-1]).std(axis=0).max() > 5  # not blank


def test_render_png(rendering, pat, tmp_path):
    path = viz.render_png(tmp_path / "fold.png", pat, OMEGA, size=(320, 240))
    _check_image(path, (320, 240))


def test_render_png_shows_the_fold(rendering, pat, tmp_path):
    """Two fold angles give two different pictures, each with more than background."""
    images = [iio.imread(viz.render_png(tmp_path / f"fold{k}.png", pat, omega, size=(160, 120)))
              for k, omega in enumerate((0.4, 2.4))]
    for img in images:
        background = img[0, 0]
        assert (img != background).any(axis=-1).mean() > 0.01
    assert np.abs(images[0].astype(int) - images[1].astype(int)).max() > 50


@pytest.mark.parametrize("kind", ["points", "mesh"])
def test_render_png_with_target(rendering, pat, tmp_path, kind):
    Y = marching.fold(pat, OMEGA).reshape(-1, 3)
    target = Y + [0.0, 0.0, 0.2] if kind == "points" else trimesh.Trimesh(
        Y + [0.0, 0.0, 0.2], export.triangles(pat.N, pat.M), process=False)
    path = viz.render_png(tmp_path / f"{kind}.png", pat, OMEGA, target=target, size=(300, 200))
    _check_image(path, (300, 200))


def test_folding_gif(rendering, pat, tmp_path):
    path = viz.folding_gif(tmp_path / "fold.gif", pat, 2.5, frames=6, size=(160, 120))
    frames = iio.imread(path, index=None)
    assert frames.shape[:3] == (6, 120, 160)
    assert frames[0].std() > 0 and not np.array_equal(frames[0], frames[-1])


def test_rendering_unavailable_gives_reason(monkeypatch):
    monkeypatch.setattr(viz, "_PROBE", "import sys; sys.exit('no EGL here')")
    viz.rendering_available.cache_clear()
    try:
        ok, reason = viz.rendering_available()
    finally:
        viz.rendering_available.cache_clear()
    assert not ok and "no EGL here" in reason and "libegl1" in reason
