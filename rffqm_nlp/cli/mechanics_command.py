"""``rffqm mechanics``: the bar-and-hinge model of a saved design at its designed state
(rq.mechanics): its softest modes beside the folding mode's own stiffness, Poisson's ratio
of the folding motion, and the linear response of the locked shape to its own weight and
point loads (docs/mechanics.md)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np
import typer
from rich.console import Console
from rich.table import Table

from ..design.results import DesignResult
from ..errors import InputError
from ..files import Key, check_value
from .options import check_path
from .output import quantity_table, user_errors, wrote

#: Default sheet (rq.mechanics.MATERIALS) and flat width along x (mm).
MATERIAL, WIDTH_MM = "polypropylene", 300.0


def _numbers(text: str, count: int, name: str) -> list[float]:
    """``count`` comma-separated numbers of an option's value."""
    parts = text.split(",")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != count or not all(np.isfinite(values)):
        raise InputError(f"{name} takes {count} comma-separated finite numbers, got "
                         f"{len(parts)} items")
    return values


def _material(name: str, modulus: Optional[float], poisson: Optional[float],
              thickness: Optional[float], fold_stiffness: Optional[float],
              density: Optional[float]):
    """The sheet: the named one, its fields replaced by those given (SI, mm and GPa in)."""
    from ..mechanics import Material

    base = Material.named(name)
    fields = {"E": base.E if modulus is None else check_value(
                  modulus, Key("number", low=1e-6, high=1e4), "--modulus") * 1e9,
              "nu": base.nu if poisson is None else poisson,
              "thickness": base.thickness if thickness is None else check_value(
                  thickness, Key("number", low=1e-4, high=1e3), "--thickness") * 1e-3,
              "fold_stiffness": base.fold_stiffness if fold_stiffness is None
              else fold_stiffness,
              "density": base.density if density is None else density}
    return Material(**fields)


def mechanics_cmd(
    result_dir: Path = typer.Argument(..., help="Folder of a saved design (result.json).",
                                      show_default=False),
    width: float = typer.Option(WIDTH_MM, "--width", help="The flat pattern's extent along x "
                                "(mm)."),
    material: str = typer.Option(MATERIAL, "--material", help="A sheet: paper, card, "
                                 "polypropylene or pet; the options below replace its "
                                 "values."),
    modulus: Optional[float] = typer.Option(None, "--modulus", help="Young's modulus (GPa)."),
    poisson: Optional[float] = typer.Option(None, "--poisson", help="Poisson's ratio of the "
                                            "sheet."),
    thickness: Optional[float] = typer.Option(None, "--thickness", help="Sheet thickness "
                                              "(mm)."),
    fold_stiffness: Optional[float] = typer.Option(None, "--fold-stiffness", help="Crease "
                                                   "stiffness (N m/rad per m of crease); 0 "
                                                   "for free hinges."),
    density: Optional[float] = typer.Option(None, "--density", help="Density (kg/m^3)."),
    load: list[str] = typer.Option([], "--load", help="A point load i,j,Fx,Fy,Fz (1-based "
                                   "vertex, N, the target's frame); repeat for more."),
    gravity: bool = typer.Option(True, "--gravity/--no-gravity", help="The sheet's own "
                                 "weight, down the target's -z."),
    support: list[str] = typer.Option([], "--support", help="A held vertex i,j (1-based); "
                                      "repeat for more (default: the four corners)."),
    tie: list[str] = typer.Option([], "--tie", help="A tie i1,j1,i2,j2 between two vertices "
                                  "(the lock); repeat for more."),
    lock: bool = typer.Option(False, "--lock", help="Tie the design with the lock that "
                              "`rffqm make` recommends (its lock.csv), besides any --tie."),
    at: Optional[str] = typer.Option(None, "--at", help="Vertex i,j of the point stiffness "
                                     "(default: the middle vertex)."),
    modes: int = typer.Option(12, "--modes", help="Softest modes to list, 7 to 200."),
    view: Optional[Path] = typer.Option(None, "--view", help="Write the displaced design, "
                                        "coloured by displacement with an exaggeration "
                                        "slider, to this HTML file."),
) -> None:
    """The mechanics of a saved design at its designed state: the bar-and-hinge model's
    softest modes beside the folding mode's own stiffness, Poisson's ratio of the folding
    motion, and the linear response to the sheet's weight and the point loads: the
    largest deflection (mm), the stiffness against a point load at a vertex, the largest
    bar strain and hinge moment, with the ties given and, with ``--lock``, those of the lock
    that ``rffqm make`` recommends (:func:`rffqm_nlp.make.lock.lock_ties`). Exit status 2
    on bad input or a state that the supports and ties do not hold.
    """
    from ..mechanics import BarAndHinge, poisson_ratio

    with user_errors():
        check_path(result_dir, "RESULT_DIR")
        check_path(view, "--view", output=True)
        width_m = check_value(width, Key("number", low=1e-3, high=1e7), "--width") * 1e-3
        sheet = _material(material, modulus, poisson, thickness, fold_stiffness, density)
        result = DesignResult.load(result_dir)
        pat = result.pattern
        rotation = np.asarray(result.rotation)
        loads = [_numbers(t, 5, "--load") for t in load]
        loads = [[i, j, *(rotation.T @ np.array(f))] for i, j, *f in loads] or None
        supports = [_numbers(t, 2, "--support") for t in support] or None
        ties = [np.reshape(_numbers(t, 4, "--tie"), (2, 2)) for t in tie]
        if lock:
            from ..make.lock import lock_ties

            ties += [np.array([[t.i1, t.j1], [t.i2, t.j2]], dtype=float)
                     for t in lock_ties(pat, result.omega)]
        vertex = _numbers(at, 2, "--at") if at else [pat.N // 2 + 1, pat.M // 2 + 1]
        model = BarAndHinge(pat, result.omega, sheet, width=width_m)
        found = model.modes(modes)
        down = rotation.T @ np.array([0.0, 0.0, -1.0])
        response = model.solve(loads=loads, supports=supports, ties=ties or None,
                               gravity=gravity, down=down)
        stiffness = model.point_stiffness(vertex, down, supports=supports, ties=ties or None)
        try:
            nu = f"{poisson_ratio(pat, result.omega):.6g}"
        except InputError:
            nu = "none (flat or folded flat)"
        if view is not None:
            from ..show.displacement import write_html

            write_html(result, response, model.scale, view)
    console = Console()
    console.print(_modes_table(found))
    console.print(quantity_table(f"mechanics: {result_dir}", [
        ("sheet", f"{material}: E {sheet.E / 1e9:.3g} GPa, nu {sheet.nu:g}, "
                  f"t {sheet.thickness * 1e3:.3g} mm"),
        ("width (mm)", f"{width_m * 1e3:.6g}"),
        ("zero modes", str(found.zero_count)),
        ("folding mode stiffness (N/m)", f"{found.folding:.6g}"),
        ("modes softer than folding", str(found.softer_than_folding)),
        ("Poisson's ratio", nu),
        ("largest deflection (mm)", f"{response.largest_deflection_mm:.6g} at "
                                    f"{response.largest_at}"),
        (f"point stiffness at {tuple(int(v) for v in vertex)} (N/m)", f"{stiffness:.6g}"),
        ("largest bar strain", f"{np.abs(response.bar_strains).max():.3g}"),
        ("largest hinge moment (N m)", f"{np.abs(response.hinge_moments).max():.3g}"),
        ("tie forces (N)", ", ".join(f"{f:.4g}" for f in response.tie_forces) or "no ties"),
    ]))
    if view is not None:
        wrote(view)


def _modes_table(found) -> Table:
    """The softest modes: eigenvalue (N/m) and its share of the largest."""
    from rich.table import Table

    table = Table(title="softest modes")
    for column in ("mode", "eigenvalue (N/m)", "/ largest"):
        table.add_column(column, justify="right")
    for n, (value, rel) in enumerate(zip(found.values, found.relative), start=1):
        table.add_row(str(n), f"{value:.4g}", f"{rel:.3g}")
    return table
