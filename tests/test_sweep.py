"""Design studies: study files, grid and sample expansion, runs on a LocalCluster and
serially, killed workers, resume, multistart and the ``rffqm sweep`` command.

Four tiny designs (4 x 4 panels, under a second each) run three times: on a LocalCluster
with 2 workers, serially, and on a LocalCluster where one design kills its worker once and
another on every try; the resume test re-runs the last one's folder serially.
"""

from __future__ import annotations

import functools
import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, strategies as st
from typer.testing import CliRunner

from rffqm_nlp import sweeps
from rffqm_nlp.targets import surfaces
from rffqm_nlp.cli import app
from rffqm_nlp.design import DesignProblem, SolveOptions, multistart_starts
from rffqm_nlp.errors import InfeasibleDesign, InputError, SolverFailed
from rffqm_nlp.design.results import DesignResult

STUDY = """
description = "four tiny sphere caps"

[target]
name = "sphere_cap"

[design]
panels = [4, 4]

[solve]
solver = "ipopt"
max_iter = 200

[sweep]
target.radius = [3.0, 3.5, 4.0, 4.5]
"""
RADII = (3.0, 3.5, 4.0, 4.5)
CRASH_ONCE, CRASH_ALWAYS = "radius=3.5", "radius=4.5"
FIT = ["rms", "rms_surface", "hausdorff", "plane_rms", "min_side_over_mean", "min_sector_angle"]


def crash_hook(payload: dict, marker_dir: str) -> dict:
    """:func:`sweeps.solve_design`, except that the design named CRASH_ONCE kills its worker
    process on its first try (leaving a marker file) and CRASH_ALWAYS on every try."""
    if payload["name"] == CRASH_ALWAYS:
        os._exit(1)
    marker = Path(marker_dir) / payload["id"]
    if payload["name"] == CRASH_ONCE and not marker.exists():
        marker.touch()
        os._exit(1)
    return sweeps.solve_design(payload)


def counting_task(calls: list[str]):
    """:func:`sweeps.solve_design` that records the id of every design it solves."""
    def task(payload: dict) -> dict:
        calls.append(payload["id"])
        return sweeps.solve_design(payload)
    return task


@pytest.fixture(scope="module")
def study_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("study") / "study.toml"
    path.write_text(STUDY)
    return path


@pytest.fixture(scope="module")
def designs(study_file) -> list[sweeps.Design]:
    return sweeps.Study.load(study_file).designs()


@pytest.fixture(scope="module")
def cluster_run(study_file, tmp_path_factory) -> tuple[Path, pd.DataFrame]:
    out = tmp_path_factory.mktemp("cluster") / "out"
    return out, sweeps.run(study_file, out, workers=2, progress=False)


@pytest.fixture(scope="module")
def serial_run(study_file, tmp_path_factory) -> pd.DataFrame:
    return sweeps.run(study_file, tmp_path_factory.mktemp("serial") / "out", scheduler="none",
                     progress=False)


@pytest.fixture(scope="module")
def crash_run(study_file, tmp_path_factory) -> tuple[Path, Path, pd.DataFrame]:
    base = tmp_path_factory.mktemp("crash")
    markers = base / "markers"
    markers.mkdir()
    task = functools.partial(crash_hook, marker_dir=str(markers))
    frame = sweeps.run(study_file, base / "out", workers=2, worker_retries=1, task=task,
                      progress=False)
    return base / "out", markers, frame


# --------------------------------------------------------------------------- runs
def test_cluster_run_writes_one_row_and_one_folder_per_design(cluster_run, designs):
    out, frame = cluster_run
    assert list(frame["id"]) == [d.id for d in designs]
    assert list(frame["target.radius"]) == list(RADII)
    assert list(frame["status"]) == ["solved"] * 4
    assert set(frame["solver_status"]) == {"Solve_Succeeded"}
    assert frame["worker"].str.startswith("tcp://").all()
    assert (frame["rms"] < 0.05).all() and (frame["rms"] < frame["plane_rms"]).all()
    assert (frame["iterations"] > 0).all() and (frame["time"] > 0).all()
    on_disk = pd.read_parquet(out / "results.parquet")
    pd.testing.assert_frame_equal(on_disk, frame)
    assert on_disk["collision_free"].dtype == "boolean" and on_disk["collision_free"].all()
    assert on_disk["first_contact_omega"].isna().all()
    assert len(pd.read_csv(out / "results.csv")) == 4
    for design, (_, row) in zip(designs, frame.iterrows()):
        result = DesignResult.load(out / "designs" / design.id)
        assert result.fit.rms == row["rms"]
        assert result.problem["target"]["radius"] == row["target.radius"]
        assert sweeps.completed_row(out / "designs" / design.id, design) is not None
        row_json = json.loads((out / "designs" / design.id / "row.json").read_text())["row"]
        assert row_json["collision_free"] is True and row_json["first_contact_omega"] is None
    assert not [p for p in out.rglob(".*")], "temporary files left behind"


def test_serial_run_gives_the_same_table(cluster_run, serial_run):
    _, cluster = cluster_run
    same = ["id", "name", "target.radius", "status", "solver_status", "iterations", "start"]
    pd.testing.assert_frame_equal(serial_run[same], cluster[same])
    np.testing.assert_allclose(serial_run[FIT].to_numpy(), cluster[FIT].to_numpy(),
                               rtol=1e-8, atol=1e-12)
    assert set(serial_run["worker"]) == {"in-process"}


def test_a_killed_worker_loses_no_row(crash_run, designs):
    out, markers, frame = crash_run
    by_name = frame.set_index("name")
    assert list(frame["id"]) == [d.id for d in designs]
    # Killed once: Dask reran it on a live worker.
    assert (markers / by_name.loc[CRASH_ONCE, "id"]).exists()
    assert by_name.loc[CRASH_ONCE, "status"] == "solved"
    # Killed on every try: a row that says so, and no result.
    lost = by_name.loc[CRASH_ALWAYS]
    assert lost["status"] == "worker_lost" and "died" in lost["reason"]
    assert np.isnan(lost["rms"])
    assert not (out / "designs" / lost["id"] / "result.json").exists()
    assert json.loads((out / "designs" / lost["id"] / "row.json").read_text())["row"][
        "status"] == "worker_lost"
    assert set(frame["status"]) == {"solved", "worker_lost"}
    assert (frame["status"] == "solved").sum() == 3


def test_resume_skips_finished_designs_and_recomputes_broken_ones(crash_run, serial_run,
                                                                   study_file, designs,
                                                                   tmp_path):
    source, _, _ = crash_run
    out = tmp_path / "out"
    shutil.copytree(source, out)
    ids = {d.name: d.id for d in designs}
    folder = {name: out / "designs" / i for name, i in ids.items()}
    # A truncated result.json, and another design's row.json in the wrong folder.
    result = folder["radius=3"] / "result.json"
    result.write_text(result.read_text()[:1000])
    shutil.copy(folder["radius=3.5"] / "row.json", folder["radius=4"] / "row.json")
    kept = folder["radius=3.5"] / "row.json"
    stamp = kept.stat().st_mtime_ns
    calls: list[str] = []
    frame = sweeps.run(study_file, out, scheduler="none", task=counting_task(calls),
                      progress=False)
    # The broken, the mismatched and the worker_lost designs are solved again, no other.
    assert sorted(calls) == sorted([ids["radius=3"], ids["radius=4"], ids["radius=4.5"]])
    assert kept.stat().st_mtime_ns == stamp
    assert list(frame["status"]) == ["solved"] * 4
    np.testing.assert_allclose(frame[FIT].to_numpy(), serial_run[FIT].to_numpy(), rtol=1e-8)
    pd.testing.assert_frame_equal(pd.read_parquet(out / "results.parquet"), frame)
    # Everything is complete now: a third run solves nothing and gives the same table.
    calls.clear()
    again = sweeps.run(study_file, out, scheduler="none", task=counting_task(calls),
                      progress=False)
    assert calls == []
    pd.testing.assert_frame_equal(again, frame)


# --------------------------------------------------------------------------- study files
BAD_STUDIES = [
    ("colour = 1\n", "unknown key colour at the top of the file; known: base, description, "
                     "[target], [design], [solve], [sweep]"),
    ("[desing]\npanels = [8, 8]\n", "unknown table [desing]; did you mean [design]?"),
    ("[sweep]\n\"design.panel\" = [8]\n", "unknown design key panel"),
    ("[sweep]\nradius = [1.0]\n", "radius is not a parameter"),
    ("[sweep]\n\"shape.radius\" = [1.0]\n", "shape.radius is not a parameter"),
    ("[sweep]\n\"target.radius\" = [4.0, -1.0]\n", "design 'radius=-1'"),
    ("[sweep]\n\"target.radius\" = 4.0\n", "must be a non-empty list of values"),
    ("[sweep]\n\"target.radius\" = []\n", "must be a non-empty list of values"),
    ("[sweep]\n\"target.radius\" = {low = 2.0, high = 5.0}\n", "only sample = K draws"),
    ("[sweep]\n\"target.radius\" = {low = 5.0, high = 2.0}\nsample = 2\n", "low <= high"),
    ("[sweep]\n\"target.radius\" = {lo = 2.0}\nsample = 2\n", "a range is {low = a"),
    ("[sweep]\nseed = 3\n\"target.radius\" = [4.0]\n", "for the seed of the multistart"),
    ("[sweep]\nsample = 3\n\"target.radius\" = [4.0, 5.0]\n", "the grid has only 2"),
    ("[sweep]\nsample = 0\n\"target.radius\" = [4.0]\n", "sample must be a whole number"),
    ("[sweep]\n\"target.radius\" = [4.0, 4]\n", "are the same problem"),
    ("[sweep]\n\"design.layout\" = [\"zigzag\"]\n", "layout must be one of"),
    ("[sweep]\n\"design.panels\" = [5]\n", "[design] panels[0] must be an even whole number"),
    ("[solve]\nmultistarts = 3\n",
     "unknown key [solve] multistarts; did you mean multistart?"),
    ("[sweep]\n\"solve.multistart\" = [0]\n", "[solve] multistart must be a whole number"),
    ("[sweep]\n\"solve.starts\" = [1]\n", "unknown solve key starts"),
    ("[design]\nstop_rms = 0.01\n", "[design] stop_rms is a solve option: move it to the "
                                   "[solve] table"),
    ("[solve]\nstop_rms = nan\n", "[solve] stop_rms must be a finite number > 0 or None"),
    ("[sweep]\n\"design.stop_rms\" = [0.01]\n", "it is a solve option"),
    ("[sweep]\n\"design.layot\" = [\"zigzag_i\"]\n", "did you mean design.layout?"),
    ("[[sweep.cases]]\nradius = 3.0\n", "[[sweep.cases]] #1: radius is not a parameter"),
    ("[sweep]\n\"target.radius\" = [3.0]\n[[sweep.cases]]\n\"target.radius\" = 4.0\n",
     "both a [sweep] parameter and set by [[sweep.cases]] #1"),
]


@pytest.mark.parametrize("text, message", BAD_STUDIES)
def test_bad_study_files_raise_input_errors_that_say_what_to_change(text, message, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(text + "\n[target]\nname = \"sphere_cap\"\n")
    with pytest.raises(InputError) as info:
        sweeps.Study.load(path).designs()
    assert message in str(info.value)
    assert str(info.value).startswith(f"{path}: ")


def test_base_file_and_inline_tables(tmp_path):
    base = tmp_path / "targets" / "cap.toml"
    base.parent.mkdir()
    base.write_text("[target]\nname = \"sphere_cap\"\nradius = 5.0\n"
                    "[design]\npanels = [20, 20]\nlayout = \"zigzag_j\"\n")
    study = tmp_path / "studies" / "s.toml"
    study.parent.mkdir()
    study.write_text("base = \"../targets/cap.toml\"\n[design]\npanels = [8, 8]\n"
                     "[sweep]\n\"design.panels\" = [8, 12]\n"
                     "[[sweep.cases]]\nname = \"saddle\"\n\"target.name\" = \"saddle\"\n"
                     "[[sweep.cases]]\n\"target.radius\" = 3.0\n")
    with pytest.raises(InputError, match="base names a file outside the folder"):
        sweeps.Study.load(study)
    designs = sweeps.Study.load(study, trust=True).designs()
    assert [d.name for d in designs] == ["saddle panels=8", "saddle panels=12",
                                         "radius=3 panels=8", "radius=3 panels=12"]
    assert [d.case for d in designs] == ["saddle", "saddle", "", ""]
    saddle, cap = designs[0].config, designs[3].config
    # target.name starts the target afresh (no sphere radius on the saddle); other keys merge.
    assert saddle["target"] == surfaces.get("saddle").to_config()
    assert cap["target"]["radius"] == 3.0 and cap["design"]["layout"] == "zigzag_j"
    assert cap["design"]["panels"] == [12, 12] and cap["solve"] == SolveOptions().to_config()
    (tmp_path / "targets" / "cap.toml").unlink()
    with pytest.raises(InputError, match="no such design file .*relative to the study file"):
        sweeps.Study.load(study, trust=True)


@given(radii=st.lists(st.sampled_from([2.5, 3.0, 4.0, 6.0, 9.0]), min_size=1, max_size=4,
                      unique=True),
       layouts=st.lists(st.sampled_from(["zigzag_i", "zigzag_j"]), min_size=1, unique=True),
       seeds=st.lists(st.integers(0, 50), min_size=1, max_size=3, unique=True))
def test_grid_is_the_product_of_the_lists_with_stable_unique_ids(radii, layouts, seeds):
    study = sweeps.Study(base={"target": {"name": "sphere_cap"}, "design": {"panels": [8, 8]}},
                        parameters={"target.radius": radii, "design.layout": layouts,
                                    "solve.seed": seeds})
    designs = study.designs()
    assert len(designs) == len(radii) * len(layouts) * len(seeds)
    assert len({d.id for d in designs}) == len(designs)
    assert [d.id for d in designs] == [d.id for d in study.designs()]
    combos = {(d.config["target"]["radius"], d.config["design"]["layout"],
               d.config["solve"]["seed"]) for d in designs}
    assert combos == {(r, lay, s) for r in radii for lay in layouts for s in seeds}
    for d in designs:
        assert d.id == sweeps.design_id(d.config)
        assert f"radius={d.params['target.radius']:.4g}" in d.name


def test_solve_options_are_swept_under_solve():
    base = {"target": {"name": "sphere_cap"}, "design": {"panels": [8, 8]},
            "solve": {"solver": "ipopt"}}
    designs = sweeps.Study(base=base, parameters={"solve.stop_rms": [0.01, 0.02]}).designs()
    assert [d.config["solve"]["stop_rms"] for d in designs] == [0.01, 0.02]
    assert all(d.config["solve"]["solver"] == "ipopt" for d in designs)
    assert [d.name for d in designs] == ["stop_rms=0.01", "stop_rms=0.02"]


def test_random_sample_is_seeded_and_inside_its_ranges():
    base = {"target": {"name": "sphere_cap"}, "design": {"panels": [8, 8]}}
    params = {"target.radius": sweeps.Range(3.0, 6.0), "design.alpha0": sweeps.Range(0.9, 1.3),
              "solve.seed": sweeps.Range(0, 9), "design.layout": ["zigzag_i", "zigzag_j"]}
    designs = sweeps.Study(base=base, parameters=params, sample=6, seed=1).designs()
    assert len(designs) == 6
    assert [d.id for d in designs] == [
        d.id for d in sweeps.Study(base=base, parameters=params, sample=6, seed=1).designs()]
    other = sweeps.Study(base=base, parameters=params, sample=6, seed=2).designs()
    assert {d.id for d in designs}.isdisjoint(d.id for d in other)
    for d in designs:
        assert 3.0 <= d.config["target"]["radius"] <= 6.0
        assert 0.9 <= d.config["design"]["alpha0"] <= 1.3
        assert isinstance(d.config["solve"]["seed"], int) and 0 <= d.config["solve"]["seed"] <= 9
    grid = sweeps.Study(base=base, parameters={"target.radius": [3.0, 4.0, 5.0]}, sample=2)
    assert len({d.id for d in grid.designs()}) == 2
    # Whole-number bounds draw reals for real parameters; log ranges stay inside.
    logs = sweeps.Study(base=base, parameters={"target.radius": sweeps.Range(2, 20, log=True)},
                       sample=5).designs()
    radii = [d.config["target"]["radius"] for d in logs]
    assert all(2 <= r <= 20 and r != round(r) for r in radii)
    # Whole-number parameters: distinct draws, and a clear error when too few exist.
    seeds = sweeps.Study(base=base, parameters={"solve.seed": sweeps.Range(0, 9)}, sample=10)
    assert sorted(d.config["solve"]["seed"] for d in seeds.designs()) == list(range(10))
    with pytest.raises(InputError, match="only 10 distinct designs"):
        replace(seeds, sample=11).designs()


# --------------------------------------------------------------------------- multistart
def tiny() -> DesignProblem:
    return DesignProblem(surfaces.get("sphere_cap", radius=4.0), panels=(4, 4))


#: the options of the multistart tests
TINY = SolveOptions(solver="ipopt", max_iter=200)


def test_multistart_keeps_the_best_start_and_records_every_start():
    prob = tiny()
    res = prob.solve(TINY, multistart=3, seed=0)
    ms = res.stats.multistart
    assert ms["starts"] == 3 and ms["seed"] == 0 and len(ms["runs"]) == 3
    assert [(r["alpha0"], r["omega0"]) for r in ms["runs"]] == multistart_starts(prob, 3, 0)
    assert ms["runs"][0]["alpha0"] == prob.alpha0 and ms["runs"][0]["omega0"] == prob.omega0
    rms = [r["rms"] for r in ms["runs"]]
    assert all(r is not None for r in rms)
    assert ms["chosen"] == int(np.argmin(rms)) and res.fit.rms == min(rms)
    assert res.problem == prob.config(replace(TINY, multistart=3, seed=0))
    chosen = ms["runs"][ms["chosen"]]
    again = replace(prob, alpha0=chosen["alpha0"], omega0=chosen["omega0"]).solve(TINY)
    assert again.fit.rms == pytest.approx(res.fit.rms, rel=1e-9)
    for a, w in multistart_starts(prob, 20, 5):
        assert prob.min_angle < a < np.pi / 2 and prob.omega_bounds[0] < w < prob.omega_bounds[1]


def test_multistart_tolerates_failed_starts_unless_all_fail(monkeypatch):
    prob = tiny()
    real = DesignProblem.solve

    def flaky(self, options, **kw):
        if options.multistart == 1 and self.alpha0 == prob.alpha0:
            raise SolverFailed("no luck", status="Maximum_Iterations_Exceeded")
        return real(self, options, **kw)

    monkeypatch.setattr(DesignProblem, "solve", flaky)
    res = prob.solve(replace(TINY, multistart=2, seed=0))
    first, second = res.stats.multistart["runs"]
    assert res.stats.multistart["chosen"] == 1
    assert first["status"] == "Maximum_Iterations_Exceeded" and first["rms"] is None
    assert second["rms"] == res.fit.rms

    def failing(self, options, **kw):
        if options.multistart == 1:
            raise SolverFailed("no luck", status="Restoration_Failed")
        return real(self, options, **kw)

    monkeypatch.setattr(DesignProblem, "solve", failing)
    with pytest.raises(SolverFailed, match="all 3 starts of the multistart failed") as info:
        prob.solve(replace(TINY, multistart=3))
    assert info.value.status == "Restoration_Failed"

    def infeasible(self, options, **kw):
        if options.multistart == 1:
            raise InfeasibleDesign("cannot")
        return real(self, options, **kw)

    monkeypatch.setattr(DesignProblem, "solve", infeasible)
    with pytest.raises(InfeasibleDesign, match="all 2 starts"):
        prob.solve(replace(TINY, multistart=2))


def test_multistart_rejects_bad_arguments():
    prob = tiny()
    with pytest.raises(InputError, match="multistart must be a whole number"):
        prob.solve(TINY, multistart=0)
    with pytest.raises(InputError, match="seed must be a whole number"):
        prob.solve(TINY, multistart=2, seed=-1)
    with pytest.raises(InputError, match="exclude each other"):
        prob.solve(TINY, multistart=2, warm_start=object())
    with pytest.raises(InputError, match=r"unknown key \[solve\] multi_start; did you mean "
                                         r"multistart"):
        prob.solve(TINY, multi_start=2)


# --------------------------------------------------------------------------- command line
def test_cli_sweep_serial_with_multistart(tmp_path):
    study = tmp_path / "study.toml"
    study.write_text(STUDY.replace("[3.0, 3.5, 4.0, 4.5]", "[3.0, 4.0]")
                     .replace("max_iter = 200\n", "max_iter = 200\nmultistart = 2\n"))
    out = tmp_path / "out"
    res = CliRunner().invoke(app, ["sweep", str(study), "--out", str(out), "--scheduler",
                                   "none"])
    assert res.exit_code == 0, res.output
    assert "designs solved" in res.output and "best fit RMS" in res.output
    # Not a terminal: one progress line per design instead of a live bar.
    assert "[1/2] radius=3 (" in res.output and "[2/2] radius=4 (" in res.output
    frame = pd.read_csv(out / "results.csv")
    assert list(frame["status"]) == ["solved", "solved"]
    for _, row in frame.iterrows():
        result = DesignResult.load(out / "designs" / row["id"])
        assert result.stats.multistart["chosen"] == row["start"]
        assert len(result.stats.multistart["runs"]) == 2
    # The saved results are ordinary design results: the other commands take them.
    first = out / "designs" / frame["id"][0]
    res = CliRunner().invoke(app, ["export", str(first), "--format", "svg"])
    assert res.exit_code == 0, res.output
    assert (first / "crease.svg").exists()
    # A second run finds everything done.
    res = CliRunner().invoke(app, ["sweep", str(study), "--out", str(out), "--scheduler",
                                   "none"])
    assert res.exit_code == 0 and "2 of 2 designs already complete" in res.output, res.output


@pytest.mark.parametrize("args, message", [
    (["missing.toml"], "no such study file"),
    (["{bad}"], "unknown key colour at the top of the file"),
])
def test_cli_sweep_user_errors_are_one_line(args, message, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("colour = 1\n")
    args = [a.replace("{bad}", str(bad)) for a in args]
    res = CliRunner().invoke(app, ["sweep", *args, "--out", str(tmp_path / "out"),
                                   "--scheduler", "none"])
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit)
    errors = [line for line in res.output.splitlines() if "error" in line.lower()]
    assert len(errors) == 1 and message in errors[0], res.output


def test_designs_solve_withone_thread_in_every_pool_casadis_openblas_included():
    from threadpoolctl import threadpool_info

    with sweeps.one_thread():
        pools = threadpool_info()
    assert any("casadi" in pool["filepath"] for pool in pools)
    assert all(pool["num_threads"] == 1 for pool in pools)


def test_rq_sweep_is_the_run_function():
    import rffqm_nlp as rq

    assert rq.sweep is sweeps.run and rq.sweeps is sweeps
