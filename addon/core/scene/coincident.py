"""Coincident faces: where flush boxes touch or end in one plane, faces lie on each other.

A probe ray through such a place crosses two or more faces at the same distance (a wall standing
on a floor slab: the wall's bottom and the slab's top, opposite ways, net 0; a wall sunk into the
slab to its bottom: both bottoms, the same way, 2), but a ray tracer returns one of them, and a
winding count (:func:`.visibility.windings`) then misses the others. Here each traced triangle
knows the other triangles in its plane whose bounding boxes meet its own, and which way each
faces; a hit counts every one of them that holds the hit point strictly inside. A triangle with many
partners (a floor slab under every wall and table standing on it) files them on a grid over its own
barycentric square, each in the cells its bounding box there covers: a hit tests its cell's only.
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
# Candidate pairs tested for overlap at once.
PAIR_BLOCK = 1 << 16
# A triangle's grid of its partners: cells a side, about the square root of its partners', at most.
MOST_GRID = 8


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
        pairs = []
        order = np.argsort(plane, kind="stable")
        cuts = np.flatnonzero(np.diff(plane[order])) + 1
        low, high = np.ascontiguousarray(c.min(axis=1).T), np.ascontiguousarray(c.max(axis=1).T)  # (3,N)
        starts, ends = np.concatenate([[0], cuts]), np.concatenate([cuts, [len(order)]])
        several = ends - starts > 1  # (a plane of two triangles or more)
        for start, end in zip(starts[several], ends[several]):
            group = order[start:end]
            if not ok[group[0]] or group.size ** 2 > MAX_PAIRS:
                continue
            a, b = np.repeat(group, group.size), np.tile(group, group.size)
            keep = a != b
            for axis in range(3):  # (an axis at a time, on the pairs still meeting: (m,) arrays, no (m,3))
                a, b = a[keep], b[keep]
                keep = (low[axis].take(a) <= high[axis].take(b) + OFFSET_TOLERANCE) & \
                    (low[axis].take(b) <= high[axis].take(a) + OFFSET_TOLERANCE)
            pairs.append(np.column_stack([a[keep], b[keep]]))
        pairs = np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)
        # only pairs whose insides overlap: a grid's neighbours share edges, and a hit tests each pair
        pairs = pairs[_overlapping(c, n, pairs)]
        pairs = pairs[np.argsort(pairs[:, 0], kind="stable")]
        self.first = np.searchsorted(pairs[:, 0], np.arange(len(c) + 1))
        self.partner = pairs[:, 1]
        self.same = side[pairs[:, 0]] == side[pairs[:, 1]]
        # each partner's barycentric rows, made once: a hit is then two dot products a partner
        self.origin, self.to_v, self.to_u = _barycentric_rows(c[self.partner])
        self._grid(c, pairs[:, 0])

    def _grid(self, corners, owner):
        """Each triangle's partners filed by cell of a G x G grid over its own barycentric square
        (G about the square root of its partners, MOST_GRID at most; 1 without partners):
        ``cell_start`` (N,) its first cell, ``side`` (N,) G, ``cell_first``/``cell_rows`` (CSR)
        the partner rows of each cell."""
        count = np.diff(self.first)
        self.side = np.clip(np.ceil(np.sqrt(count)), 1, MOST_GRID).astype(np.int64)
        self.cell_start = np.cumsum(self.side ** 2) - self.side ** 2
        has = np.flatnonzero(count > 0)
        self.own = tuple(np.zeros((len(count), 3)) for _ in range(3))
        if has.size:
            for mine, rows in zip(self.own, _barycentric_rows(corners[has])):
                mine[has] = rows
        # the partners' corners in their owner's barycentric frame: each one's box of cells
        w = corners[self.partner] - self.own[0][owner][:, None, :]
        v = np.einsum("pkj,pj->pk", w, self.own[1][owner])
        u = np.einsum("pkj,pj->pk", w, self.own[2][owner])
        g = self.side[owner]
        low_i, high_i = (np.clip(np.floor(x * g), 0, g - 1).astype(np.int64) for x in (v.min(axis=1), v.max(axis=1)))
        low_j, high_j = (np.clip(np.floor(x * g), 0, g - 1).astype(np.int64) for x in (u.min(axis=1), u.max(axis=1)))
        wide, tall = high_i - low_i + 1, high_j - low_j + 1
        per = wide * tall
        row = np.repeat(np.arange(len(owner)), per)
        k = np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)
        i, j = low_i[row] + k // tall[row], low_j[row] + k % tall[row]
        cell = self.cell_start[owner[row]] + i * g[row] + j
        order = np.argsort(cell, kind="stable")
        cells = int(self.cell_start[-1] + self.side[-1] ** 2) if len(count) else 0
        self.cell_first = np.searchsorted(cell[order], np.arange(cells + 1))
        self.cell_rows = row[order]

    def _cells(self, triangle, points):
        """(n,) the grid cell of each hit on ``triangle`` (n,) at ``points`` (n,3)."""
        w = points - self.own[0].take(triangle, axis=0)
        g = self.side.take(triangle)
        i = np.clip(np.floor(np.einsum("ij,ij->i", w, self.own[1].take(triangle, axis=0)) * g), 0, g - 1).astype(np.int64)
        j = np.clip(np.floor(np.einsum("ij,ij->i", w, self.own[2].take(triangle, axis=0)) * g), 0, g - 1).astype(np.int64)
        return self.cell_start.take(triangle) + i * g + j

    @property
    def any(self):
        return self.partner.size > 0

    def faces_at(self, triangle, points):
        """(n,) int: for each hit on ``triangle`` (n,) at ``points`` (n,3) float64, the faces
        met there counted as the hit face counts: 1 plus each coincident face facing the same
        way, minus each facing the other way (holding the point strictly inside)."""
        out = np.ones(len(triangle), np.int64)
        some = np.flatnonzero(self.first.take(triangle + 1) > self.first.take(triangle))
        if some.size == 0:
            return out
        triangle, points = triangle.take(some), points.take(some, axis=0)
        cell = self._cells(triangle, points)
        count = self.cell_first.take(cell + 1) - self.cell_first.take(cell)
        ends = np.cumsum(count)
        # a block of hits at a time, about PAIR_BLOCK pairs each: the pairs' arrays of a whole cast
        # (millions) went out to memory and back
        cuts = np.searchsorted(ends, np.arange(PAIR_BLOCK, ends[-1], PAIR_BLOCK), side="left")
        for a, b in zip(np.concatenate([[0], cuts]), np.concatenate([cuts, [len(triangle)]])):
            if b > a:
                out[some[a:b]] += self._met(cell[a:b], points[a:b], count[a:b])
        return out

    def _met(self, cell, points, count):
        """(n,) the coincident faces each hit (in ``cell``, with ``count`` partners filed there)
        meets, counted +1 facing the hit face's way, -1 the other."""
        hit = np.repeat(np.arange(len(cell)), count)
        if hit.size == 0:
            return 0
        row = self.cell_rows.take(np.repeat(self.cell_first.take(cell) - np.cumsum(count) + count, count) + np.arange(hit.size))
        w = points.take(hit, axis=0)
        w -= self.origin.take(row, axis=0)
        v = np.einsum("ij,ij->i", w, self.to_v.take(row, axis=0))
        near = np.flatnonzero((v > INSIDE_MARGIN) & (v < 1 - INSIDE_MARGIN))  # (u only where v may be inside)
        row, v = row.take(near), v.take(near)
        u = np.einsum("ij,ij->i", w.take(near, axis=0), self.to_u.take(row, axis=0))
        inside = (u > INSIDE_MARGIN) & (u + v < 1 - INSIDE_MARGIN)
        signs = np.where(self.same.take(row.compress(inside)), 1.0, -1.0)
        return np.bincount(hit.take(near).compress(inside), weights=signs, minlength=len(cell)).astype(np.int64)


def _overlapping(corners, normal, pairs):
    """(m,) bool: whether the coplanar triangles of each pair (m,2) overlap by more than
    OFFSET_TOLERANCE across every in-plane axis of their six edges (separating axes), a block of
    pairs at a time."""
    keep = np.zeros(len(pairs), bool)
    for start in range(0, len(pairs), PAIR_BLOCK):
        rows = pairs[start:start + PAIR_BLOCK]
        a, b, n = corners[rows[:, 0]], corners[rows[:, 1]], normal[rows[:, 0]]
        apart = np.zeros(len(a), bool)
        for tri in (a, b):
            for i in range(3):
                axis = np.cross(tri[:, (i + 1) % 3] - tri[:, i], n)
                axis /= np.maximum(np.linalg.norm(axis, axis=1), 1e-300)[:, None]
                pa, pb = np.einsum("nkj,nj->kn", a, axis), np.einsum("nkj,nj->kn", b, axis)  # (3,n): rows, not a short axis
                low_a, high_a = np.minimum(np.minimum(pa[0], pa[1]), pa[2]), np.maximum(np.maximum(pa[0], pa[1]), pa[2])
                low_b, high_b = np.minimum(np.minimum(pb[0], pb[1]), pb[2]), np.maximum(np.maximum(pb[0], pb[1]), pb[2])
                apart |= (high_a <= low_b + OFFSET_TOLERANCE) | (high_b <= low_a + OFFSET_TOLERANCE)
        keep[start:start + PAIR_BLOCK] = ~apart
    return keep


def _barycentric_rows(tri):
    """For triangles tri (n,3,3) of positive area: (origin, to_v, to_u) (n,3) each, so that a
    point p in a triangle's plane is p = origin + v e1 + u e2 with v = (p - origin) . to_v and
    u = (p - origin) . to_u (e1, e2 its edges from the first corner)."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d11, d12, d22 = (np.einsum("ij,ij->i", x, y)[:, None] for x, y in ((e1, e1), (e1, e2), (e2, e2)))
    det = d11 * d22 - d12 * d12
    return tri[:, 0].copy(), (d22 * e1 - d12 * e2) / det, (d11 * e2 - d12 * e1) / det


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
