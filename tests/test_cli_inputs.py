"""What a user types is checked (issue "Files from others are inert", the audit of `rffqm`).

Every option out of its range, every path no file can have and every size too large is
refused before any work with exit status 2 and exactly one non-empty line on stderr, with
no control character in it; every path and name the commands print is shown through
errors.safe_text. The commands run in-process (typer's CliRunner) on small results made
by hand (tests/view_results.py), so no design is solved here.
"""

from __future__ import annotations

import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from rich.console import Console
from scipy.spatial import cKDTree
from typer.testing import CliRunner
from view_results import miura_result

from rffqm_nlp import cli, memory
from rffqm_nlp.cli import forward_commands, output
from rffqm_nlp.show import view
from rffqm_nlp.show import pictures as viz
from rffqm_nlp.cli import app
from rffqm_nlp.design import DesignProblem
from rffqm_nlp.errors import InputError
from rffqm_nlp.design.results import DesignResult

try:
    runner = CliRunner(mix_stderr=False)
except TypeError:                      # click >= 8.2 keeps stderr apart by itself
    runner = CliRunner()

#: Characters no line on the terminal may hold: C0 (but the newline), DEL and C1 controls.
CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f]")
#: A name that would recolour, clear and retitle a terminal if printed as it is.
NASTY = "a\x1b[31mred\x1b[2J\x9b1m\x1b]0;title\x07"


@pytest.fixture(autouse=True)
def plain_console(monkeypatch):
    """The commands' stderr console without colours, so any control character on stderr
    comes from what they print, not from rich's styling."""
    monkeypatch.setattr(output, "console", Console(stderr=True, force_terminal=False,
                                                color_system=None))


@pytest.fixture(scope="module")
def saved(tmp_path_factory) -> Path:
    """The folder of a saved 8 x 8 result (a Miura-ori designed at omega 1.3)."""
    folder = tmp_path_factory.mktemp("result")
    miura_result(8).save(folder)
    return folder


def invoke(*args):
    return runner.invoke(app, [str(a) for a in args])


def stderr_of(res) -> str:
    return res.stderr if hasattr(res, "stderr") else res.output


def refused(res, *fragments: str) -> str:
    """Exit status 2, no traceback, exactly one non-empty stderr line naming every
    fragment and holding no control character; returns that line."""
    stderr = stderr_of(res)
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert res.exit_code == 2, (res.exit_code, repr(res.exception), stderr)
    assert isinstance(res.exception, (SystemExit, type(None))), repr(res.exception)
    assert len(lines) == 1, stderr
    assert "Traceback" not in stderr
    assert not CONTROL.search(stderr.replace("\n", "")), repr(stderr)
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


@pytest.fixture
def no_work(monkeypatch):
    """Any march, fold, page or render fails the test: refusals come before any work."""
    def never(*args, **kwargs):
        raise AssertionError("work started before the refusal")

    monkeypatch.setattr(forward_commands, "miura_boundary", never)
    monkeypatch.setattr(DesignResult, "load", never)
    monkeypatch.setattr(view, "spec", never)
    monkeypatch.setattr(viz, "folding_gif", never)


# --------------------------------------------------------------------------- numbers
@pytest.mark.parametrize("args, fragments", [
    (["--seed", "-1", "--perturb", "0.01"], ["--seed", "got the whole number -1"]),
    (["--seed", str(2**64)], ["--seed"]),
    (["--perturb", "1e308"], ["--perturb", "1e+308"]),
    (["--perturb", "nan"], ["--perturb", "nan"]),
    (["--perturb", "-0.1"], ["--perturb"]),
    (["--frames", "1" + "0" * 23], ["--frames", "[0, 1000]", "24 digits"]),
    (["--frames", "1000000"], ["--frames", "[0, 1000]"]),
    (["--frames", "-1"], ["--frames"]),
    (["--rows", "0"], ["--rows"]),
    (["--cols", "100001"], ["--cols", "100000"]),
    (["--alpha0", "inf"], ["--alpha0"]),
    (["--alpha0", "1.5708"], ["--alpha0"]),
    (["--a", "1e300"], ["--a ", "(a length)"]),
    (["--b", "0"], ["--b "]),
    (["--omega", "4"], ["--omega", "[-pi, pi]"]),
    (["--omega", "-inf"], ["--omega"]),
    (["--layout", NASTY], ["--layout", "a string of"]),
])
def test_march_options_out_of_range(tmp_path, no_work, args, fragments):
    out = tmp_path / "m"
    refused(invoke("march", "--out", out, *args), *fragments)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("command, minimum", [("fold", 1), ("render", 2), ("view", 2)])
@pytest.mark.parametrize("frames", ["1000000", "1" + "0" * 23, "1001", "-5"])
def test_frames_beyond_the_maximum_are_refused_before_the_result_is_read(
        tmp_path, no_work, command, minimum, frames):
    line = refused(invoke(command, tmp_path / "none", "--frames", frames), "--frames",
                   f"[{minimum}, {cli.MAX_FRAMES}]")
    assert "no design result" not in line


@pytest.mark.parametrize("args, fragments", [
    (["fold", "{r}", "--omega", "nan"], ["--omega", "nan"]),
    (["fold", "{r}", "--omega", "1e300"], ["--omega"]),
    (["export", "{r}", "-f", "svg", "--omega", "-7"], ["--omega"]),
    (["check", "{r}", "--omega", "inf"], ["--omega"]),
    (["check", "{r}", "--clearance", "-1"], ["--clearance", ">= 0"]),
    (["check", "{r}", "--clearance", "nan"], ["--clearance"]),
    (["check", "{r}", "--clearance", "1e300"], ["--clearance", "shortest side"]),
    (["sweep", "{r}/study.toml", "--out", "{r}/o", "--workers", "0"], ["--workers"]),
    (["sweep", "{r}/study.toml", "--out", "{r}/o", "--workers", "100000"],
     ["--workers", "256"]),
    (["design", "{r}/t.toml", "--out", "{r}/o", "--max-iter", "0"], ["--max-iter"]),
    (["design", "{r}/t.toml", "--out", "{r}/o", "--max-iter", str(2**40)], ["--max-iter"]),
])
def test_other_options_out_of_range(saved, args, fragments):
    before = sorted(p.name for p in saved.iterdir())
    refused(invoke(*[a.format(r=saved) for a in args]), *fragments)
    assert sorted(p.name for p in saved.iterdir()) == before


@pytest.mark.parametrize("args", [["march", "--frames", "abc"], ["march", "--frames", "1e23"],
                                  ["march", "--seed", "1.5"], ["view", "x", "--frames", "2.5"],
                                  ["fold", "x", "--omega", "pi"]])
def test_typer_parse_errors_exit_2_in_one_line(tmp_path, args):
    """Options not of their type at all are refused by typer (its message, its exit
    status 2), on one line naming the command's help."""
    refused(invoke(*args), "Invalid value", "--help")


@pytest.mark.parametrize("args, fragments", [
    (["march", "--frames", NASTY], ["Invalid value for '--frames'"]),
    (["march", "--" + NASTY], ["No such option", "\\x1b"]),
    ([NASTY], ["No such command", "\\x1b"]),
    (["view"], ["Missing argument"]),
])
def test_usage_errors_in_one_line_without_control_characters(args, fragments):
    refused(invoke(*args), *fragments)


def test_the_bare_command_still_shows_its_help_and_version_still_works():
    res = invoke()
    assert "Usage" in res.output and "march" in res.output
    res = invoke("--version")
    assert res.exit_code == 0 and res.stdout.startswith("rffqm-nlp ")


# --------------------------------------------------------------------------- huge values
def _huge(result: DesignResult, offset: float) -> DesignResult:
    """``result`` moved by ``offset`` along x (its folded state and target too)."""
    shift = np.array([offset, 0.0, 0.0])
    return replace(result, translation=result.translation + shift,
                   folded=result.folded + shift, target_points=result.target_points + shift)


def test_view_of_a_result_with_huge_finite_coordinates(tmp_path):
    """A saved result whose coordinates are finite but about 1e300: one line, no page."""
    folder = tmp_path / "huge"
    folder.mkdir()
    _huge(miura_result(4), 1e300).save(folder)
    assert np.abs(DesignResult.load(folder).folded).max() > 1e299
    refused(invoke("view", folder, "--frames", "3"), "coordinates up to 1e+150")
    assert [p.name for p in folder.iterdir()] == ["result.json"]


@pytest.mark.parametrize("offset, fragment", [(1e200, "coordinates up to 1e+150"),
                                              (1e20, "too small a shape")])
def test_the_view_refuses_coordinates_it_cannot_draw(offset, fragment):
    with pytest.raises(InputError, match=re.escape(fragment)):
        view.spec(_huge(miura_result(4), offset), frames=3)


def test_the_view_keeps_the_shape_of_a_design_far_from_the_origin():
    """A design 1e6 away from the origin keeps 4 digits of its own size (not of 1e6)."""
    near, far = miura_result(4), _huge(miura_result(4), 1e6)
    a, b = view.spec(near, frames=3), view.spec(far, frames=3)
    xa, xb = np.array(a["data"][0]["x"]), np.array(b["data"][0]["x"])
    assert np.ptp(xb) > 1.0
    np.testing.assert_allclose(xb - 1e6, xa, atol=2e-3)
    np.testing.assert_allclose(b["data"][0]["intensity"], a["data"][0]["intensity"],
                               atol=2e-3)


# --------------------------------------------------------------------------- paths
@pytest.mark.parametrize("args", [
    ["view", "a\x00b"],
    ["fold", "a\x00b", "--omega", "1"],
    ["export", "{r}", "-f", "svg", "--out", "{r}/x\x00.svg"],
    ["march", "--out", "m\x00n"],
    ["check", "a\x00b.fold"],
    ["design", "t\x00.toml", "--out", "o"],
])
def test_a_nul_character_in_a_path(saved, args):
    """Typer refuses it as a path (its message, on one line)."""
    refused(invoke(*[a.format(r=saved) for a in args]), "null byte")


def test_check_path_refuses_a_nul_character():
    """The commands' own check, for a path typer passes on."""
    with pytest.raises(InputError, match=r"out a\\x00b: a path cannot hold a NUL"):
        cli.check_path(Path("a\x00b"), "--out", output=True)


@pytest.mark.parametrize("args, fragments", [
    (["march", "--out", "m" * 300], ["--out", "too long"]),
    (["march", "--out", "m" * 240], ["--out", "too long", "215"]),
    (["view", "{r}", "--out", "{r}/" + "v" * 5000 + ".html"], ["--out", "too long"]),
    (["view", "/".join(["d" * 200] * 30)], ["RESULT_DIR", "too long", "4096"]),
])
def test_an_over_long_path_before_any_work(saved, no_work, args, fragments):
    line = refused(invoke(*[a.format(r=saved) for a in args]), *fragments)
    assert len(line) < 600


def test_the_handler_turns_a_path_error_from_anywhere_into_one_line(saved, monkeypatch):
    """A NUL or unencodable path that reaches the os module deeper down (here: a result
    folder's own reading) is one line too."""
    for exc in (ValueError("embedded null byte"),
                UnicodeEncodeError("utf-8", "\ud800", 0, 1, "surrogates not allowed")):
        def load(*args, exc=exc, **kwargs):
            raise exc
        monkeypatch.setattr(DesignResult, "load", load)
        refused(invoke("view", saved), "path")


def test_other_value_errors_still_show_their_traceback(saved, monkeypatch):
    def load(*args, **kwargs):
        raise ValueError("a bug, not a user error")
    monkeypatch.setattr(DesignResult, "load", load)
    res = invoke("view", saved)
    assert isinstance(res.exception, ValueError)


# --------------------------------------------------------------------------- messages
@pytest.mark.parametrize("args", [
    ["view", "{r}/" + NASTY],
    ["fold", "{r}/" + NASTY * 40, "--omega", "1"],
    ["export", "{r}", "-f", "svg", "--out", "{r}/" + NASTY + ".png"],
    ["check", "{r}/" + NASTY + ".fold"],
    ["design", "{r}/" + NASTY + ".toml", "--out", "{r}/o"],
])
def test_error_lines_escape_control_characters(saved, args):
    line = refused(invoke(*[a.format(r=saved) for a in args]))
    assert "\\x1b" in line or "\\x07" in line


def test_written_paths_and_tables_escape_control_characters(saved, tmp_path, monkeypatch):
    monkeypatch.setenv("COLUMNS", "1000")         # the summary table on one line a row
    out = tmp_path / (NASTY + ".json")
    res = invoke("fold", saved, "--omega", "1", "--out", out)
    assert res.exit_code == 0, stderr_of(res)
    assert out.is_file()
    stderr = stderr_of(res)
    assert "wrote" in stderr and "\\x1b" in stderr
    assert not CONTROL.search(stderr.replace("\n", "")), repr(stderr)
    march_out = tmp_path / NASTY
    res = invoke("march", "--rows", "2", "--cols", "2", "--out", march_out)
    assert res.exit_code == 0, stderr_of(res)
    assert march_out.is_dir()
    assert "\x1b" not in res.stdout and "\x9b" not in res.stdout and "\\x1b" in res.stdout


def test_warnings_go_through_safe_text(monkeypatch, capsys):
    monkeypatch.setattr(output, "console", Console(stderr=True, force_terminal=False,
                                                color_system=None, width=10_000))
    output.warn("render skipped: " + NASTY + "\nsecond line [bold]x[/bold]")
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and not CONTROL.search(err.rstrip("\n")), repr(err)
    assert "\\x1b[31mred" in err and "[bold]x[/bold]" in err


# --------------------------------------------------------------------------- sizes
def test_the_view_page_is_bounded_before_any_work(saved, monkeypatch, tmp_path):
    monkeypatch.setattr(view, "MAX_POINTS", 81 * 10)       # 8 x 8 panels: 81 vertices
    monkeypatch.setattr(view, "spec", lambda *a, **k: pytest.fail("the page was built"))
    out = tmp_path / "v.html"
    refused(invoke("view", saved, "--out", out, "--frames", "24"), "25 states",
            "choose --frames 9 or fewer")
    assert not out.exists()


def test_design_writes_a_smaller_view_of_a_large_design(tmp_path, monkeypatch):
    """A design whose view would hold more than view.MAX_POINTS positions gets a page with
    fewer slider states, and a warning saying so."""
    result = miura_result(8)
    result = replace(result, fit=replace(result.fit, rms_surface_vertices=0.01,
                                         hausdorff_vertices=0.02, coverage=1.0))
    monkeypatch.setattr(DesignProblem, "solve", lambda self, *a, **k: result)
    monkeypatch.setattr(viz, "start_rendering_probe", lambda: None)
    monkeypatch.setattr(viz, "rendering_available", lambda: (False, "not in this test"))
    monkeypatch.setattr(view, "MAX_POINTS", 81 * 10)
    toml = tmp_path / "t.toml"
    toml.write_text('[target]\nname = "sphere_cap"\n[design]\npanels = [8, 8]\n')
    res = invoke("design", toml, "--out", tmp_path / "o", "--quiet")
    assert res.exit_code == 0, stderr_of(res)
    assert "view.html has 10 slider states instead of 25" in stderr_of(res)
    html = (tmp_path / "o" / "view.html").read_text()
    assert html.startswith("<!DOCTYPE html>")


def test_render_refuses_a_gif_this_machine_cannot_hold(saved, monkeypatch, tmp_path):
    monkeypatch.setattr(memory, "available", lambda: int(1e9))
    monkeypatch.setattr(viz, "folding_gif", lambda *a, **k: pytest.fail("rendered"))
    refused(invoke("render", saved, "--out", tmp_path / "r", "--frames", "1000"),
            "rffqm render of 8 x 8 panels in 1000 states needs about", "--frames")
    assert not (tmp_path / "r").exists()


def test_fold_refuses_states_this_machine_cannot_hold(saved, monkeypatch):
    monkeypatch.setattr(memory, "available", lambda: int(2e8))
    refused(invoke("fold", saved, "--frames", "1000"), "rffqm fold of 8 x 8 panels",
            "choose fewer --frames")


def test_march_refuses_a_pattern_this_machine_cannot_hold(tmp_path, monkeypatch, no_work):
    monkeypatch.setattr(memory, "available", lambda: int(2e9))
    refused(invoke("march", "--rows", "1000", "--cols", "1000", "--out", tmp_path / "m"),
            "rffqm march on 1000 x 1000 panels needs about 2.8 GB")
    assert list(tmp_path.iterdir()) == []


#: Peaks of `rffqm march` measured 2026-12-07 (docs/benchmarks/march_memory.md): (rows =
#: cols, frames, GB).
MARCH_PEAKS = [(1, 0, 0.147), (200, 0, 0.206), (400, 0, 0.367), (800, 0, 0.997),
               (1000, 0, 1.654), (1200, 0, 2.926), (1600, 0, 4.067), (1, 1000, 0.148),
               (50, 200, 0.331), (100, 100, 0.499), (150, 100, 0.932), (200, 20, 0.457),
               (300, 40, 1.440), (400, 10, 0.788), (800, 5, 1.562)]


@pytest.mark.parametrize("n, frames, peak", MARCH_PEAKS)
def test_the_march_estimate_bounds_the_measured_peaks(n, frames, peak):
    """An upper bound with a margin of at least a quarter, and not wildly above."""
    ratio = memory.march_estimate(n, n, frames) / 1e9 / peak
    assert 1.25 <= ratio <= 2.5, ratio


def test_the_march_estimate_bounds_a_march_measured_now(tmp_path):
    """`rffqm march` in a child process of its own: its peak resident size stays below
    the estimate."""
    out = tmp_path / "m"
    code = ("import resource, subprocess, sys; "
            "r = subprocess.run(sys.argv[1:], capture_output=True); "
            "assert r.returncode == 0, r.stderr; "
            "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024)")
    command = [sys.executable, "-c", "from rffqm_nlp.cli import app; app()", "march",
               "--rows", "120", "--cols", "120", "--frames", "30", "--out", str(out)]
    peak = int(subprocess.run([sys.executable, "-c", code, *command], check=True,
                              capture_output=True, text=True).stdout)
    assert (out / "frames.json").is_file()
    assert 0.1e9 < peak < memory.march_estimate(120, 120, 30), peak


# --------------------------------------------------------------------------- distances
def _exact(Y: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Distances of the states' vertices to the nearest of all the target's samples, by
    scipy's cKDTree with its defaults, (K, n)."""
    samples = view.target_samples(T, view.refinement(T)).reshape(-1, 3)
    return cKDTree(samples).query(Y.reshape(-1, 3))[0].reshape(len(Y), -1)


def _far_design(lift: float) -> DesignResult:
    """The 12 x 12 Miura result with its target lifted by ``lift`` along z."""
    result = miura_result(12)
    return replace(result, target_points=result.target_points + [0.0, 0.0, lift])


def test_state_distances_exact_within_the_colour_scale():
    """The designed state's distances are the exact ones; another state's are too where
    they lie within the colour scale, and beyond it they are upper bounds beyond it."""
    result = _far_design(0.1)
    omegas, at = view.slider_omegas(result.omega, 12)
    Y = view.states(result, omegas)
    T = result.target_points
    d = view.state_distances(Y, T, at)
    exact = _exact(Y, T)
    top = exact[at].max()
    np.testing.assert_array_equal(d[at], exact[at])
    inside = exact <= top
    assert (~inside).sum() > 100 and inside.sum() > 500
    np.testing.assert_array_equal(d[inside], exact[inside])
    assert np.all(d[~inside] >= exact[~inside]) and np.all(d[~inside] > top)


def test_far_from_its_target_the_other_states_are_within_a_64th_of_the_scale():
    result = _far_design(30.0)
    omegas, at = view.slider_omegas(result.omega, 8)
    Y = view.states(result, omegas)
    T = result.target_points
    samples = view.target_samples(T, view.refinement(T))
    d = view.state_distances(Y, T, at)
    exact = _exact(Y, T)
    top = exact[at].max()
    assert view.scale_stride(samples, top) > 1
    np.testing.assert_array_equal(d[at], exact[at])
    inside = exact <= top
    assert inside.sum() > 500
    assert np.all(d[inside] >= exact[inside])
    assert np.all(d[inside] - exact[inside] <= top / view.SCALE_STEPS)


def test_distances_are_those_to_the_nearest_sample():
    result = _far_design(5.0)
    Y = view.states(result, [0.0, 1.0, result.omega])
    T = result.target_points
    exact = _exact(Y, T)
    np.testing.assert_array_equal(view.distances(Y, T).reshape(3, -1), exact)
    bounded = view.distances(Y, T, within=6.0).reshape(3, -1)
    assert np.all(bounded[exact < 6.0] == exact[exact < 6.0])
    assert np.all(bounded[exact >= 6.0] >= exact[exact >= 6.0])
    assert (exact >= 6.0).any() and (exact < 6.0).any()


def test_the_samples_are_bounded(monkeypatch):
    T = miura_result(40).target_points
    assert view.refinement(T) == view.TARGET_REFINE
    monkeypatch.setattr(view, "MAX_SAMPLES", 10_000)
    refine = view.refinement(T)
    assert refine < view.TARGET_REFINE
    n, m = T.shape[0] - 1, T.shape[1] - 1
    assert (refine * n + 1) * (refine * m + 1) <= 10_000
    assert view.far_samples(view.target_samples(T)).shape[0] <= view.FAR_SAMPLES
