"""Discrete shape measures: coarse-graining, finite-difference fundamental forms, rigid
alignment and distances between a folded lattice and its target (docs/paper.md s.8).

Lattice arguments come in one of two forms, and results come back in the same form:

* an (n, m, 3) NumPy array of points;
* a sequence of three 2-D (n, m) matrices (the x, y, z components), NumPy arrays or CasADi
  SX/MX/DM matrices; only slicing, +, -, *, / and sqrt are used, so the functions build CasADi
  graphs when given symbols.

The lattice is the paper's integer lattice r(i, j) with parameter spacings hu (along i) and
hv (along j), both 1 by default.

Numeric arguments are checked (finite real numbers of the shapes said; a target a
:class:`~rffqm_nlp.targets.surfaces.Surface` or points), and so are numeric results: a lattice with
no finite result (a degenerate one, or coordinates so large that their products overflow)
raises :class:`~rffqm_nlp.errors.InputError` instead of giving NaN or infinity.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import directed_hausdorff

from ..model.backend import finite_array, finite_result, is_casadi, math_for
from ..errors import InputError
from ..files import Key, check_value, describe_value
from .parametric import Surface, check_surface
from .point_sets import point_set_diameter

Lattice = Any  # (n, m, 3) ndarray or a sequence of three (n, m) matrices
Forms = tuple[Any, Any, Any, Any, Any, Any]

# -- lattice representation ---------------------------------------------------------------


def _split(P: Lattice) -> tuple[list, bool]:
    """(components [x, y, z], stacked) where stacked says P was an (n, m, 3) array."""
    if isinstance(P, np.ndarray) and P.ndim == 3:
        if P.shape[2] != 3:
            raise InputError(f"a lattice array must have shape (n, m, 3), got {P.shape}")
        P = finite_array(P, "the lattice", allowed="an (n, m, 3) array of finite numbers")
        return [P[..., k] for k in range(3)], True
    if isinstance(P, Sequence) and not isinstance(P, str) and len(P) == 3:
        comps = [c if is_casadi(c) else finite_array(
            c, f"the lattice's component {k}", ndim=2, allowed="an (n, m) matrix of finite "
            "numbers") for k, c in enumerate(P)]
        if any(len(c.shape) != 2 or c.shape != comps[0].shape for c in comps):
            raise InputError("a lattice given by components needs three 2-D matrices of one "
                             f"shape, got shapes {[tuple(c.shape) for c in comps]}")
        return comps, False
    raise InputError("a lattice must be an (n, m, 3) array or a sequence of three (n, m) "
                     f"matrices (x, y, z), got {describe_value(P)}")


def _join(comps: Sequence[Any], stacked: bool) -> Any:
    """Components back into the caller's form (an (..., 3) array or a tuple)."""
    return np.stack(comps, axis=-1) if stacked else tuple(comps)


def _sqrt(x: Any) -> Any:
    """Elementwise square root of a NumPy array or a CasADi matrix."""
    return math_for(x).sqrt(x)


def _dot(a: Sequence[Any], b: Sequence[Any]) -> Any:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: Sequence[Any], b: Sequence[Any]) -> list:
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _shift(c: Any, di: int, dj: int, n: int, m: int, ci: int = 1, cj: int = 1) -> Any:
    """c[i+di, j+dj] for the rows i in ci..n-1-ci and the columns j in cj..m-1-cj."""
    return c[ci + di:n - ci + di, cj + dj:m - cj + dj]


def coarse_grain(Y: Lattice) -> Lattice:
    """r(i, j) = y^{(2i)(2j)}: every second vertex of a (2N+1, 2M+1) folded lattice, giving
    (N+1, M+1) points (docs/paper.md s.8; indices from 0)."""
    comps, stacked = _split(Y)
    n, m = comps[0].shape
    if n % 2 == 0 or m % 2 == 0:
        raise InputError(f"coarse_grain needs a (2N+1, 2M+1) vertex lattice (odd sizes, from "
                         f"2N x 2M panels), got {n} x {m}")
    return _join([c[0:n:2, 0:m:2] for c in comps], stacked)


# -- finite differences -------------------------------------------------------------------


def fundamental_forms(P: Lattice, hu: float = 1.0, hv: float = 1.0) -> Forms:
    """Discrete (E, F, G, L, M, N) at the interior points, each (n-2, m-2).

    Central differences r_u = (r[i+1,j] - r[i-1,j]) / (2 hu), r_v likewise,
    r_uu = (r[i+1,j] - 2 r[i,j] + r[i-1,j]) / hu^2, r_vv likewise,
    r_uv = (r[i+1,j+1] - r[i+1,j-1] - r[i-1,j+1] + r[i-1,j-1]) / (4 hu hv), unit normal
    n = r_u x r_v / |r_u x r_v|; E = r_u.r_u, F = r_u.r_v, G = r_v.r_v, L = r_uu.n,
    M = r_uv.n, N = r_vv.n. Second-order accurate in hu, hv. The stencils skip the centre
    point in r_u, r_v and only see second differences through n, so this loss alone is blind
    to tangential offsets between the four parity classes (i mod 2, j mod 2): combine it with
    a term that sees them, such as the design's position term (docs/paper.md s.8).
    """
    comps, _ = _split(P)
    hu = check_value(hu, Key("number", low=0.0, low_open=True, hint="(a spacing)"), "hu")
    hv = check_value(hv, Key("number", low=0.0, low_open=True, hint="(a spacing)"), "hv")
    n, m = comps[0].shape
    if n < 3 or m < 3:
        raise InputError(f"fundamental_forms needs a lattice of at least 3 x 3 points, got "
                         f"{n} x {m}")
    if is_casadi(*comps):
        return _forms(comps, hu, hv)
    with np.errstate(all="ignore"):
        forms = _forms(comps, hu, hv)
    return finite_result(forms, "fundamental_forms has no finite value: the lattice is "
                                "degenerate (r_u x r_v = 0 at an interior point) or its "
                                "coordinates are too large for floating point")


def _forms(comps: list, hu: float, hv: float) -> Forms:
    """The forms of :func:`fundamental_forms` from the components."""
    n, m = comps[0].shape

    def at(di: int, dj: int) -> list:
        return [_shift(c, di, dj, n, m) for c in comps]

    c0, ip, im, jp, jm = at(0, 0), at(1, 0), at(-1, 0), at(0, 1), at(0, -1)
    pp, pm, mp, mm = at(1, 1), at(1, -1), at(-1, 1), at(-1, -1)
    r_u = [(a - b) / (2 * hu) for a, b in zip(ip, im)]
    r_v = [(a - b) / (2 * hv) for a, b in zip(jp, jm)]
    r_uu = [(a - 2 * c + b) / hu**2 for a, c, b in zip(ip, c0, im)]
    r_vv = [(a - 2 * c + b) / hv**2 for a, c, b in zip(jp, c0, jm)]
    r_uv = [(a - b - c + d) / (4 * hu * hv) for a, b, c, d in zip(pp, pm, mp, mm)]
    cross = _cross(r_u, r_v)
    norm = _sqrt(_dot(cross, cross))
    normal = [c / norm for c in cross]
    return (_dot(r_u, r_u), _dot(r_u, r_v), _dot(r_v, r_v),
            _dot(r_uu, normal), _dot(r_uv, normal), _dot(r_vv, normal))


# -- rigid alignment ----------------------------------------------------------------------


def _points(P: Any, what: str) -> tuple[np.ndarray, tuple[int, ...]]:
    """(k, 3) numeric points of a (k, 3) array, an (n, m, 3) lattice or a component triple,
    and the (..., 3) shape they came in."""
    allowed = "finite points of shape (k, 3) or (n, m, 3), at least one"
    if (isinstance(P, Sequence) and not isinstance(P, str) and len(P) == 3
            and not is_casadi(*P) and all(np.ndim(c) == 2 for c in P)
            and len({np.shape(c) for c in P}) == 1):
        P = np.stack([finite_array(c, what, allowed=allowed) for c in P], axis=-1)
    arr = finite_array(P, what, allowed=allowed)
    if arr.shape[-1:] != (3,) or arr.ndim < 2 or arr.size == 0:
        raise InputError(f"{what} must be {allowed}, got shape {arr.shape}")
    return arr.reshape(-1, 3), arr.shape


def kabsch(P: Any, Q: Any, reflection: bool = False) -> tuple[np.ndarray, np.ndarray, float]:
    """(R, t, rms) minimising sum_k |R p_k + t - q_k|^2 over rotations R (orthogonal R if
    ``reflection``) and translations t, for corresponding points P, Q ((k, 3) or lattices);
    rms = sqrt(mean_k |R p_k + t - q_k|^2)."""
    (p, _), (q, _) = _points(P, "P"), _points(Q, "Q")
    if p.shape != q.shape:
        raise InputError(f"kabsch needs corresponding points, got {len(p)} and {len(q)}")
    reflection = check_value(reflection, Key("bool"), "reflection")
    pc, qc = p.mean(axis=0), q.mean(axis=0)
    with np.errstate(all="ignore"):
        H = (p - pc).T @ (q - qc)
    finite_result(H, "kabsch: the points are too large for floating point (their products "
                     "overflow); scale them down")
    u, _, vt = np.linalg.svd(H)
    d = np.ones(3)
    if not reflection:
        d[2] = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    R = vt.T @ np.diag(d) @ u.T
    t = qc - R @ pc
    with np.errstate(all="ignore"):
        rms = float(np.sqrt(np.mean(np.sum((p @ R.T + t - q) ** 2, axis=1))))
    return finite_result((R, t, rms), "kabsch: the points are too large for floating point "
                                      "(their distances overflow); scale them down")


def align(P: Any, Q: Any, reflection: bool = False) -> np.ndarray:
    """P moved rigidly (see :func:`kabsch`) onto Q, in P's (k, 3) or (n, m, 3) shape."""
    R, t, _ = kabsch(P, Q, reflection)
    p, shape = _points(P, "P")
    return (p @ R.T + t).reshape(shape)


# -- distances ----------------------------------------------------------------------------


def distances_to(points: Any, target: Surface | Any) -> np.ndarray:
    """Distance from each of ``points`` ((..., 3), or a component triple) to the target,
    shape (...): to its closest point on a Surface (:meth:`Surface.closest_points`; on a
    :class:`~rffqm_nlp.targets.meshes.Mesh` made from a mesh, on its triangles), or to the nearest
    of a point set ((k, 3) or (n, m, 3); scipy's cKDTree)."""
    pts, shape = _points(points, "points")
    if isinstance(target, Surface):
        dist = target.closest_points(pts)[2]
    else:
        dist = cKDTree(_points(target, "target points")[0]).query(pts)[0]
    return _finite_distances(np.asarray(dist, dtype=float).reshape(shape[:-1]))


def _finite_distances(value: Any) -> Any:
    """Distances (or their summaries) unless one overflowed."""
    return finite_result(value, "the distances overflow: the points are too far from the "
                                "target for floating point")


def rms_distance(points: Any, target: Surface | Any) -> float:
    """sqrt(mean d^2) of the distances d from each point to the target.

    For a Surface, d is the distance to its closest point over the domain
    (:meth:`Surface.closest_points`: nearest point of a 101 x 101 sample, refined by
    Gauss-Newton on r(u, v), accurate to round-off); for a point set, to the nearest point.
    Points are not aligned first: use :func:`align` for that.
    """
    d = distances_to(points, target)
    with np.errstate(all="ignore"):
        return _finite_distances(float(np.sqrt(np.mean(d**2))))


def hausdorff_distance(points: Any, target: Surface | Any) -> float:
    """Hausdorff distance: one-sided max_p dist(p, surface) for a Surface target (closest
    points as in :func:`rms_distance`), symmetric for two point sets."""
    if isinstance(target, Surface):
        return float(distances_to(points, target).max())
    p, q = _points(points, "points")[0], _points(target, "target points")[0]
    with np.errstate(all="ignore"):
        return _finite_distances(float(max(directed_hausdorff(p, q)[0],
                                           directed_hausdorff(q, p)[0])))


def relative_fit(points: Any, target: Surface | Any) -> dict[str, float]:
    """{"rms": ..., "hausdorff": ...} of :func:`rms_distance` and :func:`hausdorff_distance`
    divided by the target's diameter (:meth:`Surface.diameter`, or the largest distance
    between two target points)."""
    diameter = (target.diameter() if isinstance(target, Surface)
                else point_set_diameter(_points(target, "target points")[0]))
    if not diameter > 0:
        raise InputError("the target has zero diameter, so a relative fit is undefined")
    return {"rms": rms_distance(points, target) / diameter,
            "hausdorff": hausdorff_distance(points, target) / diameter}


# -- areas --------------------------------------------------------------------------------

#: Composite Gauss-Legendre rule of :func:`surface_area`: cells per direction, nodes per cell.
AREA_CELLS, AREA_ORDER = 16, 4


def lattice_area(P: Any) -> float:
    """Area of the lattice (n, m, 3) as a surface of two triangles per cell (each cell split
    along its diagonal (i, j)-(i+1, j+1))."""
    flat, shape = _points(P, "lattice")
    if len(shape) != 3:
        raise InputError(f"lattice_area needs an (n, m, 3) lattice, got shape {shape}")
    pts = flat.reshape(shape)
    a, b, c, d = pts[:-1, :-1], pts[1:, :-1], pts[1:, 1:], pts[:-1, 1:]
    with np.errstate(all="ignore"):
        first = np.linalg.norm(np.cross(b - a, c - a), axis=-1)
        second = np.linalg.norm(np.cross(c - a, d - a), axis=-1)
        area = float(0.5 * (first.sum() + second.sum()))
    return finite_result(area, "lattice_area overflows: the lattice's coordinates are too "
                               "large for floating point")


def surface_area(target: Surface) -> float:
    """Area of r(u, v) over the target's domain: the integral of |r_u x r_v| by a composite
    Gauss-Legendre rule (:data:`AREA_CELLS` cells of :data:`AREA_ORDER` nodes per direction)
    with the surface's exact derivatives. For a :class:`~rffqm_nlp.targets.meshes.Mesh` this is the
    area of its fitted spline over the domain."""
    check_surface(target, "target")
    nodes, weights = np.polynomial.legendre.leggauss(AREA_ORDER)
    (u0, u1), (v0, v1) = target.domain

    def rule(lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
        edges = np.linspace(lo, hi, AREA_CELLS + 1)
        half = np.diff(edges)[:, None] / 2
        x = (edges[:-1, None] + half) + half * nodes[None, :]
        return x.ravel(), (half * weights[None, :]).ravel()

    (u, wu), (v, wv) = rule(u0, u1), rule(v0, v1)
    r_u, r_v = target.derivatives(u[:, None], v[None, :])
    with np.errstate(all="ignore"):
        area = float(np.sum(np.linalg.norm(np.cross(r_u, r_v), axis=-1)
                            * wu[:, None] * wv[None, :]))
    return finite_result(area, f"the area of {target.name!r} overflows: its coordinates are "
                               "too large for floating point")


def shape_fit(folded: np.ndarray, target: Surface) -> dict[str, float]:
    """Fits of an aligned folded state (2N+1, 2M+1, 3) against the target's shape (closest
    points on the surface, or on the mesh for a :class:`~rffqm_nlp.targets.meshes.Mesh`), over the
    diameter: ``rms_surface``, ``hausdorff`` of the coarse lattice ``folded[::2, ::2]``,
    ``rms_surface_vertices``, ``hausdorff_vertices`` of every vertex, and ``coverage``: the
    coarse lattice's :func:`lattice_area` over the target's :func:`surface_area`."""
    check_surface(target, "target")
    shape = _points(folded, "folded")[1]
    if len(shape) != 3:
        raise InputError(f"shape_fit needs a folded state (2N+1, 2M+1, 3), got shape {shape}")
    # one closest-point query for every vertex; the coarse lattice is a subset of them
    dist = distances_to(folded, target) / target.diameter()
    coarse = dist[::2, ::2]
    return {"rms_surface": float(np.sqrt(np.mean(coarse ** 2))), "hausdorff": float(coarse.max()),
            "rms_surface_vertices": float(np.sqrt(np.mean(dist ** 2))),
            "hausdorff_vertices": float(dist.max()),
            "coverage": lattice_area(coarse_grain(folded)) / surface_area(target)}
