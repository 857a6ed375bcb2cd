"""Which patches some surface crosses (the only ones that can be partly buried,
:mod:`.visibility`): rays in the plane just above each patch that meet something short of its
edges. A parallelogram's two diagonals are cut by any line across it, and where parallelograms
tile a grid (:mod:`.patch_grids`) their diagonals line up into the grid's diagonal lines, one ray
each; other patches: each edge of their triangles.
"""
from __future__ import annotations

import numpy as np

# The in-plane rays stop this share of the patch short of its edges (surfaces that touch a patch
# along its boundary, a wall standing on a floor's patch edge, are not crossings).
EDGE_SHARE = 1e-3
# Surfaces a ray along a grid's diagonal line is traced through at most.
MAX_CROSSINGS = 64
# Rays per tracer call.
BLOCK_RAYS = 1 << 18


def _meets_within(g, origins, directions, patch):
    """(n,) bool for (3,n) float32 rays from points of ``patch``: they meet a surface before
    t = 1 (the end of the direction vector)."""
    n = origins.shape[1]
    out = np.zeros(n, bool)
    tracer = g.surface_tracer
    for start in range(0, n, BLOCK_RAYS):
        block = slice(start, min(n, start + BLOCK_RAYS))
        o = np.ascontiguousarray(origins[:, block].T, dtype=np.float32)
        d = np.ascontiguousarray(directions[:, block].T, dtype=np.float32)
        hit, _, _, t, _ = tracer.first_hit_barycentric(o, d, g.region_of(patch[block]))
        out[block] = (hit >= 0) & (t < 1.0)
    return out


def crossed_patches(geometry):
    """(m,) int the patches some surface crosses: in-plane rays just above each meet something
    short of its edges. A parallelogram's two diagonals are cut by any line across it; where
    parallelograms tile a grid (:mod:`.patch_grids`) their diagonals line up into the grid's
    diagonal lines, one ray each (traced on past every hit), so a wall of n x m patches costs
    about 2 (n + m) rays instead of 2 n m. Other patches: each edge of their triangles."""
    g = geometry
    crossed = np.zeros(g.patch_count, bool)
    grids = g.patch_grids
    on_grid = np.zeros(g.patch_count, bool)
    if grids is not None and grids.rectangles:
        on_grid[grids.cell_patch[:-1][grids.cell_patch[:-1] >= 0]] = True
        on_grid[grids.cell_patch[_other_cells(grids)]] = False
        _grid_crossings(g, grids, crossed)
    para = np.flatnonzero(g.patch_parallelogram & ~on_grid)
    e = EDGE_SHARE
    for start in range(0, para.size, BLOCK_RAYS // 2):
        patch = para[start:start + BLOCK_RAYS // 2]
        frame = g.parallelogram_frame.take(patch, axis=1).astype(np.float64)
        corner, a, b = frame[0:3], frame[3:6], frame[6:9]
        starts = np.hstack([corner + e * (a + b), corner + (1 - e) * a + e * b])
        ends = np.hstack([corner + (1 - e) * (a + b), corner + e * a + (1 - e) * b])
        two = np.concatenate([patch, patch])
        hit = _meets_within(g, starts.astype(np.float32), (ends - starts).astype(np.float32), two)
        crossed[two[hit]] = True
    other = np.flatnonzero(~g.patch_parallelogram[g.triangle_patch])
    for start in range(0, other.size, BLOCK_RAYS // 3):
        rows = other[start:start + BLOCK_RAYS // 3]
        frame = g.frames_of(rows).astype(np.float64)
        p0 = frame[0:3]
        corners = [p0, p0 + frame[3:6], p0 + frame[6:9]]
        centroid = sum(corners) / 3
        corners = [centroid + (1 - e) * (c - centroid) for c in corners]
        starts = np.hstack(corners)
        ends = np.hstack(corners[1:] + corners[:1])
        patch = np.tile(g.triangle_patch.take(rows), 3)
        hit = _meets_within(g, starts.astype(np.float32), (ends - starts).astype(np.float32), patch)
        crossed[patch[hit]] = True
    return np.flatnonzero(crossed)


def _other_cells(grids):
    """The cells of patches traced as their own triangles (one-cell grids after the rectangles)."""
    first = grids.cell_table[6, 2 * grids.rectangles:-1].astype(np.int64)
    return np.unique(first)


def _diagonal_lines(grids):
    """The grids' rectangles (corner c00, edges A and B, cells n_a x n_b, first cell, normal) and
    their lattices' diagonal lines, each rectangle's s - t = k and s + t = k in lattice units (s
    along A, t along B), as (rectangle, s0, s1, t0, t1) from end to end, EDGE_SHARE of a cell
    short of the rectangle's sides."""
    R = grids.rectangles
    tri = grids.corners[0:2 * R:2].astype(np.float64)  # (c00, end_a, c11) of each rectangle
    c00, end_a, c11 = tri[:, 0], tri[:, 1], tri[:, 2]
    A, B = end_a - c00, c11 - end_a
    n_a = grids.cell_table[2, 0:2 * R:2].astype(np.int64)
    n_b = grids.cell_table[3, 0:2 * R:2].astype(np.int64)
    first = grids.cell_table[6, 0:2 * R:2].astype(np.int64)
    normal = np.cross(A, B)
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    e = EDGE_SHARE
    lines = n_a + n_b - 1  # s - t = k, k from -(n_b - 1) to n_a - 1; s + t = k, k from 1 to n_a + n_b - 1
    rect = np.repeat(np.arange(R), 2 * lines)
    k_start = np.concatenate([np.concatenate([-(n_b[r] - 1) + np.arange(lines[r]), 1 + np.arange(lines[r])]) for r in range(R)])
    anti = np.concatenate([np.repeat([False, True], lines[r]) for r in range(R)])
    na, nb = n_a[rect].astype(np.float64), n_b[rect].astype(np.float64)
    k = k_start.astype(np.float64)
    # Along s - t = k: s from max(k, 0) to min(n_a, n_b + k); along s + t = k: s from max(0, k - n_b) to min(n_a, k).
    s0 = np.where(anti, np.maximum(0, k - nb), np.maximum(k, 0))
    s1 = np.where(anti, np.minimum(na, k), np.minimum(na, nb + k))
    t0 = np.where(anti, k - s0, s0 - k)
    t1 = np.where(anti, k - s1, s1 - k)
    sign_t = np.where(anti, -1.0, 1.0)  # (both ends moved in along the line by e in s and t)
    s0, s1 = s0 + e, s1 - e
    t0, t1 = t0 + sign_t * e, t1 - sign_t * e
    keep = s1 > s0
    return c00, A, B, n_a, n_b, first, normal, rect[keep], s0[keep], s1[keep], t0[keep], t1[keep]


def _grid_crossings(g, grids, crossed):
    """Marks in ``crossed`` the cells of the grids' rectangles that a surface crosses: rays along
    every diagonal line of each rectangle's lattice (cells' diagonals end to end), pushed off
    along its normal and stopping EDGE_SHARE of a cell short of the rectangle's sides, traced on
    past each hit; a hit inside a cell (farther than EDGE_SHARE from its sides) marks it."""
    c00, A, B, n_a, n_b, first, normal, rect, s0, s1, t0, t1 = _diagonal_lines(grids)
    e = EDGE_SHARE
    a, b = A[rect] / n_a[rect, None], B[rect] / n_b[rect, None]  # (one cell's edges)
    start = c00[rect] + s0[:, None] * a + t0[:, None] * b + g.ray_offset * normal[rect]
    span = (s1 - s0)[:, None] * a + (t1 - t0)[:, None] * b
    o = start.copy()
    live = np.arange(rect.size)
    done = np.zeros(rect.size)  # the share of each line traced so far
    tracer = grids.tracer
    for _ in range(MAX_CROSSINGS):
        if live.size == 0:
            break
        d32 = span[live].astype(np.float32)
        hit, _, _, t, _ = tracer.first_hit_barycentric(o[live].astype(np.float32), d32)
        at = done[live] + t  # (the direction is the whole span: t is a share of the line)
        met = (hit >= 0) & (at < 1.0)
        live, at = live[met], at[met]
        if live.size == 0:
            break
        r = rect[live]
        s = s0[live] + at * (s1[live] - s0[live])
        tt = t0[live] + at * (t1[live] - t0[live])
        # A hit on a cell's side is a surface touching the cells there (a box standing on the
        # lattice); one that crosses a cell also crosses its diagonals away from its sides.
        inner = (np.abs(s - np.round(s)) > e) & (np.abs(tt - np.round(tt)) > e)
        i = np.clip(np.floor(s), 0, n_a[r] - 1).astype(np.int64)
        j = np.clip(np.floor(tt), 0, n_b[r] - 1).astype(np.int64)
        patch = grids.cell_patch[(first[r] + i * n_b[r] + j)[inner]]
        crossed[patch[patch >= 0]] = True
        step = g.ray_offset / np.linalg.norm(span[live], axis=1)
        done[live] = at + step
        o[live] = start[live] + done[live][:, None] * span[live]
    return crossed
