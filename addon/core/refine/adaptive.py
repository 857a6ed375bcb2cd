"""Adaptive patches: splitting chosen patches of a patch mesh where the light changes.

A patch mesh's quads and triangles are *cells*: a cell splits into four (a quad 2 x 2 at its
edges' midpoints and its centre, a triangle at its edges' midpoints), its children split again,
and so on. Cells that meet along an edge differ by at most one split (a balanced, or
restricted, quadtree: splitting a cell first splits its coarser neighbours), so that an unsplit
cell has at most one extra point on each edge: the midpoint its finer neighbour made. That
point becomes one of its polygon's corners (a planar n-gon, collinear corner included), so the
written mesh has no T-junction: every edge inside a surface has two polygons, and smooth colours
are continuous across it. A patch stays coplanar triangles: each polygon with extra points is
triangulated by a fixed pattern of its own (:func:`.patterns.pattern`), no triangle of zero
area, and started where Blender's own triangulation of it has none either (but a quad with
midpoints on two opposite edges, which no start saves).

Faces kept whole as n-gons (more than four corners) never split, and neither do the cells
that share an edge with them (their midpoints would land on the n-gon's edge). Cells of
different objects are never joined: where two objects' patches touch, refinement on one side
leaves the other's edge as it was (the smoothing joins them by position as before).

Where to split: :mod:`.adaptive_light`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..mesh.faces import ranks_in_runs, starts_of, triangle_areas
from ..mesh.meshing import PatchMesh
from .patterns import pattern

KEY = np.int64(1) << np.int64(31)  # edge key: smaller point * KEY + larger point


def edge_keys(a, b):
    a = np.asarray(a, np.int64)
    b = np.asarray(b, np.int64)
    return np.minimum(a, b) * KEY + np.maximum(a, b)


@dataclass
class Cells:
    """One object's patches as cells of a refinement.

    points   (N,3) float64  the mesh's points, the new midpoints and centres appended
    corners  (L,4) int64    each cell's own corners (a triangle's fourth is -1)
    level    (L,)  int32    splits from the first patch
    origin   (L,)  int64    the first mesh's patch each cell lies in
    face     (L,)  int64    its source face
    frozen   (L,)  bool     never split (an n-gon, or a cell beside one)
    mid_keys, mid_points    sorted edge keys that have a midpoint, and its point
    half_keys, half_parent  sorted keys of edges made by halving, and the edge each halves
    base                    the first PatchMesh (its patches' polygons and triangles)
    """

    points: np.ndarray
    corners: np.ndarray
    level: np.ndarray
    origin: np.ndarray
    face: np.ndarray
    frozen: np.ndarray
    base: PatchMesh
    mid_keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    mid_points: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    half_keys: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    half_parent: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def count(self):
        return len(self.level)

    @property
    def is_quad(self):
        return self.corners[:, 3] >= 0

    def edges(self):
        """(cell (E,), edge key (E,), first point, second point, edge number): every cell's own
        edges, n-gons (frozen, no corners) left out."""
        quad = self.is_quad
        valid = self.corners[:, 0] >= 0
        cells, number, a, b = [], [], [], []
        for k in range(4):
            idx = np.flatnonzero(valid & quad) if k == 3 else np.flatnonzero(valid)
            if k < 2:
                second = self.corners[idx, k + 1]
            elif k == 2:
                second = np.where(quad[idx], self.corners[idx, 3], self.corners[idx, 0])
            else:
                second = self.corners[idx, 0]
            cells.append(idx)
            number.append(np.full(idx.size, k))
            a.append(self.corners[idx, k])
            b.append(second)
        cells, number, a, b = (np.concatenate(x) for x in (cells, number, a, b))
        return cells, edge_keys(a, b), a, b, number


def cells_of(mesh: PatchMesh) -> Cells:
    """The patches of ``mesh`` as unsplit cells (level 0): quads and triangles; n-gons and the
    cells sharing an edge with one frozen."""
    sizes = np.asarray(mesh.face_sizes, np.int64)
    starts = starts_of(sizes)
    P = len(sizes)
    corners = np.full((P, 4), -1, np.int64)
    verts = np.asarray(mesh.corner_verts, np.int64)
    small = np.flatnonzero(sizes <= 4)
    for k in range(4):
        has = small[sizes[small] > k]
        corners[has, k] = verts[starts[has] + k]
    frozen = sizes > 4
    if frozen.any():
        # every edge of an n-gon: the cells with that edge are frozen too
        big = np.flatnonzero(frozen)
        rank = ranks_in_runs(sizes[big])
        first = np.repeat(starts[big], sizes[big])
        size = np.repeat(sizes[big], sizes[big])
        a = verts[first + rank]
        b = verts[first + (rank + 1) % size]
        ngon_keys = np.unique(edge_keys(a, b))
        probe = Cells(np.asarray(mesh.points), corners, np.zeros(P, np.int32), np.arange(P), np.asarray(mesh.patch_face, np.int64),
                      frozen, mesh)
        cell, key, *_ = probe.edges()
        hit = np.isin(key, ngon_keys)
        frozen[cell[hit]] = True
    return Cells(np.array(mesh.points, np.float64), corners, np.zeros(P, np.int32), np.arange(P, dtype=np.int64),
                 np.asarray(mesh.patch_face, np.int64), frozen, mesh)


def _lookup(sorted_keys, keys):
    """(index of each of ``keys`` in ``sorted_keys``, found (bool))."""
    at = np.searchsorted(sorted_keys, keys)
    at = np.minimum(at, max(len(sorted_keys) - 1, 0))
    found = (sorted_keys[at] == keys) if len(sorted_keys) else np.zeros(len(keys), bool)
    return at, found


def coarser_neighbours(cells: Cells, chosen):
    """(L,) bool: the cells across an edge of a chosen cell that are one split coarser (the
    chosen cell's edge halves theirs)."""
    cell, key, *_ = cells.edges()
    mine = chosen[cell]
    at, halved = _lookup(cells.half_keys, key[mine])
    parents = cells.half_parent[at[halved]]
    out = np.zeros(cells.count, bool)
    if parents.size:
        has = np.isin(key, parents)
        out[cell[has]] = True
    return out


def finer_neighbours(cells: Cells, chosen):
    """(L,) bool: the cells whose edge halves an edge of a chosen cell."""
    cell, key, *_ = cells.edges()
    at, halved = _lookup(cells.half_keys, key)
    out = np.zeros(cells.count, bool)
    chosen_keys = key[chosen[cell]]
    if chosen_keys.size and halved.any():
        parent = cells.half_parent[at[halved]]
        has = np.isin(parent, chosen_keys)
        out[cell[np.flatnonzero(halved)[has]]] = True
    return out


def balanced(cells: Cells, marked):
    """The cells to split so that ``marked`` ones split and neighbours still differ by at most
    one split: marked cells' coarser neighbours too (repeatedly); marks that would need a
    frozen cell split are dropped."""
    marked = np.asarray(marked, bool) & ~cells.frozen
    while True:
        closed = marked.copy()
        while True:
            more = coarser_neighbours(cells, closed) & ~closed
            if not more.any():
                break
            closed |= more
        bad = closed & cells.frozen
        if not bad.any():
            return closed
        # drop every mark that leads to a frozen cell: the finer cells around it, repeatedly
        drop = bad.copy()
        while True:
            more = finer_neighbours(cells, drop) & ~drop
            if not more.any():
                break
            drop |= more
        marked &= ~drop


def _midpoints(cells: Cells, a, b):
    """(n,) the midpoint of each edge (a, b), made where it is new: (cells with the points and
    maps grown, the midpoints)."""
    key = edge_keys(a, b)
    at, found = _lookup(cells.mid_keys, key)
    out = np.empty(len(key), np.int64)
    out[found] = cells.mid_points[at[found]]
    new_keys, first, inverse = np.unique(key[~found], return_index=True, return_inverse=True)
    if new_keys.size:
        na = np.asarray(a, np.int64)[~found][first]
        nb = np.asarray(b, np.int64)[~found][first]
        lo, hi = np.minimum(na, nb), np.maximum(na, nb)
        start = len(cells.points)
        new_points = start + np.arange(new_keys.size, dtype=np.int64)
        points = np.vstack([cells.points, 0.5 * (cells.points[lo] + cells.points[hi])])
        out[~found] = new_points[inverse]
        mid_keys = np.concatenate([cells.mid_keys, new_keys])
        mid_points = np.concatenate([cells.mid_points, new_points])
        order = np.argsort(mid_keys, kind="stable")
        halves = np.concatenate([edge_keys(lo, new_points), edge_keys(new_points, hi)])
        half_keys = np.concatenate([cells.half_keys, halves])
        half_parent = np.concatenate([cells.half_parent, new_keys, new_keys])
        horder = np.argsort(half_keys, kind="stable")
        cells = replace(cells, points=points, mid_keys=mid_keys[order], mid_points=mid_points[order],
                        half_keys=half_keys[horder], half_parent=half_parent[horder])
    return cells, out


def split(cells: Cells, marked, balance=True):
    """Split the marked cells (with ``balance``, also what :func:`balanced` adds): (the new
    cells, the old cell each new cell lies in (L',))."""
    marked = balanced(cells, marked) if balance else (np.asarray(marked, bool) & ~cells.frozen)
    chosen = np.flatnonzero(marked)
    if chosen.size == 0:
        return cells, np.arange(cells.count)
    c = cells.corners[chosen]
    quad = c[:, 3] >= 0
    q, t = chosen[quad], chosen[~quad]
    cq, ct = c[quad], c[~quad]
    # every edge's midpoint at once: quads' four edges, then triangles' three
    a = np.concatenate([cq[:, 0], cq[:, 1], cq[:, 2], cq[:, 3], ct[:, 0], ct[:, 1], ct[:, 2]])
    b = np.concatenate([cq[:, 1], cq[:, 2], cq[:, 3], cq[:, 0], ct[:, 1], ct[:, 2], ct[:, 0]])
    cells, mids = _midpoints(cells, a, b)
    nq, nt = len(q), len(t)
    mq = mids[: 4 * nq].reshape(4, nq).T
    mt = mids[4 * nq:].reshape(3, nt).T
    centre = len(cells.points) + np.arange(nq, dtype=np.int64)
    points = np.vstack([cells.points, cells.points[cq].mean(axis=1)]) if nq else cells.points
    no = np.full(nt, -1, np.int64)
    children = [
        np.stack([cq[:, 0], mq[:, 0], centre, mq[:, 3]], axis=1),
        np.stack([mq[:, 0], cq[:, 1], mq[:, 1], centre], axis=1),
        np.stack([centre, mq[:, 1], cq[:, 2], mq[:, 2]], axis=1),
        np.stack([mq[:, 3], centre, mq[:, 2], cq[:, 3]], axis=1),
        np.stack([ct[:, 0], mt[:, 0], mt[:, 2], no], axis=1),
        np.stack([mt[:, 0], ct[:, 1], mt[:, 1], no], axis=1),
        np.stack([mt[:, 2], mt[:, 1], ct[:, 2], no], axis=1),
        np.stack([mt[:, 0], mt[:, 1], mt[:, 2], no], axis=1),
    ]
    parent_of_child = np.concatenate([q, q, q, q, t, t, t, t])
    keep = np.flatnonzero(~marked)
    parent = np.concatenate([keep, parent_of_child])
    corners = np.concatenate([cells.corners[keep], *children])
    # cells in the first mesh's patch order, each patch's cells in the order made
    order = np.argsort(cells.origin[parent], kind="stable")
    parent = parent[order]
    out = replace(
        cells, points=points, corners=corners[order],
        level=(cells.level[parent] + np.isin(parent, chosen)).astype(np.int32),
        origin=cells.origin[parent], face=cells.face[parent], frozen=cells.frozen[parent],
    )
    return out, parent


def _midpoint_masks(cells: Cells, conforming):
    """((L,) bits of the edges of each cell that carry a midpoint, (L,4) those midpoints or -1)."""
    L = cells.count
    mask = np.zeros(L, np.int64)
    mid = np.full((L, 4), -1, np.int64)
    if conforming and len(cells.mid_keys):
        cell, key, _, _, number = cells.edges()
        at, found = _lookup(cells.mid_keys, key)
        np.bitwise_or.at(mask, cell[found], np.left_shift(1, number[found]))
        mid[cell[found], number[found]] = cells.mid_points[at[found]]
    return mask, mid


def _polygons(cells: Cells, rest, mask, mid):
    """Per pattern (corner count, midpoint bits) of the cells ``rest``: (cells, (n,k) polygon
    corners, (n,t,3) its triangles)."""
    kinds = np.where(cells.is_quad[rest], 4, 3) * 16 + mask[rest]
    out = []
    for kind in np.unique(kinds):
        members = rest[kinds == kind]
        polygon, triangles = pattern(*divmod(int(kind), 16))
        local = np.empty((len(members), 8), np.int64)
        local[:, 0::2] = cells.corners[members]
        local[:, 1::2] = mid[members]
        corners = local[:, list(polygon)]
        out.append((members, corners, corners[:, triangles]))
    return out


def patch_mesh(cells: Cells, conforming=True):
    """(PatchMesh of the cells, the first mesh's patch of each patch): one patch a cell, in cell
    order. ``conforming``: a cell takes its neighbours' midpoints on its edges as corners (no
    T-junction); else each cell is its own corners (for estimates that need no welded mesh).
    The patches' triangles are each cell's own (the core's); ``shading_triangles`` and
    ``shading_triangle_patch`` on the mesh triangulate the polygons, midpoints included.
    Unsplit cells of the first mesh without such points keep its polygon and triangles."""
    L, base, quad = cells.count, cells.base, cells.is_quad
    mask, mid = _midpoint_masks(cells, conforming)
    first = cells.level == 0
    kept = np.flatnonzero(first & (mask == 0))
    polygons = _polygons(cells, np.flatnonzero(~first | (mask != 0)), mask, mid)
    sizes = np.zeros(L, np.int64)
    base_sizes = np.asarray(base.face_sizes, np.int64)
    sizes[kept] = base_sizes[cells.origin[kept]]
    for members, corners, _ in polygons:
        sizes[members] = corners.shape[1]
    starts = starts_of(sizes)
    corner_verts = np.empty(int(sizes.sum()), np.int64)
    rank = ranks_in_runs(sizes[kept])
    corner_verts[np.repeat(starts[kept], sizes[kept]) + rank] = np.asarray(base.corner_verts, np.int64)[
        np.repeat(starts_of(base_sizes)[cells.origin[kept]], sizes[kept]) + rank]
    for members, corners, _ in polygons:
        corner_verts[(starts[members][:, None] + np.arange(corners.shape[1])).ravel()] = corners.ravel()
    # the core's triangles: each cell's own (a grid cell's two, a parallelogram where it was one),
    # which cover the polygon whatever midpoints its edges carry
    own = [(members, cells.corners[members][:, :count][:, pattern(count, 0)[1]])
           for count, members in ((4, np.flatnonzero(~first & quad)), (3, np.flatnonzero(~first & ~quad)))]
    triangles, triangle_patch = _triangulation(L, base, cells.origin, np.flatnonzero(first), own)
    # the shading's: the polygon's own corners, midpoints included (smooth colours need them)
    shading = _triangulation(L, base, cells.origin, kept, [(members, tris) for members, _, tris in polygons])
    area = np.bincount(triangle_patch, weights=triangle_areas(cells.points, triangles), minlength=L)
    mesh = PatchMesh(cells.points, sizes.astype(np.int32), corner_verts.astype(np.int32), cells.face.astype(np.int32),
                     triangles.astype(np.int32), triangle_patch.astype(np.int32), area)
    mesh.shading_triangles = shading[0].astype(np.int32)
    mesh.shading_triangle_patch = shading[1].astype(np.int32)
    return mesh, cells.origin.copy()


def _triangulation(count, base, origin, from_base, parts):
    """(triangles (T,3), patch of each (T,)) sorted by patch: the first mesh's triangles for the
    cells ``from_base`` (unsplit first patches), and ``parts`` (cells, (n,t,3) triangles)."""
    tri_parts, patch_parts = [], []
    if from_base.size:
        base_tp = np.asarray(base.triangle_patch, np.int64)
        patch_of_base = np.full(base.patch_count, -1, np.int64)
        patch_of_base[origin[from_base]] = from_base
        rows = np.flatnonzero(patch_of_base[base_tp] >= 0)
        tri_parts.append(np.asarray(base.triangles, np.int64)[rows])
        patch_parts.append(patch_of_base[base_tp[rows]])
    for members, tris in parts:
        if len(members):
            tri_parts.append(tris.reshape(-1, 3))
            patch_parts.append(np.repeat(members, tris.shape[1]))
    triangles = np.concatenate(tri_parts) if tri_parts else np.zeros((0, 3), np.int64)
    triangle_patch = np.concatenate(patch_parts) if patch_parts else np.zeros(0, np.int64)
    order = np.argsort(triangle_patch, kind="stable")
    return triangles[order], triangle_patch[order]


def shading_triangulation(mesh):
    """(triangles, patch of each) the smooth colours are made on: a refined mesh's triangles with
    every polygon corner (its neighbours' midpoints included), else the mesh's own."""
    if getattr(mesh, "shading_triangles", None) is not None:
        return mesh.shading_triangles, mesh.shading_triangle_patch
    return mesh.triangles, mesh.triangle_patch


def refine(mesh: PatchMesh, marked, cells: Cells | None = None):
    """Split the ``marked`` patches of ``mesh`` (and what balance needs): (the refined PatchMesh,
    the first mesh's patch of each refined patch, its Cells for further splits)."""
    cells = cells_of(mesh) if cells is None else cells
    cells, _ = split(cells, marked)
    refined, origin = patch_mesh(cells)
    return refined, origin, cells
