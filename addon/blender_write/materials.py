"""Result materials that show each original material's own surface colour times the light the
solve found arriving, plus its emission (bpy).

A copy of the original material keeps only what drives its base colour and emission (image
textures with their Mapping, UV Map and Texture Coordinate nodes, colour attributes, checkers,
node groups), and shows

    (base colour * scale + offset) * light + emission colour * strength

through an Emission shader, ``light`` being a colour attribute of the result mesh (the smooth
light arriving, H in B = E + rho H). With live lamps the copy keeps its own shader too, which
Cycles lights; the camera sees that shader, whose one bounce gathers the light of the results it
meets (their shaders lit by the lamps plus their solved light after a bounce, BOUNCED_ATTRIBUTE:
H less the light Cycles draws live). EEVEE sees the Emission shader, and where the scene has lamps,
a dielectric Principled BSDF's glossy layers lit by them (their highlights, which EEVEE draws
with their shadows), the emission's glossy part then lit by the light less the lamps'
(LAMPLESS_ATTRIBUTE), its base colour's weight and its glossy layers' albedo as the camera sees
them (the glossy albedo rises towards grazing; their means over the views the solve's
reflectivity); the world's EEVEE output lights nothing (``eevee_world``) and nothing else of
EEVEE's own lights a result, so each part of the light counts once.
The texture stays at its own resolution whatever the patch
size; the patch's reflected radiosity is the area mean of (base colour x light) over it, up to
how much the texture and the light vary together inside it. The user's material is never
changed: a copy is made and cut down.
"""

from __future__ import annotations

import bpy

from ..blender_read.materials import BASE, EMISSION, shader_node, surface_terms, view_terms
from .glossy_layers import as_viewed, has_highlights, plus_highlights
from .shader_nodes import feed, flat_switch, output_node, shader_or_flat, times_light

TEXTURED_PROPERTY = "radiosity_textured_from"  # marks our copies: the source material's name
LIVE_PROPERTY = "radiosity_live_lamps"  # marks copies whose own shader the lamps light (textured_material)
LIVE_EMITS_PROPERTY = "radiosity_live_emits"  # marks live copies whose own emission lights the others
HIGHLIGHTS_PROPERTY = "radiosity_highlights"  # marks live copies whose EEVEE output draws the lamps' highlights
TEXTURED_SUFFIX = " Radiosity"
BOUNCED_ATTRIBUTE = "Radiosity Bounced Light"  # live: the light arriving less the light Cycles draws live
LAMPLESS_ATTRIBUTE = "Radiosity Light Less Lamps"  # live with lamps: the light arriving less the lamps' (EEVEE's)
IDENTITY = ((1.0, 1.0, 1.0), (0.0, 0.0, 0.0))  # (scale, offset): the base colour is the reflectivity


def is_textured_material(material) -> bool:
    return material is not None and TEXTURED_PROPERTY in material.keys()


def can_copy(material):
    """(True, None) where ``textured_material`` can show ``material``; (False, note) where it
    cannot (a surface shader it does not know: the note says so); (False, None) for no
    material or one without nodes, which the flat result material shows as they are."""
    if material is None or material.node_tree is None:
        return False, None
    if bpy.app.version < (5, 0, 0) and not material.use_nodes:
        return False, None
    node = shader_node(material)
    if node is None or (node.bl_idname not in BASE and node.bl_idname not in EMISSION):
        kind = "nothing" if node is None else f"'{node.name}' ({node.bl_idname})"
        return False, (f"material '{material.name}': its surface is {kind}, not a Principled, Diffuse or Emission "
                       "shader; its result shows the baked 'Radiosity' colours, without its textures")
    return True, None


def textured_material(source, light_attribute, flat_attribute, terms=IDENTITY, live=False, lamps=False):
    """A new material showing ``source``'s base colour * scale + offset (``terms``, RGB each)
    times the colour attribute ``light_attribute``, plus its emission, or, where the panel's
    flat switch is on, the colour attribute ``flat_attribute``; ``can_copy(source)`` must
    hold. The copy is cut down to what drives that, and marked as ours. ``live``: so in EEVEE;
    in Cycles its own shader for the lamps to light, with BOUNCED_ATTRIBUTE (``_lit_by_lamps``).
    ``live`` with ``lamps`` (the scene has lamps; LAMPLESS_ATTRIBUTE written), a dielectric Principled
    BSDF (``has_highlights``) in EEVEE: its glossy layers draw the lamps' highlights live, and the
    emission shows its scale and offset as the camera sees them (``view_terms``: the glossy layers'
    albedo rises towards grazing, the base colour's weight falls; their means over the views the
    solve's), the offset's part lit by the light less the lamps' (``glossy_layers.as_viewed``)."""
    material = source.copy()
    material.name = source.name + TEXTURED_SUFFIX
    for key in list(material.keys()):  # (a copy carries the source's custom properties)
        del material[key]
    material[TEXTURED_PROPERTY] = source.name
    if material.animation_data is not None:
        material.animation_data_clear()
    tree = material.node_tree
    shader = tree.nodes[shader_node(source).name]
    nodes, links = tree.nodes, tree.links
    x, y = shader.location.x + 300, shader.location.y

    surface = nodes.new("ShaderNodeVectorMath")  # base colour * scale + offset
    surface.operation = "MULTIPLY_ADD"
    surface.label = "Reflectivity"
    surface.location = (x, y)
    feed(links, shader, BASE.get(shader.bl_idname), surface.inputs[0], default=(0.0, 0.0, 0.0))
    surface.inputs[1].default_value = tuple(float(v) for v in terms[0])
    surface.inputs[2].default_value = tuple(float(v) for v in terms[1])

    outputs = []
    if live and shader.bl_idname in BASE:  # (Cycles: its own shader lit by the lamps, and the bounced light)
        bounced = emission_output(tree, times_light(tree, surface, BOUNCED_ATTRIBUTE, (x, y + 900)), flat_attribute,
                                  (x + 600, y + 900))
        outputs.append(output_node(tree, "CYCLES", _lit_by_lamps(tree, shader, bounced, (x + 800, y + 900)),
                               (x + 1200, y + 900)))
        material[LIVE_PROPERTY] = True
    highlights = live and lamps and has_highlights(shader) and any(terms[1])
    if highlights:  # (as the camera sees the surface, the lamps' highlights drawn live)
        lit = as_viewed(tree, shader, view_terms(source), light_attribute, LAMPLESS_ATTRIBUTE, (x, y - 1400))
    else:  # (the mean over the views: a lamp's light is far from even, docs/picture.md)
        lit = times_light(tree, surface, light_attribute, (x, y))
    emission = emission_output(tree, _plus_emission(material, shader, lit, live, (x, y)), flat_attribute, (x + 600, y))
    shown = emission.outputs["Emission"]
    if highlights:
        shown = plus_highlights(tree, shader, emission, (x + 800, y - 300))
        material[HIGHLIGHTS_PROPERTY] = True
    outputs.append(output_node(tree, "EEVEE" if outputs else "ALL", shown, (x + 1200, y)))
    _keep_only_upstream(tree, outputs)
    return material


def _plus_emission(material, shader, total, live, location):
    """``total`` (a socket) plus the shader's emission colour x strength where it emits; an
    emitting live copy is marked LIVE_EMITS_PROPERTY (its own shader lights the others in Cycles,
    sampled as a light)."""
    tree, (x, y) = material.node_tree, location
    if not _emits(shader):
        return total
    if live:
        material[LIVE_EMITS_PROPERTY] = True
    emitted = _emitted(tree, shader, (x, y - 450))
    added = tree.nodes.new("ShaderNodeVectorMath")
    added.operation = "ADD"
    added.location = (x + 400, y)
    tree.links.new(total, added.inputs[0])
    tree.links.new(emitted, added.inputs[1])
    return added.outputs[0]


def follow_emission(copy, source):
    """A live copy's own shader's emission (``LIVE_EMITS_PROPERTY``: it lights the others in
    the render) set to its source's now, where the source's inputs are values (Relight)."""
    node, own = shader_node(source), None
    if node is not None and copy.node_tree is not None:
        own = copy.node_tree.nodes.get(node.name)
    if own is None or own.bl_idname != node.bl_idname:
        return
    for name in EMISSION.get(node.bl_idname, ()):
        if not node.inputs[name].is_linked and not own.inputs[name].is_linked:
            own.inputs[name].default_value = node.inputs[name].default_value


def _lit_by_lamps(tree, shader, emission, location):
    """The surface shader of a live result in Cycles: the source's own shader, lit by the scene's
    lamps and emitting materials as the renderer draws them, its own emission lighting the
    others. The camera sees that shader, whose bounce gathers the light of the surfaces its rays
    meet; a ray leaving a camera hit sees the shader plus ``emission``, the solved light after a
    bounce (what the lamps' light on it does not hold); a deeper ray sees its own emission alone,
    so that no light is counted twice at any number of bounces (``_seen_by``). Where the flat
    switch is on, the camera sees the flat colours alone."""
    nodes, links = tree.nodes, tree.links
    x, y = location
    switch = flat_switch(tree, (x, y + 250))
    either = nodes.new("ShaderNodeMath")
    either.operation = "MAXIMUM"
    either.location = (x - 200, y + 300)
    links.new(_ray_depth(tree, "COMPARE", (x - 400, y + 300)), either.inputs[0])  # (a ray leaving a camera hit)
    links.new(switch.outputs["Fac"], either.inputs[1])
    links.new(either.outputs[0], emission.inputs["Strength"])
    shown = shader_or_flat(tree, shader, emission, switch, (x, y))
    return _seen_by(tree, shader, shown, (x + 200, y - 250))


def _seen_by(tree, shader, surface, location):
    """``surface`` for camera rays and the rays leaving a camera hit; for every deeper ray nothing
    but the source's own emission, if it emits (it stays a light): a render with more bounces would
    otherwise light the results again from one another, the light the solve has already put in
    them (any number of bounces then draws the same picture; shadow rays still meet an opaque
    surface)."""
    nodes, links = tree.nodes, tree.links
    x, y = location
    seen = nodes.new("ShaderNodeMixShader")
    seen.label = "Camera rays and the next (deeper: its own emission)"
    seen.location = (x + 200, y)
    links.new(_ray_depth(tree, "LESS_THAN", (x, y - 250)), seen.inputs["Fac"])
    emitted = _emitted(tree, shader, (x, y - 450))
    if emitted is not None:
        light = nodes.new("ShaderNodeEmission")
        light.location = (x + 100, y - 450)
        light.inputs["Strength"].default_value = 1.0
        links.new(emitted, light.inputs["Color"])
        links.new(light.outputs["Emission"], seen.inputs[1])
    links.new(surface, seen.inputs[2])
    return seen.outputs[0]


def camera_only(tree, emission, location):
    """Makes the Emission shader ``emission`` (a live run's flat result material: the whole
    solved light) seen by camera rays and the rays leaving a camera hit alone, as ``_seen_by``."""
    tree.links.new(_ray_depth(tree, "LESS_THAN", location), emission.inputs["Strength"])


def _ray_depth(tree, operation, location):
    """A socket from a Light Path node's Ray Depth (0 for a camera ray, 1 for a ray leaving its
    hit): ``LESS_THAN`` 1 up to depth 1; ``COMPARE`` 1 at depth 1 alone."""
    path = tree.nodes.new("ShaderNodeLightPath")
    path.location = location
    test = tree.nodes.new("ShaderNodeMath")
    test.operation = operation
    test.location = (location[0] + 150, location[1])
    tree.links.new(path.outputs["Ray Depth"], test.inputs[0])
    test.inputs[1].default_value = 1.5 if operation == "LESS_THAN" else 1.0
    test.inputs[2].default_value = 0.5  # (COMPARE's epsilon)
    return test.outputs[0]


def _emits(shader):
    """Whether the shader has an emission whose strength is not a plain 0."""
    if shader.bl_idname not in EMISSION:
        return False
    strength = shader.inputs[EMISSION[shader.bl_idname][1]]
    return strength.is_linked or strength.default_value != 0


def _emitted(tree, shader, location):
    """The shader's emission colour x strength (a socket: its own subtree where linked), or None
    where it emits nothing."""
    if not _emits(shader):
        return None
    colour, strength = (shader.inputs[name] for name in EMISSION[shader.bl_idname])
    emitted = tree.nodes.new("ShaderNodeVectorMath")
    emitted.operation = "SCALE"
    emitted.label = "Emission"
    emitted.location = location
    feed(tree.links, shader, colour.name, emitted.inputs[0], default=(0.0, 0.0, 0.0))
    if strength.is_linked:
        tree.links.new(strength.links[0].from_socket, emitted.inputs["Scale"])
    else:
        emitted.inputs["Scale"].default_value = float(strength.default_value)
    return emitted.outputs[0]


def emission_output(tree, colour, flat_attribute, location):
    """An Emission shader of ``colour`` (a socket), or of the colour attribute ``flat_attribute``
    where the scene's flat switch is on (``shader_nodes.FLAT_SWITCH``)."""
    nodes, links = tree.nodes, tree.links
    x, y = location
    switch = flat_switch(tree, (x - 200, y + 250))
    flat = nodes.new("ShaderNodeAttribute")
    flat.attribute_type = "GEOMETRY"
    flat.attribute_name = flat_attribute
    flat.location = (x - 200, y - 250)
    mix = nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.clamp_factor = True
    mix.location = (x, y)
    links.new(switch.outputs["Fac"], mix.inputs["Factor"])
    links.new(colour, mix.inputs[6])  # (A, the colour inputs of the RGBA mode)
    links.new(flat.outputs["Color"], mix.inputs[7])
    emission = nodes.new("ShaderNodeEmission")
    emission.location = (x + 200, y)
    emission.inputs["Strength"].default_value = 1.0
    links.new(mix.outputs[2], emission.inputs["Color"])
    return emission


def _keep_only_upstream(tree, outputs):
    """Remove every node that does not feed ``outputs`` (the original shaders, other outputs)."""
    feeding = {}  # node name -> the nodes linked into it (one pass over the links: a socket's
    for link in tree.links:  # .links scans them all again each time it is read)
        feeding.setdefault(link.to_node.name, []).append(link.from_node)
    keep = {output.name for output in outputs}
    stack = list(outputs)
    while stack:
        node = stack.pop()
        for source in feeding.get(node.name, ()):
            if source.name not in keep:
                keep.add(source.name)
                stack.append(source)
    for node in [n for n in tree.nodes if n.name not in keep]:
        tree.nodes.remove(node)


def result_materials(slot_names, light_attribute, flat_attribute, fallback, notes, made, live=False, lamps=False):
    """The result material of each source slot: the textured copy of the named material
    (made once a run, kept in ``made`` by name; ``live``: lit by the lamps too, and with
    ``lamps`` their highlights drawn live in EEVEE), or ``fallback`` where there is none or it
    cannot be copied (``notes`` get a line for the latter, once)."""
    out = []
    for name in slot_names:
        source = bpy.data.materials.get(name)
        if name not in made:
            ok, note = can_copy(source) if source is not None and not is_textured_material(source) else (False, None)
            if note:
                notes.append(note)
            # the surface as the camera sees it (a Principled BSDF's specular layer beside its base colour)
            made[name] = (textured_material(source, light_attribute, flat_attribute,
                                            surface_terms(source), live, lamps) if ok else None)
        out.append(made[name] or fallback)
    return out


def remove_unused_textured():
    """Our textured copies that no object uses any more (a previous run's)."""
    for material in [m for m in bpy.data.materials if is_textured_material(m) and m.users == 0]:
        bpy.data.materials.remove(material)
