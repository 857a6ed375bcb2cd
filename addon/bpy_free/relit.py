"""Per-source results on the Blender side: the groups a solve keeps apart (Blender's light
groups where the scene uses them, else each lamp, the world and each emissive material), each
group's outputs per result object, and their recombination with new strengths and colours.

A result object keeps, per group, the values its outputs are made of ("flat": each patch's
radiosity, "irradiance": each patch's light arriving, "smooth" and "light": the smooth
radiosity and light arriving at every polygon corner; with live lamps "bounced" and
"bounced_irradiance", the light arriving less what the renderer draws live, and "lampless" and
"lampless_irradiance", it less the lamps' alone, which EEVEE draws); an output is the sum of its groups'
values times their weights, so relighting is one pass over them and traces no ray. No bpy.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import partial

import numpy as np

from ..core.display import live_sources, smoothing
from ..core.display.covered import seen_parts
from ..core.estimate.grouping import PER_SOURCE_MAX, source_groups
from ..core.lights.lights import WorldLight
from ..core.estimate.per_source import PerSource
from ..core.relight.relighting import relight, smooth_sources
from . import shown_mesh

# Automatic keeps per-source results from 2 up to this many sources: the walks' solves then cost
# 1.13-1.3x, the two-way iteration's 1.3x at 4 (benchmarks/results/relight.md); more cost more.
# (One source: the solve's memory alone; On keeps them.)
AUTO_MAX_SOURCES = 8
AUTO_MAX_SIZE = PER_SOURCE_MAX // 8  # patches x sources: the .blend and the relight's memory keep them too


def groups_for(scene, patches, choice, notes):
    """The SourceGroups for the setting ``choice`` (AUTO, ON, OFF), or None (Automatic says why
    in ``notes``): emissive patches by their object's light group, else their material; lights
    by theirs, else each its own."""
    if choice == "OFF":
        return None
    labels = patch_labels(patches)
    light_labels = list(patches.light_labels) if patches.light_labels else None
    groups = source_groups(scene, labels, light_labels)
    size = scene.patch_count * groups.count
    if choice == "AUTO" and groups.count < 2:
        return None
    if choice == "AUTO" and (groups.count > AUTO_MAX_SOURCES or size > AUTO_MAX_SIZE):
        notes.append(f"per-light results left out: {groups.count} sources x {scene.patch_count:,} patches (Automatic "
                     f"keeps them up to {AUTO_MAX_SOURCES} sources and {AUTO_MAX_SIZE:,} patches x sources); "
                     "put lamps in light groups or set Per-light results to On")
        return None
    return groups


def measured_choice_groups(groups):
    """The groups Automatic's method choice measures with (the core's pilots of both methods), or
    None: only beyond AUTO_MAX_SOURCES, where the two-way iteration's per-source cost grows past
    the walk's; within it the pilots took more time than they saved (docs/relighting.md)."""
    return groups if groups is not None and groups.count > AUTO_MAX_SOURCES else None


def patch_labels(patches):
    """(P,) object: each patch's group label, its object's light group or else its material
    (None for patches made without their materials' names: by emittance)."""
    if patches.patch_material is None:
        return None
    labels = np.array(patches.material_names, dtype=object)[patches.patch_material]
    for k, group in enumerate(patches.object_lightgroups):
        if group:
            labels[patches.combined.patch_slice(k)] = group
    return labels


def members_of(scene, groups):
    """Each group's lights {(kind, name): power (3,) at the solve's strengths} (kind: light or
    world); ``_material_members`` adds the emissive materials."""
    members = [dict() for _ in range(groups.count)]
    power = scene.source_power
    P = scene.patch_count
    lights = scene.lights
    light_power = np.zeros((len(lights), 3))
    if len(lights):
        np.add.at(light_power, lights.light_of, power[P:])
    for k, light in enumerate(lights.lights):
        kind = "world" if isinstance(light, WorldLight) else "light"
        members[groups.light_group[k]][(kind, light.name)] = light_power[k]
    return members


def _material_members(members, groups, scene, patch_material):
    """Adds each group's emissive materials and their power (A E summed over their patches)."""
    patch_group = groups.patch_group(scene.patch_count)
    emitting = np.flatnonzero(patch_group >= 0)
    power = scene.source_power[: scene.patch_count]
    for group, material in set(zip(patch_group[emitting].tolist(), patch_material[emitting].tolist())):
        rows = emitting[(patch_group[emitting] == group) & (patch_material[emitting] == material)]
        members[group][("material", str(material))] = power[rows].sum(axis=0)


@dataclass
class SourceResults:
    """What a per-source solve leaves for relighting: the groups' names and ``members`` (per group
    [(kind, name, power (3,))]), the core's PerSource (the error's covariance), and per object
    {kind: (S,n,3) float32} (None for an object that gets no result)."""

    per_source: PerSource
    groups: object
    members: list
    arrays: list = field(default_factory=list)
    targets: list = field(default_factory=list)
    smooth: dict = field(default_factory=dict)  # (while the outputs are made) kind -> per object (S,C_k,3)
    drawn: object = None  # (S,P,3) each group's light the renderer draws live, where flat bounced light is written
    lamps: object = None  # (S,P,3) the lamps' and suns' part of it (EEVEE's), where flat lampless light is written

    @property
    def names(self):
        return self.per_source.names

    def meta(self):
        """The numbers relighting needs besides the arrays, as JSON-ready values."""
        ps = self.per_source
        return {"names": list(ps.names),
                "members": [[[kind, name, [float(x) for x in p]] for kind, name, p in group] for group in self.members],
                "power": ps.power.tolist(), "covariance": ps.covariance.tolist(),  # (NaN below 2 chunks: JSON's NaN)
                "scale": float(ps.scale), "target_error": ps.target_error,
                "reflected_means": None if ps.reflected_means is None else ps.reflected_means.tolist(),
                "lit_batches": None if ps.lit_batches is None else ps.lit_batches.tolist(),
                "sampled_share": None if ps.sampled_share is None else ps.sampled_share.tolist()}


def source_results(scene, patches, result, groups):
    """The SourceResults of a per-source ``result`` (its arrays filled by ``add_object_values``)."""
    members = members_of(scene, groups)
    if patches.patch_material is not None:
        _material_members(members, groups, scene, np.array(patches.material_names, dtype=object)[patches.patch_material])
    listed = [[(kind, name, power) for (kind, name), power in group.items()] for group in members]
    return SourceResults(result.per_source, groups, listed)


def source_corners(scene, result, light=False, shading=None, live=False, deadline=None, surface=None, direct=None,
                   display=None):
    """Like smooth_colours.smooth_corners for a per-source ``result``: with ``light`` and ``live`` the live
    parts, then ("light", (S,T,3,3)) with ``light``, then ("smooth", (S,T,3,3)): each group's smooth values, the total's noise-filter
    weights, clips and corner scales held (core relighting.smooth_sources), adding up to the
    total's; on the ``shading`` triangles (a refined mesh's) where given; the direct light's
    retries within ``deadline``."""
    triangles, triangle_patch = shading if shading is not None else (scene.triangles, scene.triangle_patch)
    if surface is None:
        surface = smoothing.Surface.of(scene.vertices, triangles, triangle_patch, scene.patch_count,
                                       **seen_parts(scene, triangles, triangle_patch))
    yield from smooth_sources(surface, scene, result, light, triangles=triangles, live=live, deadline=deadline,
                              direct=direct, display=display)


def drawn_light(out, scene, result, deadline=None):
    """(P,3) each patch's mean of the light the renderer draws live (``live_sources.live_light``);
    for a per-source solve the sum of each group's, which ``out.sources_out.drawn`` keeps (the
    groups' flat bounced light then adds up to the whole's)."""
    if out.sources_out is None:
        return live_sources.live_light(scene, result, deadline)
    ps = result.per_source
    drawn = ps.direct_irradiance
    if drawn is None:
        drawn = live_sources.live_means(scene, seed=result.seed, light=result.irradiance, light_group=ps.light_group,
                                        patch_group=ps.patch_group, groups=ps.count, deadline=deadline)
    out.sources_out.drawn = drawn
    return drawn.sum(axis=0)


def lamp_light(out, scene, result, drawn, deadline=None):
    """(P,3) the lamps' and suns' part of ``drawn`` (``drawn_light``'s: what EEVEE draws live,
    ``live_sources.lamp_part``); for a per-source solve the sum of each group's, which
    ``out.sources_out.lamps`` keeps."""
    if out.sources_out is None:
        return live_sources.lamp_part(scene, drawn, seed=result.seed, light=result.irradiance, deadline=deadline)
    ps = result.per_source
    lamps = live_sources.lamp_part(scene, out.sources_out.drawn, ps.light_group, ps.patch_group, ps.count, result.seed,
                                   result.irradiance, deadline)
    out.sources_out.lamps = lamps
    return lamps.sum(axis=0)


def weights(meta, current):
    """(S,3) each group's weight: its members' current emission over their solved one, per
    channel, their solved powers weighting them; ``current`` maps (kind, name) -> (emission now
    (3,), emission solved (3,)) (a member missing: 0). Also the channels that cannot be relit
    (a channel solved at 0 and lit now) as a set of group names."""
    out = np.zeros((len(meta["names"]), 3))
    unsolved = set()
    for s, group in enumerate(meta["members"]):
        total = np.zeros(3)
        for kind, name, power, *_ in group:
            now, solved = current.get((kind, name), (np.zeros(3), np.ones(3)))
            now, solved, power = (np.asarray(x, np.float64) for x in (now, solved, power))
            ratio = np.divide(now, solved, out=np.zeros(3), where=solved > 0)
            if ((solved <= 0) & (now > 0)).any():
                unsolved.add(meta["names"][s])
            out[s] += power * ratio
            total += power
        out[s] = np.divide(out[s], total, out=np.zeros(3), where=total > 0)
    return out, unsolved


def relit_error(meta, w):
    """The core's Relit of no patches (its error numbers) for weights ``w`` (S,3)."""
    S = len(meta["names"])
    covariance = np.asarray(meta["covariance"], np.float64)
    empty = np.zeros((S, 0, 3))
    # (None: the paper's b_ave, and no group's batches checked, as in results saved before them)
    means, lit, share = (meta.get(key) for key in ("reflected_means", "lit_batches", "sampled_share"))
    power = np.asarray(meta["power"], np.float64)
    ps = PerSource(tuple(meta["names"]), empty, empty, power, covariance,
                   float(meta["scale"]), _target_error(meta, power), reflected_means=None if means is None else np.asarray(means, np.float64),
                   lit_batches=None if lit is None else np.asarray(lit, np.int64),
                   sampled_share=None if share is None else np.asarray(share, np.float64))
    return relight(ps, w)


def _target_error(meta, power):
    """The solve's relative error target kept in ``meta`` (files saved before it was kept so kept
    the paper's MSE: relative to b_ave, the scale times the power)."""
    if "target_error" in meta or meta.get("target_mse") is None:
        return meta.get("target_error")
    return math.sqrt(meta["target_mse"]) / (float(meta["scale"]) * float(power.sum(axis=0).mean()))


def error_text(relit):
    """The relit error line, e.g. "relit: error 1.3% (the solve's target 1% applies to the solved
    strengths)"; past the target it says so."""
    if relit.unmeasured:
        its = "its" if len(relit.unmeasured) == 1 else "their"
        return (f"relit: error unknown: {', '.join(relit.unmeasured)} had too few of the solve's paths ({its} light in "
                f"fewer than 2 batches) for {its} share of the light now")
    if relit.dark:
        return "relit: no light reflected at these strengths (no error to give)"
    if not math.isfinite(relit.relative_rms):
        return "relit: error unknown (the solve had fewer than 2 batches)"
    text = f"relit: error {relit.relative_rms * 100:.3g}%"
    if relit.target_relative_rms is None:
        return text
    target = relit.target_relative_rms * 100
    if relit.past_target:
        return text + f", past the solve's {target:.2g}% target (it applies to the solved strengths): Update or solve again"
    return text + f" (the solve's target {target:.2g}% applies to the solved strengths)"


class SmoothSources:
    """The smooth outputs of a per-source solve: ``corners`` yields the totals as
    smooth_colours.smooth_corners does (the groups' sum, so that relighting at the solved strengths
    gives the picture the solve wrote) and keeps each group's at the objects' polygon corners."""

    def __init__(self, out, at_polygon_corners):
        self.out, self.at_polygon_corners = out, at_polygon_corners

    def corners(self, scene, result, light=False, shading=None, live=False, deadline=None, surface=None, direct=None,
                display=None):
        results = self.out.sources_out
        for name, per_group in source_corners(scene, result, light, shading, live, deadline, surface, direct, display):
            per_object = [self.at_polygon_corners(self.out, scene, corners, shading) for corners in per_group]
            results.smooth[name] = [None if parts[0] is None else np.stack(parts) for parts in zip(*per_object)]
            yield name, per_group.sum(axis=0)
            del per_group


def add_object_values(out, settings):
    """Fills ``out.sources_out.arrays``: per receiving object {kind: (S,n,3) float32} for the
    outputs ``out`` writes, and ``targets``: (attribute, kind, domain) each output is made of."""
    results = out.sources_out
    if results is None:
        return
    ps, patches = results.per_source, out.patches
    results.targets = output_targets(settings, out)
    kinds = {kind for _, kind, _ in results.targets}
    for k, o in enumerate(patches.objects):
        if not o.receives:
            results.arrays.append(None)
            continue
        rows = patches.combined.patch_slice(k)
        polygon = partial(shown_mesh.per_polygon, out, k)  # (per polygon of the mesh written)
        values = {"flat": polygon(ps.radiosity[:, rows]).astype(np.float32)}
        if "irradiance" in kinds or "irradiance_point" in kinds:
            values["irradiance"] = polygon(ps.irradiance[:, rows]).astype(np.float32)
        if "bounced_irradiance" in kinds:
            values["bounced_irradiance"] = polygon(ps.irradiance[:, rows] - results.drawn[:, rows]).astype(np.float32)
        if "lampless_irradiance" in kinds:
            values["lampless_irradiance"] = polygon(ps.irradiance[:, rows] - results.lamps[:, rows]).astype(np.float32)
        if "irradiance_point" in kinds:
            from ..core.mesh import meshing

            values["irradiance_point"] = np.stack([meshing.point_average(shown_mesh.mesh_of(out, k), h).astype(np.float32)
                                                   for h in values.pop("irradiance")])
        for name, per_object in results.smooth.items():
            values[name] = per_object[k]
        results.arrays.append(values)
    results.smooth = {}


def output_targets(settings, out):
    """[(attribute, kind, domain)]: which stored values make each output the run writes
    (domain FACE_CORNERS: a patch's value on its polygon's corners)."""
    smooth_made = any(c is not None for c in out.smooth_colours)
    output = settings.output
    smooth = output == "VERTEX" or (output in ("BOTH", "TEXTURED") and smooth_made)
    targets = [("Radiosity", "smooth", "CORNER")] if smooth else []
    if output in ("FACE", "BOTH", "TEXTURED"):
        targets.append(("Radiosity Patches" if smooth else "Radiosity", "flat", "FACE_CORNERS"))
    if output == "TEXTURED":
        corner = out.light_domain == "CORNER"
        targets.append(("Radiosity Light", "light" if corner else "irradiance", "CORNER" if corner else "FACE"))
        if out.live_lamps:
            targets.append(("Radiosity Bounced Light", "bounced" if corner else "bounced_irradiance",
                            "CORNER" if corner else "FACE"))
        if out.live_lamps and any(c is not None for c in out.lampless_colours):
            targets.append(("Radiosity Light Less Lamps", "lampless" if corner else "lampless_irradiance",
                            "CORNER" if corner else "FACE"))
    elif settings.light_output:
        targets.append(("Radiosity Light", "irradiance_point" if output == "VERTEX" else "irradiance",
                        "POINT" if output == "VERTEX" else "FACE_CORNERS"))
    return targets
