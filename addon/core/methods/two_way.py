"""The two-way iteration (``two_way``, beyond the paper): stochastic Jacobi with every ray
shooting and gathering about a control variate, its direct light always gathered.

What a solve plans for it: chunks large enough that each patch gets TWO_WAY_RAYS_PER_PATCH
first-generation rays (fewer, and what a generation passes on is mostly its own noise), up to
TWO_WAY_CHUNK_RAYS_PER_PATCH, and where the plan is only a guess (a run to an error target),
at least the balance of the stop rule (``balanced_chunk``); its direct light's samples allotted
partly by a pilot of the direct light (``two_way.direct_samples``); and what the forecast predicts of it: its
variance per path falls as its chunks grow, as v_inf (1 + TWO_WAY_GROWTH P / n). The paper's
formulas do not predict its error, which is measured.
"""
from __future__ import annotations

import math

from . import walk_stages as stages
from .first_shot import Gathering, pilot_irradiance
from ..names import GATHERED, TWO_WAY
from ..estimate.plan import MEASURED_STOP_CHUNKS, MIN_MEASURED_CHUNKS, chunk_paths_for
from .two_way_iteration import GENERATION_RAYS, direct_samples, rays_per_path, two_way_chunk
from .base import GatheringIntegrator, Method, solve_gathering, spec_gathering

# The two-way iteration needs this many first-generation rays a patch in a chunk: with fewer,
# what a generation passes on is mostly its own noise, which the next generation's gathering
# reads, and its gain over the walk per ray goes (the closed Cornell box, 2,940-535,815
# patches: from 4 rays a patch 2.3-3.2x the walk's, at one ray 0.82-1.21;
# benchmarks/results/auto_method.md). Its chunks get them as far as TWO_WAY_MAX_CHUNK_PATHS and
# MIN_MEASURED_CHUNKS chunks in the plan allow (methods.automatic takes the walk where they do not).
TWO_WAY_RAYS_PER_PATCH = 4
# ... and grow on to this many, within TWO_WAY_MIN_CHUNKS chunks of the plan: the noise a
# generation passes on keeps falling (the figure 4 room, 16M paths: 8, 16 and 32 rays a patch,
# 1.0, 0.83 and 0.67 of the variance per path, the time alike; docs/performance.md).
TWO_WAY_CHUNK_RAYS_PER_PATCH = 32
# A small plan's two-way chunks: half as many as the walk's, twice as large. A chunk's variance
# per path falls as it grows (its last, sparse generations and the roulette that ends them carry
# a smaller share of its light): at 2M paths 13% less in the Cornell box and 10% in the empty
# room than in 32 chunks, 2-3% more in 8 (docs/performance.md); 16 leave the batch estimate 15
# degrees of freedom.
TWO_WAY_MIN_CHUNKS = 16
# A chunk's gathering samples and rays go a block at a time (first_shot.SAMPLE_BLOCK,
# two_way.RAY_BLOCK); what it holds at once beyond a block is its samples' points and values.
TWO_WAY_MAX_CHUNK_PATHS = 1 << 20
# The variance per path in chunks of n paths over P patches, as v_inf (1 + TWO_WAY_GROWTH P / n):
# fitted over chunk sizes 4x apart, 6-30 in the suite and sample scenes (docs/performance.md,
# "The time prediction").
TWO_WAY_GROWTH = 12.0


class TwoWay(Method):
    """The two-way stochastic Jacobi iteration."""

    name = TWO_WAY
    direct_lights = (GATHERED,)

    def chunk_paths(self, patch_count, expected_path_length, planned_paths, time_limited=False, guessed=False):
        """The usual rays (a small plan in TWO_WAY_MIN_CHUNKS chunks), or more: up to
        TWO_WAY_CHUNK_RAYS_PER_PATCH first-generation rays a patch (GENERATION_RAYS a path)
        within TWO_WAY_MIN_CHUNKS chunks of the plan, and at least TWO_WAY_RAYS_PER_PATCH within
        MIN_MEASURED_CHUNKS; never more than TWO_WAY_MAX_CHUNK_PATHS. ``guessed``: the plan is
        only the walk's prediction for a run that stops on its measured error; the chunks then
        grow to at least ``balanced_chunk`` (up to TWO_WAY_CHUNK_RAYS_PER_PATCH), where small
        chunks would cost more paths than the fewest chunks the stop rule reads. Under a time
        limit, the usual rays (about plan.RAYS_PER_CHUNK): a chunk of a million paths can take
        longer than the limit, and a run stopped before its first chunk has nothing to give."""
        usual = chunk_paths_for(rays_per_path(expected_path_length), planned_paths, TWO_WAY_MIN_CHUNKS)
        if time_limited:
            return usual
        paths_for = lambda rays: math.ceil(rays * patch_count / GENERATION_RAYS)  # noqa: E731
        grown = min(paths_for(TWO_WAY_CHUNK_RAYS_PER_PATCH), math.ceil(planned_paths / TWO_WAY_MIN_CHUNKS))
        enough = min(paths_for(TWO_WAY_RAYS_PER_PATCH), math.ceil(planned_paths / MIN_MEASURED_CHUNKS))
        if guessed:
            grown = max(grown, min(paths_for(TWO_WAY_CHUNK_RAYS_PER_PATCH), balanced_chunk(patch_count, planned_paths)))
        return int(min(TWO_WAY_MAX_CHUNK_PATHS, max(usual, grown, enough)))

    def pays(self, patch_count, chunk_paths):
        """Whether chunks of ``chunk_paths`` give each patch TWO_WAY_RAYS_PER_PATCH rays."""
        return first_generation_rays(patch_count, chunk_paths) >= TWO_WAY_RAYS_PER_PATCH

    def rays_per_path(self, bounces):
        return rays_per_path(bounces)

    def variance_scale(self, patch_count, pilot_chunk, chunk):
        return (1 + TWO_WAY_GROWTH * patch_count / chunk) / (1 + TWO_WAY_GROWTH * patch_count / pilot_chunk)

    def create(self, scene, tables, chunk, seed, prediction):
        """Its gathering, the samples allotted partly by a pilot's direct light."""
        with tables.numpy_turn:
            pilot = pilot_irradiance(tables, Gathering(scene, direct_samples(chunk, scene)), int(seed))
        return TwoWayChunks(tables, solve_gathering(scene, tables, direct_samples(chunk, scene, pilot), seed))

    def rebuild(self, scene, tables, spec):
        return TwoWayChunks(tables, spec_gathering(scene, spec))


def balanced_chunk(patch_count, planned_paths):
    """The chunk of n paths at which the fewest chunks a measured stop reads (MEASURED_STOP_CHUNKS
    of them, K) hold the paths the plan's run takes at that size, its variance per path grown
    as (1 + G P / n) (TWO_WAY_GROWTH): K n = N (1 + G P / n), for N the plan's paths. Smaller
    chunks need more paths for the same error; larger ones run past it."""
    k, n = MEASURED_STOP_CHUNKS, float(planned_paths)
    return math.ceil((n + math.sqrt(n * n + 4.0 * k * TWO_WAY_GROWTH * patch_count * n)) / (2.0 * k))


def first_generation_rays(patch_count, chunk_paths):
    """The rays a patch gets, on average, in a two-way chunk's first generation."""
    return GENERATION_RAYS * chunk_paths / patch_count


class TwoWayChunks(GatheringIntegrator):
    """The two-way iteration's chunks: the tables and the gathering of the direct light."""

    def run(self, sizes, rng, abort=None):
        sizes = [int(n) for n in sizes]
        tables = stages.chunk_wide(self.tables, sum(sizes))
        with tables.numpy_turn:
            return [two_way_chunk(tables, self.gathering, n, rng, lambda: stages.check(abort)) for n in sizes]
