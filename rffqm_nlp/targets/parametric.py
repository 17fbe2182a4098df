"""The parametric surface r(u, v) every target is (docs/paper.md s.8): :class:`Surface`.

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

The built-ins (:mod:`.builtins`), :class:`~rffqm_nlp.targets.custom.Custom` and
:class:`~rffqm_nlp.targets.meshes.Mesh` are its subclasses; users reach them all as
``rq.surfaces`` (:mod:`.surfaces`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from functools import cached_property
from typing import Any

import casadi as ca
import numpy as np
import trimesh
from scipy.optimize import brentq
from scipy.spatial import cKDTree

from ..errors import SurfaceError
from ..files import Key, check_value, describe_value
from ..model import backend
from ..model.backend import finite_array, finite_result
from .point_sets import (GRID, MAX_GRID, grid_faces, mean_neighbour_distances,
                         point_set_diameter, refuse_points)

Domain = tuple[tuple[float, float], tuple[float, float]]

#: The math for a surface function's arguments (``m = mathlib(u, v); m.sin(u)``): CasADi's
#: functions if any argument is a CasADi object, else NumPy's. Both namespaces have ``sin,
#: cos, tan, atan, atan2, sqrt, exp, log, sinh, cosh, tanh, fabs, where, pi``. This is
#: :func:`rffqm_nlp.model.backend.math_for`, under the name surface functions use.
mathlib = backend.math_for

#: Grid (per direction) on which a new surface is checked to be finite and regular.
_CHECK_GRID = 21
#: Grid (per direction) of the sample whose largest point distance is the diameter and
#: whose nearest point starts :meth:`Surface.closest_points` at its default resolution.
SAMPLE_GRID = 101
#: Newton steps of :meth:`Surface.closest_points` at most, and step halvings in each.
NEWTON_STEPS, HALVINGS = 100, 30
#: A point has converged when its step moves it by at most this fraction of the domain.
CONVERGED = 1e-15
#: Steps up to this fraction of the domain are taken without asking that they bring the point
#: closer: Newton's model is exact to round-off there, and the distance, flat to second order
#: about the closest point, can no longer be told apart from its rounding.
SMALL_STEP = 1e-8
#: |r_u x r_v| below this times mean |r_u| * mean |r_v| counts as singular.
_REGULARITY_TOL = 1e-9
#: ``domain = [[u0, u1], [v0, v1]]`` of a [target] table.
DOMAIN_KEY = Key("list", length=2, item=Key("list", length=2, item=Key("number")),
                 hint="([[u0, u1], [v0, v1]])")
#: ``spacing = (s_i, s_j)`` of :meth:`Surface.lattice`.
_SPACING = Key("list", length=2, item=Key("number", low=0, low_open=True), hint="(s_i, s_j)")


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
        self.name = checked_value(name, Key("string"), "name")
        self.params = checked_value(params, Key("table", item=Key("number")), "params")
        self.domain = check_domain(domain)
        self._check_regular()

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        raise SurfaceError(f"{type(self).__name__} has no r(u, v): subclass Surface with "
                           "_r(u, v), or use surfaces.Custom(fn, domain) or surfaces.get(name)")

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.params.items())
        return f"<Surface {self.name}({args}) on {self.domain}>"

    # -- the AD graph -------------------------------------------------------------------
    @cached_property
    def _functions(self) -> tuple[ca.Function, ca.Function, ca.Function, ca.Function]:
        """(r, geometry, second derivatives, first derivatives) CasADi Functions of (u, v),
        built once from one SX graph."""
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
        second = ca.Function("second", [u, v], [ca.vertcat(r, r_u, r_v, r_uu, r_uv, r_vv)],
                             ["u", "v"], ["derivatives"])
        first = ca.Function("first", [u, v], [r_u, r_v], ["u", "v"], ["r_u", "r_v"])
        return point, geometry, second, first

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
        shape, (r_u, r_v) = self._evaluate(self._functions[3], u, v)
        return r_u.T.reshape(shape + (3,)), r_v.T.reshape(shape + (3,))

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
        n_u, n_v = (checked_value(n, GRID, k) for n, k in ((n_u, "n_u"), (n_v, "n_v")))
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
        return point_set_diameter(self._reference_sample)

    @cached_property
    def _reference_sample(self) -> np.ndarray:
        """The :data:`SAMPLE_GRID` x :data:`SAMPLE_GRID` :meth:`sample` (cached): the
        diameter's points and the start of :meth:`closest_points`."""
        return self.sample(SAMPLE_GRID, SAMPLE_GRID)

    @cached_property
    def _reference_tree(self) -> cKDTree:
        """A k-d tree on the points of :attr:`_reference_sample` (cached)."""
        return cKDTree(self._reference_sample.reshape(-1, 3))

    def lattice_uv(self, N: int, M: int,
                   spacing: tuple[float, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Parameters (u (N+1,), v (M+1,)) of the lattice (0..N) x (0..M) (docs/paper.md s.8).

        With ``spacing=None`` the lattice spans the whole domain, uniform in parameter space.
        With ``spacing=(s_i, s_j)`` it spans a sub-rectangle centred in the domain, uniform in
        parameter space, whose half-extents are chosen (brentq, alternating between the two
        directions) so that the mean distance between lattice neighbours along i is s_i and
        along j is s_j.
        """
        N, M = (checked_value(n, Key("whole", low=1, high=MAX_GRID - 1), k)
                for n, k in ((N, "N"), (M, "M")))
        if spacing is None:
            return self.grid_uv(N + 1, M + 1)
        s_i, s_j = checked_value(spacing, _SPACING, "spacing")
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

    def closest_points(self, points: Any, resolution: int = SAMPLE_GRID
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Closest points of the surface (over its domain) to ``points`` (..., 3).

        A nearest-neighbour search on the (resolution x resolution) :meth:`sample` (cached
        at the default resolution) gives the start, then Newton's method on |r(u, v) - p|^2
        with the AD derivatives and the domain as box constraints converges to the closest
        point, to round-off for points whose closest point is regular
        (:meth:`_project`). Returns (uv (..., 2), closest (..., 3), distances (...)).
        """
        pts = finite_array(points, "points", allowed="a finite array of shape (..., 3)",
                           error=SurfaceError)
        if pts.shape[-1:] != (3,):
            raise SurfaceError(f"points must be a finite array of shape (..., 3), got shape "
                               f"{pts.shape}")
        shape, pts = pts.shape[:-1], pts.reshape(-1, 3)
        resolution = checked_value(resolution, GRID, "resolution")
        refuse_points(resolution * resolution, 12, f"a {resolution} x {resolution} sample")
        tree = (self._reference_tree if resolution == SAMPLE_GRID
                else cKDTree(self.sample(resolution, resolution).reshape(-1, 3)))
        u, v = self.grid_uv(resolution, resolution)
        idx = tree.query(pts)[1] if len(pts) else np.zeros(0, dtype=np.int64)
        uv, closest = self._project(pts, u[idx // resolution], v[idx % resolution])
        with np.errstate(all="ignore"):
            dist = np.linalg.norm(closest - pts, axis=1)
        finite_result(dist, "the distances to the surface overflow: the points are too far "
                            "from it for floating point")
        return (uv.reshape(shape + (2,)), closest.reshape(shape + (3,)), dist.reshape(shape))

    def _derivatives(self, uu: np.ndarray, vv: np.ndarray) -> np.ndarray:
        """(r, r_u, r_v, r_uu, r_uv, r_vv) at (u, v) (n,) each: (6, n, 3)."""
        _, (out,) = self._evaluate(self._functions[2], uu, vv)
        return out.reshape(6, 3, -1).transpose(0, 2, 1)

    def _project(self, pts: np.ndarray, uu: np.ndarray, vv: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """The closest points to ``pts`` (n, 3) from the starts (u, v) (n,): their (u, v)
        (n, 2) and r(u, v) (n, 3). Projected Newton steps (:func:`_newton_steps`) with step
        halving, in one evaluation of the derivatives at all the points still moving per
        step, until a step moves a point by at most :data:`CONVERGED` of the domain."""
        (u0, u1), (v0, v1) = self.domain
        span = np.array([u1 - u0, v1 - v0])
        uv = np.stack([uu, vv], axis=1).astype(float)
        der = self._derivatives(uv[:, 0], uv[:, 1])
        active = np.arange(len(pts))  # the points still moving
        for _ in range(NEWTON_STEPS):
            step = _newton_steps(der[:, active], pts[active], uv[active], self.domain)
            move = np.max(np.abs(step) / span, axis=1)
            active, step, move = active[move > CONVERGED], step[move > CONVERGED], \
                move[move > CONVERGED]
            if active.size == 0:
                break
            dist = np.linalg.norm(der[0, active] - pts[active], axis=1)
            t = np.ones(len(active))
            todo = np.arange(len(active))  # the points whose step is not yet taken
            for _ in range(HALVINGS):
                k = active[todo]
                trial = np.clip(uv[k] + t[todo, None] * step[todo], (u0, v0), (u1, v1))
                new = self._derivatives(trial[:, 0], trial[:, 1])
                ok = ((np.linalg.norm(new[0] - pts[k], axis=1) <= dist[todo])
                      | (t[todo] * move[todo] <= SMALL_STEP))
                uv[k[ok]], der[:, k[ok]] = trial[ok], new[:, ok]
                todo = todo[~ok]
                if todo.size == 0:
                    break
                t[todo] /= 2
            active = np.setdiff1d(active, active[todo], assume_unique=True)  # stuck: done
        return uv, der[0]

    # -- configuration ------------------------------------------------------------------
    def to_config(self) -> dict:
        """The ``[target]`` table that :func:`from_config` turns back into this surface."""
        return {"name": self.name, **self.params, "domain": domain_list(self.domain)}

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


def _newton_steps(der: np.ndarray, pts: np.ndarray, uv: np.ndarray, domain: Domain
                 ) -> np.ndarray:
    """Steps (n, 2) in (u, v) towards the closest points of r to ``pts`` (n, 3) from the
    parameters ``uv`` (n, 2), where ``der`` (6, n, 3) holds (r, r_u, r_v, r_uu, r_uv, r_vv):
    Newton's step on f = |r - p|^2 / 2 (gradient g = (r_u . e, r_v . e), e = r - p; Hessian
    the first form plus e . r_uu, e . r_uv, e . r_vv) where that Hessian is positive
    definite, else the Gauss-Newton step (the first form alone). A parameter on a bound of
    ``domain`` whose gradient points out of the domain stays there (the step solves for the
    other parameter alone)."""
    r, r_u, r_v, r_uu, r_uv, r_vv = der
    e = r - pts
    g_u, g_v = np.sum(r_u * e, 1), np.sum(r_v * e, 1)
    E, F, G = np.sum(r_u * r_u, 1), np.sum(r_u * r_v, 1), np.sum(r_v * r_v, 1)
    h_uu, h_uv, h_vv = E + np.sum(e * r_uu, 1), F + np.sum(e * r_uv, 1), G + np.sum(e * r_vv, 1)
    newton = (h_uu > 0) & (h_uu * h_vv - h_uv * h_uv > 0)
    h_uu, h_uv, h_vv = (np.where(newton, h, f) for h, f in ((h_uu, E), (h_uv, F), (h_vv, G)))
    det = h_uu * h_vv - h_uv * h_uv
    du, dv = -(h_vv * g_u - h_uv * g_v) / det, -(h_uu * g_v - h_uv * g_u) / det
    (u0, u1), (v0, v1) = domain
    fix_u = ((uv[:, 0] <= u0) & (g_u > 0)) | ((uv[:, 0] >= u1) & (g_u < 0))
    fix_v = ((uv[:, 1] <= v0) & (g_v > 0)) | ((uv[:, 1] >= v1) & (g_v < 0))
    du, dv = np.where(fix_v, -g_u / h_uu, du), np.where(fix_u, -g_v / h_vv, dv)
    return np.stack([np.where(fix_u, 0.0, du), np.where(fix_v, 0.0, dv)], axis=1)


def checked_value(value: Any, key: Key, name: str) -> Any:
    """:func:`rffqm_nlp.files.check_value` raising :class:`SurfaceError`."""
    return check_value(value, key, name, SurfaceError)


def check_domain(domain: Any) -> Domain:
    """``domain`` as ((u0, u1), (v0, v1)): numbers with u0 < u1 and v0 < v1, else
    :class:`SurfaceError`."""
    (u0, u1), (v0, v1) = checked_value(domain, DOMAIN_KEY, "domain")
    for name, a, b in (("u", u0, u1), ("v", v0, v1)):
        if not a < b:
            raise SurfaceError(f"the {name} range ({a}, {b}) of the domain is empty or "
                               f"inverted; give {name}0 < {name}1")
    return (u0, u1), (v0, v1)


def domain_list(dom: Domain) -> list[list[float]]:
    """The domain as a [target] table writes it: [[u0, u1], [v0, v1]]."""
    return [list(dom[0]), list(dom[1])]


def _solve_extent(residual: Callable[[float], float], most: float) -> float:
    """Half-extent x in (0, most] with residual(x) = 0 (residual(0) < 0, increasing)."""
    if residual(most) <= 0:
        return most
    return brentq(residual, 0.0, most, xtol=1e-15 * most, rtol=4 * np.finfo(float).eps)
