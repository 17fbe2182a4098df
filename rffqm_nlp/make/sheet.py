"""The flat pattern at its physical size: vertices, outline and creases in millimetres,
and the perforation of each crease.

Coordinates: the flat pattern scaled by ``scale`` (mm per pattern unit) and moved so that
its lowest x and y are 0, y up: a vertex x of the pattern is at (x - x_min) * scale.
The creases are the interior edges in the edge order of the FOLD file
(:func:`rffqm_nlp.io.foldfile.edges_vertices`: horizontal edges row by row, then vertical
ones), each with its 1-based vertex pair, its assignment (M or V, the sign of its fold
angle at the designed state) and that fold angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..files import Key, check_value
from ..io.foldfile import edge_assignments, edge_fold_angles, edges_vertices, finite_pattern
from ..model.pattern import Pattern, check_fold_angle
from .options import MAX_LENGTH, finite_scale


@dataclass(frozen=True)
class Sheet:
    """A pattern at its physical size (see the module).

    ``points`` (N+1, M+1, 2) the vertices (mm); ``size`` (width, height) of the flat
    pattern (mm); ``scale`` (mm per pattern unit); ``outline`` (2(N+M), 2) the boundary
    vertices counter-clockwise from vertex (1, 1); ``ends`` (C, 4) each crease's vertices
    (i1, j1, i2, j2), 1-based; ``kinds`` (C,) "M" or "V"; ``angles`` (C,) its fold angle at
    the designed state (radians, valley positive); ``segments`` (C, 2, 2) its two ends
    (mm).
    """

    points: np.ndarray
    size: tuple[float, float]
    scale: float
    outline: np.ndarray
    ends: np.ndarray
    kinds: np.ndarray
    angles: np.ndarray
    segments: np.ndarray

    @property
    def lengths(self) -> np.ndarray:
        """Each crease's length (C,) in mm."""
        return np.linalg.norm(self.segments[:, 1] - self.segments[:, 0], axis=1)

    @classmethod
    def of(cls, pat: Pattern, omega: float, scale: float) -> Sheet:
        """The sheet of ``pat`` designed to fold to ``omega``, ``scale`` mm per unit."""
        finite_pattern(pat)
        omega = check_fold_angle(omega, "omega")
        X = pat.X[..., :2]
        lo = X.reshape(-1, 2).min(axis=0)
        extent = np.ptp(X.reshape(-1, 2), axis=0)
        if not np.all(extent > 0):
            raise InputError("the flat pattern has no extent to make")
        scale = finite_scale(check_value(scale, Key("number", low=0, low_open=True),
                                         "scale"), tuple(extent))
        P = (X - lo) * scale
        N, M = pat.N, pat.M
        edges = edges_vertices(N, M)
        kinds = edge_assignments(pat, omega)
        angles = edge_fold_angles(pat, omega)
        inner = kinds != "B"
        e = edges[inner]
        flat = P.reshape(-1, 2)
        ends = np.stack([e[:, 0] // (M + 1) + 1, e[:, 0] % (M + 1) + 1,
                         e[:, 1] // (M + 1) + 1, e[:, 1] % (M + 1) + 1], axis=1)
        return cls(points=P, size=(float(extent[0] * scale), float(extent[1] * scale)),
                   scale=float(scale), outline=boundary_ring(P), ends=ends,
                   kinds=kinds[inner], angles=angles[inner],
                   segments=np.stack([flat[e[:, 0]], flat[e[:, 1]]], axis=1))


def boundary_ring(P: np.ndarray) -> np.ndarray:
    """The boundary vertices of a vertex grid P (N+1, M+1, d), counter-clockwise in the
    flat pattern from vertex (1, 1): along the bottom row, up the last column, back along
    the top row, down the first column; (2(N+M), d)."""
    return np.concatenate([P[0, :-1], P[:-1, -1], P[-1, :0:-1], P[:0:-1, 0]])


def cut_outline(sheet: Sheet, kerf: float) -> np.ndarray:
    """The outline the tool follows (k, 2), closed (the first point repeated last): the
    sheet's outline offset outwards by half the ``kerf`` (mm) with mitred corners
    (shapely), so that the part comes out at its size; the outline itself for no kerf."""
    ring = sheet.outline
    if kerf > 0:
        from shapely.geometry import Polygon

        polygon = Polygon(ring)
        if not polygon.is_valid:
            raise InputError("the flat pattern's outline crosses itself; it cannot be cut "
                             "with a kerf (make it with kerf 0)")
        grown = polygon.buffer(kerf / 2, join_style="mitre", mitre_limit=10.0)
        ring = np.asarray(grown.exterior.coords)[:-1]
    return np.concatenate([ring, ring[:1]])


def perforation(length: float, dash: float, gap: float, relief: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Where the cuts of one perforated crease of ``length`` lie, as distances from its
    start: (starts, ends), each (n,), n >= 1. Both ends keep an uncut corner relief of
    ``relief`` (at most a quarter of the crease, so that half of it is perforated); between
    them n dashes and n - 1 gaps, n the whole number nearest to the ratio of the room plus
    a gap to ``dash`` + ``gap``, both stretched by one factor so that the first dash starts
    and the last one ends exactly at the reliefs (all in mm)."""
    positive = Key("number", low=0, low_open=True, high=MAX_LENGTH, hint="(mm)")
    length = check_value(length, positive, "length")
    dash, gap = check_value(dash, positive, "dash"), check_value(gap, positive, "gap")
    relief = min(check_value(relief, Key("number", low=0, high=MAX_LENGTH, hint="(mm)"),
                             "relief"), length / 4)
    room = length - 2 * relief
    n = max(1, int(round((room + gap) / (dash + gap))))
    stretch = room / (n * dash + (n - 1) * gap)
    starts = relief + np.arange(n) * stretch * (dash + gap)
    return starts, starts + stretch * dash


def dashes(sheet: Sheet, dash: float, gap: float, relief: float) -> list[np.ndarray]:
    """The cuts of every crease (:func:`perforation`) as segments, one (n, 2, 2) array per
    crease (mm)."""
    out = []
    for (p0, p1), length in zip(sheet.segments, sheet.lengths):
        starts, ends = perforation(float(length), dash, gap, relief)
        t = (p1 - p0) / length
        out.append(np.stack([p0 + starts[:, None] * t, p0 + ends[:, None] * t], axis=1))
    return out
