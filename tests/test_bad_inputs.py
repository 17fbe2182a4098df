"""Every malformed target or study file is refused in one line (issue 18, items 7 and 10).

A generated corpus of malformed design files and study files runs through the command line
(in-process): exit status 2, exactly one non-empty line on stderr that names the key, no
output folder; and through the API: :class:`InputError` with the same key named. Nothing
is solved: every refusal comes before any work.
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp import cli, design, files, memory, sweeps
from rffqm_nlp.design.problem import DEFAULT_WEIGHTS
from rffqm_nlp.model import lengths
from rffqm_nlp.cli import app, forward_commands, result_files
from rffqm_nlp.errors import InputError

try:
    runner = CliRunner(mix_stderr=False)
except TypeError:                      # click >= 8.2 keeps stderr apart by itself
    runner = CliRunner()

TARGET = '[target]\nname = "sphere_cap"\n'
SECRET = "SECRET-" + "x" * 40          # a long string from a file: never in a message


def design_file(target: str = TARGET, design_lines: str = "", solve_lines: str = "") -> str:
    """A small design file with extra [design] and [solve] lines."""
    return f"{target}\n[design]\npanels = [8, 8]\n{design_lines}\n[solve]\n{solve_lines}\n"


# --------------------------------------------------------------------------- the corpus
def _wrong_types() -> list[tuple[str, str, list[str]]]:
    """A value of the wrong type for every key of [design] and [solve]."""
    wrong = {"number": '"abc"', "whole": "2.5", "choice": "5", "list": "4", "table": "5",
             "scalar": "5"}
    cases = []
    for key, rule in design.DESIGN_KEYS.items():
        lines = f"{key} = {wrong[rule.kind]}"
        text = (design_file(design_lines=lines) if key != "panels"
                else design_file().replace("panels = [8, 8]", lines))
        cases.append((f"type-design-{key}", text, [f"[design] {key}"]))
    for key, rule in design.SOLVE_KEYS.items():
        cases.append((f"type-solve-{key}", design_file(solve_lines=f"{key} = {wrong[rule.kind]}"),
                      [f"[solve] {key}"]))
    cases += [
        ("type-target-table", "target = 5\n", ["[target] must be a table"]),
        ("type-design-table", "design = \"big\"\n" + TARGET, ["[design] must be a table"]),
        ("type-target-name", "[target]\nname = 5\n", ["[target] name"]),
        ("type-target-param", TARGET + 'radius = "big"\n', ["[target] radius"]),
        ("type-target-domain", TARGET + "domain = 5\n", ["[target] domain"]),
        ("type-target-python", '[target]\npython = 5\ndomain = [[0.0, 1.0], [0.0, 1.0]]\n',
         ["[target] python"]),
        ("type-design-panels-item", design_file().replace("[8, 8]", '["a", 4]'),
         ["[design] panels[0]"]),
        ("type-design-panels-bool", design_file().replace("[8, 8]", "[true, 8]"),
         ["[design] panels[0]"]),
        ("type-design-fix-item", design_file(design_lines='fix = ["everything"]'),
         ["[design] fix[0]"]),
        ("type-solve-ipopt-value", design_file(solve_lines="ipopt_options = {tol_x = [1]}"),
         ["[solve] ipopt_options.tol_x"]),
    ]
    return cases


def _not_finite() -> list[tuple[str, str, list[str]]]:
    """NaN or infinity for every float."""
    values = ["nan", "inf", "-inf"]
    cases = []
    floats = [(k, "design") for k, r in design.DESIGN_KEYS.items() if r.kind == "number"]
    floats += [(k, "solve") for k, r in design.SOLVE_KEYS.items() if r.kind == "number"]
    for i, (key, table) in enumerate(floats):
        line = f"{key} = {values[i % 3]}"
        text = design_file(design_lines=line) if table == "design" else design_file(
            solve_lines=line)
        cases.append((f"nonfinite-{table}-{key}", text, [f"[{table}] {key}", "finite number"]))
    for i, weight in enumerate(DEFAULT_WEIGHTS):
        cases.append((f"nonfinite-weight-{weight}",
                      design_file(design_lines=f"weights = {{{weight} = {values[i % 3]}}}"),
                      [f"[design] weights.{weight}"]))
    cases += [
        ("nonfinite-omega-bounds", design_file(design_lines="omega_bounds = [0.1, inf]"),
         ["[design] omega_bounds[1]"]),
        ("nonfinite-continuation", design_file(solve_lines="continuation = [10.0, nan]"),
         ["[solve] continuation[1]"]),
        ("nonfinite-target-radius", TARGET + "radius = nan\n", ["[target] radius"]),
        ("nonfinite-target-domain", TARGET + "domain = [[-0.5, inf], [-0.5, 0.5]]\n",
         ["[target] domain[0][1]"]),
        ("nonfinite-ipopt-option", design_file(solve_lines="ipopt_options = {mu_init = nan}"),
         ["[solve] ipopt_options.mu_init"]),
    ]
    return cases


def _wrong_lengths_and_ranges() -> list[tuple[str, str, list[str]]]:
    with_panels = design_file().replace
    return [
        ("length-panels-1", with_panels("[8, 8]", "[8]"), ["[design] panels", "a list of 1"]),
        ("length-panels-3", with_panels("[8, 8]", "[8, 8, 8]"), ["[design] panels"]),
        ("length-omega-bounds", design_file(design_lines="omega_bounds = [0.1]"),
         ["[design] omega_bounds"]),
        ("length-domain", TARGET + "domain = [[-0.5, 0.5]]\n", ["[target] domain"]),
        ("length-domain-inner", TARGET + "domain = [[-0.5, 0.5], [0.1, 0.2, 0.3]]\n",
         ["[target] domain[1]"]),
        ("length-continuation", design_file(solve_lines="continuation = []"),
         ["[solve] continuation"]),
        ("range-panels-odd", with_panels("[8, 8]", "[8, 7]"), ["[design] panels[1]", "even"]),
        ("range-panels-small", with_panels("[8, 8]", "[2, 8]"), ["[design] panels[0]", ">= 4"]),
        ("range-alpha0", design_file(design_lines="alpha0 = 2.0"), ["[design] alpha0"]),
        ("range-min-angle", design_file(design_lines="min_angle = 1.0"), ["[design] min_angle"]),
        ("range-omega0", design_file(design_lines="omega0 = 3.5"), ["[design] omega0"]),
        ("range-omega0-bounds", design_file(design_lines="omega0 = 1.0\n"
                                            "omega_bounds = [1.5, 2.5]"), ["omega_bounds"]),
        ("range-weights-zero", design_file(design_lines="weights = {position = 0.0}"),
         ["[design] weights"]),
        ("range-max-iter", design_file(solve_lines="max_iter = 0"), ["[solve] max_iter"]),
        ("range-tol", design_file(solve_lines="tol = 0.0"), ["[solve] tol"]),
        ("range-time-limit", design_file(solve_lines="time_limit = -1"), ["[solve] time_limit"]),
        ("range-seed", design_file(solve_lines="seed = -1"), ["[solve] seed"]),
        ("range-boundary-knots", design_file(solve_lines="boundary_knots = 1"),
         ["[solve] boundary_knots", "at least 2"]),
        ("range-solver", design_file(solve_lines='solver = "bfgs"'), ["[solve] solver"]),
        ("range-layout", design_file(design_lines='layout = "zigzag_k"'),
         ["[design] layout", "did you mean"]),
        ("range-target-name", '[target]\nname = "sphere_cup"\n',
         ["[target] name", "did you mean 'sphere_cap'"]),
        ("range-lm-sequential", design_file(solve_lines='transcription = "sequential"'),
         ["[solve] solver", "simultaneous"]),
        ("ipopt-option-field", design_file(solve_lines="ipopt_options = {max_iter = 3}"),
         ["[solve] ipopt_options", "max_iter"]),
    ]


def _unknown_names() -> list[tuple[str, str, list[str]]]:
    return [
        ("unknown-table", TARGET + "[desing]\npanels = [8, 8]\n",
         ["unknown table [desing]; did you mean [design]?"]),
        ("unknown-table-far", TARGET + "[colours]\nred = 1\n", ["unknown table [colours]"]),
        ("unknown-top-key", "panels = [8, 8]\n" + TARGET, ["unknown key panels"]),
        ("unknown-design-key", design_file(design_lines="panles = [8, 8]"),
         ["[design] panles", "did you mean panels?"]),
        ("unknown-solve-key", design_file(solve_lines='solvr = "ipopt"'),
         ["[solve] solvr", "did you mean solver?"]),
        ("unknown-target-key", TARGET + "radus = 3.0\n",
         ["[target] radus", "did you mean radius?"]),
        ("unknown-weight", design_file(design_lines="weights = {postion = 1.0}"),
         ["[design] weights.postion", "did you mean position?"]),
        ("unknown-python-key", '[target]\npython = "s.py:f"\ndomain = [[0.0, 1.0], [0.0, 1.0]]\n'
                               "radius = 1.0\n", ["[target] radius"]),
        ("solve-key-in-design", design_file(design_lines="stop_rms = 0.01"),
         ["[design] stop_rms", "[solve]"]),
        ("no-target", "[design]\npanels = [8, 8]\n", ["[target]"]),
        ("name-and-python", TARGET + 'python = "s.py:f"\n', ["[target]", "not both"]),
        ("python-form", '[target]\npython = "os.system(1)"\ndomain = [[0.0, 1.0], [0.0, 1.0]]\n',
         ["[target] python", "form"]),
        ("python-untrusted-file", '[target]\npython = "shapes.py:dome"\n'
                                  "domain = [[0.0, 1.0], [0.0, 1.0]]\n",
         ["[target] python", "shapes.py", "--trust"]),
        ("python-untrusted-module", '[target]\npython = "json:loads"\n'
                                    "domain = [[0.0, 1.0], [0.0, 1.0]]\n",
         ["[target] python", "module json", "--trust"]),
        ("secret-not-echoed", design_file(design_lines=f'layout = "{SECRET}"'),
         ["[design] layout", "a string of 47 characters"]),
        ("secret-key-not-echoed", TARGET + f'"{SECRET}" = 1\n', ["[target]", "(a name of 47"]),
        ("empty", "", ["[target]"]),
    ]


DESIGN_CORPUS = _wrong_types() + _not_finite() + _wrong_lengths_and_ranges() + _unknown_names()


def _fifo(folder: Path) -> Path:
    path = folder / "pipe.toml"
    os.mkfifo(path)
    return path


def _directory(folder: Path) -> Path:
    path = folder / "folder.toml"
    path.mkdir()
    return path


def _written(name: str, data: bytes):
    def make(folder: Path) -> Path:
        path = folder / name
        path.write_bytes(data)
        return path
    return make


#: Files that are no design file at all: (id, maker(folder) -> path, fragments).
SPECIAL_FILES = [
    ("fifo", _fifo, ["FIFO", "not a regular file"]),
    ("dev-null", lambda folder: Path(os.devnull), ["character device", "not a regular file"]),
    ("directory", _directory, ["a folder", "not a regular file"]),
    ("missing", lambda folder: folder / "none.toml", ["no such design file"]),
    ("binary", _written("binary.toml", bytes(range(256)) * 4), ["not UTF-8"]),
    ("nul-bytes", _written("nul.toml", TARGET.encode() + b"\x00\x01 = 2\n"),
     ["not valid TOML", "line 3"]),
    ("too-big", _written("big.toml", TARGET.encode() + b"#" * (files.MAX_TOML_BYTES + 1)),
     ["more than the 1024 KiB"]),
    ("nested", _written("nested.toml", b"a = " + b"[" * 100_000), ["too deeply"]),
    ("toml-quote", _written("quote.toml", f"[{SECRET}]\n[{SECRET}]\n".encode()),
     ["not valid TOML", "line 2"]),
]


# --------------------------------------------------------------------------- helpers
def assert_one_line(res, fragments: list[str]) -> str:
    """Exit status 2, no exception, exactly one non-empty line on stderr naming every
    fragment, and never the secret."""
    stderr = res.stderr if hasattr(res, "stderr") else res.output
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert res.exit_code == 2, (res.exit_code, res.output, stderr)
    assert isinstance(res.exception, (SystemExit, type(None))), repr(res.exception)
    assert len(lines) == 1, stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert "SECRET" not in stderr and "Traceback" not in stderr
    return lines[0]


def run_design(path: Path, out: Path, *extra: str):
    return runner.invoke(app, ["design", str(path), "--out", str(out), "--quiet", *extra])


@pytest.fixture
def no_work(monkeypatch):
    """Any start of a solve fails the test: a refusal comes before any work."""
    def start(self):
        raise AssertionError("a malformed file reached DesignProblem.start")
    monkeypatch.setattr(design.DesignProblem, "start", start)


# --------------------------------------------------------------------------- design files
def test_the_corpus_is_large_enough():
    assert len(DESIGN_CORPUS) + len(SPECIAL_FILES) >= 70
    assert len({case for case, _, _ in DESIGN_CORPUS}) == len(DESIGN_CORPUS)


@pytest.mark.parametrize("text, fragments", [c[1:] for c in DESIGN_CORPUS],
                         ids=[c[0] for c in DESIGN_CORPUS])
def test_malformed_design_files_are_refused_in_one_line(tmp_path, no_work, text, fragments):
    path = tmp_path / "design.toml"
    path.write_text(text)
    out = tmp_path / "out"
    line = assert_one_line(run_design(path, out), fragments)
    assert not out.exists()
    with pytest.raises(InputError) as info:
        rq.load_design(path)
    message = str(info.value)
    assert "\n" not in message and all(f in message for f in fragments), message
    assert message in line


@pytest.mark.parametrize("make, fragments", [c[1:] for c in SPECIAL_FILES],
                         ids=[c[0] for c in SPECIAL_FILES])
def test_files_that_are_no_design_file_are_refused_in_one_line(tmp_path, no_work, make,
                                                                  fragments):
    path = make(tmp_path)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    assert_one_line(run_design(path, out), fragments)
    with pytest.raises(InputError, match=str(path).replace(".", r"\.")):
        rq.load_design(path)
    assert time.perf_counter() - t0 < 5           # a FIFO never blocks
    assert not out.exists()


def test_a_size_this_machine_cannot_hold_is_refused_before_any_work(tmp_path, no_work):
    path = tmp_path / "huge.toml"
    path.write_text(design_file().replace("[8, 8]", "[100000, 100000]"))
    out = tmp_path / "out"
    t0 = time.perf_counter()
    line = assert_one_line(run_design(path, out), [
        "[design] panels = [100000, 100000] with solver levenberg-marquardt needs about",
        "GB available; choose fewer panels"])
    assert time.perf_counter() - t0 < 1.0
    assert not out.exists()
    problem, options = rq.load_design(path)
    need = design.memory_estimate(problem, options)
    assert f"needs about {memory.gigabytes(need)} GB" in line
    with pytest.raises(InputError, match="choose fewer panels"):
        problem.solve(options)
    with pytest.raises(InputError, match="with solver ipopt"):
        problem.solve(options, solver="ipopt")
    small = design.DesignProblem(target=problem.target, panels=(8, 8))
    design.check_memory(small, options)           # a small design passes


def test_the_panels_override_of_the_command_is_checked_too(tmp_path, no_work):
    path = tmp_path / "design.toml"
    path.write_text(design_file())
    out = tmp_path / "out"
    assert_one_line(run_design(path, out, "--panels", "100000,100000"), ["choose fewer panels"])
    assert_one_line(run_design(path, out, "--panels", "8,7"), ["[design] panels[1]"])
    assert not out.exists()


@pytest.mark.parametrize("function, objective, program", [
    ("side_length_lp", None, "lp"), ("side_length_nlp", "max_min", "lp"),
    ("side_length_nlp", "uniform", "nlp")])
def test_side_lengths_this_machine_cannot_hold_are_refused_before_any_work(
        function, objective, program, monkeypatch):
    """The side-length programs' dense maps grow like N M (N + M): a 3000 x 3000 pattern
    (over 10,000 GB) is refused in one line before the maps are built."""
    def maps(bd):
        raise AssertionError("the length maps were built")
    monkeypatch.setattr(lengths, "length_maps", maps)
    bd = rq.miura_boundary(3000, 3000, a=1.0, b=1.3, alpha0=1.1)
    with pytest.raises(InputError) as info:
        getattr(lengths, function)(bd, **({} if objective is None else
                                          {"objective": objective}))
    line = str(info.value)
    assert line.startswith(f"{function} on 3000 x 3000")
    need = lengths.memory_estimate(3000, 3000, program)
    assert "\n" not in line and f"on 3000 x 3000 panels needs about {memory.gigabytes(need)} GB" \
        in line and line.endswith("choose fewer panels or keep the given side lengths")


def test_the_march_command_refuses_an_lp_it_cannot_hold(tmp_path, monkeypatch):
    """`rffqm march --lp` on a pattern this machine cannot hold: exit status 2, one line,
    no output folder, before the maps are built."""
    def maps(bd):
        raise AssertionError("the length maps were built")
    monkeypatch.setattr(lengths, "length_maps", maps)
    out = tmp_path / "march"
    # 800 x 800: the march itself fits any machine with 1.5 GB (cli.march_memory)
    res = runner.invoke(app, ["march", "--rows", "800", "--cols", "800", "--lp",
                              "--out", str(out)])
    assert_one_line(res, ["side_length_lp on 800 x 800 panels needs about",
                          "GB available; choose fewer panels"])
    assert not out.exists()


@pytest.mark.parametrize("frames, fragments", [
    (0, ["rffqm march on 100000 x 100000 panels needs about 2.6e4 GB;",
         "GB available; choose fewer panels"]),
    (50, ["rffqm march on 100000 x 100000 panels with 50 frames needs about 2.5e5 GB;",
          "GB available; choose fewer panels or frames"])])
def test_the_march_command_refuses_a_pattern_it_cannot_hold(tmp_path, monkeypatch, frames,
                                                            fragments):
    """`rffqm march` on a pattern (and motion) this machine cannot hold: exit status 2, one
    line with the estimate, no output folder, before any march."""
    def boundary(*args, **kwargs):
        raise AssertionError("the boundary was built")
    monkeypatch.setattr(forward_commands, "miura_boundary", boundary)
    out = tmp_path / "march"
    res = runner.invoke(app, ["march", "--rows", "100000", "--cols", "100000", "--frames",
                              str(frames), "--out", str(out)])
    assert_one_line(res, fragments)
    assert not out.exists()


def test_the_side_length_memory_model_matches_the_measured_peaks():
    """memory.LENGTHS_PER_UNIT (2026-12-02, docs/decisions/memory.md): HiGHS' LP of eq:linearP
    peaked at 0.55 and 3.5 GB at 100 and 200 panels a side, its max-min LP at 0.58 and 1.71
    GB at 100 and 150, IPOPT's "uniform" NLP at 0.45 and 1.17 GB at 50 and 70."""
    gb = lambda n, program: lengths.memory_estimate(n, n, program) / 1e9  # noqa: E731
    assert gb(100, "lp") == pytest.approx(0.55, rel=0.15)
    assert gb(200, "lp") == pytest.approx(3.5, rel=0.15)
    assert gb(100, "lp") == pytest.approx(0.58, rel=0.15)
    assert gb(150, "lp") == pytest.approx(1.71, rel=0.15)
    assert gb(50, "nlp") == pytest.approx(0.45, rel=0.2)
    assert gb(70, "nlp") == pytest.approx(1.17, rel=0.15)


def test_memory_model_matches_the_measured_peaks():
    """docs/decisions/memory.md: Levenberg-Marquardt in the whole design 0.39 and 1.08 GB at 100 and
    200 panels a side with the target lattice fixed, 0.39, 1.13, 2.04 and 5.40 GB at 100,
    200, 300 and 500 with the free correspondence (2026-12-03), IPOPT (simultaneous) 2.1 GB
    at 100 x 100 and 6.9-7.4 GB at 200 x 200."""
    target = rq.surfaces.get("sphere_cap")

    def gb(panels: int, correspondence: str = "free", **options) -> float:
        problem = design.DesignProblem(target=target, panels=(panels, panels),
                                       correspondence=correspondence)
        return design.memory_estimate(problem, design.SolveOptions(**options)) / 1e9

    assert gb(100, "lattice") == pytest.approx(0.39, rel=0.15)
    assert gb(200, "lattice") == pytest.approx(1.08, rel=0.15)
    assert gb(100) == pytest.approx(0.39, rel=0.15)
    assert gb(200) == pytest.approx(1.13, rel=0.15)
    assert gb(300) == pytest.approx(2.04, rel=0.2)
    assert gb(500) == pytest.approx(5.40, rel=0.2)
    # a refusal should err high: the model is at least each Levenberg-Marquardt peak (to 1%)
    for n, peak in ((100, 0.39), (200, 1.13), (300, 2.04), (500, 5.40)):
        assert gb(n) >= 0.99 * peak
    # with stop_rms the run may end in the coarse basis of 32 knots a class (1.06, 1.87
    # and 4.80 GB at 200, 300 and 500, 2026-12-03); below 64 panels a side there is none
    coarse = lambda n: gb(n, stop_rms=0.009)  # noqa: E731
    assert coarse(200) == pytest.approx(1.06, rel=0.15)
    assert coarse(300) == pytest.approx(1.87, rel=0.15)
    assert 0.99 * 4.80 <= coarse(500) <= 1.2 * 4.80
    assert coarse(40) == gb(40) and coarse(200) < gb(200)
    assert gb(500, stop_rms=0.009, boundary_knots=0) == gb(500)
    assert gb(100, solver="ipopt") == pytest.approx(2.1, rel=0.15)
    assert gb(200, solver="ipopt") == pytest.approx(7.2, rel=0.15)
    assert gb(20, solver="ipopt", transcription="sequential") < 2
    assert gb(100_000) > 1e5  # refused on any machine


# --------------------------------------------------------------------------- the API
@pytest.mark.parametrize("kw, name", [
    ({"panels": 4}, "[design] panels"), ({"panels": ("a", 4)}, "[design] panels[0]"),
    ({"panels": (8, 8.0)}, "[design] panels[1]"),
    ({"weights": {"position": math.nan}}, "[design] weights.position"),
    ({"weights": {"shape": 1.0}}, "[design] weights.shape"), ({"weights": 1.0}, "weights"),
    ({"fix": "angles"}, "[design] fix"), ({"omega_bounds": (0.1, 0.2, 0.3)}, "omega_bounds"),
    ({"layout": None}, "[design] layout"), ({"alpha0": "1.1"}, "[design] alpha0"),
    ({"min_length": math.inf}, "[design] min_length")])
def test_design_problem_raises_input_error_naming_the_field(kw, name):
    target = rq.surfaces.get("sphere_cap")
    with pytest.raises(InputError) as info:
        design.DesignProblem(target=target, **kw)
    assert name in str(info.value)
    with pytest.raises(InputError, match="target must be a surface"):
        design.DesignProblem(target={"name": "sphere_cap"})


@pytest.mark.parametrize("kw, name", [
    ({"max_iter": 2.5}, "[solve] max_iter"), ({"max_iter": True}, "[solve] max_iter"),
    ({"time_limit": -1}, "[solve] time_limit"), ({"ipopt_options": 5}, "ipopt_options"),
    ({"ipopt_options": {"mu_init": [1]}}, "ipopt_options.mu_init"),
    ({"ipopt_options": {"Bad Name": 1}}, "ipopt_options"),
    ({"continuation": 10.0}, "[solve] continuation"), ({"solver": None}, "[solve] solver"),
    ({"stop_rms": math.nan}, "[solve] stop_rms"), ({"seed": 1.5}, "[solve] seed"),
    ({"boundary_knots": 2.5}, "[solve] boundary_knots")])
def test_solve_options_raise_input_error_naming_the_field(kw, name):
    with pytest.raises(InputError) as info:
        design.SolveOptions(**kw)
    assert name in str(info.value)


def test_check_table_says_what_is_allowed():
    spec = {"n": files.Key("whole", low=1), "x": files.Key("number", low=0.0, high=1.0,
                                                            high_open=True, optional=True)}
    assert files.check_table({"n": 3, "x": None}, spec, "[t]") == {"n": 3, "x": None}
    for table, message in [
            ({"n": 0}, "[t] n must be a whole number >= 1, got the whole number 0"),
            ({"x": 1.0}, "[t] x must be a finite number in [0, 1) or None"),
            ({"nn": 1}, "unknown key [t] nn; did you mean n?"),
            ({"zzz": 1}, "unknown key [t] zzz; known: n, x"),
            ([1, 2], "[t] must be a table, got a list of 2 items")]:
        with pytest.raises(InputError) as info:
            files.check_table(table, spec, "[t]")
        assert message in str(info.value)


# --------------------------------------------------------------------------- trust
SHAPES = "import casadi as ca\n\ndef dome(u, v):\n    return u, v, 0.2 * ca.cos(u) * ca.cos(v)\n"


def test_code_runs_only_with_trust(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)                    # the file is found by path, not sys.path
    folder = tmp_path / "shared"
    folder.mkdir()
    (folder / "shapes.py").write_text(SHAPES)
    path = folder / "dome.toml"
    path.write_text(design_file(target='[target]\npython = "shapes.py:dome"\n'
                                       "domain = [[-1.0, 1.0], [-1.0, 1.0]]\n"))
    with pytest.raises(InputError, match="pass --trust"):
        rq.load_design(path)
    problem, _ = rq.load_design(path, trust=True)
    assert problem.target.point(0.0, 0.0)[2] == pytest.approx(0.2)
    assert problem.panels == (8, 8)
    out = tmp_path / "out"
    assert_one_line(run_design(path, out), ["[target] python", "pass --trust"])

    def start(self):                               # with --trust the solve is reached
        raise RuntimeError(f"started {self.target.point(0.0, 0.0)[2]:.2f}")
    monkeypatch.setattr(design.DesignProblem, "start", start)
    res = run_design(path, out, "--trust")
    assert isinstance(res.exception, RuntimeError) and str(res.exception) == "started 0.20"
    assert not out.exists()


# --------------------------------------------------------------------------- study files
STUDY_CORPUS = [
    ("unknown-top-key", "colour = 1\n", ["unknown key colour"]),
    ("unknown-table", "[desing]\npanels = [8, 8]\n",
     ["unknown table [desing]; did you mean [design]?"]),
    ("sweep-not-table", "sweep = 5\n", ["[sweep] must be a table"]),
    ("description-type", "description = 5\n", ["description must be a string"]),
    ("base-not-toml", 'base = "notes.txt"\n', ["base must name a design file ending in .toml"]),
    ("base-not-string", "base = 5\n", ["base must be a string"]),
    ("base-missing", 'base = "none.toml"\n', ["base: no such design file"]),
    ("base-binary", 'base = "binary.toml"\n', ["base file", "not UTF-8"]),
    ("base-fifo", 'base = "pipe.toml"\n', ["base file", "FIFO"]),
    ("base-unknown-table", 'base = "extra.toml"\n', ["unknown table [colours]"]),
    ("base-secret", 'base = "secret.toml"\n', ["[design] layout", "a string of 47 characters"]),
    ("sweep-not-list", '[sweep]\n"target.radius" = 4.0\n', ["[sweep] target.radius"]),
    ("sweep-panels", '[sweep]\n"design.panels" = [5]\n', ["[design] panels[0]"]),
    ("sweep-max-iter", '[sweep]\n"solve.max_iter" = [2.5]\n', ["[solve] max_iter"]),
    ("sweep-sample", '[sweep]\nsample = 0\n"target.radius" = [4.0]\n', ["[sweep] sample"]),
    ("sweep-secret", f'[sweep]\n"design.layout" = ["{SECRET}"]\n', ["[design] layout"]),
    ("solve-nan", "[solve]\nstop_rms = nan\n", ["[solve] stop_rms"]),
    ("sweep-huge", '[sweep]\n"design.panels" = [100000]\n', ["choose fewer panels"]),
    ("python-untrusted", '[target]\npython = "shapes.py:dome"\ndomain = [[0.0, 1.0], [0.0, 1.0]]\n',
     ["[target] python", "--trust"]),
    ("base-python-untrusted", 'base = "python.toml"\n', ["[target] python", "--trust"]),
]


def _study_folder(folder: Path) -> None:
    """The design files the study corpus names as base."""
    (folder / "binary.toml").write_bytes(bytes(range(256)))
    os.mkfifo(folder / "pipe.toml")
    (folder / "extra.toml").write_text(TARGET + "[colours]\nred = 1\n")
    (folder / "secret.toml").write_text(design_file(design_lines=f'layout = "{SECRET}"'))
    (folder / "python.toml").write_text('[target]\npython = "shapes.py:dome"\n'
                                        "domain = [[0.0, 1.0], [0.0, 1.0]]\n")
    (folder / "shapes.py").write_text(SHAPES)


@pytest.mark.parametrize("text, fragments", [c[1:] for c in STUDY_CORPUS],
                         ids=[c[0] for c in STUDY_CORPUS])
def test_malformed_study_files_are_refused_in_one_line(tmp_path, no_work, text, fragments):
    _study_folder(tmp_path)
    path = tmp_path / "study.toml"
    body = text if "base" in text or "[target]" in text else text + "\n" + TARGET
    path.write_text(body + ("\n[design]\npanels = [8, 8]\n" if "[design]" not in body
                            and "design.panels" not in body and "base" not in body else ""))
    out = tmp_path / "out"
    t0 = time.perf_counter()
    res = runner.invoke(app, ["sweep", str(path), "--out", str(out), "--scheduler", "none",
                              "--quiet"])
    assert_one_line(res, fragments)
    assert not out.exists()
    with pytest.raises(InputError) as info:
        sweeps.Study.load(path).designs()
    assert all(f in str(info.value) for f in fragments) and SECRET not in str(info.value)
    assert time.perf_counter() - t0 < 10


def test_a_study_runs_code_only_with_trust(tmp_path):
    _study_folder(tmp_path)
    path = tmp_path / "study.toml"
    path.write_text('base = "python.toml"\n[design]\npanels = [8, 8]\n'
                    '[sweep]\n"design.layout" = ["zigzag_i", "zigzag_j"]\n')
    designs = sweeps.Study.load(path, trust=True).designs()
    assert [d.config["target"]["python"] for d in designs] == [f"{tmp_path / 'shapes.py'}:dome"] * 2
    assert all(d.payload()["trust"] for d in designs)
    with pytest.raises(InputError, match="pass --trust"):
        sweeps.Study.load(path).designs()


def test_render_rebuilds_a_code_target_only_with_trust(tmp_path, monkeypatch):
    (tmp_path / "shapes.py").write_text(SHAPES)
    result = SimpleNamespace(
        problem={"target": {"python": f"{tmp_path / 'shapes.py'}:dome",
                            "domain": [[-1.0, 1.0], [-1.0, 1.0]]}},
        target_points=np.zeros((3, 3, 3)), rotation=np.eye(3), translation=np.zeros(3),
        target_grid=None)
    warnings: list[str] = []
    monkeypatch.setattr(result_files, "warn", warnings.append)
    points = result_files.target_for_render(result)
    assert np.shape(points) == (9, 3) and "pass --trust" in warnings[0]
    mesh = result_files.target_for_render(result, trust=True)
    assert len(mesh.faces) > 0 and len(warnings) == 1
