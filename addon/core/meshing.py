"""Meshing of polygon meshes into radiosity patches (pure numpy, no bpy).

A source mesh is given the way Blender stores it: vertex positions, the
number of corners of each face (``face_sizes``) and the vertex of each corner
(``corner_verts``, faces one after the other).  Faces whose longest edge is
larger than the patch size are subdivided:

* quads into a regular ``n x m`` grid (bilinear, ``n`` and ``m`` from the
  longest of each pair of opposite edges),
* triangles regularly into ``n**2`` triangles (``n`` from the longest edge),
* n-gons are triangulated first (with the triangulation given by the caller,
  e.g. Blender's loop triangles, or a fan) and each triangle is then
  subdivided as a triangle.

Faces that are small enough are kept as they are: one face, one patch.

A patch must be coplanar triangles (the core refuses a patch whose triangles
face different ways).  A quad or n-gon that is not planar (a twisted quad, a
sculpted or deformed mesh, a NURBS surface's tessellation) is therefore never
one patch nor a grid of bilinear cells: it is split into the triangles of its
triangulation, each of which is a patch of its own (subdivided as a triangle
when larger than the patch size).  A face is planar when every triangle of its
triangulation is within PLANAR_ANGLE_DEGREES of the face's area-weighted
normal; triangles of no area at the core's tolerance do not count (their normal
is rounding noise) and, in split faces, are left out.  Every
face of the resulting *patch mesh* is one patch; points generated on the same
source edge at the same fraction are welded, so neighbouring patches share
vertices wherever their subdivisions agree.

The work is vectorised: faces are grouped by subdivision shape and every group
is handled with array operations (the only Python loops run over distinct
subdivision counts, never over faces).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .validation import RELATIVE_DEGENERATE_AREA

__all__ = [
    "PatchMesh",
    "mesh_patches",
    "nonplanar_faces",
    "default_min_area",
    "PLANAR_ANGLE_DEGREES",
    "concatenate",
    "reverse_faces",
    "fan_triangulation",
    "triangle_areas",
    "point_average",
    "corner_values",
]


# A quad or n-gon is one patch (or a grid of patches) only if every triangle of its
# triangulation is within this angle of the face's area-weighted normal; otherwise each of its
# triangles is a patch.  Far below the core's limit (a triangle at most 60 degrees from its
# patch's normal, MIN_PATCH_NORMAL_COSINE), also for the cells of a grid (a bilinear cell of a
# quad within the angle is within about twice the angle); far above float32 rounding, which
# tilts a triangle by ~1e-7 x (distance from the origin / face size) radians, so faces that are
# planar but for the rounding of their vertices stay whole.
PLANAR_ANGLE_DEGREES = 1.0
PLANAR_COSINE = float(np.cos(np.radians(PLANAR_ANGLE_DEGREES)))


@dataclass
class PatchMesh:
    """A patch mesh: every face is one patch.

    points        (N, 3) float64  positions of the patch mesh's vertices
    face_sizes    (P,)   int64    corners of each patch face (3, 4, or the
                                  source face's size for kept faces)
    corner_verts  (C,)   int64    point index of each corner, faces in order
    patch_face    (P,)   int64    source face each patch comes from
    triangles     (T, 3) int64    triangulation of the patches (into points)
    triangle_patch(T,)   int64    patch of each triangle
    patch_area    (P,)   float64  area of each patch (sum of its triangles)
    """

    points: np.ndarray
    face_sizes: np.ndarray
    corner_verts: np.ndarray
    patch_face: np.ndarray
    triangles: np.ndarray
    triangle_patch: np.ndarray
    patch_area: np.ndarray

    @property
    def patch_count(self) -> int:
        return int(len(self.face_sizes))

    @property
    def face_starts(self) -> np.ndarray:
        """First corner of each patch face (Blender's ``loop_start``)."""
        return _starts(self.face_sizes)

    @property
    def corner_patch(self) -> np.ndarray:
        """Patch of each corner (for writing flat colours on corners)."""
        return np.repeat(np.arange(self.patch_count), self.face_sizes)


@dataclass
class CombinedPatches:
    """Several patch meshes concatenated into the arrays PatchScene takes."""

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_patch: np.ndarray
    patch_object: np.ndarray  # (P,) index of the mesh each patch comes from
    patch_offsets: np.ndarray  # (M+1,) patches of mesh k: offsets[k]:offsets[k+1]
    patch_area: np.ndarray
    meshes: list = field(default_factory=list)

    @property
    def patch_count(self) -> int:
        return int(self.patch_offsets[-1])

    def patch_slice(self, k: int) -> slice:
        return slice(int(self.patch_offsets[k]), int(self.patch_offsets[k + 1]))


def _starts(sizes: np.ndarray) -> np.ndarray:
    starts = np.zeros(len(sizes), dtype=np.int64)
    if len(sizes) > 1:
        np.cumsum(sizes[:-1], out=starts[1:])
    return starts


def triangle_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle, (T,)."""
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def reverse_faces(face_sizes, corner_verts) -> np.ndarray:
    """Corner vertices with the winding of every face reversed.

    Used for objects with a negative scale: their world-space faces would
    otherwise point inwards.  The first corner of each face stays first.
    """
    face_sizes = np.asarray(face_sizes, dtype=np.int64)
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    starts = _starts(face_sizes)
    face_of_corner = np.repeat(np.arange(len(face_sizes)), face_sizes)
    local = np.arange(len(corner_verts)) - starts[face_of_corner]
    size = face_sizes[face_of_corner]
    new_local = (size - local) % size  # 0 -> 0, 1 -> n-1, 2 -> n-2, ...
    return corner_verts[starts[face_of_corner] + new_local]


def fan_triangulation(face_sizes, corner_verts):
    """Fan triangulation of every face: (triangles (T,3), triangle_face (T,)).

    Correct for convex faces; for concave n-gons pass Blender's loop
    triangles to :func:`mesh_patches` instead.
    """
    face_sizes = np.asarray(face_sizes, dtype=np.int64)
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    starts = _starts(face_sizes)
    counts = np.maximum(face_sizes - 2, 0)
    triangle_face = np.repeat(np.arange(len(face_sizes)), counts)
    k = np.arange(int(counts.sum())) - np.repeat(_starts(counts), counts)
    first = starts[triangle_face]
    triangles = np.stack(
        [corner_verts[first], corner_verts[first + k + 1], corner_verts[first + k + 2]],
        axis=1,
    )
    return triangles.reshape(-1, 3), triangle_face


def default_min_area(points, triangles) -> float:
    """The core's degenerate-triangle area for a scene made of this mesh alone:
    RELATIVE_DEGENERATE_AREA x (bounding-box diagonal of the vertices the triangles use)**2."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if not len(triangles):
        return 0.0
    used = points[np.unique(triangles)]
    diagonal = float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
    return RELATIVE_DEGENERATE_AREA * diagonal**2


def nonplanar_faces(points, face_count, face_triangles, triangle_face, min_area=None):
    """Which faces are not planar, and which triangles have an area: (nonplanar (F,), has_area (T,)).

    A triangle has an area when its area exceeds ``min_area`` (by default
    :func:`default_min_area`; pass the whole scene's, RELATIVE_DEGENERATE_AREA x its
    diagonal**2, to match the core exactly: it drops triangles of that area or less).  A face
    is non-planar when one of its triangles with an area is further than PLANAR_ANGLE_DEGREES
    from the face's normal (the sum of those triangles' area vectors, as the core computes a
    patch's normal), or when those area vectors cancel.  A face whose triangles all lack an
    area counts as planar (it is left as it is; the caller decides about zero-area faces).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    t = np.asarray(face_triangles, dtype=np.int64).reshape(-1, 3)
    tf = np.asarray(triangle_face, dtype=np.int64).ravel()
    if min_area is None:
        min_area = default_min_area(points, t)
    p = points[t]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # 2 x area x normal
    double_area = np.linalg.norm(cross, axis=1)
    has_area = 0.5 * double_area > float(min_area)
    w = np.where(has_area[:, None], cross, 0.0)
    normal = np.stack([np.bincount(tf, weights=w[:, k], minlength=face_count) for k in range(3)], axis=1)
    length = np.linalg.norm(normal, axis=1)
    total = np.bincount(tf, weights=np.where(has_area, double_area, 0.0), minlength=face_count)
    folded = (length <= 1e-12 * total) & (total > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = np.einsum("ij,ij->i", cross, normal[tf]) / (double_area * length[tf])
    tilted = has_area & ~(cosine >= PLANAR_COSINE)  # NaN (a folded face) counts as tilted
    nonplanar = folded | (np.bincount(tf, weights=tilted, minlength=face_count) > 0)
    return nonplanar, has_area


# ---------------------------------------------------------------------------
# Templates: the local parametrisation of one subdivided face.
# ---------------------------------------------------------------------------

def _grid_template(n: int, m: int):
    """Points (u, v) of an n x m grid and its cells as local point indices.

    u runs along edge 0->1 (n cells), v along edge 0->3 (m cells).  Point
    index = i * (m + 1) + j for u = i / n, v = j / m.
    """
    i, j = np.meshgrid(np.arange(n + 1), np.arange(m + 1), indexing="ij")
    i = i.ravel()
    j = j.ravel()
    ci, cj = np.meshgrid(np.arange(n), np.arange(m), indexing="ij")
    base = (ci * (m + 1) + cj).ravel()
    # counter-clockwise like the source quad (0 -> 1 -> 2 -> 3)
    cells = np.stack([base, base + (m + 1), base + (m + 1) + 1, base + 1], axis=1)
    return i, j, cells


def _triangle_template(n: int):
    """Barycentric lattice of a triangle cut n times per edge.

    Point (i, j) has weights (n - i - j, i, j) / n on corners (0, 1, 2).
    Returns i, j and the n**2 sub-triangles (local indices, same winding).
    """
    ii, jj = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = ii + jj <= n
    i = ii[keep]
    j = jj[keep]
    index = -np.ones((n + 1, n + 1), dtype=np.int64)
    index[i, j] = np.arange(len(i))
    ui, uj = np.nonzero(ii + jj <= n - 1)  # "upward" triangles
    up = np.stack([index[ui, uj], index[ui + 1, uj], index[ui, uj + 1]], axis=1)
    di, dj = np.nonzero(ii + jj <= n - 2)  # "downward" triangles
    down = np.stack(
        [index[di + 1, dj], index[di + 1, dj + 1], index[di, dj + 1]], axis=1
    )
    return i, j, np.concatenate([up, down]).reshape(-1, 3)


# ---------------------------------------------------------------------------
# Point keys for welding.
#   kind 0: source vertex a
#   kind 1: point on the source segment (a, b), a < b, at fraction num/den from a
#   kind 2: interior point, unique id a
# ---------------------------------------------------------------------------

def _edge_point_keys(va, vb, num, den):
    """Keys of points at fraction num/den on the segment va -> vb (arrays)."""
    va = np.asarray(va, dtype=np.int64)
    vb = np.asarray(vb, dtype=np.int64)
    num = np.asarray(num, dtype=np.int64)
    den = np.asarray(den, dtype=np.int64)
    swap = va > vb
    a = np.where(swap, vb, va)
    b = np.where(swap, va, vb)
    num = np.where(swap, den - num, num)
    g = np.gcd(num, den)
    g[g == 0] = 1
    num //= g
    den //= g
    keys = np.zeros((len(a), 5), dtype=np.int64)
    keys[:, 0] = 1
    keys[:, 1] = a
    keys[:, 2] = b
    keys[:, 3] = num
    keys[:, 4] = den
    at_a = num == 0
    at_b = num == den
    keys[at_a] = 0
    keys[at_a, 1] = a[at_a]
    keys[at_b] = 0
    keys[at_b, 1] = b[at_b]
    return keys


def _vertex_keys(v):
    v = np.asarray(v, dtype=np.int64).ravel()
    keys = np.zeros((len(v), 5), dtype=np.int64)
    keys[:, 1] = v
    return keys


class _Builder:
    """Collects generated points (as keys + positions) and patch faces."""

    def __init__(self):
        self.keys = []
        self.positions = []
        self.faces = []  # list of (sizes, corners as global generated index, patch_face)
        self.count = 0
        self.interior = 0

    def add_points(self, keys, positions):
        start = self.count
        self.keys.append(keys)
        self.positions.append(positions)
        self.count += len(keys)
        return start

    def interior_keys(self, count):
        keys = np.zeros((count, 5), dtype=np.int64)
        keys[:, 0] = 2
        keys[:, 1] = self.interior + np.arange(count)
        self.interior += count
        return keys

    def add_faces(self, sizes, corners, patch_face, order):
        self.faces.append((sizes, corners, patch_face, order))


def _longest_edges(points, face_sizes, corner_verts, starts):
    """Longest boundary edge of every face."""
    face_of_corner = np.repeat(np.arange(len(face_sizes)), face_sizes)
    local = np.arange(len(corner_verts)) - starts[face_of_corner]
    nxt = starts[face_of_corner] + (local + 1) % face_sizes[face_of_corner]
    length = np.linalg.norm(points[corner_verts[nxt]] - points[corner_verts], axis=1)
    longest = np.zeros(len(face_sizes))
    if len(length):
        np.maximum.at(longest, face_of_corner, length)
    return longest


def _weld(keys, n_vertices):
    """Merge generated points with equal keys.

    Returns (unique key rows, index of the first generated point of each,
    output point of every generated point).  Interior points (kind 2) are
    unique by construction; the others are welded through one int64 code
    per key (a 1-D sort instead of a row-wise one).
    """
    kind = keys[:, 0]
    shared = np.flatnonzero(kind != 2)
    interior = np.flatnonzero(kind == 2)
    k = keys[shared]
    code = k[:, 1].copy()  # kind 0: the source vertex
    on_edge = k[:, 0] == 1
    if np.any(on_edge):
        pair = k[on_edge, 1] * n_vertices + k[on_edge, 2]
        _, pair_id = np.unique(pair, return_inverse=True)
        D = int(k[on_edge, 4].max()) + 1
        if (pair_id.max() + 1) * D * D + n_vertices < 2**62:
            code[on_edge] = n_vertices + (pair_id.ravel() * D + k[on_edge, 3]) * D + k[on_edge, 4]
        else:  # astronomically many edges x cuts: weld row-wise
            _, code = np.unique(k, axis=0, return_inverse=True)
            code = code.ravel()
    _, first, inv = np.unique(code, return_index=True, return_inverse=True)
    inverse = np.empty(len(keys), dtype=np.int64)
    inverse[shared] = inv.ravel()
    inverse[interior] = len(first) + np.arange(len(interior))
    first_index = np.concatenate([shared[first], interior])
    return keys[first_index], first_index, inverse


def _prepare(vertices, face_sizes, corner_verts, patch_size, face_triangles, triangle_face):
    """Checked arrays for :func:`mesh_patches` and :func:`count_patches` (a fan triangulation
    where none is given)."""
    points = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    face_sizes = np.asarray(face_sizes, dtype=np.int64).ravel()
    corner_verts = np.asarray(corner_verts, dtype=np.int64).ravel()
    patch_size = float(patch_size)
    if not np.isfinite(patch_size) or patch_size <= 0:
        raise ValueError(f"patch size must be a positive number, got {patch_size!r}")
    if face_sizes.sum() != len(corner_verts):
        raise ValueError("face_sizes do not add up to the number of corners")
    if len(face_sizes) and face_sizes.min() < 3:
        raise ValueError("every face needs at least 3 corners")
    if len(corner_verts) and (corner_verts.min() < 0 or corner_verts.max() >= len(points)):
        raise ValueError("corner_verts index outside the vertices")
    if not np.all(np.isfinite(points)):
        raise ValueError("vertex positions contain NaN or infinity")
    if face_triangles is None:
        face_triangles, triangle_face = fan_triangulation(face_sizes, corner_verts)
    else:
        face_triangles = np.asarray(face_triangles, dtype=np.int64).reshape(-1, 3)
        triangle_face = np.asarray(triangle_face, dtype=np.int64).ravel()
        if len(triangle_face) != len(face_triangles):
            raise ValueError("triangle_face must have one entry per triangle")
    return points, face_sizes, corner_verts, patch_size, face_triangles, triangle_face


@dataclass
class _FacePlan:
    """What the meshing does with each face: keep it (one patch), cut a quad into an
    n_u x n_v grid, or cut it into its triangles, each into n_t^2 triangles."""

    starts: np.ndarray        # (F,) first corner of each face
    limit: float              # the patch size, with a tolerance
    kept_face: np.ndarray     # (F,) bool
    quads: np.ndarray         # (Q,) faces cut into grids
    quad_corners: np.ndarray  # (Q,4) their vertices
    n_u: np.ndarray           # (Q,) grid cells along edges 01 / 23
    n_v: np.ndarray           # (Q,) grid cells along edges 12 / 30
    cut: np.ndarray           # (T,) bool: triangles of the triangulation that become patches


def _plan_faces(points, face_sizes, corner_verts, patch_size, face_triangles, triangle_face, min_area):
    F = len(face_sizes)
    starts = _starts(face_sizes)
    longest = _longest_edges(points, face_sizes, corner_verts, starts)
    # n-gons: also look at the diagonals of their triangulation
    tri_longest = np.zeros(F)
    if len(face_triangles):
        np.maximum.at(tri_longest, triangle_face, _triangle_longest_edges(points, face_triangles))
    # tolerance so that a face exactly patch_size long is not cut in two
    limit = patch_size * (1.0 + 1e-9)
    ngon = face_sizes > 4
    big = np.where(ngon, np.maximum(longest, tri_longest), longest) > limit
    # non-planar quads and n-gons: their triangles, each a patch (never a grid of
    # bilinear cells, which would not be planar either)
    nonplanar, has_area = nonplanar_faces(points, F, face_triangles, triangle_face, min_area)
    kept_face = ~big & ~nonplanar
    grid_face = big & (face_sizes == 4) & ~nonplanar
    to_triangles = ~kept_face & ~grid_face
    quads = np.nonzero(grid_face)[0]
    q = corner_verts[starts[quads][:, None] + np.arange(4)]  # (Q,4)
    e = np.linalg.norm(points[q][:, [1, 2, 3, 0]] - points[q], axis=2)  # edges 01 12 23 30
    n_u = np.maximum(np.ceil(np.maximum(e[:, 0], e[:, 2]) / limit), 1).astype(np.int64)
    n_v = np.maximum(np.ceil(np.maximum(e[:, 1], e[:, 3]) / limit), 1).astype(np.int64)
    # triangles without an area are left out (faces with some area only: a face of
    # no area at all stays, for the caller to refuse or drop)
    face_has_area = np.bincount(triangle_face, weights=has_area, minlength=F) > 0
    cut = to_triangles[triangle_face] & (has_area | ~face_has_area[triangle_face])
    return _FacePlan(starts, limit, kept_face, quads, q, n_u, n_v, cut)


def _triangle_longest_edges(points, triangles):
    p = points[triangles]
    return np.linalg.norm(p[:, [1, 2, 0]] - p, axis=2).max(axis=1)


def _triangle_subdivisions(points, triangles, limit):
    """n of each triangle cut into n^2 triangles no longer than ``limit``."""
    if not len(triangles):
        return np.zeros(0, dtype=np.int64)
    return np.maximum(np.ceil(_triangle_longest_edges(points, triangles) / limit), 1).astype(np.int64)


def count_patches(vertices, face_sizes, corner_verts, patch_size, face_triangles=None, triangle_face=None, min_area=None) -> float:
    """How many patches :func:`mesh_patches` makes of these faces (same arguments), without
    making them: O(faces), a float so that absurd counts cannot overflow."""
    args = _prepare(vertices, face_sizes, corner_verts, patch_size, face_triangles, triangle_face)
    points, face_triangles = args[0], args[4]
    plan = _plan_faces(*args, min_area)
    n_t = _triangle_subdivisions(points, face_triangles[plan.cut], plan.limit)
    return (
        float(np.count_nonzero(plan.kept_face))
        + float(np.sum(plan.n_u.astype(np.float64) * plan.n_v))
        + float(np.sum(n_t.astype(np.float64) ** 2))
    )


def mesh_patches(
    vertices,
    face_sizes,
    corner_verts,
    patch_size: float,
    face_triangles=None,
    triangle_face=None,
    min_area=None,
) -> PatchMesh:
    """Subdivide the faces of one mesh into patches no larger than ``patch_size``.

    vertices      (V, 3) positions (world space)
    face_sizes    (F,)   corners per face (>= 3)
    corner_verts  (C,)   vertex of each corner, faces one after the other
    patch_size    largest patch edge, > 0
    face_triangles, triangle_face   optional triangulation of the source faces
                  (vertex indices, (T,3), and the face of each triangle), used
                  to triangulate n-gons, non-planar faces and kept faces; fan
                  triangulation if not given.
    min_area      triangles of this area or less are degenerate (see
                  :func:`nonplanar_faces`): they do not make a face non-planar,
                  and faces cut into triangles leave them out (the core would
                  drop them, leaving empty patches).  Default: the core's
                  tolerance for a scene of this mesh alone; pass
                  RELATIVE_DEGENERATE_AREA x (scene diagonal)**2 when several
                  meshes make one scene.

    Returns a :class:`PatchMesh` whose patches appear in source-face order
    (all patches of face 0 first, then face 1, ...).
    """
    args = _prepare(vertices, face_sizes, corner_verts, patch_size, face_triangles, triangle_face)
    points, face_sizes, corner_verts, patch_size, face_triangles, triangle_face = args
    plan = _plan_faces(*args, min_area)
    F = len(face_sizes)
    starts, limit, kept_face = plan.starts, plan.limit, plan.kept_face

    b = _Builder()

    # --- kept faces: corners are source vertices --------------------------
    kept = np.nonzero(kept_face)[0]
    if len(kept):
        ksizes = face_sizes[kept]
        corner_idx = np.repeat(starts[kept], ksizes) + (
            np.arange(int(ksizes.sum())) - np.repeat(_starts(ksizes), ksizes)
        )
        verts = corner_verts[corner_idx]
        first = b.add_points(_vertex_keys(verts), points[verts])
        b.add_faces(ksizes, first + np.arange(len(verts)), kept, kept * 0)

    # --- quads into grids ---------------------------------------------------
    quads = plan.quads
    if len(quads):
        q = plan.quad_corners
        p = points[q]  # (Q,4,3)
        n_u, n_v = plan.n_u, plan.n_v
        shapes, shape_of = np.unique(np.stack([n_u, n_v], axis=1), axis=0, return_inverse=True)
        shape_of = shape_of.ravel()
        for s, (n, m) in enumerate(shapes):
            sel = np.nonzero(shape_of == s)[0]
            qs, ps = q[sel], p[sel]
            i, j, cells = _grid_template(int(n), int(m))
            u = (i / n)[None, :, None]
            v = (j / m)[None, :, None]
            pos = (
                (1 - u) * (1 - v) * ps[:, None, 0]
                + u * (1 - v) * ps[:, None, 1]
                + u * v * ps[:, None, 2]
                + (1 - u) * v * ps[:, None, 3]
            )  # (G, K, 3)
            G, K = len(sel), len(i)
            keys = b.interior_keys(G * K).reshape(G, K, 5)
            # boundary points lie on source edges; corners are source vertices
            on_v0 = j == 0  # edge 0 -> 1, fraction i/n
            on_v1 = j == m  # edge 3 -> 2, fraction i/n
            on_u0 = i == 0  # edge 0 -> 3, fraction j/m
            on_u1 = i == n  # edge 1 -> 2, fraction j/m
            for mask, a, c, num, den in (
                (on_v0, 0, 1, i, n),
                (on_v1, 3, 2, i, n),
                (on_u0, 0, 3, j, m),
                (on_u1, 1, 2, j, m),
            ):
                cnt = int(mask.sum())
                ek = _edge_point_keys(
                    np.repeat(qs[:, a], cnt),
                    np.repeat(qs[:, c], cnt),
                    np.tile(num[mask], G),
                    np.full(G * cnt, den),
                )
                keys[:, mask] = ek.reshape(G, cnt, 5)
            first = b.add_points(keys.reshape(-1, 5), pos.reshape(-1, 3))
            corners = first + (np.arange(G)[:, None, None] * K + cells[None]).reshape(-1)
            nc = len(cells)
            b.add_faces(
                np.full(G * nc, 4, dtype=np.int64),
                corners,
                np.repeat(quads[sel], nc),
                np.tile(np.arange(nc), G),
            )

    # --- triangles, triangulated n-gons and non-planar faces ----------------
    tri_sel = np.nonzero(plan.cut)[0]
    if len(tri_sel):
        t = face_triangles[tri_sel]
        tf = triangle_face[tri_sel]
        if np.any(np.diff(tf) < 0):
            srt = np.argsort(tf, kind="stable")
            t, tf = t[srt], tf[srt]
        p = points[t]
        n_t = _triangle_subdivisions(points, t, limit)
        # rank of each triangle inside its face, to keep patches in face order
        order_in_face = np.arange(len(tf)) - np.searchsorted(tf, tf)
        for n in np.unique(n_t):
            sel = np.nonzero(n_t == n)[0]
            ts, ps = t[sel], p[sel]
            i, j, subs = _triangle_template(int(n))
            w1 = (i / n)[None, :, None]
            w2 = (j / n)[None, :, None]
            pos = (1 - w1 - w2) * ps[:, None, 0] + w1 * ps[:, None, 1] + w2 * ps[:, None, 2]
            G, K = len(sel), len(i)
            keys = b.interior_keys(G * K).reshape(G, K, 5)
            for mask, a, c, num in (
                (j == 0, 0, 1, i),  # edge 0 -> 1 at i/n
                (i == 0, 0, 2, j),  # edge 0 -> 2 at j/n
                (i + j == n, 1, 2, j),  # edge 1 -> 2 at j/n
            ):
                cnt = int(mask.sum())
                ek = _edge_point_keys(
                    np.repeat(ts[:, a], cnt),
                    np.repeat(ts[:, c], cnt),
                    np.tile(num[mask], G),
                    np.full(G * cnt, int(n)),
                )
                keys[:, mask] = ek.reshape(G, cnt, 5)
            first = b.add_points(keys.reshape(-1, 5), pos.reshape(-1, 3))
            corners = first + (np.arange(G)[:, None, None] * K + subs[None]).reshape(-1)
            ns = len(subs)
            b.add_faces(
                np.full(G * ns, 3, dtype=np.int64),
                corners,
                np.repeat(tf[sel], ns),
                np.repeat(order_in_face[sel] * (int(n_t.max()) ** 2 + 1), ns)
                + np.tile(np.arange(ns), G),
            )

    # --- weld and assemble ---------------------------------------------------
    if b.count == 0:
        empty_i = np.zeros(0, dtype=np.int64)
        return PatchMesh(
            np.zeros((0, 3)), empty_i, empty_i, empty_i,
            np.zeros((0, 3), dtype=np.int64), empty_i, np.zeros(0),
        )
    keys = np.concatenate(b.keys)
    positions = np.concatenate(b.positions)
    uniq, first_index, inverse = _weld(keys, len(points))
    out_points = positions[first_index].copy()
    # canonical positions: source vertices exactly, edge points from the
    # lower-indexed vertex, so both neighbouring faces agree bit for bit
    kind0 = uniq[:, 0] == 0
    out_points[kind0] = points[uniq[kind0, 1]]
    kind1 = uniq[:, 0] == 1
    if np.any(kind1):
        a = points[uniq[kind1, 1]]
        c = points[uniq[kind1, 2]]
        frac = (uniq[kind1, 3] / uniq[kind1, 4])[:, None]
        out_points[kind1] = a + frac * (c - a)

    sizes = np.concatenate([f[0] for f in b.faces])
    corners = inverse[np.concatenate([f[1] for f in b.faces])]
    patch_face = np.concatenate([f[2] for f in b.faces])
    order = np.concatenate([f[3] for f in b.faces])
    # patches in source-face order
    perm = np.lexsort((order, patch_face))
    fstarts = _starts(sizes)
    sizes_sorted = sizes[perm]
    corner_index = np.repeat(fstarts[perm], sizes_sorted) + (
        np.arange(int(sizes_sorted.sum())) - np.repeat(_starts(sizes_sorted), sizes_sorted)
    )
    corners = corners[corner_index]
    patch_face = patch_face[perm]
    sizes = sizes_sorted

    # triangulation of the patches
    P = len(sizes)
    pstarts = _starts(sizes)
    tri_patch = np.zeros(0, dtype=np.int64)
    tris = np.zeros((0, 3), dtype=np.int64)
    # triangles and grid cells: fan (exact for a planar cell); kept quads and
    # kept n-gons: the source triangulation (Blender's, when given)
    kept_patch = kept_face[patch_face]
    small = (sizes == 3) | ((sizes == 4) & ~kept_patch)
    if np.any(small):
        sp = np.nonzero(small)[0]
        cnt = sizes[sp] - 2
        tp = np.repeat(sp, cnt)
        k = np.arange(int(cnt.sum())) - np.repeat(_starts(cnt), cnt)
        f0 = pstarts[tp]
        tris = np.stack([corners[f0], corners[f0 + k + 1], corners[f0 + k + 2]], axis=1)
        tri_patch = tp
    # kept quads and n-gons: the source triangulation, mapped onto the patch points
    if np.any(~small):
        ng = np.nonzero(~small)[0]
        src_face = patch_face[ng]
        # map source vertex -> output point for the n-gon corners
        vkey_point = -np.ones(len(points), dtype=np.int64)
        vkey_point[uniq[kind0, 1]] = np.nonzero(kind0)[0]
        patch_of_face = -np.ones(F, dtype=np.int64)
        patch_of_face[src_face] = ng
        tsel = np.nonzero(patch_of_face[triangle_face] >= 0)[0]
        tsel = tsel[kept_face[triangle_face[tsel]]]
        tris = np.concatenate([tris, vkey_point[face_triangles[tsel]]])
        tri_patch = np.concatenate([tri_patch, patch_of_face[triangle_face[tsel]]])
    order_t = np.argsort(tri_patch, kind="stable")
    tris = tris[order_t].astype(np.int64)
    tri_patch = tri_patch[order_t].astype(np.int64)
    area = np.bincount(tri_patch, weights=triangle_areas(out_points, tris), minlength=P)
    return PatchMesh(
        points=out_points,
        face_sizes=sizes.astype(np.int64),
        corner_verts=corners.astype(np.int64),
        patch_face=patch_face.astype(np.int64),
        triangles=tris,
        triangle_patch=tri_patch,
        patch_area=area,
    )


def concatenate(meshes) -> CombinedPatches:
    """Concatenate patch meshes (one per object) into PatchScene arrays."""
    meshes = list(meshes)
    vertex_offsets = _starts(np.array([len(m.points) for m in meshes], dtype=np.int64))
    counts = np.array([m.patch_count for m in meshes], dtype=np.int64)
    patch_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    if meshes:
        vertices = np.concatenate([m.points for m in meshes]).reshape(-1, 3)
        triangles = np.concatenate(
            [m.triangles + off for m, off in zip(meshes, vertex_offsets)]
        ).reshape(-1, 3)
        triangle_patch = np.concatenate(
            [m.triangle_patch + off for m, off in zip(meshes, patch_offsets[:-1])]
        )
        patch_area = np.concatenate([m.patch_area for m in meshes])
    else:
        vertices = np.zeros((0, 3))
        triangles = np.zeros((0, 3), dtype=np.int64)
        triangle_patch = np.zeros(0, dtype=np.int64)
        patch_area = np.zeros(0)
    patch_object = np.repeat(np.arange(len(meshes)), counts)
    return CombinedPatches(
        vertices=vertices,
        triangles=triangles.astype(np.int64),
        triangle_patch=triangle_patch.astype(np.int64),
        patch_object=patch_object,
        patch_offsets=patch_offsets,
        patch_area=patch_area,
        meshes=meshes,
    )


def corner_values(mesh: PatchMesh, patch_values) -> np.ndarray:
    """Per-corner copy of per-patch values (flat colours), (C, ...)."""
    return np.asarray(patch_values)[mesh.corner_patch]


def point_average(mesh: PatchMesh, patch_values) -> np.ndarray:
    """Area-weighted average of the patch values around each point, (N, k).

    Every patch touching a point contributes once, weighted by its area.
    Points used by no patch get 0.
    """
    values = np.asarray(patch_values, dtype=np.float64)
    flat = values.reshape(len(values), -1)
    cp = mesh.corner_patch
    # each patch counted once per point even if it had a repeated corner
    P = max(mesh.patch_count, 1)
    code = np.unique(mesh.corner_verts.astype(np.int64) * P + cp)
    pairs = np.stack([code // P, code % P], axis=1)
    w = mesh.patch_area[pairs[:, 1]]
    N = len(mesh.points)
    total_w = np.bincount(pairs[:, 0], weights=w, minlength=N)
    out = np.empty((N, flat.shape[1]))
    for k in range(flat.shape[1]):  # over colour channels, not elements
        out[:, k] = np.bincount(pairs[:, 0], weights=w * flat[pairs[:, 1], k], minlength=N)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(total_w[:, None] > 0, out / total_w[:, None], 0.0)
    return out.reshape((N,) + values.shape[1:])
