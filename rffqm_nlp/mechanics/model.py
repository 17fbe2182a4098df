"""The bar-and-hinge model of a pattern at a folded state: :class:`BarAndHinge`.

N4B5 after Filipov et al. (Int. J. Solids Struct. 2017): the nodes are the pattern's own
vertices, so the rigidity matrix has exactly three columns per vertex in the order of the
pattern's arrays, vertex (i, j) at node (i-1)(M+1) + (j-1), and the exact folding
velocity of the march (:mod:`.folding`) is a vector of that space as it is. (N5B8 adds a
node in every panel, whose velocity the march does not give.) The bars are the panel
edges and one diagonal per panel (:mod:`.frame`), their stiffness the panels' membrane
(:mod:`.material`); panels bend on hinges along their diagonals, and the creases fold on
hinges whose rest angle is the fold angle at this state, so the state is unstressed and
the stiffness is the linear one, K = R^T C R + J^T diag(k) J.

Lengths are in metres: the pattern's unit times ``scale`` (m per pattern unit), which
``width`` (the flat pattern's extent along x, in metres) sets.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ..files import Key, check_value
from ..model.pattern import Pattern, check_fold_angle, check_pattern
from . import compatibility
from .folding import folded_state
from .frame import build_frame
from .loads import Response, point_stiffness, solve
from .material import Material, bending_stiffness, check_material, membrane_matrix
from .modes import Modes, folding_energy, softest_modes

_WIDTH = Key("number", low=1e-6, high=1e4, optional=True, hint="(m)")
#: Most modes :meth:`BarAndHinge.modes` computes.
MAX_MODES = 200


class BarAndHinge:
    """The N4B5 bar-and-hinge model of ``pattern`` folded at ``omega`` (module docstring).

    ``material`` is a :class:`~.material.Material`; ``width`` (m, 1e-6 to 1e4) the flat
    pattern's extent along x, None to read the pattern's lengths as metres. Raises :class:`InputError` for
    a bad argument.
    """

    def __init__(self, pattern: Pattern, omega: float, material: Material,
                 width: float | None = None):
        self.pattern = check_pattern(pattern, "pattern")
        self.omega = check_fold_angle(omega)
        self.material = check_material(material)
        width = check_value(width, _WIDTH, "width")
        extent = float(np.ptp(pattern.X[..., 0]))
        self.scale = 1.0 if width is None else width / extent
        self.frame = build_frame(pattern.X)
        Y, V = folded_state(pattern, self.omega)
        #: Node positions (n_nodes, 3) in metres and the folding velocity (3 n_nodes,) in m/rad.
        self.positions = Y.reshape(-1, 3) * self.scale
        self.velocity = V.reshape(-1) * self.scale

    @property
    def N(self) -> int:
        """Panel rows."""
        return self.pattern.N

    @property
    def M(self) -> int:
        """Panel columns."""
        return self.pattern.M

    def rigidity_matrix(self) -> sp.csr_matrix:
        """The bars' compatibility matrix R (n_bars, 3 (N+1)(M+1)), sparse: one row per bar
        (:mod:`.frame`'s order), three columns per vertex, vertex (i, j) at node
        (i-1)(M+1) + (j-1), columns x, y, z. R u is the bars' elongation rate (m/s for
        velocities u in m/s)."""
        return compatibility.rigidity_matrix(self.positions, self.frame.bars)

    def hinge_jacobian(self) -> sp.csr_matrix:
        """The hinges' fold-angle Jacobian J (n_hinges, 3 (N+1)(M+1)) in 1/m: bending hinges,
        then fold hinges (:mod:`.frame`); valley positive."""
        return compatibility.hinge_jacobian(self.positions, self.frame.hinges)

    def bar_lengths(self) -> np.ndarray:
        """The bars' lengths (n_bars,) in metres."""
        return compatibility.bar_lengths(self.positions, self.frame.bars)

    def hinge_stiffness(self) -> np.ndarray:
        """The hinges' rotational stiffness (n_hinges,) in N m/rad: k_B on the diagonals,
        fold_stiffness times the crease length on the creases (:mod:`.material`)."""
        h = self.frame.hinges
        length = np.linalg.norm(self.positions[h[:, 1]] - self.positions[h[:, 0]], axis=1)
        k = self.material.fold_stiffness * length
        k[self.frame.bending] = bending_stiffness(length[self.frame.bending], self.material)
        return k

    def membrane(self) -> sp.csr_matrix:
        """The bars' membrane stiffness C (n_bars, n_bars) in N/m (:mod:`.material`)."""
        f = self.frame
        return membrane_matrix(self.positions, f.triangles, f.triangle_bars, len(f.bars),
                               self.material)

    def stiffness(self) -> sp.csr_matrix:
        """The stiffness matrix K = R^T C R + J^T diag(k) J (3 n_nodes square, N/m),
        sparse, symmetric, in the columns of :meth:`rigidity_matrix`."""
        R, J = self.rigidity_matrix(), self.hinge_jacobian()
        K = R.T @ self.membrane() @ R + J.T @ sp.diags(self.hinge_stiffness()) @ J
        return ((K + K.T) / 2).tocsr()

    def folding_stiffness(self) -> float:
        """The folding mode's own stiffness (N/m) (:class:`~.modes.Modes` ``folding``)."""
        return folding_energy(self.stiffness(), self.velocity, self.positions)

    def modes(self, k: int = 12) -> Modes:
        """The ``k`` softest modes (7 to :data:`MAX_MODES`) by shift-invert Lanczos, and
        the folding mode's stiffness beside them (:class:`~.modes.Modes`)."""
        k = check_value(k, Key("whole", low=7, high=MAX_MODES), "k")
        k = min(k, 3 * len(self.positions) - 1)
        return self.modes_of(self.stiffness(), k)

    def modes_of(self, K: sp.spmatrix, k: int) -> Modes:
        """:func:`~.modes.softest_modes` of ``K`` with this model's folding velocity."""
        return softest_modes(K, k, self.velocity, self.positions)

    def solve(self, loads: Any = None, supports: Any = None, ties: Any = None,
              gravity: bool = False, displacements: Any = None,
              down: Any = (0.0, 0.0, -1.0)) -> Response:
        """The linear response of the state to loads (:func:`.loads.solve`): point
        ``loads`` (k, 5) rows (i, j, Fx, Fy, Fz) in N, ``supports`` 1-based vertices (i, j)
        held (None: the four corners), ``ties`` (n, 2, 2) 1-based vertex pairs or :class:`~.loads.Ties`,
        ``gravity`` from the material's density along ``down``, ``displacements`` (k, 5)
        rows (i, j, ux, uy, uz) prescribed in metres."""
        return solve(self, loads=loads, supports=supports, ties=ties, gravity=gravity,
                           displacements=displacements, down=down)

    def point_stiffness(self, vertex: Any, direction: Any, supports: Any = None,
                        ties: Any = None) -> float:
        """The stiffness (N/m) against a point load at the 1-based ``vertex`` along
        ``direction``: the load over the displacement it causes there along it
        (:func:`~.loads.point_stiffness`)."""
        return point_stiffness(self, vertex, direction, supports=supports, ties=ties)
