"""Curvature maps (rffqm_nlp.targets.curvature): closed forms on a sphere cap lattice, a designed
sphere cap, the sign convention, and curvature.png."""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.image import imread

import rffqm_nlp as rq
from rffqm_nlp.show import pictures as viz
from rffqm_nlp.targets.curvature import Curvature, curvature_maps, lattice_curvatures

R = 4.0


@pytest.fixture(scope="module")
def cap():
    return rq.surfaces.get("sphere_cap", radius=R)


@pytest.fixture(scope="module")
def designed(cap):
    """An 8 x 8 design of the sphere cap, solved to convergence, the target lattice fixed
    (at 8 x 8 panels a free correspondence fits the sphere cap less closely: docs/meshes.md)."""
    return rq.DesignProblem(cap, panels=(8, 8), correspondence="lattice").solve()


def test_sphere_cap_lattice_has_k_one_over_r_squared_and_h_one_over_r(cap):
    T = cap.lattice(10, 12)
    K, H = lattice_curvatures(T)
    assert K.shape == H.shape == (9, 11)
    # second-order differences on a lattice of spacing ~0.13 R: within 5%
    np.testing.assert_allclose(K, 1 / R ** 2, rtol=0.05)
    # outward normal (r_u x r_v points up, away from the centre below): H = -1/R
    np.testing.assert_allclose(H, -1 / R, rtol=0.05)
    # the lattice read with j reversed has the opposite normal: H = +1/R, K unchanged
    K_flip, H_flip = lattice_curvatures(T[:, ::-1])
    np.testing.assert_allclose(K_flip, K[:, ::-1], rtol=1e-12)
    np.testing.assert_allclose(H_flip, -H[:, ::-1], rtol=1e-12)


def test_saddle_lattice_has_negative_gaussian_curvature():
    saddle = rq.surfaces.get("saddle")
    maps = curvature_maps(saddle.lattice(8, 8), saddle.lattice(8, 8), saddle)
    assert np.all(maps.target_K < 0)
    np.testing.assert_allclose(maps.target_K, maps.surface_K, rtol=0.2)


def test_design_side_takes_the_targets_normal(cap):
    T = cap.lattice(6, 6)
    # the same lattice with its rows in reverse order has the opposite discrete normal
    same = curvature_maps(T, T, cap)
    reversed_rows = curvature_maps(T[::-1], T, cap)
    np.testing.assert_allclose(reversed_rows.design_H, same.design_H[::-1], rtol=1e-12)
    assert np.all(same.design_H < 0) and np.all(reversed_rows.design_H < 0)
    np.testing.assert_allclose(same.surface_K, 1 / R ** 2, rtol=1e-9)
    np.testing.assert_allclose(same.surface_H, -1 / R, rtol=1e-9)


def test_designed_sphere_cap_curvature_approximates_the_sphere(designed):
    maps = designed.curvature
    assert isinstance(maps, Curvature)
    for name in ("design_K", "design_H", "target_K", "target_H", "surface_K", "surface_H"):
        assert getattr(maps, name).shape == (3, 3)
    # the folded coarse lattice: each point within 30%, the mean within 10%, H of the
    # target's sign (its outward normal)
    np.testing.assert_allclose(maps.design_K, 1 / R ** 2, rtol=0.3)
    assert maps.design_K.mean() == pytest.approx(1 / R ** 2, rel=0.1)
    assert np.all(maps.design_H < 0)
    assert maps.design_H.mean() == pytest.approx(-1 / R, rel=0.1)
    np.testing.assert_allclose(maps.target_K, 1 / R ** 2, rtol=0.06)


def test_mismatched_lattices_are_refused(cap):
    with pytest.raises(rq.InputError, match="one shape"):
        curvature_maps(cap.lattice(4, 4), cap.lattice(4, 6), cap)


def test_degenerate_lattices_and_wrong_arguments_are_refused_not_nan(cap):
    """A lattice with no finite curvature (all one point, rows shrunk to points) is an
    InputError, never NaN maps; so are arguments of the wrong kind."""
    T = cap.lattice(4, 4)
    folded = np.repeat(T[:, :1], T.shape[1], axis=1)    # each row one point: r_v = 0
    for call, words in (
            (lambda: lattice_curvatures(np.zeros((4, 4, 3))), "no finite value"),
            (lambda: curvature_maps(folded, T, cap), "no finite value"),
            (lambda: lattice_curvatures(T, orient=np.ones((2, 3, 3))),
             r"^orient must be an array of finite numbers of shape \(3, 3, 3\)"),
            (lambda: lattice_curvatures("T"), "^P must be an array of finite numbers of shape "
                                              r"\(n, m, 3\)"),
            (lambda: curvature_maps(T, T, "sphere_cap"), "^target must be a surface"),
            (lambda: curvature_maps(T, np.where(T > 0, np.nan, T), cap),
             "^target_points must be")):
        with pytest.raises(rq.InputError, match=words):
            call()
    maps = curvature_maps(T + 0.01, T, cap)
    assert all(np.all(np.isfinite(v)) for v in maps.to_dict().values())


def test_curvature_png_is_written_and_not_blank(designed, tmp_path):
    path = viz.plot_curvature(designed.curvature, tmp_path / "curvature.png")
    image = imread(path)
    assert image.shape[0] >= 500 and image.shape[1] >= 600
    assert image[..., :3].std() > 0.05
    assert [p.name for p in tmp_path.iterdir()] == ["curvature.png"]
