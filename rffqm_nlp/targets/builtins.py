"""The built-in target surfaces: their formulas, parameter checks and default domains, and
their registry (:func:`names`, :func:`describe`, :func:`get`, :func:`target_keys`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

from ..errors import SurfaceError
from ..files import Key, describe_value, shown_name
from .parametric import DOMAIN_KEY, Domain, Surface, check_domain, checked_value, mathlib


@dataclass(frozen=True)
class _Spec:
    """A built-in: r(params, u, v), default parameters, default domain, parameter checks."""

    r: Callable[[dict, Any, Any], tuple[Any, Any, Any]]
    defaults: dict[str, float]
    domain: Callable[[dict], Domain]
    check: Callable[[dict, Domain], None]
    doc: str


class _Builtin(Surface):
    def __init__(self, name: str, spec: _Spec, params: dict, domain: Any):
        self._spec = spec
        dom = check_domain(spec.domain(params) if domain is None else domain)
        spec.check(params, dom)
        super().__init__(name, params, dom)

    def _r(self, u: Any, v: Any) -> tuple[Any, Any, Any]:
        return self._spec.r(self.params, u, v)


def _positive(params: dict, *keys: str) -> None:
    for key in keys:
        checked_value(params[key], Key("number", low=0, low_open=True), key)


def _inside_open(dom: Domain, limit: float, what: str) -> None:
    """Both parameters must stay in (-limit, limit)."""
    for name, (a, b) in zip("uv", dom):
        if max(abs(a), abs(b)) >= limit:
            raise SurfaceError(f"the {name} range {(a, b)} reaches {what} at |{name}| = "
                               f"{limit:.6g}; keep |{name}| < {limit:.6g}")


def _at_most_turn(dom: Domain, which: str) -> None:
    """An angle parameter may span at most one full turn (no overlapping sheets)."""
    a, b = dom["uv".index(which)]
    if b - a > 2 * math.pi:
        raise SurfaceError(f"the angle {which} spans {b - a:.6g} > 2*pi, so the surface "
                           f"overlaps itself; use a {which} range of length <= 2*pi")


def _gnomonic(m: SimpleNamespace, u: Any, v: Any) -> tuple[Any, Any, Any]:
    """Direction (tan u, tan v, 1): equiangular coordinates around the +z pole."""
    return m.tan(u), m.tan(v), 1.0


def _sphere_cap(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    x, y, z = _gnomonic(m, u, v)
    s = p["radius"] / m.sqrt(x * x + y * y + z * z)
    return s * x, s * y, s * z


def _ellipsoid_cap(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    x, y, z = _gnomonic(m, u, v)
    s = 1 / m.sqrt((x / p["a"]) ** 2 + (y / p["b"]) ** 2 + (z / p["c"]) ** 2)
    return s * x, s * y, s * z


def _hyperboloid(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    return p["a"] * m.cosh(u) * m.cos(v), p["b"] * m.cosh(u) * m.sin(v), p["c"] * m.sinh(u)


def _vase_radius(p: dict, m: SimpleNamespace, z: Any) -> Any:
    return p["radius"] + p["amplitude"] * m.sin(2 * math.pi * z / p["wavelength"])


def _quarter_vase(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    rho = _vase_radius(p, m, u)
    return rho * m.cos(v), rho * m.sin(v), u


def _saddle(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    return u, v, u * u / (2 * p["a"]) - v * v / (2 * p["b"])


def _paraboloid(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    return u, v, u * u / (2 * p["a"]) + v * v / (2 * p["b"])


def _cylinder(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    return p["radius"] * m.sin(v), u, p["radius"] * m.cos(v)


def _torus_patch(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    ring = p["R"] + p["r"] * m.cos(v)
    return ring * m.cos(u), ring * m.sin(u), p["r"] * m.sin(v)


def _gaussian_bump(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    m = mathlib(u, v)
    return u, v, p["height"] * m.exp(-(u * u + v * v) / (2 * p["width"] ** 2))


def _plane(p: dict, u: Any, v: Any) -> tuple[Any, Any, Any]:
    return u, v, 0.0


def _check_sphere(p: dict, dom: Domain) -> None:
    _positive(p, "radius")
    _inside_open(dom, math.pi / 2, "the equator (beyond the hemisphere)")


def _check_ellipsoid(p: dict, dom: Domain) -> None:
    _positive(p, "a", "b", "c")
    _inside_open(dom, math.pi / 2, "the equator (beyond the half ellipsoid)")


def _check_hyperboloid(p: dict, dom: Domain) -> None:
    _positive(p, "a", "b", "c")
    _at_most_turn(dom, "v")


def _check_vase(p: dict, dom: Domain) -> None:
    _positive(p, "radius", "wavelength")
    if abs(p["amplitude"]) >= p["radius"]:
        raise SurfaceError(f"|amplitude| = {abs(p['amplitude'])} must be smaller than radius = "
                           f"{p['radius']} so that the profile radius stays positive")
    _at_most_turn(dom, "v")


def _check_ab(p: dict, dom: Domain) -> None:
    _positive(p, "a", "b")


def _check_cylinder(p: dict, dom: Domain) -> None:
    _positive(p, "radius")
    _at_most_turn(dom, "v")


def _check_torus(p: dict, dom: Domain) -> None:
    _positive(p, "R", "r")
    if p["r"] >= p["R"]:
        raise SurfaceError(f"the tube radius r = {p['r']} must be smaller than the centre-line "
                           f"radius R = {p['R']} (else the torus is singular)")
    _at_most_turn(dom, "u")
    _at_most_turn(dom, "v")


def _check_bump(p: dict, dom: Domain) -> None:
    _positive(p, "width")


def _check_nothing(p: dict, dom: Domain) -> None:
    """The plane has no parameters to check."""


def _fixed(dom: Domain) -> Callable[[dict], Domain]:
    return lambda p: dom


_BUILTINS: dict[str, _Spec] = {
    "sphere_cap": _Spec(
        _sphere_cap, {"radius": 4.0}, _fixed(((-0.6, 0.6), (-0.6, 0.6))), _check_sphere,
        "Cap of the sphere of the given radius centred at the origin, around the pole "
        "(0, 0, radius), K = 1/radius^2 > 0. r = radius * d/|d| with d = (tan u, tan v, 1): "
        "u, v are angles (radians), |u|, |v| < pi/2 (the hemisphere)."),
    "hyperboloid": _Spec(
        _hyperboloid, {"a": 2.0, "b": 2.0, "c": 2.0}, _fixed(((-0.8, 0.8), (-0.8, 0.8))),
        _check_hyperboloid,
        "Hyperboloid of one sheet x^2/a^2 + y^2/b^2 - z^2/c^2 = 1, K < 0: "
        "r = (a cosh u cos v, b cosh u sin v, c sinh u); u along the axis, v an angle."),
    "quarter_vase": _Spec(
        _quarter_vase, {"radius": 2.0, "amplitude": 0.5, "wavelength": 8.0},
        lambda p: ((-p["wavelength"] / 4, p["wavelength"] / 4), (-math.pi / 4, math.pi / 4)),
        _check_vase,
        "Quarter turn of the surface of revolution with profile radius "
        "rho(z) = radius + amplitude sin(2 pi z / wavelength): r = (rho(u) cos v, "
        "rho(u) sin v, u). The default domain spans half a wavelength around z = 0, where "
        "rho'' and hence K change sign."),
    "saddle": _Spec(
        _saddle, {"a": 4.0, "b": 4.0}, _fixed(((-2.0, 2.0), (-2.0, 2.0))), _check_ab,
        "Hyperbolic paraboloid z = u^2/(2a) - v^2/(2b) over (x, y) = (u, v), K < 0."),
    "cylinder": _Spec(
        _cylinder, {"radius": 3.0}, _fixed(((-2.0, 2.0), (-0.7, 0.7))), _check_cylinder,
        "Circular cylinder r = (radius sin v, u, radius cos v) about the y axis, K = 0, "
        "|H| = 1/(2 radius); u along the axis, v an angle."),
    "paraboloid": _Spec(
        _paraboloid, {"a": 4.0, "b": 4.0}, _fixed(((-2.0, 2.0), (-2.0, 2.0))), _check_ab,
        "Elliptic paraboloid z = u^2/(2a) + v^2/(2b) over (x, y) = (u, v), K > 0."),
    "ellipsoid_cap": _Spec(
        _ellipsoid_cap, {"a": 3.0, "b": 4.0, "c": 2.5}, _fixed(((-0.6, 0.6), (-0.6, 0.6))),
        _check_ellipsoid,
        "Cap of the ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1 around (0, 0, c), the radial "
        "projection of (tan u, tan v, 1); |u|, |v| < pi/2."),
    "torus_patch": _Spec(
        _torus_patch, {"R": 4.0, "r": 1.5},
        _fixed(((-0.6, 0.6), (math.pi / 2 - 0.8, math.pi / 2 + 0.8))), _check_torus,
        "Patch of the torus r = ((R + r cos v) cos u, (R + r cos v) sin u, r sin v), "
        "K = cos v / (r (R + r cos v)); the default patch straddles the top circle v = pi/2, "
        "so K changes sign."),
    "gaussian_bump": _Spec(
        _gaussian_bump, {"height": 1.0, "width": 1.0}, _fixed(((-3.0, 3.0), (-3.0, 3.0))),
        _check_bump, "Graph z = height exp(-(u^2 + v^2) / (2 width^2)) over (x, y) = (u, v)."),
    "plane": _Spec(_plane, {}, _fixed(((-2.0, 2.0), (-2.0, 2.0))), _check_nothing,
                   "The plane z = 0 over (x, y) = (u, v)."),
}


def names() -> list[str]:
    """Names of the built-in surfaces."""
    return list(_BUILTINS)


def describe(name: str) -> str:
    """Description of a built-in surface, its parameters and their defaults."""
    spec = _spec(name)
    defaults = ", ".join(f"{k}={v}" for k, v in spec.defaults.items()) or "no parameters"
    domain = spec.domain(spec.defaults)
    return f"{name}: {spec.doc} Parameters: {defaults}; default domain {domain}."


def get(name: str, domain: Any = None, **params: float) -> Surface:
    """The built-in surface ``name`` with ``params`` overriding its defaults (see
    :func:`describe`) and an optional domain ((u0, u1), (v0, v1))."""
    spec = _spec(name)
    unknown = sorted(set(params) - set(spec.defaults))
    if unknown:
        valid = ", ".join(spec.defaults) or "none"
        raise SurfaceError(f"unknown parameter(s) {', '.join(unknown)} for surface {name!r}; "
                           f"valid parameters: {valid} (and domain)")
    values = {k: checked_value(params.get(k, default), Key("number"), k)
              for k, default in spec.defaults.items()}
    return _Builtin(name, spec, values, domain)


def _spec(name: str) -> _Spec:
    if not isinstance(name, str):
        raise SurfaceError(f"name must be the name of a built-in surface (one of "
                           f"{', '.join(_BUILTINS)}), got {describe_value(name)}")
    if name not in _BUILTINS:
        shown = repr(name) if shown_name(name) == name else shown_name(name)
        raise SurfaceError(f"unknown surface {shown}; built-in surfaces: {', '.join(_BUILTINS)}"
                           f" (or use python = \"module:function\" for your own)")
    return _BUILTINS[name]


def target_keys(name: str) -> dict[str, Key]:
    """The keys of a [target] table naming the built-in ``name``: name, domain and its
    parameters."""
    return {"name": Key("choice", choices=tuple(_BUILTINS)), "domain": DOMAIN_KEY,
            **{param: Key("number") for param in _spec(name).defaults}}
