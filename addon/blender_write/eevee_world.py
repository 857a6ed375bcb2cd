"""The world as EEVEE shows it beside live results (bpy): seen by the camera, lighting nothing.

A live result's EEVEE output draws the lamps' highlights with a Principled BSDF's specular layer
(``materials.textured_material``), and EEVEE lights such a layer by its world probe as well: the
sky would shine on every glossy floor of a closed room, through its walls, on top of the sky's
light the solve has already put in the results. So the world gets an output of its own for
EEVEE: its surface to camera rays (the sky through a window stays in the picture), black to the
probes. Cycles keeps the world's own output (set to Cycles where it was for every engine), and
everything the add-on reads of the world (its light, its signature) ignores what is added here
(``is_ours``). Taken out again, the user's output put back as it was, when a run no longer needs
it (``restore``), or when no object shows such a result any more (``restore_unless_shown``: the
results deleted by hand; ``ui.world_watch`` calls it). EEVEE's own reflections (Raytracing,
reflection probes) would add the room's light again: a run says so (``reflection_notes``).
"""
from __future__ import annotations

from ..blender_read.lights import EEVEE_WORLD_PREFIX as PREFIX
from ..blender_read.lights import added_for_eevee as is_ours
from ..blender_read.lights import world_output as user_output
from .materials import HIGHLIGHTS_PROPERTY

WAS_ALL = "radiosity_output_was_all"  # on our output: the user's output was for every engine
OUTPUT = PREFIX + "World Output"


def camera_only(world):
    """Gives ``world`` (or None) its EEVEE output seen by camera rays alone (the module's
    docstring), or brings it up to date with the user's surface. False, changing nothing, where
    the world has no nodes, no surface or an EEVEE output of the user's own."""
    tree = getattr(world, "node_tree", None)
    if tree is None:
        return False
    output = user_output(tree)
    if output is None or not output.inputs["Surface"].is_linked:
        return False
    if any(n.bl_idname == "ShaderNodeOutputWorld" and n.target == "EEVEE" and not is_ours(n) for n in tree.nodes):
        return False
    nodes, links = tree.nodes, tree.links
    ours = nodes.get(OUTPUT)
    if ours is None:
        x, y = output.location
        path = nodes.new("ShaderNodeLightPath")
        path.name = path.label = PREFIX + "Light Path"
        path.location = (x, y - 250)
        mix = nodes.new("ShaderNodeMixShader")
        mix.name = PREFIX + "Camera Only"
        mix.label = "EEVEE: the world to camera rays alone (the results hold its light)"
        mix.location = (x, y - 450)
        links.new(path.outputs["Is Camera Ray"], mix.inputs["Fac"])
        ours = nodes.new("ShaderNodeOutputWorld")
        ours.name = ours.label = OUTPUT
        ours.location = (x + 200, y - 450)
        ours.target = "EEVEE"
        links.new(mix.outputs[0], ours.inputs["Surface"])
        ours[WAS_ALL] = output.target == "ALL"
    mix = nodes[PREFIX + "Camera Only"]
    links.new(output.inputs["Surface"].links[0].from_socket, mix.inputs[2])
    if output.target == "ALL":
        output.target = "CYCLES"
    output.is_active_output = True
    ours.is_active_output = True
    return True


def restore(world):
    """Takes ``world``'s EEVEE output of ``camera_only`` out, the user's output for every engine
    again where it was."""
    tree = getattr(world, "node_tree", None)
    if tree is None:
        return
    ours = tree.nodes.get(OUTPUT)
    if ours is not None and ours.get(WAS_ALL, False):
        output = user_output(tree)
        if output is not None:
            output.target = "ALL"
            output.is_active_output = True
    for node in [n for n in tree.nodes if is_ours(n)]:
        tree.nodes.remove(node)


def has_output(world):
    """Whether ``world`` (or None) has the EEVEE output ``camera_only`` adds (a dictionary look-up:
    cheap enough for every depsgraph update)."""
    tree = getattr(world, "node_tree", None)
    return tree is not None and tree.nodes.get(OUTPUT) is not None


def restore_unless_shown(world, scenes, first=()):
    """``restore``s ``world`` where it has our EEVEE output and no object of ``scenes`` (those the
    world lights) shows a material whose EEVEE output draws the highlights; True where it did.
    The objects ``first`` (the results' collections) are looked at before the scenes' others: a
    result moved out of its collection or copied still counts (it still draws the highlights)."""
    if not has_output(world):
        return False
    if any(_shows_highlights(o) for o in first) or any(_shows_highlights(o) for scene in scenes for o in scene.objects):
        return False
    restore(world)
    return True


def _shows_highlights(obj):
    return obj.type == "MESH" and any(slot.material is not None and slot.material.get(HIGHLIGHTS_PROPERTY)
                                      for slot in obj.material_slots)


def reflection_notes(scene):
    """Notes on what of EEVEE's own would reflect the results in their glossy layers, whose
    emission holds that light already: its Raytracing, reflection probes (spheres, planes)."""
    notes = []
    if getattr(getattr(scene, "eevee", None), "use_raytracing", False):
        notes.append("EEVEE's Raytracing is on (Render Properties): its reflections add the room's light to the "
                     "results' glossy layers, whose colours hold it already; turn it off to see them as solved")
    probes = sorted(o.name for o in scene.objects if o.type == "LIGHT_PROBE" and o.data.type in ("SPHERE", "PLANE"))
    if probes:
        notes.append(f"EEVEE's reflection probes ({', '.join(probes[:3])}{' and more' if len(probes) > 3 else ''}) "
                     "add the room's light to the results' glossy layers, whose colours hold it already; hide them "
                     "from the render to see the results as solved")
    return notes
