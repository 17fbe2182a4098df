"""Tests of the parametric-surface library: curvatures against closed forms, lattices,
meshes, custom surfaces, TOML targets and input validation."""

from __future__ import annotations

import math
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import rffqm_nlp as rq
from rffqm_nlp.errors import InputError, SurfaceError

S = rq.surfaces
TARGETS = Path(__file__).resolve().parents[1] / "targets"
TOL = dict(rtol=1e-10, atol=1e-12)
BUILTINS = ["sphere_cap", "hyperboloid", "quarter_vase", "saddle", "cylinder", "paraboloid",
            "ellipsoid_cap", "torus_patch", "gaussian_bump", "plane"]


def random_uv(surface, n=200, seed=0):
    rng = np.random.default_rng(seed)
    (u0, u1), (v0, v1) = surface.domain
    return rng.uniform(u0, u1, n), rng.uniform(v0, v1, n)


def graph_curvatures(fx, fy, fxx, fxy, fyy):
    """K and H of the graph (u, v, f(u, v)) with normal (-fx, -fy, 1)/w."""
    w2 = 1 + fx**2 + fy**2
    K = (fxx * fyy - fxy**2) / w2**2
    H = ((1 + fy**2) * fxx - 2 * fx * fy * fxy + (1 + fx**2) * fyy) / (2 * w2**1.5)
    return K, H


def revolution_curvatures(rho, d1, d2):
    """K and |H| of the surface of revolution with profile radius rho(z)."""
    K = -d2 / (rho * (1 + d1**2) ** 2)
    H = np.abs(1 / (rho * np.sqrt(1 + d1**2)) - d2 / (1 + d1**2) ** 1.5) / 2
    return K, H


def test_names_lists_all_builtins():
    assert S.names() == BUILTINS


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_defaults_are_regular_and_sized(name):
    surface = S.get(name)
    assert surface.name == name and 2 <= surface.diameter() <= 10
    u, v = random_uv(surface, 50)
    r_u, r_v = surface.derivatives(u, v)
    n = surface.normal(u, v)
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(np.sum(n * r_u, -1), 0.0, atol=1e-13)
    np.testing.assert_allclose(np.sum(n * r_v, -1), 0.0, atol=1e-13)
    E, F, G, L, M, N = surface.fundamental_forms(u, v)
    np.testing.assert_allclose(E, np.sum(r_u * r_u, -1), **TOL)
    np.testing.assert_allclose(F, np.sum(r_u * r_v, -1), **TOL)
    np.testing.assert_allclose(G, np.sum(r_v * r_v, -1), **TOL)


def test_sphere_cap_curvatures_and_outward_normal():
    R = 2.7
    cap = S.get("sphere_cap", radius=R)
    u, v = random_uv(cap)
    p = cap.point(u, v)
    np.testing.assert_allclose(np.linalg.norm(p, axis=-1), R, **TOL)
    np.testing.assert_allclose(cap.normal(u, v), p / R, **TOL)
    np.testing.assert_allclose(cap.gaussian_curvature(u, v), 1 / R**2, **TOL)
    # documented sign convention: H < 0 where the surface bends away from n
    np.testing.assert_allclose(cap.mean_curvature(u, v), -1 / R, **TOL)


def test_cylinder_curvatures():
    cyl = S.get("cylinder", radius=1.7)
    u, v = random_uv(cyl)
    np.testing.assert_allclose(cyl.gaussian_curvature(u, v), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.abs(cyl.mean_curvature(u, v)), 1 / (2 * 1.7), **TOL)


def test_torus_curvatures_and_sign_change():
    R, r = 5.0, 1.2
    torus = S.get("torus_patch", R=R, r=r)
    u, v = random_uv(torus)
    np.testing.assert_allclose(torus.gaussian_curvature(u, v),
                               np.cos(v) / (r * (R + r * np.cos(v))), **TOL)
    np.testing.assert_allclose(np.abs(torus.mean_curvature(u, v)),
                               (R + 2 * r * np.cos(v)) / (2 * r * (R + r * np.cos(v))), **TOL)
    K = S.get("torus_patch").gaussian_curvature(*np.meshgrid(*S.get("torus_patch").grid_uv(9, 9)))
    assert K.min() < -0.05 and K.max() > 0.05


def test_ellipsoid_cap_curvatures():
    a, b, c = 3.0, 4.0, 2.5
    ell = S.get("ellipsoid_cap", a=a, b=b, c=c)
    u, v = random_uv(ell)
    x, y, z = np.moveaxis(ell.point(u, v), -1, 0)
    np.testing.assert_allclose(x**2 / a**2 + y**2 / b**2 + z**2 / c**2, 1.0, **TOL)
    q = x**2 / a**4 + y**2 / b**4 + z**2 / c**4
    np.testing.assert_allclose(ell.gaussian_curvature(u, v), 1 / (a * b * c) ** 2 / q**2, **TOL)
    H = np.abs(x**2 + y**2 + z**2 - a**2 - b**2 - c**2) / (2 * (a * b * c) ** 2 * q**1.5)
    np.testing.assert_allclose(np.abs(ell.mean_curvature(u, v)), H, **TOL)


def test_hyperboloid_curvatures_negative_everywhere():
    a, b, c = 1.5, 2.5, 1.8
    hyp = S.get("hyperboloid", a=a, b=b, c=c)
    u, v = random_uv(hyp)
    x, y, z = np.moveaxis(hyp.point(u, v), -1, 0)
    q = x**2 / a**4 + y**2 / b**4 + z**2 / c**4
    np.testing.assert_allclose(hyp.gaussian_curvature(u, v), -1 / (a * b * c) ** 2 / q**2, **TOL)
    # circular one: a surface of revolution with rho(z) = a sqrt(1 + z^2/c^2)
    circ = S.get("hyperboloid", a=2.0, b=2.0, c=1.5)
    z = circ.point(u, v)[..., 2]
    s = 1 + z**2 / 1.5**2
    K, H = revolution_curvatures(2.0 * np.sqrt(s), 2.0 * z / (1.5**2 * np.sqrt(s)),
                                 2.0 / (1.5**2 * s**1.5))
    np.testing.assert_allclose(circ.gaussian_curvature(u, v), K, **TOL)
    np.testing.assert_allclose(np.abs(circ.mean_curvature(u, v)), H, **TOL)
    uu, vv = np.meshgrid(*hyp.grid_uv(21, 21))
    assert np.all(hyp.gaussian_curvature(uu, vv) < 0)


def test_quarter_vase_curvatures_change_sign():
    R0, A, lam = 2.0, 0.5, 8.0
    vase = S.get("quarter_vase", radius=R0, amplitude=A, wavelength=lam)
    u, v = random_uv(vase)
    k = 2 * math.pi / lam
    K, H = revolution_curvatures(R0 + A * np.sin(k * u), A * k * np.cos(k * u),
                                 -A * k**2 * np.sin(k * u))
    np.testing.assert_allclose(vase.gaussian_curvature(u, v), K, **TOL)
    np.testing.assert_allclose(np.abs(vase.mean_curvature(u, v)), H, **TOL)
    uu, vv = np.meshgrid(*vase.grid_uv(21, 21), indexing="ij")
    K = vase.gaussian_curvature(uu, vv)
    assert K.min() < -0.05 and K.max() > 0.05
    assert np.all(K[uu < -0.1] < 0) and np.all(K[uu > 0.1] > 0)  # K ~ sin(2 pi z / lambda)


@pytest.mark.parametrize("name, f", [
    ("paraboloid", lambda u, v: (u / 3, v / 5, 1 / 3 + 0 * u, 0 * u, 1 / 5 + 0 * u)),
    ("saddle", lambda u, v: (u / 3, -v / 5, 1 / 3 + 0 * u, 0 * u, -1 / 5 + 0 * u)),
    ("gaussian_bump", lambda u, v: _bump_derivatives(u, v, 1.3, 0.9)),
])
def test_graph_surfaces_signed_curvatures(name, f):
    params = {"paraboloid": dict(a=3.0, b=5.0), "saddle": dict(a=3.0, b=5.0),
              "gaussian_bump": dict(height=1.3, width=0.9)}[name]
    surface = S.get(name, **params)
    u, v = random_uv(surface)
    K, H = graph_curvatures(*f(u, v))
    np.testing.assert_allclose(surface.gaussian_curvature(u, v), K, **TOL)
    np.testing.assert_allclose(surface.mean_curvature(u, v), H, **TOL)


def _bump_derivatives(u, v, h, w):
    f = h * np.exp(-(u**2 + v**2) / (2 * w**2))
    return (-u / w**2 * f, -v / w**2 * f, (u**2 / w**4 - 1 / w**2) * f, u * v / w**4 * f,
            (v**2 / w**4 - 1 / w**2) * f)


def test_plane_is_flat():
    plane = S.get("plane")
    u, v = random_uv(plane)
    for form in plane.fundamental_forms(u, v)[3:]:
        np.testing.assert_array_equal(form, 0.0)
    np.testing.assert_array_equal(plane.gaussian_curvature(u, v), 0.0)


def test_point_broadcasts_and_matches_sample():
    cap = S.get("sphere_cap")
    assert cap.point(0.1, 0.2).shape == (3,)
    assert cap.point(np.zeros(4)[:, None], np.zeros(5)).shape == (4, 5, 3)
    assert cap.fundamental_forms(np.zeros(4)[:, None], np.zeros(5))[0].shape == (4, 5)
    u, v = cap.grid_uv(6, 7)
    np.testing.assert_array_equal(cap.sample(6, 7), cap.point(u[:, None], v[None, :]))
    np.testing.assert_array_equal(cap.lattice(5, 6), cap.sample(6, 7))
    np.testing.assert_allclose(cap.point(0.0, 0.0), [0.0, 0.0, 4.0], **TOL)


def test_casadi_function_is_usable_in_graphs():
    cap = S.get("sphere_cap", radius=2.0)
    u = ca.MX.sym("u")
    g = ca.Function("g", [u], [ca.jacobian(ca.sumsqr(cap.casadi_function()(u, 0.3)), u)])
    assert abs(float(g(0.4))) < 1e-12  # |r| = R on the whole sphere


def test_mesh_is_consistently_oriented():
    torus = S.get("torus_patch")
    mesh = torus.mesh(8, 11)
    assert mesh.vertices.shape == (88, 3) and mesh.faces.shape == (2 * 7 * 10, 3)
    np.testing.assert_array_equal(mesh.vertices, torus.sample(8, 11).reshape(-1, 3))
    centres = mesh.triangles.mean(axis=1)
    uv = torus.closest_points(centres)[0]
    normals = torus.normal(uv[:, 0], uv[:, 1])
    assert np.all(np.sum(mesh.face_normals * normals, axis=1) > 0.9)


def test_diameter_of_cap_and_plane():
    cap = S.get("sphere_cap")
    corners = cap.point(np.array([0.6, -0.6]), np.array([0.6, -0.6]))
    assert cap.diameter() == pytest.approx(np.linalg.norm(corners[0] - corners[1]), rel=1e-12)
    assert S.get("plane").diameter() == pytest.approx(4 * math.sqrt(2), rel=1e-12)


@settings(max_examples=40, deadline=None)
@given(n=st.integers(2, 400), shape=st.sampled_from(["ball", "sphere", "flat", "line"]),
       seed=st.integers(0, 2**32 - 1))
def test_point_set_diameter_is_the_largest_pairwise_distance(n, shape, seed):
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3)) * rng.uniform(0.1, 10, size=3)
    if shape == "sphere":  # every point a hull vertex, as on a convex cap
        pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    elif shape == "flat":
        pts[:, 2] = 0.0
    elif shape == "line":
        pts = np.outer(rng.normal(size=n), rng.normal(size=3)) + rng.normal(size=3)
    brute = np.linalg.norm(pts[:, None] - pts[None], axis=-1).max()
    assert S.point_set_diameter(pts) == pytest.approx(brute, rel=1e-12, abs=1e-300)


@pytest.mark.parametrize("name, spacing", [("sphere_cap", (0.31, 0.27)),
                                           ("hyperboloid", (0.2, 0.35)),
                                           ("quarter_vase", (0.25, 0.25))])
def test_lattice_with_spacing_has_requested_mean_distances(name, spacing):
    surface = S.get(name)
    N, M = 8, 6
    u, v = surface.lattice_uv(N, M, spacing)
    (u0, u1), (v0, v1) = surface.domain
    assert u.shape == (N + 1,) and v.shape == (M + 1,)
    assert (u[0] + u[-1]) / 2 == pytest.approx((u0 + u1) / 2, abs=1e-12)
    assert (v[0] + v[-1]) / 2 == pytest.approx((v0 + v1) / 2, abs=1e-12)
    assert u0 <= u[0] and u[-1] <= u1 and v0 <= v[0] and v[-1] <= v1
    d_i, d_j = S.mean_neighbour_distances(surface.lattice(N, M, spacing))
    assert d_i == pytest.approx(spacing[0], abs=1e-8)
    assert d_j == pytest.approx(spacing[1], abs=1e-8)


def test_lattice_spacing_too_large_says_what_fits():
    cap = S.get("sphere_cap")
    with pytest.raises(SurfaceError, match=r"holds a 10 x 10 lattice .* up to \(0\.4"):
        cap.lattice(10, 10, spacing=(1.0, 0.2))


def test_custom_surface_curvature_and_callable_forms():
    mine = S.Custom(lambda u, v: (u, v, 0.1 * u * v), ((-1, 1), (-1, 1)))
    u, v = random_uv(mine)
    K, H = graph_curvatures(0.1 * v, 0.1 * u, 0 * u, 0.1 + 0 * u, 0 * u)
    np.testing.assert_allclose(mine.gaussian_curvature(u, v), K, **TOL)
    np.testing.assert_allclose(mine.mean_curvature(u, v), H, **TOL)
    assert mine.name == "custom" and mine.params == {}
    # a 3-vector result and mathlib work too
    vec = S.Custom(lambda u, v: ca.vertcat(u, v, S.mathlib(u).sin(u)), ((0, 1), (0, 1)), "vec")
    np.testing.assert_allclose(vec.point(0.5, 0.2), [0.5, 0.2, math.sin(0.5)], **TOL)


def test_custom_surface_errors():
    with pytest.raises(SurfaceError, match="three scalars"):
        S.Custom(lambda u, v: (u, v), ((0, 1), (0, 1)))
    with pytest.raises(SurfaceError, match="three scalars"):
        S.Custom(lambda u, v: (u, v, ca.vertcat(u, v)), ((0, 1), (0, 1)))
    with pytest.raises(SurfaceError, match="raised ZeroDivisionError"):
        S.Custom(lambda u, v: (u, v, 1 / 0), ((0, 1), (0, 1)))
    with pytest.raises(SurfaceError, match="callable"):
        S.Custom("u, v, u*v", ((0, 1), (0, 1)))
    with pytest.raises(SurfaceError, match="singular"):  # sqrt has an infinite slope at 0
        S.Custom(lambda u, v: (u, v, ca.sqrt(u)), ((0, 1), (0, 1)))
    half = S.Custom(lambda u, v: (u, v, ca.sqrt(u)), ((0.5, 1), (0, 1)))
    with pytest.raises(SurfaceError, match="undefined or singular"):
        half.point(-1.0, 0.0)  # NaN never leaves a public function
    with pytest.raises(SurfaceError, match="module-level function"):
        S.Custom(lambda u, v: (u, v, u), ((0, 1), (0, 1))).to_config()


@pytest.mark.parametrize("path", sorted(p for p in TARGETS.glob("*.toml")
                                         if "[target]" in p.read_text()))    # not the study
def test_target_files_load_and_round_trip(path):
    surface = rq.load_design(path)[0].target
    assert surface.name == path.stem
    again = S.from_config(surface.to_config())
    assert again.params == surface.params and again.domain == surface.domain
    np.testing.assert_array_equal(again.sample(5, 5), surface.sample(5, 5))


@pytest.mark.parametrize("name", BUILTINS)
def test_builtin_config_round_trip(name):
    surface = S.get(name)
    config = surface.to_config()
    assert config["name"] == name
    again = S.from_config(config)
    assert again.params == surface.params and again.domain == surface.domain


def test_python_target_round_trips(tmp_path, monkeypatch):
    monkeypatch.syspath_prepend(str(Path(__file__).parent))
    import user_surface

    toml = tmp_path / "mine.toml"
    toml.write_text('[target]\npython = "user_surface:wavy_sheet"\n'
                    'domain = [[-2.0, 2.0], [-1.5, 1.5]]\n\n[design]\npanels = [4, 4]\n')
    surface = rq.load_design(toml, trust=True)[0].target
    assert surface.to_config() == {"python": "user_surface:wavy_sheet",
                                   "domain": [[-2.0, 2.0], [-1.5, 1.5]]}
    np.testing.assert_allclose(surface.point(1.0, 0.5),
                               [1.0, 0.5, 0.3 * math.sin(1.0) * math.cos(0.5)], **TOL)
    direct = S.Custom(user_surface.wavy_sheet, ((-2, 2), (-1.5, 1.5)))
    assert direct.to_config() == surface.to_config()
    unit = [[0, 1], [0, 1]]
    with pytest.raises(SurfaceError, match="three scalars"):
        S.from_config({"python": "user_surface:flat_pair", "domain": unit}, trust=True)
    with pytest.raises(SurfaceError, match="needs domain"):
        S.from_config({"python": "user_surface:wavy_sheet"}, trust=True)
    with pytest.raises(SurfaceError, match="has no function nope"):
        S.from_config({"python": "user_surface:nope", "domain": unit}, trust=True)
    with pytest.raises(SurfaceError, match="cannot import the module no_such_module_x"):
        S.from_config({"python": "no_such_module_x:f", "domain": unit}, trust=True)
    with pytest.raises(SurfaceError, match="form"):
        S.from_config({"python": "os.system('true')", "domain": unit}, trust=True)


def test_python_file_target_loads_relative_to_the_target_file(tmp_path):
    folder = tmp_path / "shared"
    folder.mkdir()
    (folder / "shapes.py").write_text(
        "import casadi as ca\n\ndef dome(u, v):\n    return u, v, 0.1 * ca.cos(u) * ca.cos(v)\n")
    toml = folder / "dome.toml"
    toml.write_text('[target]\npython = "shapes.py:dome"\ndomain = [[-1.0, 1.0], [-1.0, 1.0]]\n')
    surface = rq.load_design(toml, trust=True)[0].target  # no PYTHONPATH: the file is found by path
    np.testing.assert_allclose(surface.point(0.0, 0.0), [0.0, 0.0, 0.1], **TOL)
    config = surface.to_config()
    assert config["python"] == f"{folder / 'shapes.py'}:dome"
    again = S.from_config(config, trust=True)     # the absolute path works from anywhere
    np.testing.assert_allclose(again.sample(4, 4), surface.sample(4, 4), **TOL)
    with pytest.raises(SurfaceError, match="no such Python file"):
        S.from_config({"python": "missing.py:dome", "domain": [[0, 1], [0, 1]]},
                      root=folder, trust=True)
    (folder / "broken.py").write_text("raise RuntimeError('at import')\n")
    with pytest.raises(SurfaceError, match="running .*broken.py raised RuntimeError"):
        S.from_config({"python": "broken.py:f", "domain": [[0, 1], [0, 1]]}, root=folder,
                      trust=True)


@pytest.mark.parametrize("ref, code", [
    ("shapes.py:dome", r"would run the Python file .*shapes\.py \(all of it\) and call dome"),
    ("tests_marker_module:f", "would import the installed module tests_marker_module")])
def test_code_named_by_a_target_runs_only_when_trusted(tmp_path, ref, code):
    marker = tmp_path / "ran"
    (tmp_path / "shapes.py").write_text(f"open({str(marker)!r}, 'w').close()\n"
                                        "def dome(u, v):\n    return u, v, 0 * u\n")
    toml = tmp_path / "t.toml"
    toml.write_text(f'[target]\npython = "{ref}"\ndomain = [[0.0, 1.0], [0.0, 1.0]]\n')
    with pytest.raises(SurfaceError, match=rf"\[target\] python = .*{code}.*pass --trust"):
        rq.load_design(toml)
    assert not marker.exists()                    # nothing of the file ran


@pytest.mark.parametrize("make, message", [
    (lambda: S.get("sphere_cap", radius=-1.0), "^radius must be a finite number > 0"),
    (lambda: S.get("cylinder", radius=0.0), "^radius must be a finite number > 0"),
    (lambda: S.get("plane", domain=((0, 0), (0, 1))), "u range .* empty or inverted"),
    (lambda: S.get("plane", domain=((0, 1), (2, 1))), "v range .* empty or inverted"),
    (lambda: S.get("plane", domain=((0, 1),)), r"^domain must be a list of 2 items"),
    (lambda: S.get("plane", domain=((0, math.inf), (0, 1))), r"^domain\[0\]\[1\] must be a "
                                                              "finite number"),
    (lambda: S.get("sphere_cap", domain=((-1.6, 0.2), (-0.5, 0.5))), "beyond the hemisphere"),
    (lambda: S.get("ellipsoid_cap", domain=((-0.5, 0.5), (0, 2))), "equator"),
    (lambda: S.get("torus_patch", R=1.0, r=2.0), "smaller than the centre-line radius"),
    (lambda: S.get("torus_patch", domain=((0, 7), (0, 1))), "overlaps itself"),
    (lambda: S.get("quarter_vase", amplitude=3.0), "smaller than radius"),
    (lambda: S.get("hyperboloid", a="2"), "^a must be a finite number"),
    (lambda: S.get("sphere_cap", radius=math.nan), "^radius must be a finite number"),
    (lambda: S.get("spherecap"), "unknown surface 'spherecap'; built-in surfaces: sphere_cap"),
    (lambda: S.get("sphere_cap", radus=3.0), "unknown parameter.* radus .* valid parameters: "
                                             "radius"),
    (lambda: S.from_config({"radius": 3.0}), "needs name"),
    (lambda: S.from_config({"python": "m:f", "domain": [[0, 1], [0, 1]], "radius": 1}),
     "unknown key"),
    (lambda: S.get("plane").sample(1, 5), r"^n_u must be a whole number in \[2, 100000\]"),
    (lambda: S.get("plane").lattice(3, 3, spacing=(-1.0, 1.0)),
     r"^spacing\[0\] must be a finite number > 0"),
])
def test_bad_input_raises_surface_error(make, message):
    with pytest.raises(SurfaceError, match=message):
        make()


CAP = S.get("sphere_cap")


@pytest.mark.parametrize("make, message", [
    (lambda: S.get(["sphere_cap"]), "^name must be the name of a built-in surface .*got a "
                                    "list of 1 item"),
    (lambda: S.describe(None), "^name must be the name of a built-in surface"),
    (lambda: S.target_keys(5), "^name must be the name of a built-in surface"),
    (lambda: S.get("x" * 500), r"^unknown surface \(a name of 500 characters\);"),
    (lambda: S.Surface("mine", {}, ((0, 1), (0, 1))), "^Surface has no r\\(u, v\\): "
                                                       "subclass Surface"),
    (lambda: S.Custom(lambda u, v: (u, v, 0 * u), ((0, 1), (0, 1)), name=5),
     "^name must be a string"),
    (lambda: S.Custom(lambda u, v: (u, v, 0 * u), ((0, 1), (0, 1)), reference=[1]),
     "^reference must be a string"),
    (lambda: S.Custom("rm -rf /", ((0, 1), (0, 1))), "^Custom needs a callable .* got a "
                                                     "string of 8 characters"),
    (lambda: S.Custom(lambda u, v: "rm -rf /", ((0, 1), (0, 1))), "must return three scalars "
                                                                  ".* got a string of 8"),
    (lambda: CAP.point("a", 0.1), "^u must be a finite number or an array"),
    (lambda: CAP.normal(0.1, np.nan), "^v must be .* got nan"),
    (lambda: CAP.point(np.zeros(3), np.zeros(2)), "^u and v must broadcast together"),
    (lambda: CAP.closest_points(np.zeros((2, 2)), 11), r"^points must be a finite array of "
                                                       r"shape \(\.\.\., 3\)"),
    (lambda: CAP.closest_points(np.zeros((2, 3)), 1), r"^resolution must be a whole number"),
    (lambda: CAP.lattice_uv(10**6, 2), r"^N must be a whole number in \[1, 99999\]"),
    (lambda: S.from_config({"name": "plane"}, root=5), "^root must be a folder"),
    (lambda: S.from_config({"name": "plane"}, trust="yes"), "^trust must be true or false"),
    (lambda: S.resolve_reference("m:f", root=["."]), "^root must be a folder"),
    (lambda: S.config_of("sphere_cap"), "^surface must be a surface"),
    (lambda: S.rebuildable(None), r"^\[target\] must be a table"),
    (lambda: S.grid_faces(1, 3), r"^n_u must be a whole number in \[2, 100000\]"),
])
def test_api_arguments_raise_surface_error_in_one_line(make, message):
    """The surfaces' functions and methods name the argument and what it allows; nothing
    a caller passes is quoted beyond a short plain name."""
    with pytest.raises(SurfaceError, match=message) as exc:
        make()
    assert "\n" not in str(exc.value) and "rm -rf" not in str(exc.value)


@pytest.mark.parametrize("make, message", [
    (lambda: S.mean_neighbour_distances(np.zeros((1, 3, 3))), "at least 2 x 2 points"),
    (lambda: S.mean_neighbour_distances(np.full((2, 2, 3), 1e300) * [[[1]], [[-1]]]),
     "overflow"),
    (lambda: S.point_set_diameter(np.array([[1e200, 0, 0], [-1e200, 0, 0]])), "overflows"),
    (lambda: S.point_set_diameter(np.zeros((4, 2))), r"shape \(\.\.\., 3\)"),
    (lambda: S.refuse_points("many", 3, "x"), "^count must be a finite number"),
])
def test_point_helpers_refuse_non_finite_results(make, message):
    with pytest.raises(InputError, match=message):
        make()


def test_degenerate_point_sets_have_a_diameter():
    """Qhull cannot hull points that are all one point or on one line: the diameter comes
    from comparing them then."""
    assert S.point_set_diameter(np.zeros((100, 3))) == 0.0
    line = np.zeros((80, 3))
    line[:, 0] = np.arange(80)
    assert S.point_set_diameter(line) == pytest.approx(79.0)


def test_evaluations_beyond_the_memory_left_are_refused(monkeypatch):
    """A grid or broadcast of more points than the machine can hold is refused before any
    evaluation (10^10 points would otherwise allocate until the process is killed)."""
    monkeypatch.setattr(rq.memory, "available", lambda: 1_000_000_000)
    with pytest.raises(InputError, match="evaluating 'sphere_cap' at 10000000000 points "
                                         "needs about"):
        CAP.point(np.zeros((100_000, 1)), np.zeros((1, 100_000)))
    with pytest.raises(InputError, match="needs about"):
        CAP.sample(100_000, 100_000)
    assert CAP.sample(3, 4).shape == (3, 4, 3)


def test_describe_names_parameters_and_defaults():
    text = S.describe("torus_patch")
    assert "R=4.0, r=1.5" in text and "K = cos v" in text
    with pytest.raises(SurfaceError, match="unknown surface"):
        S.describe("donut")


def test_surface_error_is_a_value_error():
    assert issubclass(SurfaceError, ValueError)


def test_load_reports_missing_target_table(tmp_path):
    path = tmp_path / "x.toml"
    path.write_text("[design]\npanels = [2, 2]\n")
    with pytest.raises(InputError, match="needs a \\[target\\] table"):
        rq.load_design(path)
    path.write_text("[target\n")
    with pytest.raises(InputError, match="not valid TOML"):
        rq.load_design(path)
    with pytest.raises(InputError, match="no such design file: .*missing.toml"):
        rq.load_design(tmp_path / "missing.toml")
