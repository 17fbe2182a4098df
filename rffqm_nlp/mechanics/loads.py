"""The linear response of a folded state to loads: supports, ties (the lock), point loads,
gravity and prescribed displacements, and what is reported of it.

Vertices are named 1-based, (i, j), as everywhere in the package. A tie is a straight
strut between two vertices (the lock of a design, or any pair): a bar of axial stiffness
``stiffness`` (N/m) added to the model; without a stiffness it is as stiff as a strip of
the sheet as wide as it is long (E t). Supports hold every component of their vertices.
The state must be held: the supports must stop every rigid motion, and the folding mode
must be stopped by fold stiffness, a support or a tie; otherwise :class:`InputError` says
which is free.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from ..files import Key, check_value
from ..model.backend import finite_array
from .modes import factorized, rigid_motions

if TYPE_CHECKING:
    from .model import BarAndHinge

#: Standard gravity (m/s^2).
GRAVITY = 9.80665
#: A mechanism is free when the constraints stop it by less than this (relative).
FREE_TOL = 1e-9


@dataclass(frozen=True)
class Ties:
    """Struts between pairs of vertices: ``pairs`` (n, 2, 2) 1-based vertices ((i1, j1),
    (i2, j2)); ``stiffness`` the axial stiffness of each (N/m), None for E t of the
    model's sheet."""

    pairs: np.ndarray
    stiffness: float | None = None

    def __post_init__(self) -> None:
        pairs = finite_array(self.pairs, "ties", allowed="(n, 2, 2) 1-based vertex pairs "
                             "((i1, j1), (i2, j2))")
        if pairs.ndim != 3 or pairs.shape[1:] != (2, 2) or np.any(pairs != np.round(pairs)):
            raise InputError(f"ties must be (n, 2, 2) whole 1-based vertex pairs ((i1, j1), "
                             f"(i2, j2)), got shape {pairs.shape}")
        object.__setattr__(self, "pairs", pairs.astype(int))
        object.__setattr__(self, "stiffness", check_value(
            self.stiffness, Key("number", low=0.0, low_open=True, high=1e15, optional=True,
                                hint="(N/m)"), "tie stiffness"))


@dataclass(frozen=True)
class Response:
    """The linear response of a state to its loads (SI units).

    * ``displacement`` (N+1, M+1, 3): every vertex's displacement (m);
    * ``largest_deflection_mm`` and ``largest_at``: the largest displacement's length (mm)
      and its 1-based vertex (i, j);
    * ``bar_strains`` (n_bars,): elongation over length of every bar;
    * ``hinge_moments`` (n_hinges,): moment of every hinge (N m), bending hinges then fold
      hinges, positive closing a valley;
    * ``tie_forces`` (n_ties,): tension of every tie (N);
    * ``reactions`` (N+1, M+1, 3): the forces the supports and prescribed displacements
      apply (N), zero elsewhere;
    * ``energy``: the strain energy (J), ties included.
    """

    displacement: np.ndarray
    largest_deflection_mm: float
    largest_at: tuple[int, int]
    bar_strains: np.ndarray
    hinge_moments: np.ndarray
    tie_forces: np.ndarray
    reactions: np.ndarray
    energy: float


def check_vertices(value: Any, name: str, N: int, M: int, least: int = 0) -> np.ndarray:
    """``value`` as (k, 2) whole 1-based vertices (i, j) with 1 <= i <= N+1, 1 <= j <= M+1
    and at least ``least`` of them; :class:`InputError` otherwise."""
    arr = finite_array(value, name, allowed="a list of 1-based vertices (i, j)")
    if arr.size == 0:
        arr = arr.reshape(0, 2)
    elif arr.shape == (2,):
        arr = arr[None]
    if arr.ndim != 2 or arr.shape[1] != 2 or len(arr) < least or np.any(arr != np.round(arr)):
        raise InputError(f"{name} must be at least {least} whole 1-based vertices (i, j), "
                         f"got shape {arr.shape}")
    bad = (arr[:, 0] < 1) | (arr[:, 0] > N + 1) | (arr[:, 1] < 1) | (arr[:, 1] > M + 1)
    if bad.any():
        i, j = arr[np.argmax(bad)]
        raise InputError(f"{name} must name vertices (i, j) with 1 <= i <= {N + 1} and "
                         f"1 <= j <= {M + 1}, got ({i:g}, {j:g})")
    return arr.astype(int)


def _rows(value: Any, name: str, N: int, M: int, unit: str) -> tuple[np.ndarray, np.ndarray]:
    """Rows (i, j, x, y, z): the (k,) node indices and the (k, 3) vectors."""
    if value is None:
        return np.zeros(0, int), np.zeros((0, 3))
    arr = finite_array(value, name, allowed=f"rows (i, j, x, y, z) in {unit}")
    arr = arr.reshape(1, -1) if arr.ndim == 1 else arr
    if arr.ndim != 2 or arr.shape[1] != 5:
        raise InputError(f"{name} must be rows (i, j, x, y, z) in {unit}, got shape "
                         f"{arr.shape}")
    vertices = check_vertices(arr[:, :2], name, N, M)
    return _nodes(vertices, M), arr[:, 2:]


def _nodes(vertices: np.ndarray, M: int) -> np.ndarray:
    """Node indices (i-1)(M+1) + (j-1) of 1-based vertices (k, 2)."""
    return (vertices[:, 0] - 1) * (M + 1) + (vertices[:, 1] - 1)


def _unit(value: Any, name: str) -> np.ndarray:
    d = finite_array(value, name, shape=(3,), allowed="a direction (x, y, z)")
    size = np.linalg.norm(d)
    if not size > 0:
        raise InputError(f"{name} must be a non-zero direction (x, y, z)")
    return d / size


def _check_ties(ties: Any, model: "BarAndHinge") -> tuple[np.ndarray, float]:
    """(node pairs (n, 2), stiffness N/m) of ``ties``."""
    if ties is None:
        return np.zeros((0, 2), int), 0.0
    t = ties if isinstance(ties, Ties) else Ties(ties)
    ends = check_vertices(t.pairs.reshape(-1, 2), "ties", model.N, model.M)
    nodes = _nodes(ends, model.M).reshape(-1, 2)
    if np.any(nodes[:, 0] == nodes[:, 1]):
        raise InputError("a tie must join two different vertices")
    material = model.material
    return nodes, (material.E * material.thickness if t.stiffness is None else t.stiffness)


def _gravity(model: "BarAndHinge", down: np.ndarray) -> np.ndarray:
    """Nodal weights (n_nodes, 3) in N: each triangle's mass rho t A, a third at each of
    its nodes."""
    P, tri = model.positions, model.frame.triangles
    area = np.linalg.norm(np.cross(P[tri[:, 1]] - P[tri[:, 0]], P[tri[:, 2]] - P[tri[:, 0]]),
                          axis=1) / 2
    mass = np.zeros(len(P))
    np.add.at(mass, tri.ravel(), np.repeat(model.material.density
                                           * model.material.thickness * area / 3, 3))
    return mass[:, None] * GRAVITY * down


def _tie_rows(P: np.ndarray, nodes: np.ndarray) -> sp.csr_matrix:
    """The ties' compatibility rows (n_ties, 3 n_nodes), as the rigidity matrix's."""
    from .compatibility import rigidity_matrix

    return rigidity_matrix(P, nodes) if len(nodes) else sp.csr_matrix((0, 3 * len(P)))


def _check_held(model: "BarAndHinge", fixed: np.ndarray, T: sp.csr_matrix) -> None:
    """:class:`InputError` unless the supports stop every rigid motion and the supports,
    ties or fold stiffness stop the folding mode."""
    rigid = rigid_motions(model.positions)
    if np.linalg.matrix_rank(rigid[fixed], tol=FREE_TOL) < 6:
        raise InputError("the supports leave the pattern free to move rigidly: hold at least "
                         "three vertices that are not on one line")
    if model.material.fold_stiffness > 0:
        return
    space = np.column_stack([rigid, model.velocity / np.linalg.norm(model.velocity)])
    G = np.vstack([space[fixed], T @ space])
    s = np.linalg.svd(G, compute_uv=False)
    if s[-1] <= FREE_TOL * s[0]:
        raise InputError("the pattern is free to fold: without fold stiffness a support or "
                         "a tie (the lock) must stop the folding mode")


def corners(N: int, M: int) -> np.ndarray:
    """The four corner vertices (4, 2) of N x M panels, 1-based: the default supports."""
    return np.array([[1, 1], [1, M + 1], [N + 1, 1], [N + 1, M + 1]])


def _constraints(model: "BarAndHinge", supports: Any,
                 displacements: Any) -> tuple[np.ndarray, np.ndarray]:
    """(fixed dofs, their prescribed values in m) of the supports (None: the corners) and
    the displacements."""
    supports = corners(model.N, model.M) if supports is None else supports
    held = _nodes(check_vertices(supports, "supports", model.N, model.M), model.M)
    moved, values = _rows(displacements, "displacements", model.N, model.M, "m")
    nodes = np.concatenate([held, moved])
    if len(np.unique(nodes)) < len(nodes):
        raise InputError("a vertex is named twice among the supports and displacements")
    dofs = (3 * nodes[:, None] + np.arange(3)).ravel()
    return dofs, np.concatenate([np.zeros((len(held), 3)), values]).ravel()


def _forces(model: "BarAndHinge", loads: Any, gravity: bool, down: Any) -> np.ndarray:
    """The load vector (3 n_nodes,) in N."""
    f = np.zeros((len(model.positions), 3))
    nodes, values = _rows(loads, "loads", model.N, model.M, "N")
    np.add.at(f, nodes, values)
    if check_value(gravity, Key("bool"), "gravity"):
        f += _gravity(model, _unit(down, "down"))
    return f.ravel()


def solve(model: "BarAndHinge", loads: Any = None, supports: Any = None,
          ties: Any = None, gravity: bool = False, displacements: Any = None,
          down: Any = (0.0, 0.0, -1.0)) -> Response:
    """The linear response of ``model``'s state (:class:`Response`): point ``loads`` rows
    (i, j, Fx, Fy, Fz) in N, ``supports`` (k, 2) 1-based vertices held (None: the four corners), ``ties``
    (:class:`Ties` or (n, 2, 2) vertex pairs), ``gravity`` (the material's weight along the
    unit vector ``down``), ``displacements`` rows (i, j, ux, uy, uz) in m. One sparse LU
    factorisation of the free part of the stiffness. Raises :class:`InputError` for bad
    arguments and a state that the supports and ties do not hold."""
    P = model.positions
    tie_nodes, tie_k = _check_ties(ties, model)
    T = _tie_rows(P, tie_nodes)
    fixed, prescribed = _constraints(model, supports, displacements)
    _check_held(model, fixed, T)
    f = _forces(model, loads, gravity, down)
    K = (model.stiffness() + tie_k * (T.T @ T)).tocsc()
    free = np.setdiff1d(np.arange(K.shape[0]), fixed)
    u = np.zeros(K.shape[0])
    u[fixed] = prescribed
    rhs = f[free] - K[free][:, fixed] @ prescribed
    try:
        u[free] = factorized(K[free][:, free]).solve(rhs)
    except RuntimeError:
        raise InputError("the stiffness is singular under these supports and ties: hold "
                         "more vertices or add a tie") from None
    if not np.all(np.isfinite(u)):
        raise InputError("the response is not finite: the stiffness is singular under these "
                         "supports and ties; hold more vertices or add a tie")
    return _response(model, u, K, f, tie_k * (T @ u))


def _response(model: "BarAndHinge", u: np.ndarray, K: sp.spmatrix, f: np.ndarray,
              tie_forces: np.ndarray) -> Response:
    """The :class:`Response` of the displacements ``u`` (3 n_nodes,) under the stiffness
    ``K`` (ties included) and the loads ``f``."""
    N, M = model.N, model.M
    U = u.reshape(N + 1, M + 1, 3)
    size = np.linalg.norm(U, axis=2)
    at = np.unravel_index(int(np.argmax(size)), size.shape)
    Ku = K @ u
    strains = model.rigidity_matrix() @ u / model.bar_lengths()
    moments = model.hinge_stiffness() * (model.hinge_jacobian() @ u)
    with np.errstate(all="ignore"):
        energy = 0.5 * float(u @ Ku)
    parts = (size, strains, moments, tie_forces, Ku, np.array(energy))
    if not all(np.all(np.isfinite(part)) for part in parts):
        raise InputError("the response overflows: the loads or displacements are too large "
                         "for floating point")
    return Response(U, float(size.max()) * 1e3, (int(at[0]) + 1, int(at[1]) + 1), strains,
                    moments, tie_forces, (Ku - f).reshape(N + 1, M + 1, 3), energy)


def point_stiffness(model: "BarAndHinge", vertex: Any, direction: Any,
                    supports: Any = None, ties: Any = None) -> float:
    """The stiffness (N/m) against a unit point load at the 1-based ``vertex`` along the
    unit vector of ``direction``: 1 N over the displacement it causes there along it."""
    node = _nodes(check_vertices(vertex, "vertex", model.N, model.M), model.M)
    if len(node) != 1:
        raise InputError("vertex must be one 1-based vertex (i, j)")
    d = _unit(direction, "direction")
    i, j = divmod(int(node[0]), model.M + 1)
    response = solve(model, loads=[[i + 1, j + 1, *d]], supports=supports, ties=ties)
    along = float(response.displacement[i, j] @ d)
    if not along > 0:
        raise InputError("the load's vertex is held: choose a vertex that is not a support")
    return 1.0 / along
