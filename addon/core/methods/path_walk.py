"""The walk's stages for paths that carry something of their own (weights, hit points, R products).

The live paths are arrays (:class:`LivePaths`), selected path by path.

In a group of chunks each path also carries its chunk, and the live paths stay in chunk order:
a chunk's paths all start before the next chunk's, selections keep the order, and the sort by
patch sorts by chunk first. Every account of a chunk is then a sum over one contiguous run of
paths, and a chunk scores in its own P columns.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import rays
from .estimators import biased_carry, biased_cut, finite_survives
from ..lights.sampling import add_sphere_points, frame_points
from ..estimate.grouping import draw_walk_sources, fold
from ..estimate.tallies import Accounts, Scores, chunk_counts, chunk_sums, total_weight, weight_sum

# Rays per step while the chunk still has paths to start: big enough that numpy's per-call
# cost is small next to the work, small enough that a step's arrays stay in cache.
WAVEFRONT_PATHS = 1 << 14


@dataclass
class LivePaths:
    """The per-path state of a wavefront: one entry per live path."""

    patch: np.ndarray               # (n,) int32 the patch it is on (its source, then its last hit)
    chunk: np.ndarray | None        # (n,) int32 its chunk, in chunk order (None: one chunk)
    accumulated: np.ndarray | None  # (n,) product of R_bar along it (biased estimator)
    weights: np.ndarray | None      # (C,n) carried weight per channel (None: 1 on one channel)
    leave_from: np.ndarray | None   # (3,n) the point its next ray leaves from (exit_point="hit")
    weight_is_accumulated: bool     # grey biased walk: weights are a view of ``accumulated``

    @property
    def count(self):
        return self.patch.size

    def keep(self, index):
        """Only the paths at ``index`` (a new patch array, and a new point array, are set apart)."""
        if self.chunk is not None:
            self.chunk = self.chunk.take(index, mode="wrap")
        if self.accumulated is not None:
            self.accumulated = self.accumulated.take(index, mode="wrap")
        if self.weight_is_accumulated:
            self.weights = self.accumulated[None]
        elif self.weights is not None:
            self.weights = self.weights.take(index, axis=1, mode="wrap")


class PathWalk:
    """Paths as arrays: every stage reads and writes :class:`LivePaths`."""

    def __init__(self, tables, sizes, rng):
        self.tables = t = tables
        self.chunk_sizes = sizes
        # Every path's source, drawn at once for each chunk; paths start as places free up.
        # (Per source, each chunk's paths of each group are a chunk of their own: grouping)
        self.source, self.source_chunk, self.first_uniforms, self.source_part, sizes = draw_walk_sources(t, sizes, rng)
        self.sizes = sizes
        self.G, C, P = len(sizes), t.channels, t.patch_count
        self.grouped = self.G > 1
        self.total_paths = sum(sizes)
        self.scores = Scores(C, self.G * P)
        self.accounts = Accounts(self.G, C)
        self.started = 0
        self.chunk_key_bits = int(self.G - 1).bit_length()  # in the sort key by patch
        self.paths = LivePaths(
            patch=self.source[:0],
            chunk=self.source_chunk[:0] if self.grouped else None,
            accumulated=None if t.finite else np.ones(0),
            weights=None if t.unit_weights else np.zeros((C, 0)),
            leave_from=None,
            weight_is_accumulated=t.weight_is_accumulated,
        )

    # -- per-chunk sums over the live paths --------------------------------------------------
    def per_chunk(self, w, mask=None):
        """(G,C) weight ``w`` carried by the live paths (the masked ones), per chunk."""
        chunk = self.paths.chunk
        if not self.grouped:
            return (total_weight(w, self.paths.count) if mask is None else weight_sum(w, mask))[None]
        if mask is None:
            return chunk_sums(w, chunk, self.G)
        return chunk_sums(None if w is None else w.compress(mask, axis=1), chunk.compress(mask), self.G)

    def count(self, mask):
        """Number of masked live paths, (G,) per chunk."""
        if not self.grouped:
            return np.count_nonzero(mask)
        return chunk_counts(self.paths.chunk.compress(mask), self.G)

    def per_chunk_count(self):
        """Number of live paths, per chunk (a number outside a group)."""
        return chunk_counts(self.paths.chunk, self.G) if self.grouped else self.paths.count

    # -- stages ------------------------------------------------------------------------------
    def refill(self):
        """New paths from the sources take the places of ended ones; False once none is left."""
        t, p = self.tables, self.paths
        self.n_live = n_live = p.count
        self.new = new = min(WAVEFRONT_PATHS - n_live, self.total_paths - self.started) if self.started < self.total_paths else 0
        if new <= 0:
            return n_live > 0
        new_patch = self.source[self.started : self.started + new]
        new_chunk = None if self.source_chunk is None else self.source_chunk[self.started : self.started + new]
        p.patch = np.concatenate((p.patch, new_patch)) if n_live else new_patch
        if new_chunk is not None:
            p.chunk = np.concatenate((p.chunk, new_chunk)) if n_live else new_chunk
        if p.accumulated is not None:
            p.accumulated = np.concatenate((p.accumulated, np.ones(new)))
        if t.weight_is_accumulated:
            p.weights = p.accumulated[None]
        elif p.weights is not None:
            part = None if self.source_part is None else self.source_part[self.started : self.started + new]
            p.weights = np.concatenate((p.weights, t.start_weight(new_patch, part)), axis=1)
        w = None if p.weights is None else p.weights[:, n_live:]
        self.accounts.emitted += total_weight(w, new)[None] if new_chunk is None else chunk_sums(w, new_chunk, self.G)
        return True

    def generate(self, rng):
        """Each live path's next ray: from a new uniform point of its patch (random exit, and new
        paths), or from its hit point (exit_point="hit"), in a cosine-distributed direction
        about the patch's normal. Returns (origins, directions), (3,n) rows."""
        t, p = self.tables, self.paths
        n, n_live, new, start = p.count, self.n_live, self.new, self.started
        first = self.first_uniforms
        self.started += max(new, 0)
        if t.exit_random or n_live == 0:
            u = rng.random((t.uniforms_per_ray, n), dtype=np.float32)
            if first is not None and new > 0:
                u[:4, n_live:] = first[:, start : start + new]  # stratified first rays
            return rays.leave_sources(t, p.patch, u, n_live)
        u = rng.random((2, n), dtype=np.float32)
        # (new paths from a light take their rays from it below; its id, P and on, must not index
        # a patch table: take's "wrap" mode steps an id down by P at a time)
        normals = rays.patch_normals(t, p.patch if t.lights is None or new <= 0 else rays.on_patches(t, p.patch))
        origins = p.leave_from
        g = t.geometry
        origins += normals[:, :n_live] * (g.ray_offset if g.patch_ray_offset is None else g.ray_offsets(p.patch[:n_live]))
        light = back = None
        if new > 0:
            # New paths leave from points of their sources (their directions take u's rows).
            u_new = np.empty((t.uniforms_per_ray, new), dtype=np.float32)
            if first is not None:
                u_new[:4] = first[:, start : start + new]
                u[:, n_live:] = u_new[2:4]
            else:
                rng.random(dtype=np.float32, out=u_new[:2])
            if t.row_triangle is not None:
                rng.random(dtype=np.float32, out=u_new[t.row_triangle])
            source = p.patch[n_live:]
            back = rays.emitter_backs(t, p.patch, u[1], n_live)  # (before the directions take u[1])
            light = rays.light_columns(t, source)
            if light is not None:  # (their uniforms before leave_frames folds them)
                u_light = np.vstack([u_new[:2, light], u[:, n_live + light]])
                source = rays.on_patches(t, source)
            frame = rays.leave_frames(t, source, u_new)
            origins = np.concatenate((origins, frame_points(frame, u_new[0], u_new[1])), axis=1)
        directions = add_sphere_points(normals, u[0], u[1])
        if light is not None:
            rays.set_light_rays(t, p.patch[n_live + light], u_light, origins, directions, n_live + light)
        if back is not None:
            rays.turn_to_backs(t, p.patch.take(back), origins, directions, back)
        return origins, directions

    def intersect(self, origins, directions):
        """What each ray meets first (and, leaving from hit points, where)."""
        t = self.tables
        self.accounts.rays += self.per_chunk_count()
        region = rays.region_of(t, self.paths.patch)
        return rays.cast(t, origins, directions, region) if t.exit_random else rays.cast_to_points(t, origins, directions, region)

    def handle_escaped(self, hits):
        """Paths whose ray hit nothing escape, those that hit a back side are absorbed there
        (blocked); the others move to the patch they hit."""
        p, a = self.paths, self.accounts
        self.kept = None
        if not hits.front.all():
            missed = hits.hit < 0
            back = ~missed & ~hits.front
            if np.count_nonzero(missed):
                a.escaped += self.per_chunk(p.weights, missed)
                a.ended["escaped"] += self.count(missed)
            if np.count_nonzero(back):
                a.blocked += self.per_chunk(p.weights, back)
                a.ended["blocked"] += self.count(back)
            self.kept = np.flatnonzero(hits.front)
            hits.patch = hits.patch.take(self.kept, mode="wrap")
            p.keep(self.kept)
            if hits.points is not None:
                hits.points = hits.points.take(self.kept, axis=1, mode="wrap")
        p.patch, p.leave_from = hits.patch, hits.points

    def score(self, hits):
        """The power arriving at each hit patch (in a group, in its chunk's columns)."""
        p = self.paths
        self.scores.add(p.patch if p.chunk is None else p.chunk * np.int32(self.tables.patch_count) + p.patch, p.weights)
        self.arriving = self.per_chunk(p.weights)

    def survive_or_cut(self, hits, rng):
        """The estimator's rule at the hit: survive with R_bar (finite) or carry R and end
        below t (biased); then the survivors go on, grouped by patch in big scenes."""
        t, p, a = self.tables, self.paths, self.accounts
        go_on = None  # the paths that go on, in the order they go on (None: all, as they are)
        if t.finite:
            u = rng.random(self.n_live + max(self.new, 0))
            if self.kept is not None:
                u = u.take(self.kept, mode="wrap")
            go_on = np.flatnonzero(finite_survives(u, t.grey_reflectivity_at(p.patch)))
            hit_count = self.per_chunk_count()
        else:
            # New arrays, never in place: the weights just scored may be a view of ``accumulated``.
            p.accumulated = biased_carry(p.accumulated, t.grey_reflectivity_at(p.patch))
            if t.weight_is_accumulated:
                p.weights = p.accumulated[None]
            else:
                p.weights = p.weights * t.reflectivity.take(p.patch, axis=1, mode="wrap")
            a.absorbed += self.arriving - self.per_chunk(p.weights)  # (1 - R) of what arrived
            cut = biased_cut(p.accumulated, t.threshold)
            if cut.any():
                a.undistributed += self.per_chunk(p.weights, cut)
                a.ended["threshold"] += self.count(cut)
                go_on = np.flatnonzero(~cut)
        if t.speedups.sorted_paths and p.count:
            go_on = patch_order(p.patch, go_on, t.patch_key_shift, p.chunk, self.chunk_key_bits)
        if go_on is not None:
            p.patch = p.patch.take(go_on, mode="wrap")
            p.keep(go_on)
            if p.leave_from is not None:
                p.leave_from = p.leave_from.take(go_on, axis=1, mode="wrap")
        if t.finite:
            a.ended["absorbed"] += hit_count - self.per_chunk_count()
            if p.weights is not None:
                p.weights *= t.survivor_weight(p.patch)
            a.absorbed += self.arriving - self.per_chunk(p.weights)

    def tallies(self):
        t = self.tables
        tallies = self.accounts.tallies(self.sizes, self.scores.total().reshape(t.channels, self.G, t.patch_count))
        return tallies if t.groups is None else fold(tallies, self.chunk_sizes, t.groups.count)


def patch_order(patch, selected, shift, chunk=None, chunk_bits=0):
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
