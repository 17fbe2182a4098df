"""A design result, FOLD file or sweep row that is no such file (a FIFO, a device, a folder,
binary garbage, broken JSON) is refused in one line, and never blocks: nothing but a regular
file is opened (files.read_json). A file that is one but holds what rffqm never writes (a
fit or statistic of the wrong type or not finite, a rotation that is none, an integer too
large for a float, a FOLD pattern that is not its boundary data marched) is refused in one
line that never quotes the file's content."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp import files, sweeps
from rffqm_nlp.io import foldfile
from rffqm_nlp.model import numpy_model
from rffqm_nlp.design import results
from rffqm_nlp.cli import app
from rffqm_nlp.errors import InputError

try:
    runner = CliRunner(mix_stderr=False)
except TypeError:                      # click >= 8.2 keeps stderr apart by itself
    runner = CliRunner()


def _fifo(folder: Path, name: str) -> Path:
    path = folder / name
    os.mkfifo(path)
    return path


def _folder(folder: Path, name: str) -> Path:
    path = folder / name
    path.mkdir()
    return path


def _bytes(data: bytes):
    def make(folder: Path, name: str) -> Path:
        path = folder / name
        path.write_bytes(data)
        return path
    return make


def _too_big(folder: Path, name: str) -> Path:
    path = folder / name
    with open(path, "wb") as fh:                   # sparse: takes no room on disk
        fh.truncate(files.MAX_JSON_BYTES + 1)
    return path


def _broken_fold(folder: Path, name: str) -> Path:
    path = foldfile.write_fold(folder / name, rq.march(rq.miura_boundary(2, 2)), 1.0)
    data = json.loads(path.read_text())
    data["rffqm:pattern"] = {"alpha": 5}
    path.write_text(json.dumps(data))
    return path


@functools.cache
def _result_text() -> str:
    """result.json of a small design (solved once)."""
    problem = rq.DesignProblem(rq.surfaces.get("sphere_cap", radius=4.0), panels=(4, 4))
    return json.dumps(problem.solve(rq.SolveOptions(stop_rms=0.05)).to_dict())


def _result(change):
    """A maker of result.json with ``change(data)`` applied; a change that returns a string
    writes that text instead (a JSON that json.dumps cannot make)."""
    def make(folder: Path, name: str) -> Path:
        data = json.loads(_result_text())
        text = change(data)
        path = folder / name
        path.write_text(text if isinstance(text, str) else json.dumps(data))
        return path
    return make


def _set(key: str, value):
    """A change setting data[a][b] for key "a.b" (NaN and infinity written as JSON's)."""
    def change(data: dict) -> None:
        *parents, last = key.split(".")
        holder = data
        for parent in parents:
            holder = holder[parent]
        holder[last] = value
    return change


def _rotated(R):
    """A change storing the rotation R with the folded state moved by it (so the folded
    state agrees, and only the rotation itself is wrong)."""
    def change(data: dict) -> None:
        pattern = rq.Pattern.from_dict(data["pattern"])
        Y = numpy_model.fold(pattern, data["omega"])
        data["rotation"] = np.asarray(R(np.array(data["rotation"]))).tolist()
        data["folded"] = (Y @ np.array(data["rotation"]).T + data["translation"]).tolist()
    return change


def _huge_int(key: str):
    """A change writing a 400-digit integer literal as the first number of data[key]."""
    def change(data: dict) -> str:
        marker = 12345.678125
        holder = data[key]
        while isinstance(holder[0], list):
            holder = holder[0]
        holder[0] = marker
        return json.dumps(data).replace(repr(marker), "1" * 400, 1)
    return change


def _fold(change, frames: int | None = None):
    """A maker of a FOLD file of a 2 x 2 Miura-ori with ``change(data)`` applied (as
    :func:`_result`)."""
    def make(folder: Path, name: str) -> Path:
        path = foldfile.write_fold(folder / name, rq.march(rq.miura_boundary(2, 2)), 1.0,
                                   frames=frames)
        data = json.loads(path.read_text())
        text = change(data)
        path.write_text(text if isinstance(text, str) else json.dumps(data))
        return path
    return make


def _pattern(key: str, index: tuple, value=None, add: float | None = None):
    """A change of rffqm:pattern[key][index]: set to ``value`` or shifted by ``add``."""
    def change(data: dict) -> None:
        holder = data["rffqm:pattern"][key]
        for i in index[:-1]:
            holder = holder[i]
        holder[index[-1]] = value if add is None else holder[index[-1]] + add
    return change


LONG = "Q" * 5000

#: (id, maker(folder, name) -> path, fragments of the message) for both kinds of file.
BAD_FILES = [
    ("fifo", _fifo, ["FIFO", "not a regular file"]),
    ("device", lambda folder, name: Path(os.devnull), ["character device", "not a regular file"]),
    ("binary", _bytes(bytes(range(256)) * 4), ["not UTF-8"]),
    ("not-json", _bytes(b"{ not json"), ["not valid JSON", "line 1"]),
    ("too-big", _too_big, ["more than the 512 MiB"]),
]
RESULT_FILES = BAD_FILES + [
    ("folder", lambda folder, name: _folder(_folder(folder, "run"), results.FILENAME),
     ["a folder", "not a regular file"]),
    ("missing", lambda folder, name: folder / name, ["no design result"]),
    ("no-result", _bytes(b'{"format": "something else"}'), ["not a design result"]),
    ("cut", _bytes(json.dumps({"format": results.FORMAT, "version": 2}).encode()),
     ["the key 'boundary' is missing"]),
    ("broken-v1", _bytes(json.dumps({"format": results.FORMAT, "version": 1,
                                     "problem": 5}).encode()),
     ["broken design result (TypeError"]),
    # loads validated whole: every fit and statistic, the rotation
    ("fit-nan-string", _result(_set("fit.rms", "nan")),
     ["fit.rms must be a finite number >= 0, got the string 'nan'"]),
    ("fit-nan", _result(_set("fit.hausdorff", float("nan"))),
     ["fit.hausdorff holds NaN or inf"]),
    ("fit-negative", _result(_set("fit.rms_surface", -1.0)),
     ["fit.rms_surface must be a finite number >= 0, got the number -1"]),
    ("fit-flag", _result(_set("fit.collision_free", "yes")),
     ["fit.collision_free must be true or false"]),
    ("fit-missing", _result(lambda d: d["fit"].pop("rms")),
     ["fit needs rms: a finite number >= 0"]),
    ("stats-string", _result(_set("stats.iterations", "many")),
     ["stats.iterations must be a whole number >= 0, got the string 'many'"]),
    ("stats-fraction", _result(_set("stats.marched_iterations", 1.5)),
     ["stats.marched_iterations must be a whole number >= 0, got the number 1.5"]),
    ("stats-inf", _result(_set("stats.objective", float("inf"))),
     ["stats.objective holds NaN or inf"]),
    ("stats-success", _result(_set("stats.success", 1)),
     ["stats.success must be true or false"]),
    ("stats-unknown", _result(_set("stats.surprise", 1)),
     ["unknown key stats.surprise"]),
    ("stats-history", _result(lambda d: d["stats"]["history"]["elapsed"].pop()),
     ["stats.history must hold lists of one length"]),
    ("stats-history-type", _result(_set("stats.history.inf_pr", {"a": 1})),
     ["stats.history.inf_pr must be a list of items, each a finite number >= 0"]),
    ("stats-long", _result(_set("stats.iterations", LONG)),
     ["stats.iterations must be a whole number", "a string of 5000 characters"]),
    ("zero-rotation", _result(_rotated(lambda R: np.zeros((3, 3)))),
     ["rotation must be a rotation matrix", "differs from the identity by 1"]),
    ("scaled-rotation", _result(_rotated(lambda R: 2 * R)),
     ["rotation must be a rotation matrix"]),
    ("reflected-rotation", _result(_rotated(lambda R: np.diag([1.0, 1.0, -1.0]) @ R)),
     ["rotation must be a proper rotation (determinant +1)"]),
    ("omega-range", _result(_set("omega", 4.0)),
     ["omega must lie in [-pi, pi], got 4.0"]),
    # integers too large for a float, NaN and infinity anywhere
    ("huge-int-x", _result(_huge_int("x")),
     ["x holds a whole number of 400 digits (at x[0]), too large for a floating-point"]),
    ("huge-int-folded", _result(_huge_int("folded")),
     ["folded holds a whole number of 400 digits (at folded[0][0][0])"]),
    ("huge-int-fit", _result(lambda d: json.dumps(d).replace(
        '"rms": ', '"rms": ' + "9" * 400 + ', "_": ', 1)),
     ["fit.rms holds a whole number of 400 digits"]),
    ("huge-literal", _result(lambda d: json.dumps(d).replace('"omega": ', '"omega": 1e999, "_": ',
                                                              1)),
     ["omega holds NaN or inf"]),
    ("nan-in-problem", _result(_set("problem.design.min_length", float("nan"))),
     ["problem.design.min_length holds NaN or inf"]),
]
FOLD_FILES = BAD_FILES + [
    ("folder", _folder, ["a folder", "not a regular file"]),
    ("missing", lambda folder, name: folder / name, ["no FOLD file"]),
    ("broken", _broken_fold, ["the key 'rffqm:pattern.beta' is missing"]),
    # the pattern is re-marched: inadmissible boundary data, values that do not march
    ("negative-side", _fold(_pattern("lv", (0, 0), -1.0)),
     ["rffqm:pattern's boundary data: l_left[0] =", "must be a finite positive length"]),
    ("negative-inner-side", _fold(_pattern("lh", (1, 1), -1.0)),
     ["rffqm:pattern.lh does not match its boundary data re-marched"]),
    ("sigma-5", _fold(_pattern("sigma", (0, 0), 5.0)),
     ["rffqm:pattern's boundary data: boundary vertex (1, 1): sigma =",
      "must be +1 or -1"]),
    ("inner-sigma-5", _fold(_pattern("sigma", (1, 1), 5.0)),
     ["rffqm:pattern.sigma does not match its boundary data re-marched"]),
    ("shifted-alpha", _fold(_pattern("alpha", (2, 2), add=1e-3)),
     ["rffqm:pattern.alpha does not match its boundary data re-marched"]),
    ("shifted-mu", _fold(_pattern("mu", (1, 0), add=1e-3)),
     ["rffqm:pattern.mu does not match"]),
    ("unmarchable", _fold(lambda d: [_pattern("alpha", (2, 0), 3.0)(d),
                                     _pattern("beta", (2, 0), 3.0)(d)]),
     ["the boundary data of rffqm:pattern do not march", "check failed at panel"]),
    ("cut-pattern", _fold(lambda d: d["rffqm:pattern"]["X"].pop()),
     ["rffqm:pattern.X has shape (2, 3, 3), expected (3, 3, 3)"]),
    ("omega-range", _fold(_set("rffqm:omega", 7.0)),
     ["rffqm:omega must lie in [-pi, pi]"]),
    # NaN, infinity and integers too large for a float anywhere
    ("nan-in-pattern", _fold(_pattern("mu", (0, 1), float("nan"))),
     ["rffqm:pattern.mu holds NaN or inf (at rffqm:pattern.mu[0][1])"]),
    ("nan-in-frame", _fold(lambda d: d["file_frames"][1]["vertices_coords"][2].__setitem__(
        0, float("inf")), frames=2),
     ["file_frames[1].vertices_coords holds NaN or inf (at "
      "file_frames[1].vertices_coords[2][0])"]),
    ("nan-in-metadata", _fold(_set("rffqm:rms", float("nan"))),
     ["rffqm:rms holds NaN or inf"]),
    ("huge-int-coords", _fold(_huge_int("vertices_coords")),
     ["vertices_coords holds a whole number of 400 digits (at vertices_coords[0][0])"]),
    ("huge-int-pattern", _fold(lambda d: json.dumps(d).replace(
        '"lh": [[', '"lh": [[' + "7" * 400 + ", ", 1)),
     ["rffqm:pattern.lh holds a whole number of 400 digits"]),
    # strings from the file are never quoted
    ("long-assignment", _fold(lambda d: d["edges_assignment"].__setitem__(3, LONG)),
     ["edges_assignment has values outside", "edge 3 holds a string of 5000 characters"]),
    ("long-parent", _fold(lambda d: d["file_frames"][0].__setitem__("frame_parent", LONG),
                          frames=2),
     ["file_frames[0]: frame_parent (a string of 5000 characters) is not another frame"]),
    ("long-pattern", _fold(_set("rffqm:pattern.alpha", LONG)),
     ["rffqm:pattern.alpha must be a rectangular array of numbers"]),
    ("long-omega", _fold(_set("rffqm:omega", LONG)),
     ["rffqm:omega must be a number"]),
    ("omega-list", _fold(_set("rffqm:omega", [0.5, 1.0])),
     ["rffqm:omega must be one number in [-pi, pi], got a list"]),
]


def one_line_error(res) -> str:
    """Exit status 2 and exactly one non-empty line on stderr, no traceback: that line."""
    stderr = res.stderr if hasattr(res, "stderr") else res.output
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert res.exit_code == 2, (res.exit_code, res.output, stderr)
    assert isinstance(res.exception, (SystemExit, type(None))), repr(res.exception)
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    return lines[0]


def api_message(call, path: Path, fragments: list[str]) -> str:
    with pytest.raises(InputError) as info:
        call(path)
    message = str(info.value)
    assert "\n" not in message and all(f in message for f in fragments), message
    assert "QQQQQQQQ" not in message and len(message) < 400, message   # never file content
    return message


@pytest.mark.parametrize("make, fragments", [c[1:] for c in RESULT_FILES],
                         ids=[c[0] for c in RESULT_FILES])
def test_a_bad_design_result_is_refused_in_one_line(tmp_path, make, fragments):
    path = make(tmp_path, results.FILENAME)
    given = path.parent if path.name == results.FILENAME and path.is_dir() else path
    message = api_message(rq.DesignResult.load, given, fragments)
    for command in (["export", str(given), "--format", "svg", "--out",
                     str(tmp_path / "x.svg")], ["check", str(given)]):
        line = one_line_error(runner.invoke(app, command))
        assert message in line, (message, line)
    assert not (tmp_path / "x.svg").exists()


@pytest.mark.parametrize("make, fragments", [c[1:] for c in FOLD_FILES],
                         ids=[c[0] for c in FOLD_FILES])
def test_a_bad_fold_file_is_refused_in_one_line(tmp_path, make, fragments):
    path = make(tmp_path, "x.fold")
    message = api_message(foldfile.read_fold, path, fragments)
    if path.suffix == ".fold":                     # check tells a FOLD file by its suffix
        assert message in one_line_error(runner.invoke(app, ["check", str(path)]))


@pytest.mark.parametrize("command", [["export", "{fifo}", "--format", "svg"],
                                     ["check", "{fifo}.fold"]])
def test_the_command_never_waits_on_a_fifo(tmp_path, command):
    """In a process of its own, so that a hang fails the test instead of stopping it."""
    fifo = str(tmp_path / "pipe")
    os.mkfifo(fifo)
    os.mkfifo(fifo + ".fold")
    proc = subprocess.run([str(Path(sys.executable).with_name("rffqm")),
                           *[a.format(fifo=fifo) for a in command]],
                          capture_output=True, text=True, timeout=120)
    lines = [line for line in proc.stderr.splitlines() if line.strip()]
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert "FIFO (named pipe), not a regular file" in lines[0]


@pytest.mark.parametrize("make", [_fifo, _folder, _bytes(bytes(range(256)))])
def test_a_sweep_row_that_is_no_file_is_not_a_completed_design(tmp_path, make):
    make(tmp_path, sweeps.ROW_FILE)
    design = sweeps.Design(id="d", name="d", params={}, config={"design": {"panels": [2, 2]}})
    assert sweeps.completed_row(tmp_path, design) is None


def test_read_json_reads_what_write_json_wrote(tmp_path):
    value = {"a": [1, 2.5, None], "b": {"c": "text", "d": True}}
    path = files.write_json(tmp_path / "v.json", value)
    assert files.read_json(path, "value file") == value
