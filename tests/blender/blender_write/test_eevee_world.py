"""The world's EEVEE output beside live results whose glossy layers draw the lamps' highlights
(``blender_write.eevee_world``): added by a run that needs it, read by nothing of the add-on,
Cycles' output the user's, taken out by a run that does not need it."""
import bpy
import numpy as np

from addon.blender_read import lights as lights_io
from addon.blender_read.sources import world_signature
from addon.blender_write import eevee_world

from ..blender_read.test_lights import _lamp
from ..conftest import box_arrays, make_object, principled

SKY = (0.3, 0.5, 0.9)


def _sky():
    world = bpy.data.worlds.new("Sky")
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (*SKY, 1.0)
    background.inputs["Strength"].default_value = 2.0
    bpy.context.scene.world = world
    return world


def _outputs(world):
    return sorted((n.name, n.target) for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeOutputWorld")


def test_the_eevee_output_lights_nothing_and_leaves_cycles_and_what_is_read_as_they_were(blender):
    world = _sky()
    notes = []
    before = (lights_io._background(world, notes), world_signature(world), len(world.node_tree.nodes))
    assert eevee_world.camera_only(world)
    tree = world.node_tree
    assert tree.get_output_node("CYCLES").name == "World Output"
    ours = tree.get_output_node("EEVEE")
    assert eevee_world.is_ours(ours) and ours.name == eevee_world.OUTPUT
    mix = ours.inputs["Surface"].links[0].from_node  # (camera rays see the background, the rest nothing)
    assert mix.inputs["Fac"].links[0].from_socket.name == "Is Camera Ray"
    assert mix.inputs[2].links[0].from_node.bl_idname == "ShaderNodeBackground" and not mix.inputs[1].is_linked
    colour, strength, image = lights_io._background(world, notes)
    np.testing.assert_allclose(colour, before[0][0])
    assert strength == before[0][1] == 2.0 and image is None and not notes
    assert world_signature(world) == before[1]
    assert lights_io.world_gives_light(bpy.context.scene)
    count = len(tree.nodes)
    assert eevee_world.camera_only(world) and len(tree.nodes) == count  # (once)
    eevee_world.restore(world)
    assert len(tree.nodes) == before[2] and _outputs(world) == [("World Output", "ALL")]
    assert world_signature(world) == before[1]


def test_a_world_with_an_eevee_output_of_the_users_own_is_left_alone(blender):
    world = _sky()
    own = world.node_tree.nodes.new("ShaderNodeOutputWorld")
    own.target = "EEVEE"
    before = _outputs(world)
    assert not eevee_world.camera_only(world)
    assert _outputs(world) == before


def _glossy_box():
    """A closed box of glossy white walls (Specular IOR Level 0.5) with a point lamp inside."""
    white = principled("White", (0.7, 0.7, 0.7))
    white.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.5
    v, faces = box_arrays((0.0, 0.0, 0.0), (2.0, 2.0, 2.0), inward=True)
    make_object("Box", v, faces, [white])
    _lamp("POINT", "Lamp", location=(1.0, 1.0, 1.5), energy=50.0)


def test_a_live_run_with_highlights_gives_the_world_its_output_and_a_run_without_them_takes_it_out(blender):
    from benchmarks import picture as pic

    world = _sky()
    _glossy_box()
    scene = bpy.context.scene
    pic.source_objects()
    assert scene.radiosity.live_lamps and scene.radiosity.output == "TEXTURED"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert any(m.get("radiosity_highlights") for m in bpy.data.materials)
    assert world.node_tree.get_output_node("EEVEE").name == eevee_world.OUTPUT
    assert bpy.ops.radiosity.solve() == {"FINISHED"}  # (again: one output still)
    assert _outputs(world) == [(eevee_world.OUTPUT, "EEVEE"), ("World Output", "CYCLES")]
    scene.radiosity.live_lamps = False
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert _outputs(world) == [("World Output", "ALL")]
    assert not any(n.name.startswith(eevee_world.PREFIX) for n in world.node_tree.nodes)


def test_eevees_own_reflections_are_named_by_the_run(blender):
    """EEVEE's Raytracing and reflection probes would reflect the room's light in the glossy
    layers a second time: the run's notes name them (and nothing where there are none)."""
    scene = bpy.context.scene
    assert eevee_world.reflection_notes(scene) == []
    scene.eevee.use_raytracing = True
    probe = bpy.data.objects.new("Mirror Probe", bpy.data.lightprobes.new("Mirror Probe", "PLANE"))
    scene.collection.objects.link(probe)
    notes = eevee_world.reflection_notes(scene)
    assert len(notes) == 2 and "Raytracing is on" in notes[0] and "(Mirror Probe)" in notes[1]


def test_results_deleted_by_hand_give_the_world_back(blender):
    """The results that need the world's EEVEE output deleted by hand (no run to take it out),
    the next depsgraph update puts the user's world back as it was; while one such result is
    left, moved out of its collection or not, the output stays. Before, it stayed until a run
    without highlights, and objects outside the selection lost the world's light in EEVEE."""
    from benchmarks import picture as pic

    world = _sky()
    _glossy_box()
    scene = bpy.context.scene
    pic.source_objects()
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert eevee_world.has_output(world)
    results = [o for o in scene.objects if o.name.endswith(" Radiosity")]
    assert results
    kept = results[0]
    for o in results[1:]:
        bpy.data.objects.remove(o, do_unlink=True)
    for collection in list(kept.users_collection):  # (moved out of the results' collection: still shown)
        collection.objects.unlink(kept)
    scene.collection.objects.link(kept)
    bpy.context.view_layer.update()
    assert eevee_world.has_output(world)
    bpy.data.objects.remove(kept, do_unlink=True)
    bpy.context.view_layer.update()
    assert _outputs(world) == [("World Output", "ALL")]
    assert not any(n.name.startswith(eevee_world.PREFIX) for n in world.node_tree.nodes)


def test_a_file_saved_with_the_output_and_without_its_results_is_given_its_world_back_on_load(blender):
    """Results deleted while the watch was not there (the add-on off, an older version): the
    output is taken out when the file is opened (the load handler), not left for good."""
    from addon.ui import world_watch
    from benchmarks import picture as pic

    world = _sky()
    _glossy_box()
    pic.source_objects()
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    world_watch.unregister()
    try:
        for o in [o for o in bpy.context.scene.objects if o.name.endswith(" Radiosity")]:
            bpy.data.objects.remove(o, do_unlink=True)
        bpy.context.view_layer.update()
        assert eevee_world.has_output(world)  # (nothing watched)
        world_watch.on_load(None)
        assert _outputs(world) == [("World Output", "ALL")]
    finally:
        world_watch.register()
