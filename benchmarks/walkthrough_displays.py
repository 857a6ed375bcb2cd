"""The product's displays of its results, each rendered to a float image of the scene's camera
(bpy): EEVEE (Material Preview), the baked display (the result materials' view-independent part),
the 'Radiosity' attribute alone (Solid view, exporters) and the product's own Cycles preview.
Everything changed for a picture is put back after it.
"""
from __future__ import annotations

import contextlib

from benchmarks import picture as pic

EEVEE_SAMPLES = 16  # the viewport's own (Material Preview accumulates 16 by default)
BAKED_SAMPLES = 16  # emission only, no bounces: the samples only anti-alias


@contextlib.contextmanager
def results_only():
    """The sources hidden from the render and the results shown, put back after."""
    from addon.blender_write.results import previous_results

    sources = pic.source_objects()
    states = [(o, o.hide_render) for o in sources]
    for o in sources:
        o.hide_render = True
    pic.show_results(True)
    try:
        yield sources
    finally:
        for o, hidden in states:
            o.hide_render = hidden
        for o in previous_results():
            o.hide_render = True


@contextlib.contextmanager
def materials_swapped(make):
    """Every result object's materials replaced by ``make(material)`` (one each), put back after
    and the made ones removed."""
    import bpy

    from addon.blender_write.results import previous_results

    made, saved = {}, []
    for obj in previous_results():
        for slot in obj.material_slots:
            saved.append((slot, slot.material))
            key = slot.material.name if slot.material is not None else ""
            if key not in made:
                made[key] = make(slot.material)
            slot.material = made[key]
    try:
        yield
    finally:
        for slot, material in saved:
            slot.material = material
        for material in made.values():
            bpy.data.materials.remove(material)


def baked_material(material):
    """A copy of a result material showing its view-independent part alone, as emission: the
    colour its Emission shader of the solved light takes (``blender_write.materials.emission_output``:
    (base colour x scale + offset) x 'Radiosity Light' + emission, or 'Radiosity' for the flat
    result material: its EEVEE output's, where it draws the lamps' highlights as ``_as_baked``
    makes it); its live shader and outputs dropped."""
    copy = material.copy()
    tree = copy.node_tree
    _as_baked(copy)
    shown = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.target in ("ALL", "EEVEE")]
    emission = _emission_under(shown[0].inputs["Surface"]) if len(shown) == 1 else None
    colour = emission.inputs["Color"].links if emission is not None and "Color" in emission.inputs else ()
    mixes = [link.from_node for link in colour if link.from_node.bl_idname == "ShaderNodeMix"]
    if len(mixes) != 1 or mixes[0].data_type != "RGBA":
        raise RuntimeError(f"'{material.name}': not a result material of a known layout")
    for node in [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]:
        tree.nodes.remove(node)
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    tree.links.new(mixes[0].outputs[2], emission.inputs["Color"])
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.target = "ALL"
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    output.is_active_output = True
    copy.cycles.emission_sampling = "NONE"
    return copy


def _as_baked(copy):
    """A live copy whose EEVEE output draws the lamps' highlights (``glossy_layers``) made to show
    the view-independent display: its terms as viewed held at their means over the views (its
    source's ``surface_terms``), and its glossy part lit by the whole light arriving."""
    import bpy

    from addon.blender_read.materials import surface_terms
    from addon.blender_write.glossy_layers import ALBEDO_LABEL, WEIGHT_LABEL
    from addon.blender_write.materials import HIGHLIGHTS_PROPERTY, LAMPLESS_ATTRIBUTE, TEXTURED_PROPERTY
    from addon.blender_write.results import LIGHT_ATTRIBUTE_NAME

    if not copy.get(HIGHLIGHTS_PROPERTY):
        return
    means = dict(zip((WEIGHT_LABEL, ALBEDO_LABEL), surface_terms(bpy.data.materials[copy[TEXTURED_PROPERTY]])))
    for node in copy.node_tree.nodes:
        if node.bl_idname == "ShaderNodeAttribute" and node.attribute_name == LAMPLESS_ATTRIBUTE:
            node.attribute_name = LIGHT_ATTRIBUTE_NAME
        elif node.bl_idname == "ShaderNodeRGBCurve" and node.label in means:
            for c in range(3):
                for point in node.mapping.curves[c].points:
                    point.location = (point.location[0], float(means[node.label][c]))
            node.mapping.update()


def _emission_under(socket):
    """The Emission shader feeding ``socket``, through Mix and Add Shader nodes (the highlights'
    layer beside it), or None."""
    node = socket.links[0].from_node if socket.is_linked else None
    while node is not None and node.bl_idname in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        node = next((link.from_node for s in node.inputs for link in s.links
                     if link.from_node.bl_idname != "ShaderNodeAttribute"), None)
    return node if node is not None and node.bl_idname == "ShaderNodeEmission" else None


def attribute_material(_material):
    """The 'Radiosity' attribute alone as emission (what Solid view and exporters show)."""
    import bpy

    from addon.blender_write.results import ATTRIBUTE_NAME

    material = bpy.data.materials.new("Walkthrough Radiosity")
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = "GEOMETRY"
    attribute.attribute_name = ATTRIBUTE_NAME
    emission = tree.nodes.new("ShaderNodeEmission")
    tree.links.new(attribute.outputs["Color"], emission.inputs["Color"])
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    material.cycles.emission_sampling = "NONE"
    return material


@contextlib.contextmanager
def black_world():
    """A black world of its own for the render, the scene's put back after."""
    import bpy

    scene = bpy.context.scene
    kept, world = scene.world, bpy.data.worlds.new("Walkthrough Black")
    world.color = (0.0, 0.0, 0.0)
    background = world.node_tree.nodes.get("Background") if world.node_tree is not None else None
    if background is not None:
        background.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    scene.world = world
    try:
        yield
    finally:
        scene.world = kept
        bpy.data.worlds.remove(world)


def emission_image(make):
    """A result picture whose materials are ``make``'s emissions: Cycles without bounces, a black
    world, BAKED_SAMPLES (anti-aliasing): (image, seconds)."""
    import bpy

    scene = bpy.context.scene
    with results_only(), materials_swapped(make), black_world():
        pic.configure_cycles(scene, BAKED_SAMPLES)
        scene.cycles.max_bounces = 0
        return pic.render_exr(scene)


def eevee_image():
    """EEVEE over the results, the scene's lamps and world (Material Preview with Scene Lights and
    Scene World; the results' EEVEE output is emission): (image, seconds; the seconds of software
    OpenGL mean nothing)."""
    import bpy

    scene = bpy.context.scene
    with results_only():
        scene.render.engine = "BLENDER_EEVEE"
        scene.eevee.taa_render_samples = EEVEE_SAMPLES
        pic.linear_view(scene)
        scene.render.film_transparent = False
        return pic.render_exr(scene)


def preview_image(width, samples=None):
    """The product's own preview of the current view (``cli.preview``'s settings, restored after;
    ``samples``: the command line's default unless given)."""
    import bpy

    from addon.cli import preview

    scene = bpy.context.scene
    with results_only() as sources:
        changes = preview.preview_settings(scene, sources, width, samples or pic.PREVIEW_SAMPLES, 0.0)
        try:
            scene.render.threads_mode, scene.render.threads = "FIXED", pic.THREADS
            return pic.render_exr(scene)
        finally:
            changes.restore()
