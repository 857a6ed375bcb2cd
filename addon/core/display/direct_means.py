"""Each lamp's direct light on every patch as the display estimates it, in place of the solve's.

The solve gathers the direct light with shadow rays to sources chosen by power: a weak lamp
beside a sun whose power counts over the whole scene (a spot on a painting in a hall under a
skylight) gets a thousandth of the rays, and its patches' light comes out heavy-tailed, most
of them far below it (the painting at half its light, the error estimate none the wiser). The
display looks at a lamp from MEAN_SAMPLES stratified points a patch (``point_direct.live_means``,
no second round: a round taken only where the first was noisy keeps the patches whose first
missed a rare bright sample low). Where the solve kept each source group's direct light apart
(per-source results: ``PerSource.direct_irradiance``), every group of lamps alone (point, spot
and area lamps: no sun, world or emitting material, which the solve's choice serves) has its
direct light replaced by the display's; its light arriving, reflected light and radiosity
change by that difference (times the reflectivity), and so do the whole's.
"""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from .point_direct import live_means
from ..lights.lights import AreaLight, PointLight

MEAN_SAMPLES = 32  # stratified points a patch, each a shadow ray to a lamp of the group


def lamp_groups(scene, per_source):
    """(K,) the source groups of ``per_source`` made of point, spot and area lamps alone."""
    lights = scene.lights.lights
    kinds = np.zeros(per_source.count, np.int8)  # 1: a lamp in it, 2: anything else
    for light, group in zip(lights, per_source.light_group):
        kinds[group] |= 1 if isinstance(light, (PointLight, AreaLight)) else 2
    if per_source.patch_group is not None:
        emitting = np.asarray(per_source.patch_group)
        kinds[np.unique(emitting[emitting >= 0])] |= 2
    return np.flatnonzero(kinds == 1)


def lamp_scene(scene, light_group, patch_group, count):
    """(the scene with the lamps of the groups of lamps alone as its only lights and no emission,
    sharing its geometry; (L',) each such lamp's group among them; (K,) those groups), for
    ``light_group`` (L,) ``patch_group`` (P,) or None of ``count`` groups; None where no group
    is lamps alone."""
    lamps = lamp_groups(scene, SimpleNamespace(count=count, light_group=light_group, patch_group=patch_group))
    if not lamps.size:
        return None
    mine = np.flatnonzero(np.isin(light_group, lamps))
    alone = scene.with_materials(scene.reflectivity, np.zeros_like(scene.emission),
                                 lights=[scene.lights.lights[k] for k in mine])
    return alone, np.searchsorted(lamps, np.asarray(light_group)[mine]), lamps


def lamp_means(made, seed=0, rows=None, spent=None):
    """([K,]P,3) each group of lamps alone's direct light on every patch (or on ``rows``), from
    ``lamp_scene``'s ``made``: MEAN_SAMPLES stratified points a patch, one round."""
    alone, their_group, lamps = made
    return live_means(alone, samples=MEAN_SAMPLES, seed=seed, light_group=their_group,
                      patch_group=np.full(alone.patch_count, -1), groups=lamps.size, retries=0, rows=rows, spent=spent)


def corrected(scene, result):
    """``result`` (a per-source SolveResult with its groups' direct light apart) with each lamp
    group's direct light the display's (the module's docstring), else as it is."""
    ps = result.per_source
    if result.direct_irradiance is None or ps is None or ps.direct_irradiance is None or ps.light_group is None:
        return result
    made = lamp_scene(scene, ps.light_group, ps.patch_group, ps.count)
    if made is None:
        return result
    parts = np.zeros_like(ps.direct_irradiance)
    parts[made[2]] = lamp_means(made, seed=result.seed) - ps.direct_irradiance[made[2]]
    change = parts.sum(axis=0)
    reflected = result.reflected + scene.reflectivity * change
    out = replace(result, irradiance=result.irradiance + change, reflected=reflected, radiosity=scene.emission + reflected,
                  direct_irradiance=result.direct_irradiance + change)
    out.per_source = replace(ps, irradiance=ps.irradiance + parts, radiosity=ps.radiosity + scene.reflectivity * parts,
                             direct_irradiance=ps.direct_irradiance + parts)
    return out

def arriving(surface, scene, result, live=False):
    """(P,3) the light arriving shown for a ``result`` whose direct part is known: its indirect
    part noise-filtered (``Surface.arriving_light``, within the solve's measured variance, which
    is the solve's noise), and the direct part added after, as it is (the display's own:
    ``corrected``), unless ``live`` (the renderer draws it)."""
    direct = result.direct_irradiance
    light = surface.arriving_light(result.irradiance - direct, result.irradiance_variance, scene.reflectivity)
    return light if live else light + direct


def reflected(surface, scene, result):
    """(P,3) the reflected light shown for a ``result`` whose direct part is known: its indirect
    part noise-filtered (``Surface.filter_light``), the direct part's reflection added after."""
    direct = scene.reflectivity * result.direct_irradiance
    out = surface.filter_light(result.reflected - direct, result.reflected_variance)
    out += direct
    return out
