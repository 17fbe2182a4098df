"""Fuzzing the public API: thousands of bad calls, each refused by a library error or
answered with finite numbers (issue "Files from others are inert": no raw exception, no
silent NaN).

Every public function and class of the forward model, the side lengths, the shape
measures, the surfaces, the curvature maps, the collision checks and their helpers
(:data:`CALLS`; :func:`test_every_public_callable_is_fuzzed` keeps the table complete) is
called with valid arguments of which Hypothesis replaces one or several by a bad value:
None, booleans, strings, bytes, NaN, infinities, huge, tiny and negative numbers, huge
integers, empty and wrongly shaped arrays, nested lists, tables, complex numbers, objects
of the wrong class. Each call must either raise a
:class:`~rffqm_nlp.errors.RffqmError` (one non-empty line) or return a value whose numbers
are all finite; and it must end within :data:`CALL_LIMIT` seconds (an alarm ends a
hanging call). The patterns are 2 x 2 panels and the surfaces small, so the whole file
runs in well under a minute; the seed is fixed (``derandomize``), so CI sees the same
calls on every run.
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import math
import signal
import sys
import time
from typing import Any, Callable

import casadi as ca
import numpy as np
import pytest
import trimesh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import rffqm_nlp as rq
from rffqm_nlp.model import backend
from rffqm_nlp.model import boundary
from rffqm_nlp.targets import curvature
from rffqm_nlp.model import lengths
from rffqm_nlp.model import marching
from rffqm_nlp.model import numpy_model
from rffqm_nlp.model import pattern
from rffqm_nlp.targets import shape
from rffqm_nlp.targets import surfaces
from rffqm_nlp.model import vertex
from rffqm_nlp import mechanics
from rffqm_nlp.errors import RffqmError

# rq.collisions is the function, so the module by its name
collisions = importlib.import_module("rffqm_nlp.contact.collisions")
clearance = importlib.import_module("rffqm_nlp.design.clearance")
# rq.make is the package called as its function make, so the package by its name
make = importlib.import_module("rffqm_nlp.make")
thick = importlib.import_module("rffqm_nlp.contact.thick")
closed_form = importlib.import_module("rffqm_nlp.design.solvers.closed_form")
curvature_target = importlib.import_module("rffqm_nlp.targets.curvature_target")
curvature_fit = importlib.import_module("rffqm_nlp.design.curvature_fit")

#: The modules whose public callables are fuzzed.
MODULES = (boundary, pattern, numpy_model, marching, vertex, lengths, shape, surfaces,
           curvature, collisions, clearance, backend, mechanics, make, thick, closed_form,
           curvature_target, curvature_fit)
#: Longest time one call may take (seconds) before it counts as a hang.
CALL_LIMIT = 20.0
#: Result records: dataclasses that store what they are given and compute nothing (their
#: fields come from the functions fuzzed here, whose results are checked).
RECORDS = {"collisions.CollisionReport", "curvature.Curvature", "lengths.SideLengthSolution",
           "clearance.Closest", "mechanics.Modes", "mechanics.Response", "make.Made",
           "make.MakeOptions", "make.Sheet", "make.Stop", "make.Tie", "thick.ThickPanels",
           "thick.ThickReport", "closed_form.ClosedForm", "closed_form.Separable",
           "closed_form.CurvatureField", "curvature_target.Realisable"}


# --------------------------------------------------------------------------- valid inputs
BD = rq.miura_boundary(2, 2)
PAT = numpy_model.march(BD)
Y = numpy_model.fold(PAT, 1.0)
PLANE = surfaces.get("plane")
CAP = surfaces.get("sphere_cap")
LATTICE = CAP.lattice(2, 2)
TRIANGLES = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]])
_PROBLEM = rq.DesignProblem(target=PLANE, panels=(4, 4))
NLP = _PROBLEM.transcribe()
NLP_PATTERN = numpy_model.march(_PROBLEM.start().boundary)
F2 = marching.pattern_function(2, 2)
QUAT = (np.ones((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)))
#: A designed 4 x 4 sphere cap, to make.
RESULT = rq.DesignProblem(target=CAP, panels=(4, 4)).solve(rq.SolveOptions(max_iter=30))
CONES = thick.ThickPanels.build(PAT, 1.0, 0.05, "back").cones()
SHEET = mechanics.Material(E=1e9, nu=0.3, thickness=1e-3, fold_stiffness=0.1, density=900.0)
BAR_AND_HINGE = mechanics.BarAndHinge(PAT, 1.0, SHEET, width=0.1)
HELD = [[1, 1], [1, 3], [3, 1]]
#: Curvature targets: K and H, and principal curvatures given by a function.
FIELD = surfaces.Curvature(K=1.0, H=1.5, size=(1.0, 2.0))
SADDLE = surfaces.Curvature(kx=lambda x, y: 0.1 + 0 * x, ky=-0.1, size=(3.0, 2.0))
FOLDED_FIELD = numpy_model.fold(numpy_model.march(rq.miura_boundary(4, 4, 0.3, 0.4)), 2.0)
FIELD_MAPS = curvature_fit.prescribed_maps(shape.coarse_grain(FOLDED_FIELD), FIELD)


def plane_fn(u, v):
    """A user's surface r(u, v) (module level, so it can be named)."""
    return u, v, 0.1 * u * v


class Flat(surfaces.Surface):
    """A subclass of Surface as the docs describe (only ``_r``): its constructor is
    Surface's."""

    def _r(self, u, v):
        return u, v, 0 * u


#: name -> (the callable, valid keyword arguments). A bad call replaces some of them.
CALLS: dict[str, tuple[Callable, dict[str, Any]]] = {
    # boundary
    "boundary.check_size": (boundary.check_size, dict(N=2, M=3)),
    "boundary.check_boundary": (boundary.check_boundary, dict(bd=BD)),
    "boundary.mv_set": (boundary.mv_set, dict(alpha=1.0, beta=1.2, tol=1e-10)),
    "boundary.BoundaryData": (rq.BoundaryData, dict(left=BD.left, bottom=BD.bottom,
                                                    l_left=BD.l_left, l_bottom=BD.l_bottom)),
    "boundary.BoundaryData.from_vector": (rq.BoundaryData.from_vector, dict(
        x=BD.to_vector(), sigma=BD.sigma, N=2, M=2)),
    "boundary.BoundaryData.from_dict": (rq.BoundaryData.from_dict, dict(d=BD.to_dict())),
    "boundary.BoundaryData.with_lengths": (BD.with_lengths, dict(lengths=BD.lengths)),
    "boundary.miura_vertex": (boundary.miura_vertex, dict(i=1, j=2, alpha0=1.1,
                                                          layout="zigzag_i")),
    "boundary.miura_boundary": (rq.miura_boundary, dict(N=2, M=3, a=1.0, b=1.2, alpha0=1.1,
                                                        layout="zigzag_j")),
    "boundary.perturb_angles": (rq.perturb_angles, dict(bd=BD, amplitude=0.01, seed=3)),
    "boundary.refine": (boundary.refine, dict(design=BD, reference=BD,
                                              finer=rq.miura_boundary(4, 4))),
    # pattern
    "pattern.check_omega": (pattern.check_omega, dict(omega=[0.1, 0.2], name="omega")),
    "pattern.check_fold_angle": (pattern.check_fold_angle, dict(omega=0.3, name="omega")),
    "pattern.check_frames": (pattern.check_frames, dict(frames=5, minimum=2, name="frames")),
    "pattern.check_pattern": (pattern.check_pattern, dict(pat=PAT, name="pattern")),
    "pattern.motion_omegas": (pattern.motion_omegas, dict(omega_end=1.0, frames=4, minimum=1,
                                                          name="frames")),
    "pattern.check_march_memory": (pattern.check_march_memory, dict(N=2, M=2)),
    "pattern.check_fold_memory": (pattern.check_fold_memory, dict(N=2, M=2, states=3)),
    "pattern.check_folded": (pattern.check_folded, dict(Y=Y)),
    "pattern.Pattern": (rq.Pattern, {k: getattr(PAT, k) for k in
                                     ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")}),
    "pattern.Pattern.from_dict": (rq.Pattern.from_dict, dict(d=PAT.to_dict())),
    # numpy_model
    "numpy_model.mu2": (numpy_model.mu2, dict(alpha=1.0, beta=1.2, sigma=-1.0)),
    "numpy_model.mu1": (numpy_model.mu1, dict(alpha=1.0, beta=1.2, sigma=1.0)),
    "numpy_model.gamma2_bar": (numpy_model.gamma2_bar, dict(omega=0.5, alpha=1.0, beta=1.2,
                                                            sigma=-1.0)),
    "numpy_model.gamma1_bar": (numpy_model.gamma1_bar, dict(omega=0.5, alpha=1.0, beta=1.2,
                                                            sigma=1.0)),
    "numpy_model.march": (numpy_model.march, dict(bd=BD)),
    "numpy_model.fold": (numpy_model.fold, dict(pat=PAT, omega=[0.0, 1.0])),
    "numpy_model.fold_angles": (numpy_model.fold_angles, dict(pat=PAT, omega=1.0)),
    # marching
    "marching.pattern_function": (marching.pattern_function, dict(N=2, M=2)),
    "marching.fold_function": (marching.fold_function, dict(N=2, M=2)),
    "marching.folded_function": (marching.folded_function, dict(N=2, M=2)),
    "marching.marched_function": (marching.marched_function, dict(N=2, M=2)),
    "marching.panel_quaternions_function": (marching.panel_quaternions_function,
                                            dict(N=2, M=2)),
    "marching.edge_directions": (marching.edge_directions, dict(alpha=PAT.alpha,
                                                                beta=PAT.beta)),
    "marching.fold_multipliers": (marching.fold_multipliers, dict(
        alpha=PAT.alpha, beta=PAT.beta, sigma=PAT.sigma)),
    "marching.crease_quaternion": (marching.crease_quaternion, dict(
        theta=0.3, k=0.5, c=0.9, s=0.4, sign=-1.0, k_den=1.0)),
    "marching.folded_vertices": (marching.folded_vertices, dict(
        alpha=PAT.alpha, beta=PAT.beta, sigma=PAT.sigma, lh=PAT.lh, lv=PAT.lv, omega=0.7)),
    "marching.qmul": (marching.qmul, dict(p=(1.0, 0.0, 0.0, 0.0), q=(0.0, 1.0, 0.0, 0.0))),
    "marching.rotate_planar": (marching.rotate_planar, dict(q=(1.0, 0.0, 0.0, 0.0), vx_=1.0,
                                                            vy_=2.0)),
    "marching.crease_quaternions": (marching.crease_quaternions, dict(
        alpha=PAT.alpha, beta=PAT.beta, sigma=PAT.sigma, theta_h=np.zeros((3, 3)),
        omega=1.0)),
    "marching.rotated_edges": (marching.rotated_edges, dict(
        quat=QUAT, alpha=PAT.alpha, theta_h=np.zeros((3, 3)), lh=PAT.lh, lv=PAT.lv)),
    "marching.boundary_inputs": (marching.boundary_inputs, dict(bd=BD)),
    "marching.locate_failure": (marching.locate_failure, dict(
        alpha_d=np.ones((2, 2)), mu=np.full((2, 2), 3.0), lh=PAT.lh, lv=PAT.lv)),
    "marching.march": (marching.march, dict(bd=BD)),
    "marching.fold": (marching.fold, dict(pat=PAT, omega=0.7)),
    "marching.fold_angles": (marching.fold_angles, dict(pat=PAT, omega=0.7)),
    # evaluate and Evaluation give what the Function computes (NaN marks a failed march):
    # their results are not checked, their refusals are (see test_evaluation_...).
    "marching.evaluate": (marching.evaluate, dict(f=F2, args=marching.boundary_inputs(BD))),
    "marching.Evaluation": (marching.Evaluation, dict(f=F2,
                                                      args=marching.boundary_inputs(BD))),
    "marching.Evaluation.set": (marching.Evaluation(F2, marching.boundary_inputs(BD)).set,
                                dict(k=2, value=BD.l_left)),
    # vertex
    "vertex.mu2": (vertex.mu2, dict(alpha=1.0, beta=1.2, sigma=-1.0)),
    "vertex.mu2_terms": (vertex.mu2_terms, dict(alpha=1.0, beta=1.2, sigma=1.0)),
    "vertex.mu1": (vertex.mu1, dict(alpha=1.0, beta=1.2, sigma=-1.0)),
    "vertex.mv_multiplier": (vertex.mv_multiplier, dict(alpha=np.array([1.0, 1.1]),
                                                        beta=np.array([1.2, 0.9]),
                                                        sigma=np.array([-1.0, 1.0]))),
    "vertex.fold_by_multiplier": (vertex.fold_by_multiplier, dict(omega=0.4, mu=2.0)),
    "vertex.gamma2_bar": (vertex.gamma2_bar, dict(omega=0.4, alpha=1.0, beta=1.2, sigma=1.0)),
    "vertex.gamma1_bar": (vertex.gamma1_bar, dict(omega=0.4, alpha=1.0, beta=1.2, sigma=1.0)),
    "vertex.fold_angles": (vertex.fold_angles, dict(omega=0.4, alpha=1.0, beta=1.2,
                                                    sigma=-1.0)),
    "vertex.design_d": (vertex.design_d, dict(alpha_d=1.0, mu_abc=2.0)),
    "vertex.panel_sides": (vertex.panel_sides, dict(alpha_a=1.0, alpha_b=1.2, alpha_c=1.1,
                                                    l_ab=1.0, l_ac=1.0)),
    "vertex.panel_side_residuals": (vertex.panel_side_residuals, dict(
        alpha_a=1.0, alpha_b=1.2, alpha_c=1.1, l_ab=1.0, l_ac=1.0, l_cd=1.0, l_bd=1.0)),
    # lengths
    "lengths.LengthMaps": (lengths.LengthMaps, dict(Lh=np.zeros((3, 2, 4)),
                                                    Lv=np.zeros((2, 3, 4)))),
    "lengths.length_maps": (lengths.length_maps, dict(bd=BD)),
    "lengths.memory_estimate": (lengths.memory_estimate, dict(N=2, M=2, program="lp")),
    "lengths.check_memory": (lengths.check_memory, dict(bd=BD, program="nlp", name="f")),
    "lengths.side_length_lp": (lengths.side_length_lp, dict(bd=BD, eps=0.01, delta=None)),
    "lengths.side_length_nlp": (lengths.side_length_nlp, dict(
        bd=BD, objective="max_min", min_length=0.01, tol=1e-8, max_iter=50, verbose=False)),
    "lengths.length_spread": (lengths.length_spread, dict(lh=PAT.lh, lv=PAT.lv)),
    # shape
    "shape.coarse_grain": (shape.coarse_grain, dict(Y=Y)),
    "shape.fundamental_forms": (shape.fundamental_forms, dict(P=LATTICE, hu=1.0, hv=0.5)),
    "shape.kabsch": (shape.kabsch, dict(P=LATTICE, Q=LATTICE + 1.0, reflection=False)),
    "shape.align": (shape.align, dict(P=LATTICE, Q=LATTICE + 1.0, reflection=True)),
    "shape.distances_to": (shape.distances_to, dict(points=LATTICE, target=PLANE)),
    "shape.rms_distance": (shape.rms_distance, dict(points=LATTICE, target=LATTICE[::2])),
    "shape.hausdorff_distance": (shape.hausdorff_distance, dict(points=LATTICE,
                                                                target=PLANE)),
    "shape.relative_fit": (shape.relative_fit, dict(points=LATTICE, target=LATTICE + 0.1)),
    "shape.lattice_area": (shape.lattice_area, dict(P=LATTICE)),
    "shape.surface_area": (shape.surface_area, dict(target=PLANE)),
    "shape.shape_fit": (shape.shape_fit, dict(folded=Y, target=PLANE)),
    # surfaces
    "surfaces.refuse_points": (surfaces.refuse_points, dict(count=10, rows=3, what="x")),
    "surfaces.check_surface": (surfaces.check_surface, dict(surface=PLANE, name="target")),
    "surfaces.Surface": (Flat, dict(name="mine", params={"h": 1.0}, domain=((0, 1), (0, 1)))),
    "surfaces.grid_faces": (surfaces.grid_faces, dict(n_u=3, n_v=4)),
    "surfaces.mean_neighbour_distances": (surfaces.mean_neighbour_distances,
                                          dict(points=LATTICE)),
    "surfaces.point_set_diameter": (surfaces.point_set_diameter, dict(points=LATTICE)),
    "surfaces.Custom": (surfaces.Custom, dict(fn=plane_fn, domain=((-1, 1), (-1, 1)),
                                              name="mine", reference=None)),
    "surfaces.parse_reference": (surfaces.parse_reference, dict(ref="shapes.py:dome")),
    "surfaces.resolve_reference": (surfaces.resolve_reference, dict(ref="json:loads",
                                                                    root=None)),
    "surfaces.describe": (surfaces.describe, dict(name="saddle")),
    "surfaces.get": (surfaces.get, dict(name="paraboloid", domain=((-1, 1), (-1, 1)), a=3.0)),
    "surfaces.target_keys": (surfaces.target_keys, dict(name="cylinder")),
    "surfaces.from_config": (surfaces.from_config, dict(table={"name": "plane"}, root=None,
                                                        trust=False)),
    "surfaces.config_of": (surfaces.config_of, dict(surface=PLANE)),
    "surfaces.rebuildable": (surfaces.rebuildable, dict(table={"name": "plane"})),
    "surfaces.Surface.point": (CAP.point, dict(u=np.array([0.1, 0.2]), v=0.3)),
    "surfaces.Surface.derivatives": (CAP.derivatives, dict(u=0.1, v=np.array([0.2, 0.3]))),
    "surfaces.Surface.normal": (CAP.normal, dict(u=0.1, v=0.2)),
    "surfaces.Surface.fundamental_forms": (CAP.fundamental_forms, dict(u=0.1, v=0.2)),
    "surfaces.Surface.gaussian_curvature": (CAP.gaussian_curvature, dict(u=0.1, v=0.2)),
    "surfaces.Surface.mean_curvature": (CAP.mean_curvature, dict(u=0.1, v=0.2)),
    "surfaces.Surface.grid_uv": (CAP.grid_uv, dict(n_u=3, n_v=4)),
    "surfaces.Surface.sample": (CAP.sample, dict(n_u=3, n_v=4)),
    "surfaces.Surface.mesh": (CAP.mesh, dict(n_u=3, n_v=4)),
    "surfaces.Surface.lattice_uv": (CAP.lattice_uv, dict(N=2, M=3, spacing=None)),
    "surfaces.Surface.lattice": (CAP.lattice, dict(N=2, M=2, spacing=(0.5, 0.5))),
    "surfaces.Curvature": (surfaces.Curvature, dict(K=1.0, H=1.5, size=(1.0, 2.0),
                                                    name="dome", reference=None)),
    "surfaces.Curvature.values": (SADDLE.values, dict(x=np.array([0.1, 0.2]), y=0.3)),
    "surfaces.Curvature.gaussian": (FIELD.gaussian, dict(x=0.1, y=np.array([0.2, 0.3]))),
    "surfaces.Curvature.mean": (SADDLE.mean, dict(x=0.1, y=0.2)),
    "surfaces.Curvature.principal": (FIELD.principal, dict(x=0.1, y=0.2)),
    "surfaces.Curvature.lattice_xy": (FIELD.lattice_xy, dict(N=2, M=3)),
    "surfaces.Curvature.lattice": (FIELD.lattice, dict(N=2, M=3)),
    "surfaces.Curvature.sample": (FIELD.sample, dict(n_u=3, n_v=4)),
    "surfaces.Curvature.mesh": (FIELD.mesh, dict(n_u=3, n_v=4)),
    "surfaces.Curvature.scale": (SADDLE.scale, dict(N=3, M=2)),
    "curvature_target.Curvature": (curvature_target.Curvature, dict(
        kx=0.1, ky=-0.1, size=(1.0, 1.0))),
    "curvature_target.from_config": (curvature_target.from_config, dict(
        table={"K": 1.0, "size": [1.0, 2.0]}, root=None, trust=False)),
    "curvature_target.is_curvature_table": (curvature_target.is_curvature_table, dict(
        table={"kx": 0.1, "ky": 0.2, "size": [1, 1]})),
    "curvature_fit.prescribed_maps": (curvature_fit.prescribed_maps, dict(
        coarse=shape.coarse_grain(FOLDED_FIELD), target=FIELD)),
    "curvature_fit.cell_errors": (curvature_fit.cell_errors, dict(maps=FIELD_MAPS,
                                                                  diameter=2.0)),
    "curvature_fit.curvature_errors": (curvature_fit.curvature_errors, dict(
        maps=FIELD_MAPS, diameter=2.0)),
    "curvature_fit.curvature_target_fit": (curvature_fit.curvature_target_fit, dict(
        folded=FOLDED_FIELD, target=SADDLE)),
    "curvature_fit.measured": (curvature_fit.measured, dict(
        folded=FOLDED_FIELD, target_points=shape.coarse_grain(FOLDED_FIELD), target=FIELD)),
    "surfaces.Surface.closest_points": (CAP.closest_points, dict(points=LATTICE + 0.1,
                                                                 resolution=11)),
    # curvature
    "curvature.lattice_curvatures": (curvature.lattice_curvatures, dict(
        P=CAP.lattice(3, 3), orient=None)),
    "curvature.curvature_maps": (curvature.curvature_maps, dict(
        coarse=CAP.lattice(3, 3) + 0.01, target_points=CAP.lattice(3, 3), target=CAP)),
    # collisions and clearance
    "collisions.collisions": (rq.collisions, dict(pattern=PAT, omega_max=2.0, clearance=0.01,
                                                  tol=1e-3)),
    "collisions.panel_distance": (collisions.panel_distance, dict(
        geo=PAT, S=Y.reshape(1, -1, 3), s=np.array([0]), p=np.array([0]), q=np.array([3]))),
    "collisions.triangles_intersect": (collisions.triangles_intersect, dict(
        A=TRIANGLES, B=TRIANGLES + 0.5, scale=1.0)),
    "collisions.triangle_distance": (collisions.triangle_distance, dict(
        A=TRIANGLES, B=TRIANGLES + 2.0, scale=1.0)),
    "collisions.near_pairs": (collisions.near_pairs, dict(pattern=PAT, Y=Y, reach=0.5)),
    "clearance.closest": (clearance.closest, dict(pattern=PAT, omega=2.5, clearance=0.1)),
    "clearance.constrain": (clearance.constrain, dict(nlp=NLP, pattern=NLP_PATTERN, omega=1.0,
                                                      pairs=np.array([[0, 7]]),
                                                      clearance=0.01)),
    "clearance.panel_corners": (clearance.panel_corners, dict(N=2, M=3)),
    "clearance.choose_axis": (clearance.choose_axis, dict(P=TRIANGLES[0][[0, 1, 2, 2]],
                                                          Q=TRIANGLES[0][[0, 1, 2, 2]] + 1)),
    # the closed-form start
    "closed_form.closed_form_boundary": (closed_form.closed_form_boundary, dict(
        kx=0.05, ky=-0.05, panels=(4, 4), size=(2.0, 2.0), alpha0=1.1, layout="zigzag_i",
        omega=2.0, steps=None, min_angle=0.0, max_ratio=20.0)),
    "closed_form.closed_form_design": (closed_form.closed_form_design, dict(
        problem=_PROBLEM, omega=None)),
    "closed_form.closed_form_start": (closed_form.closed_form_start, dict(
        problem=_PROBLEM, omega=1.5)),
    "closed_form.curvatures_along_lattice": (closed_form.curvatures_along_lattice, dict(
        target=CAP, N=2, M=3)),
    "closed_form.separable_curvatures": (closed_form.separable_curvatures, dict(
        k_u=np.ones((3, 4)), k_v=np.zeros((3, 4)))),
    "closed_form.lattice_steps": (closed_form.lattice_steps, dict(points=LATTICE)),
    "closed_form.first_order_gains": (closed_form.first_order_gains, dict(
        alpha0=1.1, omega_z=2.0)),
    "closed_form.zigzag_gain": (closed_form.zigzag_gain, dict(
        delta=np.array([0.0, 0.1]), alpha0=1.1, omega_z=2.0)),
    "closed_form.straight_gain": (closed_form.straight_gain, dict(
        Delta=np.array([0.0, 0.1]), delta=0.0, alpha0=1.1, omega_z=2.0)),
    "closed_form.zigzag_fold": (closed_form.zigzag_fold, dict(omega=2.0, alpha0=1.1,
                                                              delta=0.1)),
    "closed_form.transposed": (closed_form.transposed, dict(bd=BD)),
    # making a design, thick panels
    "make.make": (make.make, dict(result=RESULT, width=100.0, thickness="0.2mm", ties=1)),
    "make.make_options": (make.make_options, dict(table={"width": "10cm"}, where="[make]",
                                                  process="cutter")),
    "make.length": (make.length, dict(value="3mm", name="dash", positive=True)),
    "make.perforation": (make.perforation, dict(length=20.0, dash=3.0, gap=1.0, relief=1.0)),
    "make.lock_ties": (make.lock_ties, dict(pattern=RESULT.pattern, omega=RESULT.omega,
                                            count=2, scale=10.0)),
    "make.tie_candidates": (make.tie_candidates, dict(pattern=RESULT.pattern,
                                                      omega=RESULT.omega, scale=10.0)),
    "make.crease_stops": (make.crease_stops, dict(pattern=RESULT.pattern, omega=RESULT.omega,
                                                  count=2, scale=10.0)),
    "make.Sheet.of": (make.Sheet.of, dict(pat=RESULT.pattern, omega=RESULT.omega, scale=10.0)),
    "thick.thick_collisions": (thick.thick_collisions, dict(
        pattern=RESULT.pattern, omega_max=RESULT.omega, thickness=0.01, side="auto",
        tol=1e-3)),
    "thick.choose_side": (thick.choose_side, dict(pat=PAT, omega=1.0)),
    "thick.panel_frames": (thick.panel_frames, dict(pat=PAT, Y=Y)),
    "thick.ThickPanels.build": (thick.ThickPanels.build, dict(pat=PAT, omega=1.0,
                                                              thickness=0.05, side="back")),
    "thick.cone_gap": (thick.cone_gap, dict(h_a=CONES[0][0, 0], rays_a=CONES[1][0, 0],
                                            h_b=CONES[0][1, 1], rays_b=CONES[1][1, 1])),
    # backend
    "backend.is_casadi": (backend.is_casadi, dict(args=1.0)),
    "backend.math_for": (backend.math_for, dict(args=1.0)),
    "surfaces.mathlib": (surfaces.mathlib, dict(args=1.0)),
    "surfaces.Mesh": (surfaces.Mesh, dict(source=CAP.mesh(9, 9), name="cap", knots=None,
                                          smoothing=None)),
    "backend.finite_array": (backend.finite_array, dict(value=[1.0, 2.0], name="x")),
    "backend.check_formula_args": (backend.check_formula_args, dict(alpha=1.0, sigma=1.0)),
    "backend.finite_result": (backend.finite_result, dict(value=np.ones(3), what="x")),
    # the one validator of numbers, which the modules above call
    "files.check_value": (rq.files.check_value, dict(
        value=2, key=rq.files.Key("whole", low=1), name="n")),
    "files.describe_value": (rq.files.describe_value, dict(value=np.array(2.5))),
    # mechanics
    "mechanics.Material": (mechanics.Material, dict(E=1e9, nu=0.3, thickness=1e-3,
                                                    fold_stiffness=0.1, density=900.0)),
    "mechanics.Material.named": (mechanics.Material.named, dict(name="paper")),
    "mechanics.Material.with_fold_stiffness": (SHEET.with_fold_stiffness,
                                               dict(fold_stiffness=0.2)),
    "mechanics.BarAndHinge": (mechanics.BarAndHinge, dict(pattern=PAT, omega=1.0,
                                                          material=SHEET, width=0.1)),
    "mechanics.BarAndHinge.modes": (BAR_AND_HINGE.modes, dict(k=8)),
    "mechanics.BarAndHinge.solve": (BAR_AND_HINGE.solve, dict(
        loads=[[2, 2, 0.0, 0.0, -1.0]], supports=HELD, ties=[[[1, 1], [3, 3]]], gravity=True,
        displacements=[[3, 3, 0.0, 0.0, 1e-4]], down=(0.0, 0.0, -1.0))),
    "mechanics.BarAndHinge.point_stiffness": (BAR_AND_HINGE.point_stiffness, dict(
        vertex=(2, 2), direction=(0.0, 0.0, 1.0), supports=HELD, ties=None)),
    "mechanics.Ties": (mechanics.Ties, dict(pairs=[[[1, 1], [3, 3]]], stiffness=1e5)),
    "mechanics.folded_state": (mechanics.folded_state, dict(pattern=PAT, omega=1.0)),
    "mechanics.folding_velocity": (mechanics.folding_velocity, dict(pattern=PAT, omega=1.0)),
    "mechanics.poisson_ratio": (mechanics.poisson_ratio, dict(pattern=PAT, omega=1.0)),
    "mechanics.poisson_map": (mechanics.poisson_map, dict(pattern=PAT, omega=1.0)),
}
#: Calls that take no arguments: called once each, their results checked.
NO_ARGUMENTS = {"surfaces.names": surfaces.names, "marching.panel_cell": marching.panel_cell,
                "marching.cached_graphs": marching.cached_graphs}
#: Calls whose results are what a CasADi Function computes from its inputs (NaN marks a
#: failed march there): only their refusals are checked.
UNCHECKED_RESULTS = {"marching.evaluate", "marching.Evaluation", "marching.Evaluation.set"}
#: Examples per call: cheap calls get more, calls that solve or build graphs fewer.
EXAMPLES = 32
FEWER = {"lengths.side_length_nlp": 8, "surfaces.Mesh": 8, "lengths.side_length_lp": 12, "surfaces.Custom": 10,
         "surfaces.get": 12, "surfaces.from_config": 12, "surfaces.Surface": 8,
         "collisions.collisions": 12, "clearance.closest": 12, "clearance.constrain": 8,
         "curvature.curvature_maps": 12, "shape.shape_fit": 10, "shape.surface_area": 10,
         "boundary.refine": 12, "surfaces.Surface.lattice": 10,
         "surfaces.Surface.closest_points": 12, "mechanics.BarAndHinge": 16,
         "mechanics.BarAndHinge.modes": 16, "mechanics.BarAndHinge.solve": 16,
         "mechanics.BarAndHinge.point_stiffness": 16, "make.make": 6,
         "thick.thick_collisions": 10, "make.tie_candidates": 12, "make.lock_ties": 12}


# --------------------------------------------------------------------------- bad values
finite_floats = st.floats(allow_nan=False, allow_infinity=False)
any_floats = st.floats(allow_nan=True, allow_infinity=True)
huge_ints = st.sampled_from([10**7, 2**31, 2**63, 2**64 + 1, 10**30, -10**30, -(2**63)])


def bad_values() -> st.SearchStrategy:
    """Values no argument above wants (and a few that some take)."""
    return st.one_of(
        st.none(), st.booleans(), st.text(max_size=6), st.binary(max_size=3),
        st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -1e308, 1e-308, -1e-300, 0.0,
                         -0.0, -1.0, 4.0, -4.0, 1e15]),
        any_floats, st.integers(-20, 20), huge_ints, st.complex_numbers(max_magnitude=5),
        st.lists(any_floats, max_size=4),
        st.lists(st.lists(finite_floats, max_size=3), max_size=3),
        hnp.arrays(np.float64, hnp.array_shapes(min_dims=0, max_dims=3, min_side=0,
                                                max_side=4), elements=any_floats),
        hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3, min_side=0,
                                                max_side=4),
                   elements=st.floats(-4, 4)),
        hnp.arrays(np.int64, hnp.array_shapes(min_dims=1, max_dims=2, max_side=3),
                   elements=st.integers(-3, 3)),
        st.dictionaries(st.text(max_size=3), st.integers(-2, 2), max_size=2),
        st.sampled_from([object(), BD, PAT, PLANE, (1.0, 2.0), [[0.1], [0.1, 0.2]],
                         np.array(["a", "b"]), np.array([True, False]), np.zeros((0, 3)),
                         np.zeros((2, 2, 3)), np.full((3, 3, 3), np.nan), float, len,
                         "zigzag_j", "sphere_cap", ("a", 1)]),
        st.builds(lambda: ca.DM([1.0, 2.0])), st.builds(lambda: ca.SX.sym("x")))


# --------------------------------------------------------------------------- checking
class Hang(Exception):
    """A call ran past CALL_LIMIT."""


def _alarm(signum, frame):
    raise Hang(f"a call took more than {CALL_LIMIT} s")


def assert_finite(value: Any, where: str = "result", depth: int = 0) -> None:
    """Every number in ``value`` (arrays, numbers, tuples, lists, dicts, dataclasses, CasADi
    DMs, triangle meshes) is finite; symbols, Functions, surfaces and strings pass."""
    assert depth < 8, where
    if isinstance(value, (bool, np.bool_, str, bytes, int, np.integer)) or value is None:
        return
    if isinstance(value, clearance.Closest) and value.pair is None:
        assert value.distance == math.inf       # documented: no pair within reach
        return
    if isinstance(value, clearance.NLP):        # its bounds say "none" by infinity (IPOPT's)
        return
    if isinstance(value, (float, np.floating)):
        assert math.isfinite(value), f"{where} = {value}"
    elif isinstance(value, np.ndarray):
        if value.dtype.kind in "fc":
            assert np.all(np.isfinite(value)), f"{where} holds NaN or infinity"
    elif isinstance(value, ca.DM):
        assert np.all(np.isfinite(value.full())), f"{where} holds NaN or infinity"
    elif isinstance(value, (tuple, list)):
        for k, item in enumerate(value):
            assert_finite(item, f"{where}[{k}]", depth + 1)
    elif isinstance(value, dict):
        for k, item in value.items():
            assert_finite(item, f"{where}[{k!r}]", depth + 1)
    elif isinstance(value, trimesh.Trimesh):
        assert_finite(np.asarray(value.vertices), f"{where}.vertices", depth + 1)
    elif dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            assert_finite(getattr(value, f.name), f"{where}.{f.name}", depth + 1)


def call(name: str, fn: Callable, kwargs: dict[str, Any]) -> None:
    """Call ``fn(**kwargs)`` under the alarm: a library error of one line, or a finite
    result."""
    args, kwargs = _positional(name, kwargs)
    previous = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, CALL_LIMIT)
    start = time.perf_counter()
    try:
        result = fn(*args, **kwargs)
    except RffqmError as exc:
        message = str(exc)
        assert message.strip() and "\n" not in message, (name, message)
        return
    except Hang:
        pytest.fail(f"{name} hung (more than {CALL_LIMIT} s) on {describe(kwargs)}")
    except Exception as exc:            # anything but a library error fails the test
        pytest.fail(f"{name} raised {type(exc).__name__}: {exc} on {describe(kwargs)}")
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
    assert time.perf_counter() - start < CALL_LIMIT
    if name not in UNCHECKED_RESULTS:
        assert_finite(result, f"{name}(...)")


def _positional(name: str, kwargs: dict[str, Any]) -> tuple[tuple, dict[str, Any]]:
    """(args, kwargs) of a call: is_casadi and math_for (mathlib) take their argument
    positionally."""
    if name in ("backend.is_casadi", "backend.math_for", "surfaces.mathlib"):
        return (kwargs["args"],), {}
    return (), kwargs


def describe(kwargs: dict[str, Any]) -> str:
    """The arguments of a failing call, short."""
    def short(v: Any) -> str:
        if isinstance(v, np.ndarray):
            return f"array{v.shape} {v.dtype}: {np.array2string(v.ravel()[:6])}"
        text = repr(v)
        return text if len(text) < 80 else text[:77] + "..."
    return ", ".join(f"{k}={short(v)}" for k, v in kwargs.items())


# --------------------------------------------------------------------------- the tests
@pytest.mark.parametrize("name", sorted(CALLS))
def test_valid_calls_return_finite_results(name):
    """The valid arguments of the table are valid: each call succeeds, with finite numbers
    (so a refusal in the fuzz below comes from the replaced arguments)."""
    fn, kwargs = CALLS[name]
    args, kwargs = _positional(name, kwargs)
    result = fn(*args, **kwargs)
    if name not in UNCHECKED_RESULTS:
        assert_finite(result, name)


@pytest.mark.parametrize("name", sorted(NO_ARGUMENTS))
def test_calls_without_arguments_return_finite_results(name):
    assert_finite(NO_ARGUMENTS[name]())


def _fuzz(name: str):
    fn, valid = CALLS[name]

    @settings(max_examples=FEWER.get(name, EXAMPLES), derandomize=True, deadline=None,
              database=None,
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                     HealthCheck.filter_too_much])
    @given(data=st.data())
    def run(data):
        keys = data.draw(st.lists(st.sampled_from(sorted(valid)), min_size=1,
                                  max_size=len(valid), unique=True), label="replaced")
        kwargs = dict(valid)
        for key in keys:
            kwargs[key] = data.draw(bad_values(), label=key)
        call(name, fn, kwargs)

    return run


@pytest.mark.parametrize("name", sorted(CALLS))
def test_bad_calls_raise_library_errors_or_return_finite_results(name):
    """Hypothesis replaces one or several arguments of the call by bad values (a fixed
    sequence of examples): only RffqmError, in one line, or a finite result, and no hang."""
    _fuzz(name)()


def _public(module) -> set[str]:
    """The public functions and classes of ``module`` (``<module>.<name>``): those its
    ``__all__`` lists (a public face that gathers its folder's pieces), else those defined
    in it."""
    short = module.__name__.rsplit(".", 1)[1]
    names = getattr(module, "__all__", None)
    if names is None:
        names = [name for name, obj in vars(module).items()
                 if getattr(obj, "__module__", None) == module.__name__]
    return {f"{short}.{name}" for name in names if not name.startswith("_")
            and (inspect.isfunction(getattr(module, name))
                 or inspect.isclass(getattr(module, name)))}


def test_every_public_callable_is_fuzzed():
    """A public function or class added to these modules must join CALLS (or be a result
    record that only stores its fields, or take no arguments)."""
    public = set().union(*(_public(m) for m in MODULES))
    fuzzed = {name for name in CALLS if name.count(".") == 1} | set(NO_ARGUMENTS) | RECORDS
    assert public - fuzzed == set()
    assert len(CALLS) >= 100


def test_the_fuzz_covers_the_issue_examples():
    """The calls the audit found failing are among the fuzzed ones, and each is refused by
    a library error that names the argument (deterministic, besides the fuzz)."""
    bad_pattern = rq.Pattern(PAT.alpha, np.where(np.arange(3)[:, None] == 0, PAT.alpha,
                                                 PAT.beta),
                             np.ones_like(PAT.sigma), PAT.lh, PAT.lv, PAT.mu, PAT.X)
    cases = [
        (lambda: rq.miura_boundary(2, math.nan), rq.InputError, "M must be a whole number"),
        (lambda: rq.perturb_angles(BD, 0.1, seed=-1), rq.InputError,
         "seed must be a whole number in [0, "),
        (lambda: rq.collisions(PAT, [1.0, 2.0]), rq.InputError,
         "omega_max must be a single number"),
        (lambda: surfaces.get(["sphere_cap"]), rq.SurfaceError,
         "name must be the name of a built-in surface"),
        (lambda: numpy_model.march(PAT), rq.InputError, "bd must be boundary data"),
        (lambda: rq.Pattern(PAT.alpha, PAT.beta, PAT.sigma, PAT.lh * math.nan, PAT.lv,
                            PAT.mu, PAT.X), rq.InputError, "Pattern lh must be"),
        (lambda: numpy_model.fold(bad_pattern, 1.0), rq.InputError,
         "no finite folded state"),
        (lambda: rq.fold(bad_pattern, 1.0), rq.InputError, "no finite folded state"),
    ]
    for make, kind, words in cases:
        with pytest.raises(kind) as exc:
            make()
        assert words in str(exc.value) and "\n" not in str(exc.value)


def test_the_fuzz_fails_on_a_raw_exception_a_nan_or_a_hang(monkeypatch):
    """The checker is not blind: a raw exception, a NaN result and a hang each fail."""
    with pytest.raises(pytest.fail.Exception, match="raised ValueError"):
        call("x", lambda v: float("not a number") if v else 0.0, {"v": 1})
    with pytest.raises(AssertionError, match="NaN or infinity"):
        call("x", lambda v: np.array([v]), {"v": math.nan})
    with pytest.raises(AssertionError):
        call("x", lambda v: (1.0, {"a": v}), {"v": math.inf})
    monkeypatch.setattr(sys.modules[__name__], "CALL_LIMIT", 0.2)
    with pytest.raises(pytest.fail.Exception, match="hung"):
        call("x", lambda v: time.sleep(v), {"v": 2.0})
    call("x", lambda v: rq.miura_boundary(2, v), {"v": math.nan})     # refused: passes


def test_a_surface_subclass_must_give_r():
    """Surface itself has no r(u, v): constructing it is a SurfaceError saying so."""
    with pytest.raises(rq.SurfaceError, match="subclass"):
        surfaces.Surface("mine", {}, ((0, 1), (0, 1)))
