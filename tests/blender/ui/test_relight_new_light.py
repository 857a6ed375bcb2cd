"""Light that relighting cannot follow (ui/relight.py ``assess``, blender_read/sources.py
``new_light``, the core's PerSource.unmeasured): a material that did not emit when the scene was
solved set to emit, the world turned on, an emitting object added, and a lamp whose share of the
paths a far brighter emitter hid relit to most of the light. Before, each was relit as if
nothing had changed ("relit: error 4.5%", every source current, Update "nothing is stale"; the
lamp alone black at "error 0%"). Now the new light is named in the error line and Update solves
everything; the hidden lamp's error is unknown, it is stale, and Update solves its light alone."""
import bpy
import pytest

from addon.blender_write import relight_store
from addon.ui import relight as relight_ui

from . import relight_scene as rs
from .relight_scene import Z, spy_solves, solve, joint_noise_z


def emits(material, strength, colour=(1.0, 1.0, 1.0)):
    node = bpy.data.materials[material].node_tree.nodes["Principled BSDF"]
    node.inputs["Emission Color"].default_value = (*colour, 1.0)
    node.inputs["Emission Strength"].default_value = strength


def background():
    return next(n for n in bpy.context.scene.world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")


def test_a_material_set_to_emit_is_new_light_and_update_solves_everything(blender, monkeypatch):
    rs.build(blender)
    emits("White", 0.0)  # (a white emission colour at strength 0: no source)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    scene = bpy.context.scene
    assert "White" not in relight_store.meta_of(scene)["names"]
    emits("White", 5.0)
    outcome = relight_ui.assess(scene)
    assert outcome.added == ["material White"]
    assert "material White added since the solve: Update solves again" in outcome.text()
    calls = spy_solves(monkeypatch)
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert len(calls) == 1 and "White" in calls[0]
    assert relight_ui.assess(scene).added == []


def test_the_world_turned_on_is_new_light_and_update_solves_everything(blender, monkeypatch):
    rs.build(blender)
    background().inputs["Strength"].default_value = 0.0
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    scene = bpy.context.scene
    assert "World" not in relight_store.meta_of(scene)["names"]
    background().inputs["Strength"].default_value = 1.0
    outcome = relight_ui.assess(scene)
    assert outcome.added == ["world World"] and "world World added since the solve" in outcome.text()
    calls = spy_solves(monkeypatch)
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert len(calls) == 1 and "World" in calls[0]
    assert relight_ui.assess(scene).added == []


def test_an_emitting_object_added_is_new_light_where_the_rest_of_the_scene_takes_part(blender):
    rs.build(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    scene = bpy.context.scene
    strip = bpy.data.objects["Strip"].copy()
    strip.data = strip.data.copy()
    strip.name = "Second strip"
    strip.location.y += 0.3
    scene.collection.objects.link(strip)
    assert relight_ui.assess(scene).added == ["object Second strip"]
    scene.radiosity.use_scene_objects = False  # (only the selection takes part: a new solve would not see it)
    assert relight_ui.assess(scene).added == []


def test_an_emitting_material_in_a_slot_no_face_uses_is_not_new_light(blender):
    """Not light: no solve would have it, so it must not ask for one (Update would never end)."""
    rs.build(blender)
    emits("White", 0.0)
    bpy.data.objects["Room"].data.materials.append(bpy.data.materials["White"].copy())
    unused = bpy.data.objects["Room"].data.materials[-1]
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    emits(unused.name, 5.0)
    assert relight_ui.assess(bpy.context.scene).added == []


def swamped(context, glow):
    """The room lit by its glowing strip at ``glow`` and the bulb at 500 W alone: the bulb's
    share of the power (and of the paths) about 1e-3 at 1e6."""
    settings = rs.build(context)
    for name in ("Panel", "Sun"):
        bpy.data.objects.remove(bpy.data.objects[name])
    context.scene.world = None
    bpy.data.objects["Bulb"].data.energy = 500.0
    emits("Glow", glow, (1.0, 0.9, 0.8))
    return settings


@pytest.mark.parametrize("glow,unknown", [(1e6, False), (1e10, True)])
def test_a_lamp_hidden_by_a_far_brighter_emitter_is_stale_when_it_is_most_of_the_light(blender, monkeypatch, glow,
                                                                                         unknown):
    """The glow at 1e6 leaves the bulb a few of the solve's paths (at 1e7, with the wall's patches
    behind the strip split along its outline, fewer than two batches at this seed): relit alone its error is
    measured, far past the target, and the bulb is stale; at 1e10 it drew none: the room black,
    its error unknown (before: "error 0%"), stale too. Update solves the bulb's light alone."""
    swamped(blender, glow)
    solve(monkeypatch, seed=7)
    scene = bpy.context.scene
    emits("Glow", 0.0, (1.0, 0.9, 0.8))
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    text = relight_ui.assess(scene).text()
    if unknown:
        assert text.startswith("relit: error unknown: Bulb had too few of the solve's paths"), text
    else:
        assert text.startswith("relit: error ") and ", past the solve's 5% target" in text, text
    assert text.endswith("; stale: Bulb (Update)"), text
    emits("Glow", 0.05, (1.0, 0.9, 0.8))  # (the glow's group kept: Update solves the bulb's light alone)
    outcome = relight_ui.assess(scene)
    assert outcome.state(outcome.meta["names"].index("Bulb")) == "stale"
    calls = spy_solves(monkeypatch)
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert calls == [("Bulb",)]
    outcome = relight_ui.assess(scene)
    assert outcome.outdated() == set() and outcome.error.relative_rms <= outcome.error.target_relative_rms
    updated, area = rs.patch_values()
    monkeypatch.undo()
    fresh_output = solve(monkeypatch, seed=9)
    fresh, _ = rs.patch_values()
    result = fresh_output.result
    z = joint_noise_z(updated, fresh, outcome.error.mse, result.measured_mse, result.reflected_variance, area)
    assert abs(z) < Z, z


def test_every_source_off_says_no_light_not_an_error_of_0(blender):
    rs.build(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    for name in ("Bulb", "Panel", "Sun"):
        bpy.data.objects[name].data.energy = 0.0
    background().inputs["Strength"].default_value = 0.0
    emits("Glow", 0.0)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert relight_ui.assess(bpy.context.scene).text() == "relit: no light reflected at these strengths (no error to give)"


def test_a_relight_past_the_target_marks_the_sources_to_solve_again_and_update_meets_it(blender, monkeypatch):
    """The bulb and the panel nearly off, the glow up: past the solve's target. The sources whose error
    puts it there are stale (before: "Update or solve again", and Update said nothing was stale);
    Update re-solves them to part of the target, and the relit light then meets it."""
    rs.build(blender)
    solve(monkeypatch, seed=7)
    scene = bpy.context.scene
    bpy.data.objects["Bulb"].data.energy = 0.1  # (lamps at 0 would leave their groups: a full solve)
    bpy.data.objects["Panel"].data.energy = 0.1
    bpy.data.objects["Sun"].data.energy = 0.2
    emits("Glow", 30.0, (1.0, 0.9, 0.8))
    outcome = relight_ui.assess(scene)
    assert outcome.error.past_target and outcome.over_target, outcome.text()
    assert outcome.text().endswith(f"; stale: {', '.join(sorted(outcome.over_target))} (Update)")
    calls = spy_solves(monkeypatch)
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert calls == [tuple(n for n in outcome.meta["names"] if n in outcome.over_target)]
    after = relight_ui.assess(scene)
    assert not after.error.past_target and after.outdated() == set(), after.text()
