"""Curvature fields as targets: :class:`Curvature`, reached as ``rq.surfaces.Curvature``
(docs/curvature_targets.md).

A curvature target prescribes no position: it asks the folded coarse lattice for a
Gaussian curvature K (and optionally a mean curvature H), or for principal curvatures kx
along the lattice's i direction and ky along its j direction, over a footprint of size
(Lx, Ly). The lattice point (i, j) of an (N+1) x (M+1) lattice sits at the footprint's
point (x, y) = (i Lx / N, j Ly / M). Each field is a number or a function of (x, y) that
takes and returns NumPy arrays.

Signs follow :mod:`rffqm_nlp.targets.parametric`: the normal is r_u x r_v of the lattice
(i along u, j along v), a normal curvature is positive where the lattice bends towards it,
H = (kx + ky) / 2.

The footprint stands in for a surface where a position is needed: the start's scaling
(:meth:`lattice`), the pictures (:meth:`sample`, :meth:`mesh`), the diameter.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import trimesh

from ..errors import InputError, SurfaceError, one_line
from ..files import Key, check_table, check_value, describe_value
from ..model.backend import finite_array
from .point_sets import GRID, MAX_GRID, grid_faces, refuse_points
from .user_code import check_root, code_of, import_reference, resolve_reference

#: The fields of each kind of prescription, the first ones required.
KINDS = {"gaussian": ("K", "H"), "principal": ("kx", "ky")}
#: What a function named by ``python = ...`` returns, in order (the ``fields`` key).
FIELD_LISTS = (("K",), ("K", "H"), ("kx", "ky"))
#: Points per direction on which a function field is checked (finite, of the right shape).
CHECK_GRID = 9
#: Relative tolerance of the realisability decisions (a field counts as constant, two as
#: equal, a product as zero).
DECISION_TOL = 1e-9
_SIZE = Key("list", length=2, item=Key("number", low=0.0, low_open=True), hint="(Lx, Ly)")
#: The keys of a [target] table of a curvature target (:func:`from_config`).
CURVATURE_KEYS = {
    "size": Key("list", length=2, item=Key("number", low=0.0, low_open=True), required=True,
                hint="(Lx, Ly)"),
    **{name: Key("number") for name in ("K", "H", "kx", "ky")},
    "python": Key("string"),
    "fields": Key("choice", choices=tuple(",".join(f) for f in FIELD_LISTS),
                  hint="(what the function returns)"),
    "name": Key("string"),
}

Field = float | Callable[[np.ndarray, np.ndarray], Any]


@dataclass(frozen=True)
class Realisable:
    """Whether a surface realises a prescription: ``verdict`` True, False, or None where
    the prescription alone does not decide it (then the fit says how close a design came);
    ``reason`` in one sentence."""

    verdict: bool | None
    reason: str


class Curvature:
    """A curvature field as a design target.

    ``Curvature(K=..., H=None, size=(Lx, Ly))``: Gaussian curvature K, and mean curvature H
    where given (then H^2 >= K everywhere); or ``Curvature(kx=..., ky=..., size=(Lx, Ly))``:
    principal curvatures along the lattice's two directions (1 / length units). Each field
    is a number or a function f(x, y) of arrays (x in [0, Lx], y in [0, Ly]) returning
    finite numbers of their broadcast shape. ``reference``: the ``"file.py:function"`` the
    fields were read from (:func:`from_config`), kept for :meth:`to_config`.
    Raises :class:`SurfaceError` for anything else.
    """

    def __init__(self, K: Field | None = None, H: Field | None = None, *,
                 kx: Field | None = None, ky: Field | None = None,
                 size: tuple[float, float] | None = None, name: str = "curvature",
                 reference: str | None = None):
        given = {k: v for k, v in (("K", K), ("H", H), ("kx", kx), ("ky", ky))
                 if v is not None}
        if "K" in given and not {"kx", "ky"} & set(given):
            self.kind = "gaussian"
        elif set(given) == {"kx", "ky"}:
            self.kind = "principal"
        else:
            raise SurfaceError("Curvature takes K (and optionally H), or both kx and ky, "
                               f"each a number or a function of (x, y); got {sorted(given)}")
        if size is None:
            raise SurfaceError("Curvature needs size = (Lx, Ly), the footprint's lengths "
                               "along the lattice's two directions")
        self.size = check_value(size, _SIZE, "size", SurfaceError)
        self.name = check_value(name, Key("string"), "name", SurfaceError)
        self.reference = (None if reference is None else
                          check_value(reference, Key("string"), "reference", SurfaceError))
        self.fields = {k: _checked_field(v, k) for k, v in given.items()}
        x, y = np.meshgrid(*(np.linspace(0, s, CHECK_GRID) for s in self.size),
                           indexing="ij")
        values = self.values(x, y)
        with np.errstate(all="ignore"):
            real = "H" not in values or np.all(values["H"] ** 2 >= values["K"]
                                               * (1 - DECISION_TOL))
        if not real:
            raise SurfaceError("Curvature needs H^2 >= K everywhere (real principal "
                               "curvatures); K and H given do not have it")

    def __repr__(self) -> str:
        shown = ", ".join(f"{k}={v!r}" if not callable(v) else f"{k}=<function>"
                          for k, v in self.fields.items())
        return f"<Curvature {self.name}({shown}) over {self.size[0]:g} x {self.size[1]:g}>"

    # -- the fields ------------------------------------------------------------------------
    def values(self, x: Any, y: Any) -> dict[str, np.ndarray]:
        """Each given field at the points (x, y) (arrays broadcasting together, any shape):
        {"K"[, "H"]} or {"kx", "ky"}, each of the broadcast shape (1 / length)."""
        x = np.asarray(_finite(x, "x"), dtype=float)
        y = np.asarray(_finite(y, "y"), dtype=float)
        try:
            shape = np.broadcast_shapes(x.shape, y.shape)
        except ValueError:
            raise SurfaceError(f"x and y must broadcast together, got shapes {x.shape} and "
                               f"{y.shape}") from None
        return {k: _evaluate(f, x, y, shape, k) for k, f in self.fields.items()}

    def gaussian(self, x: Any, y: Any) -> np.ndarray:
        """The prescribed Gaussian curvature at (x, y): K, or kx ky (1 / length^2)."""
        v = self.values(x, y)
        return v["K"] if self.kind == "gaussian" else v["kx"] * v["ky"]

    def mean(self, x: Any, y: Any) -> np.ndarray | None:
        """The prescribed mean curvature at (x, y): H, (kx + ky) / 2, or None where only K
        is prescribed."""
        v = self.values(x, y)
        if self.kind == "principal":
            return 0.5 * (v["kx"] + v["ky"])
        return v.get("H")

    def principal(self, x: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
        """Principal curvatures (kx, ky) at (x, y) that realise the prescription at each
        point: kx, ky themselves; from K and H, H + sqrt(H^2 - K) along x and
        H - sqrt(H^2 - K) along y; from K alone sqrt(K) along both where K >= 0, and
        +-sqrt(-K) where K < 0 (a saddle whose principal directions are the lattice's)."""
        v = self.values(x, y)
        if self.kind == "principal":
            return v["kx"], v["ky"]
        K = v["K"]
        if "H" in v:
            root = np.sqrt(np.maximum(v["H"] ** 2 - K, 0.0))
            return v["H"] + root, v["H"] - root
        root = np.sqrt(np.abs(K))
        return root, np.where(K >= 0, root, -root)

    # -- the footprint ---------------------------------------------------------------------
    @property
    def domain(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """The footprint ((0, Lx), (0, Ly))."""
        return (0.0, self.size[0]), (0.0, self.size[1])

    def lattice_xy(self, N: int, M: int) -> tuple[np.ndarray, np.ndarray]:
        """The footprint's points of an (N+1) x (M+1) lattice: x (N+1,) and y (M+1,),
        uniform over [0, Lx] and [0, Ly]."""
        N = check_value(N, Key("whole", low=1, high=MAX_GRID), "N", SurfaceError)
        M = check_value(M, Key("whole", low=1, high=MAX_GRID), "M", SurfaceError)
        refuse_points((N + 1) * (M + 1), 8, f"a {N + 1} x {M + 1} lattice")
        return np.linspace(0.0, self.size[0], N + 1), np.linspace(0.0, self.size[1], M + 1)

    def lattice(self, N: int, M: int) -> np.ndarray:
        """The flat footprint lattice (N+1, M+1, 3), (x, y, 0) at :meth:`lattice_xy`: what
        the start scales its Miura-ori to."""
        x, y = self.lattice_xy(N, M)
        return _flat(x, y)

    def sample(self, n_u: int, n_v: int) -> np.ndarray:
        """The flat footprint on an (n_u, n_v) grid, (n_u, n_v, 3), for pictures."""
        n_u, n_v = (check_value(n, GRID, k, SurfaceError) for n, k in ((n_u, "n_u"),
                                                                       (n_v, "n_v")))
        refuse_points(n_u * n_v, 8, f"a {n_u} x {n_v} sample")
        return _flat(np.linspace(0.0, self.size[0], n_u), np.linspace(0.0, self.size[1], n_v))

    def mesh(self, n_u: int, n_v: int) -> trimesh.Trimesh:
        """The flat footprint as a triangle mesh of :meth:`sample` (vertex (a, b) at
        a n_v + b)."""
        return trimesh.Trimesh(vertices=self.sample(n_u, n_v).reshape(-1, 3),
                               faces=grid_faces(n_u, n_v), process=False)

    def diameter(self) -> float:
        """The footprint's diagonal, sqrt(Lx^2 + Ly^2)."""
        return float(np.hypot(*self.size))

    def area(self) -> float:
        """The footprint's area Lx Ly."""
        return float(self.size[0] * self.size[1])

    def scale(self, N: int, M: int) -> float:
        """The curvature scale kappa of the loss and of the errors (1 / length): the
        largest |kx|, |ky|, sqrt|K| or |H| at the points of :meth:`lattice_xy` (N, M), and
        at least 1 / :meth:`diameter`."""
        x, y = self.lattice_xy(N, M)
        v = self.values(x[:, None], y[None, :])
        parts = [np.sqrt(np.abs(a)) if k == "K" else np.abs(a) for k, a in v.items()]
        return float(max(max(p.max() for p in parts), 1.0 / self.diameter()))

    # -- realisability ---------------------------------------------------------------------
    def realisable(self) -> Realisable:
        """Whether some surface realises the prescription, where the prescription decides
        it (:class:`Realisable`).

        Principal curvatures kx(x), ky(y) of one variable each, along lines of curvature:
        the Codazzi equations give E_v = 0 and G_u = 0 wherever kx != ky, so the metric is
        E(u) du^2 + G(v) dv^2, flat, and the Gauss equation asks kx ky = 0; so a surface
        exists only where kx ky = 0 everywhere (a cylinder-like bend) or kx = ky is constant
        (a sphere or a plane). Constant K and H likewise: constant principal curvatures,
        which only planes, spheres and circular cylinders have. A constant K alone: a
        sphere, a plane or a pseudospherical patch. Other fields: None."""
        x, y = np.meshgrid(*(np.linspace(0, s, CHECK_GRID) for s in self.size),
                           indexing="ij")
        v = self.values(x, y)
        scale = max(max(float(np.abs(a).max()) for a in v.values()), 1e-300)
        close = lambda a, b: bool(np.all(np.abs(a - b) <= DECISION_TOL * scale))  # noqa: E731
        if self.kind == "principal":
            kx, ky = v["kx"], v["ky"]
            if not (close(kx, kx[:, :1]) and close(ky, ky[:1, :])):
                return Realisable(None, "kx depends on y or ky on x: the prescription alone "
                                        "does not decide whether a surface realises it")
            if close(kx * ky / scale, 0.0):
                return Realisable(True, "kx ky = 0 everywhere: a surface bent along one "
                                        "direction (a cylinder-like bend) realises it")
            if close(kx, kx.flat[0]) and close(kx, ky):
                return Realisable(True, "kx = ky is constant: a sphere (or a plane) "
                                        "realises it")
            return Realisable(False, "no surface realises principal curvatures kx(x), ky(y) "
                                     "along lines of curvature unless kx ky = 0 everywhere "
                                     "or kx = ky is constant: the Codazzi equations make the "
                                     "metric flat, and the Gauss equation then asks "
                                     "kx ky = 0")
        K = v["K"]
        if not close(K, K.flat[0]):
            return Realisable(None, "K varies: the prescription alone does not decide "
                                    "whether a surface of this footprint realises it")
        if "H" not in v:
            return Realisable(True, "a constant K is realised by a sphere, a plane or a "
                                    "pseudospherical patch")
        H = v["H"]
        if not close(H, H.flat[0]):
            return Realisable(None, "H varies: the prescription alone does not decide "
                                    "whether a surface realises it")
        if close(H * H / scale, K / scale) or close(K / scale, 0.0):
            return Realisable(True, "constant K and H with H^2 = K or K = 0: a sphere, a "
                                    "circular cylinder or a plane realises it")
        return Realisable(False, "no surface has constant K and H with H^2 > K > 0 or "
                                 "K < 0: its principal curvatures would be constant and "
                                 "differ, which only planes, spheres and circular cylinders "
                                 "allow (Gauss and Codazzi equations)")

    # -- configuration ---------------------------------------------------------------------
    def to_config(self) -> dict:
        """The [target] table: the numbers and ``size``, or ``python``, ``fields`` and
        ``size`` for fields read from a function (:func:`from_config`). Raises
        :class:`SurfaceError` for a function given in Python (no table names it)."""
        table: dict[str, Any] = {"size": list(self.size)}
        if self.reference is not None:
            return {**table, "python": self.reference, "fields": ",".join(self.fields)}
        if any(callable(v) for v in self.fields.values()):
            raise SurfaceError(f"curvature target {self.name!r} holds a function given in "
                               "Python, which no table can name; name it in a [target] "
                               "table with python = \"file.py:function\" and fields")
        if self.name != "curvature":
            table["name"] = self.name
        return {**table, **{k: float(v) for k, v in self.fields.items()}}


def is_curvature_table(table: Mapping[str, Any]) -> bool:
    """Whether a [target] table names a curvature target (it has ``size``, a field or
    ``fields``)."""
    return isinstance(table, Mapping) and bool(set(table) & (set(CURVATURE_KEYS)
                                                             - {"python", "name"}))


def from_config(table: Mapping[str, Any], root: str | Path | None = None,
                trust: bool = False) -> Curvature:
    """The :class:`Curvature` of a [target] table: ``size = [Lx, Ly]`` with numbers
    ``K`` (and ``H``) or ``kx`` and ``ky``; or ``python = "file.py:function"`` (relative to
    ``root``) or ``"package.module:function"`` with ``fields`` = "K", "K,H" or "kx,ky",
    what the function f(x, y) returns in that order. Code runs only with ``trust``;
    else :class:`SurfaceError` names it."""
    try:
        values = check_table(table, CURVATURE_KEYS, "[target]")
    except InputError as exc:
        raise SurfaceError(str(exc)) from None
    name = values.pop("name", "curvature")
    size = values.pop("size")
    if "python" not in values:
        if "fields" in values:
            raise SurfaceError("[target] fields names what a python function returns; give "
                               "python = \"file.py:function\" too, or numbers K (H) or kx, ky")
        return Curvature(**{k: values[k] for k in ("K", "H") if k in values}, size=size,
                         name=name, **{k: values[k] for k in ("kx", "ky") if k in values})
    extra = set(values) - {"python", "fields"}
    if extra or "fields" not in values:
        raise SurfaceError("[target] python = ... takes fields = \"K\", \"K,H\" or \"kx,ky\" "
                           "(what the function returns) and size, and no numbers"
                           + (f"; got {', '.join(sorted(extra))}" if extra else ""))
    ref = resolve_reference(values["python"], check_root(root))
    if not check_value(trust, Key("bool"), "trust", SurfaceError):
        raise SurfaceError(f"[target] python = \"{ref}\" {code_of(ref)}; pass --trust "
                           "(trust=True in the API) if you trust that file")
    function, names = import_reference(ref), values["fields"].split(",")
    fields = {k: _picked(function, names, k) for k in names}
    return Curvature(**fields, size=size, name=name, reference=ref)


def _picked(function: Callable, names: list[str], name: str) -> Callable:
    """The field ``name`` of a function returning ``names`` (one value, or a tuple)."""
    if len(names) == 1:
        return function
    index = names.index(name)

    def field(x: np.ndarray, y: np.ndarray) -> Any:
        out = function(x, y)
        if not isinstance(out, (tuple, list)) or len(out) != len(names):
            raise SurfaceError(f"the curvature function must return {len(names)} values "
                               f"({', '.join(names)}), got {describe_value(out)}")
        return out[index]

    return field


def _finite(value: Any, name: str) -> np.ndarray:
    """``value`` as a float array of finite numbers, else :class:`SurfaceError`."""
    return finite_array(value, name, error=SurfaceError)


def _checked_field(value: Any, name: str) -> Field:
    """A number (as a float) or a callable; else :class:`SurfaceError`."""
    if callable(value):
        return value
    return check_value(value, Key("number", hint="or a function of (x, y)"), name,
                       SurfaceError)


def _evaluate(field: Field, x: np.ndarray, y: np.ndarray, shape: tuple[int, ...],
              name: str) -> np.ndarray:
    """The field at (x, y), broadcast to ``shape``; finite numbers, else
    :class:`SurfaceError` naming the field."""
    if not callable(field):
        return np.full(shape, field)
    try:
        out = np.asarray(field(x.copy(), y.copy()), dtype=float)
        out = np.broadcast_to(out, shape).copy()
    except SurfaceError:
        raise
    except Exception as exc:
        raise SurfaceError(f"the curvature function for {name} must take arrays x, y and "
                           f"return numbers of their shape: {type(exc).__name__}: "
                           f"{one_line(exc)}") from None
    if not np.all(np.isfinite(out)):
        raise SurfaceError(f"the curvature function for {name} returned NaN or infinity")
    return out


def _flat(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(x, y, 0) on the grid x (n,) by y (m,), (n, m, 3)."""
    X, Y = np.meshgrid(x, y, indexing="ij")
    return np.stack([X, Y, np.zeros_like(X)], axis=-1)
