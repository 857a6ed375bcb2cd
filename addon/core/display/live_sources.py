"""The light a renderer draws live: with Live lamps the renderer draws the lamps', suns', emitting
materials' and the world's own light pixel by pixel, and the results show the light arriving less
each patch's mean of it (``arriving``); EEVEE draws the lamps' and suns' alone (``lamp_part``).
"""
from __future__ import annotations

import numpy as np

from .direct_points import SAMPLE_DIMENSIONS, Points
from ..lights.lamp_choice import patch_spheres
from ..lights.lights import WorldLight
from ..names import EXIT_RANDOM, FINITE
from .point_direct import MORE_SAMPLES, NOISE_SHARE, RETRIES, has_lamps, light_sources
from .sample_rounds import Part, rounds, sampled
from ..methods.tables import WalkTables

LIVE_MEAN_SAMPLES = 64  # points a patch for its mean of the live light (live_means), before the noisy ones' again


def has_live(scene):
    """Whether ``scene`` has light a renderer draws live (``live_means``): a lamp, a sun, an
    emitting patch or the world."""
    return bool(scene.emission.any()) or bool(scene.lights.lights)


def draws_highlights(scene):
    """Whether EEVEE draws highlights of ``scene``'s lamps on its results (``lamp_part``'s light
    is then kept apart): a lamp or a sun, and a glossy layer (``scene.glossy``) to reflect it."""
    return has_lamps(scene) and scene.glossy is not None


def lamp_part(scene, drawn, light_group=None, patch_group=None, groups=0, seed=0, light=None, deadline=None):
    """([G,]P,3) the lamps' and suns' part of ``drawn`` ([G,]P,3, the live light, ``live_light``
    or the groups' own): what EEVEE draws live too (it draws neither emitting meshes nor, from
    ``blender_write``'s world, the sky). A group whose live light is its lamps' alone gives all of
    its row, one without lamps none; a group of both (one Blender light group of a lamp and an
    emissive material) its lamps' ``live_means`` (within ``deadline``)."""
    P = scene.patch_count
    rows = max(groups, 1)
    group_of = (lambda g: np.asarray(g, np.int64)) if groups else (lambda g: np.zeros(len(g), np.int64))
    lights = scene.lights.lights
    kinds = np.array([not isinstance(light, WorldLight) for light in lights], bool)
    of_light = group_of(light_group if groups else np.zeros(len(lights)))
    lamps = np.bincount(of_light[kinds], minlength=rows) > 0
    others = np.bincount(of_light[~kinds], minlength=rows) > 0
    emitting = np.flatnonzero(scene.emission.any(axis=1))
    if emitting.size:
        others |= np.bincount(group_of(patch_group[emitting] if groups else emitting), minlength=rows) > 0
    shaped = np.asarray(drawn, np.float64).reshape(rows, P, 3)
    out = np.where(lamps[:, None, None], shaped, 0.0)
    both = np.flatnonzero(lamps & others)
    if both.size:
        means = live_means(scene, seed=seed, light=light, light_group=light_group, patch_group=patch_group,
                           groups=groups, deadline=deadline, lamps_only=True).reshape(rows, P, 3)
        out[both] = means[both]
    return out if groups else out[0]


def arriving(surface, scene, result, live=False, deadline=None, drawn=None):
    """(P,3) the light arriving (``Surface.arriving_light``: noise filtered); ``live``: less
    the lamps', suns', emitting patches' and world's (``drawn``, else ``live_light`` within
    ``deadline``), which the renderer draws itself."""
    if live and drawn is None:
        drawn = live_light(scene, result, deadline)
    irradiance = result.irradiance - drawn if live else result.irradiance
    return surface.arriving_light(irradiance, result.irradiance_variance, scene.reflectivity)


def live_light(scene, result, deadline=None):
    """(P,3) each patch's mean of the light a renderer draws live (every source's direct light):
    the solve's own, where its chunks gathered it apart (``SolveResult.direct_irradiance``: what
    is left of the total is then the reflected light with its own noise alone), else
    ``live_means`` (within ``deadline``), an estimate of its own (the light left carries the noise of both)."""
    if result.direct_irradiance is not None:
        return result.direct_irradiance
    return live_means(scene, seed=result.seed, light=result.irradiance, deadline=deadline)


def live_means(scene, samples=LIVE_MEAN_SAMPLES, seed=0, light=None, light_group=None, patch_group=None, groups=0,
               deadline=None, spent=None, rows=None, retries=RETRIES, lamps_only=False):
    """([G,]P,3) each patch's mean of the light a renderer draws live where the lamps, suns,
    emitting materials and the world light the surfaces themselves (``LIVE`` results): their
    direct light, from ``samples`` stratified points over the patch's visible part, every lamp
    and emitting group looked at from each (the world along one cosine ray). A patch whose mean's standard error passes NOISE_SHARE of its solved
    ``light`` (P,3), or of the mean itself, is sampled again with MORE_SAMPLES times as many
    points, RETRIES times (beside an emitter the light is heavy-tailed), within ``deadline``.
    Given ``groups`` > 0, ``light_group`` (L,) and ``patch_group`` (P,): each group's
    (``corner_direct``). ``rows``: those patches' alone, (n,3) (a pilot's); ``retries``: RETRIES, or 0 (unbiased);
    ``lamps_only``: the lamps' and suns' light alone (``lamp_part``)."""
    tables = WalkTables(scene, FINITE, 1e-3, EXIT_RANDOM)
    rows = np.arange(scene.patch_count) if rows is None else np.asarray(rows, np.int64)
    out = np.zeros((max(groups, 1), len(rows), 3))
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(1 << 27,))))
    spheres = patch_spheres(scene) if has_lamps(scene) else None
    sources = light_sources(scene, light_group, patch_group, groups, sky=not lamps_only, lamps_only=lamps_only)
    with tables.numpy_turn:
        parts = [_means_of(tables, rows, rng, add, None if light is None else light[rows], spheres, paired)
                 for _, add, paired in sources]
        means = rounds(parts, len(rows), samples, retries, MORE_SAMPLES, deadline, spent)
    for (group, _, _), mean in zip(sources, means):
        out[group] += mean
    return out if groups else out[0]


def _means_of(tables, patches, rng, add, light, spheres, paired=False):
    """The ``sample_rounds.Part`` of one source's mean light over each of ``patches``
    (``live_means``); ``spheres`` (``lamp_choice.patch_spheres``) the patches' anchors where
    lamps are chosen."""
    g = tables.geometry

    def points(rows, local, u):
        anchor = None if spheres is None else (spheres[0][rows], g.patch_normal_rows.take(rows, axis=1).T.astype(
            np.float64), spheres[1][rows])
        return Points(g, rows[local], u, anchor, local)

    def sample(rows, count):
        rows = patches[rows]
        return sampled(tables, len(rows), count, rng, add, lambda block, local, u: points(rows[block], local, u),
                       SAMPLE_DIMENSIONS, paired=paired)

    def noise(mean, error):
        shown_light = mean.sum(axis=1) if light is None else np.maximum(light.sum(axis=1), mean.sum(axis=1))
        allowed = NOISE_SHARE * shown_light
        return np.divide(error, allowed, out=np.where(error > 0, np.inf, 0.0), where=allowed > 0)

    return Part(sample, noise)
