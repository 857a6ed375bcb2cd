"""The two shooting random walk estimators of Sbert & Brusi, advanced as a wavefront.

A batch of paths ("chunk") is traced as a wavefront: every live path advances one bounce per
step, and the live paths' rays go to the ray tracer together. As paths end, new ones start from
the sources in their places, so every step traces about ``WAVEFRONT_PATHS`` rays (arrays that
stay in the processor's cache) until the chunk's last paths run out. Scores accumulate with
``np.bincount``. Small chunks go through in groups (``walk_chunks``): one wavefront, each path
tagged with its chunk, every chunk with its own tallies. Walks on several threads take turns
at their numpy work (``WalkTables.numpy_turn``) and trace at the same time.

Weights are relative: a path from source i starts with per-channel weight E_ic / E_bar_i (1 in a
grey scene), and the true carried power is that weight times Phi_T / N. What a chunk tallies is
the power *incident* on each patch's front side, I_j; the reflected radiosity is
b_j = R_j I_j (Phi_T / N) / A_j.

- ``finite`` (the paper's Phi_T estimator): the carried power never changes; each hit scores,
  then the path survives with probability R_bar_j (the patch's mean reflectivity). In colour,
  survivors multiply each channel by R_jc / R_bar_j, so every channel stays unbiased.
- ``biased_infinite``: each hit scores, the carried power is multiplied by R_jc, and the path
  goes on until the product of (mean) reflectivities along it falls below the threshold t.
  The power still carried at that moment is "undistributed".

Rays that hit nothing escape; rays that hit a patch's back side are absorbed there ("blocked"):
radiosity leaves only the front side of a patch. Where the patches tile grids, walks trace the
grids instead of the patches' triangles and read a hit's patch off its grid cell
(``patch_grids``): a random exit's "hits" are then patches.

Rays leave a patch from a new uniform point of it (``exit_point="random"``, the paper's
discrete method and the default) or from where the ray arrived (``"hit"``: origin + t
direction, see ``WalkTables.hit_points``), in a cosine-distributed direction about the patch's
normal, from a point pushed off the surface.

A grey finite walk leaving from random points (the paper's plain estimator, and the default)
has interchangeable paths: each is nothing but the patch it is on. It runs in its own loop
(``_walk_exchangeable``) that regroups a step's rays by outcome with one bincount or one sort
instead of selecting survivors path by path.

Gathers use ``take(..., mode="wrap")``: every index is valid by construction (a ray tracer's
miss, -1, is only ever gathered to be masked out), and numpy's wrapping gather is about twice
as fast as its checking one.
"""
from __future__ import annotations

import threading
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from .sampling import SourceTable, add_sphere_points, channel_sum, choose_triangles, frame_points

# Rays per step while the chunk still has paths to start: big enough that numpy's per-call
# cost is small next to the work, small enough that a step's arrays stay in cache.
WAVEFRONT_PATHS = 1 << 14
# Paths that carry weights or hit points are sorted by patch at each step in scenes of at
# least this many patches (below it every table fits in cache and the sort costs as much as
# coherent rays and in-order gathers gain; above it, on the figure-4 room, the random exit's
# frame gather takes 75 instead of 180 us a step and the tracing 4% less).
SORT_MIN_PATCHES = 1 << 13
# Scored hits are kept per step and added up (one bincount) every this many hits, or every
# this many per patch if that is fewer.
SCORE_FLUSH = 1 << 18
SCORE_FLUSH_PER_PATCH = 4
# A grey finite walk leaving from random points, in a scene of at most this many patches,
# counts its hits per patch and outcome at every step (one bincount) and restarts the
# survivors from those counts, instead of selecting them path by path (see _walk_exchangeable).
COUNTED_MAX_PATCHES = 1 << 12

# In scenes of at least CLASSES_MIN_PATCHES parallelograms, whose per-patch tables outgrow the
# caches, patches are put in classes of one leaving-frame shape and one mean reflectivity
# (patches meshed from one face share a shape, and a material its reflectivity), if there are
# at most PATCH_CLASSES_MAX classes (2^12 classes take 200 kB; more, and the classes are the
# shapes alone, R_bar read per patch: _patch_classes). The walk then reads a leaving
# frame as the patch's corner and its class's shape, and a hit patch's normal and R_bar as its
# class's: between two ray casts it reads 3 rows of P corners and 2 bytes a patch where it read
# 12 rows of P and 8 bytes. In the figure 4 room (66,572 patches, 23 classes) that is about
# 3 MB less memory read a step, out of caches it shares with the ray tracer's scene (about
# 10 MB): the walk's numpy work fetched 30-40% fewer lines from memory, and the whole walk
# took 5-10% fewer cycles a ray (measured with the processor's counters, in quiet and busy
# hours of this shared machine).
CLASSES_MIN_PATCHES = 1 << 13
PATCH_CLASSES_MAX = 1 << 12

# Where a ray that missed "hits" when a hit-point exit makes points of every ray (unit space;
# float32 holds it times a direction of length <= 2 without overflow).
MISS_DISTANCE = np.float32(1e30)

FINITE = "finite"
BIASED_INFINITE = "biased_infinite"
ESTIMATORS = (FINITE, BIASED_INFINITE)
EXIT_RANDOM = "random"
EXIT_HIT = "hit"
EXIT_POINTS = (EXIT_RANDOM, EXIT_HIT)


class WalkTables:
    """Per-solve tables: materials in the layouts the walk reads, shared by all chunks."""

    def __init__(self, scene, estimator, threshold, exit_point, stratified=False):
        self.geometry = scene.geometry
        self.estimator = estimator
        self.threshold = float(threshold)
        self.exit_random = exit_point == EXIT_RANDOM
        self.stratified = bool(stratified)
        self.patch_count = scene.patch_count
        self.sources = SourceTable(scene.patch_area, scene.emission)
        R = scene.reflectivity
        self.mean_reflectivity = scene.mean_reflectivity  # R_bar (P,)
        # Grey scenes carry one channel; colour scenes three.
        self.channels = 1 if scene.is_grey else 3
        self.reflectivity = np.ascontiguousarray(R[:, : self.channels].T)  # (C,P)
        self.emission = scene.emission  # (P,3), for start_weight
        # float32 uniforms for a ray leaving from a new point of its patch: point (2),
        # direction (2), then a triangle choice unless every patch is a parallelogram. A ray
        # leaving from the hit point needs the direction's two only. The finite estimator's
        # survival test draws float64 (a float32 draw would quantise the survival probability
        # to multiples of 2^-24: a relative bias of up to 2^-24 / (1 - R) in 1 - R, 0.6% at
        # R = 0.99999).
        self.uniforms_per_ray = 4
        self.row_triangle = None
        if not self.geometry.all_parallelograms:
            self.row_triangle = self.uniforms_per_ray
            self.uniforms_per_ray += 1
        # In a grey finite walk every weight stays exactly 1: no weight arrays at all. In a grey
        # biased walk the weight is the product of reflectivities, which is the product of mean
        # reflectivities the threshold test keeps anyway (exactly: R_bar = R in grey): one array.
        self.unit_weights = estimator == FINITE and self.channels == 1
        self.weight_is_accumulated = estimator != FINITE and self.channels == 1
        # Paths of a grey finite walk leaving from random points are interchangeable: a path
        # is nothing but the patch it is on (_walk_exchangeable: counted in small scenes,
        # sorted by patch in bigger ones).
        self.exchangeable = self.unit_weights and self.exit_random
        self.counted = self.exchangeable and scene.patch_count <= COUNTED_MAX_PATCHES
        # Other walks keep their paths grouped by patch too in big scenes (a permutation of
        # what they carry, by a 16-bit key patch >> shift and numpy's radix sort).
        self.sort_paths = not self.exchangeable and scene.patch_count >= SORT_MIN_PATCHES
        self.patch_key_shift = max(0, int(scene.patch_count - 1).bit_length() - 16)
        # Where rays leave from: parallelogram patches (all of them, usually) from one column
        # each of the leave table; other patches from a triangle of theirs, chosen by area,
        # in the exit table, which also holds every triangle: a hit-point exit maps hits near
        # a triangle's edges onto its inset frame there (hit_points).
        if self.geometry.all_parallelograms:
            self.leave_table = self.geometry.leave_table
        # Patch classes (_patch_classes): in a big scene of parallelograms, a patch's leaving
        # frame is its corner and its class's shape, and a hit patch's normal and R_bar are its
        # class's.
        self.patch_class = None
        if self.geometry.all_parallelograms and self.patch_count >= CLASSES_MIN_PATCHES:
            classes = _patch_classes(self.geometry, self.mean_reflectivity)
            if classes is not None:
                self.patch_class, self.class_shape, self.class_mean_reflectivity, class_shape_index = classes
                self.class_normals = np.ascontiguousarray(self.class_shape[6:9])
                self.leave_corners = self.leave_table[0:3]  # contiguous: the table's first rows
        # The patch of a hit triangle: in a scene of parallelograms the triangles come in pairs,
        # in patch order (triangle t is half of patch t >> 1), so no table is read for it.
        self.paired_triangles = self.geometry.all_parallelograms
        # A walk needs nothing of a hit but its patch, its side and (leaving from hit points)
        # where it is: where the patches tile grids, Embree traces the grids (two triangles
        # each, beside the other patches' own triangles) and a hit's patch is its grid cell
        # (patch_grids). A random exit's "hits" are then patches (-1 a miss), and its facing
        # test reads Embree's normal (cast); a hit-point exit's hits are the grids' triangles.
        self.grids = self.geometry.patch_grids
        # The Embree scene the walk traces, built here (once per geometry), not on a thread.
        self.tracer = self.geometry.tracer if self.grids is None else self.grids.tracer
        if not self.geometry.all_parallelograms:
            self.exit_table = self.geometry.exit_table
        # A hit-point exit's edge thresholds and the frames a hit near an edge of the triangle
        # traced is mapped onto (hit_points); on the patches' triangles with patch classes, the
        # thresholds are read per class (one per shape: Geometry.edge_barycentric).
        self.class_edge_barycentric = None
        if not self.exit_random:
            if self.grids is None:
                self.hit_frames, self.edge_barycentric = self.geometry.exit_table, self.geometry.edge_barycentric
                if self.patch_class is not None:
                    self.class_edge_barycentric = self.geometry.shape_edge_barycentric[class_shape_index]
            else:
                self.hit_frames, self.edge_barycentric = self.grids.hit_frames, self.grids.edge_barycentric
        # The facing test of a ray leaving from a random point where the walk traces the
        # patches' triangles (not grids, see cast): in a scene of parallelograms
        # (two exactly coplanar triangles each) against the hit patch's normal, read from the
        # rows of the leave table that the next step gathers again for the survivors (the
        # walk touches less memory between ray casts); otherwise against the triangle's.
        self.facing_by_patch = self.geometry.all_parallelograms
        self.facing_rows = self.leave_table[9:12] if self.facing_by_patch else self.geometry.triangle_normal_rows
        # Walks on several threads take turns at their numpy work: a walk holds this lock
        # except while it traces (see walk_chunks).
        self.numpy_turn = threading.Lock()

    # A colour walk's per-channel weights, made when a walk first reads them (a grey walk never
    # does: it carries no per-channel weights).
    @cached_property
    def survivor_weight(self):
        """R_jc / R_bar_j (C,P): what survivors multiply each channel's weight by."""
        R = self.reflectivity
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(self.mean_reflectivity > 0, R / self.mean_reflectivity, 0.0)

    @cached_property
    def start_weight(self):
        """E_ic / E_bar_i (C,P): a path's starting weight from source i."""
        E = self.emission
        mean_emission = channel_sum(E) / 3  # bit for bit E.mean(axis=1), at a tenth of its cost
        with np.errstate(invalid="ignore", divide="ignore"):
            start = np.where(mean_emission > 0, E[:, : self.channels].T / mean_emission, 0.0)
        return np.ascontiguousarray(start)  # (E.T's rows: the division keeps its column order)

    def cast(self, origins, directions):
        """A random exit's rays ((3,n) rows), traced outside the numpy turn: (hit, hit_patch,
        front). ``hit`` is what each ray hits first, its triangle (where the walk traces grids,
        its patch), -1 where it hits nothing; ``hit_patch`` its patch (a miss reads as patch 0);
        ``front`` whether it meets that patch's front side (read only where it hit). On the
        grids, a hit's patch is its grid cell and the facing test reads Embree's geometric
        normal of the triangle hit, whose sign the grids keep (no table is read)."""
        if self.grids is not None:
            triangle, u, v, _, normal = self._outside_turn(self.tracer.first_hit_barycentric, origins.T, directions.T)
            hit = self.grids.hit_patches(triangle, u, v)
            return hit, np.maximum(hit, 0), _meets_front(directions, normal)
        hit = self._outside_turn(self.tracer.first_hit, origins.T, directions.T)
        hit_patch = self.hit_patches(hit)
        return hit, hit_patch, self.facing(directions, hit, hit_patch)

    def first_hit_barycentric(self, origins, directions):
        """The ray tracer's first hits with their points and normals, outside the numpy turn."""
        return self._outside_turn(self.tracer.first_hit_barycentric, origins, directions)

    def _outside_turn(self, trace, origins, directions):
        self.numpy_turn.release()
        try:
            return trace(origins, directions)
        finally:
            self.numpy_turn.acquire()

    def hit_patches(self, hit, u=None, v=None):
        """The patch of each hit triangle, int32: where the walk traces grids, the cell of the
        hit's barycentric (``u``, ``v``). A miss (-1) reads as patch 0 (misses are dropped). No
        negative index reaches a gather: with mode="wrap" numpy branches on each index's sign, a
        mispredicted branch per miss, which tripled a 3-row gather's cost in an open scene."""
        if self.grids is not None:
            patch = self.grids.hit_patches(hit, u, v)
            return np.maximum(patch, 0, out=patch)
        triangle = np.maximum(hit, 0)
        if self.paired_triangles:
            triangle >>= 1
            return triangle
        return self.geometry.triangle_patch.take(triangle, mode="wrap")

    def _class_of(self, patch):
        """The class of each of the given patches (a big scene's patch classes only)."""
        return self.patch_class.take(patch, mode="wrap")

    def facing(self, directions, hit, hit_patch):
        """Whether each ray (a (3,n) direction row) meets the front side of what it hit."""
        if self.patch_class is not None:
            hit_class = self._class_of(hit_patch)
            return _facing(directions, self.class_normals.take(hit_class, axis=1, mode="wrap"))
        normals = self.facing_rows.take(hit_patch if self.facing_by_patch else np.maximum(hit, 0), axis=1, mode="wrap")
        return _facing(directions, normals)

    def mean_reflectivity_at(self, patch):
        """R_bar of each of the given patches (float64)."""
        if self.patch_class is not None and self.class_mean_reflectivity is not None:
            return self.class_mean_reflectivity.take(self._class_of(patch), mode="wrap")
        return self.mean_reflectivity.take(patch, mode="wrap")

    def hit_points(self, origins, directions, distance, hit, hit_patch, u, v, front):
        """Where the rays that hit a front side (``front``) go on from, not yet pushed off the
        surface: (3,n) rows, computed in place in ``origins`` (``directions`` is overwritten).

        The hit point is origin + t direction, which the walk has at hand: no table of
        triangles is read, so the ray tracer's structure stays in the caches. Within the
        clearance of an edge of the triangle traced (barycentric coordinate below the
        triangle's ``edge_barycentric``), float32 rounding could put that point past the edge,
        behind an adjacent wall; those few points are the hit's barycentric coordinates mapped
        onto the triangle's ``hit_frames`` column: its inset leaving frame, as in
        :meth:`leave_random`, or where the walk traces grids its rectangle's inset frame (or
        another patch's triangle's)."""
        # A miss has t = inf: clamped to a finite MISS_DISTANCE (inf x 0 would be NaN, with a
        # warning), its point is far away and dropped with the miss.
        np.minimum(distance, MISS_DISTANCE, out=distance)
        directions *= distance
        origins += directions
        nearest = np.minimum(u, v)
        np.minimum(nearest, 1 - u - v, out=nearest)
        if self.class_edge_barycentric is not None:
            # (a random gather from a small table, not from one of T triangles: the tables a
            # step reads between ray casts stay small, see CLASSES_MIN_PATCHES)
            hit_class = self._class_of(hit_patch)
            limit = self.class_edge_barycentric.take(hit_class, mode="wrap")
        else:
            limit = self.edge_barycentric.take(np.maximum(hit, 0), mode="wrap")  # (see hit_patches)
        near = nearest < limit
        near &= front
        index = np.flatnonzero(near)
        if index.size:
            frame = self.hit_frames.take(hit.take(index, mode="wrap"), axis=1, mode="wrap")
            # The frame's corner is pushed off along the triangle's normal; the walk pushes
            # every hit point along its patch's normal (frame rows 9:12): take that off here.
            pushed_back = frame[9:12] * np.float32(self.geometry.ray_offset)
            points = frame_points(frame, u.take(index, mode="wrap"), v.take(index, mode="wrap"))
            points -= pushed_back
            origins[:, index] = points
        return origins

    def leave_random(self, patch, u):
        """Rays leaving the given patches from uniform points (``u[0]``, ``u[1]``, and
        ``u[row_triangle]`` to choose a triangle), in cosine-distributed directions (``u[2]``,
        ``u[3]``): (origins, directions), each (3,n) float32 rows (unit space)."""
        return _rays_from_frames(self.leave_frames(patch, u), u[0], u[1], u[2:4])

    def leave_frames(self, patch, u):
        """The (12,n) frames the given patches' rays leave from (corner, edge a, edge b, normal):
        their parallelograms' or, where a patch is not one, a triangle's of it (chosen with
        ``u[row_triangle]``, ``u[0]`` and ``u[1]`` folded onto it in place: leave_columns)."""
        if self.patch_class is not None:
            frame = np.empty((12, patch.size), dtype=np.float32)
            self.leave_corners.take(patch, axis=1, mode="wrap", out=frame[0:3])
            patch_class = self._class_of(patch)
            self.class_shape.take(patch_class, axis=1, mode="wrap", out=frame[3:12])
            return frame
        if self.geometry.all_parallelograms:
            return self.leave_table.take(patch, axis=1, mode="wrap")
        return self.exit_table.take(self.leave_columns(patch, u), axis=1, mode="wrap")

    def patch_normals(self, patch):
        """(3,n) float32 rows: the given patches' normals."""
        if self.patch_class is not None:
            patch_class = self._class_of(patch)
            return self.class_normals.take(patch_class, axis=1, mode="wrap")
        return self.geometry.patch_normal_rows.take(patch, axis=1, mode="wrap")

    def leave_columns(self, patch, u):
        """The exit-table column each path leaves from: its patch's parallelogram, or a
        triangle of the patch chosen by area with ``u[row_triangle]``. Where that is a
        triangle, folds (u[0], u[1]) onto it in place (u0 + u1 > 1 reflects: uniform)."""
        g = self.geometry
        if g.all_parallelograms:
            return patch + g.triangle_count
        column = choose_triangles(g, patch, u[self.row_triangle])
        fold = u[0] + u[1] > 1
        if g.any_parallelograms:
            parallelogram = g.patch_parallelogram.take(patch, mode="wrap")
            column = _select(parallelogram, patch + g.triangle_count, column)
            fold &= ~parallelogram
        # u -> 1 - u where folded, as |fold - u| (exact in float32 for u in [0, 1)).
        fold = fold.astype(np.float32)
        for row in (0, 1):
            np.subtract(fold, u[row], out=u[row])
            np.abs(u[row], out=u[row])
        return column


def _patch_classes(geometry, mean_reflectivity):
    """The patches of a scene of parallelograms in classes of one leaving-frame shape (edge a,
    edge b, normal: Geometry.leave_shapes) and one mean reflectivity each, bit for bit:
    ((P,) uint16 class of each patch, (9,K) float32 shape rows, (K,) R_bar or None, and (K,)
    shape index of each class). Where shape and R_bar together make more than
    PATCH_CLASSES_MAX classes (R_bar varies from patch to patch), the classes are the shapes
    alone and R_bar None (read per patch); None where the shapes alone are too many."""
    shapes = geometry.leave_shapes
    if shapes is None:
        return None
    shape_table, shape_of_patch = shapes
    values, value_of_patch = np.unique(mean_reflectivity, return_inverse=True)
    key = shape_of_patch.astype(np.int64) * values.size + value_of_patch.reshape(-1)
    keys, patch_class = _unique_keys(key, shape_table.shape[1] * values.size)
    if keys.size > PATCH_CLASSES_MAX:
        if shape_table.shape[1] > PATCH_CLASSES_MAX:
            return None
        return shape_of_patch, shape_table, None, np.arange(shape_table.shape[1])
    shape = keys // values.size
    return (
        patch_class.reshape(-1).astype(np.uint16),
        np.ascontiguousarray(shape_table[:, shape]),
        values[keys % values.size],
        shape,
    )


def _unique_keys(key, key_count):
    """np.unique(key, return_inverse=True) for (P,) int64 keys in [0, key_count): where the
    key range is not much bigger than P, a table of the keys present replaces the sort."""
    if key_count > 4 * key.size:
        return np.unique(key, return_inverse=True)
    present = np.zeros(key_count, dtype=bool)
    present[key] = True
    keys = np.flatnonzero(present)
    rank = np.cumsum(present) - 1  # a present key's place among the keys present
    return keys, rank.take(key, mode="wrap")


def _rays_from_frames(frame, a, b, u_direction):
    """Rays from gathered (12,n) frame rows [corner, edge a, edge b, normal]: origins
    corner + a edge_a + b edge_b, directions normal + a uniform sphere point (cosine
    distributed), computed in place in ``frame``. Returns two (3,n) views of it."""
    return frame_points(frame, a, b), add_sphere_points(frame[9:12], u_direction[0], u_direction[1])


@dataclass
class ChunkTally:
    """What one batch of paths produced, in relative weights (multiply by Phi_T / N).

    The power accounts balance path by path: every unit of weight a path starts with ends
    absorbed at a hit (the weight arriving minus the weight leaving), escaped, blocked or,
    for the biased estimator, undistributed; so emitted = absorbed + escaped + blocked +
    undistributed to rounding, in every channel.
    """

    paths: int
    rays: int
    incident: np.ndarray                 # (C,P) power incident on each patch's front side
    emitted: np.ndarray                  # (C,) total starting weight
    absorbed: np.ndarray                 # (C,) weight arriving at front hits minus weight leaving them
    escaped: np.ndarray                  # (C,) carried by rays that hit nothing
    blocked: np.ndarray                  # (C,) carried by rays that hit a back side
    undistributed: np.ndarray            # (C,) left on paths cut by the threshold
    ended: dict = field(default_factory=dict)  # path counts by how they ended


class Aborted(Exception):
    """The walk was asked to stop; its partial chunk is discarded."""


def _select(mask, value, other):
    """np.where(mask, value, other) for integers, as other + (value - other) mask: np.where
    branches on every element, and on a random mask (which rays survive) its mispredictions
    cost about 4 ns a ray, ten times this arithmetic."""
    out = value - other
    out *= mask
    out += other
    return out


def _facing(directions, normals):
    """direction . normal < 0 per column of two (3,n) row arrays."""
    return np.einsum("ij,ij->j", directions, normals) < 0


def _meets_front(directions, normal):
    """direction . Ng < 0 for (3,n) direction rows and the ray tracer's (n,3) geometric normals
    (three passes over Ng's strided columns: faster than einsum's)."""
    dot = normal[:, 0] * directions[0]
    dot += normal[:, 1] * directions[1]
    dot += normal[:, 2] * directions[2]
    return dot < 0


def walk_chunk(tables: WalkTables, paths: int, rng: np.random.Generator, abort=None) -> ChunkTally:
    """Trace ``paths`` random walks from the sources to their end; return their tallies."""
    return walk_chunks(tables, [paths], rng, abort)[0]


def _walk_paths(tables, sizes, rng, abort=None):
    """``walk_chunks`` for walks whose paths carry something of their own (weights, hit points,
    an accumulated reflectivity): the live paths are arrays, selected path by path.

    In a group (more than one chunk) each path also carries its chunk, and the live paths stay
    in chunk order: a chunk's paths all start before the next chunk's, selections keep the
    order, and the sort by patch of bigger scenes sorts by chunk first. Every account of a
    chunk is then a sum over one contiguous run of paths (``_chunk_sums``), and a chunk scores
    in its own P columns."""
    g = tables.geometry
    C, P = tables.channels, tables.patch_count
    G = len(sizes)
    grouped = G > 1
    paths = sum(sizes)
    finite = tables.estimator == FINITE
    exit_random = tables.exit_random
    scores = _Scores(C, G * P)
    absorbed = np.zeros((G, C))
    escaped = np.zeros((G, C))
    blocked = np.zeros((G, C))
    undistributed = np.zeros((G, C))
    emitted = np.zeros((G, C))
    ended = {name: np.zeros(G, dtype=np.int64) for name in ("escaped", "blocked", "absorbed", "threshold")}

    # Every path's source, drawn at once for each chunk; paths start as places free up.
    source, source_chunk, first_uniforms = _draw_sources(tables, sizes, rng)
    started = 0
    chunk_key_bits = int(G - 1).bit_length()  # in the sort key by patch (sort_paths)

    # The live paths: the patch each is on, what it carries, and its chunk (in a group).
    patch = source[:0]
    chunk = source_chunk[:0] if grouped else None
    accumulated = None if finite else np.ones(0)  # product of R_bar along the path
    weights = None if tables.unit_weights else np.zeros((C, 0))
    leave_from = None  # (3,n) the live paths' hit points, not yet pushed off (exit_point="hit")
    ray_offset = np.float32(g.ray_offset)
    rays = np.zeros(G, dtype=np.int64)

    def per_chunk(w, mask=None):
        """(G,C) weight ``w`` carried by the live paths (the masked ones), per chunk."""
        if not grouped:
            return (_total(w, patch.size) if mask is None else _weight_sum(w, mask))[None]
        if mask is None:
            return _chunk_sums(w, chunk, G)
        return _chunk_sums(None if w is None else w.compress(mask, axis=1), chunk.compress(mask), G)

    def count(mask):
        """Number of masked live paths, (G,) per chunk."""
        if not grouped:
            return np.count_nonzero(mask)
        return _chunk_counts(chunk.compress(mask), G)

    while True:
        if abort is not None and abort.is_set():
            raise Aborted
        n_live = patch.size
        new = min(WAVEFRONT_PATHS - n_live, paths - started) if started < paths else 0
        if new > 0:
            new_patch = source[started : started + new]
            patch, chunk = _joined(patch, chunk, new_patch, source_chunk, started, n_live)
            if accumulated is not None:
                accumulated = np.concatenate((accumulated, np.ones(new)))
            if tables.weight_is_accumulated:
                weights = accumulated[None]
            elif weights is not None:
                new_weights = tables.start_weight.take(new_patch, axis=1, mode="wrap")
                weights = np.concatenate((weights, new_weights), axis=1)
            emitted += _new_weight(weights, n_live, new, None if chunk is None else chunk[n_live:], G)
        elif n_live == 0:
            break
        n = patch.size

        # The rays: from new uniform points of the patches (random exit, and new paths), or
        # from the hit points (exit_point="hit"), in cosine-distributed directions.
        if exit_random or n_live == 0:
            # From new uniform points of the patches.
            u = rng.random((tables.uniforms_per_ray, n), dtype=np.float32)
            if first_uniforms is not None and new > 0:
                # A path's first ray: a randomly shifted low-discrepancy set (stratified).
                u[:4, n_live:] = first_uniforms[:, started : started + new]
            origins, directions = tables.leave_random(patch, u)
        else:
            # From the hit points, pushed off along their patch's normal, and new paths from new
            # points of their sources; every direction about its patch's normal.
            u = rng.random((2, n), dtype=np.float32)
            normals = tables.patch_normals(patch)
            origins = leave_from
            origins += normals[:, :n_live] * ray_offset
            if new > 0:
                # The new paths' points (their directions take u's rows like every path's), and
                # a triangle choice where patches are not parallelograms.
                u_new = np.empty((tables.uniforms_per_ray, new), dtype=np.float32)
                if first_uniforms is not None:
                    u_new[:4] = first_uniforms[:, started : started + new]
                    u[:, n_live:] = u_new[2:4]
                else:
                    rng.random(dtype=np.float32, out=u_new[:2])
                if tables.row_triangle is not None:
                    rng.random(dtype=np.float32, out=u_new[tables.row_triangle])
                # (leave_columns first: it folds u_new[0], u_new[1] onto triangles in place.)
                frame = tables.leave_frames(patch[n_live:], u_new)
                origins = np.concatenate((origins, frame_points(frame, u_new[0], u_new[1])), axis=1)
            directions = add_sphere_points(normals, u[0], u[1])
        started += max(new, 0)
        u_survive = rng.random(n) if finite else None

        # The ray tracer reads (n,3) views of the (3,n) rows: no transposed copies.
        if exit_random:
            # A miss (-1) reads as patch 0: harmless, masked out below.
            hit, hit_patch, front = tables.cast(origins, directions)
        else:
            hit, bary_u, bary_v, distance, hit_normal = tables.first_hit_barycentric(origins.T, directions.T)
            hit_patch = tables.hit_patches(hit, bary_u, bary_v)
            front = _meets_front(directions, hit_normal)
        front &= hit >= 0
        rays += n if chunk is None else _chunk_counts(chunk, G)
        if not exit_random:
            points = tables.hit_points(origins, directions, distance, hit, hit_patch, bary_u, bary_v, front)
        if not front.all():
            missed = hit < 0
            back = ~missed & ~front
            n_missed, n_back = int(np.count_nonzero(missed)), int(np.count_nonzero(back))
            if n_missed:
                escaped += per_chunk(weights, missed)
                ended["escaped"] += count(missed)
            if n_back:
                blocked += per_chunk(weights, back)
                ended["blocked"] += count(back)
            keep = np.flatnonzero(front)
            hit_patch = hit_patch.take(keep, mode="wrap")
            if finite:
                u_survive = u_survive.take(keep, mode="wrap")
            accumulated, weights, chunk = _carried(keep, accumulated, weights, chunk, tables)
            if not exit_random:
                points = points.take(keep, axis=1, mode="wrap")
        patch = hit_patch

        # Score: the power arriving at the hit patch (in a group, in its chunk's columns).
        scores.add(patch if chunk is None else chunk * np.int32(P) + patch, weights)
        arriving = per_chunk(weights)

        go_on = None  # which of the hit paths go on, in the order they go on (None: all, as they are)
        if finite:
            survive = u_survive < tables.mean_reflectivity_at(patch)
            go_on = np.flatnonzero(survive)
            # The absorbed are the hit paths that do not go on, counted per chunk below from
            # the chunks' runs (two searches a chunk, not a pass over the paths).
            hit_count = _chunk_counts(chunk, G) if grouped else patch.size
        else:
            # New arrays, never in place: the weights just scored may be a view of ``accumulated``.
            accumulated = accumulated * tables.mean_reflectivity_at(patch)
            if tables.weight_is_accumulated:
                weights = accumulated[None]
            else:
                weights = weights * tables.reflectivity.take(patch, axis=1, mode="wrap")
            absorbed += arriving - per_chunk(weights)  # (1 - R) of what arrived
            cut = accumulated < tables.threshold
            if cut.any():
                undistributed += per_chunk(weights, cut)
                ended["threshold"] += count(cut)
                go_on = np.flatnonzero(~cut)

        if tables.sort_paths and patch.size:
            # Paths go on grouped by patch: coherent rays, gathers in memory order.
            go_on = _patch_order(patch, go_on, tables.patch_key_shift, chunk, chunk_key_bits)
        if go_on is not None:
            patch = patch.take(go_on, mode="wrap")
            accumulated, weights, chunk = _carried(go_on, accumulated, weights, chunk, tables)
            if not exit_random:
                points = points.take(go_on, axis=1, mode="wrap")
        if finite:
            ended["absorbed"] += hit_count - (_chunk_counts(chunk, G) if grouped else patch.size)
            if weights is not None:
                weights *= tables.survivor_weight.take(patch, axis=1, mode="wrap")
            absorbed += arriving - per_chunk(weights)
        if not exit_random:
            leave_from = points

    incident = scores.total().reshape(C, G, P)
    return [
        ChunkTally(
            paths=n,
            rays=int(rays[k]),
            incident=incident[:, k].astype(np.float64),  # (a copy, contiguous)
            emitted=emitted[k],
            absorbed=absorbed[k],
            escaped=escaped[k],
            blocked=blocked[k],
            undistributed=undistributed[k],
            ended={name: int(counts[k]) for name, counts in ended.items()},
        )
        for k, n in enumerate(sizes)
    ]


def _draw_sources(tables, sizes, rng):
    """Every path's source for chunks of ``sizes`` paths, each chunk's drawn for it alone (a
    sample may come out grouped by source): (source, its chunk or None for one chunk, the
    stratified first rays' uniforms or None)."""
    first_uniforms = None
    if tables.stratified:
        drawn = [tables.sources.stratified(n, rng) for n in sizes]
        source = np.concatenate([d[0] for d in drawn])
        first_uniforms = np.concatenate([d[1] for d in drawn], axis=1)
    else:
        source = np.concatenate([tables.sources.sample(n, rng) for n in sizes])
    source_chunk = np.repeat(np.arange(len(sizes), dtype=np.int32), sizes) if len(sizes) > 1 else None
    return source, source_chunk, first_uniforms


class _SourceRuns:
    """The sources of chunks of ``sizes`` paths drawn as counts per source (the same numbers
    ``_draw_sources`` draws when every chunk's source table draws counts): the chunk-ordered
    paths come in runs, one per chunk and source, and a wavefront takes them in order."""

    def __init__(self, sources, sizes, rng):
        counts = np.concatenate([sources.counts(n, rng) for n in sizes])
        self.end = np.cumsum(counts)
        self.start = self.end - counts
        self.chunk = np.repeat(np.arange(len(sizes)), sources.patches.size)
        self.patch = np.tile(sources.patches, len(sizes))

    def add_window(self, live, first, last):
        """Adds paths ``first`` to ``last`` (exclusive) to the (chunks, patches) counts ``live``:
        from each run overlapping them, as many as overlap (O(runs overlapping), not O(paths))."""
        i = np.searchsorted(self.end, first, side="right")
        j = np.searchsorted(self.start, last, side="left")
        overlap = np.minimum(self.end[i:j], last) - np.maximum(self.start[i:j], first)
        live[self.chunk[i:j], self.patch[i:j]] += overlap  # one run per chunk and source


def _joined(patch, chunk, new_patch, source_chunk, started, n_live):
    """The live paths' patches and chunks (None outside a group) with the new paths after them
    (``new_patch``, from ``started`` in the sources)."""
    new_chunk = None if source_chunk is None else source_chunk[started : started + new_patch.size]
    if not n_live:
        return new_patch, new_chunk
    patch = np.concatenate((patch, new_patch))
    return patch, None if new_chunk is None else np.concatenate((chunk, new_chunk))


def _chunk_starts(chunk, G):
    """Where each chunk's run begins in ``chunk`` (in chunk order), and its end: (G+1,)."""
    return np.searchsorted(chunk, np.arange(G + 1, dtype=chunk.dtype))


def _chunk_counts(chunk, G):
    """(G,) number of entries of each chunk in ``chunk`` (in chunk order)."""
    return np.diff(_chunk_starts(chunk, G))


def _chunk_sums(weights, chunk, G):
    """(G,C) sums of the columns of ``weights`` (C,n) by their chunk (n,), which comes in
    chunk order: one contiguous run of columns per chunk. None is weight 1 on one channel."""
    start = _chunk_starts(chunk, G)
    if weights is None:
        return np.diff(start).astype(np.float64)[:, None]
    sums = np.zeros((G, weights.shape[0]))
    filled = start[:-1] < start[1:]
    if filled.any():
        # Each non-empty run, up to the next one's start (empty runs between take no columns).
        sums[filled] = np.add.reduceat(weights, start[:-1][filled], axis=1).T
    return sums


def _new_weight(weights, n_live, new, new_chunk, G):
    """(G,C) starting weight of the ``new`` paths just added after the ``n_live`` live ones
    (``new_chunk`` their chunks, None outside a group)."""
    w = None if weights is None else weights[:, n_live:]
    if new_chunk is None:
        return _total(w, new)[None]
    return _chunk_sums(w, new_chunk, G)


def _weight_sum(weights, mask):
    """Sum of the carried weights of the masked paths, per channel (the masked paths are
    usually few: their columns are picked out first)."""
    if weights is None:
        return np.array([float(np.count_nonzero(mask))])
    return weights.compress(mask, axis=1).sum(axis=1)


def _total(weights, n):
    """Total carried weight per channel, (C,): n paths of weight 1 where weights is None."""
    return np.array([float(n)]) if weights is None else weights.sum(axis=1)


def walk_chunks(tables: WalkTables, sizes, rng: np.random.Generator, abort=None) -> list:
    """Trace the paths of several chunks (``sizes``, a path count each) as one wavefront, every
    path tagged with its chunk; return each chunk's own tallies, in order.

    A chunk ends in steps of few rays each, when its last paths run out, which cost numpy's
    per-step work for little tracing; in a group they overlap the next chunk's start. Small
    runs, whose chunks are small (the batch error estimate wants many of them), trace up to
    twice as fast. Each chunk's sources are drawn for it alone and every hit, escape and
    weight is counted to it alone, so the chunks stay independent batches."""
    sizes = [int(n) for n in sizes]
    # The numpy turn (tables.numpy_turn), held except while tracing: walks on other threads
    # trace while this one does its numpy work, and wait for the turn rather than interleave
    # their numpy calls with this walk's one by one. Interleaved, the threads would hand the
    # GIL to and fro at nearly every call (numpy releases it inside each), at a thread wake-up
    # each; taking turns hands it over about once a step. Solves with 2 threads run 1-4% faster.
    with tables.numpy_turn:
        if tables.exchangeable:
            return _walk_exchangeable(tables, sizes, rng, abort)
        return _walk_paths(tables, sizes, rng, abort)


def _walk_exchangeable(tables, sizes, rng, abort=None):
    """``walk_chunks`` for a grey finite walk leaving from random points (the paper's plain
    estimator): every path carries the same power and leaves each patch from a new point, so a
    path is nothing but the patch it is on (and its chunk), and the live paths may be kept in
    any order without changing the estimate.

    Every ray ends one of four ways: escaped (no hit), blocked (a back side), absorbed (a front
    hit, then the survival test with R_bar fails) or surviving. Instead of selecting the
    survivors path by path (a data-dependent branch per path, the costliest numpy step here),
    a step puts each ray in a bin of its chunk's K bins by outcome, and one whole-array
    operation regroups them:

    - in a scene of at most COUNTED_MAX_PATCHES patches the bins are 2 patch + survives, then
      escaped (2P) and blocked (2P + 1), and one bincount counts the step's rays by chunk,
      patch and outcome; survivors restart from the counts, patch j s_j times, in patch
      order. The live paths are then nothing but a count per chunk and patch: in a scene of
      parallelograms (and unless the first rays are stratified, which pairs each new path
      with its own numbers) new paths join those counts, and the step's leaving frames are
      the leave table's columns repeated that many times (np.repeat, at less than half the
      cost of a gather by patch);
    - in a bigger scene the bins are the front-hit patch, then escaped (P) and blocked
      (P + 1); the step's bins are scored, and a sort puts the survivors first, in order of
      chunk and patch, so that rays leaving one patch go to the ray tracer together (coherent
      rays trace faster, and table gathers read memory in order).

    A chunk's bins hold all its accounts: its rays (every ray lands in one bin), its escaped
    and blocked paths, and so its absorbed ones (every path ends once).
    """
    g = tables.geometry
    P = tables.patch_count
    G = len(sizes)
    paths = sum(sizes)
    counted = tables.counted
    tagged = G > 1
    K = 2 * P + 2 if counted else P + 2  # bins per chunk: [2 patch + survives | patch], escaped, blocked
    escaped_bin = np.int32(K - 2)
    past = np.int32(G * K)  # a sort key past every bin: paths that do not go on
    # Live paths as counts per chunk and patch (see above), or None: as arrays of their
    # patches (and chunks). New paths join the counts from their sources' counts where each
    # chunk draws those (``SourceTable.counts``: a chunk's paths come in runs, one per source),
    # else from every path's source.
    live = runs = None
    if counted and g.all_parallelograms and not tables.stratified:
        live = np.zeros((G, P), dtype=np.int64)
        if all(tables.sources.draws_counts(n) for n in sizes):
            runs = _SourceRuns(tables.sources, sizes, rng)
    if runs is None:
        source, source_chunk, first_uniforms = _draw_sources(tables, sizes, rng)
        source = source.astype(np.int32)
        patch = source[:0]
        chunk = source_chunk[:0] if tagged else None
    if counted:
        bins = np.zeros((G, K), dtype=np.int64)
        patch_index = np.arange(P, dtype=np.int32)
        if tagged:  # (patch, chunk) pairs in patch-major order
            patch_of_pair = np.repeat(patch_index, G)
            chunk_of_pair = np.tile(np.arange(G, dtype=np.int32), P)
    else:
        scores = _Scores(1, G * K)
    started = 0
    n_live = 0
    while True:
        if abort is not None and abort.is_set():
            raise Aborted
        new = min(WAVEFRONT_PATHS - n_live, paths - started)
        if new <= 0 and n_live == 0:
            break
        n = n_live + max(new, 0)
        u = rng.random((tables.uniforms_per_ray, n), dtype=np.float32)
        if live is not None:
            if new > 0 and runs is not None:
                runs.add_window(live, started, started + new)
            elif new > 0:
                new_patch = source[started : started + new]
                if tagged:
                    pair = source_chunk[started : started + new] * np.int32(P)
                    pair += new_patch
                    live += np.bincount(pair, minlength=G * P).reshape(G, P)
                else:
                    live[0] += np.bincount(new_patch, minlength=P)
            if tagged:
                frame = np.repeat(tables.leave_table, live.sum(axis=0), axis=1)
                chunk = np.repeat(chunk_of_pair, live.T.ravel())
            else:
                frame = np.repeat(tables.leave_table, live[0], axis=1)
            origins, directions = _rays_from_frames(frame, u[0], u[1], u[2:4])
        else:
            if new > 0:
                new_patch = source[started : started + new]
                patch, chunk = _joined(patch, chunk, new_patch, source_chunk, started, n_live)
            if first_uniforms is not None and new > 0:
                u[:4, n_live:] = first_uniforms[:, started : started + new]
            origins, directions = tables.leave_random(patch, u)
        started += max(new, 0)
        u_survive = rng.random(n)
        # A miss (-1) reads as patch 0: harmless, binned out below.
        hit, hit_patch, front = tables.cast(origins, directions)
        reached = hit >= 0
        front &= reached
        ended_bin = escaped_bin + reached  # escaped, or blocked where it reached a back side
        survive = u_survive < tables.mean_reflectivity_at(hit_patch)
        if counted:
            key = hit_patch * np.int32(2)
            key += survive
            key = _select(front, key, ended_bin)
            if tagged:
                key += chunk * np.int32(K)
            step = np.bincount(key, minlength=G * K).reshape(G, K)
            bins += step
            survivors = step[:, 1 : 2 * P : 2]
            if live is not None:
                live = survivors
                n_live = int(live.sum())
            elif tagged:
                pairs = survivors.T.ravel()
                patch = np.repeat(patch_of_pair, pairs)
                chunk = np.repeat(chunk_of_pair, pairs)
                n_live = patch.size
            else:
                patch = np.repeat(patch_index, survivors[0])
                n_live = patch.size
        else:
            key = _select(front, hit_patch, ended_bin)
            if tagged:
                key += chunk * np.int32(K)
            scores.add(key, None)
            survive &= front
            key = _select(survive, key, past)
            key.sort()
            key = key[: int(np.searchsorted(key, past))]
            if tagged:
                chunk = key // np.int32(K)
                patch = key - chunk * np.int32(K)
            else:
                patch = key
            n_live = patch.size

    if counted:
        incident = bins[:, 0 : 2 * P : 2] + bins[:, 1 : 2 * P : 2]
    else:
        bins = scores.total()[0].reshape(G, K)
        incident = bins[:, :P]
    rays = bins.sum(axis=1)
    tallies = []
    for k, n in enumerate(sizes):
        escaped, blocked = int(bins[k, K - 2]), int(bins[k, K - 1])
        absorbed = n - escaped - blocked  # every path ends once
        one = lambda count: np.array([float(count)])  # noqa: E731
        tallies.append(ChunkTally(
            paths=n,
            rays=int(rays[k]),
            incident=incident[k : k + 1].astype(np.float64),
            emitted=one(n),
            absorbed=one(absorbed),
            escaped=one(escaped),
            blocked=one(blocked),
            undistributed=one(0),
            ended={"escaped": escaped, "blocked": blocked, "absorbed": absorbed, "threshold": 0},
        ))
    return tallies


def _carried(index, accumulated, weights, chunk, tables):
    """What the paths at ``index`` carry: (accumulated, weights, chunk) taken there (in a grey
    biased walk the weights are a view of the accumulated reflectivity)."""
    if chunk is not None:
        chunk = chunk.take(index, mode="wrap")
    if accumulated is not None:
        accumulated = accumulated.take(index, mode="wrap")
    if tables.weight_is_accumulated:
        return accumulated, accumulated[None], chunk
    if weights is not None:
        weights = weights.take(index, axis=1, mode="wrap")
    return accumulated, weights, chunk


class _Scores:
    """The hits of a chunk, kept per step and summed per patch (one bincount per channel)
    whenever SCORE_FLUSH_PER_PATCH times the patch count of them have gathered, at most
    SCORE_FLUSH: (C,P), float64 sums of weights, or int64 counts of unweighted hits. (A
    bincount costs a pass over the P patches, so big scenes gather the hits of many steps
    first; small scenes add every step's hits while they are still in cache. The first sums
    are the sums: a group's scores, chunks x patches, are neither zeroed nor added to first.)"""

    def __init__(self, channels, patch_count):
        self.shape = (channels, patch_count)
        self.incident = None  # until the first flush
        self.patches, self.weights, self.count = [], [], 0
        self.flush_at = min(SCORE_FLUSH, SCORE_FLUSH_PER_PATCH * patch_count)

    def add(self, patch, weights):
        self.patches.append(patch)
        if weights is not None:
            self.weights.append(weights)
        self.count += patch.size
        if self.count >= self.flush_at:
            self.flush()

    def flush(self):
        if not self.patches:
            return
        patches = np.concatenate(self.patches)
        C, P = self.shape
        if not self.weights:
            sums = np.bincount(patches, minlength=P)[None]
        else:
            w = np.concatenate(self.weights, axis=1)
            sums = [np.bincount(patches, weights=w[c], minlength=P) for c in range(C)]
        if self.incident is None:
            self.incident = np.array(sums) if self.weights else sums
        else:
            for c in range(C):
                self.incident[c] += sums[c]
        self.patches, self.weights, self.count = [], [], 0

    def total(self):
        """(C,P) float64 sums, or int64 counts where no hit carried a weight."""
        self.flush()
        if self.incident is None:
            return np.zeros(self.shape)
        return self.incident


def _patch_order(patch, selected, shift, chunk=None, chunk_bits=0):
    """Indices of the ``selected`` entries of ``patch`` (all where None), ordered by patch
    (by the 16-bit key patch >> shift, which numpy sorts with a radix sort). With ``chunk``,
    by chunk first: its ``chunk_bits`` lead the key, and the patch takes the rest."""
    if selected is None:
        selected = np.arange(patch.size)
    key = patch.take(selected, mode="wrap")
    if shift + chunk_bits:
        key = key >> (shift + chunk_bits)
    if chunk is not None:
        key |= chunk.take(selected, mode="wrap") << (16 - chunk_bits)
    order = np.argsort(key.astype(np.uint16), kind="stable")
    return selected.take(order, mode="wrap")
