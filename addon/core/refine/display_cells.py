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
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..mesh.faces import ranks_in_runs, starts_of, triangle_areas
from ..mesh.meshing import PatchMesh
from .adaptive import cells_of, patch_mesh, split
from ..display.covered import visible_corner_weights
from ..display.point_direct import CornerDirect, patch_means
from ..display.smoothing import ITERATIONS, Surface

LEVELS = 3  # splits of a patch at most: an eighth of its side
CHANGE = 0.25  # of the patch's light: a difference between corners the eye sees as a shape, not a shade
FLOOR = 0.2  # of the mean light: the least light a difference is measured against
BUDGET = 1.0  # new points at most, a share of the split meshes' points (each costs a corner's rays)
MOST = 16_384  # and at most this many: where patches are that many, a hot spot spans patches of its own
NEW_POINTS = 3  # points a split quad adds, its four midpoints shared with neighbours
FAR = np.int64(1) << np.int64(31)  # key of a new point: patch * FAR + its point in the object's cells


@dataclass
class Shown:
    """The meshes the display is written on: per object ``meshes`` (the solve's PatchMesh, or its
    cells split), ``origin`` (each polygon's patch in the solve's mesh, or None: the solve's own);
    ``vertices`` (V',3) all objects' points, ``triangles`` (T',3) and ``triangle_patch`` (T',) (the
    solve's patches) the shading triangles, ``point_starts`` each object's first point in them."""

    meshes: list
    origin: list
    vertices: np.ndarray
    triangles: np.ndarray
    triangle_patch: np.ndarray
    point_starts: np.ndarray

    def corner_patch(self, k, patch_offset):
        """(C_k,) the solve's patch (its number in the scene) of each polygon corner of object ``k``."""
        local = self.meshes[k].corner_patch if self.origin[k] is None else self.origin[k][self.meshes[k].corner_patch]
        return np.asarray(local, np.int64) + patch_offset

    def per_polygon(self, k, values):
        """Object ``k``'s per-patch ``values`` ([S,]P_k,3) per polygon of its shown mesh."""
        return values if self.origin[k] is None else np.asarray(values)[..., self.origin[k], :]


class RefinedSurface:
    """``coarse`` (``smoothing.Surface`` of the solve's triangles) as the finer cells show it: its
    per-patch filters as they are, corner values its own interpolated at the fine corners, corner
    means the fine triangles'."""

    def __init__(self, coarse, fine, shown, slots, weights):
        self.coarse, self.fine, self.shown = coarse, fine, shown
        self.slots, self.weights = slots, weights  # (T'*3,) coarse corner slots; the new points' (``_slots``)

    def __getattr__(self, name):
        return getattr(self.coarse, name)

    @property
    def triangle_patch(self):
        return self.fine.triangle_patch

    @property
    def vertices(self):
        return self.shown.vertices

    @property
    def triangles(self):
        return self.shown.triangles

    def corner_means(self, x):
        return self.fine.corner_means(x)

    def corner_values(self, patch_values, iterations=ITERATIONS, return_filter=False, dtype=np.float64):
        """``smoothing.Surface.corner_values`` of the coarse surface at the fine corners (with
        ``return_filter``, its ``apply`` too): the same means, continuous as the coarse ones."""
        if not return_filter:
            return self.interpolated(self.coarse.corner_values(patch_values, iterations, dtype=dtype))
        corners, apply = self.coarse.corner_values(patch_values, iterations, return_filter=True, dtype=dtype)
        return self.interpolated(corners), lambda parts, dtype=np.float64: self.interpolated(apply(parts, dtype))

    def interpolated(self, corners):
        """(..., T',3,k) the fine corners of coarse ``corners`` (..., T,3,k): linear within each patch."""
        corners = np.asarray(corners)
        flat = corners.reshape(corners.shape[:-3] + (-1, corners.shape[-1]))
        out = flat[..., self.slots, :]  # (a new point's row is filled below)
        rows, slots, weights = self.weights
        mixed = flat[..., slots[:, 0], :] * weights[:, 0, None]
        for j in (1, 2):
            mixed += flat[..., slots[:, j], :] * weights[:, j, None]
        out[..., rows, :] = mixed
        return out.reshape(corners.shape[:-3] + (-1, 3, corners.shape[-1]))


def refine(coarse, direct, scene, triangles, meshes, receives, light, at_points, most=None):
    """(RefinedSurface, its CornerDirect, Shown), or None where no cell splits. ``coarse`` the
    ``smoothing.Surface`` of ``triangles`` (T,3) of the scene's vertices, ``direct`` the coarse
    CornerDirect (([G,]T,3,3)); ``meshes`` the objects' PatchMeshes in scene order, ``receives``
    whether each gets results; ``light`` (P,3) the light the patches show; ``at_points(position
    (n,3), patch (n,), level)`` the direct light ([G,]n,3) at points (``point_direct.points_direct``);
    ``most``: new points at most (a time limit's), beside the budget."""
    V = len(scene.vertices)
    triangles = np.asarray(triangles, np.int64)
    tp = np.asarray(coarse.triangle_patch, np.int64)
    table = _Table(direct, triangles, tp, V)
    starts = np.cumsum([0] + [len(m.points) for m in meshes])
    offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    splittable = [k for k, m in enumerate(meshes) if receives[k] and getattr(m, "shading_triangles", None) is None
                  and m.patch_count]
    threshold, kept = _limits(coarse, scene, light)
    # (cells of the patches' triangles: a cell's triangles never cross its patch's, so the coarse light's linear
    # interpolation at the new points keeps every patch's mean, in any triangulation of the cells' polygons; only
    # the patches whose light changes and LEVELS + 1 rings around them: the balance's splits stay among them)
    rows = {k: _region(meshes[k], offsets[k] + np.asarray(meshes[k].triangle_patch, np.int64), table, starts[k],
                       threshold, kept) for k in splittable}
    splittable = [k for k in splittable if rows[k].size]
    cells = {k: cells_of(_triangle_mesh(meshes[k], rows[k])) for k in splittable}
    patch_of = {k: offsets[k] + np.asarray(meshes[k].triangle_patch, np.int64)[rows[k]] for k in splittable}
    active = {k: np.ones(cells[k].count, bool) for k in splittable}
    budget = min(BUDGET * sum(len(meshes[k].points) for k in splittable), MOST)
    budget = budget if most is None else min(budget, most)
    for level in range(LEVELS):
        made = sum(len(c.points) - len(meshes[k].points) for k, c in cells.items())
        chosen = _chosen(cells, active, starts, patch_of, meshes, table, threshold, kept, budget - made)
        if chosen is None:
            break
        for k, marked in chosen.items():
            before = cells[k]
            cells[k], parent = split(before, marked)
            active[k] = cells[k].level > before.level[parent]
        _evaluate(table, [(k, c.corners[active[k]], patch_of[k][c.origin[active[k]]]) for k, c in cells.items()],
                  starts, meshes, cells, at_points, level)
    refined = [k for k in splittable if cells[k].level.max(initial=0) > 0]
    if not refined:
        return None
    made = {k: patch_mesh(cells[k]) for k in refined}
    shown = _shown(meshes, {k: _merged(meshes[k], mesh, patch_of[k][origin] - offsets[k]) for k, (mesh, origin) in made.items()},
                   triangles, tp, starts, offsets)
    _evaluate(table, _shading_corners(shown, refined, offsets), starts, meshes, cells, at_points, LEVELS)
    fine = _Means(shown, scene.patch_count, visible_corner_weights(scene.geometry, shown.vertices, shown.triangles,
                                                                   shown.triangle_patch))
    coarse_vertex = _coarse_vertices(shown, meshes, starts)
    slots, weights = _slots(shown, coarse_vertex, scene.vertices, triangles, tp, table)
    surface = RefinedSurface(coarse, fine, shown, slots, weights)
    corners = _fine_corners(table, shown, coarse_vertex, meshes, starts, direct.corners.dtype)
    return surface, CornerDirect(corners, patch_means(fine, corners)), shown


def _limits(coarse, scene, light):
    """((P,) the change of direct light between a cell's corners that splits it, (P,) bool the patches
    kept whole: no camera sees them, or another object runs into them (a new point inside it has no light
    of its own))."""
    grey = np.asarray(light, np.float64).sum(axis=1)
    hidden = coarse.hidden if coarse.hidden is not None else np.zeros(scene.patch_count, bool)
    seen = ~hidden & (coarse.patch_area > 0)
    kept = hidden.copy()
    if scene.geometry.buried is not None:
        kept[np.concatenate([scene.geometry.buried.patch, scene.geometry.buried.whole]).astype(np.int64)] = True
    floor = FLOOR * (grey[seen].mean() if seen.any() else 0.0)
    return CHANGE * np.maximum(grey, floor), kept


def _region(mesh, patch, table, start, threshold, kept):
    """(n,) the rows of ``mesh``'s triangles (their scene patches ``patch``) that may split: every
    triangle of the patches where one's corners' direct light differs by more than its patch's
    ``threshold``, and of LEVELS + 1 rings of patches around them (sharing a point)."""
    triangles = np.asarray(mesh.triangles, np.int64)
    values = table.coarse(np.repeat(patch, 3), triangles.ravel() + start)
    grey = (values.sum(axis=-1) if values.ndim == 2 else values.sum(axis=(0, -1))).reshape(-1, 3)
    chosen = np.zeros(int(patch.max(initial=-1)) + 1, bool)
    chosen[patch[(np.ptp(grey, axis=1) > threshold[patch]) & ~kept[patch]]] = True
    if not chosen.any():
        return np.zeros(0, np.int64)
    for _ in range(LEVELS + 1):
        near = np.zeros(len(mesh.points), bool)
        near[triangles[chosen[patch]].ravel()] = True
        chosen[patch[near[triangles].any(axis=1)]] = True
    return np.flatnonzero(chosen[patch])


def _triangle_mesh(mesh, rows):
    """The ``rows`` of ``mesh``'s triangles as a PatchMesh of their own (cells that split inside their
    patch's triangles), its points all of ``mesh``'s."""
    triangles = np.asarray(mesh.triangles, np.int64)[rows]
    points = np.asarray(mesh.points, np.float64)
    return PatchMesh(points, np.full(len(triangles), 3, np.int32), triangles.ravel().astype(np.int32),
                     np.asarray(mesh.patch_face)[np.asarray(mesh.triangle_patch)[rows]], triangles.astype(np.int32),
                     np.arange(len(triangles), dtype=np.int32), triangle_areas(points, triangles))


class _Means:
    """The fine triangles as ``Surface.corner_means`` reads them: areas, patches, the part seen."""

    corner_means = Surface.corner_means

    def __init__(self, shown, patch_count, visible=None):
        self.triangle_patch = shown.triangle_patch
        self.triangle_area = triangle_areas(shown.vertices, shown.triangles)
        self.patch_area = np.bincount(self.triangle_patch, weights=self.triangle_area, minlength=patch_count)
        self.visible = None if visible is None else np.asarray(visible, np.float64).reshape(-1)
        self.visible_area = None if visible is None else np.bincount(np.repeat(self.triangle_patch, 3), weights=self.visible,
                                                                     minlength=patch_count)

    @property
    def patch_count(self):
        return len(self.patch_area)


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
        return self.coarse_values[..., _found(self.coarse_keys, patch * self.V + vertex), :]

    def new(self, keys):
        return self.new_values[..., _found(self.new_keys, keys), :]

    def add(self, keys, values):
        keys = np.concatenate([self.new_keys, keys])
        values = np.concatenate([self.new_values, values.astype(self.new_values.dtype)], axis=-2)
        order = np.argsort(keys, kind="stable")
        self.new_keys, self.new_values = keys[order], values[..., order, :]


def _found(sorted_keys, keys):
    at = np.searchsorted(sorted_keys, keys)
    if len(keys) and (at.max() >= len(sorted_keys) or not np.array_equal(sorted_keys[at], keys)):
        raise ValueError("a corner of the display's cells has no direct light")
    return at


def _values(table, k, points, patch, starts, meshes):
    """([G,]n,3) the direct light at object ``k``'s cell ``points`` (n,) of ``patch`` (n,)."""
    own = points < len(meshes[k].points)
    out = np.empty(table.coarse_values.shape[:-2] + (len(points), 3), table.coarse_values.dtype)
    out[..., own, :] = table.coarse(patch[own], points[own] + starts[k])
    out[..., ~own, :] = table.new(patch[~own] * FAR + points[~own])
    return out


def _chosen(cells, active, starts, patch_of, meshes, table, threshold, kept, budget):
    """{object: (L,) bool} the cells to split this level: active, unfrozen cells of patches not ``kept`` whose
    corners' direct light differs by more than their patch's threshold, the largest first within
    ``budget`` new points; None where none."""
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


def _evaluate(table, corner_sets, starts, meshes, cells, at_points, level):
    """Takes the direct light at every new (patch, point) of ``corner_sets`` [(object, points
    (n,m) (-1: none), patch (n,))] not yet in ``table``."""
    keys, positions = [], []
    for k, points, patch in corner_sets:
        patch = np.broadcast_to(np.asarray(patch, np.int64)[:, None], points.shape)
        new = points >= len(meshes[k].points)
        key = np.unique(patch[new] * FAR + points[new])
        key = key[~np.isin(key, table.new_keys)]
        keys.append(key)
        positions.append(cells[k].points[key % FAR])
    keys = np.concatenate(keys) if keys else np.zeros(0, np.int64)
    if keys.size:
        table.add(keys, np.asarray(at_points(np.concatenate(positions), keys // FAR, level)))


def _shown(meshes, made, triangles, tp, starts, offsets):
    """The Shown of the objects' meshes, ``made`` {object: (PatchMesh, origin)} in place of theirs."""
    out_meshes, origin, vertices, tris, patches = [], [], [], [], []
    fine_start = 0
    point_starts = []
    for k, mesh in enumerate(meshes):
        point_starts.append(fine_start)
        if k in made:
            fine, where = made[k]
            out_meshes.append(fine)
            origin.append(np.asarray(where, np.int64))
            vertices.append(fine.points)
            tris.append(np.asarray(fine.shading_triangles, np.int64) + fine_start)
            patches.append(offsets[k] + origin[-1][np.asarray(fine.shading_triangle_patch, np.int64)])
        else:
            out_meshes.append(mesh)
            origin.append(None)
            vertices.append(mesh.points)
            rows = (tp >= offsets[k]) & (tp < offsets[k + 1])
            tris.append(triangles[rows] - starts[k] + fine_start)
            patches.append(tp[rows])
        fine_start += len(vertices[-1])
    return Shown(out_meshes, origin, np.concatenate(vertices).astype(np.float64), np.concatenate(tris),
                 np.concatenate(patches), np.asarray(point_starts, np.int64))


def _merged(coarse, fine, origin):
    """(the cells' PatchMesh ``fine`` with every patch whose triangles none split nor took a point (or
    that no cell covers) written as the ``coarse`` patch's own polygon, each polygon's coarse patch): the written mesh's
    polygons a patch each where nothing changed (a quad, not its two triangles)."""
    sizes = np.asarray(fine.face_sizes, np.int64)
    P = coarse.patch_count
    count = np.bincount(origin, minlength=P)
    whole = (count == 0) | (count == np.bincount(np.asarray(coarse.triangle_patch, np.int64), minlength=P)) & (
        np.bincount(origin, weights=sizes != 3, minlength=P) == 0)
    keep = ~whole[origin]  # (the fine polygons written)
    polygon_patch = np.concatenate([np.flatnonzero(whole), origin[keep]])
    order = np.argsort(polygon_patch, kind="stable")
    polygon_patch = polygon_patch[order]
    coarse_sizes = np.asarray(coarse.face_sizes, np.int64)
    coarse_starts, fine_starts = starts_of(coarse_sizes), starts_of(sizes)
    source = np.concatenate([np.flatnonzero(whole), np.flatnonzero(keep)])[order]  # coarse patch, or fine polygon
    is_coarse = np.concatenate([np.ones(whole.sum(), bool), np.zeros(keep.sum(), bool)])[order]
    new_sizes = np.where(is_coarse, coarse_sizes[np.where(is_coarse, source, 0)], sizes[np.where(is_coarse, 0, source)])
    first = np.where(is_coarse, coarse_starts[np.where(is_coarse, source, 0)], fine_starts[np.where(is_coarse, 0, source)])
    rank = ranks_in_runs(new_sizes)
    at = np.repeat(first, new_sizes) + rank
    corner_verts = np.where(np.repeat(is_coarse, new_sizes), np.asarray(coarse.corner_verts, np.int64)[np.minimum(at, len(coarse.corner_verts) - 1)],
                            np.asarray(fine.corner_verts, np.int64)[np.minimum(at, len(fine.corner_verts) - 1)])
    # the shading triangles: a whole patch's own, a split one's cells'
    renumber = np.full(len(sizes), -1, np.int64)
    renumber[source[~is_coarse]] = np.flatnonzero(~is_coarse)
    whole_number = np.full(P, -1, np.int64)
    whole_number[source[is_coarse]] = np.flatnonzero(is_coarse)
    ctp = np.asarray(coarse.triangle_patch, np.int64)
    from_coarse = np.flatnonzero(whole[ctp])
    ftp = np.asarray(fine.shading_triangle_patch, np.int64)
    from_fine = np.flatnonzero(renumber[ftp] >= 0)
    tris = np.concatenate([np.asarray(coarse.triangles, np.int64)[from_coarse], np.asarray(fine.shading_triangles, np.int64)[from_fine]])
    tri_polygon = np.concatenate([whole_number[ctp[from_coarse]], renumber[ftp[from_fine]]])
    tri_order = np.argsort(tri_polygon, kind="stable")
    tris, tri_polygon = tris[tri_order], tri_polygon[tri_order]
    area = np.bincount(tri_polygon, weights=triangle_areas(fine.points, tris), minlength=len(source))
    mesh = PatchMesh(fine.points, new_sizes.astype(np.int32), corner_verts.astype(np.int32),
                     np.asarray(coarse.patch_face)[polygon_patch].astype(np.int32), tris.astype(np.int32),
                     tri_polygon.astype(np.int32), area)
    mesh.shading_triangles, mesh.shading_triangle_patch = mesh.triangles, mesh.triangle_patch
    return mesh, polygon_patch


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
    point = shown.triangles.ravel()
    patch = np.repeat(shown.triangle_patch, 3)
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
    point = shown.triangles.ravel()
    patch = np.repeat(shown.triangle_patch, 3)
    scene_vertex = coarse_vertex[point]
    own = scene_vertex >= 0
    slots = np.full(len(point), -1, np.int64)
    slots[own] = table.coarse_slot[_found(table.coarse_keys, patch[own] * table.V + scene_vertex[own])]
    rest = np.flatnonzero(~own)
    tri, bary = containing(shown.vertices[point[rest]], patch[rest], vertices, triangles, tp)
    return slots, (rest, tri[:, None] * 3 + np.arange(3), bary)


def containing(x, patch, vertices, triangles, tp):
    """((n,) the triangle of its ``patch`` each point ``x`` (n,3) lies in, (n,3) its barycentric
    coordinates there, clipped to the triangle): the nearest where it lies in none (float error)."""
    order = np.argsort(tp, kind="stable")
    count = np.bincount(tp, minlength=int(patch.max(initial=-1)) + 1)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    best = np.full(len(x), -np.inf)
    tri = np.zeros(len(x), np.int64)
    bary = np.zeros((len(x), 3))
    for j in range(int(count[patch].max(initial=0))):
        has = np.flatnonzero(count[patch] > j)
        t = order[first[patch[has]] + j]
        b = barycentric(x[has], *(vertices[triangles[t, c]] for c in range(3)))
        better = b.min(axis=1) > best[has]
        rows = has[better]
        best[rows], tri[rows], bary[rows] = b[better].min(axis=1), t[better], b[better]
    bary = np.clip(bary, 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    return tri, bary


def barycentric(x, a, b, c):
    """(n,3) the barycentric coordinates of points ``x`` (n,3) in triangles (a, b, c), each (n,3),
    of their projection onto its plane."""
    v0, v1, v2 = b - a, c - a, x - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    denominator = d00 * d11 - d01 * d01
    denominator = np.where(denominator != 0, denominator, 1.0)
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    return np.stack([1.0 - v - w, v, w], axis=1)


def corner_weights(coarse, fine, origin):
    """((C',3) corners of the ``coarse`` PatchMesh, (C',3) weights): each polygon corner of its
    ``fine`` cells (``origin`` (polygons,) the coarse patch of each) as the linear interpolation of
    its coarse patch's polygon corners (a coarse point: its own corner), for values kept per polygon
    corner (the source's UV maps, colours, normals)."""
    points = len(coarse.points)
    key = np.asarray(coarse.corner_patch, np.int64) * points + np.asarray(coarse.corner_verts, np.int64)
    order = np.argsort(key, kind="stable")
    vertex = np.asarray(fine.corner_verts, np.int64)
    patch = np.asarray(origin, np.int64)[fine.corner_patch]
    corner_vertex = np.repeat(vertex[:, None], 3, axis=1)
    weights = np.zeros((len(vertex), 3))
    weights[:, 0] = 1.0
    new = np.flatnonzero(vertex >= points)
    triangles = np.asarray(coarse.triangles, np.int64)
    tri, bary = containing(np.asarray(fine.points, np.float64)[vertex[new]], patch[new], np.asarray(coarse.points, np.float64),
                           triangles, np.asarray(coarse.triangle_patch, np.int64))
    corner_vertex[new], weights[new] = triangles[tri], bary
    wanted = patch[:, None] * points + corner_vertex
    return order[_found(key[order], wanted.ravel())].reshape(-1, 3), weights
