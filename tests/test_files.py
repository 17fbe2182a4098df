"""Files on disk: TOML input, JSON without NaN, and output folders replaced whole even when
the writing process is killed at any step."""

from __future__ import annotations

import json
import os
import shutil
import signal
from pathlib import Path

import numpy as np
import pytest

import rffqm_nlp as rq
from rffqm_nlp import files
from rffqm_nlp.errors import InputError, one_line
from rffqm_nlp.files import folders

OLD = {"a.txt": "old a", "only-old.txt": "old", "sub/b.txt": "old b"}
NEW = {"a.txt": "new a", "sub/b.txt": "new b", "c.txt": "new c"}


def fill(folder: Path, content: dict[str, str]) -> None:
    for name, text in content.items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        (folder / name).write_text(text)


def snapshot(folder: Path) -> dict[str, str] | None:
    """Every file below ``folder`` by relative path, or None when ``folder`` is missing."""
    if not folder.exists():
        return None
    return {p.relative_to(folder).as_posix(): p.read_text()
            for p in folder.rglob("*") if p.is_file()}


def hidden(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


# --------------------------------------------------------------------------- small helpers
def test_read_toml_errors(tmp_path):
    with pytest.raises(InputError, match="no such design file"):
        files.read_toml(tmp_path / "none.toml", "design file")
    bad = tmp_path / "bad.toml"
    bad.write_text("[target\n")
    with pytest.raises(InputError, match="study file .* is not valid TOML"):
        files.read_toml(bad, "study file")
    good = tmp_path / "good.toml"
    good.write_text("[design]\npanels = [4, 6]\n")
    assert files.read_toml(good) == {"design": {"panels": [4, 6]}}


def test_jsonable():
    pat = rq.march(rq.miura_boundary(2, 2))
    value = files.jsonable({"a": np.arange(3), 1: (np.float64(0.5), np.bool_(True)),
                            "pattern": pat})
    assert value == {"a": [0, 1, 2], "1": [0.5, True], "pattern": files.jsonable(pat.to_dict())}
    assert json.loads(json.dumps(value)) == value
    with pytest.raises(InputError, match="cannot be stored in JSON"):
        files.jsonable({"when": object()})


def test_write_json_refuses_nan_and_names_the_place(tmp_path):
    path = tmp_path / "r.json"
    with pytest.raises(InputError) as info:
        files.write_json(path, {"fit": {"rms": 0.1, "history": [1.0, np.nan]}})
    assert "fit.history[1]" in str(info.value) and "NaN or infinity" in str(info.value)
    with pytest.raises(InputError, match=r"\[0\]\.x"):
        files.write_json(path, [{"x": np.inf}])
    assert list(tmp_path.iterdir()) == []
    files.write_json(path, {"Y": np.ones((2, 2))}, indent=1)
    assert json.loads(path.read_text()) == {"Y": [[1.0, 1.0], [1.0, 1.0]]}


def test_one_line():
    assert one_line(InputError("bad\n   value  here")) == "bad value here"
    assert one_line(OSError()) == "OSError"


# --------------------------------------------------------------------------- replace_folder
def test_replace_folder_new_and_whole(tmp_path):
    out = tmp_path / "deep" / "out"
    with files.replace_folder(out) as stage:
        assert stage.parent == out.parent and stage.name.startswith(".out.staging-")
        fill(stage, OLD)
    assert snapshot(out) == OLD
    with files.replace_folder(out) as stage:
        fill(stage, NEW)
    assert snapshot(out) == NEW                    # only-old.txt is gone: replaced whole
    assert hidden(out.parent) == []
    assert out.stat().st_mode & 0o777 == files.DIR_MODE
    assert (out / "a.txt").stat().st_mode & 0o777 == files.FILE_MODE


@pytest.mark.parametrize("exchange", [True, False])
def test_replace_folder_failure_keeps_old(tmp_path, monkeypatch, exchange):
    if not exchange:
        monkeypatch.setattr(folders, "RENAMEAT2", None)
    out = tmp_path / "out"
    fill(out, OLD)
    with pytest.raises(OSError, match="disk full"), files.replace_folder(out) as stage:
        fill(stage, NEW)
        raise OSError("disk full")
    assert snapshot(out) == OLD and hidden(tmp_path) == []
    with files.replace_folder(out) as stage:
        fill(stage, NEW)
    assert snapshot(out) == NEW and hidden(tmp_path) == []


def test_exchange_swaps_two_folders(tmp_path):
    fill(tmp_path / "a", OLD)
    fill(tmp_path / "b", NEW)
    assert folders.exchange(tmp_path / "a", tmp_path / "b")
    assert snapshot(tmp_path / "a") == NEW and snapshot(tmp_path / "b") == OLD


def test_live_staging_kept_dead_removed(tmp_path):
    out = tmp_path / "out"
    fill(out, OLD)
    live = tmp_path / f".out.staging-{os.getppid()}-live"
    other = tmp_path / ".other.staging-1-x"      # another folder's: not ours to remove
    live.mkdir()
    other.mkdir()
    pid = os.fork()
    if pid == 0:
        os._exit(0)
    os.waitpid(pid, 0)                            # a process that is surely dead now
    for kind in ("staging", "ready", "aside"):
        fill(tmp_path / f".out.{kind}-{pid}-dead", {"x": "x"})
    with files.replace_folder(out) as stage:
        fill(stage, NEW)
    assert snapshot(out) == NEW
    assert hidden(tmp_path) == sorted([live.name, other.name])


def _replace_killed_at(out: Path, step: int, exchange: bool) -> bool:
    """Replace ``out`` by NEW in a forked child that SIGKILLs itself before its ``step``-th
    change on disk (mkdir, chmod, write, rename, exchange, unlink, rmdir); True when it
    was killed, False when it finished first."""
    pid = os.fork()
    if pid == 0:                                      # the child: never returns
        try:
            done = [0]

            def counted(func):
                def step_then(*args, **kwargs):
                    if done[0] == step:
                        os.kill(os.getpid(), signal.SIGKILL)
                    done[0] += 1
                    return func(*args, **kwargs)
                return step_then

            if not exchange:
                folders.RENAMEAT2 = None
            folders.exchange = counted(folders.exchange)
            for name in ("mkdir", "chmod", "rename", "unlink", "rmdir"):
                setattr(os, name, counted(getattr(os, name)))
            write = counted(fill)
            with files.replace_folder(out) as stage:
                for name, text in NEW.items():
                    write(stage, {name: text})
            os._exit(0)
        except BaseException:
            os._exit(1)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        assert os.WTERMSIG(status) == signal.SIGKILL
        return True
    assert os.WEXITSTATUS(status) == 0
    return False


@pytest.mark.parametrize("exchange", [True, False])
def test_kill_at_every_step_leaves_old_or_new(tmp_path, exchange):
    outcomes = []
    for step in range(200):
        base = tmp_path / str(step)
        out = base / "out"
        fill(out, OLD)
        killed = _replace_killed_at(out, step, exchange)
        state = snapshot(out)
        assert state in (OLD, NEW) or (state is None and not exchange), (step, state)
        files.recover_folder(out)                      # what the next run does first
        recovered = snapshot(out)
        assert recovered in (OLD, NEW) and hidden(base) == [], (step, hidden(base))
        outcomes.append((state, recovered))
        with files.replace_folder(out) as stage:       # the next run itself
            fill(stage, {"third.txt": "3"})
        assert snapshot(out) == {"third.txt": "3"} and hidden(base) == []
        shutil.rmtree(base)
        if not killed:
            assert state == NEW
            break
    else:
        pytest.fail("the replacement never finished")
    assert (OLD, OLD) in outcomes and (NEW, NEW) in outcomes
    # Two renames leave ``out`` missing for one step; the next run renames the new one in.
    assert ((None, NEW) in outcomes) == (not exchange)


def test_replace_folder_through_a_symlink(tmp_path):
    fill(tmp_path / "real", OLD)
    (tmp_path / "link").symlink_to("real")
    with files.replace_folder(tmp_path / "link") as stage:
        assert stage.parent == tmp_path
        fill(stage, NEW)
    assert (tmp_path / "link").is_symlink() and snapshot(tmp_path / "link") == NEW
    assert snapshot(tmp_path / "real") == NEW and hidden(tmp_path) == []


def test_json_whole_numbers_past_pythons_limit_are_refused_in_one_line(tmp_path):
    """Python refuses to convert a whole number of more than 4300 digits (a ValueError that
    is no JSONDecodeError); read_json refuses it first, without quoting it."""
    path = tmp_path / "result.json"
    path.write_text('{"a": -' + "9" * 5000 + "}")
    with pytest.raises(InputError, match="a whole number of 5000 digits") as info:
        files.read_json(path, "design result")
    assert "9" * 50 not in str(info.value)


def test_json_numbers_at_the_edges_are_read(tmp_path):
    path = tmp_path / "result.json"
    path.write_text('{"big": 1e308, "small": -5e-324, "whole": '
                    + "9" * files.MAX_JSON_DIGITS + "}")
    assert files.read_json(path) == {"big": 1e308, "small": -5e-324,
                                     "whole": int("9" * files.MAX_JSON_DIGITS)}


def test_check_value_takes_numpy_scalars_and_refuses_unprintable_integers():
    """An API caller's 0-d array is its number; a whole number too long for Python to print
    is described by its size (str() would raise)."""
    assert files.check_value(np.array(3), files.Key("whole", low=1), "n") == 3
    assert files.check_value(np.float64(0.5), files.Key("number"), "x") == 0.5
    with pytest.raises(InputError, match=r"^n must be a whole number >= 1, got a whole number "
                                         r"of about 5001 digits$"):
        files.check_value(-10**5000, files.Key("whole", low=1), "n")
    with pytest.raises(InputError, match="key must be a rffqm_nlp.files.Key"):
        files.check_value(1, None, "n")
    assert files.describe_value(np.array(2.5)) == "the number 2.5"
    assert files.describe_value(10**15 - 1) == "the whole number 999999999999999"
