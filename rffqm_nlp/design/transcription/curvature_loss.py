"""The loss of a curvature target (:class:`~rffqm_nlp.targets.curvature_target.Curvature`,
docs/curvature_targets.md): at every interior point of the folded coarse lattice its
discrete curvatures against the prescription (:func:`cell_residuals`), and for every line
of the lattice its length against the footprint's (:func:`line_lengths`); stated once for
the whole graph (:func:`curvature_residuals`) and once as local stencils for
:mod:`rffqm_nlp.design.solvers.levenberg_marquardt` (:func:`curvature_stencils`), in the
same rows.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from ...model.backend import is_casadi, math_for
from ...targets import shape
from ...targets.curvature_target import Curvature
from .. import stencils

#: The weights of a curvature target's loss (DesignProblem.weights).
WEIGHT_NAMES = ("curvature", "size")


@dataclass(frozen=True)
class CurvatureLoss:
    """What a curvature target asks of the coarse lattice (N+1, M+1):

    * ``kind``: "gaussian" or "principal" (:attr:`Curvature.kind`);
    * ``prescribed``: the prescribed fields at the interior points, each (N-1, M-1): (K,),
      (K, H) or (kx, ky) (1 / length);
    * ``scale``: the curvature scale kappa (:meth:`Curvature.scale`), which makes the rows
      relative; ``size``: the footprint (Lx, Ly);
    * ``weights``: the weights of the cell rows and of the line rows.
    """

    kind: str
    prescribed: tuple[np.ndarray, ...]
    scale: float
    size: tuple[float, float]
    weights: tuple[float, float]

    @classmethod
    def of(cls, target: Curvature, N: int, M: int, weights: dict[str, float]
           ) -> "CurvatureLoss":
        """The loss of ``target`` on an (N+1) x (M+1) lattice with ``weights`` (the
        problem's: "curvature" and "size", missing ones 0)."""
        x, y = target.lattice_xy(N, M)
        values = target.values(x[1:-1, None], y[None, 1:-1])
        return cls(kind=target.kind, prescribed=tuple(values[k] for k in target.fields),
                   scale=target.scale(N, M), size=tuple(target.size),
                   weights=tuple(float(weights.get(k, 0.0)) for k in WEIGHT_NAMES))

    @property
    def cells(self) -> int:
        """The interior points, (N-1) (M-1)."""
        return int(self.prescribed[0].size)

    @property
    def rows_per_cell(self) -> int:
        """Rows per interior point: 1 (K), 2 (K, H) or 5 (kx, ky, the twist, the angle and
        K)."""
        return 5 if self.kind == "principal" else len(self.prescribed)


def shape_operator(forms: Sequence[Any]) -> tuple[Any, Any, Any]:
    """(S11, S12, S22) of the symmetric shape operator I^(-1/2) II I^(-1/2) from the forms
    (E, F, G, L, M, N) (NumPy arrays or CasADi matrices of one shape): the second form in
    the orthonormal tangent frame closest to (r_u, r_v) (their polar factor), so S11 = L / E
    and S22 = N / G where F = 0. Its eigenvalues are the principal curvatures; det S = K,
    tr S = 2 H. With s = sqrt(EG - F^2), t = sqrt(E + G + 2 s),
    I^(-1/2) = [[G + s, -F], [-F, E + s]] / (s t)."""
    E, F, G, L, M, N = forms
    m = math_for(*forms)
    s = m.sqrt(E * G - F * F)
    st = s * m.sqrt(E + G + 2 * s)
    a, b, c = (G + s) / st, -F / st, (E + s) / st
    row0, row1 = (a * L + b * M, a * M + b * N), (b * L + c * M, b * M + c * N)
    return (row0[0] * a + row0[1] * b, row0[0] * b + row0[1] * c,
            row1[0] * b + row1[1] * c)


def cell_residuals(forms: Sequence[Any], prescribed: Sequence[Any], kind: str,
                   scale: float) -> list[Any]:
    """The rows of one or many interior points (each argument of one shape): with
    "gaussian" (K - K*) / kappa^2 and, where H* is prescribed, (H - H*) / kappa, K and H
    from the forms as :mod:`rffqm_nlp.targets.curvature` has them; with "principal"
    (S11 - kx*) / kappa, (S22 - ky*) / kappa and sqrt(2) S12 / kappa
    (:func:`shape_operator`), whose squares sum to |S - diag(kx*, ky*)|^2 / kappa^2,
    F / sqrt(E G), the cosine of the angle of the lattice's lines, which lines of
    curvature make right, and (K - kx* ky*) / kappa^2: all vanish where the lattice's
    lines are lines of curvature of these principal curvatures; where no surface has them,
    the K row keeps the compromise's Gaussian curvature (docs/curvature_targets.md)."""
    E, F, G, L, M, N = forms
    if kind == "principal":
        s11, s12, s22 = shape_operator(forms)
        return [(s11 - prescribed[0]) / scale, (s22 - prescribed[1]) / scale,
                np.sqrt(2.0) * s12 / scale, F / math_for(*forms).sqrt(E * G),
                ((L * N - M * M) / (E * G - F * F) - prescribed[0] * prescribed[1])
                / scale ** 2]
    det = E * G - F * F
    out = [((L * N - M * M) / det - prescribed[0]) / scale ** 2]
    if len(prescribed) > 1:
        out.append(((E * N - 2 * F * M + G * L) / (2 * det) - prescribed[1]) / scale)
    return out


def line_lengths(r: Sequence[Any]) -> tuple[Any, Any]:
    """The lengths of the lattice's lines, r = (rx, ry, rz) each (n, m): along i for every
    column (1, m) and along j for every row (n, 1); sums of the straight steps."""
    m = math_for(*r)
    steps_i = m.sqrt(sum((c[1:, :] - c[:-1, :]) ** 2 for c in r))
    steps_j = m.sqrt(sum((c[:, 1:] - c[:, :-1]) ** 2 for c in r))
    if is_casadi(*r):
        return ca.sum1(steps_i), ca.sum2(steps_j)
    return steps_i.sum(axis=0, keepdims=True), steps_j.sum(axis=1, keepdims=True)


def curvature_residuals(r: Sequence[ca.MX], loss: CurvatureLoss) -> ca.MX:
    """The loss rows of the coarse lattice r = (rx, ry, rz) ((N+1) x (M+1) each): the cell
    rows of :func:`cell_residuals`, block by block, each block (N-1, M-1) column-major,
    times sqrt(w_curvature / cells); then the lines' lengths over Lx (M+1 lines along i)
    and over Ly (N+1 along j), less 1, times sqrt(w_size / lines)."""
    forms = shape.fundamental_forms(r)
    w_cells, w_size = loss.weights
    out = []
    if w_cells > 0:
        rows = cell_residuals(forms, [ca.DM(p) for p in loss.prescribed], loss.kind,
                              loss.scale)
        out += [np.sqrt(w_cells / loss.cells) * ca.vec(row) for row in rows]
    if w_size > 0:
        along_i, along_j = line_lengths(r)
        lines = along_i.numel() + along_j.numel()
        out += [np.sqrt(w_size / lines) * (ca.vec(along_i) / loss.size[0] - 1),
                np.sqrt(w_size / lines) * (ca.vec(along_j) / loss.size[1] - 1)]
    return ca.vertcat(*out)


def curvature_stencils(loss: CurvatureLoss,
                       points: Callable[[np.ndarray, np.ndarray], list[np.ndarray]],
                       rows: Callable[..., list[np.ndarray]]) -> list[stencils.Stencil]:
    """The rows of :func:`curvature_residuals` as stencils: one per interior point on its
    3 x 3 neighbourhood of lattice points, one per line on its points. ``points(i, j)``
    gives the columns in x of the lattice points (i, j) (x, y, z, each of the shape of i),
    ``rows(*shapes)`` the next rows of the residuals, one column-major block per shape."""
    out = []
    w_cells, w_size = loss.weights
    ni, mi = loss.prescribed[0].shape
    if w_cells > 0:
        a, b = np.meshgrid(np.arange(1, ni + 1), np.arange(1, mi + 1), indexing="ij")
        around = [points(a + di, b + dj) for dj in (-1, 0, 1) for di in (-1, 0, 1)]
        blocks = [ca.SX.sym(f"r{c}", 3, 3) for c in range(3)]
        p = [ca.SX.sym(f"p{k}") for k in range(len(loss.prescribed))]
        res = cell_residuals(shape.fundamental_forms(blocks), p, loss.kind, loss.scale)
        f = ca.Function("curvature", [ca.vertcat(*(ca.vec(m) for m in blocks)), ca.vertcat(*p)],
                        [np.sqrt(w_cells / loss.cells) * ca.vertcat(*res)])
        out.append(stencils.repeated(f, [around[k][c] for c in range(3) for k in range(9)],
                                     rows(*[(ni, mi)] * len(res)), list(loss.prescribed)))
    if w_size > 0:
        n1, m1 = ni + 2, mi + 2
        weight = np.sqrt(w_size / (n1 + m1))
        j = np.arange(m1)
        along_i = [points(np.full(m1, i), j) for i in range(n1)]  # line j: points (0..N, j)
        out.append(_line_stencil(along_i, loss.size[0], weight, rows((m1,))[0]))
        i = np.arange(n1)
        along_j = [points(i, np.full(n1, k)) for k in range(m1)]  # line i: points (i, 0..M)
        out.append(_line_stencil(along_j, loss.size[1], weight, rows((n1,))[0]))
    return out


def _line_stencil(line: list[list[np.ndarray]], total: float, weight: float,
                  rows: np.ndarray) -> stencils.Stencil:
    """One row per line, weight (its length / total - 1): ``line[k]`` holds the columns
    (x, y, z) of the line's k-th point at every instance."""
    n = len(line)
    xyz = [ca.SX.sym(c, n) for c in "xyz"]
    length = sum(ca.sqrt(sum((c[k + 1] - c[k]) ** 2 for c in xyz)) for k in range(n - 1))
    f = ca.Function("line", [ca.vertcat(*xyz), ca.SX.sym("p", 0)],
                    [weight * (length / total - 1)])
    return stencils.repeated(f, [line[k][c] for c in range(3) for k in range(n)], [rows])


def loss_value(coarse: np.ndarray, loss: CurvatureLoss) -> float:
    """The loss (half the sum of the squared rows of :func:`curvature_residuals`) of a
    coarse lattice (N+1, M+1, 3) in NumPy."""
    r = [coarse[..., c] for c in range(3)]
    w_cells, w_size = loss.weights
    total = 0.0
    with np.errstate(all="ignore"):
        if w_cells > 0:
            rows = cell_residuals(shape.fundamental_forms(r), loss.prescribed, loss.kind,
                                  loss.scale)
            total += w_cells / loss.cells * sum(float(np.sum(row ** 2)) for row in rows)
        if w_size > 0:
            along_i, along_j = line_lengths(r)
            lines = along_i.size + along_j.size
            total += w_size / lines * float(np.sum((along_i / loss.size[0] - 1) ** 2)
                                            + np.sum((along_j / loss.size[1] - 1) ** 2))
    return 0.5 * total if np.isfinite(total) else float("inf")
