"""The rffqm command: every command's files, and a one-line reason for every user error.

One real design (an 8 x 8 sphere cap, ~20 s) runs once per module; the other tests reuse
its output folder, or replace the solve by the saved result where only the file handling
is under test.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from rffqm_nlp.io import export
from rffqm_nlp.io import foldfile
from rffqm_nlp.model import marching
from rffqm_nlp.targets import surfaces
from rffqm_nlp.show import pictures as viz
from rffqm_nlp.cli import app
from rffqm_nlp.design import DesignProblem
from rffqm_nlp.errors import SolverFailed
from rffqm_nlp.design.results import DesignResult

runner = CliRunner()

SMALL = """
[target]
name = "sphere_cap"
radius = 4.0

[design]
panels = [8, 8]
{extra}

[solve]
{solve}
"""
DESIGN_FILES = {"result.json", "pattern.fold", "crease.svg", "crease.pdf", "crease.dxf",
                "folded.obj", "folded.glb", "convergence.png", "view.html", "curvature.png"}
RENDER_FILES = {"render.png", "folding.gif"}
N_VERTICES = 9 * 9


def invoke(*args: str):
    return runner.invoke(app, [str(a) for a in args])


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    return struct.unpack(">II", data[16:24])


def assert_user_error(res, *fragments: str) -> str:
    """Non-zero exit, no traceback, exactly one error line that names every fragment."""
    assert res.exit_code != 0, res.output
    assert isinstance(res.exception, (SystemExit, type(None))), repr(res.exception)
    assert "Traceback" not in res.output
    errors = [ln for ln in res.output.splitlines() if "error" in ln.lower()]
    assert len(errors) == 1, res.output
    for fragment in fragments:
        assert fragment in errors[0], (fragment, res.output)
    return errors[0]


def write_toml(folder: Path, name: str, extra: str = "", solve: str = "") -> Path:
    """A design file of SMALL with ``extra`` [design] and ``solve`` [solve] lines."""
    path = folder / name
    path.write_text(SMALL.format(extra=extra, solve=solve))
    return path


def leftovers(folder: Path) -> list[str]:
    """Hidden temporary files or folders the commands might have left in ``folder``."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


@pytest.fixture(scope="module")
def designed(tmp_path_factory):
    base = tmp_path_factory.mktemp("design")
    toml = write_toml(base, "cap.toml")
    out = base / "runs" / "cap"
    res = invoke("design", toml, "--out", out)
    assert res.exit_code == 0, res.output
    return out, res


@pytest.fixture(scope="module")
def result(designed) -> DesignResult:
    return DesignResult.load(designed[0])


@pytest.fixture
def fake_solve(monkeypatch, result):
    """Replace the IPOPT solve by the module's saved result (file handling tests)."""
    monkeypatch.setattr(DesignProblem, "solve", lambda self, *args, **kw: result)


# --------------------------------------------------------------------------- design
def test_design_writes_every_file(designed, result):
    out, res = designed
    rendering, reason = viz.rendering_available()
    names = {p.name for p in out.iterdir()}
    assert names == DESIGN_FILES | (RENDER_FILES if rendering else set())
    assert leftovers(out.parent) == []
    for word in ("Hausdorff", "smallest side / mean", "smallest sector angle", "iterations",
                 "Solve_Succeeded", "collision-free from flat to omega"):
        assert word in res.output
    if not rendering:
        assert "warning" in res.output and reason.split()[0] in res.output

    assert result.stats.success and result.pattern.N == 8 and result.pattern.M == 8
    assert result.fit.rms < result.fit.plane_rms
    pat, omega, meta = foldfile.read_fold(out / "pattern.fold")
    assert omega == pytest.approx(result.omega)
    np.testing.assert_allclose(pat.X, result.pattern.X)
    assert meta["target"]["name"] == "sphere_cap" and meta["fit"] == result.fit.to_dict()
    frames = json.loads((out / "pattern.fold").read_text())["file_frames"]
    assert len(frames) == 24
    assert frames[0]["rffqm:omega"] == 0.0
    assert frames[-1]["rffqm:omega"] == pytest.approx(result.omega)
    for name in ("folded.obj", "folded.glb"):
        mesh = trimesh.load(out / name, force="mesh", process=False)
        assert len(mesh.vertices) == N_VERTICES and len(mesh.faces) == 2 * 64
    assert (out / "crease.svg").read_text().lstrip().startswith("<?xml")
    assert (out / "crease.pdf").read_bytes()[:5] == b"%PDF-"
    import ezdxf

    assert len(ezdxf.readfile(out / "crease.dxf").modelspace().query("LINE")) == 2 * 8 * 9
    assert png_size(out / "convergence.png")[0] > 100
    if rendering:
        assert png_size(out / "render.png") == (800, 600)
        assert (out / "folding.gif").read_bytes()[:6] == b"GIF89a"


def test_design_panels_two_words_and_progress_lines(tmp_path, monkeypatch):
    seen = {}

    def failing(self, options, callback=None, **kw):
        seen["panels"], seen["max_iter"] = self.panels, options.max_iter
        if callback is not None:
            callback({"iter": 0, "objective": 1.0, "inf_pr": 0.5, "elapsed": 0.0})
        raise SolverFailed("IPOPT did not converge: status Stop_Here", status="Stop_Here")

    monkeypatch.setattr(DesignProblem, "solve", failing)
    toml = write_toml(tmp_path, "t.toml")
    for panels in (["--panels", "4", "6"], ["--panels", "4,6"]):
        res = invoke("design", toml, *panels, "--max-iter", "7", "--out", tmp_path / "o")
        assert_user_error(res, "Stop_Here")
        assert seen == {"panels": (4, 6), "max_iter": 7}
        assert "Levenberg-Marquardt iteration 0" in res.output  # plain progress (no terminal)
    res = invoke("design", "--panels", "6", "4", toml, "--out", tmp_path / "o", "--quiet")
    assert_user_error(res, "Stop_Here")
    assert seen["panels"] == (6, 4) and "Levenberg-Marquardt iteration" not in res.output
    assert not (tmp_path / "o").exists() and leftovers(tmp_path) == []
    ipopt = write_toml(tmp_path, "ipopt.toml", solve='solver = "ipopt"')
    res = invoke("design", ipopt, "--out", tmp_path / "o")
    assert "IPOPT iteration 0" in res.output


def test_design_without_rendering_warns_and_force_replaces_the_folder(tmp_path, fake_solve,
                                                                       monkeypatch):
    monkeypatch.setattr(viz, "rendering_available", lambda: (False, "no OpenGL here"))
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    (out / "crease.svg").write_text("old")
    res = invoke("design", write_toml(tmp_path, "t.toml"), "--out", out, "--force")
    assert res.exit_code == 0, res.output
    assert "warning" in res.output and "no OpenGL here" in res.output
    assert {p.name for p in out.iterdir()} == DESIGN_FILES          # replaced whole
    assert (out / "crease.svg").read_text() != "old"
    assert leftovers(tmp_path) == []
    DesignResult.load(out)


def test_failure_after_the_solve_leaves_no_files(tmp_path, fake_solve, monkeypatch):
    def broken(*args, **kw):
        raise OSError("No space left on device")

    monkeypatch.setitem(export.EXPORTERS, "dxf", export.Exporter("crease.dxf", broken))
    out = tmp_path / "deep" / "out"
    res = invoke("design", write_toml(tmp_path, "t.toml"), "--out", out, "-q")
    assert_user_error(res, "No space left on device")
    assert not out.exists() and leftovers(tmp_path / "deep") == []


# --------------------------------------------------------------------------- fold
def test_fold_one_omega_to_stdout(designed, result):
    res = invoke("fold", designed[0], "--omega", "1.0")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert data["omega"] == 1.0 and data["frame"] == "pattern"
    assert np.asarray(data["Y"]).shape == (9, 9, 3)


def test_fold_frames_to_file(designed, result, tmp_path):
    path = tmp_path / "states.json"
    res = invoke("fold", designed[0], "--frames", "5", "--aligned", "--out", path)
    assert res.exit_code == 0, res.output
    data = json.loads(path.read_text())
    Y = np.asarray(data["Y"])
    assert Y.shape == (5, 9, 9, 3) and data["frame"] == "target"
    np.testing.assert_allclose(data["omega"], np.linspace(0, result.omega, 5))
    np.testing.assert_allclose(Y[-1], result.folded, atol=1e-9)
    assert leftovers(tmp_path) == []


# --------------------------------------------------------------------------- export
@pytest.mark.parametrize("fmt", ["fold", "svg", "dxf", "pdf", "obj", "ply", "glb"])
def test_export_every_format(designed, result, tmp_path, fmt):
    path = tmp_path / f"x.{fmt}"
    res = invoke("export", designed[0], "--format", fmt, "--out", path, "--omega", "1.5")
    assert res.exit_code == 0, res.output
    assert path.stat().st_size > 0
    if fmt == "fold":
        pat, omega, _ = foldfile.read_fold(path)
        assert omega == 1.5 and pat.N == 8
    elif fmt in ("obj", "ply", "glb"):
        mesh = trimesh.load(path, force="mesh", process=False)
        assert len(mesh.vertices) == N_VERTICES
        np.testing.assert_allclose(np.asarray(mesh.vertices).reshape(9, 9, 3),
                                   marching.fold(result.pattern, 1.5), atol=1e-5)
    assert leftovers(tmp_path) == []


# --------------------------------------------------------------------------- render, targets
def test_render(designed, tmp_path):
    ok, reason = viz.rendering_available()
    assert ok, f"off-screen rendering is needed: {reason}"
    out = tmp_path / "pictures"
    res = invoke("render", designed[0], "--out", out, "--frames", "4")
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} == RENDER_FILES
    assert png_size(out / "render.png") == (800, 600)
    import imageio.v3 as iio

    assert iio.imread(out / "folding.gif", index=None).shape[0] == 4


def test_render_into_a_result_folder_keeps_it(designed, tmp_path, monkeypatch):
    """render writes its two files into an existing folder one by one (atomically each)
    and never replaces the folder."""
    monkeypatch.setattr(viz, "rendering_available", lambda: (True, ""))
    monkeypatch.setattr(viz, "render_png", lambda path, *a, **kw: Path(path).write_text("png"))
    monkeypatch.setattr(viz, "folding_gif", lambda path, *a, **kw: Path(path).write_text("gif"))
    folder = tmp_path / "result"
    folder.mkdir()
    for name in ("result.json", "crease.svg"):
        (folder / name).write_bytes((designed[0] / name).read_bytes())
    (folder / "notes.txt").write_text("mine")
    inode = folder.stat().st_ino
    res = invoke("render", folder, "--frames", "3")
    assert res.exit_code == 0, res.output
    assert {p.name for p in folder.iterdir()} == {"result.json", "crease.svg", "notes.txt",
                                                  *RENDER_FILES}
    assert folder.stat().st_ino == inode and (folder / "render.png").read_text() == "png"
    assert leftovers(folder) == [] and leftovers(tmp_path) == []


def test_render_without_rendering_fails_cleanly(designed, tmp_path, monkeypatch):
    monkeypatch.setattr(viz, "rendering_available", lambda: (False, "no OpenGL here"))
    res = invoke("render", designed[0], "--out", tmp_path / "p")
    assert_user_error(res, "cannot render", "no OpenGL here")
    assert not (tmp_path / "p").exists()


# --------------------------------------------------------------------------- view
def test_view_writes_a_small_self_contained_page(designed, tmp_path):
    out = tmp_path / "view.html"
    res = invoke("view", designed[0], "--out", out, "--frames", "6")
    assert res.exit_code == 0, res.output
    html = out.read_text()
    assert html.startswith("<!DOCTYPE html>") and 'class="rffqm-view"' in html
    assert "<script src" not in html and out.stat().st_size < 5_000_000
    assert [p.name for p in tmp_path.iterdir()] == ["view.html"]
    # the design wrote the same page (24 states) into its folder
    written = (designed[0] / "view.html").stat().st_size
    assert 0 < written < 5_000_000


def test_view_defaults_to_the_result_folder(designed, tmp_path):
    folder = tmp_path / "result"
    folder.mkdir()
    (folder / "result.json").write_bytes((designed[0] / "result.json").read_bytes())
    res = invoke("view", folder / "result.json", "--frames", "3")
    assert res.exit_code == 0, res.output
    assert {p.name for p in folder.iterdir()} == {"result.json", "view.html"}


def test_view_bad_input_exits_2_in_one_line(designed, tmp_path):
    for args, fragments in (
            ([tmp_path / "none"], ["no design result"]),
            ([designed[0], "--out", tmp_path / "view.png"], ["--out", ".html"]),
            ([designed[0], "--out", tmp_path / "no" / "v.html"], ["--out", "no folder"]),
            ([designed[0], "--frames", "1", "--out", tmp_path / "v.html"], ["--frames"])):
        res = invoke("view", *args)
        assert res.exit_code == 2, res.output
        assert_user_error(res, *fragments)
    assert list(tmp_path.iterdir()) == []


def test_curvature_png_of_the_design(designed, result):
    assert png_size(designed[0] / "curvature.png")[0] > 500
    assert result.curvature.design_K.shape == (3, 3)


def test_targets_lists_every_builtin():
    res = invoke("targets")
    assert res.exit_code == 0, res.output
    for name in surfaces.names():
        assert name in res.output
    assert "radius" in res.output


@pytest.mark.parametrize("command", [[], ["design"], ["fold"], ["export"], ["render"],
                                     ["view"], ["check"], ["targets"], ["march"]])
def test_help(command):
    res = invoke(*command, "--help")
    assert res.exit_code == 0 and "Usage" in res.output


def test_march_still_works(tmp_path):
    out = tmp_path / "m"
    res = invoke("march", "--rows", "4", "--cols", "5", "--out", out, "--frames", "3")
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} == {"boundary.json", "pattern.json",
                                               "folded.json", "frames.json"}
    assert np.asarray(json.loads((out / "frames.json").read_text())["Y"]).shape == (3, 5, 6, 3)
    assert_user_error(invoke("march", "--out", out), "not empty", "--force")
    res = invoke("march", "--rows", "2", "--cols", "2", "--out", out, "--force")
    assert res.exit_code == 0, res.output
    assert {p.name for p in out.iterdir()} == {"boundary.json", "pattern.json", "folded.json"}
    assert leftovers(tmp_path) == []


# --------------------------------------------------------------------------- user errors
def test_design_missing_file(tmp_path):
    res = invoke("design", tmp_path / "nothere.toml", "--out", tmp_path / "o")
    assert_user_error(res, "no such design file", "nothere.toml")
    assert not (tmp_path / "o").exists()


def test_design_bad_toml(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[target\nname = 1\n")
    assert_user_error(invoke("design", path, "--out", tmp_path / "o"), "not valid TOML")
    assert not (tmp_path / "o").exists()


def test_design_unknown_target(tmp_path):
    path = tmp_path / "blob.toml"
    path.write_text('[target]\nname = "blob"\n')
    assert_user_error(invoke("design", path, "--out", tmp_path / "o"),
                      "[target] name must be one of", "got the string 'blob'", "sphere_cap")
    assert not (tmp_path / "o").exists()


def test_design_refuses_non_empty_folder_before_solving(tmp_path, monkeypatch):
    def never(self, **kw):
        raise AssertionError("the solve ran before the output folder was checked")

    monkeypatch.setattr(DesignProblem, "solve", never)
    out = tmp_path / "o"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    res = invoke("design", write_toml(tmp_path, "t.toml"), "--out", out)
    assert_user_error(res, "not empty", "--force")
    assert [p.name for p in out.iterdir()] == ["keep.txt"]


def test_design_infeasible(tmp_path):
    res = invoke("design", write_toml(tmp_path, "t.toml", "min_length = 1.5"),
                 "--out", tmp_path / "o", "--quiet")
    line = assert_user_error(res, "min_length")
    assert res.output.strip() == line.strip()
    assert not (tmp_path / "o").exists() and leftovers(tmp_path) == []


def test_design_solver_failure_names_status(tmp_path):
    res = invoke("design", write_toml(tmp_path, "t.toml", solve="max_iter = 1"),
                 "--out", tmp_path / "o", "--quiet")
    line = assert_user_error(res, "Maximum_Iterations_Exceeded")
    assert res.output.strip() == line.strip()
    assert not (tmp_path / "o").exists() and leftovers(tmp_path) == []


@pytest.mark.parametrize("panels", ["7", "7 8", "a,b"])
def test_design_bad_panels(tmp_path, panels):
    res = invoke("design", write_toml(tmp_path, "t.toml"), "--out", tmp_path / "o",
                 "--panels", *panels.split())
    assert_user_error(res, "panels")


def test_march_failing_final_check(tmp_path):
    out = tmp_path / "m"
    res = invoke("march", "--rows", "10", "--cols", "10", "--perturb", "0.157", "--seed", "0",
                 "--out", out)
    assert_user_error(res, "final check", "panel (")
    assert not out.exists() and leftovers(tmp_path) == []


def test_result_commands_on_missing_or_broken_results(tmp_path):
    missing = tmp_path / "none"
    for args in (["fold", missing, "--omega", "1"], ["export", missing, "-f", "svg"],
                 ["render", missing]):
        assert_user_error(invoke(*args), "no design result")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "result.json").write_text("{not json")
    assert_user_error(invoke("fold", broken, "--frames", "3"), "not valid JSON")
    (broken / "result.json").write_text(json.dumps({"format": "something else"}))
    assert_user_error(invoke("export", broken, "-f", "obj"), "not a design result")


def test_result_command_option_errors(designed, tmp_path):
    out = designed[0]
    assert_user_error(invoke("fold", out), "exactly one of --omega")
    assert_user_error(invoke("fold", out, "--omega", "1", "--frames", "3"), "exactly one")
    assert_user_error(invoke("fold", out, "--omega", "4"), "[-pi, pi]")
    assert_user_error(invoke("export", out, "-f", "stl", "--out", tmp_path / "x.stl"),
                      "unknown format 'stl'")
    assert_user_error(invoke("export", out, "-f", "svg", "--out", tmp_path / "no" / "x.svg"),
                      "No such file or directory")
    assert list(tmp_path.iterdir()) == []
