"""Several folded states of one sheet as one simultaneous NLP (:func:`several_states`): the
crease pattern's variables and rows once, the kinematics, omega, alignment and loss of every
state beside them (docs/several_states.md)."""

from __future__ import annotations

from collections.abc import Sequence

import casadi as ca
import numpy as np

from ...model import numpy_model
from ...targets import shape
from ..stencils import GraphJacobian
from .correspondence import GRID_REGULARIZATION
from .inputs import Setup, damping_weights
from .lifting import MeanTree, sides_by_antidiagonal
from .loss import design_residuals, state_residuals
from .nlp import NLP, Layout, StateFunctions
from .simultaneous_nlp import (Projection, bound_pattern, boundary_places, fold_rows, layout,
                               pattern_blocks, pattern_groups, pattern_rows, state_blocks)

#: How a target lattice's indices are laid onto the pattern's (:func:`oriented`): (swap,
#: flip_i, flip_j), the eight symmetries of the index rectangle, the identity first.
ORIENTATIONS = tuple((swap, flip_i, flip_j) for swap in (False, True)
                     for flip_i in (False, True) for flip_j in (False, True))


def oriented(lattice, orientation: tuple[bool, bool, bool]):
    """A target lattice relabelled onto the pattern's indices: an array (n, m, 3) or a
    list of matrices (n x m each, NumPy or CasADi) transposed where ``orientation`` swaps
    (then (m, n)), its rows and columns reversed where it flips i and j (after the swap).
    The points stay; only which lattice index each belongs to changes."""
    swap, flip_i, flip_j = orientation
    if isinstance(lattice, np.ndarray):
        out = lattice.transpose(1, 0, 2) if swap else lattice
        out = out[::-1] if flip_i else out
        return out[:, ::-1] if flip_j else out
    out = []
    for c in lattice:
        c = c.T if swap else c
        rows, cols = list(range(c.shape[0])), list(range(c.shape[1]))
        out.append(c[rows[::-1] if flip_i else rows, cols[::-1] if flip_j else cols])
    return out


def several_states(setups: Sequence[Setup], weights: Sequence[float],
                   orientations: Sequence[tuple[bool, bool, bool]] | None = None) -> NLP:
    """One crease pattern folded into K >= 2 states: state k at its own omega_k, aligned by
    its own rigid motion onto its own target (``setups[k]``: its omega and bounds, its
    alignment, target lattice, spacing, loss weights, correspondence or curvature loss),
    its loss times sqrt(``weights[k]``). ``orientations[k]`` (default the identity) lays a
    free correspondence's lattice onto the pattern's indices (:func:`oriented`; a fixed
    target lattice comes oriented in its setup, and a swapped correspondence has the
    transposed shape).

    The pattern's blocks and rows are those of :func:`.simultaneous_nlp.simultaneous`,
    once; each state has the kinematics blocks and rows of that transcription
    (:func:`.simultaneous_nlp.fold_rows`) and, with a free correspondence, its controls.
    What the states share comes from ``setups[0]``: the initial boundary data, the
    constraints, the Miura reference of the Tikhonov term (on the pattern alone: the
    omegas are free of it) and the held groups ``fixed`` ("omega" holds every omega).
    The variables are the pattern's, each state's kinematics and controls, then the
    global ones, omega_k and the alignment (q_k, t_k) of each state (``parts``: local,
    global). ``states`` holds each state's Functions; ``unpack``, ``folded`` and
    ``free_target`` are the first state's. Levenberg-Marquardt on the marching manifold
    solves it as it solves one state: the design is the pattern's boundary data and each
    state's omega, alignment and controls, the rest marched and folded state by state
    (``project``, :class:`StatesProjection`); its Jacobians are CasADi's of the whole graph
    (:class:`rffqm_nlp.design.stencils.GraphJacobian`), not stencils: a design of several
    states is small (docs/several_states.md)."""
    first = setups[0]
    N, M = first.boundary.N, first.boundary.M
    K = len(setups)
    tree = MeanTree((N + 1) * M + N * (M + 1), order=sides_by_antidiagonal(N, M))
    names = [list(state_blocks(N, M, s.correspondence)) for s in setups]
    lay = Layout({**pattern_blocks(N, M, tree),
                  **{f"{n}{k}": shp for k, s in enumerate(setups)
                     for n, shp in state_blocks(N, M, s.correspondence).items()},
                  **{f"omega{k}": (1, 1) for k in range(K)},
                  **{f"rigid{k}": (7, 1) for k in range(K)}})
    parts = (ca.MX.sym("x", lay.size - 8 * K), ca.MX.sym("x_global", 8 * K))
    x = ca.vertcat(*parts)
    v = lay.views(x)
    start = numpy_model.march(first.boundary)
    pattern = pattern_rows(first, v, start, tree)
    kinematics, losses, own, rows = [], [], [], []
    lower, upper = [], []
    functions = []
    for k, setup in enumerate(setups):
        state = {n: v[f"{n}{k}"] for n in names[k]} | {"omega": v[f"omega{k}"]}
        phi_res, q_res, y_res, Y = fold_rows(v, start.sigma, state)
        kinematics += [phi_res, q_res, y_res]
        corr = setup.correspondence
        grid = None if corr is None else (state["U"], state["V"])
        lattice = (None if grid is None else
                   oriented(corr.lattice(*grid), orientations[k] if orientations else
                            ORIENTATIONS[0]))
        rigid = v[f"rigid{k}"]
        losses.append(np.sqrt(weights[k]) * state_residuals(setup, shape.coarse_grain(Y),
                                                              rigid, grid, lattice))
        if k == 0:  # the pattern's Tikhonov term, omega held at its reference
            own.append(design_residuals(first, rigid, ca.vertcat(
                pattern.boundary, first.reference_omega), grid))
        else:
            own.append(ca.sumsqr(rigid[:4]) - 1)
            if grid is not None:
                own.append(corr.residuals(*grid, GRID_REGULARIZATION
                                          * first.weights.get("regularization", 0)))
        if corr is not None:
            g_k, lo, hi = corr.rows(*grid)
            rows.append(g_k)
            lower.append(lo)
            upper.append(hi)
        functions.append(StateFunctions(
            omega=ca.Function(f"omega{k}", [x], [state["omega"]]),
            folded=ca.Function(f"folded{k}", [x], Y),
            target=None if corr is None else ca.Function(f"target{k}", [x], lattice)))
    g = ca.vertcat(pattern.march, pattern.edges, *kinematics, pattern.mean,
                   pattern.inequalities, *rows)
    n_eq = g.numel() - pattern.inequalities.numel() - sum(r.numel() for r in rows)
    lbg = np.concatenate([np.zeros(n_eq), pattern.lower, *lower])
    ubg = np.concatenate([np.zeros(n_eq), pattern.upper, *upper])
    project = StatesProjection(setups, lay, tree, start.sigma)
    given = {"A": start.alpha, "B": start.beta, "LH": start.lh, "LV": start.lv}
    for k, setup in enumerate(setups):
        given |= {f"omega{k}": setup.omega, f"rigid{k}": setup.rigid0()}
        if setup.correspondence is not None:
            given |= dict(zip((f"U{k}", f"V{k}"),
                              setup.correspondence.views(setup.controls0())))
    x0 = project(lay.pack(given))
    if x0 is None:
        raise RuntimeError("the start does not march with the CasADi graph")
    lbx, ubx, groups = _bounds(setups, lay, x0)
    lengths = np.zeros(lay.size, dtype=bool)
    for name in lay.shapes:
        if name[:2] in ("LH", "LV", "Yx", "Yy", "Yz") or name == "P":
            lengths[lay.slices[name]] = True
        if name.startswith("rigid"):
            lengths[lay.slices[name].stop - 3:lay.slices[name].stop] = True
    damping = damping_weights(first, lengths)
    grids = []
    for k, setup in enumerate(setups):
        if setup.correspondence is not None:
            grids.append(lay.indices(f"U{k}", f"V{k}"))
            damping[grids[-1]] = setup.correspondence.damping_weights()
    design = np.concatenate([*groups.values(), lay.indices(*(f"rigid{k}" for k in range(K))),
                             *grids])
    position, klass = boundary_places(lay, N, M)
    residuals = ca.vertcat(*losses, *own)
    state0 = functions[0]
    return NLP(x=x, residuals=residuals, g=g, lbg=lbg, ubg=ubg, lbx=lbx, ubx=ubx, x0=x0,
               unpack=ca.Function("unpack", [x], [pattern.boundary, v["omega0"]]),
               folded=state0.folded, groups=groups, parts=parts, damping_weights=damping,
               free_target=state0.target, states=tuple(functions),
               project=project,
               design_index=design, pattern_index=lay.indices("A", "B", "LH", "LV"),
               boundary_position=position, boundary_class=klass,
               r_jacobian=GraphJacobian(residuals, x), g_jacobian=GraphJacobian(g, x))


class StatesProjection:
    """:attr:`NLP.project` of :func:`several_states`: x (n,) -> the point of x's boundary
    data, each state's omega, alignment and controls, the pattern marched and folded into
    every state; None where a state's :class:`.simultaneous_nlp.Projection` is None. Each
    state has the Projection of a one-state layout (:func:`.simultaneous_nlp.layout`),
    whose blocks are copied from and into x's by name (the pattern marched once a state)."""

    def __init__(self, setups: Sequence[Setup], lay: Layout, tree: MeanTree,
                 sigma: np.ndarray):
        N, M = sigma.shape[0] - 1, sigma.shape[1] - 1
        pattern = set(pattern_blocks(N, M, tree))
        self._states = []
        for k, setup in enumerate(setups):
            single = layout(N, M, tree, setup.correspondence)
            xs = ca.MX.sym("x", single.size)
            grid = single.indices(*(("U", "V") if setup.correspondence is not None else ()))
            names = list(single.shapes)
            written = [n for n in names if (n not in pattern or k == 0)
                       and n not in ("omega", "rigid", "U", "V")]
            self._states.append((Projection(xs, single.views(xs), single, sigma, tree, grid),
                                 single.size, _indices(single, lay, names, k),
                                 _indices(single, lay, written, k)))

    def __call__(self, x: np.ndarray) -> np.ndarray | None:
        out = np.array(x, dtype=float)
        for project, size, (into, read), (mine, written) in self._states:
            xs = np.zeros(size)
            xs[into] = x[read]
            point = project(xs)
            if point is None:
                return None
            out[written] = point[mine]
        return out


def _indices(single: Layout, lay: Layout, names: Sequence[str], k: int
             ) -> tuple[np.ndarray, np.ndarray]:
    """The indices of the blocks ``names`` in a one-state layout and, in the same order,
    of the same blocks in the layout of several states (a state's own block named with
    its number ``k``)."""
    return (single.indices(*names),
            lay.indices(*(n if n in lay.slices else f"{n}{k}" for n in names)))


def _bounds(setups: Sequence[Setup], lay: Layout, x0: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(lbx, ubx, groups) of :func:`several_states`' variables: the pattern's as in the
    simultaneous transcription, each state's omega within its bounds, its first panel's
    rotation the identity and its first vertex at 0 (eq:creaseInputs), its controls in its
    domain; the held groups at ``x0``."""
    first = setups[0]
    lbx, ubx = np.full(lay.size, -np.inf), np.full(lay.size, np.inf)
    bound_pattern(first, lay, lbx, ubx)
    for k, setup in enumerate(setups):
        lbx[lay.slices[f"omega{k}"]], ubx[lay.slices[f"omega{k}"]] = setup.omega_bounds
        for name in ("Qx", "Qy", "Qz", "Yx", "Yy", "Yz"):
            lbx[lay.index(f"{name}{k}", 0, 0)] = ubx[lay.index(f"{name}{k}", 0, 0)] = 0.0
        lbx[lay.index(f"Qw{k}", 0, 0)] = ubx[lay.index(f"Qw{k}", 0, 0)] = 1.0
        if setup.correspondence is not None:
            grid = lay.indices(f"U{k}", f"V{k}")
            lbx[grid], ubx[grid] = setup.correspondence.bounds()
    groups = {**pattern_groups(lay),
              "omega": np.array([lay.index(f"omega{k}", 0, 0)[0] for k in range(len(setups))])}
    for name in first.fixed:
        lbx[groups[name]] = ubx[groups[name]] = x0[groups[name]]
    return lbx, ubx, groups
