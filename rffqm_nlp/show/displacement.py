"""The view of a design under load: the folded pattern coloured by each vertex's
displacement (mm), displaced by it times an exaggeration that a slider chooses.

The page is drawn in the target's frame like the design's view (:mod:`.view`): every
position moved by the design's rigid motion (``rotation @ y + translation``), the
displacements (metres, in the model's frame) rotated with it and divided by the model's
scale (m per pattern unit). The slider's steps restyle the mesh's x, y, z; the largest
step shows the largest displacement at :data:`SHOWN` of the pattern's extent.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..io.export import triangles
from ..mechanics.loads import Response
from ..model import numpy_model
from .view import write_figure

if TYPE_CHECKING:
    from ..design.results import DesignResult

#: The largest exaggeration shows the largest displacement at this share of the extent.
SHOWN = 0.1
#: The slider's steps, as shares of the largest exaggeration (true scale is added).
STEPS = (0.0, 0.125, 0.25, 0.5, 1.0)


def exaggerations(largest: float, extent: float) -> np.ndarray:
    """The slider's exaggeration factors (ascending, 1 among them): :data:`STEPS` of the
    factor that shows a displacement ``largest`` at :data:`SHOWN` of ``extent`` (both in
    pattern units)."""
    top = SHOWN * extent / largest if largest > 0 else 1.0
    return np.unique(np.concatenate([np.array(STEPS) * top, [1.0]]))


def spec(result: DesignResult, response: Response, scale: float) -> dict:
    """The figure {"data", "layout"}: a Mesh3d of the design's folded state coloured by
    displacement (mm), a slider of :func:`exaggerations`, starting at the largest."""
    pat = result.pattern
    Y = numpy_model.fold(pat, result.omega).reshape(-1, 3) @ result.rotation.T \
        + result.translation
    U = response.displacement.reshape(-1, 3) @ result.rotation.T / scale
    size_mm = np.linalg.norm(response.displacement.reshape(-1, 3), axis=1) * 1e3
    extent = float(np.ptp(Y, axis=0).max())
    factors = exaggerations(float(np.linalg.norm(U, axis=1).max()), extent)
    steps = []
    for e in factors:
        P = Y + e * U
        steps.append({"method": "restyle", "label": f"x{e:.3g}",
                      "args": [{"x": [P[:, 0].tolist()], "y": [P[:, 1].tolist()],
                                "z": [P[:, 2].tolist()]}, [0]]})
    tri = triangles(pat.N, pat.M)
    first = steps[-1]["args"][0]
    mesh = {"type": "mesh3d", "x": first["x"][0], "y": first["y"][0], "z": first["z"][0],
            "i": tri[:, 0].tolist(), "j": tri[:, 1].tolist(), "k": tri[:, 2].tolist(),
            "intensity": size_mm.tolist(), "cmin": 0.0,
            "cmax": float(size_mm.max()) or 1.0, "colorscale": "Viridis",
            "colorbar": {"title": {"text": "displacement<br>(mm)"}}, "flatshading": True,
            "name": "displaced pattern", "hoverinfo": "skip"}
    layout = {"title": {"text": f"largest displacement {response.largest_deflection_mm:.4g} "
                                f"mm at vertex {response.largest_at}", "x": 0.5},
              "scene": {"aspectmode": "data", "xaxis": {"visible": False},
                        "yaxis": {"visible": False}, "zaxis": {"visible": False}},
              "margin": {"l": 0, "r": 0, "t": 40, "b": 0},
              "sliders": [{"active": len(steps) - 1, "steps": steps,
                           "currentvalue": {"prefix": "exaggeration: "},
                           "pad": {"t": 10, "b": 10}}]}
    return {"data": [mesh], "layout": layout}


def write_html(result: DesignResult, response: Response, scale: float,
               path: str | os.PathLike) -> Path:
    """Write the figure of :func:`spec` as one self-contained HTML page, atomically."""
    return write_figure(spec(result, response, scale), path, "rffqm-nlp design under load")
