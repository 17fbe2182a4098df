"""The smooth surface of a :class:`~rffqm_nlp.targets.meshes.Mesh` (step 4 of
:mod:`.meshes`, which gives the P-spline's objective): a tensor-product cubic B-spline on
uniform knots, fitted by penalised least squares and handed to CasADi as a bspline
interpolant."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
from scipy import sparse
from scipy.interpolate import BSpline

from .parametrization import TIE, solve_spd

#: Fewest and most knot spans per direction.
KNOT_SPANS = (4, 60)


def knot_spans(uv: np.ndarray, per_cell: int) -> tuple[int, int]:
    """Knot spans (n_u, n_v): about per_cell points per cell, cells about square."""
    extent = np.ptp(uv, axis=0)
    cells = len(uv) / per_cell
    aspect = extent[0] / extent[1]
    lo, hi = KNOT_SPANS

    def spans(x: float) -> int:
        """x rounded half to even, x a round-off (TIE) off a half counting as on it."""
        if abs(2 * x - round(2 * x)) <= TIE * x:
            x = round(2 * x) / 2
        return int(np.clip(round(x), lo, hi))

    return spans(math.sqrt(cells * aspect)), spans(math.sqrt(cells / aspect))


def _uniform_knots(lo: float, hi: float, spans: int) -> np.ndarray:
    """Uniform cubic knots (spans + 7,) whose basis is a partition of unity on [lo, hi]."""
    h = (hi - lo) / spans
    return np.r_[lo + h * np.arange(-3, 0), np.linspace(lo, hi, spans + 1),
                 hi + h * np.arange(1, 4)]


def _second_differences(n: int) -> sparse.csr_matrix:
    return sparse.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n)).tocsr()


def _basis(uv: np.ndarray, lo: np.ndarray, hi: np.ndarray, spans: tuple[int, int]
           ) -> sparse.csr_matrix:
    """The tensor-product cubic B-spline basis (n, (spans_u + 3) (spans_v + 3)) on uniform
    knots over [lo, hi] at uv (n, 2) (clipped to it)."""
    t_u, t_v = (_uniform_knots(lo[k], hi[k], spans[k]) for k in range(2))
    n_v = spans[1] + 3
    b_u = BSpline.design_matrix(np.clip(uv[:, 0], lo[0], hi[0]), t_u, 3).tocsr()
    b_v = BSpline.design_matrix(np.clip(uv[:, 1], lo[1], hi[1]), t_v, 3).tocsr()
    n = len(uv)
    iu, iv = b_u.indices.reshape(n, 4), b_v.indices.reshape(n, 4)
    wu, wv = b_u.data.reshape(n, 4), b_v.data.reshape(n, 4)
    cols = (iu[:, :, None] * n_v + iv[:, None, :]).reshape(n, 16)
    vals = (wu[:, :, None] * wv[:, None, :]).reshape(n, 16)
    return sparse.csr_matrix((vals.ravel(), (np.repeat(np.arange(n), 16), cols.ravel())),
                             shape=(n, (spans[0] + 3) * n_v))


def smoothed(uv: np.ndarray, points: np.ndarray, spans: tuple[int, int],
              smoothing: float) -> tuple[np.ndarray, np.ndarray]:
    """The P-spline fit (:mod:`.meshes`, step 4) over the bounding box of uv (n, 2): its values
    (n, 3) at uv and its control points ((spans_u + 3) (spans_v + 3), 3)."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    n_u, n_v = spans[0] + 3, spans[1] + 3
    a = _basis(uv, lo, hi, spans)
    d_u = sparse.kron(_second_differences(n_u), sparse.identity(n_v))
    d_v = sparse.kron(sparse.identity(n_u), _second_differences(n_v))
    weight = smoothing * len(uv) / (n_u * n_v)
    lhs = (a.T @ a + weight * (d_u.T @ d_u + d_v.T @ d_v)).tocsc()
    coef = solve_spd(lhs, a.T @ points)
    return a @ coef, coef


def fit_spline(uv: np.ndarray, points: np.ndarray, spans: tuple[int, int],
                smoothing: float) -> ca.Function:
    """The P-spline fit (:mod:`.meshes`, step 4), as a CasADi bspline interpolant
    (u, v) -> r (3)."""
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    coef = smoothed(uv, points, spans, smoothing)[1]
    g_u, g_v = (np.linspace(lo[k], hi[k], 2 * spans[k] + 1) for k in range(2))
    grid = np.stack(np.meshgrid(g_u, g_v, indexing="ij"), -1).reshape(-1, 2)
    values = (_basis(grid, lo, hi, spans) @ coef).reshape(len(g_u), len(g_v), 3)
    spline = ca.interpolant("mesh_r", "bspline", [g_u, g_v],
                            values.transpose(2, 0, 1).ravel(order="F"))
    # CasADi's bspline is 0 outside its grid: a parameter a round-off outside (a free
    # correspondence's grid on the domain's edge) is put back on it, with the identity's
    # derivative on the edge itself
    uv_sym = ca.SX.sym("uv", 2)
    on_grid = ca.vertcat(*(ca.if_else(uv_sym[k] < lo[k], lo[k],
                                      ca.if_else(uv_sym[k] > hi[k], hi[k], uv_sym[k]))
                           for k in range(2)))
    return ca.Function("mesh_r", [uv_sym], [spline(on_grid)])


def in_units(spline: ca.Function, centre: np.ndarray, scale: float) -> ca.Function:
    """r (u, v) -> centre + scale * spline(u / scale, v / scale): a spline fitted in the unit
    frame (:mod:`.mesh_input`) in the shape's own units, its parameters lengths there too."""
    uv = ca.SX.sym("uv", 2)
    return ca.Function("mesh_r", [uv], [ca.DM(centre) + scale * spline(uv / scale)])
