"""The closed-form alternating perturbation (docs/closed_form.md) against the exact model:
the march keeps its angles, its fold angles, the curvature per gradient of each
perturbation, the designs for prescribed curvatures, the separable approximation of a
target and the start of a design problem."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import rffqm_nlp as rq
from rffqm_nlp.design.solvers import closed_form as cf
from rffqm_nlp.errors import InfeasibleDesign, InputError
from rffqm_nlp.model import numpy_model
from rffqm_nlp.model.boundary import BoundaryData, miura_boundary
from rffqm_nlp.targets import shape


def alternating(rows: int, cols: int, alpha0: float, delta: np.ndarray,
                ratio: np.ndarray | None = None) -> BoundaryData:
    """The alternating perturbation in the layout "zigzag_j", written out by hand: vertex
    (i, j) gets (theta_j + s_i delta_j, theta_j - s_i delta_j, -1), the even rows' straight
    sides ``ratio`` (rows / 2,) times the odd rows', every side 1 otherwise."""
    i, j = np.arange(rows + 1), np.arange(cols + 1)
    theta = np.where(j % 2 == 0, alpha0, np.pi - alpha0)
    s = np.where(i % 2 == 0, 1.0, -1.0)
    alpha = theta[None, :] + s[:, None] * delta[None, :]
    beta = theta[None, :] - s[:, None] * delta[None, :]
    left = np.column_stack([alpha[:, 0], beta[:, 0], -np.ones(rows + 1)])
    bottom = np.column_stack([alpha[0, 1:], beta[0, 1:], -np.ones(cols)])
    sides = np.ones(rows)
    if ratio is not None:
        sides[1::2] = ratio
    return BoundaryData(left, bottom, sides, np.ones(cols))


def lattice(bd: BoundaryData, omega: float) -> np.ndarray:
    """The folded coarse lattice (N+1, M+1, 3)."""
    return shape.coarse_grain(numpy_model.fold(numpy_model.march(bd), omega))


def along(P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The discrete normal curvatures along i and along j at the interior points."""
    E, _, G, L, _, N = shape.fundamental_forms(P)
    return L / E, N / G


def test_the_march_keeps_the_alternating_angles():
    delta = 0.3 * np.sin(np.linspace(0, 2, 11))
    pat = numpy_model.march(alternating(8, 10, 1.1, delta))
    theta = np.where(np.arange(11) % 2 == 0, 1.1, np.pi - 1.1)
    s = np.where(np.arange(9) % 2 == 0, 1.0, -1.0)[:, None]
    assert np.allclose(pat.alpha, theta + s * delta, atol=1e-12)
    assert np.allclose(pat.beta, theta - s * delta, atol=1e-12)
    assert np.all(pat.sigma == -1)


def test_fold_angles_of_the_alternating_pattern():
    """Zig-zag creases fold by +-omega; the straight creases at column j by
    tan(|gamma| / 2) = tan(omega / 2) cos(alpha0) / cos(delta_j) (eq:foldAngMult)."""
    delta = np.linspace(-0.2, 0.3, 9)
    omega = 1.7
    gamma_h, gamma_v = numpy_model.fold_angles(numpy_model.march(alternating(6, 8, 1.1, delta)),
                                               omega)
    assert np.allclose(np.abs(gamma_h[1:-1]), omega, atol=1e-12)
    expected = np.tan(omega / 2) * np.cos(1.1) / np.cos(delta[1:-1])
    assert np.allclose(np.tan(np.abs(gamma_v[:, 1:-1]) / 2), expected, atol=1e-12)


@pytest.mark.parametrize("delta0, omega", [(0.0, 1.2), (0.25, 1.2), (0.0, 2.4), (-0.4, 2.4)])
def test_zigzag_gain_is_the_marched_curvature(delta0, omega):
    """kx = G(delta) d(delta)/dX along the zig-zag direction, exact in delta."""
    slope = 1e-4                                  # d(delta) per column
    delta = delta0 + slope * (np.arange(17) - 8)
    _, k_j = along(lattice(alternating(4, 16, 1.1, delta), omega))
    gain, column = cf.zigzag_gain(delta0, 1.1, omega)
    assert k_j[0, 3] * column / slope == pytest.approx(gain, rel=1e-3)


@pytest.mark.parametrize("delta, omega", [(0.0, 1.2), (0.3, 2.4)])
def test_straight_gain_is_the_marched_curvature(delta, omega):
    """ky = P(Delta) d(Delta)/dY along the straight direction (its first line exact)."""
    ratio = 1 + 0.3 + 1e-4 * (np.arange(8) - 4)    # Delta = 0.3 in the middle
    k_i, _ = along(lattice(alternating(16, 4, 1.1, np.full(5, delta), ratio), omega))
    gain, period = cf.straight_gain(0.3, delta, 1.1, omega)
    assert k_i[3, 0] * period / 1e-4 == pytest.approx(gain, rel=1e-3)


@pytest.mark.parametrize("alpha0, omega", [(1.1, 2.0), (0.6, 0.9), (1.45, 2.9)])
def test_first_order_gains_in_closed_form(alpha0, omega):
    g0, p0 = cf.first_order_gains(alpha0, omega)
    assert g0 == pytest.approx(float(cf.zigzag_gain(0.0, alpha0, omega)[0]), rel=1e-12)
    assert p0 == pytest.approx(float(cf.straight_gain(0.0, 0.0, alpha0, omega)[0]), rel=1e-12)


@pytest.mark.parametrize("layout", ["zigzag_i", "zigzag_j"])
@pytest.mark.parametrize("kx, ky", [(0.08, 0.0), (0.0, 0.08)])
def test_constant_curvature_converges_with_the_panels(layout, kx, ky):
    """A constant curvature along one direction: the discrete curvature of the folded
    lattice along the line where the relations are exact (along i the first interior
    column, along j the first interior row) converges to it at second order; everywhere it
    stays within 2%."""
    errors = []
    for n in (8, 16, 32):
        design = cf.closed_form_boundary(kx, ky, panels=(n, n), size=(4.0, 3.0), layout=layout)
        k_i, k_j = along(lattice(design.boundary, design.omega))
        err = np.abs(k_i - kx) + np.abs(k_j - ky)
        assert err.max() <= 0.02 * 0.08
        errors.append(err[:, 0].max() if kx else err[0, :].max())
    assert errors[2] < errors[1] < errors[0] and errors[2] < errors[0] / 8


@pytest.mark.parametrize("omega", [2.0, -2.0])
def test_curvatures_keep_their_signs(omega):
    for layout in ("zigzag_i", "zigzag_j"):
        design = cf.closed_form_boundary(0.05, -0.03, panels=(16, 16), size=(3.0, 3.0),
                                         layout=layout, omega=omega)
        k_i, k_j = along(lattice(design.boundary, omega))
        assert np.allclose(k_i, 0.05, atol=2e-3) and np.allclose(k_j, -0.03, atol=2e-3)


@pytest.mark.parametrize("layout", ["zigzag_i", "zigzag_j"])
def test_zero_curvature_is_the_miura_ori(layout):
    design = cf.closed_form_boundary(0.0, 0.0, panels=(6, 8), size=(3.0, 4.0), alpha0=1.0,
                                     layout=layout, omega=1.7)
    miura = miura_boundary(6, 8, 1.0, 1.0, 1.0, layout)
    bd = design.boundary
    assert np.array_equal(bd.left, miura.left) and np.array_equal(bd.bottom, miura.bottom)
    assert np.ptp(bd.l_left) < 1e-12 and np.ptp(bd.l_bottom) < 1e-12
    assert np.all(design.delta == 0) and np.all(design.Delta == 0)
    P = lattice(bd, 1.7)
    assert np.allclose(np.linalg.norm(P[1:] - P[:-1], axis=-1), 1.0)
    assert np.allclose(np.linalg.norm(P[:, 1:] - P[:, :-1], axis=-1), 1.0)


def test_transposed_is_the_mirrored_pattern():
    design = cf.closed_form_boundary(0.05, 0.02, panels=(6, 10), size=(3.0, 4.0),
                                     layout="zigzag_j")
    bd = design.boundary
    mirrored = cf.transposed(bd)
    assert mirrored.N == bd.M and mirrored.M == bd.N
    again = cf.transposed(mirrored)
    assert np.allclose(again.left, bd.left) and np.allclose(again.l_left, bd.l_left)
    a, b = numpy_model.march(bd), numpy_model.march(mirrored)
    assert np.allclose(b.alpha, a.alpha.T) and np.allclose(b.beta, np.pi - a.beta.T)
    assert np.allclose(b.lh, a.lv.T)


def test_separable_fields_are_kept_exactly():
    kx, ky = np.linspace(-0.2, 0.3, 5), np.cos(np.arange(7.0))
    sep = cf.separable_curvatures(np.repeat(kx[:, None], 7, 1), np.repeat(ky[None, :], 5, 0))
    assert np.allclose(sep.kx, kx) and np.allclose(sep.ky, ky) and sep.residual < 1e-15


def test_separable_approximation_is_least_squares():
    rng = np.random.default_rng(1)
    k_u, k_v = rng.normal(size=(5, 7)), rng.normal(size=(5, 7))
    sep = cf.separable_curvatures(k_u, k_v)
    assert np.allclose((k_u - sep.kx[:, None]).sum(axis=1), 0)     # normal equations
    assert np.allclose((k_v - sep.ky[None, :]).sum(axis=0), 0)
    assert 0 < sep.residual < 1


def test_curvatures_along_the_lattice_of_a_sphere():
    k_u, k_v = cf.curvatures_along_lattice(rq.surfaces.get("sphere_cap", radius=2.0), 4, 6)
    assert k_u.shape == k_v.shape == (5, 7)
    assert np.allclose(k_u, -0.5) and np.allclose(k_v, -0.5)   # the normal r_u x r_v points out


def test_the_start_of_the_sphere_cap_fits_far_better_than_the_miura():
    problem = rq.DesignProblem(target=rq.surfaces.get("sphere_cap"), panels=(32, 32))
    miura, start = problem.start(), cf.closed_form_start(problem)
    assert np.array_equal(start.target_points, miura.target_points)
    assert start.spacing == miura.spacing and start.omega == problem.omega0

    def fits(s):
        folded = numpy_model.fold(numpy_model.march(s.boundary), s.omega)
        coarse = shape.coarse_grain(folded) @ s.rotation.T + s.translation
        rms = np.sqrt(np.mean(np.sum((coarse - s.target_points) ** 2, axis=-1)))
        return rms, shape.rms_distance(coarse, problem.target)

    (lattice_cf, surface_cf), (lattice_miura, surface_miura) = fits(start), fits(miura)
    assert surface_cf < 0.4 * surface_miura and lattice_cf < lattice_miura


@settings(max_examples=15, deadline=None)
@given(kx=st.floats(-0.025, 0.025), slope=st.floats(-0.005, 0.005), ky=st.floats(-0.025, 0.025),
       n=st.integers(1, 8), m=st.integers(1, 8), layout=st.sampled_from(["zigzag_i", "zigzag_j"]),
       omega=st.floats(1.8, 2.8))
def test_small_curvatures_march(kx, slope, ky, n, m, layout, omega):
    design = cf.closed_form_boundary(lambda x: kx + slope * x, ky, panels=(2 * n, 2 * m),
                                     size=(4.0, 4.0), layout=layout, omega=omega)
    folded = numpy_model.fold(numpy_model.march(design.boundary), design.omega)
    assert np.all(np.isfinite(folded))


@pytest.mark.parametrize("kwargs", [dict(omega=0.0), dict(panels=(5, 4)), dict(kx="0.1"),
                                    dict(size=(0.0, 1.0)), dict(steps=([1.0], [1.0, 1.0])),
                                    dict(layout="diagonal"), dict(kx=lambda x: x * np.nan),
                                    dict(kx=[[], [0.0]])])
def test_bad_arguments_are_refused(kwargs):
    args = {**dict(kx=0.01, ky=0.0, panels=(4, 4), size=(1.0, 1.0)), **kwargs}
    kx, ky = args.pop("kx"), args.pop("ky")
    with pytest.raises(InputError):
        cf.closed_form_boundary(kx, ky, **args)


def test_too_much_curvature_is_infeasible():
    with pytest.raises(InfeasibleDesign, match="larger omega"):
        cf.closed_form_boundary(2.0, 0.0, panels=(8, 8), size=(4.0, 4.0))


@pytest.mark.parametrize("call", [
    lambda: cf.closed_form_start(None), lambda: cf.closed_form_design("sphere_cap"),
    lambda: cf.transposed(None), lambda: cf.zigzag_fold("2", 1.1, 0.0),
    lambda: cf.zigzag_fold(2.0, 1.1, 1.2), lambda: cf.zigzag_gain(1.2, 1.1, 2.0),
    lambda: cf.straight_gain(-1.0, 0.0, 1.1, 2.0), lambda: cf.first_order_gains(1.1, 0.0),
    lambda: cf.separable_curvatures(np.zeros((0, 3)), np.zeros((0, 3))),
    lambda: cf.lattice_steps(np.zeros((1, 4, 3))),
    lambda: cf.curvatures_along_lattice("sphere_cap", 2, 2)])
def test_the_other_public_functions_refuse_bad_arguments(call):
    with pytest.raises(InputError):
        call()
