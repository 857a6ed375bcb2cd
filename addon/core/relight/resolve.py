"""A source group solved again alone (a lamp moved, reshaped, re-angled or added) on the same
patches, the other groups' results kept: the per-source results of the scene as it is now."""
from __future__ import annotations

import math

import numpy as np

from ..estimate.grouping import SourceGroups, check_per_source, source_groups
from ..estimate.per_source import PerSource, scene_scale
from ..settings import Settings
from ..solver import solve


def resolve(scene, per_source, names, settings=None, *, target_mse=None, **changes):
    """``per_source`` with the groups ``names`` re-solved on ``scene`` (a lamp moved, reshaped,
    re-angled or added: the scene as it is now, on the same patches) and the others kept as they
    are: a PerSource of the scene's groups (``settings.groups``, default ``source_groups(scene)``),
    in their order. The re-solve traces only the named groups' sources (every other light and
    emitting patch left out) with ``settings`` (a Settings, with ``changes`` by field; its target,
    or ``target_mse``, applies to the named groups' light alone); it is independent of
    the kept groups' run (give it a seed of its own), so their covariance is 0. A group of the
    solve the scene no longer has (a lamp deleted) is left out. ValueError in one line for a
    name the scene's groups do not have, a group the solve did not have that is not named, or
    other patches (geometry changed: solve again)."""
    settings = Settings.of(settings, **changes)
    groups = source_groups(scene) if settings.groups is None else settings.groups
    check_per_source(scene, groups)
    names = (names,) if isinstance(names, str) else tuple(names)
    unknown = [n for n in names if n not in groups.names]
    if unknown:
        raise ValueError(f"no source group named {', '.join(map(repr, unknown))}; "
                         f"the groups are {', '.join(map(repr, groups.names))}")
    if per_source.radiosity.shape[1] != scene.patch_count:
        raise ValueError(f"the per-source results are of {per_source.radiosity.shape[1]:,} patches, the scene has "
                         f"{scene.patch_count:,}: the geometry changed, solve again")
    missing = [n for n in groups.names if n not in names and n not in per_source.names]
    if missing:
        raise ValueError(f"source groups {', '.join(map(repr, missing))} are new: name them to be solved")
    new = [groups.names.index(n) for n in dict.fromkeys(names)]
    sub = _named_sources(scene, groups, new)
    if sub is None:  # the named groups give no light now: their results are nothing
        redone = _dark(scene.patch_count, len(new), per_source.covariance.shape[0])
    else:
        sub_scene, sub_groups = sub
        redone = solve(sub_scene, settings.but(per_source=True, groups=SourceGroups(*sub_groups)),
                       target_mse=target_mse).per_source
    return _joined(scene, groups, per_source, new, redone)


def _named_sources(scene, groups, new):
    """(a scene of only the groups ``new``'s sources, its SourceGroups' fields), or None where
    they give no power."""
    P = scene.patch_count
    local = np.full(groups.count, -1, np.int32)
    local[new] = np.arange(len(new), dtype=np.int32)
    own = groups.patch_group(P)
    patch_group = np.where(own >= 0, local.take(np.maximum(own, 0)), -1).astype(np.int32)
    emission = np.where((patch_group >= 0)[:, None], scene.emission, 0.0)
    light_group = local.take(groups.light_group) if len(groups.light_group) else np.zeros(0, np.int32)
    lights = [light for light, g in zip(scene.lights.lights, light_group) if g >= 0]
    power = emission.any() or any(np.any(light_power > 0) for light_power, g in
                                  zip(_light_powers(scene), light_group) if g >= 0)
    if not power:
        return None
    sub = scene.with_materials(scene.reflectivity, emission, lights)
    kept = light_group[light_group >= 0]
    light_sources = kept.take(sub.lights.light_of) if len(kept) else np.zeros(0, np.int32)
    source_group = np.concatenate([patch_group, light_sources])
    return sub, (tuple(groups.names[g] for g in new), source_group.astype(np.int32), kept.astype(np.int32))


def _light_powers(scene):
    """(L,3) each light's emitters' power summed."""
    out = np.zeros((len(scene.lights), 3))
    if len(scene.lights):
        np.add.at(out, scene.lights.light_of, scene.lights.power)
    return out


def _dark(P, S, C):
    """A PerSource of S groups that give no light."""
    zeros = np.zeros((S, P, 3))
    return PerSource(("",) * S, zeros, zeros.copy(), np.zeros((S, 3)), np.zeros((C, S, S)), math.nan,
                     lit_batches=np.zeros(S, np.int64), sampled_share=np.zeros(S))


def _joined(scene, groups, per_source, new, redone):
    """The PerSource of ``groups``: the rows ``new`` from ``redone``, the rest from ``per_source``."""
    S, P = groups.count, scene.patch_count
    source = {g: ("new", k) for k, g in enumerate(new)}
    source.update({g: ("old", per_source.names.index(n)) for g, n in enumerate(groups.names) if g not in source})
    C = max(per_source.covariance.shape[0], redone.covariance.shape[0])
    old_cov = np.broadcast_to(per_source.covariance, (C,) + per_source.covariance.shape[1:])
    new_cov = np.broadcast_to(redone.covariance, (C,) + redone.covariance.shape[1:])
    radiosity = np.empty((S, P, 3), per_source.radiosity.dtype)
    irradiance = np.empty((S, P, 3), per_source.irradiance.dtype)
    power = np.empty((S, 3))
    covariance = np.zeros((C, S, S))
    means = None if per_source.reflected_means is None or redone.reflected_means is None else np.empty((S, 3))
    counted = per_source.lit_batches is not None and per_source.sampled_share is not None
    lit, sampled = (np.zeros(S, np.int64), np.zeros(S)) if counted else (None, None)
    for g, (kind, k) in source.items():
        ps = redone if kind == "new" else per_source
        radiosity[g], irradiance[g], power[g] = ps.radiosity[k], ps.irradiance[k], ps.power[k]
        if means is not None:
            means[g] = ps.reflected_means[k]
        if counted:  # (each its own run's: a re-solved group's share is of the re-solve's samples)
            lit[g], sampled[g] = ps.lit_batches[k], ps.sampled_share[k]
        for h, (other, m) in source.items():
            if other == kind:  # (independent runs: no covariance across them)
                covariance[:, g, h] = (new_cov if kind == "new" else old_cov)[:, k, m]
    # (the target: the same relative error of the light as it is now, its power moved or not)
    return PerSource(groups.names, radiosity, irradiance, power, covariance, scene_scale(scene), per_source.target_error,
                     groups.patch_group(P).copy(), np.asarray(groups.light_group, np.int32), reflected_means=means,
                     lit_batches=lit, sampled_share=sampled)
