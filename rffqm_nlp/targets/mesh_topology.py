"""The topology a :class:`~rffqm_nlp.targets.meshes.Mesh` needs: one manifold patch of disk
topology with consistent winding (:func:`check_disk`), and its boundary loop."""

from __future__ import annotations

import numpy as np
import trimesh
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from ..errors import SurfaceError
from .mesh_input import trimesh_step


def check_disk(mesh: trimesh.Trimesh, what: str) -> None:
    """Raise SurfaceError unless the mesh is one manifold patch of disk topology; fix its
    winding when it is one."""
    with trimesh_step(what, "finding its edges"):
        keys, counts = np.unique(_edge_keys(mesh), return_counts=True)
        adjacency = mesh.face_adjacency
    edges = np.c_[keys // len(mesh.vertices), keys % len(mesh.vertices)]
    if (counts > 2).any():
        raise SurfaceError(f"{what} has {int((counts > 2).sum())} non-manifold edges (shared by "
                           f"more than two triangles); repair the mesh or crop it to one sheet")
    n_comp, _ = connected_components(
        sparse.coo_matrix((np.ones(len(adjacency)), adjacency.T),
                          shape=(len(mesh.faces),) * 2), directed=False)
    if n_comp > 1:
        raise SurfaceError(f"{what} has {n_comp} separate pieces (connected components); "
                           f"keep one, e.g. crop it or delete the others")
    boundary = edges[counts == 1]
    if len(boundary) == 0:
        raise SurfaceError(f"{what} is a closed surface (no boundary); cut it open or crop it "
                           f"to one patch that is a deformed disk")
    degree = np.bincount(boundary.ravel(), minlength=len(mesh.vertices))
    if (degree > 2).any():
        raise SurfaceError(f"{what} has {int((degree > 2).sum())} non-manifold vertices (two "
                           f"boundary loops touch); repair the mesh or crop it")
    n_vertices = len(mesh.vertices)
    n_loops = connected_components(
        sparse.coo_matrix((np.ones(len(boundary)), boundary.T), shape=(n_vertices,) * 2),
        directed=False)[0] - int((degree == 0).sum())
    if n_loops > 1:
        raise SurfaceError(f"{what} has {n_loops} boundary loops, i.e. {n_loops - 1} hole(s); "
                           f"fill the holes or crop it to a patch without holes")
    euler = n_vertices - len(edges) + len(mesh.faces)
    if euler != 1:
        raise SurfaceError(f"{what} has one boundary loop but Euler characteristic {euler} (a "
                           f"disk has 1): it has handles or is not orientable; crop it to a "
                           f"patch that is a deformed disk")
    with trimesh_step(what, "making its triangles' winding consistent"):
        if not mesh.is_winding_consistent:  # a disk is orientable: one flip per bad face
            trimesh.repair.fix_winding(mesh)
        consistent = mesh.is_winding_consistent
    if not consistent:
        raise SurfaceError(f"the triangles of {what} could not be oriented consistently; "
                           f"repair the mesh (e.g. in MeshLab or Blender) or export it again")


def _edge_keys(mesh: trimesh.Trimesh) -> np.ndarray:
    """One int64 per edge of every face (3 m,), the same for both directions: a n + b for
    the edge between vertices a < b of the n (a sort of rows, 10 x faster)."""
    edges = np.sort(mesh.edges, axis=1).astype(np.int64)
    return edges[:, 0] * len(mesh.vertices) + edges[:, 1]


def boundary_loop(mesh: trimesh.Trimesh) -> np.ndarray:
    """Vertex indices (b,) of the single boundary loop, in the faces' winding direction."""
    directed = mesh.edges
    _, inverse, counts = np.unique(_edge_keys(mesh), return_inverse=True, return_counts=True)
    succ = dict(directed[counts[inverse.ravel()] == 1].tolist())
    start = next(iter(succ))
    loop = [start]
    while (nxt := succ[loop[-1]]) != start:
        loop.append(nxt)
    return np.asarray(loop)
