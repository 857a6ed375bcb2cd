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
    reflect_first   (first_reflection) the first reflection R H^0: a constant over each patch (exit_point="random",
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
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..scene import rays
from .first_reflection import FIRST_REFLECTION_RAYS, reflect_first  # noqa: F401 (the first: read as a chunk's rays)
from .first_shot import MAX_GATHER_SAMPLES, gather_direct
from .gathered_walk import split_lost
from .jacobi_iteration import HALTON, systematic_counts
from ..lights.sampling import shifted_float32
from ..estimate.grouping import with_groups
from ..estimate.tallies import ChunkTally

# Rays of a chunk of n paths: n FIRST_REFLECTION_RAYS from the gathering samples (hit exit,
# first_reflection), then n GENERATION_RAYS in the first two-way generation, fewer as the light dies down.
GENERATION_RAYS = 2.0
# ... and n DIRECT_SAMPLES gathering samples of the direct light (two rays each).
DIRECT_SAMPLES = 1.5
# The share of them allotted by each patch's estimated direct light; the rest by the allotment
# weight alone, so that no patch's share falls below that part of it.
RECEIVED_SHARE = 0.5
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
# A generation's rays (and the first reflection's) are cast this many at a time.
RAY_BLOCK = 1 << 18


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
    sample of its direct light (first_shot.pilot_irradiance), RECEIVED_SHARE of them in
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


def two_way_chunk(tables, gathering, paths, rng, check=None):
    """One chunk of ``paths`` (the unit its rays are counted in): the direct light gathered,
    then the reflected light generation by generation. Returns a ChunkTally in the walk's
    relative weights (times Phi_T / N). ``check()`` is called every generation (it raises to
    stop)."""
    C, area = tables.channels, gathering.patch_area
    gathered = gather_direct(tables, gathering, rng, tables.groups is not None)
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
        reflect_first(tables, gathering, state, samples, paths, rng, None if tables.groups is None else gathered[3])
    first_power = reflected_power(area, state.reflected, state.groups)
    budget = GENERATION_RAYS * paths / max(first_power, 1e-300)  # rays per unit of reflected power
    weight = allotment_weight(area, tables.reflectivity.max(axis=0), tables.geometry)
    least = int(np.ceil(LEAST_RAYS * weight.size))
    while True:
        if check is not None:
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


def reflected_power(area, reflected, groups=1):
    """What a generation's rays are counted by: the power it reflects, sum_j A_j |dB_j| (an
    estimate about a control variate can be below zero in places), in its strongest channel
    (per source, of the groups' sum).
    (Counted by the channels' mean, a saturated channel outlives the others between red walls
    and the roulette's 1/chance lifted it generation after generation: in the closed Cornell
    box one run in four had a chunk that put half the variance on five patches.)"""
    if groups > 1:
        reflected = reflected.reshape(groups, -1, reflected.shape[1]).sum(axis=0)
    return float(_sums(np.abs(reflected), area).max())


def leaving(area, reflected):
    """(C,) the power each channel reflects, sum_j A_j dB_j."""
    return _sums(reflected, area)


def generation(tables, area, state, weight, count, rng):
    """One two-way generation of ``count`` rays: their irradiance added to ``state``, its
    reflection the next ``state.reflected``. The rays go out RAY_BLOCK at a time (a run of
    patches' rays each), so that a large chunk's memory stays that of a block."""
    P = tables.patch_count
    expected = weight * (count / weight.sum())  # n_i
    patch = np.repeat(np.arange(P, dtype=np.int32), systematic_counts(weight, count, rng.random()))
    blocks = _ray_blocks(count, rng)  # (its first shift drawn here, as before blocks)
    triangle_u = rng.random((1, count), dtype=np.float32) if tables.row_triangle is not None else None
    state.rays += count
    state.generations += 1
    dB = state.reflected
    beta = _sums(dB, area) / area.sum()  # (C,) the control variate
    value = dB - beta[:, None]
    density = expected / area
    H = np.zeros_like(dB)
    lost = np.zeros((2, P))  # rays from each patch that escaped, that met a back side
    for rows, u in blocks:
        if triangle_u is not None:
            u = np.vstack([u, triangle_u[:, rows]])
        _score_two_ways(tables, patch[rows], u, value, density, H, lost)
    H /= area
    sends = expected > 0  # (patches inside another object send no rays: none of beta reaches them)
    if not sends.all():
        expected = np.where(sends, expected, np.inf)
    # A ray from i that escaped or met a back side saw 0 - beta: what i's rays kept of beta.
    H += beta[:, None] * (1.0 - lost.sum(axis=0) / expected) * sends
    H += state.correction
    state.correction = 0.0
    # What the rays from i that found nothing, or a back side, estimate of i's reflected power.
    state.escaped += _sums(dB * area, lost[0] / expected)
    state.blocked += _sums(dB * area, lost[1] / expected)
    state.irradiance += H
    state.reflected = state.reflectivity * H


def _score_two_ways(tables, patch, u, value, density, H, lost):
    """Casts one block of a generation's rays (from ``patch``, uniforms ``u``) and adds each
    segment's two estimates to H (C,P, times the area), its lost rays to ``lost`` (2,P)."""
    P = tables.patch_count
    origins, directions = rays.leave_random(tables, patch, u)
    hits = rays.cast(tables, origins, directions, tables.geometry.region_of(patch))
    met = hits.front
    i, j = patch.compress(met), hits.patch.compress(met)
    # Segment i -> j adds dB_j s / A_i to H_i and dB_i s / A_j to H_j, s = 1 / (n_i/A_i + n_j/A_j).
    s = density.take(i)
    s += density.take(j)
    np.reciprocal(s, out=s)
    if value.shape[0] > tables.channels:  # (per source, many rows: both ends in one count a row)
        _score_rows(np.concatenate((i, j)), np.concatenate((j, i)), np.concatenate((s, s)), value, H)
    else:
        gathered, shot = value.take(j, axis=1), value.take(i, axis=1)
        gathered *= s
        shot *= s
        for c in range(value.shape[0]):
            H[c] += np.bincount(i, weights=gathered[c], minlength=P)
            H[c] += np.bincount(j, weights=shot[c], minlength=P)
    if not met.all():
        lost[0] += np.bincount(patch.compress(hits.hit < 0), minlength=P)
        lost[1] += np.bincount(patch.compress((hits.hit >= 0) & ~met), minlength=P)


def _score_rows(to, source, s, value, H):
    """Adds s value[:, source] to H[:, to] for every row of ``value`` (per-source rows)."""
    carried = value.take(source, axis=1)
    carried *= s
    for row, weights in zip(H, carried):
        row += np.bincount(to, weights=weights, minlength=row.size)


def _ray_blocks(count, rng):
    """The blocks of ``count`` rays, RAY_BLOCK at a time, one by one: (rows, a slice; u (4, n)
    float32), u the Halton points 0..n-1 (bases 2, 3, 5, 7) shifted by one random vector modulo
    1: each point uniform, together evenly spread; the rays of each patch take a run of them.
    Each block has its own set and shift, so that the table stays a block's size; the first
    shift is drawn now, the others as their blocks are reached."""
    shift = rng.random(4)

    def blocks():
        for start in range(0, count, RAY_BLOCK):
            n = min(RAY_BLOCK, count - start)
            points = HALTON.rows(n)[:, :n] + (shift if start == 0 else rng.random(4))[:, None]
            yield slice(start, start + n), shifted_float32(points)

    return blocks()


def _sums(values, weights):
    """(C,) sum over patches of ``values`` (C,P) times ``weights`` (P,), without BLAS: a large
    matrix product wakes BLAS's threads, which spin on after it and take the CPUs from the
    solve's other threads."""
    return np.einsum("cp,p->c", values, weights)
