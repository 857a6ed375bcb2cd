"""The first shot by gathering: each patch's direct light from every source by shadow rays.

Beyond the paper. A shooting walk's first bounce is about half its variance: where a path from
a source lands is the noisiest choice it makes. Here each patch j gathers its direct
irradiance H_j instead, from uniform points of it (stratified: a patch's samples are
Sobol' points with a random digital shift of its own), each looking at one source chosen by power
(a point on an emitting patch or on a light, or a direction of the sun) through a shadow ray
(none for a light that casts no shadow: its light passes through objects, as Cycles draws it),
and along one cosine-distributed ray (an emitting patch it meets, or the sky; none where the
only sources are lamps, which no ray meets, and with a chance where emitters are small,
``cosine_share``): the two strategies weighted by the power heuristic (``_emitter_weight``;
rays shot from the emitting patches, a third, lost to these in every scene measured:
benchmarks/direct_strategies.py). The walk then shoots only what the direct light reflects: patch j is
a source of emittance E'_j = R_j H_j, and the walk adds the light of every later bounce
(``direct_light="gathered"`` in :func:`.solver.solve`). Leaving from hit points (the
continuous walk), the reflected light leaves from where it arrived: each sample is a point
source of what it found, times R_j A_j / n_j (n_j the patch's expected gathering samples), so
that the first reflection is as uneven over a patch as the light that lands on it
(:class:`.gathered_walk.ReflectedPoints`).

Each chunk gathers with its own points and shoots its own walk from what it gathered, so the
chunks stay independent replicas of the whole estimate: batch means measure its error, which
the paper's formulas (2)-(3) do not predict. Unbiased: the walk's result is linear in its
sources, and E'_j is an unbiased estimate of R_j H_j (and the sample points an unbiased
estimate of its distribution over the patch). With exit_point="random" the walk takes each
patch's reflected light as uniform over it, the discrete method's assumption, as the shooting
walk does.
"""
from __future__ import annotations

import copy

import numpy as np

from ..lights.lights import WorldLight
from ..lights.near_choice import near_choice
from ..names import EXIT_RANDOM, FINITE
from ..scene.rays import hit_patches, meets_front
from ..lights.sampling import SourceTable, add_sphere_points, patch_point_rows, source_weights, stratified_by_patch
from ..estimate.grouping import SampleParts
from .tables import WalkTables

# A chunk's gathering aims at about this share of the rays its walk traces.
GATHER_SHARE = 0.3
# A patch's gathering samples in a chunk, at most (a small part of a SAMPLE_BLOCK): beside a small
# source the allotment gives many times the area's share (256 cut them: docs/performance.md).
MAX_GATHER_SAMPLES = 8192
# A chunk's gathering samples are drawn and traced this many at a time.
SAMPLE_BLOCK = 1 << 18
# The numbers each gathering sample draws: its point (2), a source (1), a point or direction
# of it (2), a cosine direction (2), and a triangle of either patch where patches are not
# parallelograms (2).
GATHER_DIMENSIONS = 10
# The Sobol' dimension each of them takes, stratified per patch (sampling.stratified_by_patch):
# the point on the patch the first two (a (0,2)-sequence), the point on the source or the
# direction to it the next two, then the cosine direction.
GATHER_SOBOL_DIMENSIONS = (0, 1, 6, 2, 3, 4, 5, 7, 8, 9)
# The share of samples that cast a cosine ray, where only emitting patches can be met: this
# many times the emitters' share of the area, from COSINE_SHARE_LEAST to 1.
COSINE_SHARE_PER_AREA = 10.0
COSINE_SHARE_LEAST = 0.1
# A receiver's own share beside emitters: this many times its form factor to them (near_choice's
# bound), where that is more than the scene's share.
COSINE_SHARE_PER_FORM = 3.0
# The strategies that find an emitting patch (_emitter_weight).
SHADOW, COSINE = range(2)
# Rays from the sources a solve casts, once, to split the direct light found on no front side
# between what escaped and what met a back side (fate_shares, split_lost), from its own stream
# of the solve's seed.
FATE_RAYS = 1 << 13
FATE_STREAM = 1 << 62
# A light is seen if the shadow ray meets nothing before this share of the way to it.
SEEN_BEFORE = 1.0 - 1e-5


def cosine_share(scene, world):
    """The chance that a gathering sample casts a cosine ray. Under a sky, 1 (only cosine rays
    find it); with lamps alone, 0 (no ray meets a lamp); with emitting patches, about the
    chance that it meets one: in a closed scene the area-weighted mean form factor to the
    emitters is A_E / A_T, so where emitters are small a cosine ray is nearly always wasted,
    and where they are large (a whole wall) it is what keeps the noise of patches beside them
    down (measured: 0.1 saved a fifth of the time in the suite's rooms, and cost 4x in the
    figure 1 cube, whose emitter is a face)."""
    if world:
        return 1.0
    emitting = scene.emission.any(axis=1)
    if not emitting.any():
        return 0.0
    share = COSINE_SHARE_PER_AREA * scene.patch_area[emitting].sum() / scene.total_area
    return float(np.clip(share, COSINE_SHARE_LEAST, 1.0))


def gather_samples(chunk_paths, expected_path_length, scene):
    """Expected gathering samples of each patch (P,) in a chunk of ``chunk_paths`` walks (two
    rays each): about GATHER_SHARE of the walk's rays in all. A patch's share goes as
    sqrt(A_j) R_bar_j, which minimises the area-weighted variance sum_j A_j R_j^2 Var(H_j) of
    the reflected direct light when each sample's relative variance is alike. A share below
    one is a chance of a sample (gather_direct divides by the share, not the count)."""
    budget = GATHER_SHARE * chunk_paths * max(expected_path_length, 1.0) / 2
    weight = np.sqrt(scene.patch_area) * np.maximum(scene.grey_reflectivity, 1e-3)
    return np.clip(weight * (budget / weight.sum()), 1e-3, MAX_GATHER_SAMPLES)


class Gathering:
    """What every chunk's gathering reads: the sources a shadow ray looks at, by power (emitting
    patches, then every light but the world, which the cosine rays find), and the scene's
    quantities in world units."""

    def __init__(self, scene, samples, stratified=True, fate_shares=(1.0, 0.0)):
        self.stratified = stratified  # a patch's samples a low-discrepancy set (else independent)
        self.lights = scene.lights.lights
        self.worlds = [light for light in self.lights if isinstance(light, WorldLight)]
        light_power = scene.lights.light_power()
        looked_at = np.array([not isinstance(light, WorldLight) for light in self.lights], dtype=bool)
        weights = source_weights(scene.patch_area, scene.emission, light_power * looked_at[:, None], scene.back_emits)
        self.table = SourceTable(weights) if weights.any() else None
        self.choice = weights / weights.sum() if weights.any() else weights  # P_s
        self.near = near_choice(scene, self.choice) if self.table is not None else None
        # (3,P); (P,) what a cosine ray can find; (P,) the emitters whose back emits too (scene.back_emits)
        self.emission, self.emits, self.back_emits = scene.emission.T, scene.emission.any(axis=1), scene.back_emits
        self.reflectivity = scene.reflectivity.T  # (3,P)
        self.patch_area = scene.patch_area
        self.cosine_share = cosine_share(scene, bool(self.worlds))
        # (P,) each receiver's: beside an emitter (near_choice's form factor bound), up to 1
        self.cosine_shares = np.full(scene.patch_count, self.cosine_share)
        if self.near is not None and self.near.form is not None and self.cosine_share < 1:
            near = np.clip(COSINE_SHARE_PER_FORM * self.near.form, COSINE_SHARE_LEAST, 1.0)
            self.cosine_shares = np.maximum(self.cosine_shares, near)
        # P_s / A_s of each emitting patch (_emitter_weight), A_j / n_j of each patch (ReflectedPoints).
        self.shadow_density = self.choice[:scene.patch_count] / scene.patch_area
        self._take_samples(samples)
        self.channel_power = scene.source_power.sum(axis=0)  # (3,) Phi_c
        # (escaped, blocked) of the light found on no front: what the solve measures (fate_shares).
        self.fate_shares = tuple(fate_shares)
        self.total_power = scene.total_power  # Phi_T: the solve's relative weights are times Phi_T / N
        # The glossy share of each patch's reflection (glossy.GlossyLobe) or None: where it is,
        # each sample keeps its rays' parts and directions.
        self.glossy = scene.glossy

    def _take_samples(self, samples):
        self.samples = np.asarray(samples, dtype=np.float64)  # (P,) expected, per patch
        self.whole = np.floor(self.samples).astype(np.int64)
        self.chance = self.samples - self.whole
        self.area_per_sample = self.patch_area / self.samples

    def with_samples(self, samples):
        """The same gathering with ``samples`` (P,) expected a patch (chunks of another size's)."""
        other = copy.copy(self)
        other._take_samples(samples)
        return other

    def choose(self, patch, u):
        """(n,) the source a shadow ray from each sample of ``patch`` looks at (near_choice)."""
        return self.near.choose(patch, u, self.table) if self.near.active else self.table.choose(u)

    def density(self, patch, source):
        """(n,) P_s / A_s: the chance that a sample of ``patch`` looks at emitting patch
        ``source``, per unit of its area."""
        if self.near is None or not self.near.active:
            return self.shadow_density.take(source)
        return self.near.probability(patch, source) / self.patch_area.take(source)

    def draw(self, rng):
        """This chunk's samples: the patch of each, count_j of patch j (the whole part of its
        share and one more with the fraction's chance); and what each sample's estimate is
        scaled by so that a patch's sum over ``samples`` is its samples' mean: n_j / count_j
        where every chunk draws one or more (the mean of stratified points is nearly exact, and
        a sum over n_j would be noisy by the count alone: a patch of 10.05 samples would be 0.5%
        low in most chunks and 9.5% high in one of twenty), 1 where a patch may draw none."""
        count = self.whole + (rng.random(self.samples.size) < self.chance)
        scale = np.where(self.whole >= 1, self.samples / np.maximum(count, 1), 1.0)
        patch = np.repeat(np.arange(count.size, dtype=np.int32), count)
        return patch, scale.take(patch)


def gather_direct(tables, gathering, rng, grouped=False, check=None):
    """(3,P) an unbiased estimate of each patch's direct irradiance H (scene units), the rays
    it traced, and the samples it is made of (patch (n,), unit-space point (3,n), estimate of
    the irradiance there (3,n)): per patch j, ``gathering.samples[j]`` points on average, each with a shadow ray to a
    source chosen by power and a cosine-distributed ray, weighted against each other where
    both can find the same emitting patch (multiple importance sampling, power heuristic:
    shadow rays are good at small and far sources, cosine rays at near and large ones). A
    patch's samples are stratified: Sobol' points with a random digital shift of the patch's
    own (points, sources, their points and directions evenly spread; each sample uniform, so
    the estimate stays unbiased, and chunks and patches independent, so batch means hold).
    ``grouped`` (per-source results): each sample's estimate is also kept as its shadow ray's
    and its cosine ray's parts, each of one source group (grouping.SampleParts), a fourth item.
    With a glossy lobe (``gathering.glossy``) the samples hold a fourth item: the two rays'
    parts (2,3,n) and unit directions (2,3,n float32). ``check()``: called between the two kinds of rays."""
    P, (patch, scale) = tables.patch_count, gathering.draw(rng)
    x = np.empty((3, patch.size), dtype=np.float32)  # unit space (ReflectedPoints keeps them)
    value = np.zeros((3, patch.size))
    parts = SampleParts(tables, patch) if grouped else None
    lobe = None if gathering.glossy is None else (  # (each technique's part and direction: (2,3,n) each)
        parts.value if grouped else np.zeros((2, 3, patch.size)), np.zeros((2, 3, patch.size), dtype=np.float32))
    rays = 0
    for rows in _blocks(patch, SAMPLE_BLOCK):  # (a large chunk's memory stays that of a block)
        rays += _gather_block(tables, gathering, patch[rows], x[:, rows], value[:, rows], rng, None if parts is None else
                              parts.block(rows), None if lobe is None else (lobe[0][:, :, rows], lobe[1][:, :, rows]), check)
    value *= scale
    if lobe is not None and not grouped:
        lobe[0][:] *= scale
    # (float64 even for a chunk that drew no sample: bincount of nothing gives integers)
    H = np.stack([np.bincount(patch, weights=value[c], minlength=P) for c in range(3)]).astype(np.float64, copy=False)
    H /= gathering.samples
    samples = (patch, x, value) if lobe is None else (patch, x, value, lobe)
    if parts is not None:
        parts.value *= scale
        return H, rays, samples, parts
    return H, rays, samples


def _gather_block(tables, gathering, patch, x32, value, rng, parts=None, lobe=None, check=None):
    """The samples of a run of whole patches: their points into ``x32`` (3,n), their estimates
    added to ``value`` (3,n) (and, given the block's ``parts``, (value (2,3,n), group (2,n),
    group of each shadow source), kept as its shadow and its cosine part; given ``lobe``
    (parts (2,3,n), directions (2,3,n)), the two rays' parts and directions kept there too);
    returns the rays traced."""
    g = tables.geometry
    if gathering.stratified:
        u = stratified_by_patch(patch, tables.patch_count, GATHER_SOBOL_DIMENSIONS, rng, dtype=np.float32)
    else:
        u = rng.random((GATHER_DIMENSIONS, patch.size), dtype=np.float32)
    x32[:] = patch_point_rows(g, patch, u[7], u[0].copy(), u[1].copy())
    x = x32.astype(np.float64)
    normal = g.patch_normal_rows.take(patch, axis=1).astype(np.float64)
    rays = 0
    shadow, cosine = (value, value) if parts is None else parts[0]
    if lobe is not None and parts is None:
        shadow, cosine = lobe[0]
    directions = (None, None) if lobe is None else lobe[1]
    if gathering.table is not None:
        source = gathering.choose(patch, u[2])
        rays += _shadow_rays(tables, gathering, patch, source, x, normal, u, shadow, directions[0])
        if parts is not None:
            parts[1][0] = parts[2].take(source)
    check is None or check()  # (it raises to stop the chunk)
    if gathering.cosine_share > 0:
        rays += _cosine_rays(tables, gathering, patch, x, normal, u, cosine, groups=None if parts is None else parts[1][1],
                             directions=directions[1])
    if parts is not None or lobe is not None:
        value += shadow + cosine
    return rays


def _blocks(patch, size):
    """Slices of ``patch`` (sorted, each patch's samples a run) of whole runs, about ``size``
    samples each (a run is at most MAX_GATHER_SAMPLES, far below it; a longer one a block alone)."""
    cuts = [0]
    while patch.size - cuts[-1] > size:
        cut = int(np.searchsorted(patch, patch[cuts[-1] + size], side="left"))
        cuts.append(cut if cut > cuts[-1] else int(np.searchsorted(patch, patch[cut], side="right")))
    cuts.append(patch.size)
    return [slice(a, b) for a, b in zip(cuts[:-1], cuts[1:])]


def _emitter_weight(gathering, technique, receiver, source, cos_x, cos_y, distance_world):
    """(n,) the weighted estimate over E_s, as a sample of the receiving patch, of an emitting
    patch s met at distance d by a sample of ``technique`` (SHADOW or COSINE) of patch
    ``receiver``. The strategies' densities at x, in solid angle, each per gathering sample:
    p_shadow = P_s d^2 / (A_s cos_y) (P_s the receiver's chance of looking at s)
    (one shadow ray a sample) and p_cosine = q cos_x / pi (q = the cosine share); a sample of
    strategy t weighs in as f p_t / sum p^2, f = E_s cos_x / pi (the power heuristic). A
    receiver's irradiance is the sum of its samples' estimates over n_j."""
    p_cosine = cos_x * (1.0 / np.pi)
    densities = (gathering.density(receiver, source) * distance_world**2 / cos_y,
                 gathering.cosine_shares.take(receiver) * p_cosine)
    square = densities[0] ** 2
    square += densities[1] ** 2
    weight = p_cosine * densities[technique]
    weight /= square
    return weight


def _shadow_rays(tables, gathering, patch, source, x, normal, u, value, directions=None):
    """Adds each sample's shadow-ray estimate (towards its ``source``) to ``value`` (and the
    unit direction it looked in to ``directions``, where given); returns the rays traced."""
    g, P = tables.geometry, tables.patch_count
    n = patch.size
    towards = np.empty_like(x)
    distance = np.empty(n)  # unit space, to the point looked at
    weight = np.zeros(n)  # an emitting patch's estimate over its emittance
    lit = None  # (3,n) the lights' estimates
    unshadowed, facing = np.zeros(n, dtype=bool), np.zeros(n, dtype=bool)  # a light without shadow: always seen; a front seen
    # The estimate's geometry is the surfaces' own: the points lie a ray offset off them (for the
    # rays), which seen at a grazing angle changes cos and distance by far more than the offset.
    surface = x - normal * g.ray_offsets(patch, np.float64)
    on_patch = source < P
    at_patch = slice(None) if on_patch.all() else np.flatnonzero(on_patch)
    if on_patch.any():
        towards[:, at_patch], distance[at_patch], weight[at_patch], facing[at_patch] = _towards_emitters(
            tables, gathering, patch[at_patch], source[at_patch], surface[:, at_patch], normal[:, at_patch], u[:, at_patch])
    at_light = np.flatnonzero(~on_patch)
    if at_light.size:
        lit = np.zeros_like(value)
        light = source[at_light] - P
        x_world = g.to_world(surface[:, at_light].T, patch[at_light]).T
        for k in np.flatnonzero(np.bincount(light)):  # (the lights looked at: np.unique without its sort)
            here = light == k
            cols = at_light[here]
            t, dist, v = gathering.lights[k].gather(x_world[:, here], normal[:, cols], u[3:5, cols])
            unshadowed[cols] = not getattr(gathering.lights[k], "casts_shadow", True)
            towards[:, cols] = t
            distance[cols] = dist / g.diagonal
            lit[:, cols] = v / gathering.choice[source[cols]]
    live = weight > 0
    if lit is not None:
        live |= lit.any(axis=0) & ~unshadowed
    live = np.flatnonzero(live)
    if live.size:
        hit, hit_patch, front, t = trace(tables, x[:, live], towards[:, live], g.region_of(patch[live]))
        # Seen if nothing is met before the point looked at; on an emitting patch, also if the
        # patch is met first. (A patch's points lie a ray offset off it: at grazing angles a ray
        # to a point near its far edge passes the point and misses the patch. Asking for the
        # patch alone lost 0.23% of the figure 4 room's direct light, 2% on its walls' tops.)
        met_source = (hit >= 0) & (hit_patch == source[live]) & (front == facing[live]) & on_patch[live]
        reach = distance[live]
        if g.patch_ray_offset is not None:
            # The ray leaves x, an offset along the normal from the surface the distance is
            # measured from: it comes nearest the point looked at that much sooner (an offset
            # of a few float32 spacings of a large scene may exceed a lamp's gap to a ceiling).
            reach = reach - g.ray_offsets(patch[live], np.float64) * np.einsum("in,in->n", normal[:, live], towards[:, live])
        clear = (hit < 0) | (t >= reach * SEEN_BEFORE)
        blocked = live[~(met_source | clear)]
        weight[blocked] = 0.0
        if lit is not None:
            lit[:, blocked] = 0.0
    if on_patch.any():
        value += gathering.emission.take(source if on_patch.all() else np.where(on_patch, source, 0), axis=1) * weight
    if lit is not None:
        value += lit
    if directions is not None:
        directions[:] = towards
    return live.size


def _towards_emitters(tables, gathering, patch, source, surface, normal, u):
    """For samples at ``surface`` (3,n) of ``patch`` looking at points of emitting patches
    ``source``: (unit directions (3,n), unit-space distances (n,), the estimate over the emittance
    of each, 0 where the side seen emits nothing or is the patch's own, whether a front is seen)."""
    g = tables.geometry
    e = patch_point_rows(g, source, u[8], u[3].copy(), u[4].copy()).astype(np.float64)
    normal_s = g.patch_normal_rows.take(source, axis=1)
    e -= normal_s * g.ray_offsets(source, np.float64)
    e -= surface  # surface to surface (the shadow ray follows it from x)
    if g.regions is not None:  # (from the source's region frame to the receiver's)
        e += g.regions.shift(g.regions.of(source)) - g.regions.shift(g.regions.of(patch))
    length = np.sqrt(np.einsum("in,in->n", e, e))
    e /= length
    cos_x = np.einsum("in,in->n", normal, e)
    cos_y = -np.einsum("in,in->n", normal_s, e)
    ok = (cos_x > 0) & ((cos_y > 0) | gathering.back_emits.take(source)) & (cos_y != 0) & (source != patch)
    w = _emitter_weight(gathering, SHADOW, patch, source, cos_x, np.maximum(np.abs(cos_y), 1e-12), length * g.diagonal)
    return e, length, np.where(ok, w, 0.0), cos_y > 0


def _cosine_rays(tables, gathering, patch, x, normal, u, value, cast_all=False, groups=None, directions=None):
    """Adds each sample's cosine-ray estimate to ``value``: the emitting patch it meets (weighted
    against the shadow rays), or the sky where it escapes. A sample casts one with probability
    ``gathering.cosine_share`` (u[9]), which the balance heuristic counts. Returns the rays
    traced. ``groups`` (n,), where given, takes the source group of what each ray found;
    ``directions`` (3,n), where given, the ray's unit direction."""
    g = tables.geometry
    if gathering.cosine_share < 1 and not cast_all:
        cast = np.flatnonzero(u[9] < gathering.cosine_shares.take(patch))
        part = np.zeros((3, cast.size))
        found = None if groups is None else groups[cast]
        towards = None if directions is None else np.zeros((3, cast.size), dtype=np.float32)
        rays = _cosine_rays(tables, gathering, patch[cast], x[:, cast], normal[:, cast], u[:, cast], part, True, found, towards)
        value[:, cast] += part
        if groups is not None:
            groups[cast] = found
        if directions is not None:
            directions[:, cast] = towards
        return rays
    towards = add_sphere_points(g.patch_normal_rows.take(patch, axis=1), u[5], u[6])
    towards = towards.astype(np.float64)
    towards /= np.sqrt(np.einsum("in,in->n", towards, towards))  # (normal + a sphere point: cosine distributed)
    hit, source, front, t = trace(tables, x, towards, g.region_of(patch))
    met = np.flatnonzero((front | gathering.back_emits.take(source)) & (hit >= 0) & gathering.emits.take(source) & (source != patch))
    if met.size:
        s = source[met]
        cos_x = np.einsum("in,in->n", normal[:, met], towards[:, met])
        cos_y = np.abs(np.einsum("in,in->n", g.patch_normal_rows.take(s, axis=1).astype(np.float64), towards[:, met]))
        value[:, met] += gathering.emission[:, s] * _emitter_weight(gathering, COSINE, patch[met], s, cos_x, np.maximum(cos_y, 1e-12), t[met] * g.diagonal)
    escaped = np.flatnonzero(hit < 0)
    if escaped.size and gathering.worlds:
        for world in gathering.worlds:
            value[:, escaped] += world.radiance_times_pi(towards[:, escaped])
    if groups is not None:  # (escaped: the world's group; every world is in one, grouping)
        groups[:] = np.where(hit < 0, tables.groups.world, tables.groups.whole.source_group.take(source))
    if directions is not None:
        directions[:] = towards
    return patch.size


def trace(tables, origins, directions, region=None):
    """Shadow or cosine rays (3,n rows, unit space; ``region``: their origins' region frames,
    where the scene has regions): (triangle, patch, front, distance)."""
    o = np.ascontiguousarray(origins.T, dtype=np.float32)
    d = np.ascontiguousarray(directions.T, dtype=np.float32)
    triangle, u, v, t, ng = tables.outside_turn(tables.tracer.first_hit_barycentric, o, d, region)
    patch = hit_patches(tables, triangle, u, v)
    return triangle, patch, meets_front(d.T, ng) & (triangle >= 0), t


def direct_irradiance(scene, samples=64, seed=0):
    """(P,3) an estimate of each patch's direct irradiance H alone (the light arriving straight
    from the sources), from ``samples`` gathering samples a patch, in rounds of 8 (memory)."""
    tables = WalkTables(scene, FINITE, 1e-3, EXIT_RANDOM)
    rounds = max(1, int(np.ceil(samples / 8)))
    gathering = Gathering(scene, np.full(scene.patch_count, 8.0))
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(1 << 30,))))
    total = np.zeros((3, scene.patch_count))
    with tables.numpy_turn:
        for _ in range(rounds):
            total += gather_direct(tables, gathering, rng)[0]
    return (total / rounds).T

