"""The two-way iteration's generations (``two_way``): the first reflection of the gathered direct
light, then each generation's rays, every segment used both ways about the control variate.

The first reflection (``reflect_first``), as uneven over each patch as the light that landed on it
(the hit exit).

The gathering samples (``first_shot``) are point sources of what they found
(``gathered_walk.ReflectedPoints``). Their mean over each patch is the patch reflecting its light
uniformly, which the first two-way generation carries; what is left of each sample (zero in sum
over its patch) is shot from its point in cosine directions (``_shoot_left``), and the glossy
share of a shadow ray's light along its lobe (``_shoot_glossy``, :mod:`.glossy`). Their
irradiance joins the first generation's.

A generation (``generation``) allots its rays to patches by systematic sampling, casts them from
shifted Halton points, and scores each segment's two estimates (``two_way`` says how).

Per source, every array has a row per group and channel (S C): they are counted a row at a time
(a (S C, rays) temporary leaves the cache), and the glossy rows, each all one group's light, are
kept as (C,G) with a group each (``_Lobe``); every sum meets the same values in the same order as
the dense rows', so the results are theirs to the bit.
"""
from __future__ import annotations


import numpy as np

from ..scene import rays
from ..mesh.faces import ranks_in_runs
from .gathered_walk import ReflectedPoints
from ..lights.sampling import HALTON, SOBOL, shifted_float32, systematic_counts, unit_floats

# Rays of a chunk of n paths from the gathering samples: n FIRST_REFLECTION_RAYS.
FIRST_REFLECTION_RAYS = 3.0
# A generation's rays (and the first reflection's) are cast this many at a time.
RAY_BLOCK = 1 << 18


def reflect_first(tables, gathering, state, samples, paths, rng, parts=None, check=None):
    """The first reflection as uneven over each patch as the light that landed on it (hit exit).

    Each sample k of patch j is a point source of what it found (power p_k,
    gathered_walk.ReflectedPoints), sum_k p_k = R_j A_j H_j. The samples are uniform points of j,
    m_j of them, so sources of power sum_k p_k / m_j at them are patch j reflecting R_j H_j
    uniformly, which the first two-way generation carries (``state.reflected``). What is left
    (zero in sum over each patch), c_k = p_k - sum / m_j, is shot from the samples: rays
    allotted in proportion to |c_k|, each carrying an equal share of sum |c| with c_k's sign,
    a patch's positive and negative rays in pairs of one direction (_paired_ranks). It is small
    where the direct light is even over a patch; its irradiance (``state.correction``) joins
    the first generation's. Per source (the samples' ``parts``), a ray carries each group's c_k.
    A glossy share of the shadow rays' light (:mod:`.glossy`) is no part of p_k nor of the
    uniform reflection: it is shot from the samples along its lobe (_shoot_glossy). ``check()``, where
    given, is called before each block of rays (it raises to stop)."""
    C, P = tables.channels, tables.patch_count
    patch = samples[0]
    state.reflected = state.reflectivity * state.irradiance
    points = ReflectedPoints(gathering, tables.geometry, samples, rng)
    K = points.count
    power = points.rows[:C]
    # Per source: each group's part of the samples' diffuse power (S C,K), the group of each glossy row.
    rows_power, lobe_group = (power[:, :K], None) if parts is None else points.group_power(gathering, parts, state.groups, C)
    spread = np.bincount(patch, minlength=P)  # m_j
    glossy = points.glossy_rows
    lobe = _Lobe(power[:, K:], lobe_group, state.groups, P)
    if glossy.size:  # (the lobe's light leaves no patch evenly)
        lobe_patch = patch.take(points.samples_of(glossy))
        state.reflected -= lobe.sums(lobe_patch, np.ones(glossy.size, dtype=bool), lobe.power) / gathering.patch_area
    correction = np.zeros((rows_power.shape[0], P))
    total_power = max(float(power.sum()) / C, 1e-300)
    _shoot_left(tables, state, points, None if parts is None else rows_power, power[:, :K], spread, correction,
                paths, total_power, rng, check)
    if glossy.size:
        check is None or check()
        _shoot_glossy(tables, state, points, lobe, correction, paths, total_power, rng)
    state.correction = correction / gathering.patch_area


def _shoot_left(tables, state, points, rows_power, power, spread, correction, paths, total_power, rng, check=None):
    """The first reflection's c_k (each sample's power less its patch's mean; of ``rows_power``
    (S C,K; None: ``power``) the rays carry, of the total ``power`` (C,K) they are allotted by) shot from the
    samples; their irradiance times the area added to ``correction``."""
    P = tables.patch_count
    patch = points.patch

    def less_mean(rows):  # (a row at a time: no (rows, K) temporaries)
        left, count = np.empty_like(rows), np.maximum(spread, 1)
        for out, p in zip(left, rows):
            mean = np.bincount(patch, weights=p, minlength=P) / count
            np.subtract(p, mean.take(patch), out=out)
        return left

    left = less_mean(power)  # c_k
    rows_left = left if rows_power is None else less_mean(rows_power)
    size = np.abs(left).mean(axis=0)  # what a sample's rays are allotted by
    allotted = _allot(state, size, paths, total_power, rng)
    if allotted is None:
        return
    total, count, sample = allotted
    ray_patch = patch.take(sample)
    rank, shift = _paired_ranks(ray_patch, (left.sum(axis=0) < 0).take(sample), P, rng)
    table = SOBOL.rows(int(rank.max(initial=0)) + 1)[:2]
    for start in range(0, count, RAY_BLOCK):
        check is None or check()
        rows = slice(start, min(start + RAY_BLOCK, count))
        k = sample[rows]
        u = np.empty((4, k.size), dtype=np.float32)  # (a sample's point is its origin: u[2:4] the direction)
        u[2:4] = _shifted_points(table, rank[rows], shift.take(ray_patch[rows], axis=1))
        # (signed power a ray: rows_left[:, k] times this)
        _cast_carried(tables, state, points, k, u, (rows_left, k, total / count / size.take(k)), correction)


class _Lobe:
    """The glossy rows' power (``power`` (C,G)); per source, each row's group (``group`` (G,), -1:
    none; else None) among S: a row's light is all of its group's (a part of one sample)."""

    def __init__(self, power, group, S, P):
        self.power, self.group, self.S, self.P = power, group, S, P
        if group is not None:
            self.power = np.where(group >= 0, power, 0.0)
            self.key = np.maximum(group, 0).astype(np.intp) * P  # (each row's group's first place)

    def sums(self, patch, mask, weights, rows=None):
        """(S C,P) (or (C,P)) the masked ``weights`` (C,n) of rows ``rows`` (all: None) summed by
        ``patch`` (n,), each group's channels its rows (as the rows (S C,n) with zeros elsewhere)."""
        patch = patch.compress(mask).astype(np.intp)
        if self.group is None:
            return np.stack([np.bincount(patch, weights=w.compress(mask), minlength=self.P) for w in weights])
        key = (self.key if rows is None else self.key.take(rows)).compress(mask) + patch
        S, C = self.S, weights.shape[0]
        sums = np.stack([np.bincount(key, weights=w.compress(mask), minlength=S * self.P) for w in weights])
        return sums.reshape(C, S, self.P).transpose(1, 0, 2).reshape(S * C, self.P)

    def lost(self, mask, weights, rows):
        """(S C,) (or (C,)) the masked ``weights`` (C,n) of rows ``rows`` summed by row, each as
        the (S C,n) rows' sum (zeros elsewhere; numpy's pairwise sum over the same values)."""
        if self.group is None:
            return np.array([w.compress(mask).sum() for w in weights])
        group, kept = self.group.take(rows).compress(mask), [w.compress(mask) for w in weights]
        return np.array([np.where(group == g, w, 0.0).sum() for g in range(self.S) for w in kept])


def _shoot_glossy(tables, state, points, lobe, correction, paths, total_power, rng):
    """The glossy rows' power (``lobe``, a _Lobe) shot from their samples along their lobes,
    rays allotted in proportion to it (as _shoot_left's); irradiance times area into ``correction``."""
    size = lobe.power.mean(axis=0)
    allotted = _allot(state, size, paths, total_power, rng)
    if allotted is None:
        return
    total, count, row = allotted
    for start in range(0, count, RAY_BLOCK):
        g = row[start:start + RAY_BLOCK]
        u = np.zeros((4, g.size), dtype=np.float32)  # (the lobe draws its own directions: ReflectedPoints)
        origins, directions = points.unit_rays(g + points.count, u, tables.geometry)
        hits = rays.cast(tables, origins, directions, points.regions(g + points.count, tables.geometry))
        w = lobe.power.take(g, axis=1) * (total / count / size.take(g))  # (C,n) power a ray
        correction += lobe.sums(hits.patch, hits.front, w, g)
        state.escaped += lobe.lost(hits.hit < 0, w, g)
        state.blocked += lobe.lost((hits.hit >= 0) & ~hits.front, w, g)


def _allot(state, size, paths, total_power, rng):
    """(total, count, row of each ray) of rays allotted to rows in proportion to ``size`` (n,),
    FIRST_REFLECTION_RAYS a path for the share ``total / total_power`` (counted in ``state.rays``);
    None where there is nothing to shoot."""
    total = float(size.sum())
    if total <= 0:
        return None
    count = max(1, int(np.rint(FIRST_REFLECTION_RAYS * paths * total / total_power)))
    state.rays += count
    return total, count, np.repeat(np.arange(size.size), systematic_counts(size, count, rng.random()))


def _cast_carried(tables, state, points, rows, u, carried, correction):
    """Rays from ``points``' rows ``rows`` (uniforms ``u``) carrying power ``carried`` = (values (S C,m),
    columns (n,), factor (n,)): each ray values[:, column] times its factor. What meets a front goes into
    ``correction``, what escapes or meets a back into the accounts; a row at a time (no (S C,n) temporary)."""
    origins, directions = points.unit_rays(rows, u, tables.geometry)
    hits = rays.cast(tables, origins, directions, points.regions(rows, tables.geometry))
    values, columns, factor = carried
    columns = columns.astype(np.intp, copy=False)
    index = hits.patch.compress(hits.front).astype(np.intp)
    escaped, back = np.flatnonzero(hits.hit < 0), np.flatnonzero((hits.hit >= 0) & ~hits.front)  # (few: no mask a row)
    lost = np.zeros((2, values.shape[0]))
    for r, v in enumerate(values):
        w = v.take(columns) * factor
        correction[r] += np.bincount(index, weights=w.compress(hits.front), minlength=tables.patch_count)
        lost[0, r], lost[1, r] = w.take(escaped).sum(), w.take(back).sum()
    state.escaped += lost[0]
    state.blocked += lost[1]


def _paired_ranks(ray_patch, negative, P, rng):
    """The first reflection's correction rays in pairs of one direction: each ray's rank among
    its patch's rays of its sign ((n,) int64), and a random digital shift of each patch's
    ((2,P) uint32). Ray r of a patch's rays that carry more than the patch's mean and ray r of
    those that carry less take Sobol' point r of the patch's shift (each direction uniform,
    each sign's set evenly spread): the two leave the patch in the same direction from nearby
    points, and where they land on the same patch their shares, of opposite signs, cancel.
    ``ray_patch`` is in patch order (the samples are), so a rank is a count of the rays before
    it in its patch's run with its sign: no sort."""
    position = ranks_in_runs(np.bincount(ray_patch, minlength=P))  # within its patch's run
    negative_before = np.cumsum(negative) - negative  # in the whole list
    negative_rank = negative_before - negative_before[np.arange(ray_patch.size) - position]
    rank = np.where(negative, negative_rank, position - negative_rank)
    return rank, rng.integers(0, 1 << 32, size=(2, P), dtype=np.uint32)


def _shifted_points(table, rank, shift):
    """(2, n) float32 in [0, 1): Sobol' points ``rank`` of ``table`` (2, m) uint32, each XORed
    with its own ``shift`` (2, n)."""
    points = table.take(rank, axis=1)
    points ^= shift
    return unit_floats(points, np.float32)


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
    if value.shape[0] > tables.channels:  # (per source, many rows: a row at a time)
        _score_rows(i, j, s, value, H)
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


def _score_rows(i, j, s, value, H):
    """Adds s value[:, j] to H[:, i] and s value[:, i] to H[:, j] for every row of ``value`` (per-source
    rows), a row at a time: the ends at i counted first, then those at j added one by one in order
    (np.add.at), the sums of one count over both ends to the bit, without (rows, 2n) temporaries
    that leave the cache."""
    i, j = i.astype(np.intp), j.astype(np.intp)
    for row, v in zip(H, value):
        ends = np.bincount(i, weights=v.take(j) * s, minlength=row.size)
        np.add.at(ends, j, v.take(i) * s)
        row += ends


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
