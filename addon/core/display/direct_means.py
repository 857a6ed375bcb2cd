"""Each lamp's direct light on every patch as the display estimates it, in place of the solve's.

The solve gathers the direct light with shadow rays to sources chosen by power: a weak lamp
beside a sun whose power counts over the whole scene (a spot on a painting in a hall under a
skylight) gets a thousandth of the rays, and its patches' light comes out heavy-tailed, most
of them far below it (the painting at half its light, the error estimate none the wiser). The
display looks at a lamp from MEAN_SAMPLES stratified points a patch (``live_sources.live_means``,
no second round: a round taken only where the first was noisy keeps the patches whose first
missed a rare bright sample low). Where the solve kept each source group's direct light apart
(per-source results: ``PerSource.direct_irradiance``), every group of lamps alone (point, spot
and area lamps: no sun, world or emitting material, which the solve's choice serves) has its
direct light replaced by the display's; its light arriving, reflected light and radiosity
change by that difference (times the reflectivity), and so do the whole's.

The solve's own estimate of that light is then not in the result: the solve leaves it out of its
measured error (``replaced``: estimate.batches' Replaced) and holds the rest to the target less
REPLACED_SHARE of its MSE. The display's means are two independent halves, whose difference
measures their error; where it passes that share, more points (``measured_means``); it is added
to the result's measured error (docs/errors.md, "What the target is measured on").
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from types import SimpleNamespace

import numpy as np

from .live_sources import live_means
from ..estimate.batches import Replaced
from ..estimate.error_model import relative_rms_to_mse
from ..lights.lights import AreaLight, PointLight, WorldLight
from ..names import SCALE_PAPER

MEAN_SAMPLES = 32  # stratified points a patch, each a shadow ray to a lamp of the group (two halves)
# The share of the target's MSE left for the display's direct light's error: its points cost a
# shadow ray each, the solve's paths ten rays and more, so it is small (benchmarks/results/flat_speed.md).
REPLACED_SHARE = 0.1
MOST_SAMPLES = 16 * MEAN_SAMPLES  # a patch's points at most, where the halves ask for more


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


def lamp_means(made, seed=0, rows=None, spent=None, samples=MEAN_SAMPLES):
    """([K,]P,3) each group of lamps alone's direct light on every patch (or on ``rows``), from
    ``lamp_scene``'s ``made``: ``samples`` stratified points a patch, one round."""
    alone, their_group, lamps = made
    return live_means(alone, samples=samples, seed=seed, light_group=their_group,
                      patch_group=np.full(alone.patch_count, -1), groups=lamps.size, retries=0, rows=rows, spent=spent)


def replaced(scene, groups):
    """The Replaced of a per-source solve of ``groups`` (estimate.grouping.SourceGroups, or
    None): its groups of lamps alone, whose direct light ``corrected`` replaces; None if none."""
    if groups is None:
        return None
    lamps = lamp_groups(scene, SimpleNamespace(count=groups.count, light_group=groups.light_group,
                                               patch_group=groups.patch_group(scene.patch_count)))
    return Replaced(tuple(int(k) for k in lamps), REPLACED_SHARE) if lamps.size else None


@dataclass(frozen=True)
class FirstMeans:
    """``lamp_scene``'s ``made`` and the two halves (K,P,3) of ``measured_means``' first pair."""

    made: tuple
    halves: tuple


def first_means(scene, light_group, patch_group, count, seed=0):
    """The FirstMeans of the groups of lamps alone among ``count`` groups (``light_group`` (L,),
    ``patch_group`` (P,) or None, as ``lamp_scene`` takes them), or None where there are none:
    the first pair of ``measured_means``, which needs nothing of the solve and so can be made
    beside it."""
    made = lamp_scene(scene, light_group, patch_group, count)
    if made is None:
        return None
    return FirstMeans(made, _pair(made, seed, 0, MEAN_SAMPLES // 2))


def _pair(made, seed, k, half):
    """Pair ``k`` of ``measured_means``: two independent halves of ``half`` points a patch."""
    return tuple(lamp_means(made, seed=[int(seed), k, side], samples=half) for side in (0, 1))


def measured_means(scene, made, seed=0, target_mse=None, first=None):
    """((K,P,3) each group of lamps alone's direct light on every patch, the MSE it brings the
    result, weighted as the solve's measured MSE): two independent halves of MEAN_SAMPLES / 2
    points, whose difference d gives each patch's variance of their mean, d^2 / 4; where that
    MSE passes ``target_mse``, one more pair as large as it says is needed (MOST_SAMPLES in all
    at most), each pair weighing by its points. ``first``: the first pair's halves, made already
    (``first_means``)."""
    weight = scene.area_share
    total, points, mse, half = 0.0, 0, 0.0, MEAN_SAMPLES // 2
    for k in range(2):
        a, b = first if k == 0 and first is not None else _pair(made, seed, k, half)
        gap = scene.reflectivity * (a - b).sum(axis=0)  # (P,3) the two halves' difference in the reflected light
        pair_mse = float(np.einsum("p,pc->", weight, np.square(gap))) / (4 * gap.shape[1])
        total, points = total + half * (a + b), points + 2 * half
        mse += (2 * half) ** 2 * pair_mse  # (times the pair's share squared, below)
        needed = 2 * half * pair_mse / target_mse if target_mse else 0.0
        if k or not needed > points:  # (NaN: no target to hold to)
            break
        half = int(min(np.ceil(needed - points), MOST_SAMPLES - points) // 2)
        if half < 1:
            break
    return total / points, mse / points**2


def corrected(scene, result, target_error=None, first=None):
    """``result`` (a per-source SolveResult with its groups' direct light apart) with each lamp
    group's direct light the display's (the module's docstring) and its error added to the
    measured one, else as it is. ``target_error``: the solve's, of which the display's means keep
    to REPLACED_SHARE of the MSE. ``first``: ``first_means`` of the solve's groups and seed, made
    beside the solve (the same numbers as made here)."""
    ps = result.per_source
    if result.direct_irradiance is None or ps is None or ps.direct_irradiance is None or ps.light_group is None:
        return result
    made = lamp_scene(scene, ps.light_group, ps.patch_group, ps.count) if first is None else first.made
    if made is None:
        return result
    target = None
    if target_error:
        target = REPLACED_SHARE * (relative_rms_to_mse(result.prediction, target_error) if result.error_scale == SCALE_PAPER
                                   else (target_error * result.mean_reflected) ** 2)
    means, mse = measured_means(scene, made, result.seed, target, None if first is None else first.halves)
    parts = np.zeros_like(ps.direct_irradiance)
    parts[made[2]] = means - ps.direct_irradiance[made[2]]
    change = parts.sum(axis=0)
    reflected = result.reflected + scene.reflectivity * change
    out = replace(result, irradiance=result.irradiance + change, reflected=reflected, radiosity=scene.emission + reflected,
                  direct_irradiance=result.direct_irradiance + change, measured_mse=result.measured_mse + mse)
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


def corner_sources_means(scene, result):
    """(P,3) each patch's mean of the direct light its corners show (every lamp, sun and emitting
    patch: the world's stays smooth), as the solve or the display's means have it
    (``SolveResult.direct_irradiance``, a per-source run's groups but the world's), or None where it is
    not known apart from the world's."""
    worlds = [k for k, light in enumerate(scene.lights.lights) if isinstance(light, WorldLight)]
    ps = result.per_source
    if ps is not None and ps.direct_irradiance is not None and ps.light_group is not None:
        keep = np.ones(ps.count, bool)
        keep[np.asarray(ps.light_group, np.int64)[worlds]] = False
        return ps.direct_irradiance[keep].sum(axis=0)
    if result.direct_irradiance is None or worlds:
        return None
    return result.direct_irradiance
