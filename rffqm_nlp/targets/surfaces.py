"""Parametric target surfaces r(u, v) for the inverse design (docs/paper.md s.8).

A surface is a map r(u, v) on a rectangular parameter domain ((u0, u1), (v0, v1)), written
once with operations that work on NumPy arrays and on CasADi symbols alike (:func:`mathlib`).
Everything derived from it (r_u, r_v, the unit normal, the fundamental forms, the curvatures)
comes from automatic differentiation of r: one CasADi SX graph per surface, built on first
use and evaluated vectorised on arrays of (u, v) by passing row vectors.

Conventions:

* u runs along the pattern's i direction (rows), v along j (columns).
* Unit normal n = r_u x r_v / |r_u x r_v|; first form E = r_u.r_u, F = r_u.r_v, G = r_v.r_v;
  second form L = r_uu.n, M = r_uv.n, N = r_vv.n; Gaussian curvature
  K = (LN - M^2) / (EG - F^2); mean curvature H = (EN - 2FM + GL) / (2(EG - F^2)). So H < 0
  where the surface bends away from n (a sphere with outward normal has H = -1/R).

Built-ins (:func:`names`, :func:`get`) validate their parameters and domain on construction,
users add their own with :class:`Custom`, and a design file's ``[target]`` table names one
of either (:func:`from_config`, :meth:`Surface.to_config`; a design file is read by
:func:`rffqm_nlp.design.problem.load_design`). A designer's mesh or point cloud becomes a surface
with :class:`Mesh` (module ``rffqm_nlp.targets.meshes``).
"""

from __future__ import annotations

import os
import hashlib
import importlib
import importlib.util
import math
import re
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import casadi as ca
import numpy as np
import trimesh
from scipy.optimize import brentq
from scipy.spatial import ConvexHull, QhullError, cKDTree

from ..model import backend
from .. import memory
from ..model.backend import finite_array, finite_result
from ..errors import InputError, SurfaceError, one_line
from ..files import Key, check_table, check_value, describe_value, named_path, shown_name

Domain = tuple[tuple[float, float], tuple[float, float]]

#: The math for a surface function's arguments (``m = mathlib(u, v); m.sin(u)``): CasADi's
#: functions if any argument is a CasADi object, else NumPy's. Both namespaces have ``sin,
#: cos, tan, atan, atan2, sqrt, exp, log, sinh, cosh, tanh, fabs, where, pi``. This is
#: :func:`rffqm_nlp.model.backend.math_for`, under the name surface functions use.
mathlib = backend.math_for

#: Grid (per direction) on which a new surface is checked to be finite and regular.
_CHECK_GRID = 21
#: Grid (per direction) of the sample whose largest point distance is the diameter.
_DIAMETER_GRID = 101
#: |r_u x r_v| below this times mean |r_u| * mean |r_v| counts as singular.
_REGULARITY_TOL = 1e-9
#: Most parameter values along one direction of a grid or lattice (:meth:`Surface.grid_uv`,
#: :meth:`Surface.lattice_uv`, :func:`grid_faces`); how many points one evaluation may
#: take is bounded by the memory this machine has left (:func:`refuse_points`).
MAX_GRID = 100_000
#: Bytes per point and output row of an evaluation (the result, its copies), and the
#: size from which it is checked against the memory left (smaller ones do not read /proc).
_BYTES_PER_ENTRY, _MEMORY_CHECK_FROM = 32.0, 1e8


def refuse_points(count: float, rows: int, what: str) -> None:
    """Refuse (:class:`InputError`) an evaluation of ``rows`` numbers at each of ``count``
    points (``what``) that this machine cannot hold."""
    count = check_value(count, Key("number", low=0.0), "count")
    rows = check_value(rows, Key("whole", low=0, high=2**31), "rows")
    what = check_value(what, Key("string"), "what")
    need = _BYTES_PER_ENTRY * count * rows
    if need > _MEMORY_CHECK_FROM:
        memory.refuse_beyond(need, what, "use fewer points")


def check_surface(surface: Any, name: str = "target") -> "Surface":
    """``surface`` if it is a :class:`Surface` (a built-in from :func:`get`, a
    :class:`Custom` or a :class:`~rffqm_nlp.targets.meshes.Mesh`), else :class:`SurfaceError`
    naming ``name`` and what it got."""
    if not isinstance(surface, Surface):
        raise SurfaceError(f"{name} must be a surface (rffqm_nlp.targets.surfaces.get(name), "
                           f"surfaces.Custom or surfaces.Mesh), got {describe_value(surface)}")
    return surface


class Surface:
    """A regular parametric surface r(u, v) on a rectangular domain.

    Subclasses only provide ``_r(u, v)`` (returning (x, y, z) with :func:`mathlib` math);
    construction validates the domain and checks that r is finite and regular on a grid.
    """

    def __init__(self, name: str, params: Mapping[str, float], domain: Any):
        self.name = _checked_value(name, Key("string"), "name")
        self.params = _checked_value(params, Key("table", item=Key("number")), "params")
        self.domain = _check_domain(domain)
        self._check_regular()

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        raise SurfaceError(f"{type(self).__name__} has no r(u, v): subclass Surface with "
                           "_r(u, v), or use surfaces.Custom(fn, domain) or surfaces.get(name)")

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"<Surface {self.name}({args}) on {self.domain}>"

    # -- the AD graph -------------------------------------------------------------------
    @cached_property
    def _functions(self) -> tuple[ca.Function, ca.Function, ca.Function]:
        """(r, geometry, first derivatives) CasADi Functions of (u, v), built once from one
        SX graph."""
        u, v = ca.SX.sym("u"), ca.SX.sym("v")
        r = ca.vertcat(*self._r(u, v))
        r_u, r_v = ca.jacobian(r, u), ca.jacobian(r, v)
        r_uu, r_uv, r_vv = ca.jacobian(r_u, u), ca.jacobian(r_u, v), ca.jacobian(r_v, v)
        cross = ca.cross(r_u, r_v)
        n = cross / ca.norm_2(cross)
        e, f, g = ca.dot(r_u, r_u), ca.dot(r_u, r_v), ca.dot(r_v, r_v)
        l, m, nn = ca.dot(r_uu, n), ca.dot(r_uv, n), ca.dot(r_vv, n)
        det = e * g - f * f
        k = (l * nn - m * m) / det
        h = (e * nn - 2 * f * m + g * l) / (2 * det)
        point = ca.Function("r", [u, v], [r], ["u", "v"], ["r"])
        geometry = ca.Function(
            "geometry", [u, v], [r, r_u, r_v, n, ca.vertcat(e, f, g, l, m, nn), k, h],
            ["u", "v"], ["r", "r_u", "r_v", "n", "forms", "K", "H"])
        first = ca.Function("first", [u, v], [r, r_u, r_v], ["u", "v"], ["r", "r_u", "r_v"])
        return point, geometry, first

    def casadi_function(self) -> ca.Function:
        """The CasADi Function (u, v) -> r (3x1), for use inside other CasADi graphs."""
        return self._functions[0]

    def _evaluate(self, fn: ca.Function, u: Any, v: Any) -> tuple[tuple[int, ...], list]:
        """Evaluate ``fn`` at the broadcast of u, v: (shape, outputs as (rows, n) arrays).

        Raises SurfaceError for u, v that are not finite numbers broadcasting together, and
        where an output is not finite (outside the domain, singular)."""
        u = finite_array(u, "u", allowed="a finite number or an array of finite numbers",
                         error=SurfaceError)
        v = finite_array(v, "v", allowed="a finite number or an array of finite numbers",
                         error=SurfaceError)
        try:
            shape = np.broadcast_shapes(u.shape, v.shape)
        except ValueError:
            raise SurfaceError(f"u and v must broadcast together, got shapes {u.shape} and "
                               f"{v.shape}") from None
        refuse_points(math.prod(shape), sum(fn.nnz_out(k) for k in range(fn.n_out())) + 2,
                      f"evaluating {self.name!r} at {math.prod(shape)} points")
        uu, vv = np.broadcast_arrays(u, v)
        if uu.size == 0:
            return uu.shape, [np.zeros((fn.size1_out(k), 0)) for k in range(fn.n_out())]
        # row vectors of n columns make CasADi evaluate fn n times (no Python loop)
        out = fn.call([uu.reshape(1, -1), vv.reshape(1, -1)])
        arrays = [np.array(o, dtype=float).reshape(-1, uu.size) for o in out]
        finite = np.all([np.all(np.isfinite(a), axis=0) for a in arrays], axis=0)
        if not finite.all():
            k = int(np.argmin(finite))
            raise SurfaceError(
                f"surface {self.name!r} is undefined or singular at (u, v) = "
                f"({uu.flat[k]:.6g}, {vv.flat[k]:.6g}); use (u, v) inside the domain "
                f"{self.domain}, or shrink the domain to stay away from the singularity")
        return uu.shape, arrays

    # -- pointwise quantities -----------------------------------------------------------
    def point(self, u: Any, v: Any) -> np.ndarray:
        """r(u, v) with shape broadcast(u, v).shape + (3,)."""
        shape, (r,) = self._evaluate(self._functions[0], u, v)
        return r.T.reshape(shape + (3,))

    def _geometry(self, u: Any, v: Any) -> tuple[tuple[int, ...], list]:
        return self._evaluate(self._functions[1], u, v)

    def derivatives(self, u: Any, v: Any) -> tuple[np.ndarray, np.ndarray]:
        """(r_u, r_v), each broadcast(u, v).shape + (3,)."""
        shape, out = self._geometry(u, v)
        return out[1].T.reshape(shape + (3,)), out[2].T.reshape(shape + (3,))

    def normal(self, u: Any, v: Any) -> np.ndarray:
        """Unit normal r_u x r_v / |r_u x r_v|, shape broadcast(u, v).shape + (3,)."""
        shape, out = self._geometry(u, v)
        return out[3].T.reshape(shape + (3,))

    def fundamental_forms(self, u: Any, v: Any) -> tuple[np.ndarray, ...]:
        """(E, F, G, L, M, N), each shaped like the broadcast of u, v (module docstring)."""
        shape, out = self._geometry(u, v)
        return tuple(row.reshape(shape) for row in out[4])

    def gaussian_curvature(self, u: Any, v: Any) -> np.ndarray:
        """K = (LN - M^2) / (EG - F^2), shaped like the broadcast of u, v."""
        shape, out = self._geometry(u, v)
        return out[5].reshape(shape)

    def mean_curvature(self, u: Any, v: Any) -> np.ndarray:
        """H = (EN - 2FM + GL) / (2(EG - F^2)) with n = r_u x r_v / |r_u x r_v|."""
        shape, out = self._geometry(u, v)
        return out[6].reshape(shape)

    # -- samples, lattices, meshes ------------------------------------------------------
    def grid_uv(self, n_u: int, n_v: int) -> tuple[np.ndarray, np.ndarray]:
        """(u (n_u,), v (n_v,)): uniform parameter values over the whole domain; n_u, n_v
        whole numbers in [2, :data:`MAX_GRID`]."""
        n_u, n_v = (_checked_value(n, _GRID, k) for n, k in ((n_u, "n_u"), (n_v, "n_v")))
        (u0, u1), (v0, v1) = self.domain
        return np.linspace(u0, u1, n_u), np.linspace(v0, v1, n_v)

    def sample(self, n_u: int, n_v: int) -> np.ndarray:
        """Points on the uniform (n_u, n_v) parameter grid over the whole domain, (n_u, n_v, 3)."""
        u, v = self.grid_uv(n_u, n_v)
        return self.point(u[:, None], v[None, :])

    def mesh(self, n_u: int, n_v: int) -> trimesh.Trimesh:
        """Triangle mesh of :meth:`sample`; vertex (a, b) has index a*n_v + b, and every
        triangle is oriented so that its normal agrees with r_u x r_v."""
        points = self.sample(n_u, n_v)
        return trimesh.Trimesh(vertices=points.reshape(-1, 3), faces=grid_faces(n_u, n_v),
                               process=False)

    def diameter(self) -> float:
        """Largest distance between two points of the 101 x 101 :meth:`sample` (cached)."""
        return self._diameter

    @cached_property
    def _diameter(self) -> float:
        return point_set_diameter(self.sample(_DIAMETER_GRID, _DIAMETER_GRID))

    def lattice_uv(self, N: int, M: int,
                   spacing: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Parameters (u (N+1,), v (M+1,)) of the lattice (0..N) x (0..M) (docs/paper.md s.8).

        With ``spacing=None`` the lattice spans the whole domain, uniform in parameter space.
        With ``spacing=(s_i, s_j)`` it spans a sub-rectangle centred in the domain, uniform in
        parameter space, whose half-extents are chosen (brentq, alternating between the two
        directions) so that the mean distance between lattice neighbours along i is s_i and
        along j is s_j.
        """
        N, M = (_checked_value(n, Key("whole", low=1, high=MAX_GRID - 1), k)
                for n, k in ((N, "N"), (M, "M")))
        if spacing is None:
            return self.grid_uv(N + 1, M + 1)
        s_i, s_j = _checked_value(spacing, _SPACING, "spacing")
        (u0, u1), (v0, v1) = self.domain
        uc, vc, a_max, b_max = (u0 + u1) / 2, (v0 + v1) / 2, (u1 - u0) / 2, (v1 - v0) / 2

        def mean_steps(a: float, b: float) -> tuple[float, float]:
            u, v = np.linspace(uc - a, uc + a, N + 1), np.linspace(vc - b, vc + b, M + 1)
            return mean_neighbour_distances(self.point(u[:, None], v[None, :]))

        most = mean_steps(a_max, b_max)
        if s_i > most[0] or s_j > most[1]:
            raise SurfaceError(
                f"spacing ({s_i:.6g}, {s_j:.6g}) does not fit: the domain {self.domain} of "
                f"{self.name!r} holds a {N} x {M} lattice with mean neighbour distances up to "
                f"({most[0]:.6g}, {most[1]:.6g}); use a smaller spacing, fewer panels or a "
                f"larger domain")
        a, b = a_max, b_max
        for _ in range(200):
            a_new = _solve_extent(lambda x: mean_steps(x, b)[0] - s_i, a_max)
            b_new = _solve_extent(lambda y: mean_steps(a_new, y)[1] - s_j, b_max)
            done = abs(a_new - a) <= 1e-14 * a_max and abs(b_new - b) <= 1e-14 * b_max
            a, b = a_new, b_new
            if done:
                break
        d_i, d_j = mean_steps(a, b)
        if abs(d_i - s_i) > 1e-10 * s_i or abs(d_j - s_j) > 1e-10 * s_j:
            raise SurfaceError(
                f"spacing ({s_i:.6g}, {s_j:.6g}) could not be matched on {self.name!r} (reached "
                f"({d_i:.6g}, {d_j:.6g})); use a smaller spacing or a larger domain")
        return np.linspace(uc - a, uc + a, N + 1), np.linspace(vc - b, vc + b, M + 1)

    def lattice(self, N: int, M: int, spacing: tuple[float, float] | None = None) -> np.ndarray:
        """Points r(u_i, v_j) of :meth:`lattice_uv`, shape (N+1, M+1, 3)."""
        u, v = self.lattice_uv(N, M, spacing)
        return self.point(u[:, None], v[None, :])

    def closest_points(self, points: Any, resolution: int = 101
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points of the surface (over its domain) to ``points`` (..., 3).

        A nearest-neighbour search on the (resolution x resolution) :meth:`sample` gives the
        start, then projected Gauss-Newton on |r(u, v) - p|^2 with the AD derivatives and the
        domain as box constraints converges to the closest point (to round-off for points
        whose closest point is regular). Returns (uv (..., 2), closest (..., 3),
        distances (...)).
        """
        pts = finite_array(points, "points", allowed="a finite array of shape (..., 3)",
                           error=SurfaceError)
        if pts.shape[-1:] != (3,):
            raise SurfaceError(f"points must be a finite array of shape (..., 3), got shape "
                               f"{pts.shape}")
        shape, pts = pts.shape[:-1], pts.reshape(-1, 3)
        resolution = _checked_value(resolution, _GRID, "resolution")
        refuse_points(resolution * resolution, 12, f"a {resolution} x {resolution} sample")
        u, v = self.grid_uv(resolution, resolution)
        _, idx = cKDTree(self.sample(resolution, resolution).reshape(-1, 3)).query(pts)
        uu, vv = u[idx // resolution], v[idx % resolution]
        active = np.arange(uu.size)  # the points still moving
        for _ in range(100):
            new_u, new_v, moved = self._projection_step(pts[active], uu[active], vv[active])
            uu[active], vv[active] = new_u, new_v
            active = active[moved > 1e-15]
            if active.size == 0:
                break
        closest = self.point(uu, vv)
        with np.errstate(all="ignore"):
            dist = np.linalg.norm(closest - pts, axis=1)
        finite_result(dist, "the distances to the surface overflow: the points are too far "
                            "from it for floating point")
        return (np.stack([uu, vv], -1).reshape(shape + (2,)), closest.reshape(shape + (3,)),
                dist.reshape(shape))

    def _projection_step(self, pts: np.ndarray, uu: np.ndarray, vv: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One projected Gauss-Newton step with step halving for points (n, 3) at (u, v)
        (n,) each; returns (u, v, each point's move relative to the domain size)."""
        (u0, u1), (v0, v1) = self.domain
        _, (r, r_u, r_v) = self._evaluate(self._functions[2], uu, vv)
        r, r_u, r_v = r.T, r_u.T, r_v.T
        res = r - pts
        g_u, g_v = np.sum(r_u * res, 1), np.sum(r_v * res, 1)
        e, f, g = np.sum(r_u * r_u, 1), np.sum(r_u * r_v, 1), np.sum(r_v * r_v, 1)
        det = e * g - f * f
        du, dv = -(g * g_u - f * g_v) / det, -(e * g_v - f * g_u) / det
        # a bound is active where the point sits on it and descent leads outside
        fix_u = ((uu <= u0) & (g_u > 0)) | ((uu >= u1) & (g_u < 0))
        fix_v = ((vv <= v0) & (g_v > 0)) | ((vv >= v1) & (g_v < 0))
        du, dv = np.where(fix_v, -g_u / e, du), np.where(fix_u, -g_v / g, dv)
        du, dv = np.where(fix_u, 0.0, du), np.where(fix_v, 0.0, dv)
        dist = np.linalg.norm(res, axis=1)
        t = np.ones_like(uu)
        new_u, new_v = uu.copy(), vv.copy()
        todo = np.arange(uu.size)  # the points whose step is not yet accepted
        for _ in range(30):
            cu = np.clip(uu[todo] + t[todo] * du[todo], u0, u1)
            cv = np.clip(vv[todo] + t[todo] * dv[todo], v0, v1)
            ok = np.linalg.norm(self.point(cu, cv) - pts[todo], axis=1) <= dist[todo]
            new_u[todo[ok]], new_v[todo[ok]] = cu[ok], cv[ok]
            todo = todo[~ok]
            if todo.size == 0:
                break
            t[todo] /= 2
        return new_u, new_v, np.maximum(np.abs(new_u - uu) / (u1 - u0),
                                        np.abs(new_v - vv) / (v1 - v0))

    # -- configuration ------------------------------------------------------------------
    def to_config(self) -> dict:
        """The ``[target]`` table that :func:`from_config` turns back into this surface."""
        return {"name": self.name, **self.params, "domain": _domain_list(self.domain)}

    def _check_regular(self) -> None:
        """Raise SurfaceError unless r is finite with r_u x r_v != 0 on a grid of the domain."""
        u, v = self.grid_uv(_CHECK_GRID, _CHECK_GRID)
        uu, vv = np.meshgrid(u, v, indexing="ij")
        _, out = self._geometry(uu, vv)
        r_u, r_v = out[1].T, out[2].T
        area = np.linalg.norm(np.cross(r_u, r_v), axis=1)
        typical = np.linalg.norm(r_u, axis=1).mean() * np.linalg.norm(r_v, axis=1).mean()
        bad = area <= _REGULARITY_TOL * typical
        if bad.any():
            k = int(np.argmax(bad))
            raise SurfaceError(
                f"surface {self.name!r} is singular (r_u x r_v = 0) at (u, v) = "
                f"({uu.flat[k]:.6g}, {vv.flat[k]:.6g}); shrink or move the domain {self.domain}")


def grid_faces(n_u: int, n_v: int) -> np.ndarray:
    """Triangles of an (n_u, n_v) vertex grid (vertex (a, b) = a*n_v + b), two per cell:
    (a,b)-(a+1,b)-(a+1,b+1) and (a,b)-(a+1,b+1)-(a,b+1), both oriented like r_u x r_v.
    n_u, n_v are whole numbers in [2, :data:`MAX_GRID`]."""
    n_u, n_v = (_checked_value(n, _GRID, k) for n, k in ((n_u, "n_u"), (n_v, "n_v")))
    refuse_points(n_u * n_v, 12, f"the faces of a {n_u} x {n_v} grid")
    idx = np.arange(n_u * n_v).reshape(n_u, n_v)
    p, q, r, s = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    tri = np.stack([np.stack([p, q, r], -1), np.stack([p, r, s], -1)], axis=2)
    return tri.reshape(-1, 3)


def mean_neighbour_distances(points: np.ndarray) -> tuple[float, float]:
    """Mean distance between lattice neighbours of (n, m, 3) points along i and along j."""
    points = finite_array(points, "points", shape=(None, None, 3))
    if min(points.shape[:2]) < 2:
        raise InputError(f"points must be a lattice of at least 2 x 2 points, got shape "
                         f"{points.shape}")
    with np.errstate(all="ignore"):
        d_i = np.linalg.norm(np.diff(points, axis=0), axis=-1)
        d_j = np.linalg.norm(np.diff(points, axis=1), axis=-1)
        means = float(d_i.mean()), float(d_j.mean())
    return finite_result(means, "the neighbour distances overflow: the points are too large "
                                "for floating point")


def point_set_diameter(points: np.ndarray) -> float:
    """Largest distance between two of the points (any shape (..., 3)).

    Only convex-hull vertices can realise it. A pair of farthest-point steps gives a lower
    bound d; with c the bounding-box centre and R the largest |p - c|, a point p can only be
    in a pair longer than d if |p - c| + R >= d, and the pairs of those points are compared
    in blocks. On a convex cap every sampled point is a hull vertex, so the pruning is what
    keeps it fast (measured against all pairs: docs/solvers.md, "Smaller measurements").
    Raises :class:`InputError` unless the points are finite numbers of shape (..., 3).
    """
    pts = finite_array(points, "points", allowed="a finite array of shape (..., 3)")
    if pts.shape[-1:] != (3,):
        raise InputError(f"points must be a finite array of shape (..., 3), got shape "
                         f"{pts.shape}")
    with np.errstate(all="ignore"):
        return finite_result(_diameter_of(pts.reshape(-1, 3)), "the diameter overflows: the "
                             "points are too large for floating point")


def _diameter_of(pts: np.ndarray) -> float:
    if len(pts) > 50:
        try:
            pts = pts[ConvexHull(pts, qhull_options="QJ").vertices]
        except QhullError:    # degenerate (e.g. every point the same): compare them all
            pts = np.unique(pts, axis=0)
    if len(pts) < 2:
        return 0.0
    a = int(np.argmax(((pts - pts[0]) ** 2).sum(axis=1)))
    b = int(np.argmax(((pts - pts[a]) ** 2).sum(axis=1)))
    best = float(((pts[a] - pts[b]) ** 2).sum())
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    radius = np.linalg.norm(pts - centre, axis=1)
    cand = pts[radius + radius.max() >= np.sqrt(best) * (1 - 1e-12)]
    block = max(1, 1_000_000 // len(cand))
    for k in range(0, len(cand), block):
        sq = ((cand[k:k + block, None, :] - cand[None, :, :]) ** 2).sum(axis=-1)
        best = max(best, float(sq.max()))
    return float(np.sqrt(best))


class Custom(Surface):
    """A user's surface from a callable ``fn(u, v) -> (x, y, z)``.

    ``fn`` is called with CasADi SX symbols to build the AD graph, so it must use
    CasADi-compatible math: arithmetic, ``casadi.sin`` etc., or :func:`mathlib`
    (``m = mathlib(u, v); m.sin(u)``). It is checked once on symbols and once on numbers
    (the domain's centre); a wrong result raises SurfaceError. ``reference`` is the
    ``"module:function"`` or ``"/path/file.py:function"`` it was loaded from, if any (used
    by :meth:`to_config`).
    """

    def __init__(self, fn: Callable[[Any, Any], Any], domain: Any, name: str = "custom",
                 reference: str | None = None):
        if not callable(fn):
            raise SurfaceError(f"Custom needs a callable fn(u, v) -> (x, y, z), got "
                               f"{describe_value(fn)}")
        name = _checked_value(name, Key("string"), "name")
        self._fn = fn
        self.reference = (None if reference is None else
                          _checked_value(reference, Key("string", hint="(or None)"), "reference"))
        dom = _check_domain(domain)
        _xyz(fn, ca.SX.sym("u"), ca.SX.sym("v"), "CasADi SX symbols", ca.SX)
        centre = (sum(dom[0]) / 2, sum(dom[1]) / 2)
        _xyz(fn, *centre, f"the numbers (u, v) = {centre}", ca.DM)
        super().__init__(name, {}, dom)

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        return _xyz(self._fn, u, v, "CasADi SX symbols", ca.SX)

    def to_config(self) -> dict:
        """``{"python": reference, "domain": ...}``: the reference it was loaded from, else
        "module:function" of an importable function."""
        ref = self.reference or _reference_of(self._fn)
        if ref is None:
            raise SurfaceError(
                f"custom surface {self.name!r} was made from {self._fn!r}, which cannot be "
                f"imported by name; define it as a module-level function and use "
                f"python = \"module:function\" in the [target] table")
        return {"python": ref, "domain": _domain_list(self.domain)}


def _xyz(fn: Callable, u: Any, v: Any, what: str, kind: type) -> tuple[Any, Any, Any]:
    """Call fn(u, v) and return its three components as 1x1 ``kind`` (SX or DM) matrices."""
    try:
        out = fn(u, v)
    except Exception as err:
        raise SurfaceError(
            f"the surface callable raised {type(err).__name__}: {one_line(err)} when called "
            f"with {what}; write it with CasADi-compatible math (casadi.sin, ..., or "
            f"rffqm_nlp.targets.surfaces.mathlib)") from err
    try:
        parts = ca.vertsplit(ca.vec(out)) if backend.is_casadi(out) else list(out)
        parts = [kind(p) for p in parts]
    except Exception:
        parts = None
    if parts is None or len(parts) != 3 or any(p.shape != (1, 1) for p in parts):
        raise SurfaceError(
            f"the surface callable must return three scalars (x, y, z) when called with "
            f"{what}, got {describe_value(out)}")
    if kind is ca.DM and not all(np.isfinite(float(p)) for p in parts):
        raise SurfaceError(f"the surface callable returned non-finite values (NaN or "
                           f"infinity) at {what}")
    return parts[0], parts[1], parts[2]


def _reference_of(fn: Callable) -> str | None:
    """``"module:qualname"`` if that module, already imported, holds ``fn`` itself, else
    None."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", "")
    if not module or "<" in qualname or module not in sys.modules:
        return None
    try:
        found = _attribute(sys.modules[module], qualname, f"{module}:{qualname}")
    except SurfaceError:
        return None
    return f"{module}:{qualname}" if found is fn else None


#: A Python name path (``package.module``, ``function``, ``Class.method``).
_DOTTED = re.compile(r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)*")
#: A Python file: a path ending in .py, without control characters or colons.
_PY_FILE = re.compile(r"[^\x00-\x1f\x7f:]+\.py")
_REFERENCE_FORMS = ('"file.py:function" (a Python file, relative to the target file) or '
                    '"package.module:function" (an installed module)')


def parse_reference(ref: Any) -> tuple[str, str, str]:
    """("file" or "module", the file or module, the function's name) of a target's
    ``python = ...``; :class:`SurfaceError` for anything of neither form."""
    where, sep, qualname = ref.rpartition(":") if isinstance(ref, str) else ("", "", "")
    if sep and len(ref) <= 300 and _DOTTED.fullmatch(qualname):
        if _PY_FILE.fullmatch(where):
            return "file", where, qualname
        if _DOTTED.fullmatch(where):
            return "module", where, qualname
    raise SurfaceError(f"[target] python must have the form {_REFERENCE_FORMS}, got "
                       f"{describe_value(ref)}")


def resolve_reference(ref: Any, root: str | Path | None = None) -> str:
    """``ref`` with a file made absolute (relative to ``root``, default the current folder);
    a module reference unchanged."""
    kind, where, qualname = parse_reference(ref)
    root = _check_root(root)
    if kind == "module":
        return ref
    return f"{Path(root or '.').joinpath(where).absolute()}:{qualname}"


def _code_of(ref: str) -> str:
    """What loading ``ref`` (resolved) runs, for the messages."""
    kind, where, qualname = parse_reference(ref)
    if kind == "file":
        return f"would run the Python file {where} (all of it) and call {qualname}"
    return f"would import the installed module {where} (running its code) and call {qualname}"


def _import_reference(ref: str) -> Callable:
    """The function of a resolved ``ref``: the file run as a module of its own
    (:func:`importlib.util.spec_from_file_location`), or the module imported by name."""
    kind, where, qualname = parse_reference(ref)
    if kind == "file":
        return _attribute(_run_file(Path(where)), qualname, ref)
    try:
        module = importlib.import_module(where)
    except Exception as err:
        raise SurfaceError(f"[target] python: cannot import the module {where} "
                           f"({type(err).__name__}: {one_line(err)}); check it is installed "
                           "or use python = \"file.py:function\"") from err
    return _attribute(module, qualname, ref)


def _run_file(path: Path) -> Any:
    """The module made by running the Python file ``path``, registered under a name of its
    own (so dataclasses and pickling inside it work)."""
    if not path.is_file():
        raise SurfaceError(f"[target] python: no such Python file {path} (a file is relative "
                           "to the target file)")
    name = "rffqm_target_" + hashlib.sha256(str(path).encode()).hexdigest()[:16]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except Exception as err:
        del sys.modules[name]
        raise SurfaceError(f"[target] python: running {path} raised {type(err).__name__}: "
                           f"{one_line(err)}") from err
    return module


def _attribute(obj: Any, qualname: str, ref: str) -> Callable:
    """``obj.<qualname>``, which must be callable."""
    for attr in qualname.split("."):
        if not hasattr(obj, attr):
            raise SurfaceError(f"[target] python: {ref} has no function {qualname}; check "
                               "the name is spelled right")
        obj = getattr(obj, attr)
    if not callable(obj):
        raise SurfaceError(f"[target] python: {qualname} of {ref} is not a function")
    return obj


# -- built-in surfaces --------------------------------------------------------------------


@dataclass(frozen=True)
class _Spec:
    """A built-in: r(params, u, v), default parameters, default domain, parameter checks."""

    r: Callable[[dict, Any, Any], tuple[Any, Any, Any]]
    defaults: dict[str, float]
    domain: Callable[[dict], Domain]
    check: Callable[[dict, Domain], None]
    doc: str


class _Builtin(Surface):
    def __init__(self, name: str, spec: _Spec, params: dict, domain: Any):
        self._spec = spec
        dom = _check_domain(spec.domain(params) if domain is None else domain)
        spec.check(params, dom)
        super().__init__(name, params, dom)

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        return self._spec.r(self.params, u, v)


def _positive(params: dict, *keys: str) -> None:
    for key in keys:
        _checked_value(params[key], Key("number", low=0, low_open=True), key)


def _inside_open(dom: Domain, limit: float, what: str) -> None:
    """Both parameters must stay in (-limit, limit)."""
    for name, (a, b) in zip("uv", dom):
        if max(abs(a), abs(b)) >= limit:
            raise SurfaceError(f"the {name} range {(a, b)} reaches {what} at |{name}| = "
                               f"{limit:.6g}; keep |{name}| < {limit:.6g}")


def _at_most_turn(dom: Domain, which: str) -> None:
    """An angle parameter may span at most one full turn (no overlapping sheets)."""
    a, b = dom["uv".index(which)]
    if b - a > 2 * math.pi:
        raise SurfaceError(f"the angle {which} spans {b - a:.6g} > 2*pi, so the surface "
                           f"overlaps itself; use a {which} range of length <= 2*pi")


def _gnomonic(m: SimpleNamespace, u: Any, v: Any) -> tuple[Any, Any, Any]:
    """Direction (tan u, tan v, 1): equiangular coordinates around the +z pole."""
    return m.tan(u), m.tan(v), 1.0


def _sphere_cap(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    x, y, z = _gnomonic(m, u, v)
    s = p["radius"] / m.sqrt(x * x + y * y + z * z)
    return s * x, s * y, s * z


def _ellipsoid_cap(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    x, y, z = _gnomonic(m, u, v)
    s = 1 / m.sqrt((x / p["a"]) ** 2 + (y / p["b"]) ** 2 + (z / p["c"]) ** 2)
    return s * x, s * y, s * z


def _hyperboloid(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    return p["a"] * m.cosh(u) * m.cos(v), p["b"] * m.cosh(u) * m.sin(v), p["c"] * m.sinh(u)


def _vase_radius(p: dict, m: SimpleNamespace, z: Any) -> Any:
    return p["radius"] + p["amplitude"] * m.sin(2 * math.pi * z / p["wavelength"])


def _quarter_vase(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    rho = _vase_radius(p, m, u)
    return rho * m.cos(v), rho * m.sin(v), u


def _saddle(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    return u, v, u * u / (2 * p["a"]) - v * v / (2 * p["b"])


def _paraboloid(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    return u, v, u * u / (2 * p["a"]) + v * v / (2 * p["b"])


def _cylinder(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    return p["radius"] * m.sin(v), u, p["radius"] * m.cos(v)


def _torus_patch(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    ring = p["R"] + p["r"] * m.cos(v)
    return ring * m.cos(u), ring * m.sin(u), p["r"] * m.sin(v)


def _gaussian_bump(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    return u, v, p["height"] * m.exp(-(u * u + v * v) / (2 * p["width"] ** 2))


def _plane(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    return u, v, 0.0


def _check_sphere(p: dict, dom: Domain) -> None:
    _positive(p, "radius")
    _inside_open(dom, math.pi / 2, "the equator (beyond the hemisphere)")


def _check_ellipsoid(p: dict, dom: Domain) -> None:
    _positive(p, "a", "b", "c")
    _inside_open(dom, math.pi / 2, "the equator (beyond the half ellipsoid)")


def _check_hyperboloid(p: dict, dom: Domain) -> None:
    _positive(p, "a", "b", "c")
    _at_most_turn(dom, "v")


def _check_vase(p: dict, dom: Domain) -> None:
    _positive(p, "radius", "wavelength")
    if abs(p["amplitude"]) >= p["radius"]:
        raise SurfaceError(f"|amplitude| = {abs(p['amplitude'])} must be smaller than radius = "
                           f"{p['radius']} so that the profile radius stays positive")
    _at_most_turn(dom, "v")


def _check_ab(p: dict, dom: Domain) -> None:
    _positive(p, "a", "b")


def _check_cylinder(p: dict, dom: Domain) -> None:
    _positive(p, "radius")
    _at_most_turn(dom, "v")


def _check_torus(p: dict, dom: Domain) -> None:
    _positive(p, "R", "r")
    if p["r"] >= p["R"]:
        raise SurfaceError(f"the tube radius r = {p['r']} must be smaller than the centre-line "
                           f"radius R = {p['R']} (else the torus is singular)")
    _at_most_turn(dom, "u")
    _at_most_turn(dom, "v")


def _check_bump(p: dict, dom: Domain) -> None:
    _positive(p, "width")


def _check_nothing(p: dict, dom: Domain) -> None:
    """The plane has no parameters to check."""


def _fixed(dom: Domain) -> Callable[[dict], Domain]:
    return lambda p: dom


_BUILTINS: dict[str, _Spec] = {
    "sphere_cap": _Spec(
        _sphere_cap, {"radius": 4.0}, _fixed(((-0.6, 0.6), (-0.6, 0.6))), _check_sphere,
        "Cap of the sphere of the given radius centred at the origin, around the pole "
        "(0, 0, radius), K = 1/radius^2 > 0. r = radius * d/|d| with d = (tan u, tan v, 1): "
        "u, v are angles (radians), |u|, |v| < pi/2 (the hemisphere)."),
    "hyperboloid": _Spec(
        _hyperboloid, {"a": 2.0, "b": 2.0, "c": 2.0}, _fixed(((-0.8, 0.8), (-0.8, 0.8))),
        _check_hyperboloid,
        "Hyperboloid of one sheet x^2/a^2 + y^2/b^2 - z^2/c^2 = 1, K < 0: "
        "r = (a cosh u cos v, b cosh u sin v, c sinh u); u along the axis, v an angle."),
    "quarter_vase": _Spec(
        _quarter_vase, {"radius": 2.0, "amplitude": 0.5, "wavelength": 8.0},
        lambda p: ((-p["wavelength"] / 4, p["wavelength"] / 4), (-math.pi / 4, math.pi / 4)),
        _check_vase,
        "Quarter turn of the surface of revolution with profile radius "
        "rho(z) = radius + amplitude sin(2 pi z / wavelength): r = (rho(u) cos v, "
        "rho(u) sin v, u). The default domain spans half a wavelength around z = 0, where "
        "rho'' and hence K change sign."),
    "saddle": _Spec(
        _saddle, {"a": 4.0, "b": 4.0}, _fixed(((-2.0, 2.0), (-2.0, 2.0))), _check_ab,
        "Hyperbolic paraboloid z = u^2/(2a) - v^2/(2b) over (x, y) = (u, v), K < 0."),
    "cylinder": _Spec(
        _cylinder, {"radius": 3.0}, _fixed(((-2.0, 2.0), (-0.7, 0.7))), _check_cylinder,
        "Circular cylinder r = (radius sin v, u, radius cos v) about the y axis, K = 0, "
        "|H| = 1/(2 radius); u along the axis, v an angle."),
    "paraboloid": _Spec(
        _paraboloid, {"a": 4.0, "b": 4.0}, _fixed(((-2.0, 2.0), (-2.0, 2.0))), _check_ab,
        "Elliptic paraboloid z = u^2/(2a) + v^2/(2b) over (x, y) = (u, v), K > 0."),
    "ellipsoid_cap": _Spec(
        _ellipsoid_cap, {"a": 3.0, "b": 4.0, "c": 2.5}, _fixed(((-0.6, 0.6), (-0.6, 0.6))),
        _check_ellipsoid,
        "Cap of the ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 around (0, 0, c), the radial "
        "projection of (tan u, tan v, 1); |u|, |v| < pi/2."),
    "torus_patch": _Spec(
        _torus_patch, {"R": 4.0, "r": 1.5},
        _fixed(((-0.6, 0.6), (math.pi / 2 - 0.8, math.pi / 2 + 0.8))), _check_torus,
        "Patch of the torus r = ((R + r cos v) cos u, (R + r cos v) sin u, r sin v), "
        "K = cos v / (r (R + r cos v)); the default patch straddles the top circle v = pi/2, "
        "so K changes sign."),
    "gaussian_bump": _Spec(
        _gaussian_bump, {"height": 1.0, "width": 1.0}, _fixed(((-3.0, 3.0), (-3.0, 3.0))),
        _check_bump, "Graph z = height exp(-(u^2 + v^2) / (2 width^2)) over (x, y) = (u, v)."),
    "plane": _Spec(_plane, {}, _fixed(((-2.0, 2.0), (-2.0, 2.0))), _check_nothing,
                   "The plane z = 0 over (x, y) = (u, v)."),
}


def _check_root(root: Any) -> Path | None:
    """A folder argument: None, a string or a path."""
    if root is not None and not isinstance(root, (str, Path)):
        raise SurfaceError(f"root must be a folder (a string or a path) or None, got "
                           f"{describe_value(root)}")
    return None if root is None else Path(root)


def names() -> list[str]:
    """Names of the built-in surfaces."""
    return list(_BUILTINS)


def describe(name: str) -> str:
    """Description of a built-in surface, its parameters and their defaults."""
    spec = _spec(name)
    defaults = ", ".join(f"{k}={v}" for k, v in spec.defaults.items()) or "no parameters"
    domain = spec.domain(spec.defaults)
    return f"{name}: {spec.doc} Parameters: {defaults}; default domain {domain}."


def get(name: str, domain: Any = None, **params: float) -> Surface:
    """The built-in surface ``name`` with ``params`` overriding its defaults (see
    :func:`describe`) and an optional domain ((u0, u1), (v0, v1))."""
    spec = _spec(name)
    unknown = sorted(set(params) - set(spec.defaults))
    if unknown:
        valid = ", ".join(spec.defaults) or "none"
        raise SurfaceError(f"unknown parameter(s) {', '.join(unknown)} for surface {name!r}; "
                           f"valid parameters: {valid} (and domain)")
    values = {k: _checked_value(params.get(k, default), Key("number"), k)
              for k, default in spec.defaults.items()}
    return _Builtin(name, spec, values, domain)


def _spec(name: str) -> _Spec:
    if not isinstance(name, str):
        raise SurfaceError(f"name must be the name of a built-in surface (one of "
                           f"{', '.join(_BUILTINS)}), got {describe_value(name)}")
    if name not in _BUILTINS:
        shown = repr(name) if shown_name(name) == name else shown_name(name)
        raise SurfaceError(f"unknown surface {shown}; built-in surfaces: {', '.join(_BUILTINS)}"
                           f" (or use python = \"module:function\" for your own)")
    return _BUILTINS[name]


#: ``domain = [[u0, u1], [v0, v1]]`` of a [target] table.
DOMAIN_KEY = Key("list", length=2, item=Key("list", length=2, item=Key("number")),
                 hint="([[u0, u1], [v0, v1]])")
#: The count of a grid's parameter values along one direction.
_GRID = Key("whole", low=2, high=MAX_GRID)
#: ``spacing = (s_i, s_j)`` of :meth:`Surface.lattice`.
_SPACING = Key("list", length=2, item=Key("number", low=0, low_open=True), hint="(s_i, s_j)")
#: The keys of a [target] table with python = ...
PYTHON_KEYS = {"python": Key("string", required=True),
               "domain": Key("list", length=2, item=DOMAIN_KEY.item, required=True,
                             hint=DOMAIN_KEY.hint)}
#: The keys of a [target] table with mesh = ... (a mesh or point cloud file: :class:`Mesh`)
MESH_KEYS = {"mesh": Key("string", required=True)}


def target_keys(name: str) -> dict[str, Key]:
    """The keys of a [target] table naming the built-in ``name``: name, domain and its
    parameters."""
    return {"name": Key("choice", choices=tuple(_BUILTINS)), "domain": DOMAIN_KEY,
            **{param: Key("number") for param in _spec(name).defaults}}


def from_config(table: Mapping[str, Any], root: str | Path | None = None,
                trust: bool = False) -> Surface:
    """The surface of a ``[target]`` table: ``name = "..."`` plus parameters and an optional
    ``domain = [[u0, u1], [v0, v1]]``, or ``python = "file.py:function"`` (a file relative to
    ``root``, default the current folder) or ``python = "package.module:function"``, plus a
    required ``domain``, or ``mesh = "part.stl"`` (a mesh or point cloud file relative to
    ``root``: its :class:`Mesh`, by its absolute path).

    Code named by ``python`` runs only with ``trust=True`` (a target file from someone else
    must not run code unless asked to); without it :class:`SurfaceError` names the code.
    Without it too, a ``mesh`` must lie in ``root`` or below
    (:func:`rffqm_nlp.files.named_path`).
    Every key is checked (:func:`rffqm_nlp.files.check_table`).
    """
    if not isinstance(table, Mapping):
        raise SurfaceError(f"[target] must be a table, got {describe_value(table)}")
    root = _check_root(root)
    trust = _checked_value(trust, Key("bool"), "trust")
    if not rebuildable(table):
        raise SurfaceError(
            f"[target] cannot be rebuilt: the target of this result was {table.get('made_from')} "
            "and no config names it; rebuild the problem by passing the surface: "
            "DesignProblem(target=<your surface>, **result.problem['design']), or in a file "
            "name a function with python = \"file.py:function\" and domain")
    if "mesh" in table:
        mesh = _checked(table, MESH_KEYS)["mesh"]
        try:
            path = named_path(root or ".", mesh, "[target] mesh", trust)
        except InputError as exc:
            raise SurfaceError(str(exc)) from None
        return Mesh(Path(os.path.abspath(path)))
    if "python" in table and "name" in table:
        raise SurfaceError("[target] takes name (a built-in surface) or python (your own "
                           "function), not both")
    if "python" in table:
        values = _checked(table, PYTHON_KEYS)
        ref = resolve_reference(values["python"], root)
        if not trust:
            raise SurfaceError(f"[target] python = \"{ref}\" {_code_of(ref)}; pass --trust "
                               "(trust=True in the API) if you trust that file")
        return Custom(_import_reference(ref), values["domain"], reference=ref)
    if "name" not in table:
        raise SurfaceError("the [target] table needs name = \"<surface>\" (one of "
                           f"{', '.join(_BUILTINS)}), python = \"file.py:function\" or "
                           "mesh = \"part.stl\"")
    name = _checked_value(table["name"], Key("choice", choices=tuple(_BUILTINS)), "[target] name")
    values = _checked(table, target_keys(name))
    values.pop("name")
    return get(name, values.pop("domain", None), **values)


def config_of(surface: Surface) -> dict:
    """The ``[target]`` table of ``surface`` (:meth:`Surface.to_config`), or, for a surface
    that no table can name (a lambda, a closure, a :class:`Mesh` made from arrays), the
    record ``{"name", "domain", "rebuildable": False, "made_from"}``, which
    :func:`from_config` refuses with a one-line reason."""
    check_surface(surface, "surface")
    try:
        return surface.to_config()
    except SurfaceError:
        pass
    if isinstance(surface, Custom):
        fn = surface._fn
        made_from = (f"the Python callable {getattr(fn, '__module__', '?')}."
                     f"{getattr(fn, '__qualname__', type(fn).__name__)}")
    else:
        made_from = f"a {type(surface).__name__} made in Python, not from a file"
    return {"name": surface.name, "domain": _domain_list(surface.domain),
            "rebuildable": False, "made_from": made_from}


def rebuildable(table: Mapping[str, Any]) -> bool:
    """Whether a ``[target]`` table names its surface (not a record of :func:`config_of`)."""
    if not isinstance(table, Mapping):
        raise SurfaceError(f"[target] must be a table, got {describe_value(table)}")
    return "rebuildable" not in table


def _checked(table: Mapping[str, Any], spec: dict[str, Key]) -> dict[str, Any]:
    """check_table for [target], raising SurfaceError."""
    try:
        return check_table(table, spec, "[target]")
    except InputError as exc:
        raise SurfaceError(str(exc)) from None


def _checked_value(value: Any, key: Key, name: str) -> Any:
    return check_value(value, key, name, SurfaceError)


# -- validation helpers -------------------------------------------------------------------


def _check_domain(domain: Any) -> Domain:
    (u0, u1), (v0, v1) = _checked_value(domain, DOMAIN_KEY, "domain")
    for name, a, b in (("u", u0, u1), ("v", v0, v1)):
        if not a < b:
            raise SurfaceError(f"the {name} range ({a}, {b}) of the domain is empty or "
                               f"inverted; give {name}0 < {name}1")
    return (u0, u1), (v0, v1)


def _domain_list(dom: Domain) -> list[list[float]]:
    return [list(dom[0]), list(dom[1])]


def _solve_extent(residual: Callable[[float], float], most: float) -> float:
    """Half-extent x in (0, most] with residual(x) = 0 (residual(0) < 0, increasing)."""
    if residual(most) <= 0:
        return most
    return brentq(residual, 0.0, most, xtol=1e-15 * most, rtol=4 * np.finfo(float).eps)


# meshes and point clouds as targets (rffqm_nlp.targets.meshes); last: meshes imports this
from .meshes import Mesh  # noqa: E402
