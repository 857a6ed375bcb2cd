"""The ray tracer's scene for the walks: parallelogram patches merged back into grids.

Meshing cuts a face into a grid of patches, and a walk must know which patch each ray hits;
but the ray tracer need not see the patches. Patches that tile a parallelogram as a regular
grid (a wall, a box's side) are traced as that parallelogram, two triangles, and the patch
of a hit is its grid cell. In the figure 4 room that is 196 triangles instead of 133,144:
Embree's scene is a few kB instead of about 10 MB, and it traces faster. Patches that are not
parallelograms (triangles, other quads) are traced as their own triangles, each a grid of one
cell, beside the grids.

A grid with corners c00, c10, c01, c11 (cells n_a along c10 - c00, n_b along c01 - c00) is
the triangles (c00, c10, c11) and (c00, c11, c01). Embree's barycentric (u, v) of a hit puts
it at c00 + s (c10 - c00) + t (c01 - c00), with (s, t) = (u + v, v) on the first triangle and
(u, u + v) on the second; its cell is (floor(s n_a), floor(t n_b)). The corners are ordered
so that Embree's geometric normal Ng of both triangles points to the patches' front side: a
walk's facing test is the sign of direction . Ng, for grid and own triangles alike.

The grids are found from the patches alone: patches with the same edges a and b (to within
GRID_QUANTUM) in the same plane are placed on the lattice corner + i a + j b of their group,
runs of neighbouring cells are joined into rectangles, and every corner of every patch of a
rectangle must lie where the rectangle's subdivision puts it, to within CORNER_TOLERANCE (a
few float32 roundings); a rectangle that fails is traced as its patches. Where a hit falls
within that tolerance of a cell's side it may score on the neighbouring patch: the same
uncertainty float32 already gives the patches' own triangles.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..mesh.frames import RELATIVE_EDGE_INSET, edge_barycentric, parallelogram_blocks
from .raytrace import RayTracer

# Unit space (the scene's diagonal is 1): patch edges and plane offsets that agree to within
# this (from one patch to the next, in sorted order) are taken as equal when patches are
# grouped; a group is then checked corner by corner.
GRID_QUANTUM = 2.0**-20
# Lattice coordinates of a group's patches must be this close to whole numbers.
LATTICE_TOLERANCE = 1e-3
# Every corner of a grid's patches must lie this close (unit space: about 8 float32 roundings at
# the scene's extent) to where the grid's even subdivision puts it.
CORNER_TOLERANCE = 2.5e-7
# Grids are traced only if they (with the other patches' triangles) take at most this fraction
# of the scene's triangles.
MAX_TRIANGLE_FRACTION = 0.5
# The cell arithmetic runs in float32, exact below 2^24 cells.
MAX_CELLS = 1 << 24
# Per-patch arithmetic runs this many patches at a time (every value patch by patch: the same
# numbers as all at once), so that its float64 temporaries are a block's.
BLOCK_PATCHES = 1 << 16


@dataclass(frozen=True)
class PatchGrids:
    """Rectangles of patches, traced as two triangles each, and the other patches' triangles.

    corners: (2R+L,3,3) float32 unit-space triangles (rectangle r is triangles 2r and 2r+1, then
    the L triangles of the patches that are not in rectangles, in patch order);
    cell_table: (7,2R+L+1) float32 rows per triangle: the coefficient of v in s, the coefficient
    of u in t, n_a, n_b, n_a - 1, n_b - 1 and the rectangle's first cell (a one-cell grid for
    each of the L triangles); the last column, which a miss (-1) wraps to, points at a cell of
    patch -1;
    cell_patch: (P+1,) int32 patch of each cell, rectangle by rectangle, rows of n_b cells,
    then the other patches' cells, then -1;
    rectangles: R, the number of rectangles;
    hit_frames: (12,2R+L) float32, what a walk leaving from hit points maps a hit near an edge
    onto (WalkTables.hit_points): per triangle a corner (pushed off along the normal), edges e1
    and e2 and the patch's normal, so that corner + u e1 + v e2 at the hit's barycentric (u, v)
    lies inside its rectangle inset by RELATIVE_EDGE_INSET (a grid triangle's frame is its
    rectangle's inset one, A' and B', as the triangle's barycentrics see it: e1, e2 = A', A' + B'
    on the first triangle, A' + B', B' on the second), or inside the inset triangle of another
    patch;
    edge_barycentric: (2R+L,) float32, the barycentric coordinate below which a hit on each
    triangle may lie within RELATIVE_HIT_EDGE_CLEARANCE of one of its edges."""

    corners: np.ndarray
    cell_table: np.ndarray
    cell_patch: np.ndarray
    rectangles: int
    hit_frames: np.ndarray
    edge_barycentric: np.ndarray

    @property
    def triangle_count(self):
        return self.corners.shape[0]

    def hit_patches(self, triangle, u, v):
        """The patch of each hit (a triangle of the grids, Embree's barycentric u, v), -1 for a
        miss (triangle -1, u = v = 0). (n,) int32."""
        s, t, n_a, n_b, last_a, last_b, first = self.cell_table.take(triangle, axis=1, mode="wrap")
        s *= v
        s += u  # s = u + cs v
        t *= u
        t += v  # t = v + ct u
        s *= n_a
        np.minimum(s, last_a, out=s)
        np.trunc(s, out=s)  # cell row (s >= 0 up to rounding; -0.x truncates to 0)
        t *= n_b
        np.minimum(t, last_b, out=t)
        np.trunc(t, out=t)
        s *= n_b
        s += t
        s += first
        return self.cell_patch.take(s.astype(np.int32), mode="wrap")

    @cached_property
    def tracer(self):
        """The Embree scene of the grids' triangles, built on first use."""
        return RayTracer(self.corners)


def patch_grids(geometry):
    """The grids of a scene's parallelogram patches, with every other patch's own triangles
    (a grid of one cell each), or None where they would not take at most MAX_TRIANGLE_FRACTION
    of the scene's triangles, or where patches are small beside the scene (their own offsets:
    ``geometry.patch_ray_offset``). ``geometry`` is a :class:`.geometry.Geometry` (triangles
    sorted by patch)."""
    P, T = geometry.patch_count, geometry.triangle_count
    # Where rectangles of cells meet in a T, the float32 corner of one lies off the other's edge
    # by a spacing of the scene's coordinates: a crack nothing beside an ordinary scene, but one
    # rays go through where the patches are small beside it (the patches' own triangles share
    # their corners exactly).
    if P == 0 or P >= MAX_CELLS or geometry.patch_ray_offset is not None:
        return None
    merged, patch_corners = _parallelogram_patches(geometry)
    M = merged.size  # the parallelogram patches, in patch order; grid cells 0..M-1
    if M == 0:
        return None
    normal = geometry.patch_normal[merged]
    rect = _merged_rectangles(patch_corners, normal)
    R = rect.first.size
    # Every other patch is traced as its own triangles, each a grid of one cell: the patch's
    # cell, M and on in patch order.
    is_merged = np.zeros(P, dtype=bool)
    is_merged[merged] = True
    other_patch = np.flatnonzero(~is_merged)
    other_triangle = np.flatnonzero(~is_merged[geometry.triangle_patch])
    L = other_triangle.size
    if 2 * R + L > MAX_TRIANGLE_FRACTION * T:
        return None
    c00, end_a, end_b, c11, normal, n_a, n_b, cell = _wound(rect, patch_corners, normal)
    corners = np.empty((2 * R + L, 3, 3))
    corners[0 : 2 * R : 2] = np.stack([c00, end_a, c11], axis=1)  # s = u + v, t = v
    corners[1 : 2 * R : 2] = np.stack([c00, c11, end_b], axis=1)  # s = u, t = u + v
    corners[2 * R :] = geometry.float32_corners[other_triangle]
    other_cell = np.full(P, P)
    other_cell[other_patch] = M + np.arange(other_patch.size)
    table = _cell_table(n_a, n_b, rect.first, other_cell[geometry.triangle_patch[other_triangle]], P)
    cell_patch = np.full(P + 1, -1, dtype=np.int32)
    cell_patch[cell] = merged
    cell_patch[M:P] = other_patch
    return PatchGrids(
        corners=np.ascontiguousarray(corners, dtype=np.float32),
        cell_table=np.ascontiguousarray(table, dtype=np.float32),
        cell_patch=cell_patch,
        rectangles=R,
        hit_frames=np.ascontiguousarray(_hit_frames(geometry, c00, end_a, end_b, normal, other_triangle), dtype=np.float32),
        edge_barycentric=edge_barycentric(corners),
    )


def _merged_rectangles(patch_corners, normal):
    """The Rectangles the parallelogram patches (corners (p, s1, s2, q), normals) merge into:
    groups of one plane and lattice, cut into rectangles of cells; a rectangle whose corners
    are misplaced falls back to cells of their own."""
    p, s1, s2, _ = patch_corners
    p = p.astype(np.float64)
    a = s1 - p  # (float32 s1 promoted: the differences of the float64 corners)
    b = s2 - p
    group = _groups(p, a, b, normal)
    I, J, on_lattice = _lattice(p, a, b, group)
    del p, a, b
    group = _alone(group, ~on_lattice)
    rect = _rectangles(group, I, J)
    bad = _misplaced(rect, patch_corners)
    if bad.any():
        # The cells of a failed rectangle become rectangles of their own.
        group = _alone(group, bad[rect.of_cell])
        rect = _rectangles(group, I, J)
    return rect


def _wound(rect, patch_corners, normal):
    """(c00, end_a, end_b, c11, each rectangle's normal, n_a, n_b, each cell's index) of the
    rectangles wound so that Embree's geometric normal of their triangles, which points like
    (corner1 - corner0) x (corner2 - corner0), points like their patches' normals (the walk's
    facing test reads it): where (c10 - c00) x (c01 - c00) does not, the axes are swapped (the
    rectangle transposed: a patch's cell is first + j n_a + i)."""
    c00, c10, c01, c11 = rect.corners(patch_corners)
    normal = normal[rect.corner_patch[:, 0]]
    turned = np.einsum("ij,ij->i", np.cross(c10 - c00, c01 - c00), normal) < 0
    end_a = np.where(turned[:, None], c01, c10)
    end_b = np.where(turned[:, None], c10, c01)
    n_a = np.where(turned, rect.n_b, rect.n_a)
    n_b = np.where(turned, rect.n_a, rect.n_b)
    r = rect.of_cell
    cell = np.where(turned[r], rect.first[r] + rect.j * rect.n_a[r] + rect.i, rect.cell)
    return c00, end_a, end_b, c11, normal, n_a, n_b, cell


def _cell_table(n_a, n_b, first, other_cell, P):
    """(7, 2R + L + 1) rows per triangle, the rectangles' two each, then the other patches' L
    (s and t of one-cell grids are u and v: cs = ct = 0), then a miss's: a miss (-1) wraps to
    the last column, cell P (patch -1)."""
    R, L = n_a.size, other_cell.size
    table = np.zeros((7, 2 * R + L + 1))
    table[0, 0 : 2 * R : 2] = 1.0
    table[1, 1 : 2 * R : 2] = 1.0
    for row, values in ((2, n_a), (3, n_b), (4, n_a - 1), (5, n_b - 1), (6, first)):
        table[row, : 2 * R] = np.repeat(values, 2)
    table[2:4, 2 * R :] = 1.0
    table[6, 2 * R : -1] = other_cell
    table[6, -1] = P
    return table


def _hit_frames(geometry, c00, end_a, end_b, normal, other_triangle):
    """(12, 2R + L) a hit-point exit's leaving frames (see PatchGrids): each rectangle inset by
    RELATIVE_EDGE_INSET on every side (d_a of A = c_a - c00 off the sides along B, which lie
    area / |B| apart), its corner pushed off along the patches' normal; the other patches'
    triangles keep theirs (Geometry.triangle_frame, with their patch's normal)."""
    R = c00.shape[0]
    A, B = end_a - c00, end_b - c00
    area = np.linalg.norm(np.cross(A, B), axis=1)
    d_a = np.minimum(RELATIVE_EDGE_INSET * np.linalg.norm(B, axis=1) / area, 0.25)[:, None]
    d_b = np.minimum(RELATIVE_EDGE_INSET * np.linalg.norm(A, axis=1) / area, 0.25)[:, None]
    inset_a, inset_b = (1 - 2 * d_a) * A, (1 - 2 * d_b) * B
    frames = np.empty((12, 2 * R + other_triangle.size))
    frames[0:3, : 2 * R] = np.repeat((c00 + d_a * A + d_b * B + geometry.ray_offset * normal).T, 2, axis=1)
    frames[3:6, 0 : 2 * R : 2] = inset_a.T  # u along A', v along A' + B': S = u + v, T = v
    frames[6:9, 0 : 2 * R : 2] = (inset_a + inset_b).T
    frames[3:6, 1 : 2 * R : 2] = (inset_a + inset_b).T  # S = u, T = u + v
    frames[6:9, 1 : 2 * R : 2] = inset_b.T
    frames[9:12, : 2 * R] = np.repeat(normal.T, 2, axis=1)
    frames[0:9, 2 * R :] = geometry.frames_of(other_triangle)
    frames[9:12, 2 * R :] = geometry.patch_normal_rows[:, geometry.triangle_patch[other_triangle]]
    return frames


def _parallelogram_patches(geometry):
    """(the parallelogram patches (M,), their corners (p, s1, s2, q), each (M,3) float32) of
    :func:`.frames.parallelogram_corners` on the float32 corners: the corners are float32
    numbers, kept as float32 (exactly) and promoted to float64 where computed with."""
    blocks = parallelogram_blocks(geometry.float32_corners, geometry.patch_first_triangle, geometry.patch_triangle_count)
    merged, corners = [], ([], [], [], [])
    for two, ok, block_corners in blocks:
        merged.append(two[ok])
        for out, c in zip(corners, block_corners):
            out.append(c[ok].astype(np.float32))
    if not merged:
        return np.zeros(0, np.int64), tuple(np.zeros((0, 3), np.float32) for _ in range(4))
    return np.concatenate(merged), tuple(np.concatenate(c) for c in corners)


def _alone(group, mask):
    """``group`` with each patch of ``mask`` in a group of its own (a rectangle of one cell)."""
    return np.where(mask, group.max() + 1 + np.arange(group.size), group)


def _groups(p, a, b, normal):
    """(P,) group of each patch: the same edges a, b and plane, each of their 7 coordinates
    within GRID_QUANTUM of the next (clusters by gaps, which rounding to a grid would split),
    and the same side of the plane in front (``normal``, the patches' normals: two patches
    with the same corners in the same order may face opposite ways, where their triangles
    start at different corners, and a grid has one front)."""
    m = np.cross(a, b)
    m /= np.linalg.norm(m, axis=1)[:, None]
    offset = np.einsum("ij,ij->i", m, p)
    front = np.einsum("ij,ij->i", m, normal) > 0
    del m
    # one column of cluster ids per coordinate (int32: below MAX_CELLS), sorted by the first
    # column, then the next, ...; a new group wherever one of them changes
    key = [_clusters(x, GRID_QUANTUM).astype(np.int32) for x in (*a.T, *b.T, offset)] + [front]
    order = np.lexsort(key[::-1])
    new = np.ones(order.size, dtype=bool)
    new[1:] = False
    for column in key:
        column = column[order]
        new[1:] |= column[1:] != column[:-1]
    group = np.empty(order.size, dtype=np.int64)
    group[order] = np.cumsum(new) - 1
    return group


def _clusters(x, gap):
    """(n,) cluster of each value: sorted values further apart than ``gap`` start a new one."""
    order = np.argsort(x, kind="stable")
    new = np.zeros(x.size, dtype=np.int64)
    new[1:] = np.diff(x[order]) > gap
    cluster = np.empty(x.size, dtype=np.int64)
    cluster[order] = np.cumsum(new)
    return cluster


def _lattice(p, a, b, group):
    """Each patch's lattice coordinates (I, J) in its group, p = p_0 + I a + J b (p_0 the group's
    lowest corner, a and b the group's mean edges), and whether they are whole numbers."""
    G = group.max() + 1
    count = np.bincount(group, minlength=G)[:, None]
    a_g = np.stack([np.bincount(group, weights=a[:, k], minlength=G) for k in range(3)], axis=1) / count
    b_g = np.stack([np.bincount(group, weights=b[:, k], minlength=G) for k in range(3)], axis=1) / count
    first = np.full(G, p.shape[0])
    np.minimum.at(first, group, np.arange(p.shape[0]))
    origin = p[first]
    I, J = np.empty(p.shape[0], np.int64), np.empty(p.shape[0], np.int64)
    on_lattice = np.empty(p.shape[0], bool)
    for start in range(0, p.shape[0], BLOCK_PATCHES):  # patch by patch: blocks of them
        rows = slice(start, start + BLOCK_PATCHES)
        g = group[rows]
        d = p[rows] - origin[g]
        a_p, b_p = a_g[g], b_g[g]
        aa = np.einsum("ij,ij->i", a_p, a_p)
        bb = np.einsum("ij,ij->i", b_p, b_p)
        ab = np.einsum("ij,ij->i", a_p, b_p)
        da = np.einsum("ij,ij->i", d, a_p)
        db = np.einsum("ij,ij->i", d, b_p)
        det = aa * bb - ab * ab
        i = (bb * da - ab * db) / det
        j = (aa * db - ab * da) / det
        I_rows, J_rows = np.rint(i), np.rint(j)
        on_lattice[rows] = (np.abs(i - I_rows) < LATTICE_TOLERANCE) & (np.abs(j - J_rows) < LATTICE_TOLERANCE)
        I[rows], J[rows] = I_rows, J_rows
    return I, J, on_lattice


@dataclass
class _Rectangles:
    of_cell: np.ndarray   # (P,) rectangle of each patch
    cell: np.ndarray      # (P,) each patch's cell: first[rect] + i n_b + j
    i: np.ndarray         # (P,) row in its rectangle
    j: np.ndarray         # (P,) column
    first: np.ndarray     # (R,) first cell of each rectangle
    n_a: np.ndarray       # (R,)
    n_b: np.ndarray       # (R,)
    corner_patch: np.ndarray  # (R,4) patches at cells (0,0), (n_a-1,0), (0,n_b-1), (n_a-1,n_b-1)

    def corners(self, patch_corners):
        """Each rectangle's corners c00, c10, c01, c11 (float64) from its corner patches' own corners."""
        p, s1, s2, q = patch_corners
        cp = self.corner_patch
        return tuple(c[cp[:, k]].astype(np.float64) for k, c in enumerate((p, s1, s2, q)))


def _rectangles(group, I, J):
    """Cells (group, I, J) joined into rectangles: runs of consecutive J in a row, then runs
    of consecutive rows whose runs start and end alike. A cell that two patches share (two
    faces on one place) is a rectangle of its own, once for each."""
    P = group.size
    order = np.lexsort((J, I, group))
    g, i, j = group[order], I[order], J[order]
    same_cell = np.zeros(P, dtype=bool)
    same_cell[1:] = (g[1:] == g[:-1]) & (i[1:] == i[:-1]) & (j[1:] == j[:-1])
    shared = same_cell.copy()
    shared[:-1] |= same_cell[1:]
    if shared.any():
        # Cells of more than one patch: each patch its own group, and again.
        alone = np.zeros(P, dtype=bool)
        alone[order[shared]] = True
        return _rectangles(_alone(group, alone), I, J)
    # Runs along J.
    run_start = np.ones(P, dtype=bool)
    run_start[1:] = (g[1:] != g[:-1]) | (i[1:] != i[:-1]) | (j[1:] != j[:-1] + 1)
    run = np.cumsum(run_start) - 1
    starts = np.flatnonzero(run_start)
    run_g, run_i, run_j = g[starts], i[starts], j[starts]
    run_len = np.diff(np.append(starts, P))
    # Runs joined along I where they start at the same J with the same length.
    r_order = np.lexsort((run_i, run_len, run_j, run_g))
    rg, ri, rj, rl = run_g[r_order], run_i[r_order], run_j[r_order], run_len[r_order]
    rect_start = np.ones(r_order.size, dtype=bool)
    rect_start[1:] = (rg[1:] != rg[:-1]) | (rj[1:] != rj[:-1]) | (rl[1:] != rl[:-1]) | (ri[1:] != ri[:-1] + 1)
    rect_of_sorted_run = np.cumsum(rect_start) - 1
    rect_of_run = np.empty_like(rect_of_sorted_run)
    rect_of_run[r_order] = rect_of_sorted_run
    firsts = np.flatnonzero(rect_start)
    R = firsts.size
    n_b = rl[firsts]
    n_a = np.diff(np.append(firsts, r_order.size))
    i0, j0 = ri[firsts], rj[firsts]
    first = np.concatenate(([0], np.cumsum(n_a * n_b)[:-1]))
    rect_sorted = rect_of_run[run]
    li = i - i0[rect_sorted]
    lj = j - j0[rect_sorted]
    of_cell = np.empty(P, dtype=np.int64)
    of_cell[order] = rect_sorted
    local_i = np.empty(P, dtype=np.int64)
    local_i[order] = li
    local_j = np.empty(P, dtype=np.int64)
    local_j[order] = lj
    cell = first[of_cell] + local_i * n_b[of_cell] + local_j
    at_cell = np.empty(P, dtype=np.int64)
    at_cell[cell] = np.arange(P)
    corner_cells = np.stack([first, first + (n_a - 1) * n_b, first + n_b - 1, first + n_a * n_b - 1], axis=1)
    return _Rectangles(of_cell, cell, local_i, local_j, first, n_a, n_b, at_cell[corner_cells].reshape(R, 4))


def _misplaced(rect, patch_corners):
    """(R,) whether some corner of some patch of a rectangle lies further than CORNER_TOLERANCE
    from where the rectangle's even subdivision puts it."""
    c00, c10, c01, _ = rect.corners(patch_corners)
    R = rect.first.size
    step_a = (c10 - c00) / rect.n_a[:, None]
    step_b = (c01 - c00) / rect.n_b[:, None]
    worst = np.zeros(R)
    for start in range(0, rect.of_cell.size, BLOCK_PATCHES):  # patch by patch: blocks of them
        rows = slice(start, start + BLOCK_PATCHES)
        r = rect.of_cell[rows]
        base = c00[r] + rect.i[rows, None] * step_a[r] + rect.j[rows, None] * step_b[r]
        error = np.zeros(r.size)
        for corner, (di, dj) in zip(patch_corners, ((0, 0), (1, 0), (0, 1), (1, 1))):
            expected = base + di * step_a[r] + dj * step_b[r]
            np.maximum(error, np.linalg.norm(corner[rows] - expected, axis=1), out=error)
        np.maximum.at(worst, r, error)
    return worst > CORNER_TOLERANCE
