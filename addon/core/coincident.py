"""Coincident faces: where flush boxes touch or end in one plane, faces lie on each other.

A probe ray through such a place crosses two or more faces at the same distance (a wall standing
on a floor slab: the wall's bottom and the slab's top, opposite ways, net 0; a wall sunk into the
slab to its bottom: both bottoms, the same way, 2), but a ray tracer returns one of them, and a
winding count (:func:`.visibility.windings`) then misses the others. Here each traced triangle
knows the other triangles in its plane whose bounding boxes meet its own, and which way each
faces; a hit counts every one of them that holds the hit point strictly inside.
"""
from __future__ import annotations

import numpy as np

# Planes are the same within these (unit space: the scene's diagonal is 1).
NORMAL_TOLERANCE = 1e-5
OFFSET_TOLERANCE = 1e-6
# A point lies in a triangle within this barycentric margin (on a shared edge it is in both).
INSIDE_MARGIN = 1e-6
# Pairs of a plane's triangles examined at most (a plane's triangles squared; beyond, not examined).
MAX_PAIRS = 1 << 20  # (a plane of up to 1,024 triangles: the pair test's arrays stay ~40 MB)


class Contacts:
    """For the triangles (N,3,3) a tracer traces: ``first``/``partner`` (CSR) the coplanar
    triangles each may overlap, ``same`` whether each faces the same way; :meth:`faces_at` counts
    the faces a hit meets at once."""

    def __init__(self, corners):
        c = np.asarray(corners, dtype=np.float64)
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        length = np.linalg.norm(n, axis=1)
        ok = length > 0
        n[ok] /= length[ok, None]
        offset = np.einsum("ij,ij->i", n, c[:, 0])
        # the plane up to orientation: its normal's first clear component made positive
        lead = np.argmax(np.abs(n) > 0.5 / np.sqrt(3), axis=1)
        side = np.sign(n[np.arange(len(n)), lead])
        key = np.column_stack([np.round(side[:, None] * n / NORMAL_TOLERANCE),
                               np.round(side * offset / OFFSET_TOLERANCE)]).astype(np.int64)
        key[~ok] = np.iinfo(np.int64).min  # (no plane: never a contact)
        _, plane = np.unique(key, axis=0, return_inverse=True)
        plane = plane.ravel()
        self.corners = c
        pairs = []
        order = np.argsort(plane, kind="stable")
        cuts = np.flatnonzero(np.diff(plane[order])) + 1
        low, high = c.min(axis=1), c.max(axis=1)
        for group in np.split(order, cuts):
            if group.size < 2 or not ok[group[0]] or group.size ** 2 > MAX_PAIRS:
                continue
            a, b = np.repeat(group, group.size), np.tile(group, group.size)
            meet = (a != b) & np.all((low[a] <= high[b] + OFFSET_TOLERANCE) & (low[b] <= high[a] + OFFSET_TOLERANCE), axis=1)
            pairs.append(np.column_stack([a[meet], b[meet]]))
        pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
        self.first = np.searchsorted(pairs[:, 0], np.arange(len(c) + 1))
        self.partner = pairs[:, 1]
        self.same = side[pairs[:, 0]] == side[pairs[:, 1]]

    @property
    def any(self):
        return self.partner.size > 0

    def faces_at(self, triangle, points):
        """(n,) int: for each hit on ``triangle`` (n,) at ``points`` (n,3) float64, the faces
        met there counted as the hit face counts: 1 plus each coincident face facing the same
        way, minus each facing the other way (holding the point strictly inside)."""
        count = self.first[triangle + 1] - self.first[triangle]
        out = np.ones(len(triangle), np.int64)
        hit = np.repeat(np.arange(len(triangle)), count)
        if hit.size == 0:
            return out
        row = np.repeat(self.first[triangle] - np.cumsum(count) + count, count) + np.arange(hit.size)
        inside = _in_triangles(points[hit], self.corners[self.partner[row]])
        np.add.at(out, hit[inside], np.where(self.same[row[inside]], 1, -1))
        return out


def _in_triangles(p, tri):
    """(n,) bool: points p (n,3) in the planes of triangles tri (n,3,3) lie inside them, by
    more than INSIDE_MARGIN (a point on a shared edge is in neither)."""
    e1, e2, w = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], p - tri[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", x, y) for x, y in ((e1, e1), (e1, e2), (e2, e2)))
    w1, w2 = np.einsum("ij,ij->i", w, e1), np.einsum("ij,ij->i", w, e2)
    det = d11 * d22 - d12 * d12
    safe = np.where(det > 0, det, 1.0)
    v = (d22 * w1 - d12 * w2) / safe
    u = (d11 * w2 - d12 * w1) / safe
    return (det > 0) & (v > INSIDE_MARGIN) & (u > INSIDE_MARGIN) & (u + v < 1 - INSIDE_MARGIN)


def contacts_of(geometry):
    """The Contacts of ``geometry``'s surface tracer's triangles, made once."""
    made = geometry.__dict__.get("_contacts")
    if made is None:
        grids = geometry.patch_grids
        corners = grids.corners if grids is not None else geometry.triangle_corners
        if geometry.regions is not None:  # (each region traced in a frame of its own: not compared)
            corners = np.zeros((0, 3, 3))
        made = geometry.__dict__["_contacts"] = Contacts(corners)
    return made
