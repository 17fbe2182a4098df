"""The lock's files: lock.csv (the ties), stops.csv (the crease stops) and lock.stl, the
printable parts, laid out flat side by side for printing (mm).

* A strut for each tie: a round rod between two balls whose centres are the tie's length
  apart (the ball at each end sits on its vertex), diameter :func:`strut_diameter`.
* A wedge stop for each crease stop: a prism whose cross-section is an isosceles
  triangle with the apex angle of the crease's dihedral angle on its closing side at the
  designed state, pi - |gamma|, as long as half the crease; glued into the crease it
  stops the fold at its designed angle.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..files import write_text
from .cut_files import csv_text
from .lock import Stop, Tie
from .solids import indexed, meshes, write_stl

#: The columns of lock.csv and stops.csv.
LOCK_COLUMNS = ("i1", "j1", "i2", "j2", "length_mm", "dlength_domega")
STOP_COLUMNS = ("i1", "j1", "i2", "j2", "length_mm", "angle_deg", "dangle_domega")
#: Room between two parts of lock.stl (mm).
ROOM = 5.0


def strut_diameter(thickness: float) -> float:
    """The strut's diameter (mm) for a sheet ``thickness`` (mm): 3 thicknesses, at least
    2 mm."""
    return max(2.0, 3.0 * thickness)


def strut(length: float, diameter: float):
    """A strut along x from 0 to ``length`` (mm) (manifold3d): a rod and a ball of 1.5
    diameters at each end, its axis at height 0.75 diameter (flat on the bed)."""
    import manifold3d as mf

    ball = 0.75 * diameter
    rod = mf.Manifold.cylinder(length, diameter / 2, diameter / 2, 32)
    rod = rod.rotate((0.0, 90.0, 0.0))
    ends = [mf.Manifold.sphere(ball, 32).translate((x, 0.0, 0.0)) for x in (0.0, length)]
    return (rod + ends[0] + ends[1]).translate((0.0, 0.0, ball))


def wedge(angle: float, leg: float, length: float):
    """A wedge (manifold3d): the isosceles triangle of apex ``angle`` (radians) and legs
    ``leg`` (mm) in the x-z plane, apex down at the origin, extruded ``length`` along y."""
    import manifold3d as mf

    half = angle / 2
    tri = [(0.0, 0.0), (leg * math.sin(half), leg * math.cos(half)),
           (-leg * math.sin(half), leg * math.cos(half))]
    prism = mf.Manifold.extrude(mf.CrossSection([tri]), length)
    return prism.rotate((90.0, 0.0, 0.0)).translate((0.0, length, 0.0))


def lock_parts(ties: list[Tie], stops: list[Stop], thickness: float) -> list:
    """The parts of lock.stl as manifold3d solids, side by side along y."""
    diameter = strut_diameter(thickness)
    parts, y = [], 0.0
    for tie in ties:
        parts.append(strut(tie.length, diameter).translate((0.0, y, 0.0)))
        y += 1.5 * diameter + ROOM
    for stop in stops:
        leg = max(5.0 * thickness, min(stop.length / 3, 10.0))
        apex = math.pi - abs(stop.angle)
        piece = wedge(apex, leg, stop.length / 2)
        low = piece.bounding_box()
        parts.append(piece.translate((-low[0], y - low[1], -low[2])))
        y += stop.length / 2 + ROOM
    return parts


def write_lock_files(folder: Path, ties: list[Tie], stops: list[Stop],
                     thickness: float) -> list[Path]:
    """lock.csv, stops.csv and lock.stl into ``folder`` (mm)."""
    tie_rows = [(t.i1, t.j1, t.i2, t.j2, t.length, t.dlength_domega) for t in ties]
    stop_rows = [(s.i1, s.j1, s.i2, s.j2, s.length, math.degrees(s.angle), s.dangle_domega)
                 for s in stops]
    vertices, faces = zip(*(indexed(p) for p in lock_parts(ties, stops, thickness)))
    return [write_text(folder / "lock.csv", csv_text(LOCK_COLUMNS, tie_rows)),
            write_text(folder / "stops.csv", csv_text(STOP_COLUMNS, stop_rows)),
            write_stl(folder / "lock.stl", meshes(list(vertices), list(faces)))]
