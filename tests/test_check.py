"""Self-contact in the design flow: the fit's collision flag, ``rffqm check`` (exit 0 free,
1 not, 2 bad input) and DesignProblem.min_clearance (the distance it promises, or the
status clearance_not_met)."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rffqm_nlp as rq
from rffqm_nlp.io import foldfile
from rffqm_nlp.model import numpy_model as nm
from rffqm_nlp.cli import app
from rffqm_nlp.design.clearance import choose_axis, panel_corners
from rffqm_nlp.contact.collisions import triangle_distance
from rffqm_nlp.model.lengths import side_length_lp
from rffqm_nlp.contact.thick import thick_collisions
from rffqm_nlp.design.results import DesignResult, Fit

from helpers import fit_is_finite

TARGET = Path(__file__).resolve().parents[1] / "targets" / "sphere_cap.toml"
#: A seed of the paper's Fig. Random recipe (10 x 10, angles +-0.1 pi, LP lengths) whose
#: panels never intersect up to omega 2.5 but whose panels (6, 1) and (8, 1) come within a
#: sheet thickness of 0.003 at omega 1.56.
SEED, THICKNESS = 29, 0.003


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def problem(**changes) -> rq.DesignProblem:
    """The bundled sphere cap at 8 x 8 panels."""
    prob, _ = rq.load_design(TARGET)
    return replace(prob, panels=(8, 8), **changes)


@pytest.fixture(scope="module")
def options() -> rq.SolveOptions:
    return rq.load_design(TARGET)[1]


@pytest.fixture(scope="module")
def result(options) -> DesignResult:
    return problem().solve(options)


def min_distance(pattern: rq.Pattern, omega: float) -> float:
    """Smallest distance between two panels that share no vertex at omega, by brute force
    over every such pair and their triangles (a, c, d) and (a, d, b)."""
    Y = nm.fold(pattern, omega).reshape(-1, 3)
    corners = panel_corners(pattern.N, pattern.M)
    tri = Y[corners[:, [[0, 2, 3], [0, 3, 1]]]]                     # (P, 2, 3, 3)
    i, j = np.divmod(np.arange(pattern.N * pattern.M), pattern.M)
    p, q = np.triu_indices(len(corners), 1)
    far = np.maximum(np.abs(i[p] - i[q]), np.abs(j[p] - j[q])) >= 2
    p, q = p[far], q[far]
    A = tri[p][:, [0, 0, 1, 1]].reshape(-1, 3, 3)
    B = tri[q][:, [0, 1, 0, 1]].reshape(-1, 3, 3)
    return float(triangle_distance(A, B).min())


def random_pattern() -> rq.Pattern:
    bd = rq.perturb_angles(rq.miura_boundary(10, 10), 0.1 * np.pi, SEED)
    return nm.march(side_length_lp(bd))


# --------------------------------------------------------------------------- the fit
def test_design_is_collision_free_and_the_flag_round_trips(result, tmp_path):
    assert result.fit.collision_free is True and result.fit.first_contact_omega is None
    assert fit_is_finite(result.fit)
    path = result.save(tmp_path / "run")
    stored = json.loads(path.read_text())["fit"]
    assert stored["collision_free"] is True and stored["first_contact_omega"] is None
    back = DesignResult.load(tmp_path / "run")
    assert back.fit == result.fit and back.fit.collision_free is True


def test_fit_flag_types_are_checked():
    fit = Fit(rms=0.1, rms_surface=0.1, hausdorff=0.2, plane_rms=0.3, min_side_over_mean=0.5,
              min_sector_angle=0.4, collision_free=False, first_contact_omega=0.76)
    d = fit.to_dict()
    assert d["collision_free"] is False and d["first_contact_omega"] == 0.76
    assert Fit.from_dict(d) == fit and fit_is_finite(fit)
    with pytest.raises(rq.InputError, match="fit.collision_free must be true or false"):
        Fit.from_dict({**d, "collision_free": 1.0})
    older = Fit.from_dict({k: v for k, v in d.items()
                           if k not in ("collision_free", "first_contact_omega")})
    assert older.collision_free is None and older.first_contact_omega is None


# --------------------------------------------------------------------------- rffqm check
def test_check_a_free_design_exits_0(result, tmp_path):
    result.save(tmp_path / "run")
    res = invoke("check", tmp_path / "run")
    assert res.exit_code == 0, res.output
    assert "collision-free" in res.output and "none" in res.output


def test_check_a_fold_file_in_contact_exits_1_with_the_pairs(tmp_path):
    pat = random_pattern()
    foldfile.write_fold(tmp_path / "random.fold", pat, 2.5)
    report = rq.collisions(pat, 2.5, clearance=THICKNESS)
    assert report.pairs == [((6, 1), (8, 1))]
    assert report.first_omega == pytest.approx(1.56, abs=0.01)
    res = invoke("check", tmp_path / "random.fold", "--clearance", THICKNESS)
    assert res.exit_code == 1, res.output
    assert "(6, 1)-(8, 1)" in res.output and f"{report.first_omega:.6g}" in res.output
    assert invoke("check", tmp_path / "random.fold").exit_code == 0
    early = invoke("check", tmp_path / "random.fold", "--clearance", THICKNESS, "--omega", 1.5)
    assert early.exit_code == 0, early.output


def test_check_thick_panels_follows_the_thick_report(result, tmp_path):
    """--thickness checks rffqm make's tapered panels (contact.thick.thick_collisions): the
    verdict and first contact are the thick report's, free at a thin sheet and not at one
    as thick as a panel."""
    result.save(tmp_path / "run")
    side = float(min(result.pattern.lh.min(), result.pattern.lv.min()))
    for thickness, code in ((0.01 * side, 0), (2.0 * side, 1)):
        report = thick_collisions(result.pattern, result.omega, thickness)
        assert report.free == (code == 0)
        res = invoke("check", tmp_path / "run", "--thickness", thickness)
        assert res.exit_code == code, res.output
        assert "thick panels" in res.output and "pairs sharing a vertex" in res.output
        if report.first_omega is not None:
            assert f"{report.first_omega:.6g}" in res.output
    bad = invoke("check", tmp_path / "run", "--thickness", 0)
    assert bad.exit_code == 2 and "--thickness must be" in bad.output


@pytest.mark.parametrize("args, fragment", [
    (["missing"], "no design result"),
    (["missing.fold"], "no FOLD file"),
    (["{run}", "--clearance", "-1"], "--clearance must be a finite number >= 0, got the number -1"),
    (["{run}", "--omega", "4"], "--omega"),
])
def test_check_bad_input_exits_2_in_one_line(result, tmp_path, args, fragment):
    result.save(tmp_path / "run")
    res = invoke("check", *[a.format(run=tmp_path / "run") if a.startswith("{")
                            else (tmp_path / a if a.startswith("missing") else a)
                            for a in args])
    assert res.exit_code == 2, res.output
    errors = [ln for ln in res.output.splitlines() if "error" in ln.lower()]
    assert len(errors) == 1 and fragment in errors[0], res.output


# --------------------------------------------------------------------------- min_clearance
def test_separating_axis_of_stacked_panels_is_their_normal():
    P = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=float)
    kind, sign = choose_axis(P, P + [0.2, 0.1, 0.3])
    assert (kind, sign) in ((0, 1.0), (1, 1.0))                  # a normal, Q above P


def test_min_clearance_keeps_the_distance_it_promises(result, options):
    """... solved by Levenberg-Marquardt alone: each round's start, which its new rows
    break, restored first."""
    free = min_distance(result.pattern, result.omega)
    clearance = 1.2 * free
    kept = problem(min_clearance=clearance).solve(options)
    assert kept.stats.success
    assert min_distance(kept.pattern, kept.omega) >= clearance - 1e-6
    assert kept.problem["design"]["min_clearance"] == clearance
    assert kept.stats.marched_iterations == kept.stats.iterations
    assert kept.stats.restoration_iterations > 0


def test_impossible_min_clearance_ends_clearance_not_met(result, options):
    """Three mean sides: farther apart than two panels with one panel between them can be
    in any state."""
    with pytest.raises(rq.SolverFailed, match="min_clearance = .* is not met") as info:
        problem(min_clearance=3.0).solve(options)
    assert info.value.status == "clearance_not_met"
    assert "panels (" in str(info.value)


def test_min_clearance_is_validated():
    with pytest.raises(rq.InputError, match="min_clearance"):
        problem(min_clearance=-0.1)
    with pytest.raises(rq.InputError, match="min_clearance"):
        problem(min_clearance=float("nan"))


def test_render_marks_the_panels_in_contact_red(tmp_path):
    from rffqm_nlp.show import pictures as viz

    ok, reason = viz.rendering_available()
    assert ok, f"off-screen rendering is unavailable: {reason}"
    import imageio.v3 as iio

    pat = random_pattern()
    report = rq.collisions(pat, 2.5, clearance=THICKNESS)
    red = []
    for name, contacts in (("plain.png", None), ("marked.png", report)):
        img = iio.imread(viz.render_png(tmp_path / name, pat, report.first_omega,
                                        contacts=contacts)).astype(int)
        red.append(int((img[..., 0] - np.maximum(img[..., 1], img[..., 2]) > 80).sum()))
    assert red[0] == 0 and red[1] > 20, red             # shaded red: about (140, 0, 0)
