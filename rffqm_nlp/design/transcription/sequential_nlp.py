"""The sequential transcription (:func:`sequential`): the marching graph is a function of
the boundary data (few variables, dense Jacobians)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...model.marching import folded_function, pattern_function
from ...targets import shape
from .correspondence import with_grid_rows
from .inputs import Setup, damping_weights
from .loss import objective_residuals
from .nlp import NLP

PI = np.pi


def sequential(setup: Setup) -> NLP:
    """The sequential transcription: x = (boundary angles, boundary lengths, omega, q, t),
    then the controls (Cu, Cv) of a free correspondence.

    The pattern and the folded state are functions of x through the marching graph; the
    inline constraints are every vertex angle in [min_angle, pi - min_angle], the multiplier
    margin of every panel, the MV assignment of every boundary vertex
    (:meth:`Setup.boundary_mv`), every side >= min_length * mean side, and a free
    correspondence's control rows (:meth:`Correspondence.rows`).
    """
    bd0 = setup.boundary
    N, M = bd0.N, bd0.M
    nv, nl = N + 1 + M, N + M
    corr = setup.correspondence
    n_grid = 0 if corr is None else corr.size
    n_fixed = 2 * nv + nl + 1 + 7
    x = ca.MX.sym("x", n_fixed + n_grid)
    groups = {"angles": slice(0, 2 * nv), "lengths": slice(2 * nv, 2 * nv + nl),
              "omega": slice(2 * nv + nl, 2 * nv + nl + 1),
              "rigid": slice(2 * nv + nl + 1, 2 * nv + nl + 8)}
    grid = None if corr is None else corr.views(x[n_fixed:])
    sig = ca.DM(bd0.sigma).T
    tri = ca.vertcat(x[:nv].T, x[nv:2 * nv].T, sig)
    lengths = x[groups["lengths"]].T
    omega = x[groups["omega"]]
    inputs = [tri[:, :N + 1], tri[:, N + 1:], lengths[:, :N], lengths[:, N:]]
    Y = folded_function(N, M).call([*inputs, omega])
    x0 = np.concatenate([bd0.to_vector(), [setup.omega], setup.rigid0()]
                        + ([] if corr is None else [setup.controls0()]))
    res = objective_residuals(setup, shape.coarse_grain(Y), x[groups["rigid"]],
                               x[:2 * nv + nl + 1], grid)
    # Inline constraints on the marched pattern.
    alpha, beta, _, lh, lv, mu = pattern_function(N, M).call(inputs)[:6]
    sides = ca.vertcat(ca.vec(lh), ca.vec(lv))
    angles = ca.vertcat(ca.vec(alpha), ca.vec(beta))
    sign = ca.DM(np.where(setup.mu_outside, 1.0, -1.0))
    mv, lo_mv, hi_mv = setup.boundary_mv(x[:nv], x[nv:2 * nv])
    g = ca.vertcat(angles, sign * (ca.vec(mu) ** 2 - 1), mv,
                   sides / (ca.sum1(sides) / sides.numel()) - setup.min_length)
    lo_mu, hi_mu = setup.mu_bounds()
    lbg = np.concatenate([np.full(angles.numel(), setup.min_angle), lo_mu, lo_mv,
                          np.zeros(sides.numel())])
    ubg = np.concatenate([np.full(angles.numel(), PI - setup.min_angle), hi_mu, hi_mv,
                          np.full(sides.numel(), np.inf)])
    lbx = np.concatenate([np.full(2 * nv, setup.min_angle), np.full(nl, 1e-9 * setup.spacing),
                          [setup.omega_bounds[0]], np.full(7, -np.inf)])
    ubx = np.concatenate([np.full(2 * nv, PI - setup.min_angle), np.full(nl, np.inf),
                          [setup.omega_bounds[1]], np.full(7, np.inf)])
    lengths = np.zeros(n_fixed, dtype=bool)
    lengths[groups["lengths"]] = lengths[n_fixed - 3:] = True  # boundary sides, translation
    weights = damping_weights(setup, lengths)
    free_target = None
    if corr is not None:
        g, lbg, ubg = with_grid_rows(corr, grid, g, lbg, ubg)
        lo, hi = corr.bounds()
        lbx, ubx = np.concatenate([lbx, lo]), np.concatenate([ubx, hi])
        weights = np.concatenate([weights, corr.damping_weights()])
        free_target = ca.Function("target", [x], corr.lattice(*grid))
    for name in setup.fixed:
        lbx[groups[name]] = ubx[groups[name]] = x0[groups[name]]
    unpack = ca.Function("unpack", [x], [x[:2 * nv + nl], omega])
    folded = ca.Function("folded", [x], list(Y))
    return NLP(x=x, residuals=res, g=g, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, x0=x0,
               unpack=unpack, folded=folded, groups=groups, damping_weights=weights,
               free_target=free_target,
               grid_index=None if corr is None else np.arange(n_fixed, n_fixed + n_grid))
