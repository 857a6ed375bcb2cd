"""Per-solve tables: a scene's materials, sources and geometry in the layouts the walk reads;
the speed-ups a walk uses (``Speedups``); the numpy turns chunks take on several threads.

Built once per solve and shared by all its chunks and threads. Gathers from them use
``take(..., mode="wrap")``: every index is valid by construction (a ray tracer's miss, -1, is
only ever gathered to be masked out), and numpy's wrapping gather is about twice as fast as its
checking one.

The walk's speed-ups (``Speedups``): each named, chosen for a scene in one place, and switchable one by one.

None of them changes what a walk estimates. Most change no bit of the result either (grids,
patch classes, sorted paths, grouped chunks trace and score the same rays in another order or
layout); the interchangeable and counted walks pair the same random numbers with paths in
another order, so they give another sample of the same estimator. ``docs/performance.md`` says
what each one buys.
"""
from __future__ import annotations

import copy
import threading
from dataclasses import dataclass, fields, replace

import numpy as np

from ..names import EXIT_RANDOM, FINITE, INDEPENDENT, STRATIFIED
from ..lights.sampling import SourceTable, channel_sum, source_weights
from ..estimate.grouping import WalkGroups, world_group

# At most this many patch classes (2^12 classes take 200 kB); more, and the classes are the
# shapes alone, R_bar read per patch.
PATCH_CLASSES_MAX = 1 << 12


class WalkTables:
    """What every chunk of a solve reads, whatever its method: materials (C,P), the sources, the
    leaving frames, the Embree scene the walk traces, and which speed-ups it uses
    (``speedups``). Every attribute is always there (None where the scene or the exit point
    has no use for it); a variant is a copy (``with_turn``, ``with_sources``)."""

    def __init__(self, scene, estimator, threshold, exit_point, sampling=INDEPENDENT, speedups=None, max_classes=PATCH_CLASSES_MAX,
                 groups=None, direct_apart=False):
        g = self.geometry = scene.geometry
        # Chunks that gather the direct light keep it apart in their tallies (ChunkTally.direct).
        self.direct_apart = bool(direct_apart)
        self.estimator = estimator
        self.finite = estimator == FINITE
        self.threshold = float(threshold)
        self.exit_random = exit_point == EXIT_RANDOM
        self.stratified = sampling == STRATIFIED
        self.patch_count = scene.patch_count
        self.sources = SourceTable(source_weights(scene.patch_area, scene.emission, scene.lights.power, scene.back_emits))
        # (P,) bool: the emitting patches whose paths leave their front or their back
        # (rays.emitter_backs), or None: the reflected light a gathered walk shoots
        # (with_sources) leaves fronts alone.
        self.emitter_backs = scene.back_emits if scene.back_emits.any() else None
        # Source ids from the patch count on are the lights' emitters (None: no lights).
        # Per-source results: the group of each source (grouping.WalkGroups), or None.
        self.groups = None if groups is None else WalkGroups(groups.count, groups.source_group, whole=groups, world=world_group(scene, groups))
        self.lights = scene.lights if len(scene.lights) else None
        self.grey_reflectivity = scene.grey_reflectivity  # R_bar (P,)
        # Grey scenes carry one channel; colour scenes three.
        self.channels = 1 if scene.is_grey else 3
        self.reflectivity = np.ascontiguousarray(scene.reflectivity[:, : self.channels].T)  # (C,P)
        self.emission = scene.emission  # (P,3), for start_weight
        # A grey finite walk's weights stay exactly 1: no weight arrays at all. A grey biased
        # walk's weight is the accumulated reflectivity the threshold test keeps anyway.
        self.unit_weights = self.finite and self.channels == 1
        self.weight_is_accumulated = not self.finite and self.channels == 1
        speedups = (speedups or Speedups()).resolve(scene, estimator, exit_point)
        # float32 uniforms per ray leaving a new point of its patch: point (2), direction (2),
        # and a triangle choice unless every patch is a parallelogram. (The finite survival test
        # draws float64: float32 would quantise R_bar to multiples of 2^-24.)
        self.uniforms_per_ray = 4 if g.all_parallelograms else 5
        self.row_triangle = None if g.all_parallelograms else 4
        # Sorted paths go by a 16-bit key, patch >> shift (numpy's radix sort).
        self.patch_key_shift = max(0, int(scene.patch_count - 1).bit_length() - 16)
        # Leaving frames: per patch in a scene of parallelograms, else per triangle.
        self.leave_table = g.leave_table if g.all_parallelograms else None
        self.exit_table = None if g.all_parallelograms else g.exit_table
        class_shape_index = self._set_classes(g, speedups, max_classes)
        if speedups.patch_classes and self.patch_class is None:
            speedups = speedups.without("patch_classes")
        self.speedups = speedups
        # In a scene of parallelograms the triangles come in pairs, in patch order: triangle t
        # is half of patch t >> 1.
        self.paired_triangles = g.all_parallelograms
        self.grids = g.patch_grids if speedups.grids else None
        # The Embree scene the walk traces, built here (once per geometry), not on a thread.
        self.tracer = g.tracer if self.grids is None else self.grids.tracer
        self._set_hit_exit(g, class_shape_index)
        # A random exit's facing test off the grids: in a scene of parallelograms against the
        # hit patch's normal (rows the next step gathers again), else the triangle's.
        self.facing_by_patch = g.all_parallelograms
        self.facing_rows = self.leave_table[9:12] if self.facing_by_patch else g.triangle_normal_rows
        # Walks on several threads take turns at their numpy work: a walk holds this lock
        # except while it traces (walk.walk_chunks).
        self.numpy_turn = threading.Lock()

    def _set_classes(self, g, speedups, max_classes):
        """The patch classes (tables.patch_classes), or None throughout where the speed-up is
        off or the classes too many; returns each class's shape index (or None)."""
        classes = patch_classes(g, self.grey_reflectivity, max_classes) if speedups.patch_classes else None
        self.patch_class = self.class_shape = self.class_grey_reflectivity = None
        self.class_normals = self.leave_corners = None
        if classes is None:
            return None
        self.patch_class, self.class_shape, self.class_grey_reflectivity, class_shape_index = classes
        self.class_normals = np.ascontiguousarray(self.class_shape[6:9])
        self.leave_corners = self.leave_table[0:3]  # contiguous: the table's first rows
        return class_shape_index

    def _set_hit_exit(self, g, class_shape_index):
        """A hit-point exit's edge thresholds and the frames a hit near an edge is mapped onto
        (rays.hit_points), per triangle traced, or per class where classes have shapes; None
        with the random exit."""
        self.hit_frames = self.edge_barycentric = self.class_edge_barycentric = None
        if self.exit_random:
            return
        if self.grids is not None:
            self.hit_frames, self.edge_barycentric = self.grids.hit_frames, self.grids.edge_barycentric
            return
        self.hit_frames, self.edge_barycentric = g.exit_table, g.edge_barycentric
        if self.patch_class is not None:
            self.class_edge_barycentric = g.shape_edge_barycentric[class_shape_index]

    def with_turn(self, turn):
        """These tables with another numpy turn (FreeTurn: none), everything else shared."""
        tables = copy.copy(self)
        tables.numpy_turn = turn
        return tables

    def with_sources(self, sources, emission, lights, mix=None):
        """These tables with other sources (a SourceTable, (P,3) emission, lights or None, and
        their groups' grouping.Mix where results are per source), everything else shared:
        a walk of the light the patches reflect (first_shot)."""
        tables = copy.copy(self)
        tables.sources, tables.emission, tables.lights = sources, emission, lights
        tables.emitter_backs = None
        if mix is not None:
            tables.groups = tables.groups.with_mix(mix)
        return tables

    def survivor_weight(self, patch):
        """R_jc / R_bar_j (C,n) at the given patches: what survivors multiply each channel's
        weight by (colour walks). Made for the patches asked (a (C,P) table would be as big as
        the reflectivities)."""
        R = self.reflectivity.take(patch, axis=1, mode="wrap")
        grey = self.grey_reflectivity.take(patch, mode="wrap")
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(grey > 0, R / grey, 0.0)

    def start_weight(self, source, part=None):
        """E_ic / E_bar_i (C,n): the starting weights of paths from the given sources, patches
        (index < P) or a light's emitters (P + its index) (colour walks); with ``part``, of the
        parts of a mix of groups the paths drew (grouping.Mix). Made for the sources
        asked: a (C,S) table would cost as much as the scene's emission, for the few sources."""
        if part is not None:
            return self.groups.mix.start_weight(source, part, self.channels)
        P = self.patch_count
        E = self.emission.take(source if self.lights is None else np.minimum(source, P - 1), axis=0, mode="wrap")
        if self.lights is not None:
            light = np.flatnonzero(source >= P)
            E[light] = self.lights.power.take(source[light] - P, axis=0)
        grey_emission = channel_sum(E) / 3  # bit for bit E.mean(axis=1), at a tenth of its cost
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(grey_emission > 0, E[:, : self.channels].T / grey_emission, 0.0)

    def class_of(self, patch):
        """The class of each of the given patches (with patch classes only)."""
        return self.patch_class.take(patch, mode="wrap")

    def grey_reflectivity_at(self, patch):
        """R_bar of each of the given patches (float64)."""
        if self.patch_class is not None and self.class_grey_reflectivity is not None:
            return self.class_grey_reflectivity.take(self.class_of(patch), mode="wrap")
        return self.grey_reflectivity.take(patch, mode="wrap")

    def outside_turn(self, trace, *rays):
        """``trace(*rays)`` with the numpy turn released: other walks work meanwhile."""
        self.numpy_turn.release()
        try:
            return trace(*rays)
        finally:
            self.numpy_turn.acquire()


def patch_classes(geometry, grey_reflectivity, max_classes=PATCH_CLASSES_MAX):
    """The patches of a scene of parallelograms in classes of one leaving-frame shape (edge a,
    edge b, normal: Geometry.leave_shapes) and one R_bar each, bit for bit: ((P,) uint16 class
    of each patch, (9,K) float32 shape rows, (K,) R_bar or None, (K,) shape index of each
    class). Where shape and R_bar together make more than ``max_classes`` classes (R_bar varies
    from patch to patch), the classes are the shapes alone and R_bar None (read per patch);
    None where the shapes alone are too many. A walk then reads a patch's leaving frame as its
    corner and its class's shape, and a hit patch's normal and R_bar as its class's."""
    shapes = geometry.leave_shapes
    if shapes is None:
        return None
    shape_table, shape_of_patch = shapes
    values, value_of_patch = np.unique(grey_reflectivity, return_inverse=True)
    key = shape_of_patch.astype(np.int64) * values.size + value_of_patch.reshape(-1)
    keys, patch_class = unique_keys(key, shape_table.shape[1] * values.size)
    if keys.size > max_classes:
        if shape_table.shape[1] > max_classes:
            return None
        return shape_of_patch, shape_table, None, np.arange(shape_table.shape[1])
    shape = keys // values.size
    return (
        patch_class.reshape(-1).astype(np.uint16),
        np.ascontiguousarray(shape_table[:, shape]),
        values[keys % values.size],
        shape,
    )


def unique_keys(key, key_count):
    """np.unique(key, return_inverse=True) for (P,) int64 keys in [0, key_count): where the
    key range is not much bigger than P, a table of the keys present replaces the sort."""
    if key_count > 4 * key.size:
        return np.unique(key, return_inverse=True)
    present = np.zeros(key_count, dtype=bool)
    present[key] = True
    keys = np.flatnonzero(present)
    rank = np.cumsum(present) - 1  # a present key's place among the keys present
    return keys, rank.take(key, mode="wrap")


# -- the speed-ups --------------------------------------------------------------------------------
# Interchangeable paths are counted per patch (one bincount a step) in scenes of at most this
# many patches; above it the bincount's pass over the patches costs more than a sort.
COUNTED_MAX_PATCHES = 1 << 12
# Paths that carry weights or hit points go on sorted by patch in scenes of at least this many
# patches (below it every table fits in cache and the sort gains nothing).
SORT_MIN_PATCHES = 1 << 13
# Patch classes pay where the per-patch tables outgrow the caches.
CLASSES_MIN_PATCHES = 1 << 13


@dataclass(frozen=True)
class Speedups:
    """Which speed-ups a walk uses. None: chosen for the scene (:meth:`resolve`); True or
    False: on (where the scene and walk allow it) or off."""

    interchangeable: bool | None = None  # grey finite random-exit paths are only their patch
    counted: bool | None = None          # ... and counted per patch and outcome each step
    sorted_paths: bool | None = None     # other walks go on grouped by patch each step
    patch_classes: bool | None = None    # frames and R_bar read per class of alike patches
    grids: bool | None = None            # Embree traces the grids patches tile, not their triangles
    grouped_chunks: bool | None = None   # small chunks traced together as one wavefront

    def resolve(self, scene, estimator, exit_point):
        """These speed-ups with every None chosen for ``scene`` and the walk (all bool)."""
        geometry = scene.geometry
        P = scene.patch_count

        def choose(name, allowed, wanted):
            forced = getattr(self, name)
            return bool(allowed and (wanted if forced is None else forced))

        interchangeable = choose("interchangeable", estimator == FINITE and scene.is_grey and exit_point == EXIT_RANDOM, True)
        return Speedups(
            interchangeable=interchangeable,
            counted=choose("counted", interchangeable, P <= COUNTED_MAX_PATCHES),
            sorted_paths=choose("sorted_paths", not interchangeable, P >= SORT_MIN_PATCHES),
            patch_classes=choose("patch_classes", geometry.all_parallelograms, P >= CLASSES_MIN_PATCHES),
            grids=choose("grids", self.grids is not False and geometry.patch_grids is not None, True),
            grouped_chunks=choose("grouped_chunks", True, True),
        )

    def without(self, name):
        """These speed-ups with ``name`` off (a walk found the scene does not allow it)."""
        return replace(self, **{name: False})

    def names_on(self):
        """The names of the speed-ups that are on."""
        return tuple(f.name for f in fields(self) if getattr(self, f.name))


# -- the numpy turns ------------------------------------------------------------------------------
# Chunk-wide work takes no turns where a task's paths or the scene's patches reach this many
# (benchmarks/turns.py: the two-way iteration with 1,250 paths a chunk took 1.14-1.22x the time
# without turns that it took with them in the 600- and 2,504-patch rooms, 0.95x in the
# 66,576-patch figure 4 room with 8,000 a chunk; in the empty room, with turns 0.82x the time
# without at 1,250 paths a chunk, 0.90x at 7,800, 1.24x at 31,000).
TURN_FREE_SIZE = 1 << 14


def takes_turns(tables, paths):
    """Whether chunk-wide work (the gathered walk, the generations of the Jacobi and two-way
    iterations) takes turns at numpy for a task of ``paths`` paths. The paper's walks always do
    (:func:`walk_chunks`: their steps' arrays are a wavefront's, small, and a turn a step keeps
    the GIL from changing hands inside them); chunk-wide arrays span a whole chunk, numpy lets
    go of the GIL inside most of their operations, and two threads' numpy work then runs side
    by side (``benchmarks/turns.py``), unless both the task's paths and the scene's patches,
    the lengths of its arrays, are below TURN_FREE_SIZE."""
    return max(paths, tables.patch_count) < TURN_FREE_SIZE


def chunk_wide(tables, paths):
    """``tables`` for chunk-wide work on a task of ``paths`` paths: with a numpy turn that
    never waits where it takes no turns (:func:`takes_turns`)."""
    return tables if takes_turns(tables, paths) else tables.with_turn(FreeTurn())


class FreeTurn:
    """A numpy turn that never waits (:func:`takes_turns`): the lock's calls, doing nothing."""

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def acquire(self):
        return True

    def release(self):
        pass

    def locked(self):
        return False
