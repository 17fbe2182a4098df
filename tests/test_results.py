"""Result files: typed fit and statistics, the version 3 format, validation on load."""

import json
import warnings
from dataclasses import replace

import numpy as np
import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp.design import checks, results
from rffqm_nlp.cli import app
from rffqm_nlp.design.results import DesignResult, Fit, SolveStats

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
    assert json.loads((tmp_path / "run" / "result.json").read_text())["version"] == 3


def test_fit_and_stats_round_trip_through_dicts(result):
    assert Fit.from_dict(result.fit.to_dict()) == result.fit
    assert SolveStats.from_dict(result.stats.to_dict()) == result.stats
    assert [f for f in result.fit.to_dict()] == list(rq.sweeps.FIT_COLUMNS)
    with pytest.raises(rq.InputError, match="fit needs hausdorff: a finite number >= 0"):
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
    new = ("multistart", "seed", "boundary_knots", "start")  # not in version 1's [design]
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
    with pytest.raises(rq.InputError, match="version 4 is not supported"):
        DesignResult.from_dict({**data, "version": 4})


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
    (lambda c: c.pop("surface_H"), "the key 'curvature.surface_H' is missing"),
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


# --------------------------------------------------------------------------- validated whole
def test_fit_and_stats_keys_are_their_fields():
    from dataclasses import MISSING, fields

    for cls, keys in ((Fit, results.FIT_KEYS), (SolveStats, results.STATS_KEYS)):
        assert list(keys) == [f.name for f in fields(cls)]
        for f in fields(cls):
            needed = f.default is MISSING and f.default_factory is MISSING
            assert keys[f.name].required == needed, f.name


@pytest.mark.parametrize("change, message", [
    ({"rms": "nan"}, "fit.rms must be a finite number >= 0, got the string 'nan'"),
    ({"rms": float("nan")}, "fit.rms must be a finite number >= 0, got the number nan"),
    ({"hausdorff": float("inf")}, "fit.hausdorff must be a finite number"),
    ({"coverage": -0.5}, "fit.coverage must be a finite number >= 0 or None"),
    ({"min_sector_angle": 4.0}, r"fit.min_sector_angle must be a finite number in \[0, 3.14159\]"),
    ({"first_contact_omega": True}, "fit.first_contact_omega must be a finite number"),
    ({"rms": 10**400}, "fit.rms must be a finite number >= 0, got a whole number of 401 digits"),
    ({"extra": 1.0}, "unknown key fit.extra"),
])
def test_fit_from_dict_checks_every_field(result, change, message):
    with pytest.raises(rq.InputError, match=message):
        Fit.from_dict({**result.fit.to_dict(), **change})


@pytest.mark.parametrize("change, message", [
    ({"iterations": -1}, "stats.iterations must be a whole number >= 0, got the whole number -1"),
    ({"iterations": 2.0}, "stats.iterations must be a whole number"),
    ({"build_time": float("nan")}, "stats.build_time must be a finite number >= 0"),
    ({"objective": "0.1"}, "stats.objective must be a finite number, got the string"),
    ({"success": "true"}, "stats.success must be true or false"),
    ({"solver": 5}, "stats.solver must be a string, got the whole number 5"),
    ({"start_moved": 2.0}, r"stats.start_moved must be a finite number in \[0, 1\]"),
    ({"history": {"iter": [0], "objective": [float("inf")], "inf_pr": [0.0],
                  "elapsed": [0.0]}}, r"stats.history.objective\[0\] must be a finite number"),
    ({"history": {"iter": [0], "objective": [1.0], "inf_pr": [0.0]}},
     "stats.history needs elapsed"),
    ({"multistart": {"starts": 2, "seed": 0, "chosen": 3, "time": 1.0, "runs": []}},
     "stats.multistart.chosen must be the number of one of its 0 runs"),
    ({"multistart": 5}, "stats.multistart must be a table of starts, seed, chosen"),
])
def test_stats_from_dict_checks_every_field(result, change, message):
    with pytest.raises(rq.InputError, match=message):
        SolveStats.from_dict({**result.stats.to_dict(), **change})


def test_a_multistart_record_round_trips_and_is_checked(tmp_path):
    problem = rq.DesignProblem(rq.surfaces.get("sphere_cap", radius=4.0), panels=(4, 4))
    res = problem.solve(rq.SolveOptions(stop_rms=0.05, multistart=2))
    record = res.stats.multistart
    assert record is not None and len(record["runs"]) == 2
    back = DesignResult.load(res.save(tmp_path / "run"))
    assert back.stats == res.stats and back.stats.multistart == record
    data = res.to_dict()
    data["stats"]["multistart"]["runs"][0]["alpha0"] = "1.2"
    with pytest.raises(rq.InputError, match=r"stats.multistart.runs\[0\].alpha0 must be a "
                                            "finite number"):
        DesignResult.load(saved(tmp_path, data))


def test_an_aligned_fold_of_a_zero_rotation_is_refused(result, tmp_path):
    """A zero rotation with its folded state (every vertex at the translation) once loaded,
    and ``rffqm fold --aligned`` put every vertex at one point."""
    data = result.to_dict()
    data["rotation"] = np.zeros((3, 3)).tolist()
    data["folded"] = np.broadcast_to(result.translation, result.folded.shape).tolist()
    folder = saved(tmp_path, data)
    with pytest.raises(rq.InputError, match="rotation must be a rotation matrix"):
        DesignResult.load(folder)
    res = CliRunner().invoke(app, ["fold", str(folder), "--omega", "1.0", "--aligned"])
    assert res.exit_code == 2, res.output
    errors = [line for line in res.output.splitlines() if line.strip()]
    assert len(errors) == 1 and "rotation must be a rotation matrix" in errors[0], res.output


def test_a_result_whose_re_march_overflows_is_refused(tmp_path):
    """Side lengths near the largest float: the stored arrays are finite, the re-marched
    flat positions overflow; nothing infinite may be compared (inf > inf is False) or
    loaded, and no warning is printed."""
    bd = rq.miura_boundary(2, 2, a=1e308, b=1e308)
    unit = rq.numpy_model.march(rq.miura_boundary(2, 2))    # lengths and X scale with a, b
    pattern = {**unit.to_dict(), "lh": (unit.lh * 1e308).tolist(),
               "lv": (unit.lv * 1e308).tolist(), "X": np.zeros((3, 3, 3)).tolist()}
    data = {"format": results.FORMAT, "version": results.VERSION, "omega": 1.0,
            "boundary": bd.to_dict(), "pattern": pattern, "folded": np.zeros((3, 3, 3)).tolist(),
            "target_points": np.zeros((2, 2, 3)).tolist(), "rotation": np.eye(3).tolist(),
            "translation": [0.0, 0.0, 0.0], "x": []}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(rq.InputError, match="pattern(.X)? cannot be recomputed in "
                                                "floating point"):
            DesignResult.load(saved(tmp_path, data))


def test_check_numbers_names_the_place_and_never_the_content():
    checks.check_numbers({"a": [1, 2.5, "text", None, True], "b": {"c": 10**300}}, "f.json")
    with pytest.raises(rq.InputError, match=r"^f\.json: b\.c holds NaN or inf \(at b\.c\[1\]\)"):
        checks.check_numbers({"a": [1.0], "b": {"c": [0.0, float("-inf")]}}, "f.json")
    with pytest.raises(rq.InputError, match=r"\(a name of 5000 characters\) holds a whole "
                                            "number of 400 digits"):
        checks.check_numbers({"Q" * 5000: int("9" * 400)}, "f.json")
    with pytest.raises(rq.InputError, match=r"x holds NaN or inf \(at x\[1\]\[0\]\)"):
        checks.check_numbers({"x": np.array([[0.0, 1.0], [np.nan, 2.0]])}, "f.json")
    deep = current = []
    for _ in range(5000):                     # deeper than Python's recursion limit
        current.append([])
        current = current[0]
    current.append(float("nan"))
    with pytest.raises(rq.InputError, match="the value holds NaN or inf"):
        checks.check_numbers(deep, "f.json")
