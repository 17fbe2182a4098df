"""The Jacobians of the simultaneous NLP's constraints and residuals assembled from local
stencils (:mod:`rffqm_nlp.design.stencils`): the same equations as
:func:`~rffqm_nlp.design.transcription.simultaneous_nlp.simultaneous`, each kind of row
stated once on one panel's or vertex's own variables (:class:`_ConstraintStencils`,
:class:`_ResidualStencils`), which :mod:`rffqm_nlp.design.solvers.levenberg_marquardt` uses
instead of CasADi's Jacobians of the whole graph."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ...model import vertex as vx
from ...model.marching import crease_quaternion, panel_cell, qmul, rotate_planar
from ...targets import shape
from .. import stencils
from .curvature_loss import curvature_stencils
from .inputs import Setup
from .lifting import MeanTree, fold_multipliers_kv
from .loss import design_residuals, rotation_from_quaternion
from .nlp import Layout

PI = np.pi


def constraint_jacobian(setup: Setup, lay: Layout, sigma: np.ndarray, tree: MeanTree,
                        n_g: int) -> stencils.LocalJacobian:
    """The Jacobian of :func:`simultaneous`'s constraints g (n_g rows, in its order),
    assembled from one stencil per kind of row (:class:`_ConstraintStencils`)."""
    return _ConstraintStencils(setup, lay, sigma, tree).jacobian(n_g)


def residual_jacobian(setup: Setup, lay: Layout, n_r: int
                      ) -> stencils.LocalJacobian | stencils.LiftedJacobian:
    """The Jacobian of :func:`simultaneous`'s residuals (n_r rows, in its order), assembled
    from stencils (:class:`_ResidualStencils`); with a free correspondence the target
    lattice is read as variables of its own and lifted from the controls after
    (:class:`stencils.LiftedJacobian`), so the residuals' Jacobian stays local."""
    inner = _ResidualStencils(setup, lay).jacobian(n_r)
    corr = setup.correspondence
    if corr is None:
        return inner
    controls = np.concatenate([np.arange(lay.slices[n].start, lay.slices[n].stop)
                               for n in ("U", "V")])
    return stencils.LiftedJacobian(inner, lambda x: corr.target_values(x[controls]), controls,
                                   lay.size)


class _StencilRows:
    """Rows of a vector of functions stated as stencils (:mod:`rffqm_nlp.design.stencils`), block
    after block: each block takes the next rows (:meth:`_rows`)."""

    FOLDED = ("Yx", "Yy", "Yz")

    def __init__(self, lay: Layout):
        self.lay = lay
        self.stencils: list[stencils.Stencil] = []
        self._next = 0

    def _rows(self, *shapes) -> list[np.ndarray]:
        """The next rows: one column-major block per shape."""
        blocks = []
        for s in shapes:
            blocks.append(self._next + np.arange(np.prod(s)).reshape(s, order="F"))
            self._next += blocks[-1].size
        return blocks

    def _add(self, name: str, z: list, p: list, expr: list, columns: list, rows: list,
             params: list = ()) -> None:
        """A stencil of the expressions ``expr`` in the symbols z and p, with per-input,
        per-output and per-param index arrays of one shape (:func:`stencils.repeated`)."""
        f = ca.Function(name, [ca.vertcat(*z), ca.vertcat(*p) if p else ca.SX.sym("p", 0)],
                        [ca.vertcat(*expr)])
        self.stencils.append(stencils.repeated(f, columns, rows, list(params)))

    def _whole(self, name: str, inputs: list[ca.SX], expr: ca.SX, columns: np.ndarray
               ) -> None:
        """One instance on the variables ``columns`` (in the order of ``inputs``)."""
        self.stencils.append(stencils.single(name, inputs, expr, columns,
                                             self._rows((expr.numel(),))[0]))


class _ResidualStencils(_StencilRows):
    """The rows of :func:`objective_residuals` as stencils: a curvature target's rows
    (:func:`.curvature_loss.curvature_stencils`), the position term at every
    lattice point (its 3 rows), the fundamental forms at every interior lattice point (its
    row in each of the 6 blocks), and the rows on the design alone
    (:func:`design_residuals`) one instance on the alignment, the boundary vector and a
    free correspondence's controls. With a free correspondence the columns go on past x
    into the target lattice (Tx, Ty, Tz, each column-major over the lattice)."""

    def __init__(self, setup: Setup, lay: Layout):
        super().__init__(lay)
        self.setup = setup
        N, M = lay.shapes["LV"][0], lay.shapes["LH"][1]
        self.n1, self.m1 = N // 2 + 1, M // 2 + 1
        self.free = setup.correspondence is not None

    def jacobian(self, n_r: int) -> stencils.LocalJacobian:
        weights = self.setup.weights
        if self.setup.curvature is not None:
            self.stencils += curvature_stencils(self.setup.curvature, self._points, self._rows)
        if weights.get("forms", 0) > 0:
            self._forms(weights["forms"])
        if weights.get("position", 0) > 0:
            self._position(weights["position"])
        self._design()
        n_t = 3 * self.n1 * self.m1 if self.free else 0
        return stencils.LocalJacobian(self.stencils, [], (n_r, self.lay.size + n_t))

    def _points(self, i: np.ndarray, j: np.ndarray) -> list[np.ndarray]:
        """The columns of the folded lattice points (i, j) (x, y, z), then with a free
        correspondence those of the target lattice points (x, y, z)."""
        mine = [_index(self.lay, n, 2 * i, 2 * j) for n in self.FOLDED]
        if not self.free:
            return mine
        n = self.n1 * self.m1
        return mine + [self.lay.size + c * n + i + self.n1 * j for c in range(3)]

    def _forms(self, weight: float) -> None:
        """(eq:optInverse) at the interior lattice point (a, b): its 3 x 3 neighbourhood's
        forms (:func:`shape.fundamental_forms`) minus the target's, as in
        :func:`loss_residuals`; the target's are constants without a free correspondence."""
        ni, mi = self.n1 - 2, self.m1 - 2
        a, b = (k + 1 for k in _grid(ni, mi))
        offsets = [(di, dj) for dj in (-1, 0, 1) for di in (-1, 0, 1)]  # column-major 3 x 3
        around = [self._points(a + di, b + dj) for di, dj in offsets]
        blocks = [ca.SX.sym(f"r{c}", 3, 3) for c in range(6 if self.free else 3)]
        z = [ca.vec(m) for m in blocks]
        columns = [around[k][c] for c in range(len(blocks)) for k in range(9)]
        mine = shape.fundamental_forms(blocks[:3])
        if self.free:
            theirs, p, params = shape.fundamental_forms(blocks[3:]), [], []
        else:
            p = [ca.SX.sym(f"form{k}") for k in range(6)]
            theirs, params = p, list(shape.fundamental_forms(self.setup.target))
        res = ca.vertcat(*(m - t for m, t in zip(mine, theirs))) / self.setup.spacing ** 2
        self._add("forms", z, p, [np.sqrt(weight / (6 * ni * mi)) * res], columns,
                  self._rows(*[(ni, mi)] * 6), params)

    def _position(self, weight: float) -> None:
        """R r + t minus the target at every lattice point, as in :func:`loss_residuals`
        (rows 3 p + c, p the point's column-major index); the target a constant without a
        free correspondence."""
        i, j = _grid(self.n1, self.m1)
        rigid = _symbols("rigid", 7)
        y = _symbols("y", 3)
        points = self._points(i, j)
        rigid_columns = [np.full(i.shape, self.lay.slices["rigid"].start + k) for k in range(7)]
        if self.free:
            target, p, params = _symbols("t", 3), [], []
            z, columns = y + rigid + target, points[:3] + rigid_columns + points[3:]
        else:
            target = p = _symbols("t", 3)
            z, columns = y + rigid, points + rigid_columns
            params = [self.setup.target[..., c] for c in range(3)]
        moved = ca.mtimes(rotation_from_quaternion(rigid[:4]), ca.vertcat(*y))
        res = (moved + ca.vertcat(*rigid[4:]) - ca.vertcat(*target)) / self.setup.spacing
        self._add("position", z, p, [np.sqrt(weight / i.size) * res], columns,
                  list(self._rows((3, self.n1, self.m1))[0]), params)

    def _design(self) -> None:
        """The rows after the loss: one instance of :func:`design_residuals`."""
        lay, corr = self.lay, self.setup.correspondence
        rigid = ca.SX.sym("rigid", 7)
        boundary = _boundary_columns(lay)
        bvec = ca.SX.sym("boundary", boundary.size)
        inputs = [rigid, bvec]
        columns = [np.arange(lay.slices["rigid"].start, lay.slices["rigid"].stop), boundary]
        grid = None
        if corr is not None:
            grid = tuple(ca.SX.sym(n, *corr.shape) for n in ("U", "V"))
            inputs += list(grid)
            columns += [np.arange(lay.slices[n].start, lay.slices[n].stop) for n in ("U", "V")]
        self._whole("design_residuals", inputs, design_residuals(self.setup, rigid, bvec, grid),
                    np.concatenate(columns))


def _boundary_columns(lay: Layout) -> np.ndarray:
    """Indices in x of the boundary design vector of :func:`simultaneous` (its ``bvec``:
    :meth:`BoundaryData.to_vector`'s order, then omega): the angles alpha and beta of the
    left vertices and then the bottom ones, the left and the bottom sides, omega."""
    N, M = lay.shapes["LV"][0], lay.shapes["LH"][1]
    left, bottom = np.arange(N + 1), np.arange(1, M + 1)
    angles = [np.concatenate([_index(lay, n, left, 0), _index(lay, n, 0, bottom)])
              for n in ("A", "B")]
    return np.concatenate([*angles, _index(lay, "LV", left[:-1], 0),
                           _index(lay, "LH", 0, bottom - 1), [lay.slices["omega"].start]])


def _index(lay: Layout, name: str, i, j=0) -> np.ndarray:
    """Indices in x of block ``name`` of ``lay`` at (i, j) (broadcast)."""
    return lay.slices[name].start + np.asarray(i) + lay.shapes[name][0] * np.asarray(j)


def _grid(n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """(i, j) of an n x m grid, each (n, m)."""
    return np.meshgrid(np.arange(n), np.arange(m), indexing="ij")


def _symbols(name: str, k: int) -> list[ca.SX]:
    return [ca.SX.sym(f"{name}{c}") for c in range(k)]


class _ConstraintStencils(_StencilRows):
    """The rows of :func:`simultaneous`'s g as stencils (:mod:`rffqm_nlp.design.stencils`): the
    same equations, each on one panel's or vertex's own variables. One method per block of
    rows, called in g's order, each taking the next rows."""

    QUAT = ("Qw", "Qx", "Qy", "Qz")

    def __init__(self, setup: Setup, lay: Layout, sigma: np.ndarray, tree: MeanTree):
        super().__init__(lay)
        self.setup, self.sigma, self.tree = setup, sigma, tree
        self.N, self.M = sigma.shape[0] - 1, sigma.shape[1] - 1
        self.kh0, _ = fold_multipliers_kv(sigma)
        self.constants: list[stencils.Constant] = []

    def jacobian(self, n_g: int) -> stencils.LocalJacobian:
        N, M = self.N, self.M
        march = self._rows((4, N, M))[0]
        self._edge_directions()
        self._multiplier_angles()
        self._rotations()
        self._vertices()
        sides, root = self._partial_means()
        self._cells([*march, *self._rows((N, M))])
        self._boundary_mv()
        self._sides(sides, root)
        if self.setup.correspondence is not None:
            self._grid_rows()
        return stencils.LocalJacobian(self.stencils, self.constants, (n_g, self.lay.size))

    # ------------------------------------------------------------------ helpers
    def _ix(self, name: str, i, j=0) -> np.ndarray:
        return _index(self.lay, name, i, j)

    def _omega(self, shape) -> np.ndarray:
        return np.full(shape, self.lay.slices["omega"].start)

    # ------------------------------------------------------------------ blocks of g
    def _cells(self, rows: list[np.ndarray]) -> None:
        """The panel cell (eq:marchingSector .. eq:getSides): vertex d and the sides of d
        (4 rows per panel), and the margin sign * (mu_abc^2 - 1) (``rows``: 5 blocks)."""
        N, M, S, ix = self.N, self.M, self.sigma, self._ix
        i, j = _grid(N, M)
        z, p = _symbols("z", 12), _symbols("p", 4)
        a00, b00, a10, b10, a01, b01, a11, b11, lv0, lv1, lh0, lh1 = z
        xs, ys = panel_cell()(ca.vertcat(a10, b10, p[0], lv0),
                              ca.vertcat(a00, b00, p[1], a01, b01, p[2], lh0))
        side = vx.panel_side_residuals(a00, PI - b10, b01, lv0, lh0, lv1, lh1)
        self._add("cell", z, p, [a11 - xs[0], b11 - xs[1], *side, p[3] * (ys[1] ** 2 - 1)],
                  [ix("A", i, j), ix("B", i, j), ix("A", i + 1, j), ix("B", i + 1, j),
                   ix("A", i, j + 1), ix("B", i, j + 1), ix("A", i + 1, j + 1),
                   ix("B", i + 1, j + 1), ix("LV", i, j), ix("LV", i, j + 1),
                   ix("LH", i, j), ix("LH", i + 1, j)], rows,
                  [S[1:, :M], S[:N, :M], S[:N, 1:],
                   np.where(self.setup.mu_outside, 1.0, -1.0).reshape(N, M, order="F")])

    def _edge_directions(self) -> None:
        """TH along the left column, then along the rows (linear)."""
        N, M, ix = self.N, self.M, self._ix
        left, rows = self._rows((N,), (N + 1, M))
        z = _symbols("z", 4)
        k = np.arange(N)
        self._add("theta_left", z, [], [z[0] - z[1] - (z[2] - z[3])],
                  [ix("TH", k + 1), ix("TH", k), ix("A", k), ix("B", k + 1)], [left])
        i, j = _grid(N + 1, M)
        self._add("theta", z, [], [z[0] - z[1] - (PI - z[2] - z[3])],
                  [ix("TH", i, j + 1), ix("TH", i, j), ix("A", i, j + 1), ix("B", i, j + 1)],
                  [rows])

    def _multiplier_angles(self) -> None:
        """PHI of the bottom row from its vertex, then the chain up the columns (see
        :func:`local_crease_quaternions`)."""
        N, M, S, ix = self.N, self.M, self.sigma, self._ix
        bottom, rows = self._rows((M,), (N - 2, M))
        z, p = _symbols("z", 3), _symbols("p", 2)
        num, den = vx.mu2_terms(z[1], z[2], p[0])
        j = np.arange(M)
        self._add("phi_bottom", z, p, [ca.sin(z[0]) * num + p[1] * ca.cos(z[0]) * den],
                  [ix("PHI", 0, j), ix("A", 0, j), ix("B", 0, j)], [bottom],
                  [S[0, :M], S[1, :M] * self.kh0[:M]])
        z, p = _symbols("z", 2), _symbols("p", 1)
        i, j = _grid(N - 2, M)
        self._add("phi", z, p, [z[0] - p[0] * z[1]], [ix("PHI", i + 1, j), ix("PHI", i, j)],
                  [rows], [S[2:N, :M]])

    def _rotations(self) -> None:
        """Panel rotations (eq:defGrads): R times a crease quaternion, along the bottom row,
        then up the columns."""
        N, M, S, ix, Q = self.N, self.M, self.sigma, self._ix, self.QUAT
        bottom, rows = self._rows((M - 1, 4), (N - 1, M, 4))
        z, p = _symbols("z", 12), _symbols("p", 2)
        c, s = ca.cos(z[11] / 2), ca.sin(z[11] / 2)
        num, den = vx.mu2_terms(z[9], z[10], p[0])
        qv = crease_quaternion(z[8] + z[9], -p[1] * den, c, s, sign=-1.0, k_den=num)
        prod = qmul(z[4:8], qv)
        j = np.arange(1, M)
        self._add("rotation_bottom", z, p, [z[k] - prod[k] for k in range(4)],
                  [*(ix(n, 0, j) for n in Q), *(ix(n, 0, j - 1) for n in Q), ix("TH", 0, j),
                   ix("A", 0, j), ix("B", 0, j), self._omega(j.shape)],
                  [bottom[:, k] for k in range(4)], [S[0, 1:M], self.kh0[1:M]])
        z, p = _symbols("z", 13), _symbols("p", 1)
        c, s = ca.cos(z[12] / 2), ca.sin(z[12] / 2)
        num, den = vx.mu2_terms(z[10], z[11], p[0])
        qh = crease_quaternion(z[8], -ca.sin(z[9]) * num, c, s, k_den=ca.cos(z[9]) * den)
        prod = qmul(z[4:8], qh)
        i, j = _grid(N - 1, M)
        self._add("rotation", z, p, [z[k] - prod[k] for k in range(4)],
                  [*(ix(n, i + 1, j) for n in Q), *(ix(n, i, j) for n in Q),
                   ix("TH", i + 1, j), ix("PHI", i, j), ix("A", i + 1, j), ix("B", i + 1, j),
                   self._omega(i.shape)], [rows[..., k] for k in range(4)], [S[1:N, :M]])

    def _vertices(self) -> None:
        """Folded vertices (eq:finalCalc): the previous one plus a rotated edge, along the
        bottom row, then up the columns (the last column's edges turn with the panel on
        their left)."""
        N, M, ix, Q, Y = self.N, self.M, self._ix, self.QUAT, self.FOLDED
        bottom, rows = self._rows((M, 3), (N, M + 1, 3))
        z = _symbols("z", 12)
        edge = rotate_planar(z[6:10], z[10] * ca.cos(z[11]), z[10] * ca.sin(z[11]))
        j = np.arange(M)
        self._add("vertex_bottom", z, [], [z[k] - z[3 + k] - edge[k] for k in range(3)],
                  [*(ix(n, 0, j + 1) for n in Y), *(ix(n, 0, j) for n in Y),
                   *(ix(n, 0, j) for n in Q), ix("LH", 0, j), ix("TH", 0, j)],
                  [bottom[:, k] for k in range(3)])
        z = _symbols("z", 13)
        theta = z[11] + z[12]
        edge = rotate_planar(z[6:10], z[10] * ca.cos(theta), z[10] * ca.sin(theta))
        i, j = _grid(N, M + 1)
        panel = np.minimum(j, M - 1)
        self._add("vertex", z, [], [z[k] - z[3 + k] - edge[k] for k in range(3)],
                  [*(ix(n, i + 1, j) for n in Y), *(ix(n, i, j) for n in Y),
                   *(ix(n, i, panel) for n in Q), ix("LV", i, j), ix("TH", i, j),
                   ix("A", i, j)], [rows[..., k] for k in range(3)])

    def _partial_means(self) -> tuple[np.ndarray, int]:
        """The tree of partial means (:class:`MeanTree`, linear); returns (the sides'
        indices in x, in the tree's order; the root's index)."""
        N, M = self.N, self.M
        sides = np.concatenate([self._ix("LH", *_grid(N + 1, M)).ravel("F"),
                                self._ix("LV", *_grid(N, M + 1)).ravel("F")])
        below, k = sides, self.lay.slices["P"].start
        levels = self.tree.levels
        for W, r in zip(levels, self._rows(*((W.size1(),) for W in levels))):
            node = np.arange(k, k + W.size1())
            w = W.sparse().tocoo()
            self.constants.append(stencils.Constant(np.concatenate([r, r[w.row]]),
                                                    np.concatenate([node, below[w.col]]),
                                                    np.concatenate([np.ones(r.size),
                                                                    -w.data])))
            below, k = node, k + W.size1()
        return sides, k - 1

    def _boundary_mv(self) -> None:
        """The boundary MV assignment (:meth:`Setup.boundary_mv`), on the boundary
        vertices' angles, left then bottom."""
        nv = self.N + 1 + self.M
        a, b = ca.SX.sym("a", nv), ca.SX.sym("b", nv)
        mv, _, _ = self.setup.boundary_mv(a, b)
        self._whole("mv", [a, b], mv, _boundary_columns(self.lay)[:2 * nv])

    def _sides(self, sides: np.ndarray, root: int) -> None:
        """Every side against min_length times the mean side (linear)."""
        r = self._rows((sides.size,))[0]
        self.constants.append(stencils.Constant(
            np.concatenate([r, r]), np.concatenate([sides, np.full(r.size, root)]),
            np.concatenate([np.ones(r.size), np.full(r.size, -self.setup.min_length)])))

    def _grid_rows(self) -> None:
        """The control rows of a free correspondence (:meth:`Correspondence.rows`)."""
        corr, lay = self.setup.correspondence, self.lay
        U, V = (ca.SX.sym(n, *corr.shape) for n in ("U", "V"))
        g, _, _ = corr.rows(U, V)
        self._whole("grid", [U, V], g, np.concatenate(
            [np.arange(lay.slices[n].start, lay.slices[n].stop) for n in ("U", "V")]))
