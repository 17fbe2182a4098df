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
from rffqm_nlp import export, foldfile, marching
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
