"""Source faces: areas, winding, triangulation, planarity, and the plan of how each face is cut.

A source mesh is given the way Blender stores it: vertex positions, the number of corners of
each face (``face_sizes``) and the vertex of each corner (``corner_verts``, faces one after the
other). The plan (:func:`plan_faces`) keeps a small face whole, cuts a planar quad into a grid
and cuts every other face into the triangles of its triangulation.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .validation import RELATIVE_DEGENERATE_AREA

# A quad or n-gon is one patch (or a grid of patches) only if every triangle of its
# triangulation is within this angle of the face's area-weighted normal; otherwise each of its
# triangles is a patch.  Far below the core's limit (a triangle at most 60 degrees from its
# patch's normal, MIN_PATCH_NORMAL_COSINE), also for the cells of a grid (a bilinear cell of a
# quad within the angle is within about twice the angle); far above float32 rounding, which
# tilts a triangle by ~1e-7 x (distance from the origin / face size) radians, so faces that are
# planar but for the rounding of their vertices stay whole.
PLANAR_ANGLE_DEGREES = 1.0
PLANAR_COSINE = float(np.cos(np.radians(PLANAR_ANGLE_DEGREES)))

def starts_of(sizes: np.ndarray) -> np.ndarray:
    starts = np.zeros(len(sizes), dtype=np.int64)
    if len(sizes) > 1:
        np.cumsum(sizes[:-1], out=starts[1:])
    return starts


def ranks_in_runs(sizes: np.ndarray) -> np.ndarray:
    """(sum(sizes),) int64: 0, 1, ... within each of consecutive runs of ``sizes``."""
    return np.arange(int(np.sum(sizes))) - np.repeat(starts_of(sizes), sizes)


# Per-triangle arithmetic runs this many triangles at a time (each triangle on its own: the same
# numbers as all at once), so that its float64 temporaries are a block's.
BLOCK_TRIANGLES = 1 << 16


def triangle_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle, (T,)."""
    points = np.asarray(points, dtype=np.float64)
    triangles = np.asarray(triangles).reshape(-1, 3)
    area = np.empty(len(triangles))
    for start in range(0, len(triangles), BLOCK_TRIANGLES):
        block = triangles[start:start + BLOCK_TRIANGLES]
        a, b, c = (points[block[:, k]] for k in range(3))
        area[start:start + BLOCK_TRIANGLES] = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    return area


def reverse_faces(face_sizes, corner_verts) -> np.ndarray:
    """Corner vertices with the winding of every face reversed.

    Used for objects with a negative scale: their world-space faces would
    otherwise point inwards.  The first corner of each face stays first.
    """
    face_sizes = np.asarray(face_sizes, dtype=np.int64)
    corner_verts = np.asarray(corner_verts, dtype=np.int64)
    starts = starts_of(face_sizes)
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
    starts = starts_of(face_sizes)
    counts = np.maximum(face_sizes - 2, 0)
    triangle_face = np.repeat(np.arange(len(face_sizes)), counts)
    k = ranks_in_runs(counts)
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
    cross = np.empty((len(t), 3))  # 2 x area x normal, a block of triangles at a time
    for start in range(0, len(t), BLOCK_TRIANGLES):
        p = points[t[start:start + BLOCK_TRIANGLES]]
        cross[start:start + BLOCK_TRIANGLES] = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
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


def _longest_edges(points, face_sizes, corner_verts, starts):
    """Longest boundary edge of every face."""
    face_of_corner = np.repeat(np.arange(len(face_sizes)), face_sizes)
    local = np.arange(len(corner_verts)) - starts[face_of_corner]
    nxt = starts[face_of_corner] + (local + 1) % face_sizes[face_of_corner]
    del local
    length = np.empty(len(corner_verts))
    for start in range(0, len(corner_verts), BLOCK_TRIANGLES):  # (corner by corner)
        rows = slice(start, start + BLOCK_TRIANGLES)
        length[rows] = np.linalg.norm(points[corner_verts[nxt[rows]]] - points[corner_verts[rows]], axis=1)
    longest = np.zeros(len(face_sizes))
    if len(length):
        np.maximum.at(longest, face_of_corner, length)
    return longest


def prepare(vertices, face_sizes, corner_verts, patch_size, face_triangles, triangle_face):
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
class FacePlan:
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


def plan_faces(points, face_sizes, corner_verts, patch_size, face_triangles, triangle_face, min_area):
    F = len(face_sizes)
    starts = starts_of(face_sizes)
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
    return FacePlan(starts, limit, kept_face, quads, q, n_u, n_v, cut)


def _triangle_longest_edges(points, triangles):
    longest = np.empty(len(triangles))
    for start in range(0, len(triangles), BLOCK_TRIANGLES):  # (triangle by triangle)
        p = points[triangles[start:start + BLOCK_TRIANGLES]]
        longest[start:start + BLOCK_TRIANGLES] = np.linalg.norm(p[:, [1, 2, 0]] - p, axis=2).max(axis=1)
    return longest


def triangle_subdivisions(points, triangles, limit):
    """n of each triangle cut into n^2 triangles no longer than ``limit``."""
    if not len(triangles):
        return np.zeros(0, dtype=np.int64)
    return np.maximum(np.ceil(_triangle_longest_edges(points, triangles) / limit), 1).astype(np.int64)


def count_patches(vertices, face_sizes, corner_verts, patch_size, face_triangles=None, triangle_face=None, min_area=None) -> float:
    """How many patches :func:`mesh_patches` makes of these faces (same arguments), without
    making them: O(faces), a float so that absurd counts cannot overflow."""
    args = prepare(vertices, face_sizes, corner_verts, patch_size, face_triangles, triangle_face)
    points, face_triangles = args[0], args[4]
    plan = plan_faces(*args, min_area)
    n_t = triangle_subdivisions(points, face_triangles[plan.cut], plan.limit)
    return (
        float(np.count_nonzero(plan.kept_face))
        + float(np.sum(plan.n_u.astype(np.float64) * plan.n_v))
        + float(np.sum(n_t.astype(np.float64) ** 2))
    )


def polygon_corner_values(corners, triangles, triangle_patch, corner_patch, corner_point):
    """(n,3) the value at each polygon corner (its patch ``corner_patch`` (n,), its point
    ``corner_point`` (n,), indices of the same arrays as ``triangles``), read from ``corners``
    (T,3,3) at a corner of one of the patch's triangles at that point (every such corner holds the
    same value: the patch's triangles share its normal, so one crease group at each point).
    ValueError where a polygon corner is no corner of its patch's triangles."""
    rows = polygon_corner_rows(triangles, triangle_patch, corner_patch, corner_point)
    return np.asarray(corners).reshape(-1, np.asarray(corners).shape[-1])[rows]


def polygon_corner_rows(triangles, triangle_patch, corner_patch, corner_point):
    """(n,) the triangle corner (a row of (T*3,...) corners) ``polygon_corner_values`` reads for each
    polygon corner: the same for every value set on these triangles."""
    triangles, triangle_patch, corner_patch = np.asarray(triangles), np.asarray(triangle_patch), np.asarray(corner_patch, np.int64)
    # (the triangles of the patches asked alone: an object's, not the scene's, sorted at each call)
    rows = np.flatnonzero((triangle_patch >= corner_patch.min(initial=0)) & (triangle_patch <= corner_patch.max(initial=-1)))
    mine = triangles[rows]
    points = int(max(mine.max(initial=0), np.max(corner_point, initial=0))) + 1
    key = (triangle_patch[rows].astype(np.int64)[:, None] * points + mine).ravel()
    order = np.argsort(key, kind="stable")
    wanted = corner_patch * points + corner_point
    found = order[np.minimum(np.searchsorted(key, wanted, sorter=order), key.size - 1)] if key.size else wanted[:0]
    if found.size != wanted.size or not np.array_equal(key[found], wanted):
        raise ValueError("a polygon corner is not a corner of its patch's triangles")
    return rows[found // 3] * 3 + found % 3
