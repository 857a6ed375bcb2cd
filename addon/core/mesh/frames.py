"""Leaving frames of triangles and parallelograms: where rays start on a patch, kept clear of its edges.

Positions are in unit space, (world - centre) / diagonal of the scene's bounding box.
"""
from __future__ import annotations

import numpy as np

# The ray tracer works in unit space: positions (world - centre) / diagonal, where centre and
# diagonal are the bounding box's, so that float32 precision and Embree's internal tolerances
# (its barycentrics fail below a scene size of ~1e-8) see the same scene at any scale or
# distance from the origin. Rays leave a patch from a point pushed this far along its normal
# (~170 float32 ulps at the scene's extent), or less where it is small beside the scene
# (local_offsets).
RELATIVE_RAY_OFFSET = 1e-5

# Points where rays leave a patch keep this distance (relative to the diagonal, ~17 float32
# ulps at the scene's extent) from the patch's edges, so that float32 rounding never puts an
# origin on the far side of an adjacent wall, where its ray would hit that wall's back (less,
# as the offset, for patches small beside the scene).
RELATIVE_EDGE_INSET = 1e-6

# A ray leaving from where the previous one hit starts at that hit point (origin + t direction,
# pushed off along the normal) if the point lies at least this far (relative to the diagonal)
# from every edge of its triangle: four times the edge inset (its patch's own, where it has
# one), which leaves room for float32's error in the point (~2e-7 in unit space). Closer to an
# edge, the hit's barycentric coordinates are mapped onto the triangle's inset leaving frame.
RELATIVE_HIT_EDGE_CLEARANCE = 4 * RELATIVE_EDGE_INSET

# Geometry small beside the scene's extent (a room beside a far object, a house on a terrain)
# would be crossed by offsets and insets of the diagonal: there a patch's offset and inset
# shrink with its own size (its side, the square root of its area, times these), down to a few
# float32 spacings of the scene's largest unit-space coordinate, what rounding of its positions
# needs. A patch of at least 1e-3 of the diagonal keeps RELATIVE_RAY_OFFSET and
# RELATIVE_EDGE_INSET.
LOCAL_RAY_OFFSET = 1e-2
LOCAL_EDGE_INSET = 1e-3
RAY_OFFSET_SPACINGS = 8
EDGE_INSET_SPACINGS = 4
LIGHT_OFFSET_SPACINGS = 4


def local_offsets(side, largest_coordinate):
    """(ray offsets, edge insets), each (n,) float64 unit space, of patches of unit-space
    ``side`` (n,) whose frame's coordinates reach ``largest_coordinate`` (a number, or (n,)): the
    relative ones, or less for patches small beside the scene, never below the float32
    spacings that rounding of positions needs."""
    spacing = np.spacing(np.asarray(largest_coordinate, np.float32)).astype(np.float64)
    side = np.asarray(side, dtype=np.float64)
    offset = np.maximum(RAY_OFFSET_SPACINGS * spacing, np.minimum(RELATIVE_RAY_OFFSET, LOCAL_RAY_OFFSET * side))
    inset = np.maximum(EDGE_INSET_SPACINGS * spacing, np.minimum(RELATIVE_EDGE_INSET, LOCAL_EDGE_INSET * side))
    return offset, inset


def set_by_rounding(side, largest_coordinate):
    """(n,) bool: where float32's spacing of coordinates reaching ``largest_coordinate``, not the
    patch's own ``side``, sets its ray offset or edge inset (``local_offsets``' lower bounds): the
    patches a frame of their own would give offsets of their own size."""
    spacing = np.spacing(np.asarray(largest_coordinate, np.float32)).astype(np.float64)
    side = np.asarray(side, dtype=np.float64)
    return (RAY_OFFSET_SPACINGS * spacing > np.minimum(RELATIVE_RAY_OFFSET, LOCAL_RAY_OFFSET * side)) | \
        (EDGE_INSET_SPACINGS * spacing > np.minimum(RELATIVE_EDGE_INSET, LOCAL_EDGE_INSET * side))


def edge_barycentric(corners, clearance=RELATIVE_HIT_EDGE_CLEARANCE):
    """(T,) float32: for (T,3,3) unit-space triangles, the barycentric coordinate below which a
    point may lie closer than ``clearance`` (a number, or (T,) one per triangle) to one of the
    triangle's edges (the clearance over its smallest altitude, 2 area / longest edge; 1 for
    triangles too small to have such points)."""
    corners = np.asarray(corners, dtype=np.float64)
    edges = corners[:, [1, 2, 0]] - corners
    longest = np.linalg.norm(edges, axis=2).max(axis=1)
    twice_area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        threshold = clearance * longest / twice_area
    return np.where(np.isfinite(threshold), np.minimum(threshold, 1.0), 1.0).astype(np.float32)


def inset_triangles(corners, inset):
    """Each triangle shrunk about its incentre so that every edge moves in by ``inset``
    (by at most half the inradius for tiny triangles). (T,3,3)."""
    a = np.linalg.norm(corners[:, 2] - corners[:, 1], axis=1)  # side opposite corner 0
    b = np.linalg.norm(corners[:, 0] - corners[:, 2], axis=1)
    c = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    perimeter = a + b + c
    incentre = (a[:, None] * corners[:, 0] + b[:, None] * corners[:, 1] + c[:, None] * corners[:, 2]) / perimeter[:, None]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    inradius = 2 * area / perimeter
    shrink = np.minimum(inset / inradius, 0.5)
    return incentre[:, None, :] + (1 - shrink)[:, None, None] * (corners - incentre[:, None, :])


def parallelogram_frames(sorted_corners, first, count, inset, offset, normal, out):
    """Which patches are two triangles forming a parallelogram ((P,) bool), with their leaving
    frames written into ``out`` ((9,P) float32, one coordinate per row): the corner, inset and
    pushed ``offset`` along the patch's ``normal`` ((P,3)), then the edges a and b; zeros for
    the other patches. ``inset`` and ``offset`` are numbers, or (P,) one per patch.

    Such a patch (any quad with parallel sides: the grids meshing makes) is sampled as
    corner + u a + v b, without choosing a triangle or folding. Computed a block of patches at a
    time in float64 (row by row: the same numbers as the whole at once), so that no float64
    array of every patch is made.
    """
    out[...] = 0.0
    flags = np.zeros(first.shape[0], bool)
    for two, ok, (p, s1, s2, _) in parallelogram_blocks(sorted_corners, first, count):
        edge_a, edge_b = s1 - p, s2 - p
        # Inset every side by ``inset`` (at most a quarter of the patch): corner + d_a a + d_b b.
        inset_here = inset if np.ndim(inset) == 0 else inset[two]
        d_a = np.minimum(inset_here / np.linalg.norm(edge_a, axis=1), 0.25)[:, None]
        d_b = np.minimum(inset_here / np.linalg.norm(edge_b, axis=1), 0.25)[:, None]
        corner = p + d_a * edge_a + d_b * edge_b
        corner += (offset if np.ndim(offset) == 0 else offset[two][:, None]) * normal[two]
        rows = two[ok]
        for start, values in ((0, corner), (3, (1 - 2 * d_a) * edge_a), (6, (1 - 2 * d_b) * edge_b)):
            out[start:start + 3, rows] = values[ok].T
        flags[rows] = True
    return flags


# Two-triangle patches are compared this many at a time (each on its own).
BLOCK_PATCHES = 1 << 15


def parallelogram_blocks(sorted_corners, first, count, block=None):
    """:func:`parallelogram_corners` a block of ``block`` (BLOCK_PATCHES) patches at a time:
    (patches (n,), whether each is a parallelogram (n,), (p, s1, s2, q)) for each block."""
    block = block or BLOCK_PATCHES
    two = np.flatnonzero(count == 2)
    for k in range(0, two.size, block):
        rows = two[k:k + block]
        ok, corners = _parallelogram_corners(sorted_corners, first[rows])
        yield rows, ok, corners


def parallelogram_corners(sorted_corners, first, count, block=None):
    """The corners of the patches made of two triangles: (patches with two triangles (n,),
    whether each is a parallelogram (n,), and its corners (p, s1, s2, q), each (n,3) float64).
    p is the first triangle's own corner, s1 and s2 the two corners the triangles share (the
    edges are a = s1 - p and b = s2 - p), q the second triangle's own corner (p + a + b to
    within rounding). ``sorted_corners[rows]`` gives triangles' corners (an array or
    triangles.UnitCorners); the patches are taken ``block`` at a time (each on its own)."""
    two = np.flatnonzero(count == 2)
    parts = [(ok, c) for _, ok, c in parallelogram_blocks(sorted_corners, first, count, block)]
    if not parts:
        return two, np.zeros(0, bool), tuple(np.zeros((0, 3)) for _ in range(4))
    return two, np.concatenate([ok for ok, _ in parts]), tuple(np.concatenate(c) for c in zip(*(c for _, c in parts)))


def _parallelogram_corners(sorted_corners, first):
    """parallelogram_corners of the patches whose two triangles start at ``first``."""
    t0 = np.asarray(sorted_corners[first], dtype=np.float64)  # (n,3,3)
    t1 = np.asarray(sorted_corners[first + 1], dtype=np.float64)
    tolerance = 1e-7  # unit space
    between = t0[:, :, None, :] - t1[:, None, :, :]  # (n,3,3,3): every corner of t0 to every corner of t1
    shared = np.einsum("...k,...k->...", between, between) < tolerance**2  # (n,3,3)
    shared_in_t0 = shared.any(axis=2)        # (n,3)
    shared_in_t1 = shared.any(axis=1)
    ok = (shared_in_t0.sum(axis=1) == 2) & (shared_in_t1.sum(axis=1) == 2) & (shared.sum(axis=(1, 2)) == 2)
    rows = np.arange(first.size)
    p = t0[rows, np.argmin(shared_in_t0, axis=1)]      # t0's own corner
    q = t1[rows, np.argmin(shared_in_t1, axis=1)]      # t1's own corner
    order = np.argsort(~shared_in_t0, axis=1, kind="stable")[:, :2]
    s1 = t0[rows, order[:, 0]]
    s2 = t0[rows, order[:, 1]]
    ok &= np.linalg.norm(p + q - s1 - s2, axis=1) < tolerance  # the diagonals bisect each other
    return ok, (p, s1, s2, q)
