"""Final gather: each patch's bounced light gathered again from the solved light, for the display.

The solve's estimate of a patch's bounced light (its light arriving less the direct light) carries
errors its neighbours share: the same chunks' paths bring light to a stretch of wall, so a dim wall
comes out blotched at the scale of several patches, which the noise filter (neighbours within their
noise of each other) cannot see. A final gather, as the classic two-pass methods do, takes each
patch's bounced light again from what its hemisphere sees:

    G_i = sum_j F_ij b_j  ~  mean over n cosine rays from points of i of b(hit)

b_j = R_j H_j the light the patch a ray meets passes on, as solved (0 where the ray escapes or meets
a back side: the world's light is direct light, kept apart). G_i averages the solve's errors over every patch i
sees, so what is left is each patch's own sampling noise, independent from patch to patch, which
the noise filter takes out (its variance: the rays' sample variance over n).

The smooth display shows the two estimates of the same light combined by their variances (the
solve's batch-means variance v_s, the rays' v_g, each summed over the colour channels: one share
for the three, so that a patch keeps its colour): (v_g x_s + v_s x_g) / (v_s + v_g), given the
noise filter the variance v_s v_g / (v_s + v_g). Where the solve is sure (bright patches many paths
reached) it stands; where it is not (a dim wall lit by bounced light alone) the gather does. Patches
no camera sees (``PatchScene.hidden``) keep the solve's. Each source group's parts are gathered along
the same rays and combined with the same weights, so they add up to the whole's (relighting).

The combined variance is a guide for the filter, not a measured error: the gather also carries the
solve's errors averaged over what a patch sees, which v_g leaves out (where they are one error over
the whole scene, a total's, the gather keeps it whole). So the gather serves the smooth colours
alone: the solve's result, its error and the per-patch outputs stay as solved.

Rays: RAYS a patch, stratified over the hemisphere (an 8 x RAYS/8 grid of the cosine's uniforms),
from points drawn on the patch's visible part, BLOCK_RAYS at a time on the local threads; a block's
random numbers are its own (drawn from the seed and the block's index), so the bits are the same on
any number of threads.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..lights.sampling import cosine_directions, patch_point_rows
from ..methods.first_shot import trace
from ..methods.tables import FreeTurn, WalkTables
from ..names import EXIT_RANDOM, FINITE
from ..scene.threads import each_on_threads, local_thread_count

RAYS = 32  # cosine rays a patch
STRATA = 8  # ... stratified on an 8 x RAYS/8 grid of the direction's two uniforms
BLOCK_RAYS = 1 << 16  # rays traced at a time (a block of patches)
# Patches beyond which the gather is left out: at that many the patches are small beside what a
# camera sees (their blotches too), and its rays and per-source arrays would cost as much as the
# smoothing (the textured output's smooth colours stop there too: bpy_free options.SMOOTH_MAX_PATCHES).
MOST_PATCHES = 300_000
STREAM = 1 << 29  # the gather's random stream, apart from the solve's and the display's


def gathered(scene, result, rays=RAYS, seed=None):
    """``result`` (a SolveResult whose direct light is known apart: ``direct_irradiance``, of at most
    MOST_PATCHES patches) with its light arriving, reflected light and radiosity (and each group's, for
    a per-source solve) the solve's bounced light and the gather's combined by their variances (the
    module's docstring), its light's variance the combined one; else ``result`` as it is."""
    if result.direct_irradiance is None or not 0 < scene.patch_count <= MOST_PATCHES or rays < 2:
        return result
    ps = result.per_source
    grouped = ps is not None and ps.direct_irradiance is not None
    # (what each patch passes on, b = R H, as solved: unclipped, so that the gather is linear and the parts add up)
    parts = scene.reflectivity[None] * ps.irradiance if grouped else None
    bounced = parts.sum(axis=0) if grouped else scene.reflectivity * result.irradiance
    mean, variance, part_means = gather(scene, bounced, parts, rays, result.seed if seed is None else seed)
    solve = result.irradiance - result.direct_irradiance
    v_s = np.asarray(result.irradiance_variance, np.float64)
    weight = _solve_weight(v_s, variance, scene.hidden)
    light = result.direct_irradiance + weight * solve + (1.0 - weight) * mean
    combined = np.where(np.isfinite(v_s), weight * weight * v_s, 0.0) + (1.0 - weight) ** 2 * variance
    reflected = scene.reflectivity * light
    with np.errstate(over="ignore"):  # (light past float32's square root: its variance infinite, as the solve's)
        combined = combined.astype(np.asarray(result.irradiance_variance).dtype)
    out = replace(result, irradiance=light, irradiance_variance=combined, reflected=reflected,
                  reflected_variance=scene.reflectivity ** 2 * combined, radiosity=scene.emission + reflected)
    if grouped:
        part_solve = ps.irradiance - ps.direct_irradiance
        part_light = ps.direct_irradiance + weight * part_solve + (1.0 - weight) * part_means
        out.per_source = replace(ps, irradiance=part_light,
                                 radiosity=ps.radiosity + scene.reflectivity * (part_light - ps.irradiance))
    return out


def _solve_weight(v_s, v_g, hidden=None):
    """(P,1) the solve's share v_g / (v_s + v_g) of each patch's combined estimate, the variances
    summed over the channels (one share for the three: a share of its own each would shift a
    patch's colour towards whichever estimate is the surer in that channel, specks of the walls'
    colours): 0 where the solve measured no variance (fewer than two chunks), 1 on ``hidden``
    patches, a half where neither estimate varies."""
    finite = np.isfinite(v_s).all(axis=1)
    v_s = np.where(finite, np.nan_to_num(v_s, nan=0.0, posinf=0.0).sum(axis=1), 0.0)
    v_g = np.asarray(v_g, np.float64).sum(axis=1)
    total = v_s + v_g
    weight = np.divide(v_g, total, out=np.full_like(total, 0.5), where=total > 0)
    weight = np.where(finite, weight, 0.0)
    if hidden is not None:
        weight[np.asarray(hidden, bool)] = 1.0
    return weight[:, None]


def gather(scene, values, parts=None, rays=RAYS, seed=0):
    """((P,3) each patch's mean of ``values`` (P,3) at what its cosine rays meet (0: nothing, or a
    back side), (P,3) that mean's variance (the rays' sample variance over their count), (S,P,3) the
    same means of each of ``parts`` (S,P,3) along the same rays, or None)."""
    P = scene.patch_count
    tables = WalkTables(scene, FINITE, 1e-3, EXIT_RANDOM)
    per_block = max(1, BLOCK_RAYS // rays)
    blocks = [(start, min(P, start + per_block)) for start in range(0, P, per_block)]
    mean, variance = np.zeros((P, 3)), np.zeros((P, 3))
    part_means = None if parts is None else np.zeros((len(parts), P, 3))
    # (each thread traces with its own turn at numpy: the blocks' arrays are long, numpy lets go of the GIL)
    mine = tables if local_thread_count() == 1 or len(blocks) == 1 else tables.with_turn(FreeTurn())

    def block(k):
        start, stop = blocks[k]
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=(STREAM, k))))
        with mine.numpy_turn:
            hit = _cast(mine, scene.geometry, start, stop, rays, rng)
        met, seen = hit >= 0, np.maximum(hit, 0)
        for c in range(3):  # (a channel at a time: one (n,) array in flight)
            sample = np.where(met, values[seen, c], 0.0).reshape(stop - start, rays)
            mean[start:stop, c] = sample.mean(axis=1)
            variance[start:stop, c] = sample.var(axis=1, ddof=1) / rays
            for s in range(0 if parts is None else len(parts)):
                part_means[s, start:stop, c] = np.where(met, parts[s, seen, c], 0.0).reshape(stop - start, rays).mean(axis=1)

    each_on_threads(len(blocks), block)
    return mean, variance, part_means


def _cast(tables, g, start, stop, rays, rng):
    """(n,) the patch each of ``rays`` stratified cosine rays from points of each of the patches
    start..stop-1 meets on its front (-1: none), patch by patch."""
    patch = np.repeat(np.arange(start, stop, dtype=np.int32), rays)
    n = patch.size
    k = np.tile(np.arange(rays), stop - start)
    rows = max(1, rays // STRATA)
    u1 = ((k % STRATA + rng.random(n)) / STRATA).astype(np.float32)
    u2 = ((k // STRATA % rows + rng.random(n)) / rows).astype(np.float32)
    u = rng.random((3, n), dtype=np.float32)
    origins = patch_point_rows(g, patch, u[0], u[1], u[2])
    directions = np.ascontiguousarray(cosine_directions(g, patch, u1, u2).T)
    _, hit, front, _ = trace(tables, origins, directions, g.region_of(patch))
    return np.where(front, hit, -1)
