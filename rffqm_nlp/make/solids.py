"""Thick panels as printable solids: one closed solid per panel, at the designed state and
in the flat layout, in millimetres.

Each panel is the tapered panel of :class:`rffqm_nlp.contact.thick.ThickPanels` (its
zero-thickness quadrilateral one face, the material on one side, bevels where a crease
closes on that side, meeting at the designed state): its quadrilateral, shrunk by half
the hinge gap on every side (shapely), extruded by the thickness and trimmed by the
bevel planes (manifold3d, whose solids are closed and oriented by construction), in the
panel's flat frame; then moved rigidly with its panel (y = R x + T,
:func:`rffqm_nlp.contact.thick.panel_frames`). The hinge axes stay on the zero-thickness
creases, so the panels fold with the zero-thickness kinematics.

Files: ``panels.stl`` (every panel at the designed state, the pattern's frame: panel
(1, 1) fixed), ``panels_flat.stl`` (the flat layout, in the sheet's coordinates of the cut
files, the material below z = 0 for the back side, above for the front) and
``panels.glb`` (the designed state, one named mesh "panel_i_j" per panel).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..contact.thick import ThickPanels, panel_frames
from ..errors import InputError
from ..files import atomic_path
from ..model.numpy_model import fold
from ..model.pattern import Pattern


@dataclass(frozen=True)
class Solids:
    """The panels' solids in their flat frames (mm): ``vertices`` and ``faces`` per panel
    (row-major, panel (i, j) at (i-1) M + (j-1)), their ``volumes`` (P,) (mm^3) and the
    ``areas`` (P,) of the zero-thickness panels (mm^2); ``thickness`` (mm), ``side``."""

    vertices: list[np.ndarray]
    faces: list[np.ndarray]
    volumes: np.ndarray
    areas: np.ndarray
    thickness: float
    side: int

    @property
    def volume_ratios(self) -> np.ndarray:
        """Each solid's volume over its panel's area times the thickness (P,)."""
        return self.volumes / (self.areas * self.thickness)


def _quad(X: np.ndarray, i: int, j: int) -> np.ndarray:
    """Corners a, c, d, b (4, 2) of panel (i+1, j+1), counter-clockwise."""
    return np.array([X[i, j], X[i, j + 1], X[i + 1, j + 1], X[i + 1, j]])


def build_solids(pat: Pattern, omega: float, scale: float, thickness: float,
                 side: str = "auto", hinge_gap: float = 0.0) -> Solids:
    """The tapered solids of ``pat`` (mm: ``scale`` mm per unit, ``thickness`` and
    ``hinge_gap`` in mm) bevelled for ``omega``; :class:`InputError` where a panel is
    too small for the hinge gap or loses its whole volume to the bevels."""
    import manifold3d as mf
    from shapely.geometry import Polygon

    panels = ThickPanels.build(pat, omega, thickness / scale, side)
    X = pat.X[..., :2] * scale
    vertices, faces, volumes, areas = [], [], [], []
    for i in range(pat.N):
        for j in range(pat.M):
            quad = _quad(X, i, j)
            polygon = Polygon(quad)
            areas.append(polygon.area)
            if hinge_gap > 0:
                polygon = polygon.buffer(-hinge_gap / 2, join_style="mitre")
                if polygon.is_empty or polygon.geom_type != "Polygon":
                    raise InputError(f"panel ({i + 1}, {j + 1}) is too small for a hinge "
                                     f"gap of {hinge_gap:g} mm")
            ring = np.asarray(polygon.exterior.coords)[:-1]
            solid = mf.Manifold.extrude(mf.CrossSection([ring]), thickness)
            if panels.side < 0:
                solid = solid.translate((0.0, 0.0, -thickness))
            for k in np.flatnonzero(panels.bevelled[i, j]):
                solid = solid.trim_by_plane(tuple(panels.normals[i, j, 6 + k]),
                                            float(panels.offsets[i, j, 6 + k] * scale))
            if solid.is_empty():
                raise InputError(f"panel ({i + 1}, {j + 1}) is bevelled away: a thickness "
                                 f"of {thickness:g} mm is too much for its fold angles")
            v, f = indexed(solid)
            vertices.append(v)
            faces.append(f)
            volumes.append(solid.volume())
    return Solids(vertices, faces, np.array(volumes), np.array(areas), float(thickness),
                  panels.side)


def indexed(solid) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and triangles (F, 3) of a manifold3d solid, as manifold3d indexes
    them: closed and consistently oriented over that indexing (where a bevel passes
    through a panel's corner, two of its vertices may lie within round-off of each other;
    they stay two vertices, so that no triangle degenerates)."""
    mesh = solid.to_mesh()
    return (np.asarray(mesh.vert_properties, dtype=float)[:, :3],
            np.asarray(mesh.tri_verts, dtype=np.int64))


def placed(solids: Solids, pat: Pattern, omega: float, scale: float,
           shift: np.ndarray | None = None) -> list[np.ndarray]:
    """Every solid's vertices moved with its panel to the state ``omega`` (mm), then by
    ``shift`` (3,) when given."""
    R, T = panel_frames(pat, fold(pat, omega))
    R, T = R.reshape(-1, 3, 3), T.reshape(-1, 3) * scale
    out = [v @ R[p].T + T[p] for p, v in enumerate(solids.vertices)]
    return out if shift is None else [v + shift for v in out]


def meshes(vertices: list[np.ndarray], faces: list[np.ndarray]) -> list:
    """One ``trimesh.Trimesh`` per solid (vertices as given, not merged)."""
    import trimesh

    return [trimesh.Trimesh(vertices=v, faces=f, process=False)
            for v, f in zip(vertices, faces)]


def write_stl(path: Path, parts: list) -> Path:
    """The meshes ``parts`` as one binary STL, atomically."""
    import trimesh

    with atomic_path(path) as tmp:
        trimesh.util.concatenate(parts).export(tmp, file_type="stl")
    return path


def write_glb(path: Path, parts: list, names: list[str]) -> Path:
    """The meshes ``parts`` as a binary glTF scene, one named node each, atomically."""
    import trimesh

    scene = trimesh.Scene()
    for mesh, name in zip(parts, names):
        scene.add_geometry(mesh, geom_name=name, node_name=name)
    with atomic_path(path) as tmp:
        scene.export(tmp, file_type="glb")
    return path


def write_panels(folder: Path, solids: Solids, pat: Pattern, omega: float, scale: float,
                 origin: np.ndarray) -> list[Path]:
    """panels.stl, panels_flat.stl and panels.glb into ``folder`` (see the module);
    ``origin`` (2,) the flat pattern's lowest corner (pattern units), the flat layout's
    shift to the cut files' coordinates."""
    designed = meshes(placed(solids, pat, omega, scale), solids.faces)
    shift = np.array([-origin[0] * scale, -origin[1] * scale, 0.0])
    flat = meshes([v + shift for v in solids.vertices], solids.faces)
    names = [f"panel_{i}_{j}" for i in range(1, pat.N + 1) for j in range(1, pat.M + 1)]
    return [write_stl(folder / "panels.stl", designed),
            write_stl(folder / "panels_flat.stl", flat),
            write_glb(folder / "panels.glb", designed, names)]
