"""Patches partly covered by a surface just in front of them: split along the cover's outline.

A light panel hung 2 cm under a ceiling covers part of the ceiling: the gap between them holds
light of its own (the panel's top lights the ceiling over it, which lights the panel's top back:
tens of times the room's light), which leaves through the slit along the panel's edge only. A
patch straddling the panel's outline has one radiosity, its mean over the gap and over the part
the room sees: the solve re-emits that mean from the whole patch into the room (the walls, the
table under the panel and the floor get the gap's light), and the display shows it on the part
the room sees (a bright frame round the panel). Splitting such patches where the cover's edge
crosses them (``adaptive``: 2 x 2, conforming), LEVELS times at most, keeps the gap's light on
the gap's cells: a cell splits when PROBES x PROBES points of it are some covered and some not.

A point is covered when the ray from it along its patch's normal meets a surface (either side)
within NEAR of its first patch's side: light reaches it only along the slit between the two.
Patches another object runs into (``visibility``'s buried parts) stay whole, as the Detail
refinement keeps them (a buried child gets no light).
"""
from __future__ import annotations

import numpy as np

from .adaptive import cells_of, patch_mesh, split

LEVELS = 2  # splits of a first patch at most: a quarter of its side along the outline
PROBES = 4  # points a side of a cell whose covering is probed (16 a cell)
NEAR = 0.25  # of the first patch's side: a surface this close in front covers a point
SMALLEST_SIDE = 2e-3  # of the scene's diagonal: no cell smaller (as adaptive_light's)


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
    hit, _, _, t, _ = g.surface_tracer.first_hit_barycentric(np.ascontiguousarray(origin, np.float32),
                                                             np.ascontiguousarray(normal, np.float32), g.region_of(patch))
    return (hit >= 0) & (np.asarray(t, np.float64) * g.diagonal < near)


def _probe_points(cells, rows):
    """((n*PROBES^2, 3) points spread over the cells ``rows``, (n*PROBES^2,) the row of each): a
    quad's bilinear grid, a triangle's the grid folded into it."""
    s, t = (a.ravel() for a in np.meshgrid((np.arange(PROBES) + 0.5) / PROBES, (np.arange(PROBES) + 0.5) / PROBES,
                                           indexing="ij"))
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


def split_covered(meshes, geometry, receives=None, keep_whole=None):
    """(Cells per object, or None where no patch is partly covered): the patches of ``meshes``
    (one PatchMesh per object, ``geometry`` their scene's) split where a near surface's outline
    crosses them (the module's docstring). ``receives`` (per object): only those objects split;
    ``keep_whole`` (P,) bool: patches that never split."""
    receives = [True] * len(meshes) if receives is None else list(receives)
    offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    whole = np.zeros(offsets[-1], bool) if keep_whole is None else np.asarray(keep_whole, bool)
    side = np.sqrt(np.asarray(geometry.patch_area, np.float64))
    smallest = (SMALLEST_SIDE * geometry.diagonal) ** 2 * 4  # (a cell's area: its children's four)
    cells = [cells_of(m) for m in meshes]
    changed = False
    for level in range(LEVELS):
        for k, c in enumerate(cells):
            if not receives[k] or not c.count:
                continue
            base = c.origin + offsets[k]
            rows = np.flatnonzero((c.level == level) & ~c.frozen & ~whole[base])
            rows = rows[patch_mesh(c, conforming=False)[0].patch_area[rows] >= smallest] if rows.size else rows
            if not rows.size:
                continue
            points, row = _probe_points(c, rows)
            patch = base[rows][row]
            covered = covered_points(geometry, points, patch, NEAR * side[patch])
            some = np.bincount(row, weights=covered, minlength=len(rows))
            mixed = rows[(some > 0) & (some < PROBES * PROBES)]
            if mixed.size:
                marked = np.zeros(c.count, bool)
                marked[mixed] = True
                cells[k], _ = split(c, marked)
                changed = True
    return cells if changed else None
