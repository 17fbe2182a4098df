"""rffqm_nlp.targets.meshes: meshes and point clouds as target surfaces (Mesh), their topology
checks, parametrization, spline fit and distances to the shape."""

import json
import logging
import re
import time
import zipfile

import casadi as ca
import numpy as np
import pytest
import trimesh
from scipy.spatial import Delaunay

import rffqm_nlp as rq
from rffqm_nlp.targets import mesh_domain, mesh_input, mesh_topology, meshes, parametrization
from rffqm_nlp.errors import SurfaceError
from rffqm_nlp.targets.meshes import MAX_DEVIATION, Mesh
from rffqm_nlp.targets.shape import distances_to, relative_fit


def _lattice_error(mesh: Mesh, surface) -> float:
    """Largest distance of the Mesh's 20 x 20 lattice to the original surface, over its
    diameter."""
    return float(surface.closest_points(mesh.lattice(20, 20))[2].max() / surface.diameter())


@pytest.mark.parametrize("name, fmt", [("sphere_cap", "obj"), ("saddle", "stl"),
                                       ("torus_patch", "ply"), ("quarter_vase", "obj"),
                                       ("hyperboloid", "stl"), ("ellipsoid_cap", "ply"),
                                       ("gaussian_bump", "off"), ("cylinder", "glb")])
def test_mesh_files_reload_onto_the_surface(tmp_path, name, fmt):
    surface = rq.surfaces.get(name)
    path = tmp_path / f"{name}.{fmt}"
    surface.mesh(41, 41).export(path)
    mesh = Mesh(path)
    assert isinstance(mesh, rq.surfaces.Mesh)
    assert mesh.parametrization == "rectangle"  # every one is a patch with four corners
    assert len(mesh.points) == 41 * 41  # STL's triangle soup merged back
    assert _lattice_error(mesh, surface) < 0.002
    (a, b), (c, d) = mesh.domain  # the whole patch: the lattice's corners are the mesh's
    corners = mesh.point(np.array([a, b, b, a]), np.array([c, c, d, d]))
    assert surface.closest_points(corners)[2].max() < 1e-3 * surface.diameter()
    assert np.linalg.norm(corners[:, None] - mesh.points[None], axis=2).min(1).max() \
        < 1e-3 * surface.diameter()
    assert mesh.deviation_max < MAX_DEVIATION and mesh.deviation_rms <= mesh.deviation_max
    assert mesh.to_config() == {"mesh": str(path)}


def test_irregular_triangulation(tmp_path):
    surface = rq.surfaces.get("paraboloid")
    (u0, u1), (v0, v1) = surface.domain
    rng = np.random.default_rng(3)
    s = rng.uniform(0, 1, size=(4, 30))  # random points on the four sides too
    sides = np.r_[np.c_[u0 + (u1 - u0) * s[0], np.full(30, v0)],
                  np.c_[u0 + (u1 - u0) * s[1], np.full(30, v1)],
                  np.c_[np.full(30, u0), v0 + (v1 - v0) * s[2]],
                  np.c_[np.full(30, u1), v0 + (v1 - v0) * s[3]]]
    uv = np.r_[rng.uniform((u0, v0), (u1, v1), size=(1500, 2)), sides,
               [[u0, v0], [u0, v1], [u1, v0], [u1, v1]]]
    faces = Delaunay(uv).simplices
    trimesh.Trimesh(surface.point(uv[:, 0], uv[:, 1]), faces).export(tmp_path / "irr.ply")
    mesh = Mesh(tmp_path / "irr.ply")
    assert _lattice_error(mesh, surface) < 0.002


def test_a_flat_rectangle_maps_onto_itself():
    """The conformal rectangle of a flat, irregularly meshed 3 x 1.5 rectangle is the
    rectangle itself, up to a rotation and translation (closed form: the identity)."""
    rng = np.random.default_rng(5)
    side = rng.uniform(0, 1, size=(4, 12))
    uv = np.r_[rng.uniform((0, 0), (3, 1.5), size=(300, 2)),
               np.c_[3 * side[0], np.zeros(12)], np.c_[3 * side[1], np.full(12, 1.5)],
               np.c_[np.zeros(12), 1.5 * side[2]], np.c_[np.full(12, 3.0), 1.5 * side[3]],
               [[0, 0], [3, 0], [3, 1.5], [0, 1.5]]]
    mesh = mesh_input.clean(np.c_[uv, np.zeros(len(uv))], Delaunay(uv).simplices, "flat")
    mesh_topology.check_disk(mesh, "flat")
    mapped = meshes.conformal_rectangle(mesh)
    assert mapped is not None
    assert sorted(np.ptp(mapped, axis=0)) == pytest.approx([1.5, 3.0], rel=1e-9)
    flat = np.asarray(mesh.vertices)[:, :2]
    # the loop may start at any corner: the map is the identity up to one of four turns
    turns = [np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
             for a in (0, np.pi / 2, np.pi, 3 * np.pi / 2)]
    assert min(np.ptp(mapped @ t.T - flat, axis=0).max() for t in turns) < 1e-7


@pytest.mark.parametrize("corner, mapped", [(75, True), (60, False)])
def test_a_parallelogram_far_from_right_angles_is_not_stretched_onto_a_rectangle(corner,
                                                                               mapped):
    """The conformal rectangle of a flat parallelogram stretches areas by 3.3 at 75 deg
    corners and by 12 at 60 deg (99th over 1st percentile): the second is refused
    (MAX_AREA_SPREAD) and the Mesh falls back to the projection."""
    a = np.radians(corner)
    u, v = np.meshgrid(np.linspace(0, 2, 31), np.linspace(0, 1, 21), indexing="ij")
    vertices = np.c_[(u + v * np.cos(a)).ravel(), (v * np.sin(a)).ravel(), np.zeros(u.size)]
    mesh = Mesh((vertices, rq.surfaces.grid_faces(31, 21)))
    assert (mesh.parametrization == "rectangle") is mapped
    assert (meshes.conformal_rectangle(mesh.mesh) is not None) is mapped


def test_a_bent_strip_maps_onto_its_unrolled_rectangle():
    """A cylinder strip bent by 172 deg (no graph over its plane) is developable: its
    conformal rectangle is the unrolled strip, 4 by 1.5 x the radius."""
    surface = rq.surfaces.get("cylinder", domain=((-2.0, 2.0), (-1.5, 1.5)))
    mesh = Mesh(surface.mesh(41, 41))
    assert mesh.parametrization == "rectangle"
    assert _lattice_error(mesh, surface) < 0.002
    (a, b), (c, d) = mesh.domain
    lengths = sorted([b - a, d - c])
    width, arc = sorted([4.0, 3.0 * surface.params["radius"]])
    assert lengths == pytest.approx([width, arc], rel=2e-3)


def test_corners():
    """Four corners on a square's boundary (counter-clockwise), none on a circle's, five
    (convex) on an L's, three on a chevron's (its reflex vertex turns right) and none on a
    clockwise square's: only the first has four."""
    def outline(*vertices, per_side=20):
        """A closed polygon through the vertices, per_side points per side, in the plane."""
        t = np.linspace(0, 1, per_side, endpoint=False)[:, None]
        ring = np.array(vertices, dtype=float)
        sides = [a + t * (b - a) for a, b in zip(ring, np.roll(ring, -1, axis=0))]
        pts = np.concatenate(sides)
        return np.c_[pts, np.zeros(len(pts))], np.arange(len(pts))

    def found(points, loop):
        return meshes.corners(points, np.tile([0.0, 0.0, 1.0], (len(points), 1)), loop)

    theta = np.linspace(0, 2 * np.pi, 80, endpoint=False)
    assert found(np.c_[np.cos(theta), np.sin(theta), np.zeros(80)], np.arange(80)) is None
    assert list(found(*outline((0, 0), (1, 0), (1, 1), (0, 1)))) == [0, 20, 40, 60]
    assert found(*outline((0, 0), (2, 0), (2, 1), (1, 1), (1, 2), (0, 2))) is None
    assert found(*outline((0, 0), (2, 1), (0, 2), (0.5, 1))) is None
    assert found(*outline((0, 0), (0, 1), (1, 1), (1, 0))) is None  # clockwise: turns right


def test_corners_of_a_ragged_or_bumpy_outline():
    """A square's outline jittered by a third of its points' spacing (a triangulated cloud's
    boundary): its four corners, not its jags; a square with a bump of 152 deg on a side:
    the four corners, the fifth run being CORNER_GAP blunter; a pentagon's five equal
    corners: none."""
    def found(points, window=parametrization.CORNER_WINDOW):
        pts = np.c_[points, np.zeros(len(points))]
        return meshes.corners(pts, np.tile([0.0, 0.0, 1.0], (len(pts), 1)),
                              np.arange(len(pts)), window)

    def outline(*vertices, per_side=30):
        t = np.linspace(0, 1, per_side, endpoint=False)[:, None]
        ring = np.array(vertices, dtype=float)
        return np.concatenate([a + t * (b - a) for a, b in zip(ring, np.roll(ring, -1, 0))])

    square = outline((0, 0), (1, 0), (1, 1), (0, 1))
    jagged = square + np.random.default_rng(5).uniform(-1, 1, square.shape) / 90
    at = found(jagged)
    assert at is not None and np.abs(at - [0, 30, 60, 90]).max() <= 2
    bump = outline((0, 0), (2, 0), (2, 2), (1, 2.25), (0, 2))
    assert list(found(bump)) == [0, 30, 60, 120]
    pentagon = np.c_[np.cos(2 * np.pi * np.arange(5) / 5), np.sin(2 * np.pi * np.arange(5) / 5)]
    assert found(outline(*pentagon)) is None


def random_cloud(name: str, points: int, seed: int) -> tuple:
    """``points`` uniform random parameters of a built-in surface, its points with Gaussian
    noise of 0.2% of its diameter: (the surface, the points (points, 3))."""
    surface = rq.surfaces.get(name)
    rng = np.random.default_rng(seed)
    (u0, u1), (v0, v1) = surface.domain
    pts = surface.point(rng.uniform(u0, u1, points), rng.uniform(v0, v1, points))
    return surface, pts + rng.normal(0, 0.002 * surface.diameter(), pts.shape)


@pytest.mark.parametrize("name, seed", [("sphere_cap", 0), ("saddle", 1),
                                        ("hyperboloid", 3), ("torus_patch", 2)])
def test_a_random_cloud_with_a_ragged_boundary_is_covered(name, seed):
    """Issue 44's cloud: 6,000 random points of a patch with noise of 0.2% of its diameter
    (a ragged boundary, whose jags must not count as corners, and sparse spots, which must
    not become holes): the conformal rectangle, whose domain covers
    at least 0.9 of the surface's area, and whose lattice lies on the surface (within 0.2%
    of the diameter, the noise)."""
    surface, pts = random_cloud(name, 6000, seed)
    cloud = Mesh(pts)
    assert cloud.parametrization == "rectangle"
    assert rq.shape.surface_area(cloud) >= 0.9 * rq.shape.surface_area(surface)
    assert _lattice_error(cloud, surface) < 0.002


def test_a_ragged_mesh_is_mapped_onto_a_rectangle():
    """A mesh with a ragged boundary (random points of the saddle, triangulated): the
    conformal rectangle, covering 0.95 of the surface."""
    surface = rq.surfaces.get("saddle")
    rng = np.random.default_rng(2)
    (u0, u1), (v0, v1) = surface.domain
    uv = np.c_[rng.uniform(u0, u1, 3000), rng.uniform(v0, v1, 3000)]
    tri, keep = mesh_domain.cloud_faces(uv)
    faces = tri.simplices[keep]
    faces = np.where((parametrization.signed_areas(faces, uv) < 0)[:, None], faces[:, ::-1],
                     faces)
    mesh = Mesh((surface.point(uv[:, 0], uv[:, 1]), faces))
    assert mesh.parametrization == "rectangle"
    assert rq.shape.surface_area(mesh) >= 0.95 * rq.shape.surface_area(surface)


def test_a_cloud_triangulation_keeps_its_sparse_spots_and_drops_its_bays():
    """cloud_faces drops the long triangles that reach the outside through long ones (a
    bay) and keeps those inside (a sparse spot), so the region stays a disk."""
    rng = np.random.default_rng(0)
    uv = rng.uniform(0, 1, (4000, 2))
    uv = uv[(np.linalg.norm(uv - (0.5, 0.5), axis=1) > 0.06)  # a sparse spot inside,
            | (rng.uniform(size=len(uv)) < 0.02)]           # a few points left in it
    uv = uv[~((uv[:, 0] > 0.45) & (uv[:, 0] < 0.55) & (uv[:, 1] < 0.3))]  # a bay
    tri, keep = mesh_domain.cloud_faces(uv)
    centre = tri.find_simplex(np.array([[0.5, 0.5], [0.5, 0.1]]))
    assert keep[centre[0]] and not keep[centre[1]]


def test_a_disk_without_corners_uses_lscm():
    """The bent strip cut to an ellipse has no corners and is no graph: LSCM."""
    surface = rq.surfaces.get("cylinder", domain=((-2.0, 2.0), (-1.5, 1.5)))
    full = surface.mesh(61, 61)
    u, v = surface.grid_uv(61, 61)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    inside = ((uu / 2.0) ** 2 + (vv / 1.5) ** 2 <= 1.0).ravel()
    mesh = Mesh((full.vertices, full.faces[inside[full.faces].all(axis=1)]))
    assert mesh.parametrization == "lscm"
    assert _lattice_error(mesh, surface) < 0.002


def test_tutte_fallback_is_injective_with_the_boundary_on_a_circle():
    surface = rq.surfaces.get("torus_patch", domain=((-1.2, 1.2), (0.0, 3.1)))
    mesh = mesh_input.clean(surface.mesh(31, 31).vertices, surface.mesh(31, 31).faces, "torus")
    mesh_topology.check_disk(mesh, "torus")
    uv = parametrization.tutte(mesh)
    loop = mesh_topology.boundary_loop(mesh)
    assert np.allclose(np.linalg.norm(uv[loop], axis=1), 1.0)
    assert (parametrization.signed_areas(mesh.faces, uv) > 0).all()
    assert parametrization.injective(mesh, uv, np.zeros(len(mesh.faces), dtype=bool))


def test_sphere_cap_curvature_from_the_spline():
    radius = 4.0
    surface = rq.surfaces.get("sphere_cap", radius=radius)
    mesh = Mesh(surface.mesh(61, 61))
    (a, b), (c, d) = mesh.domain
    u, v = np.linspace(a, b, 9)[2:-2], np.linspace(c, d, 9)[2:-2]
    k = mesh.gaussian_curvature(u[:, None], v[None, :])
    assert np.allclose(k, 1 / radius ** 2, rtol=0.03)
    # r_u x r_v agrees with the mesh's faces (outward): H = -1/R
    assert np.allclose(mesh.mean_curvature(u[:, None], v[None, :]), -1 / radius, rtol=0.03)


def test_point_cloud_fit_is_below_the_noise():
    surface = rq.surfaces.get("sphere_cap", radius=4.0)
    sigma = 0.002 * surface.diameter()
    rng = np.random.default_rng(7)
    points = surface.sample(60, 60).reshape(-1, 3)
    cloud = Mesh(points + rng.normal(scale=sigma, size=points.shape))
    assert cloud.mesh is None and cloud.parametrization == "rectangle"
    u, v = cloud.grid_uv(30, 30)
    fitted = cloud.point(u[:, None], v[None, :])
    dist = surface.closest_points(fitted)[2]
    assert np.sqrt(np.mean(dist ** 2)) < sigma
    assert cloud.deviation_rms == pytest.approx(sigma / surface.diameter(), rel=0.3)


def test_point_cloud_file(tmp_path):
    surface = rq.surfaces.get("gaussian_bump")
    path = tmp_path / "bump.xyz"
    np.savetxt(path, surface.sample(40, 40).reshape(-1, 3))
    cloud = Mesh(path)
    assert cloud.mesh is None and cloud.parametrization == "rectangle"
    assert _lattice_error(cloud, surface) < 0.002


def test_a_round_point_cloud_is_projected():
    """A cloud sampled over a disk has no corners: the projection and its inscribed
    rectangle."""
    surface = rq.surfaces.get("gaussian_bump")
    rng = np.random.default_rng(4)
    uv = rng.uniform(-3, 3, size=(3000, 2))
    uv = uv[np.linalg.norm(uv, axis=1) < 3]
    cloud = Mesh(surface.point(uv[:, 0], uv[:, 1]))
    assert cloud.parametrization == "projection"
    assert _lattice_error(cloud, surface) < 0.002


def test_closest_points_are_exact_on_the_mesh():
    plane = rq.surfaces.get("plane")
    mesh = Mesh(plane.mesh(11, 11))
    rng = np.random.default_rng(0)
    above = np.c_[rng.uniform(-1.5, 1.5, size=(50, 2)), rng.uniform(-1, 1, size=50)]
    uv, closest, dist = mesh.closest_points(above.reshape(5, 10, 3))
    assert uv.shape == (5, 10, 2) and dist.shape == (5, 10)
    assert np.allclose(closest.reshape(-1, 3), np.c_[above[:, :2], np.zeros(50)], atol=1e-12)
    assert np.allclose(dist.ravel(), np.abs(above[:, 2]), atol=1e-12)
    assert np.allclose(mesh.point(uv[..., 0], uv[..., 1]), closest, atol=1e-9)
    assert np.allclose(mesh.distance(above), np.abs(above[:, 2]), atol=1e-12)
    assert np.allclose(distances_to(above.reshape(5, 10, 3), mesh),
                       np.abs(above[:, 2]).reshape(5, 10), atol=1e-12)
    fit = relative_fit(above, mesh)
    assert fit["hausdorff"] == pytest.approx(np.abs(above[:, 2]).max() / mesh.diameter())
    assert fit["rms"] == pytest.approx(np.sqrt(np.mean(above[:, 2] ** 2)) / mesh.diameter())


def test_relative_fit_of_a_parametric_target():
    surface = rq.surfaces.get("sphere_cap", radius=4.0)
    points = surface.lattice(4, 4) * 1.01  # 1% of the radius outside the sphere
    fit = relative_fit(points, surface)
    assert fit["rms"] == pytest.approx(0.04 / surface.diameter(), rel=1e-6)
    assert fit["hausdorff"] == pytest.approx(fit["rms"], rel=1e-6)


def test_a_spline_too_coarse_for_the_shape_is_refused():
    bump = rq.surfaces.get("gaussian_bump", width=0.4)
    with pytest.raises(SurfaceError, match=r"deviates .* pass more knots") as info:
        Mesh(bump.mesh(61, 61), knots=(4, 4))
    assert "\n" not in str(info.value)
    assert Mesh(bump.mesh(61, 61)).deviation_max < MAX_DEVIATION


@pytest.mark.parametrize("kwargs, found", [({"knots": (2, 30)}, r"^knots\[0\] must be"),
                                           ({"knots": 12}, "^knots must be"),
                                           ({"smoothing": -1.0}, "^smoothing must be")])
def test_bad_options(kwargs, found):
    with pytest.raises(SurfaceError, match=found):
        Mesh(rq.surfaces.get("plane").mesh(5, 5), **kwargs)


def test_arrays_cannot_be_saved_as_config():
    mesh = Mesh(rq.surfaces.get("plane").mesh(5, 5))
    with pytest.raises(SurfaceError, match="cannot be saved as config"):
        mesh.to_config()


def _plane_grid(n: int = 9) -> trimesh.Trimesh:
    return rq.surfaces.get("plane").mesh(n, n)


def _two_pieces() -> trimesh.Trimesh:
    a = _plane_grid(5)
    b = a.copy()
    b.apply_translation([10.0, 0.0, 0.0])
    return trimesh.util.concatenate([a, b])


def _with_hole() -> tuple[np.ndarray, np.ndarray]:
    grid = _plane_grid(9)
    keep = np.ones(len(grid.faces), dtype=bool)
    keep[70:74] = False  # two interior cells (4, 3) and (4, 4)
    return grid.vertices, grid.faces[keep]


def _non_manifold() -> tuple[np.ndarray, np.ndarray]:
    grid = _plane_grid(9)
    fin = grid.faces[50]
    vertices = np.r_[grid.vertices, [[0.0, 0.0, 1.0]]]
    return vertices, np.r_[grid.faces, [[fin[0], fin[1], len(vertices) - 1]]]


def _pinched() -> tuple[np.ndarray, np.ndarray]:
    """Two removed cells touching at one vertex: a hole whose boundary pinches there."""
    grid = _plane_grid(9)
    keep = np.ones(len(grid.faces), dtype=bool)
    keep[[54, 55, 72, 73]] = False  # cells (3, 3) and (4, 4)
    return grid.vertices, grid.faces[keep]


def _torus_with_a_cut() -> tuple[np.ndarray, np.ndarray]:
    torus = trimesh.creation.torus(major_radius=3.0, minor_radius=1.0)
    return torus.vertices, torus.faces[1:]


@pytest.mark.parametrize("make, found", [
    (lambda: trimesh.creation.icosphere(), "closed surface"),
    (_two_pieces, "2 separate pieces"),
    (_with_hole, "2 boundary loops"),
    (_non_manifold, "1 non-manifold edges"),
    (_pinched, "1 non-manifold vertices"),
    (_torus_with_a_cut, "Euler characteristic -1"),
    (lambda: np.random.default_rng(0).normal(size=(10, 3)), "only 10 distinct points"),
    (lambda: np.outer(np.linspace(0, 1, 50), [1.0, 2.0, 3.0]), "lie on a line"),
    (lambda: (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), np.array([[0, 1, 2]])),
     "non-finite"),
])
def test_bad_shapes_raise_one_line(make, found):
    with pytest.raises(SurfaceError) as info:
        Mesh(make())
    message = str(info.value)
    assert "\n" not in message and found in message


_GARBAGE = np.random.default_rng(0).bytes(4096)


@pytest.mark.parametrize("name, content, found", [
    ("empty.stl", b"", "no triangles and no points"),
    ("garbage.stl", _GARBAGE, r"cannot read .*garbage\.stl as a mesh"),
    ("garbage.ply", _GARBAGE, r"cannot read .*garbage\.ply as a mesh"),
    ("garbage.obj", _GARBAGE, r"cannot read .*garbage\.obj as a mesh"),
    ("notes.obj", b"this is not a mesh\n" * 20, "no triangles and no points"),
    ("notes.txt", b"hello\n", "cannot read .*notes.txt as a mesh"),
    ("missing.obj", None, "no such file"),
])
def test_bad_files_raise_one_line(tmp_path, name, content, found):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(SurfaceError) as info:
        Mesh(path)
    message = str(info.value)
    assert "\n" not in message and re.search(found, message)


def test_a_design_on_a_mesh_is_judged_against_the_mesh(tmp_path):
    surface = rq.surfaces.get("sphere_cap", radius=4.0, domain=[[-0.6, 0.6], [-0.6, 0.6]])
    surface.mesh(41, 41).export(tmp_path / "cap.stl")
    target = Mesh(tmp_path / "cap.stl")
    # its domain is the whole patch: its spline's area over the domain is the mesh's, up
    # to the chords' O(h^2) (the sphere's area over the same patch is a little larger)
    assert target.parametrization == "rectangle"
    assert target.mesh.area < rq.shape.surface_area(target) < 1.001 * target.mesh.area
    result = rq.DesignProblem(target, panels=(8, 8)).solve(rq.SolveOptions(max_iter=200))
    fit = result.fit
    coarse, every = relative_fit(result.coarse, target), relative_fit(result.folded, target)
    assert (fit.rms_surface, fit.hausdorff) == pytest.approx(
        (coarse["rms"], coarse["hausdorff"]), rel=1e-12)
    assert (fit.rms_surface_vertices, fit.hausdorff_vertices) == pytest.approx(
        (every["rms"], every["hausdorff"]), rel=1e-12)
    assert fit.coverage == pytest.approx(
        rq.shape.lattice_area(result.coarse) / rq.shape.surface_area(target), rel=1e-12)
    assert 0.9 < fit.coverage < 1.1 and fit.rms_surface < 0.25 * fit.plane_rms


def test_the_spline_is_its_edge_a_round_off_outside_its_domain():
    """CasADi's bspline is 0 outside its grid: a (u, v) a round-off past the domain's edge
    (a free correspondence's grid on the edge, computed through its controls) must give the
    edge's point, and the derivative along the edge must be the spline's own."""
    mesh = Mesh(_plane_grid())
    (u0, u1), (v0, v1) = mesh.domain
    f = mesh.casadi_function()
    for u, v in [(u0, 0.5 * (v0 + v1)), (u1, v1), (0.5 * (u0 + u1), v0)]:
        edge = f(u, v).full()
        for du, dv in [(-1e-15, 0), (1e-15, 0), (0, -1e-15), (0, 1e-15)]:
            np.testing.assert_allclose(f(u + du, v + dv).full(), edge, atol=1e-12)
    a, b = ca.SX.sym("a"), ca.SX.sym("b")
    jac = ca.Function("j", [a, b], [ca.jacobian(f(a, b), ca.vertcat(a, b))])
    mid = 0.5 * (v0 + v1)
    np.testing.assert_allclose(jac(u0, mid).full(), jac(u0 + 1e-6 * (u1 - u0), mid).full(),
                               atol=1e-4)


# -- files from others: inert, bounded, and refused in one line that quotes none of them ---

SECRET = "SECRETTOKEN"


def test_a_flipped_triangle_is_turned_back(tmp_path):
    """One triangle of an OBJ wound the other way: trimesh's winding repair (which needs
    networkx) turns it back, and the Mesh is the unflipped file's."""
    mesh = rq.surfaces.get("sphere_cap", radius=4.0, domain=[[-0.6, 0.6], [-0.4, 0.4]]
                           ).mesh(21, 15)
    faces = mesh.faces.copy()
    faces[40] = faces[40][::-1]
    trimesh.Trimesh(mesh.vertices, faces, process=False).export(tmp_path / "flipped.obj")
    mesh.export(tmp_path / "good.obj")
    flipped, good = Mesh(tmp_path / "flipped.obj"), Mesh(tmp_path / "good.obj")
    assert not trimesh.Trimesh(mesh.vertices, faces, process=False).is_winding_consistent
    assert flipped.mesh.is_winding_consistent
    assert flipped.parametrization == good.parametrization == "rectangle"
    np.testing.assert_allclose(flipped.lattice(6, 6), good.lattice(6, 6), atol=1e-12)


def test_a_failure_inside_trimesh_is_one_line_without_its_text(monkeypatch):
    def broken(mesh):
        raise ValueError(f"{SECRET} from inside trimesh")

    monkeypatch.setattr(trimesh.repair, "fix_winding", broken)
    mesh = _plane_grid(7)
    faces = mesh.faces.copy()
    faces[3] = faces[3][::-1]
    with pytest.raises(SurfaceError) as info:
        Mesh((mesh.vertices, faces))
    message = str(info.value)
    assert "winding" in message and SECRET not in message and "\n" not in message


@pytest.mark.parametrize("name", ["part\x00.stl", "a\x00/part.obj"])
def test_a_nul_in_the_path_is_one_line(tmp_path, name):
    for path in (tmp_path / name, str(tmp_path / name)):
        with pytest.raises(SurfaceError) as info:
            Mesh(path)
        message = str(info.value)
        assert "NUL" in message and "\x00" not in message and "\n" not in message
    with pytest.raises(SurfaceError, match="NUL"):      # as the command line's argument
        rq.load_design(str(tmp_path / name))


def _gltf_naming(folder) -> str:
    """A glTF whose one buffer is the file SECRETTOKEN.bin next to it (three vertices)."""
    (folder / f"{SECRET}.bin").write_bytes(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                                                    dtype="<f4").tobytes())
    return json.dumps({
        "asset": {"version": "2.0"}, "buffers": [{"uri": f"{SECRET}.bin", "byteLength": 36}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
        "scenes": [{"nodes": [0]}], "scene": 0})


@pytest.mark.parametrize("name, content, kind", [
    # trimesh's messages quoted these tokens (a PLY property type, an OFF count)
    ("part.ply", f"ply\nformat ascii 1.0\nelement vertex 3\nproperty {SECRET} x\nend_header\n"
                 "1\n2\n3\n", "a PLY"),
    ("part.off", f"OFF\n{SECRET} 1 2\n", "an OFF"),
    # ... and this buffer's name; the buffer next to it is not even read (else: 3 points)
    ("part.gltf", _gltf_naming, "a glTF"),
])
def test_unparsable_files_are_refused_without_quoting_them(tmp_path, name, content, kind):
    path = tmp_path / name
    path.write_text(content if isinstance(content, str) else content(tmp_path))
    with pytest.raises(SurfaceError) as info:
        Mesh(path)
    message = str(info.value)
    assert f"could not be parsed as {kind} file" in message, message
    assert SECRET not in message and "\n" not in message


def test_trimesh_logs_nothing_of_a_file(tmp_path, caplog):
    """trimesh logs names from the file (here a material's, at debug level); nothing it logs
    while a Mesh reads a file gets out, and its logger's level is put back."""
    caplog.set_level(logging.DEBUG, logger="trimesh")
    text = trimesh.exchange.obj.export_obj(_plane_grid(9))
    (tmp_path / "part.obj").write_text(f"mtllib {SECRET}.mtl\nusemtl {SECRET}\n{text}")
    (tmp_path / f"{SECRET}.mtl").write_text("newmtl x\nmap_Kd secret.png\n")
    mesh = Mesh(tmp_path / "part.obj")
    assert len(mesh.points) == 81
    assert SECRET not in caplog.text
    assert logging.getLogger("trimesh").level == logging.DEBUG


@pytest.mark.parametrize("name", ["part.zip", "part.tar.gz", "part.bz2", "part.dxf"])
def test_archives_and_drawings_are_not_read(tmp_path, name):
    """An archive's unpacked size is not bounded by its file's: not unpacked (a file the
    command line still takes for a mesh, so it says so)."""
    path = tmp_path / name
    if name.endswith(".zip"):
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("part.obj", trimesh.exchange.obj.export_obj(_plane_grid(9)))
    else:
        path.write_bytes(b"0" * 100)
    assert meshes.is_mesh_file(path) is (name != "part.tar.gz")  # its suffix: .gz
    with pytest.raises(SurfaceError, match="names no format read here .archives are not "
                                           "unpacked.; give an OBJ"):
        Mesh(path)


def test_a_device_is_not_read():
    with pytest.raises(SurfaceError, match="no regular file"):
        Mesh("/dev/zero")


def _flat_grid(n: int) -> tuple[np.ndarray, np.ndarray]:
    u, v = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    return np.c_[u.ravel(), v.ravel(), np.zeros(n * n)], rq.surfaces.grid_faces(n, n)


@pytest.mark.parametrize("make, found", [
    (lambda: _flat_grid(225), f"100352 triangles, more than a Mesh takes ({meshes.MAX_FACES} "
                              f"triangles"),
    (lambda: (np.random.default_rng(0).normal(size=(3 * meshes.MAX_FACES + 1, 3)),
              np.array([[0, 1, 2]])), f"{3 * meshes.MAX_FACES + 1} vertices"),
    (lambda: np.random.default_rng(0).normal(size=(meshes.MAX_POINTS + 1, 3)),
     f"{meshes.MAX_POINTS + 1} points, more than a Mesh takes"),
])
def test_too_large_shapes_are_refused_before_any_work(make, found):
    source = make()
    start = time.perf_counter()
    with pytest.raises(SurfaceError) as info:
        Mesh(source)
    assert time.perf_counter() - start < 5.0  # a mesh at the limit takes seconds
    message = str(info.value)
    assert found in message and ("decimate" in message or "subsample" in message), message


def test_a_file_larger_than_the_limit_is_not_read(tmp_path):
    path = tmp_path / "part.stl"
    with open(path, "wb") as handle:
        handle.truncate(meshes.MAX_FILE_BYTES + 1)  # sparse: nothing written
    with pytest.raises(SurfaceError, match=r"part\.stl as a mesh: it is 50 MB, more than "
                                           r"the 50 MB read; decimate"):
        Mesh(path)


def _scene(piece: trimesh.Trimesh, placements: int) -> bytes:
    """A GLB placing one geometry ``placements`` times (instances share it in the file)."""
    scene = trimesh.Scene()
    scene.add_geometry(piece, geom_name="piece", node_name="n0")
    for k in range(1, placements):
        move = np.eye(4)
        move[0, 3] = 3.0 * k
        scene.graph.update(frame_to=f"n{k}", frame_from=scene.graph.base_frame, matrix=move,
                           geometry="piece")
    return scene.export(file_type="glb")


@pytest.mark.parametrize("pieces, n, found", [
    (meshes.MAX_PIECES + 1, 5, f"{meshes.MAX_PIECES + 1} pieces, more than a Mesh joins"),
    (2, 160, "101124 triangles, more than a Mesh takes"),  # 2 x 50562
])
def test_a_scene_too_large_is_refused_before_its_pieces_are_joined(tmp_path, pieces, n,
                                                                   found):
    path = tmp_path / "part.glb"
    path.write_bytes(_scene(_plane_grid(n), pieces))
    assert path.stat().st_size < meshes.MAX_FILE_BYTES
    with pytest.raises(SurfaceError, match=re.escape(found)):
        Mesh(path)
