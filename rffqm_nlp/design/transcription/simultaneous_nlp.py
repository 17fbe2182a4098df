"""The simultaneous transcription (:func:`simultaneous`): every vertex angle and side is a
variable and the marching equations are equality constraints, panel by panel (many
variables, sparse Jacobians); its rows on the crease pattern (:func:`pattern_rows`) and on
one folded state (:func:`fold_rows`), which a design of several states shares
(:mod:`.states_nlp`); and its projection of any point onto the marched designs
(:class:`Projection`)."""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...errors import InputError
from ...model import numpy_model
from ...model import vertex as vx
from ...model.marching import (Evaluation, locate_failure, marched_function, panel_cell, qmul,
                               rotated_edges)
from ...model.pattern import Pattern
from ...targets import shape
from .correspondence import Correspondence, with_grid_rows
from .inputs import Setup, damping_weights
from .lifting import (MeanTree, crease_quaternion_signs, fold_multipliers_kv,
                      local_crease_quaternions, sides_by_antidiagonal)
from .loss import objective_residuals
from .nlp import NLP, Layout
from .stencil_jacobians import constraint_jacobian, residual_jacobian

PI = np.pi


def simultaneous(setup: Setup) -> NLP:
    """The simultaneous transcription: every vertex angle, side, edge direction, panel
    rotation (quaternion) and folded vertex is a variable, and the marching equations are
    equality constraints, panel by panel. The Jacobians stay sparse, so large patterns fit.

    Pattern: the panel cell (eq:marchingSector .. eq:getSides) maps a, b, c and l_ab, l_ac to
    d, l_cd, l_bd; the sides are stated multiplied through by the denominator of
    eq:getSides (:func:`vertex.panel_side_residuals`); with the quotient IPOPT needed far
    more iterations (docs/decisions/ipopt.md).
    Kinematics: edge directions accumulate sector angles, panel quaternions multiply by
    crease quaternions (eq:defGrads), vertices add rotated edges (eq:finalCalc). The loss
    sees only the coarse lattice, but lifting every vertex keeps large designs converging:
    with the coarse lattice points alone (a smaller KKT system) a large sphere cap lost
    feasibility and did not recover (docs/decisions/ipopt.md).

    Every equality row is local (a panel and its neighbours): the column factors of the fold
    multipliers are lifted (PHI, see :func:`local_crease_quaternions`) and the mean side is
    the root of a tree of partial means (P, see :class:`MeanTree`), so the Jacobian colours
    in a few tens of forward sweeps whatever the size. Solve it with ``mu_strategy =
    adaptive`` (or a small ``mu_init``): with IPOPT's default monotone barrier from mu = 0.1
    the barrier terms (hundreds of logs against a much smaller loss) pull this
    infeasible-path method towards square panels and long sides (measured:
    docs/decisions/ipopt.md, "Cold-start barrier"), where it loses feasibility and never
    returns.
    """
    bd0 = setup.boundary
    N, M = bd0.N, bd0.M
    n1, m1 = N + 1, M + 1
    tree = MeanTree(n1 * M + N * m1, order=sides_by_antidiagonal(N, M))
    corr = setup.correspondence
    lay = layout(N, M, tree, corr)
    parts = (ca.MX.sym("x", lay.size - 8), ca.MX.sym("x_global", 8))  # omega, rigid
    x = ca.vertcat(*parts)
    v = lay.views(x)
    start = numpy_model.march(bd0)
    pattern = pattern_rows(setup, v, start, tree)
    phi_res, q_res, y_res, Y = fold_rows(v, start.sigma, v)
    bvec = ca.vertcat(pattern.boundary, v["omega"])
    grid = None if corr is None else (v["U"], v["V"])
    res = objective_residuals(setup, shape.coarse_grain(Y), v["rigid"], bvec, grid)
    g = ca.vertcat(pattern.march, pattern.edges, phi_res, q_res, y_res, pattern.mean,
                   pattern.inequalities)
    n_eq = g.numel() - pattern.inequalities.numel()
    lbg = np.concatenate([np.zeros(n_eq), pattern.lower])
    ubg = np.concatenate([np.zeros(n_eq), pattern.upper])
    if corr is not None:
        g, lbg, ubg = with_grid_rows(corr, grid, g, lbg, ubg)
    grid_index = lay.indices(*(("U", "V") if corr is not None else ()))
    project = Projection(x, v, lay, start.sigma, tree, grid_index)
    x0 = project(lay.pack({"A": start.alpha, "B": start.beta, "LH": start.lh, "LV": start.lv,
                           "omega": setup.omega, "rigid": setup.rigid0()}))
    if x0 is None:
        raise RuntimeError("the start does not march with the CasADi graph")
    if corr is not None:
        x0[grid_index] = setup.controls0()
    lbx, ubx = np.full(lay.size, -np.inf), np.full(lay.size, np.inf)
    if corr is not None:
        lbx[grid_index], ubx[grid_index] = corr.bounds()
    bound_pattern(setup, lay, lbx, ubx)
    lbx[lay.slices["omega"]], ubx[lay.slices["omega"]] = setup.omega_bounds
    for name in ("Qx", "Qy", "Qz", "Yx", "Yy", "Yz"):  # R^{11} = I, y^{11} = 0
        lbx[lay.index(name, 0, 0)] = ubx[lay.index(name, 0, 0)] = 0.0
    lbx[lay.index("Qw", 0, 0)] = ubx[lay.index("Qw", 0, 0)] = 1.0
    groups = {**pattern_groups(lay), "omega": lay.index("omega", 0, 0)}
    for name in setup.fixed:
        lbx[groups[name]] = ubx[groups[name]] = x0[groups[name]]
    unpack = ca.Function("unpack", [x], [pattern.boundary, v["omega"]])
    folded = ca.Function("folded", [x], Y)
    position, boundary_class = boundary_places(lay, N, M)
    lengths = np.zeros(lay.size, dtype=bool)
    for name in ("LH", "LV", "Yx", "Yy", "Yz", "P"):
        lengths[lay.slices[name]] = True
    lengths[lay.size - 3:] = True  # the translation of the alignment, last in x
    weights = damping_weights(setup, lengths)
    free_target = None
    if corr is not None:
        weights[grid_index] = corr.damping_weights()
        free_target = ca.Function("target", [x], corr.lattice(*grid))
    design = np.concatenate([*groups.values(), lay.indices("rigid"), grid_index])
    return NLP(x=x, residuals=res, g=g, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, x0=x0,
               unpack=unpack, folded=folded, groups=groups, project=project, parts=parts,
               damping_weights=weights, design_index=design,
               pattern_index=lay.indices("A", "B", "LH", "LV"), free_target=free_target,
               boundary_position=position, boundary_class=boundary_class,
               grid_index=None if corr is None else grid_index,
               r_jacobian=residual_jacobian(setup, lay, res.numel()),
               g_jacobian=constraint_jacobian(setup, lay, start.sigma, tree, g.numel()))



def layout(N: int, M: int, tree: MeanTree, corr: Correspondence | None) -> Layout:
    """The variables of :func:`simultaneous` for an N x M-panel pattern: the pattern's
    blocks but the mean tree's (:func:`pattern_blocks`), the state's kinematics, the mean
    tree's nodes P, a free correspondence's controls U, V (:func:`state_blocks`), then the
    global variables omega and the alignment ``rigid`` (q, t)."""
    blocks, state = pattern_blocks(N, M, tree), state_blocks(N, M, corr)
    nodes = {"P": blocks.pop("P")}
    grid = {name: state.pop(name) for name in ("U", "V") if name in state}
    return Layout({**blocks, **state, **nodes, **grid, "omega": (1, 1), "rigid": (7, 1)})


def pattern_blocks(N: int, M: int, tree: MeanTree) -> dict[str, tuple[int, int]]:
    """The simultaneous NLP's blocks of the crease pattern of an N x M-panel pattern: the
    vertex angles A, B, the sides LH, LV, the edge directions TH and the mean tree's nodes
    P, with their shapes (:class:`Layout`)."""
    return {"A": (N + 1, M + 1), "B": (N + 1, M + 1), "LH": (N + 1, M), "LV": (N, M + 1),
            "TH": (N + 1, M + 1), "P": (tree.size, 1)}


def state_blocks(N: int, M: int, corr: Correspondence | None) -> dict[str, tuple[int, int]]:
    """The blocks of one folded state of an N x M-panel pattern: the panel quaternions
    Q*, the folded vertices Y*, the fold multiplier angles PHI, and a free
    correspondence's controls U, V."""
    quaternions = {name: (N, M) for name in ("Qw", "Qx", "Qy", "Qz")}
    vertices = {name: (N + 1, M + 1) for name in ("Yx", "Yy", "Yz")}
    grid = {} if corr is None else {"U": corr.shape, "V": corr.shape}
    return {**quaternions, **vertices, "PHI": (N - 1, M), **grid}


def boundary_places(lay: Layout, N: int, M: int) -> tuple[np.ndarray, np.ndarray]:
    """:attr:`NLP.boundary_position` and :attr:`NLP.boundary_class` (each (lay.size,)) of a
    layout with the pattern's blocks A, B, LH, LV of an N x M-panel pattern."""
    n1, m1 = N + 1, M + 1
    position = np.full(lay.size, np.nan)
    for name in ("A", "B"):
        position[lay.index(name, slice(None), 0)] = -np.arange(n1)
        position[lay.index(name, 0, slice(1, None))] = np.arange(1, m1)
    position[lay.index("LV", slice(None), 0)] = -(np.arange(N) + 0.5)
    position[lay.index("LH", 0, slice(None))] = np.arange(M) + 0.5
    klass = np.full(lay.size, -1, dtype=np.int64)
    for kind, (name, rows, cols, index) in enumerate([
            ("A", slice(None), 0, np.arange(n1)), ("B", slice(None), 0, np.arange(n1)),
            ("A", 0, slice(1, None), np.arange(1, m1)), ("B", 0, slice(1, None), np.arange(1, m1)),
            ("LV", slice(None), 0, np.arange(N)), ("LH", 0, slice(None), np.arange(M))]):
        klass[lay.index(name, rows, cols)] = 2 * kind + index % 2
    return position, klass


def bound_pattern(setup: Setup, lay: Layout, lbx: np.ndarray, ubx: np.ndarray) -> None:
    """Set the bounds of the pattern's blocks in ``lbx``, ``ubx`` (lay.size each): every
    vertex angle in [min_angle, pi - min_angle], every side positive, the first edge
    direction 0 (eq:creaseInputs)."""
    for name in ("A", "B"):
        lbx[lay.slices[name]], ubx[lay.slices[name]] = setup.min_angle, PI - setup.min_angle
    for name in ("LH", "LV"):
        lbx[lay.slices[name]] = 1e-9 * setup.spacing
    lbx[lay.index("TH", 0, 0)] = ubx[lay.index("TH", 0, 0)] = 0.0


def pattern_groups(lay: Layout) -> dict[str, np.ndarray]:
    """Indices in x of the boundary data that ``fix`` can hold: "angles" (A and B along
    the left edge, then along the bottom edge) and "lengths" (LV along the left edge, LH
    along the bottom edge)."""
    return {"angles": np.concatenate([lay.index(n, slice(None), 0) for n in ("A", "B")]
                                     + [lay.index(n, 0, slice(1, None)) for n in ("A", "B")]),
            "lengths": np.concatenate([lay.index("LV", slice(None), 0),
                                       lay.index("LH", 0, slice(None))])}


@dataclass(frozen=True)
class PatternRows:
    """The rows of the simultaneous NLP on the crease pattern alone, whatever its folded
    states (:func:`pattern_rows`): the marching equations of the panel cells (``march``),
    of the edge directions (``edges``) and of the mean tree (``mean``); the inequalities
    (multiplier margins, boundary MV, sides against the mean side) with their bounds; the
    boundary data vector in :meth:`BoundaryData.to_vector` order (``boundary``)."""

    march: ca.MX
    edges: ca.MX
    mean: ca.MX
    inequalities: ca.MX
    lower: np.ndarray
    upper: np.ndarray
    boundary: ca.MX


def pattern_rows(setup: Setup, v: dict, start: Pattern, tree: MeanTree) -> PatternRows:
    """The crease pattern's rows of the simultaneous NLP from the views ``v`` of its blocks
    A, B, LH, LV, TH and P (:class:`Layout`); ``start``: the pattern the start marches to
    (its signs sigma are held)."""
    A, B, LH, LV, TH = v["A"], v["B"], v["LH"], v["LV"], v["TH"]
    N, M = start.sigma.shape[0] - 1, start.sigma.shape[1] - 1
    S = ca.DM(start.sigma)
    # Pattern: one panel cell per panel, mapped.
    cell = panel_cell().map(N * M)
    row = lambda m: ca.vec(m).T  # noqa: E731 - column-major row of a panel-shaped block
    xs, ys = cell(ca.vertcat(row(A[1:, :M]), row(B[1:, :M]), row(S[1:, :M]), row(LV[:, :M])),
                  ca.vertcat(row(A[:N, :M]), row(B[:N, :M]), row(S[:N, :M]),
                             row(A[:N, 1:]), row(B[:N, 1:]), row(S[:N, 1:]), row(LH[:N, :])))
    # The sides of d without the quotient (vertex.panel_side_residuals), with the roles of
    # the panel cell: a = (i, j), b = (i+1, j), c = (i, j+1).
    sides_res = vx.panel_side_residuals(A[:N, :M], PI - B[1:, :M], B[:N, 1:], LV[:, :M],
                                        LH[:N, :], LV[:, 1:], LH[1:, :])
    march_res = ca.vec(ca.vertcat(row(A[1:, 1:]) - xs[0, :], row(B[1:, 1:]) - xs[1, :],
                                  *(row(r) for r in sides_res)))
    mu = ys[1, :].T
    th_res = ca.vertcat(ca.vec(TH[1:, 0] - TH[:N, 0] - (A[:N, 0] - B[1:, 0])),
                        ca.vec(TH[:, 1:] - TH[:, :M] - (PI - A[:, 1:] - B[:, 1:])))
    # Boundary design vector in BoundaryData.to_vector order.
    bvec = ca.vertcat(A[:, 0], A[0, 1:].T, B[:, 0], B[0, 1:].T, LV[:, 0], LH[0, :].T)
    sides = ca.vertcat(ca.vec(LH), ca.vec(LV))
    mean_res, mean = tree.residuals(sides, v["P"])
    sign = ca.DM(np.where(setup.mu_outside, 1.0, -1.0))
    nv = N + 1 + M
    mv, lo_mv, hi_mv = setup.boundary_mv(bvec[:nv], bvec[nv:2 * nv])
    lo_mu, hi_mu = setup.mu_bounds()
    return PatternRows(
        march=march_res, edges=th_res, mean=mean_res,
        inequalities=ca.vertcat(sign * (mu ** 2 - 1), mv, sides - setup.min_length * mean),
        lower=np.concatenate([lo_mu, lo_mv, np.zeros(sides.numel())]),
        upper=np.concatenate([hi_mu, hi_mv, np.full(sides.numel(), np.inf)]), boundary=bvec)


def fold_rows(v: dict, sigma: np.ndarray, state: dict) -> tuple[ca.MX, ca.MX, ca.MX, list]:
    """The kinematics of one folded state, lifted (eq:defGrads, eq:finalCalc): the rows of
    its fold multiplier angles PHI, panel quaternions Q and folded vertices Y, and Y =
    [Yx, Yy, Yz]. ``v``: the views of the pattern's blocks A, B, LH, LV, TH; ``state``: of
    the state's blocks omega, PHI, Qw, Qx, Qy, Qz, Yx, Yy, Yz; ``sigma``: the held signs."""
    A, B, LH, LV, TH = v["A"], v["B"], v["LH"], v["LV"], v["TH"]
    N, M = sigma.shape[0] - 1, sigma.shape[1] - 1
    quat = [state["Qw"], state["Qx"], state["Qy"], state["Qz"]]
    qv, qh, phi_res = local_crease_quaternions(A, B, sigma, TH, state["omega"], state["PHI"])
    prod_row1 = qmul([c[0, :M - 1] for c in quat], qv)
    prod_rows = qmul([c[:N - 1, :] for c in quat], qh)
    q_res = ca.vertcat(*(ca.vec(c[0, 1:] - p) for c, p in zip(quat, prod_row1)),
                       *(ca.vec(c[1:, :] - p) for c, p in zip(quat, prod_rows)))
    Y = [state["Yx"], state["Yy"], state["Yz"]]
    bottom, vertical = rotated_edges(quat, A, TH, LH, LV)
    y_res = ca.vertcat(*(ca.vec(c[0, 1:] - c[0, :M] - b) for c, b in zip(Y, bottom)),
                       *(ca.vec(c[1:, :] - c[:N, :] - e) for c, e in zip(Y, vertical)))
    return phi_res, q_res, y_res, Y


class Projection:
    """The simultaneous NLP's :attr:`NLP.project`: x -> the point of x's boundary data,
    omega, alignment and controls, marched and folded, through one buffered CasADi Function
    of x (:func:`marching.marched_function` and the mean tree: the solver's trial points
    are marched without the NumPy model's Python loop over anti-diagonals, and its answer
    is re-marched with that model in the end); the lifted fold multiplier angles and the
    crease quaternions' signs in NumPy.

    None where the march fails a check (:func:`marching.locate_failure`), gives other
    vertex signs than ``sigma``, the NLP's, or the point is not finite (a NaN or inf in
    x's omega, alignment or controls). The boundary data are not validated as
    :class:`BoundaryData` does: the NLP's bounds and rows are stricter (angles within
    [min_angle, pi - min_angle], sides positive, the boundary MV rows with a margin), and
    every caller judges the point by them."""

    def __init__(self, x: ca.MX, v: dict, lay: Layout, sigma: np.ndarray, tree: MeanTree,
                 grid_index: np.ndarray):
        N, M = sigma.shape[0] - 1, sigma.shape[1] - 1
        S = ca.DM(sigma)
        A, B, LH, LV = v["A"], v["B"], v["LH"], v["LV"]
        out = marched_function(N, M)(ca.vertcat(A[:, 0].T, B[:, 0].T, S[:, 0].T),
                                     ca.vertcat(A[0, 1:], B[0, 1:], S[0, 1:]),
                                     LV[:, 0].T, LH[0, :], v["omega"])
        lh, lv = out[3], out[4]
        nodes = tree.expression(ca.vertcat(ca.vec(lh), ca.vec(lv)))
        self._marched = Evaluation(ca.Function("project", [x], [*out, nodes]),
                                   [np.zeros(lay.size)])
        self._lay, self._sigma, self._keep = lay, sigma, np.concatenate(
            [lay.indices("omega", "rigid"), grid_index])
        self._kh0, self._sp = fold_multipliers_kv(sigma)

    def __call__(self, xk: np.ndarray) -> np.ndarray | None:
        self._marched.set(0, xk)
        (alpha, beta, sigma, lh, lv, mu, alpha_d, theta,
         qw, qx, qy, qz, yx, yy, yz, nodes) = self._marched.run()
        if (locate_failure(alpha_d, mu, lh, lv) is not None
                or not np.array_equal(sigma, self._sigma)):
            return None
        N, M = mu.shape
        try:
            mu2 = vx.mu2(alpha, beta, self._sigma)[0, :]
        except InputError:          # a vertex at the pole of its fold multiplier
            return None
        phi = np.arctan((-self._kh0 / mu2 * self._sp)[1:N, :M])
        signs = crease_quaternion_signs(alpha, beta, self._sigma, phi)
        out = self._lay.pack({"A": alpha, "B": beta, "LH": lh, "LV": lv, "TH": theta,
                              "Qw": qw * signs, "Qx": qx * signs, "Qy": qy * signs,
                              "Qz": qz * signs, "Yx": yx, "Yy": yy, "Yz": yz, "PHI": phi,
                              "P": nodes})
        out[self._keep] = xk[self._keep]
        return out if np.all(np.isfinite(out)) else None
