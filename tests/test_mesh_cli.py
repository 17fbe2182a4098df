"""``rffqm design`` with a mesh or point cloud file as TARGET, and ``[target] mesh = ...``:
the design, its files, and one line with exit status 2 for every bad shape file."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp import design
from rffqm_nlp.show import pictures as viz
from rffqm_nlp.cli import app

runner = CliRunner()
CAP = {"radius": 4.0, "domain": [[-0.6, 0.6], [-0.6, 0.6]]}


def run_design(path: Path, out: Path, *extra: str):
    return runner.invoke(app, ["design", str(path), "--out", str(out), "--quiet", *extra])


def cap_mesh(folder: Path, name: str = "cap.stl", n: int = 21) -> Path:
    path = folder / name
    rq.surfaces.get("sphere_cap", **CAP).mesh(n, n).export(path)
    return path


def _two_pieces(folder: Path) -> Path:
    quad = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    faces = [[0, 1, 2], [1, 3, 2]]
    both = trimesh.util.concatenate([trimesh.Trimesh(quad, faces),
                                     trimesh.Trimesh(quad + [0, 0, 5], faces)])
    both.export(folder / "pieces.obj")
    return folder / "pieces.obj"


def _written(name: str, data: bytes):
    def make(folder: Path) -> Path:
        (folder / name).write_bytes(data)
        return folder / name
    return make


def _closed(folder: Path) -> Path:
    trimesh.creation.icosphere(2).export(folder / "ball.stl")
    return folder / "ball.stl"


def _folder(folder: Path) -> Path:
    (folder / "part.stl").mkdir()
    return folder / "part.stl"


def _archive(folder: Path) -> Path:
    with zipfile.ZipFile(folder / "part.zip", "w") as archive:
        archive.writestr("part.obj", trimesh.exchange.obj.export_obj(
            rq.surfaces.get("sphere_cap", **CAP).mesh(9, 9)))
    return folder / "part.zip"


def _too_large_file(folder: Path) -> Path:
    with open(folder / "part.stl", "wb") as handle:
        handle.truncate(rq.meshes.MAX_FILE_BYTES + 1)  # sparse: nothing written
    return folder / "part.stl"


def _too_many_triangles(folder: Path) -> Path:
    return cap_mesh(folder, "part.stl", n=225)  # 100352 triangles


SECRET = "SECRETTOKEN"
GARBAGE = np.random.default_rng(0).bytes(4000)
BAD_FILES = [
    ("archive", _archive, ["part.zip", "archives are not unpacked"]),
    ("too-large", _too_large_file, ["part.stl", "more than the 50 MB read", "decimate"]),
    ("too-many-triangles", _too_many_triangles,
     ["part.stl", "100352 triangles", "decimate it to at most 100000"]),
    ("quoting-ply", _written("part.ply", f"ply\nformat ascii 1.0\nelement vertex 3\nproperty "
                                         f"{SECRET} x\nend_header\n1\n2\n3\n".encode()),
     ["part.ply", "could not be parsed as a PLY file"]),
    ("empty", _written("part.stl", b""), ["part.stl", "no triangles and no points"]),
    ("garbage-stl", _written("part.stl", GARBAGE), ["cannot read", "part.stl"]),
    ("garbage-ply", _written("part.ply", GARBAGE), ["cannot read", "part.ply"]),
    ("garbage-off", _written("part.off", GARBAGE), ["cannot read", "part.off"]),
    ("garbage-glb", _written("part.glb", GARBAGE), ["cannot read", "part.glb"]),
    ("garbage-xyz", _written("part.xyz", GARBAGE), ["cannot read", "part.xyz"]),
    ("missing", lambda folder: folder / "none.obj", ["none.obj", "no such file"]),
    ("folder", _folder, ["part.stl", "is a folder"]),
    ("closed", _closed, ["ball.stl", "closed surface", "crop it"]),
    ("pieces", _two_pieces, ["pieces.obj", "2 separate pieces", "keep one"]),
]


@pytest.mark.parametrize("make, fragments", [c[1:] for c in BAD_FILES],
                         ids=[c[0] for c in BAD_FILES])
def test_bad_shape_files_are_refused_in_one_line(tmp_path, make, fragments):
    path = make(tmp_path)
    out = tmp_path / "out"
    res = run_design(path, out, "--panels", "8", "8")
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.exit_code == 2, (res.exit_code, res.output)
    assert len(lines) == 1 and "Traceback" not in res.output, res.output
    assert SECRET not in res.output
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name] * path.exists()


def test_load_design_reads_a_mesh_file_with_the_default_options(tmp_path, monkeypatch):
    path = cap_mesh(tmp_path)
    monkeypatch.chdir(tmp_path)
    problem, options = rq.load_design("cap.stl")
    assert isinstance(problem.target, rq.surfaces.Mesh)
    assert problem.target.to_config() == {"mesh": str(path.resolve())}
    assert options == rq.SolveOptions() and problem.panels == design.DesignProblem(
        problem.target).panels
    assert rq.meshes.is_mesh_file("a/B.PLY") and not rq.meshes.is_mesh_file("a/b.toml")


def test_design_from_a_mesh_file(tmp_path, monkeypatch):
    path = cap_mesh(tmp_path, n=41)
    drawn = {}

    def render_png(out, pattern, omega, target=None, **kw):
        drawn["target"] = target
        Path(out).write_text("png")

    monkeypatch.setattr(viz, "rendering_available", lambda: (True, ""))
    monkeypatch.setattr(viz, "render_png", render_png)
    monkeypatch.setattr(viz, "folding_gif", lambda out, *a, **kw: Path(out).write_text("gif"))
    out = tmp_path / "out"
    res = run_design(path, out, "--panels", "8", "8")
    assert res.exit_code == 0, res.output
    data = json.loads((out / "result.json").read_text())
    assert data["problem"]["target"] == {"mesh": str(path.resolve())}
    assert data["problem"]["design"]["panels"] == [8, 8]
    fit = data["fit"]
    assert fit["rms_surface"] < 0.25 * fit["plane_rms"] and 0.9 < fit["coverage"] < 1.1
    assert fit["hausdorff_vertices"] >= fit["hausdorff"]
    # render.png draws the shape itself (its 41 x 41 vertices), moved into the pattern frame
    result = rq.DesignResult.load(out)
    target = drawn["target"]
    assert isinstance(target, trimesh.Trimesh) and len(target.vertices) == 41 * 41
    moved = target.vertices @ result.rotation.T + result.translation
    assert trimesh.proximity.closest_point(trimesh.load(path), moved)[1].max() < 1e-9
    # the saved result rebuilds its target from the path: an absolute path, which a file
    # from others may name only with trust
    with pytest.raises(rq.SurfaceError, match="outside the folder"):
        rq.surfaces.from_config(data["problem"]["target"])
    assert isinstance(rq.surfaces.from_config(data["problem"]["target"], trust=True),
                      rq.surfaces.Mesh)


def test_a_design_file_names_a_mesh_relative_to_itself(tmp_path, monkeypatch):
    (tmp_path / "jobs" / "shapes").mkdir(parents=True)
    path = cap_mesh(tmp_path / "jobs" / "shapes")
    toml = tmp_path / "jobs" / "part.toml"
    toml.write_text('[target]\nmesh = "shapes/cap.stl"\n\n[design]\npanels = [8, 8]\n\n'
                    '[solve]\nstop_rms = 0.02\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    problem, options = rq.load_design(Path("..") / "jobs" / "part.toml")
    assert isinstance(problem.target, rq.surfaces.Mesh) and problem.panels == (8, 8)
    assert problem.target.path == path.resolve() and options.stop_rms == 0.02
    assert problem.to_config()["target"] == {"mesh": str(path.resolve())}


@pytest.mark.parametrize("table, fragments", [
    ('mesh = 3', ["[target] mesh", "string"]),
    ('mesh = "shapes/none.stl"', ["none.stl", "no such file"]),
    ('mesh = "cap.stl"\nname = "sphere_cap"', ["[target]", "name"]),
    ('mesh = "cap.stl"\nknots = [8, 8]', ["[target]", "knots"]),
])
def test_bad_mesh_keys_are_refused_in_one_line(tmp_path, table, fragments):
    cap_mesh(tmp_path)
    toml = tmp_path / "part.toml"
    toml.write_text(f"[target]\n{table}\n")
    out = tmp_path / "out"
    res = run_design(toml, out)
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert res.exit_code == 2 and len(lines) == 1, res.output
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert not out.exists()


@pytest.mark.parametrize("how", ["absolute", "dots"])
def test_a_design_file_opens_no_mesh_outside_its_folder(tmp_path, how):
    """A file from others names meshes only in its own folder unless the caller trusts it."""
    (tmp_path / "private").mkdir()
    (tmp_path / "downloads").mkdir()
    path = cap_mesh(tmp_path / "private")
    name = str(path) if how == "absolute" else "../private/cap.stl"
    toml = tmp_path / "downloads" / "part.toml"
    toml.write_text(f'[target]\nmesh = "{name}"\n[design]\npanels = [8, 8]\n')
    result = runner.invoke(app, ["design", str(toml), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and "[target] mesh names a file outside" in result.stderr
    assert "private" not in result.stderr and not (tmp_path / "out").exists()
    problem, _ = rq.load_design(toml, trust=True)
    assert isinstance(problem.target, rq.surfaces.Mesh)
