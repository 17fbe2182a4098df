"""SVG/PDF/DXF crease patterns, OBJ/PLY/GLB meshes and the EXPORTERS registry."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import Counter

import ezdxf
import numpy as np
import pytest
import trimesh
from crease_patterns import OMEGA, PATTERNS, expected_kinds, make_pattern, n_edges

import rffqm_nlp as rq
from rffqm_nlp.io import export
from rffqm_nlp.io import foldfile
from rffqm_nlp.model import marching
from rffqm_nlp.errors import InputError


@pytest.fixture(scope="module", params=PATTERNS)
def pat(request):
    return make_pattern(request.param)


# --------------------------------------------------------------------------- 2-D files
def test_crease_segments(pat):
    segs = export.crease_segments(pat, OMEGA)
    assert len(segs) == n_edges(pat)
    assert Counter(k for *_, k in segs) == expected_kinds(pat)
    assert all(p0.shape == (2,) and np.linalg.norm(p1 - p0) > 0 for p0, p1, _ in segs)


def test_svg_one_coloured_path_per_crease(pat, tmp_path):
    path = export.write_svg(tmp_path / "p.svg", pat, OMEGA)
    root = ET.parse(path).getroot()
    strokes = []
    for el in root.iter("{http://www.w3.org/2000/svg}path"):
        style = dict(item.strip().split(":", 1) for item in el.get("style", "").split(";")
                     if ":" in item)
        strokes.append(style.get("stroke", "").strip())
    colour = {v: k for k, v in export.COLORS.items()}
    assert Counter(colour[s] for s in strokes) == expected_kinds(pat)
    again = export.write_svg(tmp_path / "q.svg", pat, OMEGA)
    assert path.read_bytes() == again.read_bytes()


def test_pdf(pat, tmp_path):
    path = export.write_pdf(tmp_path / "p.pdf", pat, OMEGA)
    assert path.read_bytes().startswith(b"%PDF")


def test_dxf_layers(pat, tmp_path):
    path = export.write_dxf(tmp_path / "p.dxf", pat, OMEGA)
    doc = ezdxf.readfile(path)
    lines = doc.modelspace().query("LINE")
    layer_kind = {name: k for k, (name, _) in export.DXF_LAYERS.items()}
    assert Counter(layer_kind[e.dxf.layer] for e in lines) == expected_kinds(pat)
    assert doc.layers.get("MOUNTAIN").color == 1 and doc.layers.get("VALLEY").color == 5
    assert doc.layers.get("BOUNDARY").color == 7


def test_files_written_atomically(tmp_path):
    pat = marching.march(rq.miura_boundary(2, 2))
    target = tmp_path / "p.obj"
    target.write_text("old")
    with pytest.raises(InputError):
        export.write_mesh(tmp_path / "p.stl", pat, OMEGA)
    export.write_mesh(target, pat, OMEGA)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.obj"]
    assert target.read_text() != "old"


# --------------------------------------------------------------------------- meshes
@pytest.mark.parametrize("suffix", [".obj", ".ply", ".glb"])
def test_mesh_files(pat, tmp_path, suffix):
    path = export.write_mesh(tmp_path / f"p{suffix}", pat, OMEGA)
    mesh = trimesh.load(path, force="mesh")
    N, M = pat.N, pat.M
    assert len(mesh.vertices) == (N + 1) * (M + 1)
    assert len(mesh.faces) == 2 * N * M
    edges = Counter(map(tuple, np.sort(mesh.edges, axis=1)))
    assert sum(1 for n in edges.values() if n == 1) == 2 * (N + M)
    expected = export.folded_mesh(pat, OMEGA)
    np.testing.assert_allclose(np.sort(mesh.vertices, axis=0),
                               np.sort(expected.vertices, axis=0), atol=1e-6)
    if suffix == ".glb":
        assert path.read_bytes()[:4] == b"glTF"


def test_folded_mesh_geometry(pat):
    flat = export.folded_mesh(pat, 0.0)
    np.testing.assert_allclose(flat.face_normals, np.tile([0, 0, 1.0], (len(flat.faces), 1)),
                               atol=1e-12)
    folded = export.folded_mesh(pat, OMEGA)
    np.testing.assert_allclose(folded.vertices, marching.fold(pat, OMEGA).reshape(-1, 3))
    # Panels stay rigid: every triangle keeps its flat area.
    np.testing.assert_allclose(folded.area_faces, flat.area_faces, rtol=1e-9)


# --------------------------------------------------------------------------- registry
def test_registry_every_format(tmp_path):
    pat = marching.march(rq.miura_boundary(2, 3))
    assert set(export.EXPORTERS) == {"fold", "svg", "pdf", "dxf", "obj", "ply", "glb"}
    assert len({e.filename for e in export.EXPORTERS.values()}) == len(export.EXPORTERS)
    for name, exporter in export.EXPORTERS.items():
        assert exporter.suffix == f".{name}"
        path = exporter.write(tmp_path / exporter.filename, pat, OMEGA, frames=3,
                              metadata={"note": "x"})
        assert path == tmp_path / exporter.filename and path.stat().st_size > 0
    back, omega, meta = foldfile.read_fold(tmp_path / "pattern.fold")
    assert omega == OMEGA and meta == {"note": "x"}
    np.testing.assert_array_equal(back.X, pat.X)
    assert len(json.loads((tmp_path / "pattern.fold").read_text())["file_frames"]) == 3
    mesh = trimesh.load(tmp_path / "folded.ply", force="mesh", process=False)
    np.testing.assert_allclose(mesh.vertices, marching.fold(pat, OMEGA).reshape(-1, 3),
                               atol=1e-6)


# --------------------------------------------------------------------------- finite output
def _scaled(side: float) -> rq.Pattern:
    """A 2 x 2 Miura-ori whose sides are all ``side``."""
    return marching.march(rq.miura_boundary(2, 2, a=side, b=side))


def _no_inf_or_nan(path) -> None:
    """The file holds no spelled-out NaN or infinity (and a FOLD file is strict JSON)."""
    if path.suffix == ".fold":
        json.loads(path.read_text(), parse_constant=lambda c: pytest.fail(f"{path}: {c}"))
    elif path.suffix in (".svg", ".dxf", ".obj"):
        text = path.read_text().lower()
        assert "nan" not in text.split() and "inf" not in text and "infinity" not in text


@pytest.mark.parametrize("side, refused", [
    (1e150, {"ply", "glb"}),                  # beyond a 32-bit float
    (4e307, {"ply", "glb", "svg", "pdf"}),    # the drawing's bounds overflow a 64-bit float
])
def test_every_exporter_refuses_what_its_numbers_cannot_hold(tmp_path, side, refused):
    pat = _scaled(side)
    for name, exporter in export.EXPORTERS.items():
        path = tmp_path / exporter.filename
        path.write_text("old")
        if name in refused:
            with pytest.raises(InputError) as info:
                exporter.write(path, pat, OMEGA, frames=3)
            message = str(info.value)
            assert "\n" not in message and message.startswith(f"cannot write {path}: "), message
            assert ("32-bit float" in message) if name in ("ply", "glb") else \
                ("NaN or inf" in message), message
            assert path.read_text() == "old"
        else:
            exporter.write(path, pat, OMEGA, frames=3)
            _no_inf_or_nan(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        e.filename for e in export.EXPORTERS.values())          # no temporary file left


def test_mesh_number_types():
    assert export.MESH_NUMBERS["ply"][0] == export.MESH_NUMBERS["glb"][0] == float(
        np.finfo(np.float32).max)
    assert export.MESH_NUMBERS["obj"][0] == float(np.finfo(np.float64).max)
    assert set(export.MESH_NUMBERS) == set(export.MESH_FORMATS.values())


def test_a_folding_that_overflows_is_never_written(tmp_path, monkeypatch):
    """Folded coordinates or fold angles that come out NaN or infinite (an overflow) are
    refused by every writer of the folded state, and by the functions that return them."""
    pat = marching.march(rq.miura_boundary(2, 2))

    def overflowing(pattern, omega):
        Y = marching.fold(pattern, omega)
        return np.where(np.arange(Y.shape[-2])[:, None] == 1, np.inf, Y)

    monkeypatch.setattr(export, "fold", overflowing)
    monkeypatch.setattr(foldfile, "fold", overflowing)
    with pytest.raises(InputError, match="the folded coordinates at omega 1.3 hold NaN or inf"):
        export.folded_mesh(pat, OMEGA)
    with pytest.raises(InputError, match="the folded coordinates of the frames hold NaN"):
        foldfile.fold_dict(pat, OMEGA, frames=3)
    for name in ("obj", "ply", "glb", "fold"):
        exporter = export.EXPORTERS[name]
        with pytest.raises(InputError, match=rf"^cannot write .*{exporter.filename}: .*NaN"):
            exporter.write(tmp_path / exporter.filename, pat, OMEGA, frames=3)
    monkeypatch.setattr(foldfile, "fold_angles",
                        lambda pattern, omega: (np.full((3, 2), np.nan), np.zeros((2, 3))))
    with pytest.raises(InputError, match="the fold angles at omega 1.3 hold NaN or inf"):
        foldfile.edge_fold_angles(pat, OMEGA)
    for name in ("svg", "pdf", "dxf"):
        exporter = export.EXPORTERS[name]
        with pytest.raises(InputError, match=rf"^cannot write .*{exporter.filename}: the fold "
                                             "angles"):
            exporter.write(tmp_path / exporter.filename, pat, OMEGA)
    assert list(tmp_path.iterdir()) == []


def test_fold_metadata_must_be_finite():
    pat = marching.march(rq.miura_boundary(2, 2))
    with pytest.raises(InputError, match="rffqm:rms holds NaN or inf"):
        foldfile.fold_dict(pat, OMEGA, metadata={"rms": float("nan")})
    with pytest.raises(InputError, match="rffqm:seed holds a whole number of 400 digits"):
        foldfile.fold_dict(pat, OMEGA, metadata={"seed": int("9" * 400)})
