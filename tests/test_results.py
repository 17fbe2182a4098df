"""Result files: typed fit and statistics, the version 2 format, validation on load."""

import json
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp import results
from rffqm_nlp.cli import app
from rffqm_nlp.results import DesignResult, Fit, SolveStats

from helpers import fit_is_finite


@pytest.fixture(scope="module")
def result() -> DesignResult:
    problem = rq.DesignProblem(rq.surfaces.get("sphere_cap", radius=4.0), panels=(4, 6))
    return problem.solve(rq.SolveOptions(stop_rms=0.05))


def saved(tmp_path, data: dict):
    """``data`` written as result.json (NaN allowed, as a foreign writer might) in a folder."""
    (tmp_path / "result.json").write_text(json.dumps(data))
    return tmp_path


def test_round_trip_keeps_every_field(result, tmp_path):
    back = DesignResult.load(result.save(tmp_path / "run"))
    assert isinstance(back.fit, Fit) and isinstance(back.stats, SolveStats)
    assert back.fit == result.fit and back.stats == result.stats
    assert back.problem == result.problem and set(back.problem) == {"target", "design", "solve"}
    assert back.omega == result.omega
    for name in ("folded", "target_points", "rotation", "translation", "x"):
        np.testing.assert_array_equal(getattr(back, name), getattr(result, name))
    np.testing.assert_array_equal(back.pattern.X, result.pattern.X)
    assert json.loads((tmp_path / "run" / "result.json").read_text())["version"] == 2


def test_fit_and_stats_round_trip_through_dicts(result):
    assert Fit.from_dict(result.fit.to_dict()) == result.fit
    assert SolveStats.from_dict(result.stats.to_dict()) == result.stats
    assert [f for f in result.fit.to_dict()] == list(rq.sweeps.FIT_COLUMNS)
    with pytest.raises(rq.InputError, match="'hausdorff' is missing"):
        Fit.from_dict({k: v for k, v in result.fit.to_dict().items() if k != "hausdorff"})


def test_shape_fits_are_measured_and_optional_in_older_files(result):
    fit = result.fit
    assert fit.rms_surface_vertices is not None and fit.hausdorff_vertices is not None
    assert 0 < fit.rms_surface_vertices <= fit.hausdorff_vertices
    assert 0.5 < fit.coverage < 1.5
    new = ("rms_surface_vertices", "hausdorff_vertices", "coverage")
    older = Fit.from_dict({k: v for k, v in fit.to_dict().items() if k not in new})
    assert older.coverage is None and fit_is_finite(older)
    assert older.to_dict()["coverage"] is None and Fit.from_dict(older.to_dict()) == older
    assert not fit_is_finite(replace(fit, coverage=float("inf")))


def test_nan_in_the_pattern_is_refused_naming_the_key(result, tmp_path):
    data = result.to_dict()
    data["pattern"]["X"][1][2][0] = float("nan")
    with pytest.raises(rq.InputError, match=r"pattern\.X holds NaN or inf"):
        DesignResult.load(saved(tmp_path, data))


def test_inf_in_the_boundary_data_is_refused(result, tmp_path):
    data = result.to_dict()
    data["boundary"]["l_left"][0] = float("inf")
    with pytest.raises(rq.InputError, match=r"boundary\.l_left holds NaN or inf"):
        DesignResult.load(saved(tmp_path, data))


@pytest.mark.parametrize("key, cut, message", [
    ("folded", lambda a: a[:-1], r"folded has shape \(4, 7, 3\), expected \(5, 7, 3\)"),
    ("pattern.lh", lambda a: [a[0][:-1]] + a[1:], r"pattern\.lh must be a rectangular array"),
    ("pattern.mu", lambda a: [row[:-1] for row in a], r"pattern\.mu has shape \(4, 5\)"),
    ("target_points", lambda a: [row[:-1] for row in a],
     r"target_points has shape \(3, 3, 3\), expected \(3, 4, 3\)"),
    ("rotation", lambda a: a[:2], r"rotation has shape \(2, 3\)"),
])
def test_cut_arrays_and_wrong_shapes_are_refused(result, tmp_path, key, cut, message):
    data = result.to_dict()
    *parents, name = key.split(".")
    holder = data[parents[0]] if parents else data
    holder[name] = cut(holder[name])
    with pytest.raises(rq.InputError, match=message):
        DesignResult.load(saved(tmp_path, data))


def test_a_tampered_pattern_value_is_refused(result, tmp_path):
    data = result.to_dict()
    data["pattern"]["alpha"][2][3] += 1e-6
    with pytest.raises(rq.InputError, match=r"pattern\.alpha does not match its boundary data "
                                            "re-marched"):
        DesignResult.load(saved(tmp_path, data))


def test_a_tampered_folded_state_is_refused(result, tmp_path):
    data = result.to_dict()
    data["folded"][1][1][2] += 1e-6
    with pytest.raises(rq.InputError, match="folded does not match the pattern folded at omega"):
        DesignResult.load(saved(tmp_path, data))
    data = result.to_dict()
    data["translation"][0] += 1e-3
    with pytest.raises(rq.InputError, match="folded does not match"):
        DesignResult.load(saved(tmp_path, data))


def test_version_1_is_migrated_its_solve_keys_moved_from_design(result, tmp_path):
    data = result.to_dict()
    design = {**data["problem"]["design"], **data["problem"]["solve"]}
    new = ("multistart", "seed", "boundary_knots")  # not in version 1's [design]
    for key in new:
        del design[key]
    v1 = {**data, "version": 1, "problem": {"target": data["problem"]["target"],
                                            "design": design}}
    migrated = results.migrate_v1(v1)
    assert migrated["version"] == 2
    assert migrated["problem"]["design"] == data["problem"]["design"]
    assert migrated["problem"]["solve"] == {k: v for k, v in data["problem"]["solve"].items()
                                            if k not in new}
    back = DesignResult.load(saved(tmp_path, v1))
    assert back.problem == migrated["problem"] and back.fit == result.fit
    problem, options = rq.design.from_config(back.problem)
    assert options.solver == result.stats.solver and options.stop_rms == 0.05
    with pytest.raises(rq.InputError, match="version 3 is not supported"):
        DesignResult.from_dict({**data, "version": 3})


def test_save_refuses_nan_and_writes_nothing(result, tmp_path):
    bad = replace(result, fit=replace(result.fit, rms=float("nan")))
    with pytest.raises(rq.InputError, match="fit.rms"):
        bad.save(tmp_path / "run")
    assert not (tmp_path / "run" / "result.json").exists()


def test_cli_refuses_a_broken_result_with_exit_2_and_one_line(result, tmp_path):
    data = result.to_dict()
    data["pattern"]["lv"][0][0] = float("nan")
    folder = saved(tmp_path, data)
    res = CliRunner().invoke(app, ["fold", str(folder), "--omega", "1.0"])
    assert res.exit_code == 2, res.output
    errors = [line for line in res.output.splitlines() if line.strip()]
    assert len(errors) == 1 and "pattern.lv holds NaN or inf" in errors[0], res.output


def test_curvature_maps_round_trip(result, tmp_path):
    maps = result.curvature
    assert maps is not None and maps.design_K.shape == (1, 2)  # interior of the 3 x 4 lattice
    back = DesignResult.load(result.save(tmp_path / "run"))
    for name, value in vars(maps).items():
        np.testing.assert_array_equal(getattr(back.curvature, name), value)
    assert back.target_grid is None  # a built-in target: the config rebuilds it


@pytest.mark.parametrize("change, message", [
    (lambda c: c.update(target_H=[[0.1]]),
     r"curvature\.target_H has shape \(1, 1\), expected \(1, 2\)"),
    (lambda c: c["design_K"][0].__setitem__(1, float("nan")), r"curvature\.design_K holds NaN"),
    (lambda c: c.pop("surface_H"), "'surface_H' is missing"),
])
def test_broken_curvature_maps_are_refused(result, tmp_path, change, message):
    data = result.to_dict()
    change(data["curvature"])
    with pytest.raises(rq.InputError, match=message):
        DesignResult.load(saved(tmp_path, data))


def test_a_result_without_curvature_maps_loads(result, tmp_path):
    data = result.to_dict()
    del data["curvature"]
    assert DesignResult.load(saved(tmp_path, data)).curvature is None


def test_a_broken_target_grid_is_refused(result, tmp_path):
    data = result.to_dict()
    data["target_grid"] = [[[0.0, 0.0, 0.0]]]
    with pytest.raises(rq.InputError, match=r"target_grid has shape \(1, 1, 3\)"):
        DesignResult.load(saved(tmp_path, data))


def test_a_result_displays_its_view_in_a_notebook(result):
    html = result._repr_html_()
    assert html.startswith('<div id="rffqm-view-') and 'class="rffqm-view"' in html
    assert "Plotly.newPlot(div" in html
    figure = result.view(frames=4)
    assert [trace.type for trace in figure.data] == ["mesh3d", "scatter3d", "scatter3d",
                                                     "scatter3d", "mesh3d"]
    assert len(figure.layout.sliders[0].steps) == 5


def test_target_mesh_of_a_rebuilt_surface_a_kept_grid_and_a_mesh(result):
    surface = rq.surfaces.from_config(result.problem["target"])
    rebuilt = results.target_mesh(result, n=9)
    assert len(rebuilt.vertices) == 81 and len(rebuilt.faces) == 2 * 8 * 8
    assert rq.shape.distances_to(rebuilt.vertices, surface).max() < 1e-9
    grid = surface.sample(5, 7)
    kept = results.target_mesh(replace(result, target_grid=grid))
    np.testing.assert_array_equal(kept.vertices, grid.reshape(-1, 3))
    assert len(kept.faces) == 2 * 4 * 6
    mesh = rq.surfaces.Mesh(rq.surfaces.get("plane").mesh(11, 11))
    np.testing.assert_array_equal(results.target_mesh(result, target=mesh).faces,
                                  mesh.mesh.faces)


def test_target_mesh_of_a_target_that_cannot_be_rebuilt_is_refused(result):
    code = {"python": "math:sqrt", "domain": [[-1.0, 1.0], [-1.0, 1.0]]}
    with pytest.raises(rq.RffqmError, match="pass --trust"):
        results.target_mesh(replace(result, problem={**result.problem, "target": code}))
    with pytest.raises(rq.InputError, match=r"no \[target\] table"):
        results.target_mesh(replace(result, problem={}))
