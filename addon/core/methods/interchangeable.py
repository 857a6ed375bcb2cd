"""The walk's stages for the paper's plain walk, whose paths are interchangeable.

A grey finite walk leaving from random points: every path carries the same power and leaves each
patch from a new point, so a path is nothing but the patch it is on (and its chunk), and the live
paths may be kept in any order without changing the estimate.

Every ray ends one of four ways: escaped (no hit), blocked (a back side), absorbed (a front hit,
then the survival test fails) or surviving. Instead of selecting the survivors path by path, a
step puts each ray in a bin of its chunk's K bins by outcome, and one whole-array operation
regroups them:

- counted (small scenes): the bins are 2 patch + survives, then escaped (2P) and blocked
  (2P + 1); one bincount counts the step's rays by chunk, patch and outcome, and survivors
  restart from the counts, patch j s_j times, in patch order. In a scene of parallelograms
  (unless first rays are stratified, which pairs each new path with its own numbers) the live
  paths are nothing but a count per chunk and patch: new paths join the counts, and a step's
  leaving frames are the leave table's columns repeated that many times;
- sorted (bigger scenes): the bins are the front-hit patch, then escaped (P) and blocked
  (P + 1); the bins are scored, and a sort puts the survivors first, in order of chunk and
  patch, so that rays leaving one patch go to the ray tracer together.

A chunk's bins hold all its accounts: its rays, its escaped and blocked paths, and so its
absorbed ones (every path ends once).
"""
from __future__ import annotations

import numpy as np

from ..scene import rays
from .estimators import finite_survives
from .path_walk import WAVEFRONT_PATHS
from ..lights.sampling import SourceRuns, draw_sources
from ..estimate.grouping import draw_walk_sources, fold
from ..estimate.tallies import ChunkTally, Scores


class InterchangeableWalk:
    """Interchangeable paths: as counts per chunk and patch, or as an array of their patches."""

    def __init__(self, tables, sizes, rng):
        self.tables = t = tables
        g = t.geometry
        self.chunk_sizes = sizes
        if t.groups is not None:  # (each chunk's paths of each group a chunk of their own: grouping)
            drawn = draw_walk_sources(t, sizes, rng)
            sizes = drawn[-1]
        self.sizes = sizes
        self.P = P = t.patch_count
        self.G = G = len(sizes)
        self.total_paths = sum(sizes)
        self.counted = t.speedups.counted
        self.tagged = G > 1
        self.K = K = 2 * P + 2 if self.counted else P + 2  # bins per chunk: [2 patch + survives | patch], escaped, blocked
        self.escaped_bin = np.int32(K - 2)
        self.past = np.int32(G * K)  # a sort key past every bin: paths that do not go on
        # Live paths as counts per chunk and patch, or (live None) as arrays of their patches and
        # chunks. New paths join the counts from their sources' counts where each chunk draws
        # those (a chunk's paths come in runs, one per source), else from every path's source.
        self.live = self.runs = None
        if self.counted and g.all_parallelograms and not t.stratified and t.lights is None and t.emitter_backs is None:
            self.live = np.zeros((G, P), dtype=np.int64)
            if t.groups is None and all(t.sources.draws_counts(n) for n in sizes):
                self.runs = SourceRuns(t.sources, sizes, rng)
        self.first_uniforms = None
        if self.runs is None:
            if t.groups is None:
                drawn = draw_sources(t.sources, sizes, rng, t.stratified)
            source, self.source_chunk, self.first_uniforms = drawn[:3]
            self.source = source.astype(np.int32)
            self.patch = self.source[:0]
            self.chunk = self.source_chunk[:0] if self.tagged else None
        if self.counted:
            self.bins = np.zeros((G, K), dtype=np.int64)
            self.patch_index = np.arange(P, dtype=np.int32)
            if self.tagged:  # (patch, chunk) pairs in patch-major order
                self.patch_of_pair = np.repeat(self.patch_index, G)
                self.chunk_of_pair = np.tile(np.arange(G, dtype=np.int32), P)
        else:
            self.scores = Scores(1, G * K)
        self.started = 0
        self.n_live = 0
        self.region = None  # the region frame of each ray's origin (.regions), or None

    def refill(self):
        """New paths take the places of ended ones; False once none is left."""
        self.new = new = min(WAVEFRONT_PATHS - self.n_live, self.total_paths - self.started)
        if new <= 0 and self.n_live == 0:
            return False
        if new > 0:
            start, end = self.started, self.started + new
            if self.live is None:
                new_patch = self.source[start:end]
                if self.n_live:
                    self.patch = np.concatenate((self.patch, new_patch))
                    if self.tagged:
                        self.chunk = np.concatenate((self.chunk, self.source_chunk[start:end]))
                else:
                    self.patch = new_patch
                    self.chunk = self.source_chunk[start:end] if self.tagged else None
            elif self.runs is not None:
                self.runs.add_window(self.live, start, end)
            elif self.tagged:
                pair = self.source_chunk[start:end] * np.int32(self.P)
                pair += self.source[start:end]
                self.live += np.bincount(pair, minlength=self.G * self.P).reshape(self.G, self.P)
            else:
                self.live[0] += np.bincount(self.source[start:end], minlength=self.P)
        return True

    def generate(self, rng):
        """A ray from a new uniform point of each live path's patch, cosine-distributed."""
        t, new, start = self.tables, self.new, self.started
        n = self.n_live + max(new, 0)
        self.n = n
        self.started += max(new, 0)
        u = rng.random((t.uniforms_per_ray, n), dtype=np.float32)
        if self.live is not None:
            # The leave table's columns, each repeated as many times as paths are on its patch.
            on_patch = self.live.sum(axis=0) if self.tagged else self.live[0]
            if self.tagged:
                self.chunk = np.repeat(self.chunk_of_pair, self.live.T.ravel())
            frame = np.repeat(t.leave_table, on_patch, axis=1)
            if t.geometry.buried is not None:  # (points of partly buried patches on their visible part)
                t.geometry.buried.remap(np.repeat(np.arange(self.P, dtype=np.int32), on_patch), None, u[0], u[1])
            if t.geometry.regions is not None:
                self.region = np.repeat(t.geometry.regions.patch_region, on_patch)
            return rays.rays_from_frames(frame, u[0], u[1], u[2:4])
        self.region = rays.region_of(t, self.patch)
        if self.first_uniforms is not None and new > 0:
            u[:4, self.n_live :] = self.first_uniforms[:, start : start + new]  # stratified first rays
        return rays.leave_sources(t, self.patch, u, self.n_live)

    def intersect(self, origins, directions):
        return rays.cast(self.tables, origins, directions, self.region)

    def handle_escaped(self, hits):
        """Escaped and blocked rays go to their chunk's last two bins."""
        self.ended_bin = self.escaped_bin + (hits.hit >= 0)

    def score(self, hits):
        """Each ray's bin: its front-hit patch (counted: twice it), or how it ended."""
        key = rays.select(hits.front, hits.patch * np.int32(2) if self.counted else hits.patch, self.ended_bin)
        if self.tagged:
            key += self.chunk * np.int32(self.K)
        self.key = key
        if not self.counted:
            self.scores.add(key, None)

    def survive_or_cut(self, hits, rng):
        """The finite estimator's survival test; the survivors regrouped by patch (and chunk)."""
        survive = finite_survives(rng.random(self.n), self.tables.grey_reflectivity_at(hits.patch))
        survive &= hits.front
        key = self.key
        if self.counted:
            key += survive  # bin 2 patch + 1: survived
            step = np.bincount(key, minlength=self.G * self.K).reshape(self.G, self.K)
            self.bins += step
            survivors = step[:, 1 : 2 * self.P : 2]
            if self.live is not None:
                self.live = survivors
                self.n_live = int(survivors.sum())
                return
            if self.tagged:
                pairs = survivors.T.ravel()
                self.patch = np.repeat(self.patch_of_pair, pairs)
                self.chunk = np.repeat(self.chunk_of_pair, pairs)
            else:
                self.patch = np.repeat(self.patch_index, survivors[0])
        else:
            key = rays.select(survive, key, self.past)
            key.sort()
            key = key[: int(np.searchsorted(key, self.past))]
            if self.tagged:
                self.chunk = key // np.int32(self.K)
                self.patch = key - self.chunk * np.int32(self.K)
            else:
                self.patch = key
        self.n_live = self.patch.size

    def tallies(self):
        P, K = self.P, self.K
        if self.counted:
            bins = self.bins
            incident = bins[:, 0 : 2 * P : 2] + bins[:, 1 : 2 * P : 2]
        else:
            bins = self.scores.total()[0].reshape(self.G, K)
            incident = bins[:, :P]
        rays_per_chunk = bins.sum(axis=1)
        tallies = []
        for k, n in enumerate(self.sizes):
            escaped, blocked = int(bins[k, K - 2]), int(bins[k, K - 1])
            absorbed = n - escaped - blocked  # every path ends once
            one = lambda count: np.array([float(count)])  # noqa: E731
            tallies.append(ChunkTally(
                paths=n,
                rays=int(rays_per_chunk[k]),
                incident=incident[k : k + 1].astype(np.float64),
                emitted=one(n),
                absorbed=one(absorbed),
                escaped=one(escaped),
                blocked=one(blocked),
                undistributed=one(0),
                ended={"escaped": escaped, "blocked": blocked, "absorbed": absorbed, "threshold": 0},
            ))
        return tallies if self.tables.groups is None else fold(tallies, self.chunk_sizes, self.tables.groups.count)
