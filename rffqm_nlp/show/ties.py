"""The lock's ties in the interactive view: one line trace of the tie segments, moved
with the folding motion (:func:`rffqm_nlp.show.view.spec` with ``ties``).

A tie is a pair of 1-based vertices (i1, j1, i2, j2), as :func:`rffqm_nlp.make.lock_ties`
gives them (their ``i1, j1, i2, j2`` fields) or as rows of lock.csv.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..errors import InputError
from ..files import Key, check_value

#: The colour and width of the ties' lines.
COLOR, WIDTH = "#ff8c00", 6


def tie_ids(ties: Sequence, N: int, M: int) -> np.ndarray:
    """Row-major vertex ids (n, 2) of ``ties``: objects with fields i1, j1, i2, j2 or
    sequences of those four numbers (1-based), each vertex of the N x M pattern."""
    rows = []
    for k, tie in enumerate(ties):
        values = ([getattr(tie, f) for f in ("i1", "j1", "i2", "j2")]
                  if hasattr(tie, "i1") else list(tie)[:4])
        if len(values) != 4:
            raise InputError(f"ties[{k}] must give four vertex numbers i1, j1, i2, j2")
        i1, j1, i2, j2 = (check_value(v, Key("whole", low=1, high=bound),
                                      f"ties[{k}].{name}")
                          for v, name, bound in zip(values, ("i1", "j1", "i2", "j2"),
                                                    (N + 1, M + 1, N + 1, M + 1)))
        rows.append(((i1 - 1) * (M + 1) + j1 - 1, (i2 - 1) * (M + 1) + j2 - 1))
    return np.array(rows, dtype=int).reshape(-1, 2)


def tie_xyz(P: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """The tie lines of the vertices P (V, 3): each segment's two ends then a break (NaN),
    (3 n, 3)."""
    gap = np.full((len(ids), 1, 3), np.nan)
    return np.concatenate([P[ids], gap], axis=1).reshape(-1, 3)


def tie_trace(xyz: dict) -> dict:
    """The plotly trace of the ties from their x, y, z lists."""
    return {"type": "scatter3d", **xyz, "mode": "lines", "name": "lock ties",
            "hoverinfo": "skip", "connectgaps": False,
            "line": {"color": COLOR, "width": WIDTH}}


def add_ties(fig: dict, Y: np.ndarray, ids: np.ndarray, at: int, listed) -> None:
    """Add the ties' trace to the figure ``fig`` (a view spec) and to each slider step:
    ``Y`` (K, V, 3) the states of the steps, ``at`` the designed one, ``listed`` the
    view's rounding of coordinates to lists."""
    index = len(fig["data"])
    per_step = [tie_xyz(Y[n], ids) for n in range(len(Y))]
    xyz = [{a: listed(p[:, k]) for k, a in enumerate("xyz")} for p in per_step]
    fig["data"].append(tie_trace(xyz[at]))
    for step, coords in zip(fig["layout"]["sliders"][0]["steps"], xyz):
        restyle, traces = step["args"]
        for axis in "xyz":
            restyle[axis] = [*restyle[axis], coords[axis]]
        restyle["intensity"] = [*restyle["intensity"], None]
        step["args"] = [restyle, [*traces, index]]
