"""Rays of a walk: leaving a patch, tracing them, and where a hit goes on from.

Rays leave a patch from a new uniform point of it (exit_point="random", the paper's discrete
method) or from where the previous ray hit (exit_point="hit"), in a cosine-distributed
direction about the patch's normal, from a point pushed off the surface. Points and directions
are (3,n) float32 rows, one coordinate per row, in unit space; the ray tracer reads (n,3) views
of them. A hit on a patch's back side is a hit all the same: the walk absorbs it ("blocked").
A path's first ray from an emitting patch leaves its front or its back, half each (emitting
patches emit from both sides, as Cycles' do: ``emitter_backs``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..lights.sampling import add_sphere_points, choose_triangles, frame_points

# Where a ray that missed "hits" when a hit-point exit makes points of every ray (unit space;
# float32 holds it times a direction of length <= 2 without overflow).
MISS_DISTANCE = np.float32(1e30)


@dataclass
class Hits:
    """What a step's rays met first."""

    hit: np.ndarray                  # (n,) triangle (or, on grids for a random exit, patch); -1: nothing
    patch: np.ndarray                # (n,) int32 its patch (a miss reads as patch 0)
    front: np.ndarray                # (n,) bool: it met that patch's front side
    points: np.ndarray | None = None  # (3,n) where (exit_point="hit"), not yet pushed off


def leave_sources(tables, source, u, first_new=0):
    """:func:`leave_random` for paths on patches; paths just started at a light (a source id
    from the patch count on) take that light's rays, from the same uniforms u[0:4]; paths just
    started (columns from ``first_new`` on) at an emitting patch leave its front or its back
    (:func:`emitter_backs`)."""
    back = emitter_backs(tables, source, u[3], first_new)
    light = light_columns(tables, source)
    if light is None:
        origins, directions = leave_random(tables, source, u)
    else:
        u_light = u[:4, light].copy()  # (before leave_random folds points onto triangles)
        origins, directions = leave_random(tables, on_patches(tables, source), u)
        set_light_rays(tables, source[light], u_light, origins, directions, light)
    if back is not None:
        turn_to_backs(tables, source.take(back), origins, directions, back)
    return origins, directions


def emitter_backs(tables, source, u, first_new=0):
    """The columns, from ``first_new`` on, of new paths at emitting patches (source ids below
    the patch count) that leave the patch's back: those whose direction uniform ``u`` (n,) is
    1/2 or more. Every new column's ``u`` is then 2u modulo 1 (in place, exact in float32): still
    uniform, and independent of the side. Only patches whose back emits (``tables.emitter_backs``)
    leave it; None where no new path leaves a back."""
    if tables.emitter_backs is None or first_new >= source.size:
        return None
    v = u[first_new:]
    v *= np.float32(2.0)
    back = v >= 1
    v -= back
    new = source[first_new:]
    back &= tables.emitter_backs.take(new, mode="wrap")
    if tables.lights is not None:
        back &= new < tables.patch_count
    columns = np.flatnonzero(back)
    return columns + first_new if columns.size else None


def turn_to_backs(tables, patch, origins, directions, columns):
    """Turns the rays in ``columns`` of (3,n) ``origins`` and ``directions``, leaving the fronts
    of ``patch`` (one a column) in cosine directions n + s, to leave their backs: the
    origin pushed off the other side, the direction -(n + s) (cosine-distributed about -n)."""
    g = tables.geometry
    offset = g.ray_offset if g.patch_ray_offset is None else g.ray_offsets(patch)
    origins[:, columns] -= patch_normals(tables, patch) * (2 * offset)
    directions[:, columns] *= np.float32(-1.0)


def light_columns(tables, source):
    """The columns of ``source`` that are lights' emitters, or None (no lights, or none there)."""
    if tables.lights is None:
        return None
    light = np.flatnonzero(source >= tables.patch_count)
    return light if light.size else None


def on_patches(tables, source):
    """``source`` with every light's emitter replaced by patch 0 (to gather patch tables with)."""
    return np.where(source < tables.patch_count, source, 0).astype(source.dtype)


def region_of(tables, source):
    """(n,) the region frame (.regions) of rays leaving ``source`` (patches, or lights' emitters
    from the patch count on), or None where the scene is one frame."""
    g = tables.geometry
    if g.regions is None:
        return None
    region = g.regions.of(on_patches(tables, source) if tables.lights is not None else source)
    light = light_columns(tables, source)
    if light is not None:
        region[light] = tables.lights.regions(source[light] - tables.patch_count, g)
    return region


def set_light_rays(tables, source, u, origins, directions, columns):
    """Rays from the lights' emitters ``source`` (ids from the patch count on) with uniforms
    ``u`` (4, m), written into ``columns`` of (3,n) ``origins`` and ``directions`` (unit space:
    ``tables.lights`` is a Lights table, or the gathered first shot's ReflectedPoints)."""
    o, d = tables.lights.unit_rays(source - tables.patch_count, u, tables.geometry)
    origins[:, columns] = o
    directions[:, columns] = d


def leave_random(tables, patch, u):
    """Rays leaving the given patches from uniform points (``u[0]``, ``u[1]``, and
    ``u[row_triangle]`` to choose a triangle), in cosine-distributed directions (``u[2]``,
    ``u[3]``): (origins, directions)."""
    return rays_from_frames(leave_frames(tables, patch, u), u[0], u[1], u[2:4])


def rays_from_frames(frame, a, b, u_direction):
    """Rays from gathered (12,n) frame rows [corner, edge a, edge b, normal]: origins
    corner + a edge_a + b edge_b, directions normal + a uniform sphere point (cosine
    distributed), computed in place in ``frame``. Returns two (3,n) views of it."""
    return frame_points(frame, a, b), add_sphere_points(frame[9:12], u_direction[0], u_direction[1])


def leave_frames(tables, patch, u):
    """The (12,n) frames the given patches' rays leave from (corner, edge a, edge b, normal):
    their parallelograms' or, where a patch is not one, a triangle's of it (chosen with
    ``u[row_triangle]``, ``u[0]`` and ``u[1]`` folded onto it in place: leave_columns). Points
    of partly buried patches are drawn on their visible part (their uniforms remapped in place)."""
    g = tables.geometry
    if g.buried is not None:
        g.buried.remap(patch, u[tables.row_triangle] if tables.row_triangle is not None else None, u[0], u[1])
    if tables.patch_class is not None:
        frame = np.empty((12, patch.size), dtype=np.float32)
        tables.leave_corners.take(patch, axis=1, mode="wrap", out=frame[0:3])
        tables.class_shape.take(tables.class_of(patch), axis=1, mode="wrap", out=frame[3:12])
        return frame
    if tables.geometry.all_parallelograms:
        return tables.leave_table.take(patch, axis=1, mode="wrap")
    return tables.exit_table.take(leave_columns(tables, patch, u), axis=1, mode="wrap")


def leave_columns(tables, patch, u):
    """The exit-table column each path leaves from: its patch's parallelogram, or a triangle of
    the patch chosen by area with ``u[row_triangle]``. Where that is a triangle, folds
    (u[0], u[1]) onto it in place (u0 + u1 > 1 reflects: uniform)."""
    g = tables.geometry
    if g.all_parallelograms:
        return patch + g.triangle_count
    column = choose_triangles(g, patch, u[tables.row_triangle])
    fold = u[0] + u[1] > 1
    if g.any_parallelograms:
        parallelogram = g.patch_parallelogram.take(patch, mode="wrap")
        column = select(parallelogram, patch + g.triangle_count, column)
        fold &= ~parallelogram
    # u -> 1 - u where folded, as |fold - u| (exact in float32 for u in [0, 1)).
    fold = fold.astype(np.float32)
    for row in (0, 1):
        np.subtract(fold, u[row], out=u[row])
        np.abs(u[row], out=u[row])
    return column


def patch_normals(tables, patch):
    """(3,n) float32 rows: the given patches' normals."""
    if tables.patch_class is not None:
        return tables.class_normals.take(tables.class_of(patch), axis=1, mode="wrap")
    return tables.geometry.patch_normal_rows.take(patch, axis=1, mode="wrap")


def cast(tables, origins, directions, region=None):
    """A random exit's rays, traced outside the numpy turn: Hits without points. On the grids a
    hit's patch is its grid cell and the facing test reads Embree's geometric normal of the
    triangle hit, whose sign the grids keep (no table is read). ``region``: each origin's
    region frame (:func:`region_of`), where the scene has regions."""
    if tables.grids is not None:
        triangle, u, v, _, normal = tables.outside_turn(tables.tracer.first_hit_barycentric, origins.T, directions.T)
        hit = tables.grids.hit_patches(triangle, u, v)
        patch, front = np.maximum(hit, 0), meets_front(directions, normal)
    else:
        hit = tables.outside_turn(tables.tracer.first_hit, origins.T, directions.T, region)
        patch = hit_patches(tables, hit)
        front = facing(tables, directions, hit, patch)
    front &= hit >= 0
    return Hits(hit, patch, front)


def cast_to_points(tables, origins, directions, region=None):
    """A hit-point exit's rays, traced outside the numpy turn: Hits with the points they go on
    from (computed in place in ``origins``; ``directions`` is overwritten). ``region`` as for
    :func:`cast`."""
    hit, u, v, distance, normal = tables.outside_turn(tables.tracer.first_hit_barycentric, origins.T, directions.T, region)
    patch = hit_patches(tables, hit, u, v)
    front = meets_front(directions, normal)
    front &= hit >= 0
    return Hits(hit, patch, front, hit_points(tables, origins, directions, distance, hit, patch, u, v, front))


def hit_patches(tables, hit, u=None, v=None):
    """The patch of each hit triangle, int32: where the walk traces grids, the cell of the hit's
    barycentric (``u``, ``v``). A miss (-1) reads as patch 0 (misses are dropped): no negative
    index reaches a gather, where numpy would branch on each index's sign."""
    if tables.grids is not None:
        patch = tables.grids.hit_patches(hit, u, v)
        return np.maximum(patch, 0, out=patch)
    triangle = np.maximum(hit, 0)
    if tables.paired_triangles:
        triangle >>= 1
        return triangle
    return tables.geometry.triangle_patch.take(triangle, mode="wrap")


def facing(tables, directions, hit, hit_patch):
    """Whether each ray (a (3,n) direction row) meets the front side of what it hit."""
    if tables.patch_class is not None:
        return dot_negative(directions, tables.class_normals.take(tables.class_of(hit_patch), axis=1, mode="wrap"))
    rows = tables.facing_rows.take(hit_patch if tables.facing_by_patch else np.maximum(hit, 0), axis=1, mode="wrap")
    return dot_negative(directions, rows)


def hit_points(tables, origins, directions, distance, hit, hit_patch, u, v, front):
    """Where the rays that hit a front side (``front``) go on from, not yet pushed off the
    surface: (3,n) rows, computed in place in ``origins`` (``directions`` is overwritten).

    The hit point is origin + t direction, which the walk has at hand: no table of triangles is
    read. Within the clearance of an edge of the triangle traced (barycentric coordinate below
    its ``edge_barycentric``), float32 rounding could put that point past the edge, behind an
    adjacent wall; those few points are the hit's barycentrics mapped onto the triangle's
    ``hit_frames`` column: its inset leaving frame (on grids, its rectangle's)."""
    # A miss has t = inf: clamped (inf x 0 would be NaN), its far point is dropped with the miss.
    np.minimum(distance, MISS_DISTANCE, out=distance)
    directions *= distance
    origins += directions
    nearest = np.minimum(u, v)
    np.minimum(nearest, 1 - u - v, out=nearest)
    if tables.class_edge_barycentric is not None:
        limit = tables.class_edge_barycentric.take(tables.class_of(hit_patch), mode="wrap")
    else:
        limit = tables.edge_barycentric.take(np.maximum(hit, 0), mode="wrap")
    near = nearest < limit
    if tables.geometry.regions is not None:
        # origin + t direction is in the origin's frame, not the hit's (or far from it): every
        # hit point is made from its barycentrics, in its own region's frame.
        near[:] = True
    near &= front
    index = np.flatnonzero(near)
    if index.size:
        frame = tables.hit_frames.take(hit.take(index, mode="wrap"), axis=1, mode="wrap")
        # The frame's corner is pushed off along the triangle's normal; the walk pushes every
        # hit point along its patch's normal (frame rows 9:12): take that off here.
        g = tables.geometry
        offset = g.ray_offset if g.patch_ray_offset is None else g.ray_offsets(hit_patch.take(index, mode="wrap"))
        pushed_back = frame[9:12] * offset
        points = frame_points(frame, u.take(index, mode="wrap"), v.take(index, mode="wrap"))
        points -= pushed_back
        origins[:, index] = points
    return origins


def select(mask, value, other):
    """np.where(mask, value, other) for integers, as other + (value - other) mask: np.where
    branches on every element, and on a random mask its mispredictions cost ten times this."""
    out = value - other
    out *= mask
    out += other
    return out


def dot_negative(directions, normals):
    """direction . normal < 0 per column of two (3,n) row arrays."""
    return np.einsum("ij,ij->j", directions, normals) < 0


def meets_front(directions, normal):
    """direction . Ng < 0 for (3,n) direction rows and the ray tracer's (n,3) geometric normals
    (three passes over Ng's strided columns: faster than einsum's)."""
    dot = normal[:, 0] * directions[0]
    dot += normal[:, 1] * directions[1]
    dot += normal[:, 2] * directions[2]
    return dot < 0
