"""The display's own finer cells: a patch split where its direct light changes, the solve's patches kept.

The display shows the direct light at each patch's corners (``point_direct``), but a lamp's hot
spot, a spot's cone or a shadow's edge narrower than a patch falls between its corners and is drawn
as wide as the patch (a wedge on the wall beside a sconce). So the display's mesh is finer than the
solve's where the direct light says so: a cell whose corners' direct light differs by more than
CHANGE of its patch's light (or of FLOOR times the mean light, where that is more: dark corners do not
take the budget) splits 2 x 2 (``refine.adaptive``: conforming, no T-junction), up to LEVELS times,
the largest differences first, within BUDGET new points. The direct light is taken at the new points
as at the corners (``point_direct``: the same samples and retries); the rest of the light, the solve's
smooth values, is the coarse corners' linear interpolation there. ``point_direct.shown`` then keeps
every patch's mean its solved value (its M the mean of the fine direct light's interpolation), and the
solve's patches, error and time are untouched. Every output (the colours, the source's layers, relight's
stored values) is written on the finer cells, each cell's patch its origin's.

Not split: patches no camera sees, n-gons kept whole and their neighbours, meshes a Detail refinement made.
A patch another object runs into (a wall's beside a painting hung into it, a floor's under a wall) splits;
its new points inside that object show the coarse display there (they add no shape nobody sees, and a
point without light would darken the visible part of its cells).
A mesh the outline split made (``refine.covered_parts``: a ceiling round a panel hung under it, a
floor round a rug) splits as any mesh, on its shading triangles (its polygons' every corner, the
neighbours' midpoints too: no T-junction): the light through a lit gap's slit falls off within cm of
the outline, and a sun's patch crosses a floor that has a rug on it, as any floor.
"""
from __future__ import annotations

import numpy as np

from ..mesh.faces import triangle_areas
from ..mesh.meshing import PatchMesh
from .adaptive import cells_of, patch_mesh, split
from .cell_meshes import Means, RefinedSurface, barycentric, containing, found, merged, shown_of
from ..display.covered import visible_corner_weights
from ..display.point_direct import CornerDirect, inside_other, patch_means

LEVELS = 3  # splits of a patch at most: an eighth of its side
CHANGE = 0.25  # of the patch's light: a difference between corners the eye sees as a shape, not a shade
FLOOR = 0.2  # of the mean light: the least light a difference is measured against
BUDGET = 1.0  # new points at most, a share of the split meshes' points (each costs a corner's rays)
MOST = 2_048  # and at most this many: where patches are that many, a hot spot spans patches of its own
NEW_POINTS = 3  # points a split cell adds at most (a triangle's three midpoints; fewer where neighbours share them)
FAR = np.int64(1) << np.int64(31)  # key of a new point: patch * FAR + its point in the object's cells


def refine(coarse, direct, scene, triangles, meshes, receives, light, at_points, most=None, covered=None, means=None):
    """(RefinedSurface, its CornerDirect, Shown), or None where no cell splits. ``coarse`` the
    ``smoothing.Surface`` of ``triangles`` (T,3) of the scene's vertices, ``direct`` the coarse
    CornerDirect (([G,]T,3,3)); ``meshes`` the objects' PatchMeshes in scene order, ``receives``
    whether each gets results; ``light`` (P,3) the light the patches show; ``at_points(position
    (n,3), patch (n,), level)`` the direct light ([G,]n,3) at points (``point_direct.points_direct``);
    ``most``: new points at most (a time limit's), beside the budget; ``covered`` (P,) bool the patches under
    a cover (the outline split's, whose meshes then split on their shading triangles); ``means`` (P,3) each
    patch's mean of the direct light the corners show (``direct_means.corner_sources_means``), where known:
    a patch whose corners miss it (``_missed``) splits once, as if they differed."""
    V = len(scene.vertices)
    triangles = np.asarray(triangles, np.int64)
    tp = np.asarray(coarse.triangle_patch, np.int64)
    table = _Table(direct, triangles, tp, V)
    starts = np.cumsum([0] + [len(m.points) for m in meshes])
    offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    threshold, kept = _limits(coarse, scene, light)
    missed = _missed(direct, means, threshold, kept)
    written = meshes
    if covered is not None:  # (the outline split's meshes: their cells on their shading triangles, the covered whole)
        kept |= covered
        meshes = [_on_shading(m, offsets[k], covered) for k, m in enumerate(meshes)]
    splittable = [k for k, m in enumerate(meshes) if receives[k] and getattr(m, "shading_triangles", None) is None
                  and m.patch_count]
    # (cells of the patches' triangles: a cell's triangles never cross its patch's, so the coarse light's linear
    # interpolation at the new points keeps every patch's mean, in any triangulation of the cells' polygons; only
    # the patches whose light changes and LEVELS + 1 rings around them: the balance's splits stay among them)
    rows = {k: _region(meshes[k], offsets[k] + np.asarray(meshes[k].triangle_patch, np.int64), table, starts[k],
                       threshold, kept, missed) for k in splittable}
    splittable = [k for k in splittable if rows[k].size]
    cells = {k: cells_of(_triangle_mesh(meshes[k], rows[k])) for k in splittable}
    patch_of = {k: offsets[k] + np.asarray(meshes[k].triangle_patch, np.int64)[rows[k]] for k in splittable}
    active = {k: np.ones(cells[k].count, bool) for k in splittable}
    budget = min(BUDGET * sum(len(meshes[k].points) for k in splittable), MOST, np.inf if most is None else most)
    for level in range(LEVELS):
        made = sum(len(c.points) - len(meshes[k].points) for k, c in cells.items())
        chosen = _chosen(cells, active, starts, patch_of, meshes, table, threshold, kept, budget - made,
                         missed if level == 0 else None)
        if chosen is None:
            break
        for k, marked in chosen.items():
            before = cells[k]
            cells[k], parent = split(before, marked)
            active[k] = cells[k].level > before.level[parent]
        _evaluate(table, [(k, c.corners[active[k]], patch_of[k][c.origin[active[k]]], rows[k][c.origin[active[k]]])
                           for k, c in cells.items()], starts, meshes, cells, at_points, level, scene.geometry)
    refined = [k for k in splittable if cells[k].level.max(initial=0) > 0]
    if not refined:
        return None
    made = {k: patch_mesh(cells[k]) for k in refined}
    shown = shown_of(written, {k: merged(meshes[k], mesh, patch_of[k][origin] - offsets[k]) for k, (mesh, origin) in made.items()},
                   triangles, tp, starts, offsets)
    _evaluate(table, _shading_corners(shown, refined, offsets), starts, meshes, cells, at_points, LEVELS)
    fine = Means(shown, scene.patch_count, visible_corner_weights(scene.geometry, shown.vertices, shown.triangles,
                                                                   shown.triangle_patch))
    coarse_vertex = _coarse_vertices(shown, meshes, starts)
    slots, weights = _slots(shown, coarse_vertex, scene.vertices, triangles, tp, table)
    surface = RefinedSurface(coarse, fine, shown, slots, weights)
    corners = _fine_corners(table, shown, coarse_vertex, meshes, starts, direct.corners.dtype)
    return surface, CornerDirect(corners, patch_means(fine, corners)), shown


def _limits(coarse, scene, light):
    """((P,) the change of direct light between a cell's corners that splits it, (P,) bool the patches
    kept whole: no camera sees them, or they lie inside another object whole. (A patch another object
    runs into splits: its new points inside that object take the coarse display there, ``_under``.)"""
    grey = np.asarray(light, np.float64).sum(axis=1)
    hidden = coarse.hidden if coarse.hidden is not None else np.zeros(scene.patch_count, bool)
    seen = ~hidden & (coarse.patch_area > 0)
    kept = hidden.copy()
    if scene.geometry.buried is not None:
        kept[np.asarray(scene.geometry.buried.whole, np.int64)] = True
    floor = FLOOR * (grey[seen].mean() if seen.any() else 0.0)
    return CHANGE * np.maximum(grey, floor), kept


def _region(mesh, patch, table, start, threshold, kept, missed=None):
    """(n,) the rows of ``mesh``'s triangles (their scene patches ``patch``) that may split: every
    triangle of the patches where one's corners' direct light differs by more than its patch's
    ``threshold`` or misses its mean (``missed`` > 1), and of LEVELS + 1 rings of patches around them
    (sharing a point)."""
    triangles = np.asarray(mesh.triangles, np.int64)
    values = table.coarse(np.repeat(patch, 3), triangles.ravel() + start)
    grey = (values.sum(axis=-1) if values.ndim == 2 else values.sum(axis=(0, -1))).reshape(-1, 3)
    chosen = np.zeros(int(patch.max(initial=-1)) + 1, bool)
    changes = np.ptp(grey, axis=1) > threshold[patch]
    if missed is not None:
        changes |= missed[patch] > 1.0
    chosen[patch[changes & ~kept[patch]]] = True
    if not chosen.any():
        return np.zeros(0, np.int64)
    for _ in range(LEVELS + 1):
        near = np.zeros(len(mesh.points), bool)
        near[triangles[chosen[patch]].ravel()] = True
        chosen[patch[near[triangles].any(axis=1)]] = True
    return np.flatnonzero(chosen[patch])


def _missed(direct, means, threshold, kept):
    """(P,) how far each patch's corners miss its mean direct light ``means`` (P,3): |mean - M| over its
    ``threshold`` (M the mean of the corners' interpolation): a spot's cone on a wall between a
    patch's corners, none of which it reaches; 0 for the ``kept``; None without ``means``."""
    if means is None:
        return None
    shown = direct.means.sum(axis=-1) if direct.means.ndim == 2 else direct.means.sum(axis=(0, -1))
    gap = np.abs(np.asarray(means, np.float64).sum(axis=1) - shown)
    out = np.divide(gap, threshold, out=np.zeros_like(gap), where=threshold > 0)
    out[kept] = 0.0
    return out


def _on_shading(mesh, offset, covered):
    """``mesh`` as a PatchMesh whose triangles are its shading triangles where it is one the outline
    split made (shading triangles, and a patch of it ``covered`` (P,) bool: scene patches from
    ``offset``), else as it is (a Detail refinement's meshes stay as made)."""
    if getattr(mesh, "shading_triangles", None) is None or not covered[offset:offset + mesh.patch_count].any():
        return mesh
    triangles, patch = np.asarray(mesh.shading_triangles, np.int64), np.asarray(mesh.shading_triangle_patch, np.int64)
    return PatchMesh(mesh.points, mesh.face_sizes, mesh.corner_verts, mesh.patch_face, triangles, patch, mesh.patch_area)


def _triangle_mesh(mesh, rows):
    """The ``rows`` of ``mesh``'s triangles as a PatchMesh of their own (cells that split inside their
    patch's triangles), its points all of ``mesh``'s."""
    triangles = np.asarray(mesh.triangles, np.int64)[rows]
    points = np.asarray(mesh.points, np.float64)
    return PatchMesh(points, np.full(len(triangles), 3, np.int32), triangles.ravel().astype(np.int32),
                     np.asarray(mesh.patch_face)[np.asarray(mesh.triangle_patch)[rows]], triangles.astype(np.int32),
                     np.arange(len(triangles), dtype=np.int32), triangle_areas(points, triangles))


class _Table:
    """The direct light by (patch, point): the coarse corners' (a scene vertex) and the new points'
    (an object's cell point past its mesh's own), grown as points are evaluated."""

    def __init__(self, direct, triangles, tp, V):
        self.V = V
        keys, first = np.unique(np.repeat(tp, 3) * V + triangles.ravel(), return_index=True)
        flat = direct.corners.reshape(direct.corners.shape[:-3] + (-1, 3))
        self.coarse_keys, self.coarse_values, self.coarse_slot = keys, flat[..., first, :], first
        self.new_keys = np.zeros(0, np.int64)
        self.new_values = flat[..., :0, :]

    def coarse(self, patch, vertex):
        return self.coarse_values[..., found(self.coarse_keys, np.asarray(patch, np.int64) * self.V + vertex), :]

    def new(self, keys):
        return self.new_values[..., found(self.new_keys, keys), :]

    def add(self, keys, values):
        keys = np.concatenate([self.new_keys, keys])
        values = np.concatenate([self.new_values, values.astype(self.new_values.dtype)], axis=-2)
        order = np.argsort(keys, kind="stable")
        self.new_keys, self.new_values = keys[order], values[..., order, :]


def _values(table, k, points, patch, starts, meshes):
    """([G,]n,3) the direct light at object ``k``'s cell ``points`` (n,) of ``patch`` (n,)."""
    own = points < len(meshes[k].points)
    out = np.empty(table.coarse_values.shape[:-2] + (len(points), 3), table.coarse_values.dtype)
    out[..., own, :] = table.coarse(patch[own], points[own] + starts[k])
    out[..., ~own, :] = table.new(patch[~own] * FAR + points[~own])
    return out


def _chosen(cells, active, starts, patch_of, meshes, table, threshold, kept, budget, missed=None):
    """{object: (L,) bool} the cells to split this level: active, unfrozen cells of patches not ``kept`` whose
    corners' direct light differs by more than their patch's threshold (or whose patch's corners miss
    its mean: ``missed`` (P,), its score), the largest first within ``budget`` new points; None where none."""
    found = []
    for k, c in cells.items():
        rows = np.flatnonzero(active[k] & ~c.frozen)
        patch = patch_of[k][c.origin[rows]]
        rows, patch = rows[~kept[patch]], patch[~kept[patch]]
        corners = c.corners[rows]
        has = corners >= 0
        value = np.zeros(corners.shape)
        lit = _values(table, k, corners[has], np.broadcast_to(patch[:, None], corners.shape)[has], starts, meshes)
        value[has] = lit.sum(axis=-1) if lit.ndim == 2 else lit.sum(axis=(0, -1))  # (grey: every group's)
        change = np.where(has, value, -np.inf).max(axis=1) - np.where(has, value, np.inf).min(axis=1)
        score = np.divide(change, threshold[patch], out=np.zeros_like(change), where=threshold[patch] > 0)
        if missed is not None:
            score = np.maximum(score, missed[patch])
        over = score > 1.0
        found.append((k, rows[over], score[over]))
    scores = np.concatenate([s for _, _, s in found]) if found else np.zeros(0)
    room = int(budget // NEW_POINTS)
    if not scores.size or room <= 0:
        return None
    cut = np.sort(scores)[::-1][min(room, scores.size) - 1]
    out = {}
    for k, rows, score in found:
        marked = np.zeros(cells[k].count, bool)
        marked[rows[score >= cut]] = True
        if marked.any():
            out[k] = marked
    return out or None


def _evaluate(table, corner_sets, starts, meshes, cells, at_points, level, geometry=None):
    """Takes the direct light at every new (patch, point) of ``corner_sets`` [(object, points
    (n,m) (-1: none), patch (n,)[, the row of the object's triangles each cell lies in (n,)])] not
    yet in ``table``; with the rows and ``geometry``, a new point inside another object (a floor's
    under a wall standing on it) casts no rays: it takes its triangle's coarse corners'
    interpolation (``_under``)."""
    keys, positions, under = [], [], []
    for k, points, patch, *base in corner_sets:
        patch = np.broadcast_to(np.asarray(patch, np.int64)[:, None], points.shape)
        new = points >= len(meshes[k].points)
        key, first = np.unique(patch[new] * FAR + points[new], return_index=True)
        fresh = ~np.isin(key, table.new_keys)
        key, first = key[fresh], first[fresh]
        position = cells[k].points[key % FAR]
        if base and geometry is not None and key.size:
            inside = inside_other(geometry, position, key // FAR)
            if inside.any():
                row = np.broadcast_to(base[0][:, None], points.shape)[new][first][inside]
                under.append((key[inside], _under(table, meshes[k], starts[k], position[inside], key[inside] // FAR, row)))
                key, position = key[~inside], position[~inside]
        keys.append(key)
        positions.append(position)
    keys = np.concatenate(keys) if keys else np.zeros(0, np.int64)
    if keys.size:
        table.add(keys, np.asarray(at_points(np.concatenate(positions), keys // FAR, level)))
    for key, values in under:
        table.add(key, values)


def _under(table, mesh, start, position, patch, row):
    """([G,]n,3) the coarse display at new points inside another object: their triangles' (``row`` of
    ``mesh``'s) coarse corners' linear interpolation (a point nobody sees adds no shape, and a dark
    one would pull its cells' visible part down)."""
    triangle = np.asarray(mesh.triangles, np.int64)[row]
    corner = np.asarray(mesh.points, np.float64)[triangle]  # (n,3,3)
    weight = barycentric(position, corner[:, 0], corner[:, 1], corner[:, 2])
    coarse = table.coarse(np.repeat(patch, 3), triangle.ravel() + start)
    coarse = coarse.reshape(coarse.shape[:-2] + (len(patch), 3, 3))
    return (coarse * weight[:, :, None]).sum(axis=-2)


def _shading_corners(shown, refined, offsets):
    """[(object, points (n,3) in its cells, patch (n,))] the shading triangles' corners of the split objects."""
    out = []
    for k in refined:
        mesh = shown.meshes[k]
        out.append((k, np.asarray(mesh.shading_triangles, np.int64),
                    offsets[k] + shown.origin[k][np.asarray(mesh.shading_triangle_patch, np.int64)]))
    return out


def _coarse_vertices(shown, meshes, starts):
    """(V',) the scene vertex of each shown point, -1 for a new one."""
    out = []
    for k, mesh in enumerate(shown.meshes):
        own = np.full(len(mesh.points), -1, np.int64)
        own[:len(meshes[k].points)] = starts[k] + np.arange(len(meshes[k].points))
        out.append(own)
    return np.concatenate(out)


def _fine_corners(table, shown, coarse_vertex, meshes, starts, dtype):
    """([G,]T',3,3) the direct light at the shown triangles' corners."""
    point = shown.triangles.ravel().astype(np.int64)
    patch = np.repeat(shown.triangle_patch.astype(np.int64), 3)
    scene_vertex = coarse_vertex[point]
    own = scene_vertex >= 0
    out = np.empty(table.coarse_values.shape[:-2] + (len(point), 3), dtype)
    out[..., own, :] = table.coarse(patch[own], scene_vertex[own])
    k = np.searchsorted(shown.point_starts, point[~own], side="right") - 1
    out[..., ~own, :] = table.new(patch[~own] * FAR + point[~own] - shown.point_starts[k])
    return out.reshape(out.shape[:-2] + (-1, 3, 3))


def _slots(shown, coarse_vertex, vertices, triangles, tp, table):
    """((T'*3,) each shown corner's coarse corner slot, -1 for a new point; (the new points' corners
    (n,), their coarse triangle's three slots (n,3), their weights (n,3))): the linear interpolation
    in its patch's coarse triangles."""
    point = shown.triangles.ravel().astype(np.int64)
    patch = np.repeat(shown.triangle_patch.astype(np.int64), 3)
    scene_vertex = coarse_vertex[point]
    own = scene_vertex >= 0
    slots = np.full(len(point), -1, np.int32 if len(triangles) * 3 < 2**31 else np.int64)
    slots[own] = table.coarse_slot[found(table.coarse_keys, patch[own] * table.V + scene_vertex[own])]
    rest = np.flatnonzero(~own)
    tri, bary = containing(shown.vertices[point[rest]], patch[rest], vertices, triangles, tp)
    return slots, (rest, tri[:, None] * 3 + np.arange(3), bary)

