"""From design to object (issue 45): the files of ``rq.make`` and ``rffqm make`` read back
with independent readers (svgelements, ezdxf and its audit, pypdf, trimesh, manifold3d,
the csv module, the FOLD writer), and the issue's goals measured on the bundled sphere
cap: the outline within 0.05 mm at 300 mm, every crease on its layer, closed thick
solids of at least 0.7 of area times thickness at 1% of the panel size that stay apart
from flat to the designed state, ties whose length matches the folded pattern to 1e-9
and whose rate is at least 0.05 of the pattern's size per radian."""

from __future__ import annotations

import csv
import importlib
import math

import ezdxf
import manifold3d as mf
import numpy as np
import pytest
import svgelements
import trimesh
from pypdf import PdfReader
from shapely.geometry import Polygon
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp.cli import app
from rffqm_nlp.contact import thick
from rffqm_nlp.io.foldfile import fold_dict
from rffqm_nlp.make import lock, options, sheet, solids
from rffqm_nlp.show import view

#: px per mm of an SVG reader (CSS: 96 px per inch)
PX = 96 / 25.4
WIDTH = 300.0


@pytest.fixture(scope="module")
def cap():
    """The bundled sphere cap, designed (20 x 20 panels)."""
    problem, opts = rq.load_design("targets/sphere_cap.toml")
    return problem.solve(opts)


@pytest.fixture(scope="module")
def panel_size(cap):
    """The mean side of the panels at 300 mm (mm)."""
    pat = cap.pattern
    scale = WIDTH / np.ptp(pat.X[..., 0])
    return float(np.mean(np.r_[pat.lh.ravel(), pat.lv.ravel()]) * scale)


@pytest.fixture(scope="module")
def made(cap, panel_size, tmp_path_factory):
    """``rq.make`` of the cap at 300 mm, 1% of the panel size thick, written out."""
    out = tmp_path_factory.mktemp("made") / "cap"
    return rq.make(cap, out, width="300mm", thickness=0.01 * panel_size), out


def scaled_pattern(cap, made_):
    """The flat pattern scaled to the sheet (mm, lowest corner at 0), (N+1, M+1, 2)."""
    X = cap.pattern.X[..., :2]
    return (X - X.reshape(-1, 2).min(axis=0)) * made_.scale


def outline_of(P):
    return np.concatenate([P[0, :-1], P[:-1, -1], P[-1, :0:-1], P[:0:-1, 0]])


# --------------------------------------------------------------------------- options
def test_lengths_take_units_and_refuse_the_rest_in_one_line():
    assert options.length("300mm", "w") == 300.0
    assert options.length("30 cm", "w") == 300.0
    assert options.length("1in", "w") == pytest.approx(25.4)
    assert options.length(2.5, "w") == options.length("2.5", "w") == 2.5
    for bad in ("abc", -1, "1e9mm", True, None, float("nan")):
        with pytest.raises(rq.InputError) as exc:
            options.length(bad, "width", positive=True)
        assert "width" in str(exc.value) and "\n" not in str(exc.value)


def test_options_in_one_place(tmp_path):
    o = options.make_options({"process": "cutter", "thickness": "0.3mm"}, dash=4)
    assert (o.process, o.thickness, o.dash, o.gap) == ("cutter", 0.3, 4.0, 1.0)
    assert options.make_options(process="print").hinge_gap == 0.4
    with pytest.raises(rq.InputError, match="one of width, height and scale"):
        options.make_options(width=100, scale=2.0)
    with pytest.raises(rq.InputError, match="unknown key"):
        options.make_options({"widht": 100})
    with pytest.raises(rq.InputError, match="process"):
        options.make_options(process="waterjet")
    path = tmp_path / "make.toml"
    path.write_text('[make]\nheight = "20cm"\nkerf = 0.1\n')
    table = options.read_make_table(path)
    assert options.make_options(table).height == 200.0
    assert options.MakeOptions(scale=2.0).mm_per_unit((3.0, 4.0)) == 2.0


def test_perforation_starts_and_ends_on_dash_boundaries():
    for length in (1.0, 5.0, 17.3, 40.0, 123.4):
        starts, ends = sheet.perforation(length, 3.0, 1.0, 1.0)
        relief = min(1.0, length / 4)
        assert starts[0] == pytest.approx(relief) and ends[-1] == pytest.approx(length - relief)
        dash, gaps = ends - starts, starts[1:] - ends[:-1]
        assert np.allclose(dash, dash[0]) and np.allclose(gaps, dash[0] / 3)
        assert (ends - starts).sum() >= 0.5 * (length - 2 * relief)


# --------------------------------------------------------------------------- cut files
def svg_layers(path):
    """{layer id: {path id: points (k, 2) in mm, y up}} of an SVG, read by svgelements."""
    doc = svgelements.SVG.parse(str(path), reify=True)
    height = doc.height / PX
    layers = {}
    for group in doc.elements():
        if isinstance(group, svgelements.Group) and group.id in ("CUT", "MOUNTAIN", "VALLEY"):
            layers[group.id] = {}
            for p in group:
                if isinstance(p, svgelements.Path):
                    pts = [(s.end.x / PX, height - s.end.y / PX) for s in p.segments()
                           if not isinstance(s, svgelements.Close)]
                    layers[group.id][p.id] = np.array(pts)
    return doc, layers


def test_svg_at_true_scale_outline_and_every_crease_on_its_layer(cap, made):
    made_, out = made
    doc, layers = svg_layers(out / "cut.svg")
    W, H = made_.sheet.size
    assert W == pytest.approx(WIDTH, abs=1e-9)
    assert doc.values["width"] == f"{WIDTH:g}mm" and doc.width / PX == pytest.approx(W)
    ring = layers["CUT"]["outline"]
    expected = outline_of(scaled_pattern(cap, made_))
    assert ring.shape == expected.shape
    assert np.abs(ring - expected).max() < 0.05                  # the goal: 0.05 mm
    rows = list(csv.DictReader(open(out / "fold_angles.csv")))
    N, M = cap.pattern.N, cap.pattern.M
    assert len(rows) == (N + 1) * M + N * (M + 1) - 2 * (N + M)
    for row in rows:
        name = "crease-{i1}-{j1}-{i2}-{j2}".format(**row)
        layer = "MOUNTAIN" if row["assignment"] == "M" else "VALLEY"
        assert name in layers[layer]
        assert (float(row["angle_deg"]) > 0) == (row["assignment"] == "V")
        P = scaled_pattern(cap, made_)
        a = P[int(row["i1"]) - 1, int(row["j1"]) - 1]
        b = P[int(row["i2"]) - 1, int(row["j2"]) - 1]
        assert float(row["length_mm"]) == pytest.approx(np.linalg.norm(b - a), rel=1e-9)
        pts = layers[layer][name]                     # every dash on the crease's line
        t = (b - a) / np.linalg.norm(b - a)
        off = pts - a
        assert np.abs(t[0] * off[:, 1] - t[1] * off[:, 0]).max() < 1e-3


def test_fold_angles_agree_with_the_fold_file(cap, made):
    made_, out = made
    d = fold_dict(cap.pattern, cap.omega)
    inner = [k for k, a in enumerate(d["edges_assignment"]) if a != "B"]
    rows = list(csv.DictReader(open(out / "fold_angles.csv")))
    assert [d["edges_assignment"][k] for k in inner] == [r["assignment"] for r in rows]
    assert np.allclose([d["edges_foldAngle"][k] for k in inner],
                       [float(r["angle_deg"]) for r in rows], atol=1e-6)


def test_dxf_in_mm_passes_ezdxf_audit(cap, made):
    made_, out = made
    doc = ezdxf.readfile(out / "cut.dxf")
    auditor = doc.audit()
    assert not auditor.has_errors and not auditor.has_fixes
    assert doc.header["$INSUNITS"] == 4
    assert {"CUT", "MOUNTAIN", "VALLEY"} <= {layer.dxf.name for layer in doc.layers}
    msp = doc.modelspace()
    (poly,) = msp.query("LWPOLYLINE[layer=='CUT']")
    ring = np.array([p[:2] for p in poly.get_points()])
    assert np.abs(ring - outline_of(scaled_pattern(cap, made_))).max() < 0.05
    lines = {layer: len(msp.query(f"LINE[layer=='{layer}']")) for layer in ("MOUNTAIN",
                                                                             "VALLEY")}
    kinds = made_.sheet.kinds
    assert lines["MOUNTAIN"] >= (kinds == "M").sum() and lines["VALLEY"] >= (kinds == "V").sum()


def test_pdf_page_is_the_sheet_at_one_to_one(made):
    made_, out = made
    box = PdfReader(out / "cut.pdf").pages[0].mediabox
    W, H = made_.sheet.size
    assert float(box.width) == pytest.approx(W / 25.4 * 72, abs=0.01)
    assert float(box.height) == pytest.approx(H / 25.4 * 72, abs=0.01)
    pages = PdfReader(out / "assembly.pdf").pages
    assert len(pages) >= 2                             # an overview, then A4 tiles at 1:1
    a4 = (210 / 25.4 * 72, 297 / 25.4 * 72)
    assert all(float(p.mediabox.width) == pytest.approx(a4[0], abs=0.05) for p in pages)


def test_back_side_is_the_sheet_turned_over(made):
    made_, out = made
    _, front = svg_layers(out / "cut.svg")
    _, back = svg_layers(out / "cut_back.svg")
    W = made_.sheet.size[0]
    assert set(back["MOUNTAIN"]) == set(front["VALLEY"])
    assert set(back["VALLEY"]) == set(front["MOUNTAIN"])
    for name, pts in front["MOUNTAIN"].items():
        mirrored = back["VALLEY"][name]
        assert np.allclose(mirrored[:, 0], W - pts[:, 0], atol=1e-3)    # svgelements'
        assert np.allclose(mirrored[:, 1], pts[:, 1], atol=1e-3)        # mm in px: 1e-6


def test_kerf_offsets_the_outline_by_half_of_it(cap):
    s = sheet.Sheet.of(cap.pattern, cap.omega, 20.0)
    tool = sheet.cut_outline(s, 0.2)
    shrunk = Polygon(tool).buffer(-0.1, join_style="mitre")
    original = Polygon(s.outline)
    assert shrunk.symmetric_difference(original).area < 1e-6 * original.area
    assert np.array_equal(sheet.cut_outline(s, 0.0)[:-1], s.outline)


# --------------------------------------------------------------------------- thick panels
def test_thick_solids_closed_and_full_at_one_percent(cap, made, panel_size):
    made_, out = made
    scene = trimesh.load(out / "panels.glb", process=False)       # the file's own indices
    meshes = list(scene.geometry.values())
    N, M = cap.pattern.N, cap.pattern.M
    assert len(meshes) == N * M
    t = 0.01 * panel_size
    X = scaled_pattern(cap, made_)
    areas = [Polygon([X[i, j], X[i, j + 1], X[i + 1, j + 1], X[i + 1, j]]).area
             for i in range(N) for j in range(M)]
    volumes = {name: m.volume for name, m in scene.geometry.items()}
    for name, mesh in scene.geometry.items():
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    ratios = np.array([volumes[f"panel_{i}_{j}"] / (areas[(i - 1) * M + j - 1] * t)
                       for i in range(1, N + 1) for j in range(1, M + 1)])
    assert ratios.min() >= 0.7                                  # the goal
    assert np.allclose(ratios, made_.solids.volume_ratios, rtol=1e-4)   # float32 files
    stl = trimesh.load(out / "panels.stl")
    assert stl.volume == pytest.approx(sum(volumes.values()), rel=1e-4)
    assert made_.thick.free and made_.thick.vertex_pairs_checked == 2 * (N - 1) * (M - 1)


def _placed_manifolds(pat, panels, omega, scale=1.0):
    """manifold3d solids of the tapered panels moved to ``omega`` (pattern units)."""
    sol = solids.build_solids(pat, panels.omega, scale, panels.thickness * scale,
                              "back" if panels.side < 0 else "front")
    R, T = thick.panel_frames(pat, rq.numpy_model.fold(pat, omega))
    R, T = R.reshape(-1, 3, 3), T.reshape(-1, 3) * scale
    out = []
    for p, (v, f) in enumerate(zip(sol.vertices, sol.faces)):
        solid = mf.Manifold(mf.Mesh(np.asarray(v, np.float32), np.asarray(f, np.uint32)))
        assert solid.volume() > 0
        out.append(solid.transform(np.c_[R[p], T[p]]))
    return out


def test_neighbours_never_overlap_until_the_design_and_do_beyond(cap):
    """Crease neighbours and vertex neighbours, intersected by manifold3d: no overlap from
    flat to the designed state; folding on past it, the bevels press into each other."""
    pat, om = cap.pattern, cap.omega
    t = 0.02 * float(np.mean(pat.lh))
    panels = thick.ThickPanels.build(pat, om, t, "back")
    N, M = pat.N, pat.M
    p = lambda i, j: i * M + j                                    # noqa: E731
    pairs = [(p(i, j), p(i, j + 1)) for i in range(0, N, 3) for j in range(0, M - 1, 3)]
    pairs += [(p(i, j), p(i + 1, j)) for i in range(0, N - 1, 3) for j in range(0, M, 3)]
    pairs += [(p(i, j), p(i + 1, j + 1)) for i in range(0, N - 1, 3) for j in range(0, M - 1, 3)]
    for w in np.linspace(0, om, 5):
        solid = _placed_manifolds(pat, panels, w)
        least = min(s.volume() for s in solid)
        overlap = max((solid[a] ^ solid[b]).volume() for a, b in pairs)
        assert overlap < 1e-5 * least               # round-off of float32 meshes at most
    beyond = _placed_manifolds(pat, panels, om + 0.3 * (math.pi - om))
    assert max((beyond[a] ^ beyond[b]).volume() for a, b in pairs[:10]) > 1e-2 * least


def test_cone_gaps_are_exact_for_vertex_neighbours():
    """The cones' angular distance against manifold3d's intersection of the solids of the
    two panels that share only a vertex, past the designed state of their bevels: each
    pair with a positive gap is apart, each with a negative one overlaps."""
    pat = rq.numpy_model.march(rq.miura_boundary(4, 4, alpha0=1.1))
    t = 0.15
    panels = thick.ThickPanels.build(pat, 1.0, t, "back")
    h, rays, _ = panels.cones()
    rows = np.array([[0, 0, 2, 1, 1, 0], [0, 1, 3, 1, 0, 1], [1, 1, 2, 2, 2, 0],
                     [1, 2, 3, 2, 1, 1], [2, 2, 2, 3, 3, 0], [2, 1, 3, 3, 0, 1]])
    seen = set()
    for w in (0.5, 1.0, 2.0, 2.8, 3.1):
        R, _ = thick.panel_frames(pat, rq.numpy_model.fold(pat, w))
        Q = np.swapaxes(R[rows[:, 0], rows[:, 1]], -1, -2) @ R[rows[:, 3], rows[:, 4]]
        gap = thick.cone_gap(h[rows[:, 0], rows[:, 1], rows[:, 2]],
                             rays[rows[:, 0], rows[:, 1], rows[:, 2]],
                             np.einsum("nij,nrj->nri", Q, h[rows[:, 3], rows[:, 4], rows[:, 5]]),
                             np.einsum("nij,nrj->nri", Q, rays[rows[:, 3], rows[:, 4], rows[:, 5]]))
        solid = _placed_manifolds(pat, panels, w)
        for r, g in zip(rows, gap):
            volume = (solid[r[0] * 4 + r[1]] ^ solid[r[3] * 4 + r[4]]).volume()
            least = min(solid[r[0] * 4 + r[1]].volume(), solid[r[3] * 4 + r[4]].volume())
            if g > 1e-6:
                assert volume < 1e-6 * least
            elif g < 0:
                assert volume > 1e-6 * least
            seen.add(g > 0)
    assert seen == {True, False}                    # both kinds of case were met


def test_thick_check_flags_panels_too_thick(cap):
    rep = thick.thick_collisions(cap.pattern, cap.omega, 0.2 * float(np.mean(cap.pattern.lh)))
    assert not rep.free and rep.first_omega is not None and rep.pairs
    assert rep.far.clearance == pytest.approx(2 * rep.thickness)


# --------------------------------------------------------------------------- the lock
def test_lock_ties_match_the_folded_pattern_and_block_the_motion(cap, made):
    made_, out = made
    rows = list(csv.DictReader(open(out / "lock.csv")))
    assert len(rows) == 3
    assert list(rows[0]) == ["i1", "j1", "i2", "j2", "length_mm", "dlength_domega"]
    Y = rq.numpy_model.fold(cap.pattern, cap.omega) * made_.scale
    size = max(made_.sheet.size)
    for row in rows:
        a = (int(row["i1"]) - 1, int(row["j1"]) - 1)
        b = (int(row["i2"]) - 1, int(row["j2"]) - 1)
        length = float(row["length_mm"])
        assert length == pytest.approx(np.linalg.norm(Y[a] - Y[b]), rel=1e-9)   # the goal
        rate = float(row["dlength_domega"])
        assert abs(rate) >= 0.05 * size                                          # the goal
        h = 1e-6
        ends = lambda w: rq.numpy_model.fold(cap.pattern, w)[[a[0], b[0]], [a[1], b[1]]]  # noqa
        fd = [np.linalg.norm(np.subtract(*ends(cap.omega + s * h))) for s in (1, -1)]
        assert rate == pytest.approx((fd[0] - fd[1]) / (2 * h) * made_.scale, rel=1e-6)
    parts = trimesh.load(out / "lock.stl")                        # merged by position
    bodies = parts.split(only_watertight=False)
    assert len(bodies) == len(made_.ties) + len(made_.stops)
    assert all(b.is_watertight and b.volume > 0 for b in bodies)


def test_stops_are_the_fastest_creases(cap):
    stops = lock.crease_stops(cap.pattern, cap.omega, 2)
    gh, gv = rq.numpy_model.fold_angles(cap.pattern, [cap.omega - 1e-6, cap.omega + 1e-6])
    rate = np.abs(np.r_[(gh[1] - gh[0]).ravel(), (gv[1] - gv[0]).ravel()]) / 2e-6
    assert abs(stops[0].dangle_domega) == pytest.approx(rate.max(), rel=1e-5)


def test_ties_in_the_view(cap, made):
    made_, _ = made
    fig = view.spec(cap, frames=4, ties=made_.ties)
    assert len(fig["data"]) == len(view.TRACES) + 1
    trace = fig["data"][-1]
    step = fig["layout"]["sliders"][0]["steps"][fig["layout"]["sliders"][0]["active"]]
    assert step["args"][1][-1] == len(fig["data"]) - 1
    tie = made_.ties[0]
    y = cap.folded[tie.i1 - 1, tie.j1 - 1]
    assert trace["x"][0] == pytest.approx(y[0], abs=1e-2 * np.ptp(cap.folded))
    assert view.spec(cap, frames=4)["data"][-1]["name"] == "target"


# --------------------------------------------------------------------------- the command
def test_rffqm_make_writes_the_folder_whole(cap, tmp_path):
    cap.save(tmp_path / "cap")
    out = tmp_path / "made"
    runner = CliRunner()
    result = runner.invoke(app, ["make", str(tmp_path / "cap"), "--width", "200mm",
                                 "--thickness", "0.2mm", "--ties", "2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    names = {p.name for p in out.iterdir()}
    assert {"cut.svg", "cut.dxf", "cut.pdf", "cut_back.svg", "fold_angles.csv",
            "assembly.pdf", "panels.stl", "panels.glb", "lock.csv", "lock.stl",
            "view.html", "make.json"} <= names
    again = runner.invoke(app, ["make", str(tmp_path / "cap"), "--out", str(out)])
    assert again.exit_code == 2 and "--force" in again.output
    bad = runner.invoke(app, ["make", str(tmp_path / "cap"), "--width", "wide", "--out",
                              str(tmp_path / "x")])
    assert bad.exit_code == 2 and "--width" not in names and not (tmp_path / "x").exists()


def test_rq_make_is_called_as_the_function():
    """rq.make is the package (importing it sets the attribute) and calls make()."""
    assert rq.make is importlib.import_module("rffqm_nlp.make") and callable(rq.make)
    with pytest.raises(rq.InputError, match="result must be"):
        rq.make(3.0)
