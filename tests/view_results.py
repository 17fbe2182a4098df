"""A DesignResult made by hand from a marched Miura-ori, for the view's tests."""

from __future__ import annotations

import numpy as np

from rffqm_nlp.model import numpy_model
from rffqm_nlp.model.boundary import miura_boundary
from rffqm_nlp.design.results import DesignResult, Fit, SolveStats


def _rotation(angle: float) -> np.ndarray:
    """Rotation by ``angle`` about the axis (1, 1, 1) / sqrt(3), (3, 3)."""
    k = np.ones(3) / np.sqrt(3.0)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def miura_result(panels: int = 8, omega: float = 1.3) -> DesignResult:
    """A (panels x panels) Miura-ori designed at ``omega``, moved by a rotation and a
    translation; its target lattice is its own coarse lattice lifted by 0.1 along z, so the
    distances to the target are positive."""
    pattern = numpy_model.march(miura_boundary(panels, panels, 1.0, 1.0, 1.1, "zigzag_i"))
    R, t = _rotation(0.4), np.array([0.5, -1.0, 2.0])
    folded = numpy_model.fold(pattern, omega) @ R.T + t
    target = folded[::2, ::2] + np.array([0.0, 0.0, 0.1])
    fit = Fit(rms=0.01, rms_surface=0.01, hausdorff=0.02, plane_rms=0.1,
              min_side_over_mean=0.9, min_sector_angle=1.1)
    stats = SolveStats(status="Solve_Succeeded", success=True, iterations=0, build_time=0.0,
                       solve_time=0.0, objective=0.0, solver="levenberg-marquardt",
                       transcription="simultaneous", hessian="exact")
    return DesignResult(boundary=pattern.boundary, omega=omega, pattern=pattern, folded=folded,
                        target_points=target, rotation=R, translation=t, fit=fit, stats=stats)
