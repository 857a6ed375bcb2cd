"""Relighting in Blender: ``radiosity.relight`` recombines the stored per-source results with
the sources' current strengths and colours (no ray traced), live from a depsgraph handler;
the panel's list of sources (bpy); ``relight_update`` re-solves what is stale."""

from __future__ import annotations

import time

import bpy
import numpy as np
from bpy.app.handlers import persistent

from ..blender_read import sources
from ..blender_write import relight_store
from ..blender_write.materials import LIVE_EMITS_PROPERTY, TEXTURED_PROPERTY, follow_emission, is_textured_material
from ..bpy_free import relit
from . import handlers

LIVE_DELAY = 0.02  # seconds: changes that come together (a slider drag) relight once
_STATE = {"pending": False, "seconds": 0.0, "generation": 0, "panel": (None, None)}


class Relit:
    """One relight's outcome: the weights (S,3), the core's error numbers, each group's state and
    share of the light, the groups that need an Update (moved or reshaped: ``stale``; a channel
    solved dark lit now: ``unsolved``; too few of the solve's paths for their share now, their
    error unknown: ``unmeasured``; the ones whose error puts the relit light past the solve's
    target: ``over_target``) and the light the solve did not have (``added``: lamps, emitting
    materials and objects, the world)."""

    def __init__(self, meta, w, error, stale, added, unsolved):
        self.meta, self.weights, self.error, self.stale, self.added = meta, w, error, stale, added
        self.unsolved, self.unmeasured, self.over_target = unsolved, set(error.unmeasured), set(error.over_target)
        power = (w * np.asarray(meta["power"], np.float64)).sum(axis=1)
        self.shares = power / power.sum() if power.sum() > 0 else np.zeros(len(power))

    def outdated(self):
        """The groups whose results an Update solves again."""
        return self.stale | self.unsolved | self.unmeasured | self.over_target

    def state(self, s):
        if self.meta["names"][s] in self.outdated():
            return "stale"
        return "current" if np.allclose(self.weights[s], 1.0, rtol=1e-6, atol=0) else "relit"

    def text(self):
        line = relit.error_text(self.error)
        if self.added:
            line += f"; {', '.join(self.added)} added since the solve: Update solves again"
        elif self.outdated():
            line += f"; stale: {', '.join(sorted(self.outdated()))} (Update)"
        return line


def assess(scene, meta=None):
    """The Relit of the scene's stored per-source results with its sources as they are now;
    ValueError in one line where there are none."""
    meta = meta if meta is not None else relight_store.meta_of(scene)
    if meta is None:
        raise ValueError("no per-light results to relight: solve with Per-light results On or Automatic first")
    members = [(m[0], m[1]) for group in meta["members"] for m in group]
    now = sources.current(scene, members)
    pairs, stale = {}, set()
    for s, group in enumerate(meta["members"]):
        for kind, name, _power, solved, signature in group:
            emission, sign = now[(kind, name)]
            pairs[(kind, name)] = (np.zeros(3) if emission is None else emission, solved)
            if sign is not None and signature is not None and sign != signature:
                stale.add(meta["names"][s])
    if sources.geometry_signature(scene, meta["solved"]) != meta["geometry"]:
        stale = set(meta["names"])
    known = {name for kind, name in members if kind == "light"}
    rest_of_scene = bool(getattr(getattr(scene, "radiosity", None), "use_scene_objects", False))
    added = sources.added_lamps(scene, known) + sources.new_light(scene, members, meta["solved"], rest_of_scene)
    w, unsolved = relit.weights(meta, pairs)
    return Relit(meta, w, relit.relit_error(meta, w), stale, added, unsolved)


def relight(scene):
    """Recombines every stored output with the sources' current strengths and colours; returns
    the Relit. ValueError in one line (nothing written) where the results are missing."""
    meta = relight_store.meta_of(scene)
    outcome = assess(scene, meta)
    stored, objects = relight_store.load(scene, meta)
    w = outcome.weights
    for name in meta["objects"]:
        mesh = objects[name].data
        for attribute_name, kind, domain in meta["targets"]:
            attribute = mesh.attributes.get(attribute_name)
            if attribute is None:
                raise ValueError(f"'{name}' lost its '{attribute_name}' colours: solve again to relight")
            stored.write(name, attribute, kind, domain, w)
        mesh.update_tag()
    _textured_emission()
    meta["relit"] = w.tolist()
    relight_store.save_meta(scene, meta)
    settings = scene.radiosity
    settings.last_relit = outcome.text()
    settings.last_relative_error = outcome.error.relative_rms * 100.0
    return outcome


def _textured_emission():
    """The textured copies' emission term follows their source materials' emission now."""
    for material in bpy.data.materials:
        if not is_textured_material(material) or material.node_tree is None:
            continue
        source = bpy.data.materials.get(material[TEXTURED_PROPERTY])
        if source is not None and material.get(LIVE_EMITS_PROPERTY):
            follow_emission(material, source)  # (a live copy's own shader emits)
        if source is None:
            continue
        emission = sources.material_emission(source)
        strength = float(np.max(emission)) if emission.any() else 0.0
        for node in [n for n in material.node_tree.nodes if n.label == "Emission"]:  # (live: EEVEE's and Cycles')
            if not node.inputs["Scale"].is_linked:
                node.inputs["Scale"].default_value = strength
            if not node.inputs[0].is_linked:
                node.inputs[0].default_value = tuple(emission / strength) if strength > 0 else (0.0, 0.0, 0.0)


class RADIOSITY_OT_relight(bpy.types.Operator):
    """Recombine the stored per-light results with the lamps', world's and emissive materials' current strengths and colours, without tracing a ray"""

    bl_idname = "radiosity.relight"
    bl_label = "Relight"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        started = time.perf_counter()
        context.evaluated_depsgraph_get()  # (moved lamps' matrices up to date)
        try:
            outcome = relight(context.scene)
        except ValueError as exc:
            self.report({"ERROR"}, f"Radiosity: {exc}")
            return {"CANCELLED"}
        _STATE["seconds"] = time.perf_counter() - started
        self.report({"WARNING"} if outcome.error.past_target or outcome.outdated() or outcome.added else {"INFO"},
                    f"Radiosity {outcome.text()} ({_STATE['seconds'] * 1000:.0f} ms)")
        return {"FINISHED"}


# -- live --------------------------------------------------------------------------------------
_SOURCE_TYPES = (bpy.types.Light, bpy.types.World, bpy.types.Material, bpy.types.NodeTree)


def _source_changed(depsgraph):
    for update in depsgraph.updates:
        data = update.id
        if isinstance(data, _SOURCE_TYPES):
            return True
        if isinstance(data, bpy.types.Object) and data.type == "LIGHT":
            return True
    return False


@persistent
def on_depsgraph_update(scene, depsgraph):
    """A source's data changed and the scene has per-source results: relight soon (once for a
    burst of changes)."""
    _STATE["generation"] += 1  # (the panel's list is made again)
    settings = getattr(scene, "radiosity", None)
    if _STATE["pending"] or settings is None or not settings.live_relight or not _source_changed(depsgraph):
        return
    if relight_store.meta_of(scene) is None:
        return
    _STATE["pending"] = True
    bpy.app.timers.register(live_tick, first_interval=LIVE_DELAY)


def live_tick():
    """The live relight: only where the weights moved since the last one (None: no repeat)."""
    _STATE["pending"] = False
    scene = bpy.context.scene
    meta = relight_store.meta_of(scene)
    if meta is None or not scene.radiosity.live_relight:
        return None
    try:
        outcome = assess(scene, meta)
        if np.array_equal(outcome.weights, np.asarray(meta["relit"], np.float64).reshape(outcome.weights.shape)):
            scene.radiosity.last_relit = outcome.text()
            return None
        started = time.perf_counter()
        relight(scene)
        _STATE["seconds"] = time.perf_counter() - started
    except ValueError as exc:
        scene.radiosity.last_relit = f"relight failed: {exc}"
    _redraw()
    return None


def _redraw():
    for window in getattr(bpy.context.window_manager, "windows", []):
        for area in window.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()


# -- panel -------------------------------------------------------------------------------------
class VIEW3D_PT_radiosity_relight(bpy.types.Panel):
    bl_label = "Relight"
    bl_idname = "VIEW3D_PT_radiosity_relight"
    bl_parent_id = "VIEW3D_PT_radiosity"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"

    @classmethod
    def poll(cls, context):
        return relight_store.meta_of(context.scene) is not None

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        key = (_STATE["generation"], scene.session_uid, scene.radiosity.last_relit)
        try:
            outcome = _STATE["panel"][1] if _STATE["panel"][0] == key else assess(scene)
        except ValueError as exc:
            layout.label(text=str(exc))
            return
        _STATE["panel"] = (key, outcome)
        col = layout.column(align=True)
        icons = {"current": "CHECKMARK", "relit": "LIGHT", "stale": "ERROR"}
        for s, name in enumerate(outcome.meta["names"]):
            state = outcome.state(s)
            col.label(text=f"{name}: {state}, {outcome.shares[s]:.0%} of the light", icon=icons[state])
        for line in _lines(outcome.text(), 60):
            layout.label(text=line)
        layout.prop(scene.radiosity, "live_relight")
        row = layout.row(align=True)
        row.operator("radiosity.relight", icon="LIGHT")
        row.operator("radiosity.update", icon="FILE_REFRESH")


def _lines(text, width):
    words, lines = text.split(), [""]
    for word in words:
        if lines[-1] and len(lines[-1]) + len(word) + 1 > width:
            lines.append(word)
        else:
            lines[-1] = f"{lines[-1]} {word}".strip()
    return lines


@persistent
def on_load(_):
    """A file with per-source results opened: their arrays read now, so that its first relight
    is as quick as the next (reading every source's attributes took up to a second)."""
    scene = bpy.context.scene
    meta = relight_store.meta_of(scene) if scene is not None else None
    if meta is not None:
        try:
            relight_store.load(scene, meta)
        except ValueError:  # (damaged results: the relight says so when asked)
            pass


classes = (RADIOSITY_OT_relight, VIEW3D_PT_radiosity_relight)
HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("load_post", on_load))


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    handlers.attach(*HANDLERS)


def unregister():
    handlers.detach(*HANDLERS)
    if bpy.app.timers.is_registered(live_tick):
        bpy.app.timers.unregister(live_tick)
    _STATE["pending"] = False
    relight_store.forget()
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
