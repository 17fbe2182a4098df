"""The bar-and-hinge model (rq.mechanics): the exact folding velocity in the rigidity
matrix's null space and the hinges' Jacobian against the fold angles, the zero-mode counts,
the folding mode's stiffness beside the softest modes, Poisson's ratio against the Miura's
closed form, the membrane and the in-plane stiffness against closed forms, and the linear
response to loads (docs/mechanics.md)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import rffqm_nlp as rq
from rffqm_nlp.errors import InputError, MarchingError
from rffqm_nlp.mechanics import BarAndHinge, Material, Ties
from rffqm_nlp.mechanics.compatibility import fold_angles
from rffqm_nlp.mechanics.frame import build_frame
from rffqm_nlp.mechanics.modes import ZERO, rigid_motions

mc = rq.mechanics
SHEET = Material(E=1.5e9, nu=0.42, thickness=5e-4, fold_stiffness=0.5, density=905.0)
FREE = SHEET.with_fold_stiffness(0.0)


def miura(N: int, M: int, layout: str = "zigzag_j", alpha0: float = 1.1, a: float = 1.0,
          b: float = 1.3) -> rq.Pattern:
    return rq.numpy_model.march(rq.miura_boundary(N, M, a=a, b=b, alpha0=alpha0,
                                                  layout=layout))


def perturbed(N: int, M: int, amplitude: float = 0.05, seed: int = 1,
              layout: str = "zigzag_j") -> rq.Pattern:
    bd = rq.perturb_angles(rq.miura_boundary(N, M, layout=layout), amplitude * np.pi,
                           seed=seed)
    return rq.numpy_model.march(rq.lengths.side_length_lp(bd))


def exact_fold_rates(pattern: rq.Pattern, omega: float) -> np.ndarray:
    """d gamma/d omega of every interior crease in the fold hinges' order: tan(gamma/2) =
    k tan(omega/2) gives d gamma/d omega = sin(gamma)/sin(omega) (docs/mechanics.md)."""
    gh, gv = rq.numpy_model.fold_angles(pattern, omega)
    return np.concatenate([np.sin(gh[1:-1]).ravel(), np.sin(gv[:, 1:-1]).ravel()]) \
        / np.sin(omega)


def assert_velocity_exact(pattern: rq.Pattern, omega: float) -> None:
    model = BarAndHinge(pattern, omega, SHEET)
    v = model.velocity
    Rv = model.rigidity_matrix() @ v
    assert np.abs(Rv).max() <= 1e-10 * np.abs(v).max()
    assert np.linalg.norm(Rv) <= 1e-10 * np.linalg.norm(v)
    Jv = model.hinge_jacobian() @ v
    rates = exact_fold_rates(pattern, omega)
    scale = np.abs(rates).max(initial=1.0)
    assert np.abs(Jv[model.frame.bending]).max() <= 1e-9 * scale
    assert np.abs(Jv[model.frame.folds] - rates).max(initial=0.0) <= 1e-9 * scale


# --------------------------------------------------------------------------- kinematics
@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.filter_too_much])
@given(N=st.integers(1, 6), M=st.integers(1, 6), layout=st.sampled_from(["zigzag_i",
                                                                         "zigzag_j"]),
       alpha0=st.floats(0.5, 1.4), amplitude=st.sampled_from([0.0, 0.01, 0.05]),
       seed=st.integers(0, 100), omega=st.floats(0.2, 2.9), sign=st.sampled_from([1, -1]))
def test_folding_velocity_is_in_the_null_space(N, M, layout, alpha0, amplitude, seed,
                                               omega, sign):
    """||R v|| <= 1e-10 ||v|| and the hinges' rates are the exact fold-angle rates, on
    hypothesis-drawn Miuras and perturbed patterns."""
    bd = rq.miura_boundary(N, M, alpha0=alpha0, layout=layout)
    if amplitude:
        try:
            bd = rq.lengths.side_length_lp(rq.perturb_angles(bd, amplitude * np.pi, seed=seed))
            pattern = rq.numpy_model.march(bd)
        except (MarchingError, InputError):
            assume(False)
    else:
        pattern = rq.numpy_model.march(bd)
    assert_velocity_exact(pattern, sign * omega)


@pytest.mark.parametrize("pattern", [miura(40, 40), perturbed(30, 40, 0.02, seed=3)],
                         ids=["miura-40x40", "perturbed-30x40"])
def test_folding_velocity_is_in_the_null_space_of_a_larger_pattern(pattern):
    assert_velocity_exact(pattern, 1.7)


def test_velocity_agrees_with_a_finite_difference():
    """A cross-check only: the method is the fold graph's forward derivative."""
    pattern, omega, h = perturbed(6, 5, 0.03), 1.1, 1e-6
    fd = (rq.numpy_model.fold(pattern, omega + h) - rq.numpy_model.fold(pattern, omega - h)) / (2 * h)
    v = mc.folding_velocity(pattern, omega)
    assert np.abs(v - fd).max() <= 1e-7 * np.abs(v).max()


def test_hinge_jacobian_is_the_gradient_of_the_fold_angles():
    pattern = perturbed(4, 5, 0.03)
    P = rq.numpy_model.fold(pattern, 0.9).reshape(-1, 3)
    frame = build_frame(pattern.X)
    model = BarAndHinge(pattern, 0.9, SHEET)
    du = np.random.default_rng(0).normal(size=P.shape)
    h = 1e-6
    fd = (fold_angles(P + h * du, frame.hinges) - fold_angles(P - h * du, frame.hinges)) / (2 * h)
    exact = model.hinge_jacobian() @ du.ravel()
    assert np.abs(fd - exact).max() < 1e-7 * np.abs(exact).max()
    gh, gv = rq.numpy_model.fold_angles(pattern, 0.9)
    creases = np.concatenate([gh[1:-1].ravel(), gv[:, 1:-1].ravel()])
    assert np.allclose(fold_angles(P, frame.hinges)[frame.folds], creases, atol=1e-12)
    assert np.abs(fold_angles(P, frame.hinges)[frame.bending]).max() < 1e-12


def test_rigidity_matrix_layout():
    """One row per bar, three columns per vertex, vertex (i, j) at (i-1)(M+1) + (j-1)."""
    N, M = 3, 4
    model = BarAndHinge(miura(N, M), 1.0, SHEET)
    R = model.rigidity_matrix()
    bars = (N + 1) * M + N * (M + 1) + N * M
    assert R.shape == (bars, 3 * (N + 1) * (M + 1))
    # the first bar is the edge (1, 1) -> (1, 2): columns 0..2 and 3..5
    assert set(R[0].indices) == {0, 1, 2, 3, 4, 5}
    Y = rq.numpy_model.fold(model.pattern, 1.0)
    d = (Y[0, 0] - Y[0, 1]) / np.linalg.norm(Y[0, 0] - Y[0, 1])
    assert np.allclose(R[0].toarray()[0, :6], np.concatenate([d, -d]))
    # rigid motions lie in the null spaces of R and J
    rigid = rigid_motions(model.positions)
    assert np.abs(R @ rigid).max() < 1e-12
    assert np.abs(model.hinge_jacobian() @ rigid).max() < 1e-10


# --------------------------------------------------------------------------- modes
@pytest.mark.parametrize("pattern", [miura(4, 6), miura(5, 3, "zigzag_i"), perturbed(6, 6)],
                         ids=["miura", "miura-zigzag_i", "perturbed"])
def test_zero_modes_seven_free_six_with_fold_stiffness(pattern):
    for material, zeros in ((FREE, 7), (SHEET, 6)):
        model = BarAndHinge(pattern, 1.3, material, width=0.3)
        modes = model.modes(12)
        assert modes.zero_count == zeros
        dense = sl.eigvalsh(model.stiffness().toarray())
        assert np.sum(dense <= ZERO * dense.max()) == zeros
        assert np.allclose(modes.values[zeros:], dense[zeros:12], rtol=1e-8)
        assert modes.largest == pytest.approx(dense.max(), rel=1e-2)


def test_zero_modes_of_every_bundled_design():
    """The designs of targets/*.toml, solved, have seven zero modes with free hinges and six
    with fold stiffness."""
    for name in ("sphere_cap", "hyperboloid", "quarter_vase"):
        problem, options = rq.load_design(f"targets/{name}.toml")
        result = problem.solve(options)
        for material, zeros in ((FREE, 7), (SHEET, 6)):
            modes = BarAndHinge(result.pattern, result.omega, material, width=0.3).modes(10)
            assert modes.zero_count == zeros, name
            assert modes.values[zeros] > 1e3 * ZERO * modes.largest


def test_folding_mode_is_softest_where_panels_are_stiff():
    """Soft creases, stiff panels: the exact folding velocity is the softest non-rigid mode,
    its Rayleigh quotient that mode's eigenvalue (to the panels' small share)."""
    soft = Material(E=1e11, nu=0.3, thickness=2e-3, fold_stiffness=1e-3)
    modes = BarAndHinge(perturbed(7, 10), 1.3, soft, width=0.3).modes(10)
    assert modes.zero_count == 6
    assert modes.softer_than_folding == 0
    assert modes.folding == pytest.approx(modes.values[6], rel=1e-4)
    assert modes.folding_overlap == pytest.approx(1.0, abs=1e-4)


def test_a_softer_panel_bending_mode_is_reported():
    """On the 7 x 10 pattern with 5% perturbations and a polypropylene sheet, panel-bending
    modes are softer than folding: the report says so and stays consistent."""
    modes = BarAndHinge(perturbed(7, 10), 1.3, Material.named("polypropylene"),
                        width=0.3).modes(12)
    assert modes.softer_than_folding > 0
    assert modes.values[6] < modes.folding
    assert modes.folding_overlap < 0.5
    # the Rayleigh quotient bounds the softest non-rigid eigenvalue
    assert modes.folding >= modes.values[6]


# --------------------------------------------------------------------------- Poisson
def miura_poisson(omega: float, alpha0: float, layout: str) -> float:
    """Schenk & Guest's nu_SL = -cos^2(theta) tan^2(alpha0) in the paper's parametrisation
    (docs/mechanics.md): L1, L2 are N L and M S (zigzag_j, theta = |omega|/2) or N S and
    M L (zigzag_i, tan theta = tan(|omega|/2)/cos alpha0)."""
    if layout == "zigzag_j":
        theta = abs(omega) / 2
        return -1.0 / (np.cos(theta) ** 2 * np.tan(alpha0) ** 2)
    theta = np.arctan(np.tan(abs(omega) / 2) / np.cos(alpha0))
    return -np.cos(theta) ** 2 * np.tan(alpha0) ** 2


@pytest.mark.parametrize("layout", ["zigzag_j", "zigzag_i"])
@pytest.mark.parametrize("alpha0", [0.7, 1.1])
def test_miura_poisson_ratio_equals_the_closed_form(layout, alpha0):
    pattern = miura(6, 8, layout, alpha0)
    for omega in np.linspace(0.15, 3.0, 10) * np.array([1, -1] * 5):
        expected = miura_poisson(omega, alpha0, layout)
        assert mc.poisson_ratio(pattern, omega) == pytest.approx(expected, rel=1e-10)
        cells = mc.poisson_map(pattern, omega)
        assert cells.shape == (3, 4)
        assert np.allclose(cells, expected, rtol=1e-10)


def test_poisson_ratio_refuses_flat_states_and_odd_maps():
    with pytest.raises(InputError, match="strictly between"):
        mc.poisson_ratio(miura(2, 2), 0.0)
    with pytest.raises(InputError, match="even N and M"):
        mc.poisson_map(miura(3, 2), 1.0)


# --------------------------------------------------------------------------- closed forms
def test_membrane_is_exact_for_a_uniform_strain():
    """The flat sheet under a uniform in-plane strain stores (1/2) t A eps : D : eps, the
    constant-strain triangles' exact energy, and no hinge energy."""
    pattern = perturbed(4, 5, 0.03)
    model = BarAndHinge(pattern, 0.0, SHEET, width=0.2)
    strain = np.array([[1e-3, 4e-4, 0], [4e-4, -2e-3, 0], [0, 0, 0]])
    u = (model.positions @ strain.T).ravel()
    exx, eyy, gxy = strain[0, 0], strain[1, 1], 2 * strain[0, 1]
    E, nu, t = SHEET.E, SHEET.nu, SHEET.thickness
    density = E / (1 - nu ** 2) * (exx ** 2 + eyy ** 2 + 2 * nu * exx * eyy
                                   + (1 - nu) / 2 * gxy ** 2) / 2
    P, tri = model.positions, model.frame.triangles
    area = np.linalg.norm(np.cross(P[tri[:, 1]] - P[tri[:, 0]], P[tri[:, 2]] - P[tri[:, 0]]),
                          axis=1).sum() / 2
    assert 0.5 * u @ (model.stiffness() @ u) == pytest.approx(t * area * density, rel=1e-10)


def test_bending_hinge_follows_filipov_scaling():
    """k_B = 0.55 E t^3 / (12 (1 - nu^2)) (D/t)^(1/3): stiffness ~ t^(8/3) at fixed size."""
    pattern = miura(2, 2)
    stiff = [BarAndHinge(pattern, 1.0, Material(2e9, 0.3, t, 0.1), width=0.1).hinge_stiffness()
             for t in (1e-4, 8e-4)]
    bend = slice(0, 4)
    assert np.allclose(stiff[1][bend] / stiff[0][bend], 8 ** (8 / 3), rtol=1e-12)
    assert np.allclose(stiff[1][4:] / stiff[0][4:], 1.0)


def in_plane_stiffness(model: BarAndHinge, M: int) -> float:
    """The stiffness against opposite unit forces at (1, 1) and (1, M+1) along their chord,
    the rigid motions taken out (dense, small models only)."""
    K = model.stiffness().toarray()
    P = model.positions
    rigid = rigid_motions(P)
    d = (P[M] - P[0]) / np.linalg.norm(P[M] - P[0])
    f = np.zeros_like(P)
    f[0], f[M] = -d, d
    u = np.linalg.solve(K + rigid @ rigid.T * np.abs(K).max(), f.ravel()).reshape(P.shape)
    return 1.0 / ((u[M] - u[0]) @ d)


def test_in_plane_stiffness_tends_to_the_rigid_folding_closed_form():
    """As panels stiffen against creases, the stiffness against opposite forces at (1, 1)
    and (1, M+1) along their chord tends to Schenk & Guest's kappa / (dL2/domega)^2, kappa
    the sum of k_F L (d gamma/d omega)^2 over the creases, here written for the Miura
    (docs/mechanics.md); the gap falls as 1/E."""
    N, M, omega, alpha0, a, b = 4, 4, 1.2, 1.1, 1.0, 1.3
    pattern = miura(N, M, alpha0=alpha0, a=a, b=b)
    gaps = []
    for E in (1e12, 1e13):
        material = Material(E=E, nu=0.3, thickness=1e-3, fold_stiffness=0.1)
        model = BarAndHinge(pattern, omega, material, width=0.2)
        t = np.tan(omega / 2)
        straight = np.cos(alpha0) * (1 + t * t) / (1 + (np.cos(alpha0) * t) ** 2)
        kappa = material.fold_stiffness * model.scale * ((N - 1) * M * b
                                                         + N * (M - 1) * a * straight ** 2)
        zeta = np.arctan(np.cos(omega / 2) * np.tan(alpha0))
        dL2 = M * model.scale * b * np.sin(omega / 2) * np.tan(alpha0) * np.cos(zeta) ** 3 / 2
        closed = kappa / dL2 ** 2
        gaps.append(closed - in_plane_stiffness(model, M))
    assert 0 < gaps[1] < 2e-4 * closed
    assert gaps[0] / gaps[1] == pytest.approx(10, rel=0.05)


# --------------------------------------------------------------------------- loads
def test_gravity_response_is_in_equilibrium():
    """The supports carry the sheet's weight, rho t A g, and nothing sideways."""
    model = BarAndHinge(perturbed(6, 6), 1.3, SHEET, width=0.3)
    r = model.solve(gravity=True)
    P, tri = model.positions, model.frame.triangles
    area = np.linalg.norm(np.cross(P[tri[:, 1]] - P[tri[:, 0]], P[tri[:, 2]] - P[tri[:, 0]]),
                          axis=1).sum() / 2
    weight = SHEET.density * SHEET.thickness * area * 9.80665
    total = r.reactions.reshape(-1, 3).sum(axis=0)
    assert total == pytest.approx([0, 0, weight], rel=1e-8, abs=1e-9 * weight)
    assert r.largest_deflection_mm > 0
    assert np.isfinite(r.bar_strains).all() and np.isfinite(r.hinge_moments).all()


def test_maxwell_reciprocity_and_point_stiffness():
    model = BarAndHinge(perturbed(6, 6), 1.3, SHEET, width=0.3)
    a, b = (3, 4), (5, 2)
    ua = model.solve(loads=[[*a, 0, 0, -1]]).displacement
    ub = model.solve(loads=[[*b, 0, 0, -1]]).displacement
    assert ua[b[0] - 1, b[1] - 1, 2] == pytest.approx(ub[a[0] - 1, a[1] - 1, 2], rel=1e-8)
    k = model.point_stiffness(a, (0, 0, -1))
    assert k == pytest.approx(1.0 / ua[a[0] - 1, a[1] - 1, 2] * -1, rel=1e-10)


def test_prescribed_rigid_displacement_strains_nothing():
    model = BarAndHinge(miura(4, 4), 1.3, SHEET, width=0.3)
    shift = [1e-3, -2e-3, 5e-4]
    rows = [[i, j, *shift] for i, j in ((1, 1), (1, 5), (5, 1), (5, 5))]
    r = model.solve(supports=np.zeros((0, 2)), displacements=rows)
    assert np.allclose(r.displacement, shift, atol=1e-12)
    assert np.abs(r.bar_strains).max() < 1e-12


def test_ties_lock_a_free_pattern():
    """Without fold stiffness the pattern folds freely under three held vertices; a tie
    (the lock) holds it."""
    model = BarAndHinge(miura(4, 4), 1.3, FREE, width=0.3)
    held = [(1, 1), (1, 2), (2, 1)]
    with pytest.raises(InputError, match="free to fold"):
        model.solve(loads=[[5, 5, 0, 0, -1]], supports=held)
    r = model.solve(loads=[[5, 5, 0, 0, -1]], supports=held, ties=Ties([[[1, 1], [5, 5]]]))
    assert r.largest_deflection_mm > 0 and abs(r.tie_forces[0]) > 0
    with pytest.raises(InputError, match="rigidly"):
        model.solve(supports=[(1, 1)], ties=[[[1, 1], [5, 5]]])


def test_bad_arguments_are_refused_in_one_line():
    model = BarAndHinge(miura(2, 2), 1.0, SHEET)
    for call in (lambda: Material(-1.0, 0.3, 1e-3), lambda: Material(1e9, 0.6, 1e-3),
                 lambda: Material.named("steel"), lambda: BarAndHinge(miura(2, 2), 4.0, SHEET),
                 lambda: BarAndHinge(miura(2, 2), 1.0, "paper"),
                 lambda: model.solve(supports=[(0, 1), (1, 2), (2, 1)]),
                 lambda: model.solve(loads=[[1, 1, 0, 0]]),
                 lambda: model.solve(ties=[[[1, 1], [1, 1]]]),
                 lambda: model.modes(3)):
        with pytest.raises(InputError) as info:
            call()
        assert "\n" not in str(info.value)


# --------------------------------------------------------------------------- command and view
def test_command_prints_the_report_and_writes_the_view(tmp_path):
    from typer.testing import CliRunner

    from rffqm_nlp.cli.group import app
    from view_results import miura_result

    miura_result(6, 1.3).save(tmp_path / "design")
    page = tmp_path / "load.html"
    run = CliRunner().invoke(app, ["mechanics", str(tmp_path / "design"), "--load",
                                   "4,4,0,0,-1", "--view", str(page), "--thickness", "0.3"])
    assert run.exit_code == 0, run.output
    for line in ("zero modes", "folding mode stiffness", "Poisson's ratio",
                 "largest deflection (mm)", "point stiffness at (4, 4)", "largest bar strain",
                 "largest hinge moment"):
        assert line in run.output
    assert page.read_text().startswith("<!DOCTYPE html>")
    bad = CliRunner().invoke(app, ["mechanics", str(tmp_path / "design"), "--support", "1,1"])
    assert bad.exit_code == 2 and "free to move rigidly" in bad.output
    bad = CliRunner().invoke(app, ["mechanics", str(tmp_path / "design"), "--load", "1,2"])
    assert bad.exit_code == 2 and "--load takes 5" in bad.output


def test_displacement_view_slider_exaggerates_the_displacement():
    from rffqm_nlp.show import displacement
    from view_results import miura_result

    result = miura_result(4, 1.3)
    model = BarAndHinge(result.pattern, result.omega, SHEET, width=0.2)
    response = model.solve(gravity=True)
    fig = displacement.spec(result, response, model.scale)
    steps = fig["layout"]["sliders"][0]["steps"]
    Y = rq.numpy_model.fold(result.pattern, result.omega).reshape(-1, 3) \
        @ result.rotation.T + result.translation
    U = response.displacement.reshape(-1, 3) @ result.rotation.T / model.scale
    labels = [s["label"] for s in steps]
    assert "x1" in labels and labels[0] == "x0"
    top = steps[-1]["args"][0]
    moved = np.stack([top["x"][0], top["y"][0], top["z"][0]], axis=1) - Y
    factor = float(np.sum(moved * U) / np.sum(U * U))
    assert factor == pytest.approx(float(labels[-1][1:]), rel=5e-3)
    assert np.allclose(moved, factor * U, rtol=1e-9, atol=1e-12 * np.abs(moved).max())
    extent = np.ptp(Y, axis=0).max()
    assert np.linalg.norm(moved, axis=1).max() == pytest.approx(0.1 * extent, rel=1e-9)
    assert fig["data"][0]["intensity"] == pytest.approx(
        (np.linalg.norm(response.displacement.reshape(-1, 3), axis=1) * 1e3).tolist())


def test_command_locks_the_design_with_the_recommended_ties(tmp_path):
    """--lock ties the sheet with rffqm make's lock: supported at one corner only, the
    sheet's weight would fold it; locked, it holds, and the tie forces are reported."""
    from typer.testing import CliRunner

    from rffqm_nlp.cli.group import app
    from rffqm_nlp.make.lock import lock_ties
    from view_results import miura_result

    result = miura_result(6, 1.3)
    result.save(tmp_path / "design")
    args = ["mechanics", str(tmp_path / "design"), "--support", "1,1", "--support", "1,2",
            "--support", "2,1", "--fold-stiffness", "0"]
    free = CliRunner().invoke(app, args)
    assert free.exit_code == 2 and "free to fold" in free.output
    locked = CliRunner().invoke(app, [*args, "--lock"])
    assert locked.exit_code == 0, locked.output
    count = len(lock_ties(result.pattern, result.omega))
    forces = next(line for line in locked.output.splitlines() if "tie forces" in line)
    assert count >= 1 and forces.count(",") == count - 1 and "no ties" not in forces
