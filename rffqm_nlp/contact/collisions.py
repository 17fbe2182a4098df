"""Self-contact of a folding pattern: flat overlaps and the first contact along the motion.

RFFQM guarantees a rigid folding motion, not that the sheet stays clear of itself.
:func:`collisions` checks the motion omega in [0, omega_max] of a marched
:class:`~rffqm_nlp.model.pattern.Pattern` for two panels that share no vertex touching,
intersecting or coming closer than a ``clearance``; :func:`near_pairs` gives the pairs
within a reach in one state (for :mod:`rffqm_nlp.design.clearance`).

The method, module by module:

* :mod:`~rffqm_nlp.contact.panels`: panels are rigid and planar, so panel (i, j) is
  exactly two triangles; the folded states come from
  :func:`rffqm_nlp.model.numpy_model.fold` (batched) and are held as tables of named
  fields (corners, centroid, unit normal, radius), beside their frames.
* :mod:`~rffqm_nlp.contact.narrow`: exact distances between panels (separating axes and
  segment and vertex-face distances of their triangles), cheap lower bounds on them, and
  the overlaps of the flat pattern.
* :mod:`~rffqm_nlp.contact.broad`: for each step of the motion (coarse steps, halved
  where the sheet moves far from one affine map over one), k-d tree queries
  with a reach per panel from an affine fit of the step's displacements (one per grid
  tile where a large sheet bends) give every pair the step's sphere gaps and cheapest
  motion bound do not certify clear, in chunks of bounded size.
* :mod:`~rffqm_nlp.contact.motion`: those pairs are certified clear by distance bounds
  at the step's ends and a bound on how far their distance can change, or followed into
  the halves of the step until they touch or the step is shorter than ``tol``.

Guarantee: no contact is missed provided that within one step the path of every vertex
relative to another, and of every vertex in the frame of another panel, is at most
``SAFETY`` times its chord (smooth motion on short steps); a pair whose distance dips
below the clearance only between two samples less than ``tol`` apart may be missed.
``first_omega`` lies within ``tol`` after the true first contact.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..files import Key, check_value
from ..model.backend import finite_array, finite_result
from ..model.pattern import Pattern, check_fold_angle, check_pattern
from .broad import pairs_within
from .motion import first_contact
from .narrow import (flat_overlaps, panel_distance, quad_distance, triangle_distance,
                     triangles_intersect)
from .panels import Geometry, PanelPair

__all__ = ["CollisionReport", "PanelPair", "collisions", "near_pairs", "panel_distance",
           "triangle_distance", "triangles_intersect"]


@dataclass(frozen=True)
class CollisionReport:
    """Result of :func:`collisions`.

    ``free``: no flat overlap and no contact on the motion. ``first_omega``: the smallest
    |omega| in [0, |omega_max|] at which two panels that share no vertex touch or come
    closer than ``clearance``, signed like ``omega_max`` (0.0 when the flat state is
    already in contact), or None. ``pairs``: the panel pairs in contact there, 1-based
    ((i, j), (k, l)) with (i, j) < (k, l). ``flat_overlaps``: pairs whose interiors overlap
    in the flat pattern (any two panels, neighbours included).
    """

    free: bool
    first_omega: float | None
    pairs: list[PanelPair] = field(default_factory=list)
    flat_overlaps: list[PanelPair] = field(default_factory=list)
    omega_max: float = 0.0
    clearance: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dictionary (pairs as nested lists)."""
        return {"free": self.free, "first_omega": self.first_omega,
                "pairs": [[list(p), list(q)] for p, q in self.pairs],
                "flat_overlaps": [[list(p), list(q)] for p, q in self.flat_overlaps],
                "omega_max": self.omega_max, "clearance": self.clearance}


def collisions(pattern: Pattern, omega_max: float, *, clearance: float = 0.0,
               tol: float = 1e-4) -> CollisionReport:
    """Flat overlaps and the first self-contact of ``pattern`` folding from 0 to ``omega_max``.

    ``omega_max`` in [-pi, pi] (negative: the other folding branch); ``clearance`` >= 0 a
    distance (a sheet thickness) that panels sharing no vertex must keep; ``tol`` > 0 the
    accuracy of ``first_omega`` in omega. See the module docstring for the method. Raises
    :class:`~rffqm_nlp.errors.InputError` for arguments of other kinds (``pattern`` not a
    :class:`~rffqm_nlp.model.pattern.Pattern`, ``omega_max`` not one number in [-pi, pi], ...).
    """
    check_pattern(pattern, "pattern")
    w_max = check_fold_angle(omega_max, "omega_max")
    clearance = check_value(clearance, Key("number", low=0, hint="(a distance)"),
                               "clearance")
    tol = check_value(tol, Key("number", low=0, low_open=True, hint="(a step in omega)"),
                         "tol")
    geo = Geometry(pattern)
    flat = flat_overlaps(geo)
    first, pairs = first_contact(geo, w_max, float(clearance), float(tol))
    return CollisionReport(free=not flat and first is None, first_omega=first, pairs=pairs,
                           flat_overlaps=flat, omega_max=w_max, clearance=float(clearance))


def near_pairs(pattern: Pattern, Y: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of panels that share no vertex within ``reach`` in one state, for
    :mod:`rffqm_nlp.design.clearance`: the pairs (n, 2) (0-based panel indices p = (i-1) M +
    (j-1), p < q) whose bounding spheres in the folded vertices Y ((N+1, M+1, 3)) come
    within ``reach`` (the broad phase), and their exact distances (n,). Raises
    :class:`~rffqm_nlp.errors.InputError` for arguments of other kinds or shapes."""
    check_pattern(pattern, "pattern")
    Y = finite_array(Y, "Y", shape=(pattern.N + 1, pattern.M + 1, 3))
    reach = check_value(reach, Key("number", low=0.0, hint="(a distance)"), "reach")
    geo = Geometry(pattern)
    S = Y.reshape(1, -1, 3)
    pq = pairs_within(geo, geo.centres(S)[0], float(reach))
    s = np.zeros(len(pq), dtype=np.int64)
    d = quad_distance(geo.quads(S, s, pq[:, 0]), geo.quads(S, s, pq[:, 1]), geo.scale)
    return pq, finite_result(d, "the panel distances are not finite (degenerate panels or "
                                "coordinates too large)")
