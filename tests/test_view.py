"""The interactive view (rffqm_nlp.show.view) without a browser: traces, slider, page."""

from __future__ import annotations

import base64
import gzip
import json
import re
from dataclasses import replace

import numpy as np
import pytest
from plotly.offline import get_plotlyjs
from scipy.spatial import cKDTree
from view_results import miura_result

from rffqm_nlp.model import numpy_model
from rffqm_nlp.design import results
from rffqm_nlp.show import view
from rffqm_nlp.errors import InputError
from rffqm_nlp.io.export import COLORS
from rffqm_nlp.io.foldfile import edge_assignments, edges_vertices


@pytest.fixture(scope="module")
def result():
    return miura_result(8, omega=1.3)


@pytest.fixture(scope="module")
def fig(result):
    return view.figure(result, frames=12)


def expected_state(result, w):
    """Pattern vertices at ``w`` in the target frame, ((N+1)(M+1), 3), from the model."""
    Y = numpy_model.fold(result.pattern, w) @ result.rotation.T + result.translation
    return Y.reshape(-1, 3)


def steps(fig):
    return fig.layout.sliders[0].steps


def payloads(html):
    """The two gzip+base64 strings of a page: plotly.js and the figure, decoded."""
    packed = re.findall(r'inflate\("([A-Za-z0-9+/=]+)"\)', html)
    assert len(packed) == 2
    return [gzip.decompress(base64.b64decode(p)).decode("utf-8") for p in packed]


def test_traces(fig):
    types = [t.type for t in fig.data]
    assert types == ["mesh3d", "scatter3d", "scatter3d", "scatter3d", "mesh3d"]
    assert [t.name for t in fig.data[1:4]] == ["mountain", "valley", "boundary"]
    assert [t.line.color for t in fig.data[1:4]] == [COLORS["M"], COLORS["V"], COLORS["B"]]
    mesh = fig.data[0]
    assert mesh.flatshading and mesh.lighting.diffuse > 0
    assert len(mesh.i) == 2 * 8 * 8 and len(mesh.x) == 9 * 9
    assert fig.data[4].visible is False
    (button,) = fig.layout.updatemenus[0].buttons
    assert button.args[0] == {"visible": True} and list(button.args[1]) == [4]
    assert button.args2[0] == {"visible": False} and list(button.args2[1]) == [4]


@pytest.mark.parametrize("omega, frames", [(1.3, 12), (-2.0, 5), (np.pi / 2, 3)])
def test_slider_steps(omega, frames):
    res = miura_result(4, omega=omega)
    st = view.spec(res, frames)["layout"]["sliders"][0]["steps"]
    assert len(st) == frames + 1
    designed = [s for s in st if s["label"] == view.DESIGNED]
    assert len(designed) == 1 and float(designed[0]["value"]) == omega
    w = np.array([float(s["value"]) for s in st])
    assert w[0] == 0.0 and w[-1] == pytest.approx(np.copysign(np.pi, omega))
    assert np.all(np.diff(np.abs(w)) >= 0)
    assert np.all(np.sign(w[1:]) == np.sign(omega))


@pytest.mark.parametrize("frames", [1, 0, 2.5, True])
def test_frames_checked(result, frames):
    with pytest.raises(InputError, match="frames"):
        view.figure(result, frames)


def test_starts_at_designed_state(result, fig):
    slider = fig.layout.sliders[0]
    assert slider.steps[slider.active].label == view.DESIGNED
    P = expected_state(result, result.omega)
    np.testing.assert_allclose(np.column_stack([fig.data[0].x, fig.data[0].y, fig.data[0].z]),
                               P, atol=1e-3 * np.abs(P).max())
    np.testing.assert_allclose(P.reshape(result.folded.shape), result.folded, atol=1e-12)


def test_steps_restyle_the_model_geometry(result, fig):
    """Every step's mesh coordinates are the model's fold at its omega, rounded to 4
    significant digits of the largest coordinate; only x, y, z and the distances move."""
    all_states = [expected_state(result, float(s.value)) for s in steps(fig)]
    atol = 0.5e-3 * max(np.abs(P).max() for P in all_states) * (1 + 1e-9)
    for s, P in zip(steps(fig), all_states):
        assert s.method == "restyle" and list(s.args[1]) == [0, 1, 2, 3]
        assert set(s.args[0]) == {"x", "y", "z", "intensity"}
        got = np.column_stack([s.args[0][a][0] for a in "xyz"])
        assert np.abs(got - P).max() <= atol
    P0 = all_states[0]
    normal = np.linalg.svd(P0 - P0.mean(axis=0))[2][-1]
    assert np.abs((P0 - P0.mean(axis=0)) @ normal).max() < 1e-9  # omega = 0 is flat


def crease_edges(trace_xyz, P):
    """The edges (vertex pairs) drawn by a crease trace, vertices found among P."""
    pts = np.column_stack([np.array(c, dtype=float) for c in trace_xyz])
    _, idx = cKDTree(P).query(np.nan_to_num(pts, nan=1e9))
    edges = set()
    for a, b, pa, pb in zip(idx[:-1], idx[1:], pts[:-1], pts[1:]):
        if not (np.isnan(pa).any() or np.isnan(pb).any()):
            edges.add((min(a, b), max(a, b)))
    return edges


@pytest.mark.parametrize("omega", [1.3, -0.7])
def test_crease_kinds_match_the_assignments(omega):
    res = miura_result(6, omega=omega)
    sp = view.spec(res, 4)
    step = next(s for s in sp["layout"]["sliders"][0]["steps"] if s["label"] == view.DESIGNED)
    P = expected_state(res, omega)
    kinds = edge_assignments(res.pattern, omega)
    ev = edges_vertices(res.pattern.N, res.pattern.M)
    seen = set()
    for n, kind in enumerate("MVB", start=1):
        drawn = crease_edges([step["args"][0][a][n] for a in "xyz"], P)
        expected = {tuple(sorted(e)) for e in ev[kinds == kind].tolist()}
        assert drawn == expected, kind
        assert sp["data"][n]["line"]["color"] == COLORS[kind]
        seen |= drawn
    assert len(seen) == len(ev)


def test_distances_to_a_plane():
    """Points above a flat lattice are at their height from it."""
    x, y = np.meshgrid(np.linspace(0, 4, 5), np.linspace(0, 3, 4), indexing="ij")
    T = np.stack([x, y, np.zeros_like(x)], axis=-1)
    pts = np.array([[1.25, 1.5, 0.3], [3.0, 0.125, -0.2], [2.0, 2.0, 0.0]])
    np.testing.assert_allclose(view.distances(pts, T), [0.3, 0.2, 0.0], atol=1e-12)
    assert view.target_samples(T, 4).shape == (17, 13, 3)


def test_intensity_is_the_distance_to_the_target(result, fig):
    """The target is the coarse lattice lifted by 0.1: the designed state's coarse vertices
    lie within 0.1 of it, and the colour range ends at the largest distance."""
    s = steps(fig)[fig.layout.sliders[0].active]
    d = np.array(s.args[0]["intensity"][0]).reshape(9, 9)
    assert np.all(d[::2, ::2] <= 0.1 + 1e-3) and d[::2, ::2].min() > 0.02
    assert fig.data[0].cmin == 0 and fig.data[0].cmax == pytest.approx(d.max(), abs=1e-3)
    flat = np.array(steps(fig)[0].args[0]["intensity"][0])
    assert flat.max() > d.max()


def test_page_is_self_contained(result, tmp_path):
    path = view.write_html(result, tmp_path / "view.html", frames=6)
    html = path.read_text()
    assert re.search(r"<script[^>]*\bsrc\s*=", html) is None
    assert re.search(r"<link\b", html) is None
    plotly_js, figure_json = payloads(html)
    assert plotly_js == get_plotlyjs()
    assert json.loads(figure_json)["data"] == json.loads(json.dumps(view.spec(result, 6)["data"]))
    assert [p.name for p in tmp_path.iterdir()] == ["view.html"]


def test_write_is_atomic(result, tmp_path):
    path = tmp_path / "view.html"
    path.write_text("old")
    with pytest.raises(InputError):
        view.write_html(result, path, frames=1)
    assert path.read_text() == "old"
    view.write_html(result, path, frames=3)
    assert path.read_text().startswith("<!DOCTYPE html>")
    assert [p.name for p in tmp_path.iterdir()] == ["view.html"]


def test_repr_html(result):
    html = view.repr_html(result)
    assert html.startswith('<div id="rffqm-view-') and "</script>" in html
    _, figure_json = payloads(html)
    assert len(json.loads(figure_json)["layout"]["sliders"][0]["steps"]) == 25


def test_page_size_at_40_by_40(tmp_path):
    path = view.write_html(miura_result(40), tmp_path / "view.html")
    assert path.stat().st_size < 5_000_000


def test_target_trace_uses_the_kept_target_grid(result):
    """A result that keeps a target grid (its target cannot be rebuilt) draws that grid as
    the target surface, and frames the scene around it."""
    T = np.asarray(result.target_points)
    u = np.linspace(0.0, 1.0, 13)[:, None, None]
    v = np.linspace(0.0, 1.0, 11)[None, :, None]
    grid = T[0, 0] + u * (T[-1, 0] - T[0, 0]) + v * (T[0, -1] - T[0, 0]) + [0.0, 0.0, 3.0]
    kept = replace(result, target_grid=grid)
    target = view.spec(kept, frames=4)["data"][4]
    assert target["type"] == "mesh3d" and len(target["i"]) == 2 * 12 * 10
    np.testing.assert_allclose(np.array(target["z"]), grid[..., 2].ravel(), atol=1e-3)
    z_range = view.spec(kept, frames=4)["layout"]["scene"]["zaxis"]["range"]
    assert z_range[1] >= grid[..., 2].max()
    plain = view.spec(result, frames=4)["data"][4]  # no config: the target lattice's cells
    assert len(plain["z"]) == T.shape[0] * T.shape[1]
    rebuilt = replace(result, problem={"target": {"name": "sphere_cap"}})
    assert len(view.spec(rebuilt, frames=4)["data"][4]["z"]) == results.TARGET_MESH ** 2
