"""``radiosity.update``'s work (bpy): the stale sources' results solved again, and only theirs,
where a lamp moved, was reshaped or re-angled (core relight.resolve, on the same patches, the
other sources' results kept as they are); a full solve where the geometry changed, a lamp was
added, the solve's results are not in memory (a reopened file) or Detail refined the patches."""

from __future__ import annotations

import math
from dataclasses import replace

import bpy
import numpy as np

from ..blender_read import sources
from ..blender_read.selection import read_selection
from ..blender_write import relight_keep, relight_store, solve_job
from ..blender_write.results import write_results
from ..bpy_free import adaptive_patches, pipeline, relit
from ..bpy_free.settings import method_for, prediction_for
from ..bpy_free.patches import make_patches
from ..bpy_free.scene_notes import scene_and_notes
from ..core.estimate.per_source import group_power
from ..core.relight.resolve import resolve
from ..core.relight.relit_checks import REST_SHARE
from . import relight as relight_ui


def update(context):
    """Solves again what is stale; returns what it did, or ValueError in one line."""
    scene = context.scene
    meta = relight_store.meta_of(scene)
    outcome = relight_ui.assess(scene, meta)
    stale = sorted(outcome.outdated())
    if not stale and not outcome.added:
        return "nothing is stale: Relight follows strengths and colours without a solve"
    last = relight_keep.LAST.get(meta["token"])
    if sources.geometry_signature(scene, meta["solved"]) != meta["geometry"]:
        return _full(context, meta, "the geometry changed")
    if outcome.added:
        return _full(context, meta, f"{', '.join(outcome.added)} added")
    if last is None:
        return _full(context, meta, "the solve's results are not in memory (the file was reopened)")
    if last[1].detail != "OFF":  # (its patches came from the solve's own light: a lamp moved moves them)
        return _full(context, meta, f"Detail {last[1].detail.lower()} refines the patches from the light")
    return _partial(context, meta, stale, last, outcome)


def _select(context, meta):
    """The solved selection's objects (those still there), selected alone."""
    objects = [context.scene.objects[name] for name in meta["selected"] if name in context.scene.objects]
    if not objects:
        raise ValueError("the solved objects are gone: select objects and solve")
    for obj in context.view_layer.objects:
        obj.select_set(obj in objects)
    return objects


def _full(context, meta, why):
    _select(context, meta)
    finished = solve_job.run(context)
    if finished.status != "FINISHED":
        raise ValueError(finished.error or "the solve did not finish")
    said = next((text for kind, text in reversed(finished.messages) if kind == "INFO"), "")
    return f"solved again ({why})" + (f"; {said}" if said else "")


def resolve_target(outcome, scene, groups, stale, target):
    """The relative error a re-solve of the groups ``stale`` alone is held to, relative to their
    own light (the solve's ``target`` (None: a path count) is of the whole light): the error the
    whole light's target allows them, or, where the relight asks (a group relit past its share
    of the paths, or the light past the target), the relit target times the square root of the
    share the groups kept leave (REST_SHARE), so that the recombination meets it."""
    if target is None:
        return None
    error = outcome.error
    if (outcome.unmeasured or outcome.over_target) and error.target_relative_rms is not None:
        return math.sqrt(1.0 - REST_SHARE) * error.target_relative_rms
    power = group_power(scene, groups).mean(axis=1)
    share = power[[groups.names.index(name) for name in stale]].sum() / power.sum()
    return target / share if share > 0 else target


def _partial(context, meta, stale, last, outcome):
    """Re-solves the groups ``stale`` alone on the scene as it is (to ``resolve_target`` where the
    relight asks), keeps the others, writes."""
    scene = context.scene
    result, settings, patch_size = last
    _select(context, meta)
    objects, notes = read_selection(context)
    # (the patches a near surface partly covers split as the solve split them: the same patches)
    patches = adaptive_patches.covered(objects, make_patches(objects, patch_size, layers=True), layers=True)
    del objects
    core_scene, more = scene_and_notes(patches)
    groups = relit.groups_for(core_scene, patches, "ON", [])
    if list(groups.names) != list(meta["names"]):
        return _full(context, meta, "the sources changed")
    prediction, target = prediction_for(core_scene, settings)
    settings = method_for(core_scene, settings)
    # (a seed of its own: the re-solve is independent of the solve)
    core = settings.core(core_scene, seed=int(settings.seed) + 1,
                         target_error=resolve_target(outcome, core_scene, groups, stale, settings.core().target_error))
    per_source = resolve(core_scene, result.per_source, stale, core.but(groups=groups))
    total = per_source.radiosity.sum(axis=0)
    # (the smoothing's filter weights come from the solve's variances: the re-solved light's own are not kept)
    result = replace(result, per_source=per_source, radiosity=total, irradiance=per_source.irradiance.sum(axis=0),
                     reflected=total - core_scene.emission)
    out = pipeline.SolveOutput(patches, result, prediction, target, notes=notes + more,
                               settings_relative_rms=None if settings.paths else settings.relative_rms,
                               sources=pipeline.sources_text(core_scene))
    out.sources_out = relit.source_results(core_scene, patches, result, groups)
    pipeline.write_colours(out, core_scene, result, settings)
    relit.add_object_values(out, settings)
    created = write_results(context, out, settings.output, scene=scene)
    relight_keep.keep(scene, created, out, _snapshot(scene, meta, stale), settings)
    relight_ui.relight(scene)
    return f"{', '.join(stale)} solved again, the other sources' results kept"


def _snapshot(scene, meta, stale):
    """The strengths each group's results now hold: the solve's for the kept groups, today's
    for the re-solved ones."""
    now = sources.current(scene, [(m[0], m[1]) for group in meta["members"] for m in group])
    out = {}
    for name, group in zip(meta["names"], meta["members"]):
        for kind, member, _power, solved, signature in group:
            out[(kind, member)] = now[(kind, member)] if name in stale else (np.asarray(solved), signature)
    return out


class RADIOSITY_OT_update(bpy.types.Operator):
    """Solve again what is stale: the moved, reshaped or re-angled lamps' own results only where
    that is all that changed, else (geometry changed, a lamp added) a full solve"""

    bl_idname = "radiosity.update"
    bl_label = "Update"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        context.evaluated_depsgraph_get()
        try:
            message = update(context)
        except ValueError as exc:
            self.report({"ERROR"}, f"Radiosity: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Radiosity: {message}")
        return {"FINISHED"}


classes = (RADIOSITY_OT_update,)


register, unregister = bpy.utils.register_classes_factory(classes)
