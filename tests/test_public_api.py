"""Every name the README and the docs show users still works (the public API is stable
while the package's insides move)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import rffqm_nlp as rq

ROOT = Path(__file__).resolve().parents[1]

#: Names users reach through ``rq.``: the top level and the documented modules' names.
PUBLIC = [
    # the top level
    "BoundaryData", "BoundaryDataError", "CollisionReport", "DesignProblem", "DesignResult",
    "Fit", "InfeasibleDesign", "InputError", "MarchingError", "Pattern", "RffqmError",
    "SolveOptions", "SolveStats", "SolverFailed", "SurfaceError", "collisions", "fold",
    "load_design", "march", "miura_boundary", "perturb_angles", "sweep", "__version__",
    "DesignResult.load", "DesignResult.save", "DesignResult.view", "DesignProblem.solve",
    "SolveOptions.from_config", "SolveOptions.to_config",
    # targets
    "surfaces.get", "surfaces.names", "surfaces.Custom", "surfaces.Surface", "surfaces.Mesh",
    "surfaces.from_config", "surfaces.grid_faces", "meshes.is_mesh_file", "meshes.FORMATS",
    "surfaces.Curvature",
    # the forward models and side lengths
    "numpy_model.march", "numpy_model.fold", "marching.march", "marching.fold",
    "lengths.side_length_lp", "lengths.side_length_nlp",
    # files
    "foldfile.write_fold", "foldfile.read_fold", "export.write_svg", "export.write_pdf",
    "export.write_dxf", "export.write_mesh",
    # shape measures
    "shape.relative_fit", "shape.shape_fit", "shape.distances_to", "shape.surface_area",
    "shape.lattice_area",
    # design, results, sweeps
    "design.from_config", "results.Fit", "sweeps.run", "sweeps.Study", "sweeps.FIT_COLUMNS",
    "sweeps.STATE_COLUMNS",
    "sweeps.MAX_DESIGNS", "sweeps.csv_frame",
    "ipopt_options.OPTIONS", "ipopt_options.check_ipopt_options",
    # making a design (rq.make is the package, called as its function)
    "make", "make.make", "make.lock_ties", "make.perforation", "make.MAKE_KEYS",
    # mechanics
    "mechanics.Material", "mechanics.Material.named", "mechanics.MATERIALS",
    "mechanics.BarAndHinge", "mechanics.BarAndHinge.rigidity_matrix",
    "mechanics.BarAndHinge.stiffness", "mechanics.BarAndHinge.modes",
    "mechanics.BarAndHinge.solve", "mechanics.BarAndHinge.point_stiffness",
    "mechanics.Ties", "mechanics.folding_velocity", "mechanics.poisson_ratio",
    "mechanics.poisson_map",
]


def resolve(dotted: str):
    obj = rq
    for part in dotted.split("."):
        obj = getattr(obj, part)
    return obj


@pytest.mark.parametrize("name", PUBLIC)
def test_public_name_resolves(name):
    assert resolve(name) is not None


def test_every_name_the_readme_and_the_docs_show_is_listed():
    """A name the README or a page of docs/ (not the dated decisions log, which keeps the
    names of its time) writes as ``rq.X`` or ``rq.module.X`` is in :data:`PUBLIC`."""
    pages = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    shown = {name for page in pages
             for name in re.findall(r"\brq\.([A-Za-z_][\w.]*[A-Za-z_0-9])", page.read_text())}
    missing = sorted(name for name in shown if name not in PUBLIC
                     and not any(p.startswith(name + ".") for p in PUBLIC))
    assert missing == []


def test_all_lists_only_names_that_resolve():
    for name in rq.__all__:
        assert getattr(rq, name) is not None
