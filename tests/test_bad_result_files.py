"""A design result, FOLD file or sweep row that is no such file (a FIFO, a device, a folder,
binary garbage, broken JSON) is refused in one line, and never blocks: nothing but a regular
file is opened (files.read_json)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp import files, foldfile, results, sweeps
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
     ["the key 'omega' is missing"]),
    ("broken-v1", _bytes(json.dumps({"format": results.FORMAT, "version": 1,
                                     "problem": 5}).encode()),
     ["broken design result (TypeError"]),
]
FOLD_FILES = BAD_FILES + [
    ("folder", _folder, ["a folder", "not a regular file"]),
    ("missing", lambda folder, name: folder / name, ["no FOLD file"]),
    ("broken", _broken_fold, ["broken rffqm design data"]),
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
