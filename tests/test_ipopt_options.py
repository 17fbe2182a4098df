"""IPOPT options from a file are inert (issue 41): no option a file sets opens a file or
loads a library unless the caller trusts it, nothing is built to check them, and the table
they are checked against agrees with IPOPT itself."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import casadi as ca
import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp.cli import app
from rffqm_nlp.ipopt_options import (FILE_OPTIONS, INT_MAX, LOADING_CHOICES, NO_OPTION_FILE,
                                     OPTIONS, check_ipopt_options)

try:
    runner = CliRunner(mix_stderr=False)
except TypeError:                      # click >= 8.2 keeps stderr apart by itself
    runner = CliRunner()

VICTIM_TEXT = "a thesis nobody may empty\n"
SECRET = "SECRET-" + "y" * 40


@pytest.fixture
def victim(tmp_path: Path) -> Path:
    path = tmp_path / "thesis.tex"
    path.write_text(VICTIM_TEXT)
    return path


def design_file(tmp_path: Path, ipopt_options: str, target: str = 'name = "sphere_cap"',
                name: str = "design.toml") -> Path:
    path = tmp_path / name
    path.write_text(f"[target]\n{target}\n[design]\npanels = [4, 4]\n"
                    f"[solve]\nsolver = \"ipopt\"\nmax_iter = 3\nipopt_options = {ipopt_options}\n")
    return path


def refused_in_one_line(result, *names: str) -> str:
    assert result.exit_code == 2, result.output
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    for name in names:
        assert name in lines[0]
    return lines[0]


# --------------------------------------------------------------------------- hole 1
@pytest.mark.parametrize("target", ['name = "sphere_cap"', 'name = "no_such_surface"'])
def test_a_design_file_cannot_empty_a_file_it_names(tmp_path, victim, target):
    path = design_file(tmp_path, f'{{output_file = "{victim}"}}', target)
    result = runner.invoke(app, ["design", str(path), "--out", str(tmp_path / "out")])
    line = refused_in_one_line(result)
    assert victim.read_text() == VICTIM_TEXT
    assert str(victim) not in line and not (tmp_path / "out").exists()
    with pytest.raises(rq.InputError, match=r"ipopt_options.output_file names a file"):
        rq.load_design(design_file(tmp_path, f'{{output_file = "{victim}"}}'))
    assert victim.read_text() == VICTIM_TEXT


def test_a_study_cannot_empty_a_file_it_names(tmp_path, victim):
    base = design_file(tmp_path, f'{{"ipopt.output_file" = "{victim}"}}')
    study = tmp_path / "study.toml"
    study.write_text(f'base = "{base.name}"\n[sweep]\n"design.layout" = ["zigzag_j"]\n')
    result = runner.invoke(app, ["sweep", str(study), "--out", str(tmp_path / "out"),
                                 "--scheduler", "none"])
    refused_in_one_line(result, "ipopt_options.output_file")
    assert victim.read_text() == VICTIM_TEXT


def test_options_are_checked_without_building_a_solver(victim):
    """Trusted options naming a file are kept, and touch it only when a solve runs."""
    options = rq.SolveOptions(solver="ipopt", ipopt_options={"output_file": str(victim)},
                              trust=True)
    assert options.ipopt_options == {"output_file": str(victim)}
    problem = rq.DesignProblem(target=rq.surfaces.get("sphere_cap"), panels=(4, 4))
    problem.transcribe()
    assert victim.read_text() == VICTIM_TEXT
    with pytest.raises(rq.InputError, match="output_file names a file"):
        rq.SolveOptions(ipopt_options={"output_file": str(victim)})
    with pytest.raises(rq.InputError, match="trust must be true or false"):
        rq.SolveOptions(trust="yes")


def test_trust_is_the_callers_word_never_a_files(tmp_path, victim):
    """A [solve] table cannot say trust = true, and saved options do not carry trust."""
    path = tmp_path / "design.toml"
    path.write_text('[target]\nname = "sphere_cap"\n[solve]\ntrust = true\n'
                    f'ipopt_options = {{output_file = "{victim}"}}\n')
    with pytest.raises(rq.InputError, match=r"unknown key \[solve\] trust"):
        rq.load_design(path)
    options = rq.SolveOptions(ipopt_options={"output_file": str(victim)}, trust=True)
    assert "trust" not in options.to_config()
    with pytest.raises(rq.InputError, match="output_file names a file"):
        rq.SolveOptions.from_config(options.to_config())
    assert rq.SolveOptions.from_config(options.to_config(), trust=True) == options


def test_trusted_output_file_reaches_ipopt(tmp_path):
    """The opt-in works: with trust, IPOPT writes the file the options name."""
    log = tmp_path / "ipopt.out"
    problem, options = rq.load_design(
        design_file(tmp_path, f'{{output_file = "{log}", file_print_level = 5}}'), trust=True)
    with pytest.raises(rq.SolverFailed, match="Maximum_Iterations_Exceeded"):
        problem.solve(options)
    assert "Number of Iterations" in log.read_text()


# --------------------------------------------------------------------------- hole 2
EVIL_C = r"""
#include <stdio.h>
#include <stdlib.h>
__attribute__((constructor)) static void ran(void) {
    const char *path = getenv("RFFQM_TEST_MARKER");
    if (path) { FILE *f = fopen(path, "w"); if (f) { fputs("ran\n", f); fclose(f); } }
}
"""


@pytest.fixture
def evil_library(tmp_path: Path) -> Path:
    """A shared library whose constructor writes the file $RFFQM_TEST_MARKER."""
    source, library = tmp_path / "evil.c", tmp_path / "evil.so"
    source.write_text(EVIL_C)
    compiler = shutil.which("cc") or shutil.which("gcc")
    assert compiler, "setup.sh installs gcc for this test"
    subprocess.run([compiler, "-shared", "-fPIC", "-o", str(library), str(source)], check=True)
    return library


@pytest.mark.parametrize("option", ["hsllib", "pardisolib"])
def test_a_design_file_cannot_load_a_library(tmp_path, evil_library, monkeypatch, option):
    marker = tmp_path / "marker"
    monkeypatch.setenv("RFFQM_TEST_MARKER", str(marker))
    solver = "ma27" if option == "hsllib" else "pardiso"
    path = design_file(tmp_path, f'{{linear_solver = "{solver}", {option} = "{evil_library}"}}')
    result = runner.invoke(app, ["design", str(path), "--out", str(tmp_path / "out")])
    refused_in_one_line(result)
    assert not marker.exists()


def test_the_library_test_would_see_a_load(tmp_path, evil_library):
    """The control of the test above: trusted, the same options do load the library (in a
    child process, so that this one never loads it)."""
    marker = tmp_path / "marker"
    path = design_file(tmp_path, f'{{linear_solver = "ma27", hsllib = "{evil_library}"}}')
    script = textwrap.dedent(f"""
        import rffqm_nlp as rq
        problem, options = rq.load_design({str(path)!r}, trust=True)
        try:
            problem.solve(options)
        except rq.SolverFailed as exc:
            print(exc.status)
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env={**os.environ, "RFFQM_TEST_MARKER": str(marker)}, timeout=300)
    assert marker.read_text() == "ran\n", out.stderr


@pytest.mark.parametrize("option, value", [(name, choice) for name, choices in
                                           LOADING_CHOICES.items() for choice in choices])
def test_choices_that_load_a_library_need_trust(option, value):
    with pytest.raises(rq.InputError, match="load a shared library"):
        check_ipopt_options({option: value})
    assert check_ipopt_options({option: value}, trust=True) == {option: value}


# --------------------------------------------------------------------------- hole 3
def test_a_design_file_cannot_print_a_file(tmp_path):
    secret = tmp_path / "secret.opt"
    secret.write_text(f"tol 1e-3\n# {SECRET}\n")
    path = design_file(tmp_path, f'{{option_file_name = "{secret}"}}')
    result = runner.invoke(app, ["design", str(path), "--out", str(tmp_path / "out")])
    refused_in_one_line(result, "option_file_name")
    assert SECRET not in result.output + result.stderr and "tol" not in result.output


def test_an_ipopt_opt_in_the_working_folder_is_not_read(tmp_path, victim, monkeypatch):
    """IPOPT reads ./ipopt.opt by default; every solver the package builds turns that off."""
    (tmp_path / "ipopt.opt").write_text(f"output_file {victim}\n")
    monkeypatch.chdir(tmp_path)
    problem = rq.DesignProblem(target=rq.surfaces.get("sphere_cap"), panels=(4, 4))
    with pytest.raises(rq.SolverFailed, match="Maximum_Iterations_Exceeded"):
        problem.solve(rq.SolveOptions(solver="ipopt", max_iter=2))
    rq.lengths.side_length_nlp(rq.miura_boundary(2, 2))
    assert victim.read_text() == VICTIM_TEXT
    x = ca.MX.sym("x")   # the control: without NO_OPTION_FILE, IPOPT reads the file
    ca.nlpsol("s", "ipopt", {"x": x, "f": x * x},
              {"ipopt.sb": "yes", "ipopt.print_level": 0, "print_time": False})(x0=1)
    assert victim.read_text() == ""


# --------------------------------------------------------------------------- the table
@pytest.mark.parametrize("options, match", [
    ({"no_such_option": 1}, "no_such_option is not an option of IPOPT 3.14"),
    ({"mu_stratgy": "adaptive"}, "did you mean mu_strategy"),
    ({"mu_strategy": "fastest"}, "mu_strategy must be one of 'monotone', 'adaptive'"),
    ({"bound_mult_init_val": -1.0}, "bound_mult_init_val must be a finite number > 0"),
    ({"bound_mult_init_val": float("nan")}, "finite number"),
    ({"acceptable_iter": 2.5}, "acceptable_iter must be a whole number"),
    ({"acceptable_iter": 10**30}, "acceptable_iter must be a whole number in"),
    ({"warm_start_init_point": True}, "one of 'yes', 'no'"),
    ({"ipopt.tol": 1e-3}, "through SolveOptions.tol"),
    ({"max_wall_time": 10.0}, "through SolveOptions.time_limit"),
    ({"print_level": 3}, r"through solve\(verbose=...\)"),
    ({7: 1}, "names as keys"),
    ("mu_init=1e-3", r"must be a table of IPOPT options by name, got a string of 12 char")])
def test_bad_options_are_refused_in_one_line(options, match):
    with pytest.raises(rq.InputError, match=match) as info:
        rq.SolveOptions(ipopt_options=options)
    assert "\n" not in str(info.value)


def test_trust_allows_files_but_still_checks_names_and_values():
    assert check_ipopt_options({"ipopt.hsllib": "libhsl.so"}, trust=True) == {
        "hsllib": "libhsl.so"}
    with pytest.raises(rq.InputError, match="must be a string"):
        check_ipopt_options({"output_file": 5}, trust=True)
    with pytest.raises(rq.InputError, match="must be a finite number > 0"):
        check_ipopt_options({"tol": 0.0}, trust=True)


def _builds(name: str, value) -> bool:
    x = ca.MX.sym("x")
    try:
        ca.nlpsol("s", "ipopt", {"x": x, "f": x * x}, {f"ipopt.{name}": value, **NO_OPTION_FILE,
                                                      "ipopt.sb": "yes", "print_time": False})
    except RuntimeError:
        return False
    return True


def _edges(key) -> list[tuple[object, bool]]:
    """(value, allowed) at each finite bound of a number option: the bound or the nearest
    value inside, and the nearest value outside."""
    cases = []
    for bound, is_open, inward in ((key.low, key.low_open, 1), (key.high, key.high_open, -1)):
        if bound is None or abs(bound) >= INT_MAX:
            continue
        step = 1 if key.kind == "whole" else 1e-9 * max(1.0, abs(bound))
        inside = bound + inward * step if is_open else bound
        outside = bound if is_open else bound - inward * step
        cases += [(inside, True), (outside, False)]
    return cases


def test_the_table_agrees_with_ipopt():
    """Every option IPOPT 3.14 documents is in the table or names a file; every allowed
    choice and every bound's edge is what IPOPT itself accepts (print_level: CasADi's)."""
    disagree = []
    for name, key in OPTIONS.items():
        if key.kind == "choice":
            cases = [(choice, True) for choice in key.choices] + [("no-such-choice", False)]
        else:
            cases = _edges(key)
        for value, allowed in cases:
            if name != "print_level" and _builds(name, value) != allowed:
                disagree.append((name, value, allowed))
    assert disagree == []
    assert not (set(FILE_OPTIONS) & set(OPTIONS))
    assert not _builds("no_such_option", 1)
