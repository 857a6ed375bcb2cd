"""Subdividing planned faces into patches, with points shared where neighbouring faces agree.

Grid and triangle templates; points keyed by where they lie on the source mesh (a source vertex,
a fraction of a source edge, or an interior point), so that neighbouring faces share the points
their subdivisions agree on.

The work is vectorised: faces are grouped by subdivision shape and every group is handled with
array operations (the only Python loops run over distinct subdivision counts, never over faces).
"""

from __future__ import annotations

import numpy as np

from .faces import ranks_in_runs, triangle_subdivisions

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


class Builder:
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


def weld(keys, n_vertices):
    """Merge generated points with equal keys.

    Returns (unique key rows, index of the first generated point of each,
    output point of every generated point).  Interior points (kind 2) are
    unique by construction; the others are welded through one int64 code
    per key (a 1-D sort instead of a row-wise one).
    """
    kind = keys[:, 0]
    shared = np.flatnonzero(kind != 2)
    interior = np.flatnonzero(kind == 2)
    k = keys if shared.size == len(keys) else keys[shared]  # (no copy where no point is interior)
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



def add_kept_faces(b, plan, points, face_sizes, corner_verts):
    """Faces kept whole: their corners are source vertices."""
    kept_face, starts = plan.kept_face, plan.starts
    kept = np.nonzero(kept_face)[0]
    if len(kept):
        ksizes = face_sizes[kept]
        corner_idx = np.repeat(starts[kept], ksizes) + ranks_in_runs(ksizes)
        verts = corner_verts[corner_idx]
        first = b.add_points(_vertex_keys(verts), points[verts])
        b.add_faces(ksizes, first + np.arange(len(verts)), kept, kept * 0)


def add_grids(b, plan, points):
    """Quads cut into grids of bilinear cells, grouped by grid shape."""
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
            # boundary points lie on source edges; corners are source vertices
            edges = (
                (j == 0, 0, 1, i, n),  # edge 0 -> 1, fraction i/n
                (j == m, 3, 2, i, n),  # edge 3 -> 2, fraction i/n
                (i == 0, 0, 3, j, m),  # edge 0 -> 3, fraction j/m
                (i == n, 1, 2, j, m),  # edge 1 -> 2, fraction j/m
            )
            nc = len(cells)
            _add_subdivided(b, qs, pos, edges, cells, 4, np.repeat(quads[sel], nc), np.tile(np.arange(nc), len(sel)))

def add_triangles(b, plan, points, face_triangles, triangle_face):
    """Triangles (of n-gons and non-planar faces too) cut into n^2 triangles each."""
    limit = plan.limit
    tri_sel = np.nonzero(plan.cut)[0]
    if len(tri_sel):
        t = face_triangles[tri_sel]
        tf = triangle_face[tri_sel]
        if np.any(np.diff(tf) < 0):
            srt = np.argsort(tf, kind="stable")
            t, tf = t[srt], tf[srt]
        p = points[t]
        n_t = triangle_subdivisions(points, t, limit)
        # rank of each triangle inside its face, to keep patches in face order
        order_in_face = np.arange(len(tf)) - np.searchsorted(tf, tf)
        for n in np.unique(n_t):
            sel = np.nonzero(n_t == n)[0]
            ts, ps = t[sel], p[sel]
            i, j, subs = _triangle_template(int(n))
            w1 = (i / n)[None, :, None]
            w2 = (j / n)[None, :, None]
            pos = (1 - w1 - w2) * ps[:, None, 0] + w1 * ps[:, None, 1] + w2 * ps[:, None, 2]
            edges = (
                (j == 0, 0, 1, i, int(n)),  # edge 0 -> 1 at i/n
                (i == 0, 0, 2, j, int(n)),  # edge 0 -> 2 at j/n
                (i + j == n, 1, 2, j, int(n)),  # edge 1 -> 2 at j/n
            )
            ns = len(subs)
            order = np.repeat(order_in_face[sel] * (int(n_t.max()) ** 2 + 1), ns) + np.tile(np.arange(ns), len(sel))
            _add_subdivided(b, ts, pos, edges, subs, 3, np.repeat(tf[sel], ns), order)


def _add_subdivided(b, source_corners, pos, edges, cells, sides, face, order):
    """G faces subdivided alike: their points ((G,K,3) ``pos``) keyed as interior points, or, for
    each (mask, a, c, num, den) of ``edges``, as the point at num/den of the source edge from
    corner a to corner c of ``source_corners`` (G,corners); then the ``cells`` (local point
    indices, ``sides`` corners each) as faces with their source ``face`` and ``order``."""
    G, K = pos.shape[:2]
    keys = b.interior_keys(G * K).reshape(G, K, 5)
    for mask, a, c, num, den in edges:
        cnt = int(mask.sum())
        ek = _edge_point_keys(
            np.repeat(source_corners[:, a], cnt),
            np.repeat(source_corners[:, c], cnt),
            np.tile(num[mask], G),
            np.full(G * cnt, den),
        )
        keys[:, mask] = ek.reshape(G, cnt, 5)
    first = b.add_points(keys.reshape(-1, 5), pos.reshape(-1, 3))
    corners = first + (np.arange(G)[:, None, None] * K + cells[None]).reshape(-1)
    b.add_faces(np.full(G * len(cells), sides, dtype=np.int64), corners, face, order)
