"""Patches partly covered by a surface just in front of them: split along the cover's outline.

A light panel hung 2 cm under a ceiling covers part of the ceiling: the gap between them holds
light of its own (the panel's top lights the ceiling over it, which lights the panel's top back:
about a hundred times the room's light), which leaves through the slit along the panel's edge
only. A patch straddling the panel's outline has one radiosity, its mean over the gap and over
the part the room sees: the solve re-emits that mean from the whole patch into the room (the
walls, the table under the panel and the floor get the gap's light), and the display shows it on
the part the room sees. So a cell whose PROBES x PROBES points are some covered and some not
splits (``adaptive``: 2 x 2, conforming), its split lines moved onto the outline (where its
covering changes along each of its two directions, SNAP probes a side and bisection): a straight
outline across a patch, or a panel's corner in it, leaves every new cell wholly covered or
wholly not. Then, up to LEVELS, the cells beside a covered one split again: the light leaking
from the gap is a strip a gap's height wide along the slit, which a cell shows spread over its
width. A moved point stays on its edge (a neighbour sharing it keeps it as a corner on its own
edge: no crack) and in the cell's plane.

A point is covered when the ray from it along its patch's normal meets a surface (either side,
within 30 degrees of parallel to it) within NEAR of its first patch's side: light reaches it only along the slit between the two.
Patches another object runs into (``visibility``'s buried parts) stay whole, as the Detail
refinement keeps them (a buried child gets no light).

Each cell's side of the outline (``CoveredSplit.covered``: most of its probes covered) goes to the
display as data: the smoothing keeps the two sides apart as at a crease (``smoothing.Surface``'s
``covered``), so that the gap's light, tens of times the room's, is not spread into the room's cells.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .adaptive import cells_of, patch_mesh, split
from ..scene.crossings import crossed_patches
from ..scene.geometry_build import build_geometry

LEVELS = 2  # splits of a first patch at most: along the outline, then the cells beside it once more
PROBES = 4  # points a side of a cell whose covering is probed (16 a cell)
EDGE = 0.02  # of a cell's side: its outer probes this far in (a sliver of cover along an edge is met)
NEAR = 0.25  # of the first patch's side: a surface this close in front covers a point
PARALLEL = np.cos(np.radians(30.0))  # ... if it lies within this of parallel to the patch
SNAP = 16  # probes a side of a split cell where its covering changes (its split lines moved there)
SNAP_LIMIT = 0.4  # of a cell's side from its middle, a split line moves at most (no sliver of a neighbour)
SMALLEST_SIDE = 2e-3  # of the scene's diagonal: no cell smaller (as adaptive_light's)


@dataclass
class CoveredSplit:
    """The outline split: the cells per object (core refine.adaptive Cells) and, per object, each
    cell's side of the outline, (L,) bool: most of its probe points covered (False on objects
    that do not receive, and on patches kept whole)."""
    cells: list
    covered: list


def covered_points(geometry, position, patch, near):
    """(n,) bool: the world points ``position`` (n,3) of ``patch`` (n,) (the geometry's patches)
    from which the ray along the patch's normal meets a surface within ``near`` (n,) (world)."""
    g = geometry
    if not len(patch):
        return np.zeros(0, bool)
    unit = (np.asarray(position, np.float64) - g.centre) / g.diagonal
    if g.regions is not None:
        unit -= g.regions.centre[g.regions.of(patch)]
    normal = g.patch_normal_rows.take(patch, axis=1).T.astype(np.float64)
    offset = np.asarray(g.ray_offsets(patch, np.float64), np.float64)
    origin = unit + normal * (offset[:, None] if offset.ndim else offset)
    hit, _, _, t, met = g.surface_tracer.first_hit_barycentric(np.ascontiguousarray(origin, np.float32),
                                                               np.ascontiguousarray(normal, np.float32), g.region_of(patch))
    met = np.asarray(met, np.float64)
    # (a cover lies along the patch, as a panel under a ceiling: a surface met at a slant, the next face
    # of a bend or a concave corner, leaves the light an opening as wide as the distance)
    along = np.abs(np.einsum("ij,ij->i", met, normal)) >= PARALLEL * np.maximum(np.linalg.norm(met, axis=1), 1e-30)
    # (a warped patch's probe points lie a little off its triangles: meeting the patch itself is no cover)
    other = (hit >= 0) & (g.triangle_patch.take(np.maximum(hit, 0)) != patch)
    return other & (np.asarray(t, np.float64) * g.diagonal < near) & along


def _probe_points(cells, rows):
    """((n*PROBES^2, 3) points spread over the cells ``rows``, (n*PROBES^2,) the row of each): a
    quad's bilinear grid, a triangle's the grid folded into it."""
    grid = EDGE + (1 - 2 * EDGE) * np.arange(PROBES) / (PROBES - 1)
    s, t = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    corners = cells.corners[rows]
    quad = corners[:, 3] >= 0
    p = cells.points[np.maximum(corners, 0)]  # (n,4,3)
    bilinear = ((1 - s)[None, :, None] * (1 - t)[None, :, None] * p[:, None, 0] + s[None, :, None] * (1 - t)[None, :, None]
                * p[:, None, 1] + s[None, :, None] * t[None, :, None] * p[:, None, 2] + (1 - s)[None, :, None]
                * t[None, :, None] * p[:, None, 3])
    over = s + t > 1
    fs, ft = np.where(over, 1 - s, s), np.where(over, 1 - t, t)
    folded = p[:, None, 0] + fs[None, :, None] * (p[:, None, 1] - p[:, None, 0]) + ft[None, :, None] * (p[:, None, 2] - p[:, None, 0])
    points = np.where(quad[:, None, None], bilinear, folded)
    return points.reshape(-1, 3), np.repeat(np.arange(len(rows)), PROBES * PROBES)


def covered_cells(meshes, combined, receives=None):
    """The cells per object of ``covered_split`` (None where no patch is partly covered)."""
    made = covered_split(meshes, combined, receives)
    return None if made is None else made.cells


def covered_split(meshes, combined, receives=None):
    """``split_covered`` of ``meshes`` (their ``combined`` CombinedPatches) on their rays alone: no buried
    parts (the split scene finds them), a patch another surface crosses kept whole, as a buried one
    would be (a buried child gets no light)."""
    geometry = build_geometry(combined.vertices, combined.triangles, combined.triangle_patch, combined.patch_count,
                              visible_parts=False)
    whole = np.zeros(combined.patch_count, bool)
    whole[crossed_patches(geometry)] = True
    return split_covered(meshes, geometry, receives, whole)


def split_covered(meshes, geometry, receives=None, keep_whole=None):
    """(CoveredSplit, or None where no patch is partly covered): the patches of ``meshes`` (one
    PatchMesh per object, ``geometry`` their scene's) split where a near surface's outline crosses
    them (the module's docstring), and each cell's side of it. ``receives`` (per object): only
    those objects split; ``keep_whole`` (P,) bool: patches that never split."""
    receives = [True] * len(meshes) if receives is None else list(receives)
    offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    whole = np.zeros(offsets[-1], bool) if keep_whole is None else np.asarray(keep_whole, bool)
    side = np.sqrt(np.asarray(geometry.patch_area, np.float64))
    smallest = (SMALLEST_SIDE * geometry.diagonal) ** 2 * 4  # (a cell's area: its children's four)
    cells = [cells_of(m) for m in meshes]
    share = [np.full(c.count, np.nan) for c in cells]  # (each cell's covered probes' share; nan: not known)
    changed = False
    for level in range(LEVELS):
        for k, c in enumerate(cells):
            if not receives[k] or not c.count:
                continue
            base = c.origin + offsets[k]
            rows = np.flatnonzero(~c.frozen & ~whole[base])
            rows = rows[patch_mesh(c, conforming=False)[0].patch_area[rows] >= smallest] if rows.size else rows
            if not rows.size:
                continue
            points, row = _probe_points(c, rows)
            patch = base[rows][row]
            some = np.bincount(row, weights=covered_points(geometry, points, patch, NEAR * side[patch]), minlength=len(rows))
            share[k][rows] = some / (PROBES * PROBES)
            now = c.level[rows] == level
            mixed = rows[now & (some > 0) & (some < PROBES * PROBES)]
            # (the cells beside the outline split too: the light leaking from under the cover is a strip
            # there a gap's height wide, which a cell shows spread over its width)
            beside = np.zeros(len(c.points) + 1, bool)  # (the last: a triangle's missing corner, -1)
            beside[c.corners[rows[some == PROBES * PROBES]].ravel()] = True
            beside[-1] = False
            edge = rows[now & (some == 0) & beside[c.corners[rows]].any(axis=1)] if level else rows[:0]
            if mixed.size or edge.size:
                marked = np.zeros(c.count, bool)
                marked[mixed] = marked[edge] = True
                where = _crossings(c, mixed, geometry, base[mixed], NEAR * side[base[mixed]])
                cells[k], parent = split(c, marked)
                _snap(cells[k], parent, mixed, where)
                share[k] = _inherited(share[k], cells[k].level > c.level[parent], parent)
                changed = True
    if not changed:
        return None
    return CoveredSplit(cells, _sides(cells, share, geometry, offsets, side, receives, whole))


def _inherited(share, new, parent):
    """(L',) the covered share of each cell after a split (``parent``: the old cell each lies in,
    ``new`` (L',) bool: a child): its parent's, unknown (nan) for a child of a mixed cell."""
    out = share[parent]
    out[new & ~((out == 0) | (out == 1))] = np.nan
    return out


def _sides(cells, share, geometry, offsets, side, receives, whole):
    """Per object, (L,) bool each cell's side of the outline: most of its probes covered; the cells
    not known yet (a last split's children of a mixed cell, frozen or the smallest ones) probed now."""
    out = []
    for k, c in enumerate(cells):
        known = share[k]
        base = c.origin + offsets[k]
        rows = np.flatnonzero(np.isnan(known) & ~whole[base]) if receives[k] else np.zeros(0, np.int64)
        if rows.size:
            points, row = _probe_points(c, rows)
            patch = base[rows][row]
            hit = covered_points(geometry, points, patch, NEAR * side[patch])
            known[rows] = np.bincount(row, weights=hit, minlength=len(rows)) / (PROBES * PROBES)
        out.append(np.nan_to_num(known, nan=0.0) > 0.5)
    return out


def _bilinear(corners, s, t):
    """(n,3) the points (s, t) (n,) of quads ``corners`` (n,4,3)."""
    s, t = s[:, None], t[:, None]
    return ((1 - s) * (1 - t) * corners[:, 0] + s * (1 - t) * corners[:, 1] + s * t * corners[:, 2]
            + (1 - s) * t * corners[:, 3])


def _crossings(cells, rows, geometry, patch, near):
    """(n,2) for each quad cell of ``rows``, the (s, t) its split lines move to: where its covering
    changes along s (on a row of SNAP probes where it does) and along t, found to a thousandth of the
    cell by bisection, within SNAP_LIMIT of its middle; 0.5 where it does not change that way (or a
    triangle)."""
    out = np.full((len(rows), 2), 0.5)
    quad = np.flatnonzero(cells.corners[rows, 3] >= 0)
    if not quad.size:
        return out
    corners = cells.points[cells.corners[rows[quad]]]
    n, grid = len(quad), (np.arange(SNAP) + 0.5) / SNAP
    s, t = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    probe = _bilinear(np.repeat(corners, s.size, axis=0), np.tile(s, n), np.tile(t, n))
    cover = covered_points(geometry, probe, np.repeat(patch[quad], s.size), np.repeat(near[quad], s.size))
    cover = cover.reshape(n, SNAP, SNAP)  # (cell, s, t)
    for axis in (0, 1):
        grid_of = cover if axis == 0 else cover.transpose(0, 2, 1)  # (cell, along, across)
        change = grid_of[:, 1:, :] != grid_of[:, :-1, :]  # (cell, between, across)
        has = change.any(axis=(1, 2))
        # (the change nearest the middle: the split line's own place)
        between = np.abs(np.arange(SNAP - 1) + 1 - SNAP / 2)
        score = np.where(change.any(axis=2), between[None, :], np.inf)
        step = np.argmin(score, axis=1)
        across = np.argmax(change[np.arange(n), step], axis=1)
        low, high = grid[step], grid[step + 1]
        fixed = grid[across]
        first = grid_of[np.arange(n), step, across]
        for _ in range(10):
            middle = (low + high) / 2
            at = _bilinear(corners, middle, fixed) if axis == 0 else _bilinear(corners, fixed, middle)
            same = covered_points(geometry, at, patch[quad], near[quad]) == first
            low, high = np.where(same, middle, low), np.where(same, high, middle)
        out[quad[has], axis] = np.clip((low + high)[has] / 2, 0.5 - SNAP_LIMIT, 0.5 + SNAP_LIMIT)
    return out


def _snap(cells, parent, split_rows, where):
    """Moves the new points of the split quads ``split_rows`` (old rows; ``parent`` maps the new
    cells to them) onto their split lines at (s, t) ``where`` (n,2): the edges' midpoints along
    their edges, the centre where the lines meet. Neighbours sharing a moved midpoint keep it as
    a corner on their edge (no crack); all stay in the quad's plane."""
    order = np.argsort(parent, kind="stable")
    first = np.searchsorted(parent[order], split_rows)
    quad = np.flatnonzero(cells.corners[order[first], 3] >= 0)
    rows = order[first[quad][:, None] + np.arange(4)]  # (the four children, made in this order)
    c = cells.corners
    old = np.stack([c[rows[:, 0], 0], c[rows[:, 1], 1], c[rows[:, 2], 2], c[rows[:, 3], 3]], axis=1)
    corners = cells.points[old]
    facing = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    s, t = where[quad, 0], where[quad, 1]
    points = (c[rows[:, 0], 1], c[rows[:, 1], 2], c[rows[:, 2], 3], c[rows[:, 3], 0], c[rows[:, 0], 2])
    moving = np.ones(len(quad), bool)
    for attempt in range(9):  # (a quad whose children would fold goes back to its midpoints, and so its neighbours' shared points)
        if attempt == 8:
            moving[:] = False  # (still folding: every one at its midpoints, the plain split)
        u_s, u_t = np.where(moving, s, 0.5), np.where(moving, t, 0.5)
        zero, one = np.zeros_like(u_s), np.ones_like(u_s)
        for point, (u, v) in zip(points, ((u_s, zero), (one, u_t), (u_s, one), (zero, u_t), (u_s, u_t))):
            cells.points[point] = _bilinear(corners, u, v)
        folded = moving & ~_children_face(cells, rows, facing)
        if not folded.any():
            return
        moving &= ~folded


def _children_face(cells, rows, facing):
    """(n,) bool: each of the quads' four children (``rows`` (n,4)) has both its triangles, cut
    either way, facing as ``facing`` (n,3)."""
    good = np.ones(len(rows), bool)
    for k in range(4):
        a, b, c, d = (cells.points[cells.corners[rows[:, k], j]] for j in range(4))
        for p, q, r in ((a, b, c), (a, c, d), (a, b, d), (b, c, d)):
            good &= np.einsum("ij,ij->i", np.cross(q - p, r - p), facing) > 0
    return good
