"""Corners that share one evaluation of the direct light: a flat surface's inner points.

The display's direct light is taken at every corner of every patch (``point_direct``), each a
hundredth of the way in towards its patch's centre: where a wall stands on the floor along a
patch's edge, the floor's corners on either side of it see their own side. But most points of a
mesh lie inside one flat surface, clear of anything else: there the four patches round a point
took four estimates of one light, 4x the shadow rays of one, each with noise of its own, so the
corners of neighbouring patches differed at the same point by that noise.

Such a point now takes one estimate, at its corners' mean position (a hundredth of the way in
towards the mean of its patches' centres: on a grid, the point itself), which every corner at it
reads. A point qualifies where its corners are compatible (``Surface.smooth_point``: no crease,
the same side of a cover's outline), its patches lie in one plane and none of them runs into
another object (``visibility``'s buried parts: a corner inside it takes its own patch's corners
that are not, ``point_direct._fill_buried``), and two segments through it
along the surface (the two diagonals of its tangent plane, a ray offset above it, as long as its
corners' inward steps on either side) meet nothing: a wall or partition standing on the point, or
any surface as near as those steps, meets one of them, and the corners there keep their own.
"""
from __future__ import annotations

import numpy as np

from ..scene.visibility import tangents

COPLANAR = 1.0 - 1e-9  # the patches round a point lie in one plane: their normals' dot about this at least (_planes)
CLEAR_OFFSETS = 4.0  # a probe segment's half length at least this many ray offsets


def shared_rows(surface, g, point, patch, position, inward):
    """For corners (K,) at welded ``point`` (K,) of ``patch`` (K,), world ``position`` (K,3),
    sorted by point (``np.unique``'s keys): (rows (m,) the corners evaluated, ``read`` (K,) the
    row of ``rows`` each corner reads, ``towards`` (m,3) each evaluation's inward target: its
    patch's centre, or the mean of its point's patches' centres where they share it)."""
    K = len(point)
    if K == 0 or g.regions is not None:  # (regions: each traced in a frame of its own)
        return np.arange(K), np.arange(K), surface.patch_centroid[patch]
    starts = np.flatnonzero(np.r_[True, point[1:] != point[:-1]])
    count = np.diff(np.r_[starts, K])
    group = np.repeat(np.arange(starts.size), count)
    # (one plane a patch, by its normal: (K,) ids, not (K,3) normals: the memory of the largest scenes)
    plane = _planes(surface.patch_normal)
    apart = plane[patch] != plane[patch[starts]][group]
    if g.buried is not None:  # (a patch another object runs into keeps its own corners: _fill_buried's)
        apart |= np.isin(patch, np.concatenate([g.buried.patch, g.buried.whole]))
    candidate = surface.smooth_point[point[starts]] & (count > 1) & (np.bincount(group, weights=apart, minlength=starts.size) == 0)
    del apart
    if not candidate.any():
        return np.arange(K), np.arange(K), surface.patch_centroid[patch]
    centre = surface.patch_centroid[patch]
    squared = np.zeros(K)
    for k in range(3):  # (each corner's distance to its patch's centre, an axis at a time)
        squared += (centre[:, k] - position[:, k]) ** 2
    reach = np.zeros(starts.size)
    np.maximum.at(reach, group, inward * np.sqrt(squared))
    del squared
    ask = np.flatnonzero(candidate)
    candidate[ask[~_clear(g, position[starts[ask]], patch[starts[ask]], reach[ask])]] = False
    shared = candidate[group]
    first = np.zeros(K, bool)
    first[starts] = True
    evaluated = ~shared | first
    rows = np.flatnonzero(evaluated)
    read = np.cumsum(evaluated) - 1
    read[shared] = read[starts[group[shared]]]
    towards = centre[rows]
    at = np.flatnonzero(shared[rows])
    for k in range(3):  # (the mean of its point's patches' centres, an axis at a time)
        towards[at, k] = (np.bincount(group, weights=centre[:, k], minlength=starts.size) / count)[group[rows[at]]]
    return rows, read, towards


def _planes(normal):
    """(P,) int64 an id of each patch's normal direction (rounded to COPLANAR's tolerance): patches
    round one point with the same id lie in one plane."""
    step = np.sqrt(2.0 * (1.0 - COPLANAR))
    most = int(np.ceil(1.0 / step)) + 1
    key = np.round(np.asarray(normal, np.float64) / step).astype(np.int64) + most  # (0 .. 2 most, three of them in an int64)
    return (key[:, 0] * (2 * most + 1) + key[:, 1]) * (2 * most + 1) + key[:, 2]


def _clear(g, position, patch, reach):
    """(n,) bool: whether the two diagonal segments through each world point ``position`` (n,3)
    of ``patch``, a ray offset above it, ``reach`` (n,) (world) to either side (CLEAR_OFFSETS ray
    offsets at least), meet nothing."""
    normal = g.patch_normal_rows.take(patch, axis=1).astype(np.float64)
    offset = g.ray_offsets(patch, np.float64)
    x = ((position - g.centre) / g.diagonal).T + normal * offset
    half = np.maximum(reach / g.diagonal, CLEAR_OFFSETS * offset)
    a, b = tangents(normal)
    clear = np.ones(len(patch), bool)
    for d in ((a + b) / np.sqrt(2.0), (a - b) / np.sqrt(2.0)):
        origin = np.ascontiguousarray((x - d * half).T, dtype=np.float32)
        hit, _, _, t, _ = g.surface_tracer.first_hit_barycentric(origin, np.ascontiguousarray(d.T, dtype=np.float32))
        clear &= (hit < 0) | (t > 2.0 * half)
    return clear
