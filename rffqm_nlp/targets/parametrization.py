"""Parameters (u, v) for the points of a :class:`~rffqm_nlp.targets.meshes.Mesh` (step 2 of
:mod:`.meshes`): the conformal map onto a rectangle, the projection onto the best-fit plane,
the least-squares conformal map (LSCM) and Tutte's embedding, their injectivity check, and
the rotation that aligns the parameter image with the axes."""

from __future__ import annotations

import math

import numpy as np
import trimesh
from scipy import sparse
from scipy.sparse.linalg import splu, spsolve
from scipy.spatial import ConvexHull

from ..errors import SurfaceError
from .mesh_domain import cloud_faces
from .mesh_topology import boundary_loop, check_disk

#: Largest angle between a face normal and the best-fit plane's normal for a projection.
GRAPH_ANGLE = math.radians(80.0)
#: Largest area fraction of a mesh's faces that may be steep or flipped in a projection or
#: a conformal map (slivers that CAD exports and Delaunay triangulations carry).
SLIVER_AREA = 1e-4
#: The same for a point cloud's triangulation (:func:`cloud_rectangle`), which is Delaunay
#: in the plane, not on the surface: a flipped triangle there only orders two neighbouring
#: points' parameters the wrong way, which the spline fitted to them smooths over (a
#: 6,000-point cloud of the hyperboloid flipped one of 0.04% of the area).
CLOUD_SLIVER_AREA = 1e-3
#: Largest angle (radians) between a boundary vertex's chords to its neighbours
#: :data:`CORNER_WINDOW` away for a corner of the patch (a rectangle's corner: pi / 2, a
#: straight side: pi, a circle: pi - 2 pi CORNER_WINDOW).
CORNER_ANGLE = math.radians(155.0)
#: The chords' reach, as a share of the boundary's vertices (:func:`corners`; a side of
#: fewer than about two reaches merges its corners, and the map falls back).
CORNER_WINDOW = 0.02
#: The reach on a point cloud's triangulated boundary, ragged over a few vertices: a
#: 20,000-point cloud of the sphere cap (217 boundary vertices) showed a bump of 139 deg
#: beside corners of 107-126 deg at 2%, none at 4%.
CLOUD_CORNER_WINDOW = 0.04
#: The chords' least reach in vertices, on a boundary of at least 16 times as many: a
#: ragged boundary (a point cloud's triangulation, a scan) zigzags over a vertex or two,
#: which a reach of 2% of a loop of 122 vertices (a 6,000-point cloud) took for corners.
CORNER_REACH = 4
#: Where the boundary has more than four corners, the four sharpest are taken when the
#: fifth is blunter than the fourth by at least this angle (radians): a ragged side's
#: bumps (144-154 deg on a 6,000-point cloud of the saddle) against its corners (about 105).
CORNER_GAP = math.radians(20.0)
#: Largest ratio of the 99th to the 1st percentile (by area) of the conformal rectangle's
#: area scale (parameter area over mesh area per face): a flat parallelogram with 75 deg
#: corners gives 3.3, with 60 deg 12; the bundled targets' meshes 1.4-2.8.
MAX_AREA_SPREAD = 10.0
#: Relative tolerance under which two candidates of :func:`align` (areas, sides) and of
#: :func:`~.splines.knot_spans` (a count on a half) tie: a tie is broken by a fixed rule rather than
#: by round-off, so the same shape at another size or position gives the same Mesh.
TIE = 1e-9


def _plane_axes(points: np.ndarray) -> np.ndarray:
    """Principal axes (3, 3) of the points: rows e1, e2 (in-plane, decreasing extent) and
    the normal e3 = e1 x e2."""
    centred = points - points.mean(axis=0)
    axes = np.linalg.svd(centred, full_matrices=False)[2]
    return np.stack([axes[0], axes[1], np.cross(axes[0], axes[1])])


def project(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(in-plane coordinates (n, 2) along the principal axes, the plane's normal (3,))."""
    axes = _plane_axes(points)
    return (points - points.mean(axis=0)) @ axes[:2].T, axes[2]


def parametrize(mesh: trimesh.Trimesh) -> tuple[np.ndarray, str]:
    """(uv (n, 2), method) for a disk-topology mesh with consistent winding: the conformal
    map onto a rectangle if the patch has four corners, else the projection onto the
    best-fit plane if the mesh is a graph over it, else LSCM, else Tutte's map
    (:mod:`.meshes`, step 2). Orientation: r_u x r_v agrees with the faces' normals."""
    rectangle = conformal_rectangle(mesh)
    if rectangle is not None:
        return align(rectangle), "rectangle"
    pts = np.asarray(mesh.vertices, dtype=float)
    axes = _plane_axes(pts)
    normals = mesh.face_normals
    if normals @ axes[2] @ mesh.area_faces < 0:
        axes = axes * np.array([[1.0], [-1.0], [-1.0]])
    uv = (pts - pts.mean(axis=0)) @ axes[:2].T
    steep = (normals @ axes[2]) < math.cos(GRAPH_ANGLE)
    if injective(mesh, uv, steep):
        return align(uv), "projection"
    uv = lscm(mesh)
    method = "lscm"
    if not injective(mesh, uv, np.zeros(len(mesh.faces), dtype=bool)):
        uv, method = tutte(mesh), "tutte"
    uv = align(uv)
    return uv * math.sqrt(mesh.area / signed_areas(mesh.faces, uv).sum()), method


def corners(points: np.ndarray, normals: np.ndarray, loop: np.ndarray,
            window: float = CORNER_WINDOW) -> np.ndarray | None:
    """Positions in the boundary ``loop`` (b,) of the patch's four corners, increasing, or
    None unless there are exactly four. At every boundary vertex p_k (of ``points`` (n, 3),
    with unit ``normals`` (n, 3); the loop counter-clockwise about them), the angle between
    the chords to p_{k-w} and p_{k+w} (w = ``window`` of the loop, at least one
    vertex, so a noisy boundary's zigzag averages out); the runs of vertices where the
    boundary turns left (a convex corner) and that angle is at most CORNER_ANGLE are the
    corners, each at its smallest angle. The reach w is at least :data:`CORNER_REACH`
    vertices where the loop has at least 16 times as many. Of more than four such runs the
    four sharpest are the corners when the fifth is blunter by :data:`CORNER_GAP`."""
    b = len(loop)
    w = max(1, round(window * b), min(CORNER_REACH, b // 16))
    p = points[loop]
    back, ahead = np.roll(p, w, axis=0) - p, np.roll(p, -w, axis=0) - p
    cos = np.einsum("kd,kd->k", back, ahead) / (np.linalg.norm(back, axis=1)
                                                * np.linalg.norm(ahead, axis=1))
    angle = np.arccos(np.clip(cos, -1.0, 1.0))
    left = np.einsum("kd,kd->k", np.cross(-back, ahead), normals[loop]) > 0
    sharp = (angle <= CORNER_ANGLE) & left
    if sharp.all() or not sharp.any():
        return None
    start = int(np.flatnonzero(~sharp)[0])  # runs, the loop rolled to start outside one
    order = (start + np.arange(b)) % b
    runs = np.split(order, np.flatnonzero(np.diff(sharp[order].astype(int)) != 0) + 1)
    found = sorted((float(angle[run].min()), int(run[np.argmin(angle[run])]))
                   for run in runs if sharp[run[0]])
    if len(found) < 4 or (len(found) > 4 and found[4][0] - found[3][0] < CORNER_GAP):
        return None
    return np.sort([k for _, k in found[:4]])


def _cotangent_laplacian(mesh: trimesh.Trimesh) -> sparse.csr_matrix:
    """L (n, n) with u' L u the Dirichlet energy of the piecewise linear u: the weight of
    an edge is half the sum of the cotangents of the angles opposite it."""
    n, f = len(mesh.vertices), mesh.faces
    half_cot = 0.5 / np.tan(mesh.face_angles)  # at vertex k of a face: opposite its edge
    i = np.r_[f[:, 1], f[:, 2], f[:, 0]]
    j = np.r_[f[:, 2], f[:, 0], f[:, 1]]
    w = half_cot.T.ravel()
    weights = sparse.coo_matrix((np.r_[w, w], (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsr()
    return (sparse.diags(np.asarray(weights.sum(axis=1)).ravel()) - weights).tocsr()


def solve_spd(a: sparse.spmatrix, b: np.ndarray) -> np.ndarray:
    """x with a x = b, a sparse symmetric positive definite (a Laplacian restricted to the
    free vertices, normal equations): SuperLU with a minimum degree ordering of a + a' and
    diagonal pivots, as a Cholesky factorization would (faster than spsolve's defaults:
    docs/meshes.md); spsolve's partial pivoting where that fails."""
    a = sparse.csc_matrix(a)
    b = np.asarray(b, dtype=float)
    try:
        x = splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                 options={"SymmetricMode": True}).solve(b)
    except RuntimeError:  # a zero pivot
        x = None
    if x is None or not np.all(np.isfinite(x)):
        x = spsolve(a, b)
    return np.asarray(x).reshape(b.shape)


def _harmonic(lap: sparse.csr_matrix, zero: np.ndarray, one: np.ndarray
              ) -> tuple[np.ndarray, float]:
    """(x (n,), its Dirichlet energy x' L x): L x = 0 but on the vertices ``zero`` (x = 0)
    and ``one`` (x = 1); the other boundary vertices get no flux (the natural condition)."""
    x = np.zeros(lap.shape[0])
    known = np.zeros(lap.shape[0], dtype=bool)
    known[zero] = known[one] = True
    x[one] = 1.0
    free = ~known
    x[free] = solve_spd(lap[free][:, free], -(lap[free][:, known] @ x[known]))
    return x, float(x @ (lap @ x))


def conformal_rectangle(mesh: trimesh.Trimesh, sliver: float = SLIVER_AREA,
                        window: float = CORNER_WINDOW) -> np.ndarray | None:
    """The conformal map (n, 2) of a patch with four :func:`corners` onto a rectangle of the
    mesh's area (:mod:`.meshes`, step 2), the sides in the boundary's order: bottom, right, top,
    left; None without four corners (:func:`corners` with ``window``), where triangles
    covering more than ``sliver`` of the area flip (:func:`injective`) or where the map stretches areas by more than
    MAX_AREA_SPREAD."""
    loop = boundary_loop(mesh)
    at = corners(np.asarray(mesh.vertices), np.asarray(mesh.vertex_normals), loop, window)
    if at is None:
        return None
    ends = np.r_[at, at[0] + len(loop)]
    sides = [loop[np.arange(a, b + 1) % len(loop)] for a, b in zip(ends[:-1], ends[1:])]
    lap = _cotangent_laplacian(mesh)
    u, energy_u = _harmonic(lap, sides[3], sides[1])
    v, energy_v = _harmonic(lap, sides[0], sides[2])
    if not (energy_u > 0 and energy_v > 0):
        return None
    aspect = math.sqrt(energy_u / energy_v)  # height over width
    uv = np.c_[u / math.sqrt(aspect), v * math.sqrt(aspect)] * math.sqrt(mesh.area)
    if not injective(mesh, uv, np.zeros(len(mesh.faces), dtype=bool), sliver):
        return None
    return uv if _area_spread(mesh, uv) <= MAX_AREA_SPREAD else None


def _area_spread(mesh: trimesh.Trimesh, uv: np.ndarray) -> float:
    """The ratio of the 99th to the 1st percentile, weighted by the faces' areas, of the
    map's area scale (the faces' parameter area over their area)."""
    scale = signed_areas(mesh.faces, uv) / np.maximum(mesh.area_faces, 1e-300)
    order = np.argsort(scale)
    share = np.cumsum(mesh.area_faces[order]) / mesh.area
    low, high = scale[order][np.searchsorted(share, [0.01, 0.99]).clip(0, len(scale) - 1)]
    return float(high / low) if low > 0 else math.inf


def signed_areas(faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Signed areas (m,) of the triangles ``faces`` (m, 3) in the plane of uv (n, 2):
    positive where a triangle runs counter-clockwise."""
    a, b, c = uv[faces[:, 0]], uv[faces[:, 1]], uv[faces[:, 2]]
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                  - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def injective(mesh: trimesh.Trimesh, uv: np.ndarray, bad: np.ndarray,
              sliver: float = SLIVER_AREA) -> bool:
    """Whether the map uv (n, 2) of the disk is injective up to slivers: the faces that are
    ``bad`` (m,) or not positively oriented in the plane cover at most ``sliver`` of the
    mesh's area, and the boundary is a simple polygon."""
    bad = bad | (signed_areas(mesh.faces, uv) <= 0)
    if mesh.area_faces[bad].sum() > sliver * mesh.area:
        return False
    return not _self_intersecting(uv[boundary_loop(mesh)])


def _self_intersecting(polygon: np.ndarray) -> bool:
    """Whether two non-adjacent edges of the closed polygon (b, 2) cross."""
    a, b = polygon, np.roll(polygon, -1, axis=0)
    n = len(a)
    idx = np.arange(n)

    def orient(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))

    block = max(1, 2_000_000 // n)
    for k in range(0, n, block):
        i = idx[k:k + block, None]
        p, q = a[k:k + block, None], b[k:k + block, None]
        r, s = a[None], b[None]
        cross = ((orient(p, q, r) * orient(p, q, s) < 0)
                 & (orient(r, s, p) * orient(r, s, q) < 0))
        gap = (idx[None] - i) % n
        if (cross & (gap > 1) & (gap < n - 1)).any():
            return True
    return False


def local_gradients(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray]:
    """Per face, the gradients (m, 3, 2) of the three barycentric coordinates in a local
    orthonormal frame of the face (counter-clockwise about its normal) and the areas (m,)."""
    tri = mesh.triangles
    e1 = tri[:, 1] - tri[:, 0]
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(mesh.face_normals, e1)
    rel = tri - tri[:, :1]
    q = np.stack([np.einsum("mkd,md->mk", rel, e1), np.einsum("mkd,md->mk", rel, e2)], -1)
    area = mesh.area_faces
    opposite = np.roll(q, 1, axis=1) - np.roll(q, -1, axis=1)  # q_{j+2} - q_{j+1}
    grad = np.stack([-opposite[..., 1], opposite[..., 0]], -1) / (2 * area[:, None, None])
    return grad, area


def lscm(mesh: trimesh.Trimesh) -> np.ndarray:
    """Least-squares conformal map (n, 2): Cauchy-Riemann residuals u_x - v_y, u_y + v_x per
    face weighted by sqrt(area), the two farthest-apart boundary vertices pinned."""
    n = len(mesh.vertices)
    grad, area = local_gradients(mesh)
    w = np.sqrt(area)[:, None] * np.ones((1, 3))
    faces = mesh.faces
    m = len(faces)
    rows = np.repeat(np.arange(2 * m), 6).reshape(2 * m, 6)
    cols = np.concatenate([np.c_[faces, faces + n], np.c_[faces, faces + n]])
    vals = np.concatenate([np.c_[w * grad[..., 0], -w * grad[..., 1]],
                           np.c_[w * grad[..., 1], w * grad[..., 0]]])
    a = sparse.csr_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * m, 2 * n))
    loop = boundary_loop(mesh)
    pts = mesh.vertices[loop]
    i = int(np.argmax(np.linalg.norm(pts - pts[0], axis=1)))
    j = int(np.argmax(np.linalg.norm(pts - pts[i], axis=1)))
    pinned = np.array([loop[i], loop[j]])
    length = float(np.linalg.norm(pts[i] - pts[j]))
    fixed = np.zeros(2 * n)
    fixed[pinned[1]] = length
    known = np.zeros(2 * n, dtype=bool)
    known[np.r_[pinned, pinned + n]] = True
    free = ~known
    af = a[:, free]
    x = fixed.copy()
    x[free] = solve_spd(af.T @ af, -(af.T @ (a[:, known] @ fixed[known])))
    return np.c_[x[:n], x[n:]]


def tutte(mesh: trimesh.Trimesh) -> np.ndarray:
    """Tutte's embedding (n, 2): boundary on the unit circle by arc length, every interior
    vertex the average of its neighbours (injective for a disk)."""
    n = len(mesh.vertices)
    loop = boundary_loop(mesh)
    seg = np.linalg.norm(np.diff(mesh.vertices[np.r_[loop, loop[:1]]], axis=0), axis=1)
    angle = 2 * np.pi * np.r_[0.0, np.cumsum(seg)[:-1]] / seg.sum()
    uv = np.zeros((n, 2))
    uv[loop] = np.c_[np.cos(angle), np.sin(angle)]
    edges = mesh.edges_unique
    adj = sparse.coo_matrix((np.ones(2 * len(edges)), (edges.ravel(), edges[:, ::-1].ravel())),
                            shape=(n, n)).tocsr()
    lap = sparse.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    interior = np.ones(n, dtype=bool)
    interior[loop] = False
    rhs = -(lap[interior][:, loop] @ uv[loop])
    uv[interior] = solve_spd(lap[interior][:, interior], rhs).reshape(-1, 2)
    return uv


def align(uv: np.ndarray) -> np.ndarray:
    """uv (n, 2) rotated (orientation kept) so that its smallest-area bounding rectangle is
    axis-aligned, u along the rectangle's longer side, and centred at the origin. Rectangles
    whose areas tie (within :data:`TIE`; a conformal rectangle's four sides) take the
    smallest rotation, and a square keeps its u."""
    corners = uv[ConvexHull(uv).vertices]
    edges = np.diff(np.r_[corners, corners[:1]], axis=0)
    angles = np.arctan2(edges[:, 1], edges[:, 0])
    rotations = [np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]]) for a in angles]
    extents = np.array([np.ptp(corners @ rot.T, axis=0) for rot in rotations])
    areas = extents.prod(axis=1)
    tied = np.flatnonzero(areas <= areas.min() * (1 + TIE))
    best = min(tied, key=lambda k: (round(abs(float(angles[k])), 9), -float(angles[k])))
    rot, ext = rotations[best], extents[best]
    if ext[1] > ext[0] * (1 + TIE):
        rot = np.array([[0.0, 1.0], [-1.0, 0.0]]) @ rot
    out = uv @ rot.T
    return out - 0.5 * (out.min(axis=0) + out.max(axis=0))


def cloud_rectangle(points: np.ndarray, uv: np.ndarray) -> np.ndarray | None:
    """The :func:`conformal_rectangle` (n, 2) of a cloud's points (n, 3) (on its smoothed
    surface) triangulated by :func:`cloud_faces` of their projections uv (n, 2), if that
    mesh is one disk with four corners that uses every point; else None. Its boundary is
    ragged and its triangles Delaunay in the plane only: corners with the reach
    :data:`CLOUD_CORNER_WINDOW`, slivers up to :data:`CLOUD_SLIVER_AREA`."""
    tri, keep = cloud_faces(uv)
    faces = tri.simplices[keep]
    if len(np.unique(faces)) != len(points):
        return None
    flip = signed_areas(faces, uv) < 0
    faces[flip] = faces[flip][:, ::-1]  # counter-clockwise in the plane
    mesh = trimesh.Trimesh(points, faces, process=False)
    try:
        check_disk(mesh, "the point cloud")
    except SurfaceError:
        return None
    return conformal_rectangle(mesh, CLOUD_SLIVER_AREA, CLOUD_CORNER_WINDOW)
