"""Curvature fields as targets (docs/curvature_targets.md): rq.surfaces.Curvature, its
loss and stencils, its closed form, the solve, the closed form as a method of its own,
the fit and the notes, the design file and the result file."""

from __future__ import annotations

import json
from dataclasses import replace

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rffqm_nlp as rq
from rffqm_nlp.design import curvature_fit
from rffqm_nlp.design.transcription import curvature_loss
from rffqm_nlp.design.transcription.curvature_loss import CurvatureLoss
from rffqm_nlp.errors import InfeasibleDesign, InputError, SurfaceError
from rffqm_nlp.targets import curvature_target, shape
from rffqm_nlp.targets.curvature import lattice_curvatures
from test_stencils import assembled, assert_same, casadi_jacobian

SPHERE = rq.surfaces.Curvature(K=1.0, size=(1.2, 1.2))
SADDLE = rq.surfaces.Curvature(kx=0.1, ky=-0.1, size=(10.0, 10.0))


def angle_defect_curvature(P: np.ndarray) -> np.ndarray:
    """The Gaussian curvature of a lattice P (n, m, 3) by its angle defects, at its interior
    points (n-2, m-2): 2 pi less the angles of the triangles (two per cell, grid_faces) at
    the point, over a third of their area; a discretization independent of the central
    differences of the loss (Gauss-Bonnet on the triangulated lattice)."""
    n, m, _ = P.shape
    faces = rq.surfaces.grid_faces(n, m)
    tri = P.reshape(-1, 3)[faces]
    angles, area = np.zeros(n * m), np.zeros(n * m)
    third = np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1) / 6
    for k in range(3):
        u, v = tri[:, (k + 1) % 3] - tri[:, k], tri[:, (k + 2) % 3] - tri[:, k]
        np.add.at(angles, faces[:, k], np.arctan2(np.linalg.norm(np.cross(u, v), axis=1),
                                                  np.sum(u * v, axis=1)))
        np.add.at(area, faces[:, k], third)
    return ((2 * np.pi - angles) / area).reshape(n, m)[1:-1, 1:-1]


# ---------------------------------------------------------------------------- the target
def test_a_curvature_target_takes_k_or_principal_curvatures_and_a_size():
    assert SPHERE.kind == "gaussian" and SADDLE.kind == "principal"
    for bad, words in [({"H": 1.0, "size": (1, 1)}, "takes K"),
                       ({"kx": 1.0, "size": (1, 1)}, "takes K"),
                       ({"K": 1.0, "kx": 1.0, "ky": 1.0, "size": (1, 1)}, "takes K"),
                       ({"K": 1.0}, "needs size"),
                       ({"K": 1.0, "size": (0, 1)}, "size[0] must be"),
                       ({"K": "one", "size": (1, 1)}, "K must be"),
                       ({"K": 1.0, "H": 0.5, "size": (1, 1)}, "H^2 >= K"),
                       ({"K": lambda x, y: x * np.nan, "size": (1, 1)}, "NaN"),
                       ({"K": lambda x: x, "size": (1, 1)}, "must take arrays x, y")]:
        with pytest.raises(SurfaceError, match=words.replace("^", r"\^").replace("[", r"\[")):
            rq.surfaces.Curvature(**bad)


@settings(max_examples=30, deadline=None)
@given(K=st.floats(-4, 4), excess=st.floats(0, 4), sign=st.sampled_from([-1.0, 1.0]))
def test_principal_curvatures_of_k_and_h_have_that_product_and_mean(K, excess, sign):
    """From K and H (H^2 >= K): kx ky = K and (kx + ky) / 2 = H; from K alone kx ky = K."""
    H = sign * np.sqrt(max(K, 0.0) + excess)
    kx, ky = rq.surfaces.Curvature(K=K, H=H, size=(1, 1)).principal(0.5, 0.5)
    assert kx * ky == pytest.approx(K, abs=1e-9) and (kx + ky) / 2 == pytest.approx(H)
    kx, ky = rq.surfaces.Curvature(K=K, size=(1, 1)).principal(0.5, 0.5)
    assert kx * ky == pytest.approx(K, abs=1e-12)


def test_fields_are_numbers_or_functions_of_the_footprint():
    target = rq.surfaces.Curvature(K=lambda x, y: 1 + x * y, size=(2.0, 3.0))
    x, y = target.lattice_xy(4, 6)
    assert x[-1] == 2.0 and y[-1] == 3.0 and len(x) == 5 and len(y) == 7
    assert target.gaussian(x[:, None], y[None, :])[4, 6] == pytest.approx(7.0)
    assert target.mean(1.0, 1.0) is None
    assert SADDLE.mean(0.0, 0.0) == pytest.approx(0.0)
    flat = SPHERE.lattice(2, 3)
    assert flat.shape == (3, 4, 3) and np.all(flat[..., 2] == 0) and flat[-1, -1, 0] == 1.2
    assert SPHERE.diameter() == pytest.approx(1.2 * np.sqrt(2))
    assert SPHERE.mesh(3, 3).area == pytest.approx(1.44)


@pytest.mark.parametrize("fields, verdict", [
    ({"kx": 0.1, "ky": -0.1}, False), ({"kx": 0.2, "ky": 0.2}, True),
    ({"kx": 0.1, "ky": 0.0}, True), ({"kx": lambda x, y: 0.1 + 0 * y, "ky": -0.1}, False),
    ({"kx": lambda x, y: 0.1 * y, "ky": 0.1}, None), ({"K": -1.0}, True),
    ({"K": 1.0, "H": 1.0}, True), ({"K": 0.0, "H": 0.3}, True), ({"K": 1.0, "H": 2.0}, False),
    ({"K": -1.0, "H": 0.0}, False), ({"K": lambda x, y: 1 + x}, None)])
def test_the_prescription_says_whether_a_surface_realises_it(fields, verdict):
    """Gauss and Codazzi: constant principal curvatures that differ, both nonzero, belong
    to no surface, nor do kx(x), ky(y) with kx ky != 0 that differ; constant K with H^2 =
    K or K = 0 do; varying fields are not decided by the prescription."""
    answer = rq.surfaces.Curvature(**fields, size=(1.0, 1.0)).realisable()
    assert answer.verdict is verdict and answer.reason


# ---------------------------------------------------------------------------- the loss
@settings(max_examples=40, deadline=None)
@given(E=st.floats(0.2, 3), G=st.floats(0.2, 3), cos=st.floats(-0.9, 0.9),
       II=st.tuples(*[st.floats(-2, 2)] * 3))
def test_the_symmetric_shape_operator_has_the_invariants_of_the_forms(E, G, cos, II):
    """det S = K and tr S = 2 H from the same forms, S is symmetric positive where II is,
    and S11 = L / E, S22 = N / G where F = 0."""
    F = cos * np.sqrt(E * G)
    L, M, N = II
    s11, s12, s22 = curvature_loss.shape_operator((E, F, G, L, M, N))
    det = E * G - F * F
    assert s11 * s22 - s12 ** 2 == pytest.approx((L * N - M * M) / det, abs=1e-9)
    assert s11 + s22 == pytest.approx((E * N - 2 * F * M + G * L) / det, abs=1e-9)
    s11, _, s22 = curvature_loss.shape_operator((E, 0.0, G, L, M, N))
    assert (s11, s22) == (pytest.approx(L / E), pytest.approx(N / G))


def test_the_discrete_curvatures_of_a_sphere_lattice_meet_the_loss():
    """A lattice on the unit sphere has discrete K near 1 and principal curvatures near -1
    (the cap's normal r_u x r_v points outward, away from where it bends; second order in
    the spacing): its cell rows are small, and shrink about four times when the spacing
    halves."""
    cap = rq.surfaces.get("sphere_cap", radius=1.0)
    sizes = []
    for n in (8, 16):
        lattice = cap.lattice(n, n)
        loss = CurvatureLoss.of(rq.surfaces.Curvature(kx=-1.0, ky=-1.0, size=(1.2, 1.2)), n, n,
                                {"curvature": 1.0})
        r = [lattice[..., c] for c in range(3)]
        rows = curvature_loss.cell_residuals(shape.fundamental_forms(r), loss.prescribed,
                                             loss.kind, loss.scale)
        sizes.append(max(float(np.abs(rows[k]).max()) for k in (0, 1, 4)))
    assert sizes[0] < 0.02 and sizes[1] < sizes[0] / 3


@pytest.mark.parametrize("target, weights", [
    (SPHERE, {"curvature": 1.0, "size": 1.0}), (SADDLE, {"curvature": 1.0, "size": 0.5}),
    (rq.surfaces.Curvature(K=lambda x, y: 0.5 + 0.1 * x, H=lambda x, y: 1.0 + 0 * y,
                           size=(1.5, 1.0)), {"curvature": 0.3, "size": 0.0}),
    (SADDLE, {"curvature": 0.0, "size": 1.0})])
def test_the_numpy_loss_is_the_casadi_rows(target, weights):
    """loss_value (NumPy, the closed form's choice of fold) is half the squared rows of
    curvature_residuals (CasADi) at a random lattice."""
    rng = np.random.default_rng(3)
    lattice = target.lattice(5, 4) + 0.05 * rng.standard_normal((6, 5, 3))
    loss = CurvatureLoss.of(target, 5, 4, weights)
    rows = curvature_loss.curvature_residuals([ca.DM(lattice[..., c]) for c in range(3)],
                                              loss)
    assert curvature_loss.loss_value(lattice, loss) == pytest.approx(
        0.5 * float(ca.sumsqr(rows)), rel=1e-12)


@pytest.mark.parametrize("target", [SPHERE, SADDLE, rq.surfaces.Curvature(
    K=lambda x, y: -0.01 * (1 + 0.01 * x * y), H=0.05, size=(8.0, 6.0))])
@settings(max_examples=2, deadline=None)
@given(seed=st.integers(0, 2 ** 16))
def test_the_stencil_jacobian_of_a_curvature_loss_is_casadis(target, seed):
    """The residuals' Jacobian from stencils (the cells' 3 x 3 neighbourhoods, the lines)
    has CasADi's sparsity and values at a random point near the start; g's too."""
    nlp = rq.DesignProblem(target=target, panels=(8, 6)).transcribe()
    x = nlp.x0 + 0.02 * np.random.default_rng(seed).standard_normal(nlp.x0.size)
    assert_same(assembled(nlp.r_jacobian, x), casadi_jacobian(nlp, x, "residuals"))
    assert_same(assembled(nlp.g_jacobian, x), casadi_jacobian(nlp, x))


# ---------------------------------------------------------------------------- the problem
def test_the_weights_follow_the_target_kind():
    problem = rq.DesignProblem(target=SPHERE, panels=(6, 6))
    assert set(problem.weights) == {"curvature", "size", "regularization", "smoothness"}
    surface = replace(problem, target=rq.surfaces.get("sphere_cap"))
    assert surface.weights == rq.DesignProblem(target=surface.target).weights
    with pytest.raises(InputError, match="weights position do not apply to a curvature"):
        rq.DesignProblem(target=SPHERE, weights={"position": 1.0, "curvature": 1.0})
    with pytest.raises(InputError, match="weights curvature do not apply to a surface"):
        rq.DesignProblem(target=surface.target, weights={"curvature": 1.0})
    assert problem.grid(None) is None  # no correspondence: nothing is read from the result


def test_stop_rms_is_refused_for_a_curvature_target():
    with pytest.raises(InputError, match="stop_rms"):
        rq.DesignProblem(target=SPHERE, panels=(6, 6)).solve(stop_rms=0.01)


# ---------------------------------------------------------------------------- the solve
@pytest.fixture(scope="module")
def sphere():
    """K = 1 over 1.2 x 1.2 at 12 x 12 panels: the closed form and the solve."""
    problem = rq.DesignProblem(target=SPHERE, panels=(12, 12))
    return problem, problem.solve(solver="closed-form"), problem.solve()


def test_a_constant_k_is_met_and_the_lattice_lies_on_its_sphere(sphere):
    """The solve meets K = 1 in every cell to 1e-3 (the closed form to about 6%), keeps
    the lines 1.2 long, and its Gaussian curvature by angle defects, which the loss knows
    nothing of, is 1 within the discretization's error (a lattice on the unit sphere:
    1.012 at 12 x 12 panels; K = 1 does not make a sphere: a cap bends isometrically)."""
    _, closed, solved = sphere
    assert solved.stats.success and solved.fit.curvature_rms < 1e-3
    assert solved.fit.curvature_rms < 0.05 * closed.fit.curvature_rms
    K, _ = lattice_curvatures(solved.coarse)
    assert np.abs(K - 1).max() < 2e-3
    C = solved.coarse
    along_i = np.linalg.norm(np.diff(C, axis=0), axis=-1).sum(axis=0)
    along_j = np.linalg.norm(np.diff(C, axis=1), axis=-1).sum(axis=1)
    assert np.allclose(along_i, 1.2, rtol=2e-3) and np.allclose(along_j, 1.2, rtol=2e-3)
    assert np.abs(angle_defect_curvature(C) - 1).max() < 0.035
    assert solved.fit.rms == 0 and 0.95 < solved.fit.coverage < 1.05
    assert "A surface realises this prescription" in solved.notes[0]


def test_the_closed_form_is_a_method_of_its_own(sphere):
    """solver="closed-form": no iteration, the closed form's own fold, its curvature error
    measured like any design's."""
    problem, closed, _ = sphere
    assert closed.stats.iterations == 0 and closed.stats.status == "Closed_Form"
    assert closed.stats.solver == "closed-form" and closed.omega in (
        problem.omega0, *rq.design.solvers.closed_form.prescribed.FOLDS)
    maps = curvature_fit.prescribed_maps(closed.coarse, SPHERE)
    errors = curvature_fit.cell_errors(maps, SPHERE.diameter())
    assert closed.fit.curvature_rms == pytest.approx(np.sqrt(np.mean(errors ** 2)))
    assert 0.01 < closed.fit.curvature_rms < 0.15


def test_a_saddle_that_no_surface_has_is_a_compromise_said_so():
    """kx = +0.1, ky = -0.1 (Gauss and Codazzi forbid it): the solve's K error is at most
    half the closed form's, and the notes say no surface realises it and where the error
    sits."""
    problem = rq.DesignProblem(target=SADDLE, panels=(12, 10), alpha0=1.2)
    closed = problem.solve(solver="closed-form")
    solved = problem.solve()
    assert solved.fit.curvature_rms <= 0.5 * closed.fit.curvature_rms
    note = solved.notes[0]
    assert note.startswith("No surface realises this prescription") and "lattice point" in note
    assert "Codazzi" in note and 0.9 < solved.fit.coverage < 1.1


def test_a_closed_form_that_breaks_min_length_at_every_fold_is_refused():
    problem = rq.DesignProblem(target=SPHERE, panels=(12, 12), min_length=0.9)
    with pytest.raises(InfeasibleDesign, match="min_length"):
        problem.solve(solver="closed-form")


def test_surface_designs_report_their_curvature_error_too():
    result = rq.DesignProblem(target=rq.surfaces.get("sphere_cap"), panels=(8, 8)).solve()
    maps = result.curvature
    errors = curvature_fit.cell_errors(maps, rq.surfaces.get("sphere_cap").diameter())
    assert result.fit.curvature_max == pytest.approx(np.abs(errors).max())
    assert 0 < result.fit.curvature_rms < 0.5 and result.notes == ()


# ---------------------------------------------------------------------------- files
def test_a_result_keeps_its_notes_and_curvature_errors(sphere, tmp_path):
    _, _, solved = sphere
    loaded = rq.DesignResult.load(solved.save(tmp_path))
    assert loaded.notes == solved.notes and loaded.fit == solved.fit
    d = json.loads((tmp_path / "result.json").read_text())
    older = {k: v for k, v in d.items() if k != "notes"}
    older["fit"] = {k: v for k, v in d["fit"].items() if not k.startswith("curvature_")}
    old = rq.DesignResult.from_dict(older)
    assert old.notes == () and old.fit.curvature_rms is None
    with pytest.raises(InputError, match="notes"):
        rq.DesignResult.from_dict({**d, "notes": [1.0]})


def test_a_design_file_names_a_curvature_target(tmp_path):
    (tmp_path / "field.py").write_text(
        "def saddle(x, y):\n    return 0.1 + 0 * x, -0.1 + 0 * y\n")
    (tmp_path / "saddle.toml").write_text(
        '[target]\npython = "field.py:saddle"\nfields = "kx,ky"\nsize = [10.0, 10.0]\n\n'
        "[design]\npanels = [12, 10]\nalpha0 = 1.2\n")
    with pytest.raises(SurfaceError, match="would run the Python file"):
        rq.load_design(tmp_path / "saddle.toml")
    problem, _ = rq.load_design(tmp_path / "saddle.toml", trust=True)
    assert problem.target.kind == "principal"
    assert problem.target.values(1.0, 2.0) == {"kx": pytest.approx(0.1),
                                               "ky": pytest.approx(-0.1)}
    config = problem.to_config()["target"]
    assert config["fields"] == "kx,ky" and config["python"].endswith("field.py:saddle")
    assert rq.surfaces.from_config(SPHERE.to_config()).fields == SPHERE.fields
    assert rq.surfaces.from_config({"kx": 0.1, "ky": -0.1, "size": [10, 10]}).realisable(
        ).verdict is False
    made = rq.surfaces.config_of(rq.surfaces.Curvature(K=lambda x, y: 1 + 0 * x,
                                                       size=(1, 1)))
    assert made["rebuildable"] is False
    for table, words in [({"K": 1.0}, "needs size"), ({"fields": "K", "size": [1, 1]},
                                                      "fields names"),
                         ({"python": "f.py:g", "size": [1, 1]}, "takes fields"),
                         ({"K": 1.0, "kx": 1.0, "size": [1, 1]}, "takes K")]:
        with pytest.raises(SurfaceError, match=words):
            rq.surfaces.from_config(table, root=tmp_path, trust=True)
    assert curvature_target.is_curvature_table({"K": 1.0}) and not (
        curvature_target.is_curvature_table({"name": "sphere_cap", "radius": 2.0}))


def test_a_multistart_keeps_the_start_of_the_smallest_curvature_error():
    """A curvature target's designs are their own lattices (fit.rms 0): a multistart
    compares their curvature errors instead."""
    problem = rq.DesignProblem(target=SPHERE, panels=(8, 8))
    best = problem.solve(multistart=3, seed=1)
    runs = best.stats.multistart["runs"]
    errors = [(replace(problem, alpha0=r["alpha0"], omega0=r["omega0"]).solve(
        ).fit.curvature_rms, r["start"]) for r in runs if r["rms"] is not None]
    assert len(errors) >= 2 and all(r["rms"] == 0.0 for r in runs if r["rms"] is not None)
    assert best.stats.multistart["chosen"] == min(errors)[1]
    assert best.fit.curvature_rms == min(errors)[0]


def test_the_design_command_prints_the_curvature_error_and_the_notes(tmp_path):
    from typer.testing import CliRunner

    from rffqm_nlp.cli import app

    (tmp_path / "saddle.toml").write_text(
        "[target]\nkx = 0.1\nky = -0.1\nsize = [10.0, 10.0]\n\n"
        "[design]\npanels = [8, 8]\nalpha0 = 1.2\n\n[solve]\nsolver = \"closed-form\"\n")
    run = CliRunner().invoke(app, ["design", str(tmp_path / "saddle.toml"), "--out",
                                   str(tmp_path / "out"), "--quiet"])
    assert run.exit_code == 0, run.output
    assert "curvature error: RMS, max per cell" in run.output
    assert "No surface realises this prescription" in run.output
