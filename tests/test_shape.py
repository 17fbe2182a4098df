"""Tests of the discrete shape measures: coarse-graining, finite-difference fundamental forms
(NumPy and CasADi), rigid alignment and distances to a surface."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

import rffqm_nlp as rq
from rffqm_nlp.errors import InputError

S, sh = rq.surfaces, rq.shape


def random_lattice(n=7, m=9, seed=1):
    """A smooth sheet plus noise: a generic lattice with a well-defined normal."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    P = np.stack([i, j, 0.1 * (i - 3) ** 2 - 0.05 * i * j], axis=-1).astype(float)
    return P + 0.1 * rng.standard_normal(P.shape)


def casadi_eval(fun, P, kind=ca.MX):
    """Evaluate ``fun`` on the components of P through a CasADi Function of symbols."""
    n, m, _ = P.shape
    xyz = [kind.sym(c, n, m) for c in "xyz"]
    out = fun(xyz)
    out = list(out) if isinstance(out, tuple) else [out]
    flat = [o for part in out for o in (part if isinstance(part, tuple) else (part,))]
    f = ca.Function("f", xyz, flat)
    return [np.array(r) for r in f(*(P[..., k] for k in range(3)))]


def numpy_flat(result):
    parts = result if isinstance(result, tuple) else (result,)
    flat = []
    for part in parts:
        flat += [part[..., k] for k in range(3)] if part.ndim == 3 else [part]
    return flat


def test_coarse_grain_takes_even_vertices():
    Y = np.arange(5 * 7 * 3, dtype=float).reshape(5, 7, 3)
    r = sh.coarse_grain(Y)
    assert r.shape == (3, 4, 3)
    np.testing.assert_array_equal(r[1, 2], Y[2, 4])
    _, y, _ = sh.coarse_grain([Y[..., 0], ca.DM(Y[..., 1]), Y[..., 2]])
    np.testing.assert_array_equal(np.array(y), Y[::2, ::2, 1])
    with pytest.raises(InputError, match="odd sizes"):
        sh.coarse_grain(np.zeros((4, 5, 3)))


def test_discrete_forms_of_a_plane_lattice():
    i, j = np.meshgrid(np.arange(5.0), np.arange(4.0), indexing="ij")
    P = np.stack([2 * i, 3 * j, 0 * i], -1)
    E, F, G, L, M, N = sh.fundamental_forms(P, hu=2.0, hv=0.5)
    assert E.shape == (3, 2)
    np.testing.assert_allclose(E, 1.0)
    np.testing.assert_allclose(G, 36.0)
    for form in (F, L, M, N):
        np.testing.assert_array_equal(form, 0.0)
    with pytest.raises(InputError, match="at least 3 x 3"):
        sh.fundamental_forms(P[:2])


def test_discrete_forms_converge_at_second_order_at_a_point():
    ell = S.get("ellipsoid_cap")  # a, b, c distinct: F and M are not zero
    u0, v0 = 0.13, 0.21
    exact = np.array(ell.fundamental_forms(u0, v0))
    hs = np.array([0.08, 0.04, 0.02, 0.01])
    errors = []
    for h in hs:
        hu, hv = h, 1.5 * h  # unequal spacings
        P = ell.point(u0 + hu * np.arange(-1, 2)[:, None], v0 + hv * np.arange(-1, 2)[None, :])
        errors.append(np.abs([f[0, 0] for f in sh.fundamental_forms(P, hu, hv)] - exact))
    slopes = np.polyfit(np.log(hs), np.log(np.array(errors)), 1)[0]
    assert np.all((slopes > 1.9) & (slopes < 2.1)), slopes


def test_discrete_forms_converge_at_second_order_on_lattices():
    torus = S.get("torus_patch")
    hs, errors = [], []
    for n in (9, 17, 33, 65):
        u, v = torus.lattice_uv(n - 1, n - 1)
        P = torus.lattice(n - 1, n - 1)
        exact = torus.fundamental_forms(u[1:-1, None], v[None, 1:-1])
        discrete = sh.fundamental_forms(P, u[1] - u[0], v[1] - v[0])
        errors.append(max(np.abs(d - e).max() for d, e in zip(discrete, exact)))
        hs.append(u[1] - u[0])
    slope = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.8 < slope < 2.2, slope


@pytest.mark.parametrize("kind", [ca.MX, ca.SX])
@pytest.mark.parametrize("fun", [
    lambda P: sh.fundamental_forms(P, 0.7, 1.3), sh.coarse_grain])
def test_casadi_path_equals_numpy_path(fun, kind):
    P = random_lattice()
    expected = numpy_flat(fun(P))
    got = casadi_eval(fun, P, kind)
    assert len(got) == len(expected)
    for g, e in zip(got, expected):
        assert g.shape == e.shape
        np.testing.assert_allclose(g, e, rtol=1e-14, atol=1e-14)


def test_neighbour_distances_see_parity_offsets_that_central_forms_miss():
    """docs/paper.md s.8: shifting one parity class sideways barely changes the central
    forms, while the neighbour distances change at first order."""
    P = S.get("plane").lattice(8, 8)
    Q = P.copy()
    Q[::2, ::2, 0] += 1e-3
    forms = np.abs(np.array(sh.fundamental_forms(Q)) - np.array(sh.fundamental_forms(P)))
    lengths = np.abs(np.linalg.norm(np.diff(Q, axis=0), axis=-1)
                     - np.linalg.norm(np.diff(P, axis=0), axis=-1))
    assert forms.max() < 1e-12 and lengths.max() > 9e-4


def test_bad_lattices_raise_input_error():
    with pytest.raises(InputError, match=r"\(n, m, 3\)"):
        sh.coarse_grain(np.zeros((3, 3, 2)))
    with pytest.raises(InputError, match="three 2-D matrices of one shape"):
        sh.coarse_grain([np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, 4))])


@pytest.mark.parametrize("call, words", [
    (lambda: sh.fundamental_forms(np.zeros((3, 3, 3))), "^fundamental_forms has no finite "
                                                         "value: the lattice is degenerate"),
    (lambda: sh.fundamental_forms(random_lattice(), hu=0.0), r"^hu must be a finite number > 0"),
    (lambda: sh.fundamental_forms(random_lattice(), hv="1"), r"^hv must be a finite number > 0"),
    (lambda: sh.coarse_grain(np.full((3, 3, 3), np.nan)), "^the lattice must be an .* got nan"),
    (lambda: sh.coarse_grain(None), "^a lattice must be an .* got None"),
    (lambda: sh.kabsch(np.zeros((0, 3)), np.zeros((0, 3))), r"^P must be finite points .* at "
                                                            r"least one, got shape \(0, 3\)"),
    (lambda: sh.kabsch("points", np.zeros((2, 3))), "^P must be finite points"),
    (lambda: sh.kabsch(np.full((2, 3), 1e200) * [[1], [-1]], np.zeros((2, 3))),
     "^kabsch: the points are too large"),
    (lambda: sh.kabsch(np.eye(3), np.eye(3), reflection="yes"), "^reflection must be true"),
    (lambda: sh.rms_distance(np.full((1, 3), 1e300), np.full((1, 3), -1e300)),
     "^the distances overflow"),
    (lambda: sh.hausdorff_distance(np.zeros((0, 3)), np.zeros((2, 3))), "^points must be"),
    (lambda: sh.lattice_area(np.full((2, 2, 3), 1e200) * np.arange(2)[:, None, None]),
     "^lattice_area overflows"),
    (lambda: sh.surface_area("sphere_cap"), "^target must be a surface"),
    (lambda: sh.shape_fit(np.zeros((3, 3, 3)), None), "^target must be a surface"),
    (lambda: sh.distances_to(np.zeros((2, 3)), {"points": 1}), "^target points must be"),
])
def test_shape_measures_refuse_bad_arguments_and_non_finite_results(call, words):
    """No shape measure returns NaN or infinity: a degenerate lattice, an empty point set
    or coordinates whose products overflow are InputErrors (SurfaceError for a target that
    is no surface), in one line."""
    with pytest.raises(InputError, match=words) as exc:
        call()
    assert "\n" not in str(exc.value)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kabsch_recovers_rotation_and_reflection(seed):
    rng = np.random.default_rng(seed)
    P = random_lattice(5, 6, seed)
    R = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(size=3) * 5
    R_hat, t_hat, rms = sh.kabsch(P, P @ R.T + t)
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    np.testing.assert_allclose(t_hat, t, atol=1e-12)
    assert rms < 1e-12
    aligned = sh.align(P, P @ R.T + t)
    assert aligned.shape == P.shape
    np.testing.assert_allclose(aligned, P @ R.T + t, atol=1e-12)

    mirror = R @ np.diag([1.0, 1.0, -1.0])
    Q = P @ mirror.T + t
    R_hat, t_hat, rms = sh.kabsch(P, Q, reflection=True)
    np.testing.assert_allclose(R_hat, mirror, atol=1e-12)
    np.testing.assert_allclose(t_hat, t, atol=1e-12)
    assert rms < 1e-12
    R_rot, _, rms_rot = sh.kabsch(P, Q)
    assert np.linalg.det(R_rot) == pytest.approx(1.0) and rms_rot > 0.1


def test_kabsch_on_points_and_component_triples():
    P = random_lattice(4, 4).reshape(-1, 3)
    R = Rotation.from_rotvec([0.3, -0.2, 0.9]).as_matrix()
    R_hat, _, _ = sh.kabsch(P, P @ R.T)
    np.testing.assert_allclose(R_hat, R, atol=1e-12)
    L = random_lattice(4, 4)
    aligned = sh.align([L[..., k] for k in range(3)], L @ R.T)
    np.testing.assert_allclose(aligned, L @ R.T, atol=1e-12)
    with pytest.raises(InputError, match="corresponding points"):
        sh.kabsch(P, P[:-1])


@pytest.mark.parametrize("name", ["sphere_cap", "hyperboloid", "torus_patch", "quarter_vase"])
def test_distances_vanish_on_the_surface_and_measure_normal_offsets(name):
    surface = S.get(name)
    rng = np.random.default_rng(3)
    (u0, u1), (v0, v1) = surface.domain
    # random (not grid) parameters, away from the boundary so offsets project back
    u = u0 + (u1 - u0) * rng.uniform(0.1, 0.9, (6, 7))
    v = v0 + (v1 - v0) * rng.uniform(0.1, 0.9, (6, 7))
    on = surface.point(u, v)
    fit = sh.relative_fit(on, surface)
    assert fit["rms"] < 1e-6 and fit["hausdorff"] < 1e-6
    assert sh.rms_distance(on, surface) < 1e-12
    for offset in (0.05, -0.1):
        off = on + offset * surface.normal(u, v)
        assert sh.rms_distance(off, surface) == pytest.approx(abs(offset), rel=1e-9)
        assert sh.hausdorff_distance(off, surface) == pytest.approx(abs(offset), rel=1e-9)
    uv, closest, dist = surface.closest_points(on + 0.05 * surface.normal(u, v))
    np.testing.assert_allclose(uv, np.stack([u, v], -1), atol=1e-9)
    np.testing.assert_allclose(dist, 0.05, rtol=1e-9)


def test_distance_to_a_point_beyond_the_domain_edge():
    plane = S.get("plane")  # (-2, 2)^2 in z = 0
    d = sh.hausdorff_distance(np.array([[3.0, 0.5, 4.0]]), plane)
    assert d == pytest.approx(np.hypot(1.0, 4.0), rel=1e-12)
    d = sh.hausdorff_distance(np.array([[3.0, -5.0, 0.0]]), plane)
    assert d == pytest.approx(np.hypot(1.0, 3.0), rel=1e-12)


def test_point_set_distances():
    A = random_lattice(3, 4).reshape(-1, 3)
    far = A[0] + np.array([0.0, 0.0, 7.0])
    B = np.vstack([A, far])
    assert sh.rms_distance(A, B) == 0.0
    assert sh.hausdorff_distance(A, B) == pytest.approx(np.min(np.linalg.norm(A - far, axis=1)))
    assert sh.hausdorff_distance(B, A) == sh.hausdorff_distance(A, B)
    fit = sh.relative_fit(B, A)
    diameter = max(np.linalg.norm(p - q) for p in A for q in A)
    assert fit["hausdorff"] == pytest.approx(sh.hausdorff_distance(B, A) / diameter)
    assert fit["rms"] == pytest.approx(sh.rms_distance(B, A) / diameter)


# -- areas and fits against the shape -------------------------------------------------------


def test_lattice_area_of_a_flat_sheet_and_a_bent_one():
    u, v = np.meshgrid(np.linspace(0, 3, 4), np.linspace(0, 2, 5), indexing="ij")
    flat = np.stack([u, v, np.zeros_like(u)], -1)
    assert sh.lattice_area(flat) == pytest.approx(6.0, rel=1e-14)
    # a sheet bent along its diagonal: the two triangles of a cell are counted separately
    cell = np.array([[[0, 0, 0], [0, 1, 0]], [[1, 0, 0], [1, 1, 1]]], dtype=float)
    assert sh.lattice_area(cell) == pytest.approx(2 * 0.5 * np.sqrt(2), rel=1e-14)
    with pytest.raises(InputError, match=r"\(n, m, 3\) lattice"):
        sh.lattice_area(flat.reshape(-1, 3))


@pytest.mark.parametrize("name", ["sphere_cap", "hyperboloid", "torus_patch", "plane"])
def test_surface_area_agrees_with_a_fine_mesh(name):
    surface = S.get(name)
    assert sh.surface_area(surface) == pytest.approx(surface.mesh(801, 801).area, rel=2e-5)


def test_sphere_cap_area_is_exact():
    """The gnomonic cap over (-a, a)^2 is a spherical quadrilateral (its sides are great
    circles): area R^2 (sum of its four corner angles - 2 pi)."""
    R, a = 4.0, 0.6
    cap = S.get("sphere_cap", radius=R, domain=[[-a, a], [-a, a]])
    corners = cap.point(np.array([-a, a, a, -a]), np.array([-a, -a, a, a])) / R
    angles = []
    for k in range(4):
        p, q, s = corners[k], corners[k - 1], corners[(k + 1) % 4]
        t1, t2 = q - np.dot(q, p) * p, s - np.dot(s, p) * p
        angles.append(np.arccos(np.dot(t1, t2) / np.linalg.norm(t1) / np.linalg.norm(t2)))
    assert sh.surface_area(cap) == pytest.approx(R ** 2 * (sum(angles) - 2 * np.pi), rel=1e-10)


def test_shape_fit_of_the_surface_itself_and_of_an_offset():
    surface = S.get("sphere_cap")
    (u0, u1), (v0, v1) = surface.domain
    u, v = np.linspace(u0, u1, 17), np.linspace(v0, v1, 13)
    on = surface.point(u[:, None], v[None, :])
    fit = sh.shape_fit(on, surface)
    assert max(fit["rms_surface"], fit["hausdorff"], fit["rms_surface_vertices"],
               fit["hausdorff_vertices"]) < 1e-9
    coverage = sh.lattice_area(on[::2, ::2]) / sh.surface_area(surface)
    assert fit["coverage"] == pytest.approx(coverage)
    assert 0.99 < fit["coverage"] < 1.0  # the chords of a convex cap cut it short
    # the coarse lattice on the surface, the fine vertices in between lifted off it
    off = on + 0.02 * surface.normal(u[:, None], v[None, :])
    off[::2, ::2] = on[::2, ::2]
    fit = sh.shape_fit(off, surface)
    assert fit["rms_surface"] < 1e-9
    assert fit["hausdorff_vertices"] == pytest.approx(0.02 / surface.diameter(), rel=1e-6)
    share = 1 - (9 * 7) / (17 * 13)
    assert fit["rms_surface_vertices"] == pytest.approx(
        np.sqrt(share) * 0.02 / surface.diameter(), rel=1e-6)


def test_distances_to_keep_the_points_shape_for_surfaces_and_point_sets():
    plane = rq.surfaces.get("plane")
    lattice = plane.lattice(3, 4) + np.array([0.0, 0.0, 0.25])
    np.testing.assert_allclose(rq.shape.distances_to(lattice, plane), np.full((4, 5), 0.25),
                               atol=1e-12)
    cloud = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    points = np.array([[[0.2, 0.0, 0.0], [1.0, 0.5, 0.0]]])
    np.testing.assert_allclose(rq.shape.distances_to(points, cloud), [[0.2, 0.5]], atol=1e-15)


def reference_closest(surface, p: np.ndarray) -> tuple[np.ndarray, float]:
    """The closest point of ``surface`` to p (3,) found independently: the nearest of a
    401 x 401 sample, then scipy's bounded least squares on r(u, v) - p to its tightest
    tolerances. Returns (u, v) and the distance."""
    from scipy.optimize import least_squares

    u, v = surface.grid_uv(401, 401)
    sample = surface.sample(401, 401).reshape(-1, 3)
    k = int(np.argmin(np.linalg.norm(sample - p, axis=1)))
    (u0, u1), (v0, v1) = surface.domain
    fit = least_squares(lambda x: surface.point(x[0], x[1]) - p, [u[k // 401], v[k % 401]],
                        jac=lambda x: np.stack(surface.derivatives(x[0], x[1]), axis=1),
                        bounds=([u0, v0], [u1, v1]), xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return fit.x, float(np.linalg.norm(surface.point(*fit.x) - p))


@settings(max_examples=40, deadline=None)
@given(st.sampled_from(["sphere_cap", "hyperboloid", "torus_patch", "quarter_vase", "saddle",
                        "gaussian_bump"]),
       st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(-0.05, 0.05),
       st.floats(-0.03, 0.03), st.floats(-0.03, 0.03))
def test_closest_points_agree_with_an_independent_projection(name, a, b, normal, du, dv):
    """A point off the surface (a normal offset up to 5% of the diameter and a tangential
    one, anywhere over the domain, its edges included): the closest point is no farther
    than the one of a dense sample refined by scipy's least squares (to round-off; scipy
    may stop short of it, not beyond), and the first-order conditions hold to round-off
    (the gradient of the distance vanishes along every parameter not held on a bound)."""
    surface = S.get(name)
    (u0, u1), (v0, v1) = surface.domain
    u, v = u0 + a * (u1 - u0), v0 + b * (v1 - v0)
    diameter = surface.diameter()
    r_u, r_v = surface.derivatives(u, v)
    p = (surface.point(u, v) + normal * diameter * surface.normal(u, v)
         + diameter * (du * r_u / np.linalg.norm(r_u) + dv * r_v / np.linalg.norm(r_v)))
    uv, closest, dist = surface.closest_points(p)
    _, expected = reference_closest(surface, p)
    assert expected - 1e-8 * diameter <= dist <= expected + 1e-12 * diameter
    assert dist == pytest.approx(np.linalg.norm(closest - p), abs=1e-15 * diameter)
    np.testing.assert_allclose(closest, surface.point(*uv), atol=1e-14 * diameter)
    e = closest - p
    for k, (t, lo, hi) in enumerate(zip(surface.derivatives(*uv), (u0, v0), (u1, v1))):
        if lo < uv[k] < hi:
            assert abs(e @ t) <= 1e-13 * diameter * np.linalg.norm(t)
