"""Two-way stochastic Jacobi iteration: every ray used twice, with a constant control variate.

Beyond the paper. A chunk estimates the light in generations, as stochastic Jacobi
iteration does (``jacobi``), but each generation's rays leave every patch, not only those with
power to shoot, so that each ray serves two estimates:

- gathering: a ray from patch i that meets the front of patch j samples what i receives, the
  form factor F_ij times j's reflected radiosity dB_j;
- shooting: the same ray brings j what i reflects (by reciprocity, A_i F_ij = A_j F_ji).

Both estimate the irradiance of the next generation, H_i = sum_j F_ij dB_j, from the same
segment; the balance heuristic weights them: with n_i rays expected from patch i, segment
i -> j adds dB_j / (n_i + n_j A_i / A_j) to H_i and dB_i / (n_j + n_i A_j / A_i) to H_j (the
two techniques' densities of the pair, per unit of the integrand). A ray that escapes, or meets
a back side, can only have been sampled from i: it adds 0 / n_i to H_i.

A constant control variate beta (per channel: the area-weighted mean of dB) is taken out of
every value and added back exactly: H_i = beta + sum over what i's rays see of (dB_j - beta),
where a ray that escapes or meets a back side sees 0 - beta. In a closed room dB is close to
beta everywhere after a bounce or two, so the values left are small: the shooting half, whose
noise goes with the second moment of what it carries, needs the control variate to pay.

Per chunk:

    gather_direct   each patch's direct irradiance H^0 (``first_shot``: shadow rays and cosine
                    rays, weighted by the power heuristic)
    reflect_first   (generations) the first reflection R H^0: a constant over each patch (exit_point="random",
                    the discrete method), or as uneven over a patch as the light that landed on
                    it (exit_point="hit": the constant, and what the gathering samples found
                    beyond it, shot from them, a patch's rays of either sign in pairs of one
                    direction); from the second reflection on, each patch's
                    reflected light is uniform over it
    allot           a generation's rays to patches by systematic sampling, in proportion to
                    sqrt(A_j) R_bar_j; the count in proportion to the generation's reflected power
    cast            cosine-distributed rays from Hammersley points of each patch (rays.cast)
    score_two_ways  each segment's two estimates, weighted, about the control variate
    reflect         dB = R H, the next generation's; once its power would pay for fewer than
                    LEAST_RAYS rays a patch, that many rays; below ROULETTE_SHARE of that,
                    Russian roulette: go on with dB / q with probability q

Each generation is, given the previous one, an unbiased estimate of the light it carries on,
so a chunk's total is unbiased (the roulette keeps the expectation); chunks are independent
replicas and the solve's batch means measure the error, which the paper's formulas do not
predict. The accounts balance in expectation, not path by path: what a generation's rays that
escape or meet a back side estimate of its reflected power is tallied as escaped or blocked.

What a solve plans for it: chunks large enough that each patch gets TWO_WAY_RAYS_PER_PATCH
first-generation rays (fewer, and what a generation passes on is mostly its own noise), up to
TWO_WAY_CHUNK_RAYS_PER_PATCH, and where the plan is only a guess (a run to an error target),
at least the balance of the stop rule (``balanced_chunk``); its direct light's samples allotted
partly by a pilot of the direct light (``two_way.direct_samples``); and what the forecast predicts of it: its
variance per path falls as its chunks grow, as v_inf (1 + G P / n) (``two_way_sizes``). The paper's
formulas do not predict its error, which is measured.

"""
from __future__ import annotations

import math


from dataclasses import dataclass, replace
import numpy as np

from .generations import generation, leaving, reflect_first, reflected_power
from .first_shot import MAX_GATHER_SAMPLES, gather_direct
from .gathered_walk import split_lost
from ..estimate.grouping import with_groups
from ..estimate.tallies import ChunkTally
from .first_shot import FATE_STREAM, Gathering
from ..names import GATHERED, TWO_WAY
from ..estimate.plan import MIN_CHUNK_PATHS, MIN_MEASURED_CHUNKS, chunk_paths_for
from .two_way_sizes import TWO_WAY_GROWTH, again_chunk, balanced_chunk, later_chunk
from .base import GatheringIntegrator, Method, check, solve_gathering, spec_gathering
from .tables import chunk_wide

# Rays of a chunk of n paths: n FIRST_REFLECTION_RAYS from the gathering samples (hit exit,
# generations), then n GENERATION_RAYS in the first two-way generation, fewer as the light dies down.
GENERATION_RAYS = 2.0
# ... and n DIRECT_SAMPLES gathering samples of the direct light (two rays each).
DIRECT_SAMPLES = 1.5
# The share of them allotted by each patch's estimated direct light; the rest by the allotment
# weight alone, so that no patch's share falls below that part of it.
RECEIVED_SHARE = 0.5
# The stream of a solve's seed its pilot gathering draws from (pilot_irradiance).
PILOT_STREAM = FATE_STREAM + 1
# A generation casts at least this many rays a patch: one whose power would pay for fewer goes on
# with this many. Fewer rays a patch, and a generation's estimate is spikier than the last's (a
# chain of sparse generations lets a few patches' values grow without bound: at 0.1 runs were up
# to 5x off). Measured in the closed Cornell box (2,940 and 59,535 patches): 0.5 the least MSE,
# and no heavy-tailed chunk.
LEAST_RAYS = 0.5
# Russian roulette ends a chunk's light, all or nothing for every patch at once, only once its
# power would pay for this share of LEAST_RAYS a patch: what it moves, it moves everywhere
# together (an error no filter sees as noise, which a picture shows as its brightness), so it
# plays where the light left is a small share of what the patches were given (docs/picture.md).
ROULETTE_SHARE = 0.1


@dataclass
class Chunk:
    """What a chunk carries from generation to generation, in the scene's units."""

    reflected: np.ndarray   # (C,P) dB: the radiosity each patch reflects in this generation
    irradiance: np.ndarray  # (C,P) H summed over generations so far (direct light included)
    absorbed: np.ndarray    # (C,) power, per channel
    escaped: np.ndarray
    blocked: np.ndarray
    rays: int
    generations: int = 0
    correction: np.ndarray | float = 0.0  # (C,P) irradiance the first generation adds (reflect_first)
    # Per source, every (C,P) array above is (S C,P), each group's channels: the light passes on
    # linearly, each ray carrying every group's share; ``reflectivity`` is R for those rows.
    reflectivity: np.ndarray | None = None
    groups: int = 1


def allotment_weight(area, reflectivity, geometry=None):
    """(P,) what rays are allotted to patches in proportion to: sqrt(A_j) R_j, R_j one number a
    patch (a patch's error in B is R_j times its error in H; sqrt(A) sits between the
    area-weighted error, which wants rays as A, and the per-patch one, which wants them alike).
    The direct light's samples take R_bar_j; the generations R_j of the strongest channel, as
    they are counted (a red wall, R_bar 0.25 but R_red 0.63, carries most of the late red light)."""
    weight = np.sqrt(area) * np.maximum(reflectivity, 1e-3)
    if geometry is not None and geometry.buried is not None:
        weight[geometry.buried.whole] = 0.0  # (inside another object: no ray from there meets the room)
    return weight


def rays_per_path(expected_path_length):
    """About the rays a path of a chunk costs: two a direct-light sample, GENERATION_RAYS for
    each of the paper's expected bounces (what a solve sizes its chunks by)."""
    return 2 * DIRECT_SAMPLES + GENERATION_RAYS * max(expected_path_length, 1.0)


def direct_samples(chunk_paths, scene, irradiance=None):
    """(P,) expected gathering samples of each patch's direct light in a chunk of ``chunk_paths``:
    DIRECT_SAMPLES a path in all, allotted as a generation's rays are (a share below one is a
    chance of a sample); given each patch's ``irradiance`` (P,), a pilot's root mean square
    sample of its direct light (pilot_irradiance), RECEIVED_SHARE of them in
    proportion to the allotment weight times it (what minimises the weighted sum of the
    patches' variances, sum_j w_j^2 E[X_j^2] / n_j: where a small source sends much of its
    light to a few patches, they need many more samples than their area's), the rest by the
    weight alone (no patch gets less than that part of its share: none is starved)."""
    weight = allotment_weight(scene.patch_area, scene.grey_reflectivity, scene.geometry)
    share = weight / weight.sum()
    if irradiance is not None:
        received = weight * np.maximum(np.nan_to_num(np.asarray(irradiance, dtype=np.float64)), 0.0)
        if received.sum() > 0:
            share = (1.0 - RECEIVED_SHARE) * share + RECEIVED_SHARE * received / received.sum()
    return np.clip(share * (DIRECT_SAMPLES * chunk_paths), 1e-3, MAX_GATHER_SAMPLES)


def pilot_irradiance(tables, gathering, seed):
    """(P,) the root mean square, over each patch's samples, of their estimates of its direct
    irradiance (channels summed), from one draw of ``gathering``'s samples from the seed's own
    stream (0 where a patch drew none): what a solve allots its chunks' samples by
    (two_way.direct_samples), the second moment because a sample's variance goes as it (a
    patch beside a small source finds light as heavy-tailed as it is strong). Only the
    allotment reads it, so each chunk's estimate stays unbiased whatever it says."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(PILOT_STREAM,))))
    patch, value = gather_direct(tables, gathering, rng)[2][::2]
    square = value.sum(axis=0) ** 2
    count = np.bincount(patch, minlength=tables.patch_count)
    return np.sqrt(np.bincount(patch, weights=square, minlength=tables.patch_count) / np.maximum(count, 1))


def two_way_chunk(tables, gathering, paths, rng, check=None):
    """One chunk of ``paths`` (the unit its rays are counted in): the direct light gathered,
    then the reflected light generation by generation. Returns a ChunkTally in the walk's
    relative weights (times Phi_T / N). ``check()`` is called every generation (it raises to
    stop)."""
    C, area = tables.channels, gathering.patch_area
    check = check or (lambda: None)
    gathered = gather_direct(tables, gathering, rng, tables.groups is not None, check)
    check()  # (between stages too: a run that has met its target waits for the chunks it abandons)
    H, gather_rays, samples = gathered[:3]
    H = H[:C]
    direct = H * gathering.patch_area  # (C,P) power arriving straight from the sources
    emitted = gathering.channel_power[:C]
    # What the direct light brought no patch's front escaped or met a back side (split_lost).
    escaped, blocked = split_lost(gathering, emitted - direct.sum(axis=1))
    state = Chunk(np.zeros_like(H), H.copy(), np.zeros(C), escaped, blocked, gather_rays, reflectivity=tables.reflectivity)
    if tables.groups is not None:
        state = grouped_chunk(tables, gathering, gathered[3], gather_rays)
        direct = state.irradiance * area if tables.direct_apart else None  # (S C,P) each group's direct light
    R = state.reflectivity
    if tables.exit_random:
        state.reflected = R * state.irradiance
    else:
        reflect_first(tables, gathering, state, samples, paths, rng, None if tables.groups is None else gathered[3], check)
        check()
    first_power = reflected_power(area, state.reflected, state.groups)
    budget = GENERATION_RAYS * paths / max(first_power, 1e-300)  # rays per unit of reflected power
    weight = allotment_weight(area, tables.reflectivity.max(axis=0), tables.geometry)
    least = int(np.ceil(LEAST_RAYS * weight.size))
    while True:
        check()
        count = budget * reflected_power(area, state.reflected, state.groups)
        if count <= 0:
            break
        if count < least * ROULETTE_SHARE:
            go_on = count / (least * ROULETTE_SHARE)
            if rng.random() >= go_on:
                state.absorbed += leaving(area, state.reflected)  # (the roulette's end: nothing leaves)
                break
            state.absorbed -= leaving(area, state.reflected) * (1.0 / go_on - 1.0)  # what leaves beyond it
            state.reflected = state.reflected / go_on
        count = max(count, least)
        generation(tables, area, state, weight, int(np.rint(count)), rng)
    incident = state.irradiance * area
    absorbed = state.absorbed + ((1.0 - R) * incident).sum(axis=1)
    scale = paths / gathering.total_power  # relative weight per unit of power
    direct = direct * scale if tables.direct_apart else None  # (kept in the tally only where asked)
    if tables.groups is not None:
        return grouped_tally(state, paths, scale, incident, emitted, absorbed, (escaped, blocked), direct)
    return ChunkTally(paths, state.rays, incident * scale, emitted * scale, absorbed * scale, state.escaped * scale,
                      state.blocked * scale, np.zeros(C), {"generations": state.generations}, direct=direct)


def grouped_chunk(tables, gathering, parts, gather_rays):
    """A chunk's state per source: each group's direct irradiance (from the gathering's
    ``parts``) as its rows, every account from zero (the direct light's lost part is the
    total's, added at the end: grouped_tally)."""
    C, S, P = tables.channels, tables.groups.count, tables.patch_count
    H = parts.irradiance(S, P, gathering.samples)[:, :C].reshape(S * C, P)
    zeros = lambda: np.zeros(S * C)  # noqa: E731
    return Chunk(np.zeros_like(H), H, zeros(), zeros(), zeros(), gather_rays,
                 reflectivity=np.tile(tables.reflectivity, (S, 1)), groups=S)


def grouped_tally(state, paths, scale, incident, emitted, absorbed, lost, direct):
    """The ChunkTally of a per-source chunk: (S C,...) rows summed over the groups, each group's
    incident power its ``incident_groups``, and of it the direct light (S C,P, or None) its ``direct_groups``."""
    S = state.groups
    C = incident.shape[0] // S
    by_channel = lambda a: a.reshape(S, C).sum(axis=0)  # noqa: E731
    tally = ChunkTally(paths, state.rays, None, emitted * scale, by_channel(absorbed) * scale,
                       (by_channel(state.escaped) + lost[0]) * scale, (by_channel(state.blocked) + lost[1]) * scale,
                       np.zeros(C), {"generations": state.generations})
    tally = with_groups(tally, (incident * scale).reshape(S, C, -1))
    return tally if direct is None else replace(tally, direct_groups=direct.reshape(S, C, -1))


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
# A run's later chunks (sized on its first ones: later_chunk) may grow past the plan's, up to this many
# first-generation rays a patch: where the plan's chunks are several times too small for the stop rule's
# fewest chunks, a run of many of them pays each one's start and sparse last generations, and their
# variance per path, grown as (1 + G P / n), is nearly spent here (1.19 of its large-chunk value at
# G = 12; the studio flat: 80 chunks of the plan's 47k paths, docs/performance.md).
TWO_WAY_LATER_RAYS_PER_PATCH = 128
# A chunk's gathering samples and rays go a block at a time (first_shot.SAMPLE_BLOCK,
# two_way.RAY_BLOCK); what it holds at once beyond a block is its samples' points and values.
TWO_WAY_MAX_CHUNK_PATHS = 1 << 20

class TwoWay(Method):
    """The two-way stochastic Jacobi iteration."""

    name = TWO_WAY
    direct_lights = (GATHERED,)
    sizes_later_chunks = True

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
        paths_for = lambda rays: paths_for_rays(patch_count, rays)  # noqa: E731
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

    def later_chunk(self, patch_count, first, done, variance, target_mse, most):
        """``later_chunk``, up to the larger of ``most`` and TWO_WAY_LATER_RAYS_PER_PATCH first-generation
        rays a patch (at most TWO_WAY_MAX_CHUNK_PATHS)."""
        largest = min(TWO_WAY_MAX_CHUNK_PATHS, paths_for_rays(patch_count, TWO_WAY_LATER_RAYS_PER_PATCH))
        return later_chunk(patch_count, first, done, variance, target_mse, least_chunk(patch_count), max(most, largest))

    def again_chunk(self, patch_count, sizes, increments, terms, target_mse, running, most):
        """``again_chunk``: its variance's growth measured (``measured_growth``), from ``least_chunk``
        to the larger of ``most`` and TWO_WAY_LATER_RAYS_PER_PATCH first-generation rays a patch."""
        largest = min(TWO_WAY_MAX_CHUNK_PATHS, paths_for_rays(patch_count, TWO_WAY_LATER_RAYS_PER_PATCH))
        return again_chunk(patch_count, sizes, increments, terms, target_mse, running, least_chunk(patch_count),
                           max(most, largest))

    def resized(self, state, chunk, new_chunk):
        """Its gathering's samples scaled with the chunk (DIRECT_SAMPLES a path, as direct_samples)."""
        samples = np.clip(state.gathering.samples * (new_chunk / chunk), 1e-3, MAX_GATHER_SAMPLES)
        return TwoWayChunks(state.tables, state.gathering.with_samples(samples))

    def create(self, scene, tables, chunk, seed, prediction):
        """Its gathering, the samples allotted partly by a pilot's direct light."""
        with tables.numpy_turn:
            pilot = pilot_irradiance(tables, Gathering(scene, direct_samples(chunk, scene)), int(seed))
        return TwoWayChunks(tables, solve_gathering(scene, tables, direct_samples(chunk, scene, pilot), seed))

    def rebuild(self, scene, tables, spec):
        return TwoWayChunks(tables, spec_gathering(scene, spec))


def least_chunk(patch_count):
    """The fewest paths a run's later chunks take: TWO_WAY_RAYS_PER_PATCH first-generation rays a patch."""
    return max(MIN_CHUNK_PATHS, paths_for_rays(patch_count, TWO_WAY_RAYS_PER_PATCH))


def paths_for_rays(patch_count, rays):
    """The paths of a chunk whose first generation gives each patch ``rays`` rays on average
    (``first_generation_rays``' inverse, rounded up)."""
    return math.ceil(rays * patch_count / GENERATION_RAYS)


def first_generation_rays(patch_count, chunk_paths):
    """The rays a patch gets, on average, in a two-way chunk's first generation."""
    return GENERATION_RAYS * chunk_paths / patch_count


class TwoWayChunks(GatheringIntegrator):
    """The two-way iteration's chunks: the tables and the gathering of the direct light."""

    def run(self, sizes, rng, abort=None):
        sizes = [int(n) for n in sizes]
        tables = chunk_wide(self.tables, sum(sizes))
        with tables.numpy_turn:
            return [two_way_chunk(tables, self.gathering, n, rng, lambda: check(abort)) for n in sizes]
