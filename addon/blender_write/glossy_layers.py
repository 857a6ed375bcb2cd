"""A result material's glossy layers as the camera sees them (bpy): a dielectric Principled BSDF's
base colour weight and glossy albedo at the view's angle (``core.materials.principled.view_terms``,
held by RGB Curves of the view cosine), and in EEVEE its glossy layers lit by the lamps (their
highlights, drawn live with their shadows).
"""

from __future__ import annotations

from ..blender_read.materials import BASE
from .shader_nodes import feed, flat_switch, shader_or_flat, times_light

# A live copy's glossy layers in EEVEE (``plus_highlights``): the source's Principled BSDF with these inputs so (the
# base colour black: its diffuse part is the emission's); the layers it cannot draw alone keep the whole baked.
HIGHLIGHT_INPUTS = {"Base Color": (0.0, 0.0, 0.0, 1.0), "Emission Strength": 0.0, "Subsurface Weight": 0.0,
                    "Sheen Weight": 0.0, "Alpha": 1.0}
NOT_ALONE = ("Metallic", "Transmission Weight")  # (their reflection depends on the base colour, or they pass light)
WEIGHT_LABEL, ALBEDO_LABEL = "Base colour's weight as viewed", "Glossy layers' albedo as viewed"  # (as_viewed's curves)


def has_highlights(shader):
    """Whether ``shader`` is a Principled BSDF whose glossy layers EEVEE can draw apart from its
    base colour (no metallic or transmission part: ``NOT_ALONE``)."""
    if shader.bl_idname != "ShaderNodeBsdfPrincipled":
        return False
    return not any(shader.inputs[name].is_linked or float(shader.inputs[name].default_value) > 1e-5
                   for name in NOT_ALONE if name in shader.inputs)


def as_viewed(tree, shader, viewed, light_attribute, glossy_attribute, location):
    """A socket: ``shader``'s base colour times the base's weight as the camera sees it, times
    ``light_attribute``, plus the glossy layers' albedo as the camera sees it times
    ``glossy_attribute`` (``materials.LAMPLESS_ATTRIBUTE`` where the lamps' highlights are drawn live);
    ``viewed``: ``view_terms``' (mu, scale, offset), held by two RGB Curves of the view cosine."""
    nodes, links = tree.nodes, tree.links
    x, y = location
    facing = nodes.new("ShaderNodeLayerWeight")  # (Facing: 1 - |N.I| at Blend 0.5)
    facing.location = (x - 600, y)
    cosine = nodes.new("ShaderNodeMath")
    cosine.operation = "SUBTRACT"
    cosine.label = "View cosine"
    cosine.location = (x - 400, y)
    cosine.inputs[0].default_value = 1.0
    links.new(facing.outputs["Facing"], cosine.inputs[1])
    mu, scale, offset = viewed
    weight = _curves(tree, mu, scale, WEIGHT_LABEL, (x - 200, y + 200))
    albedo = _curves(tree, mu, offset, ALBEDO_LABEL, (x - 200, y - 200))
    links.new(cosine.outputs[0], weight.inputs["Color"])
    links.new(cosine.outputs[0], albedo.inputs["Color"])
    diffuse = nodes.new("ShaderNodeVectorMath")
    diffuse.operation = "MULTIPLY"
    diffuse.label = "Diffuse reflectivity as viewed"
    diffuse.location = (x, y + 200)
    feed(links, shader, BASE[shader.bl_idname], diffuse.inputs[0], default=(0.0, 0.0, 0.0))
    links.new(weight.outputs["Color"], diffuse.inputs[1])
    lit = times_light(tree, diffuse, light_attribute, (x + 200, y + 200))
    glossy = times_light(tree, albedo, glossy_attribute, (x + 200, y - 200))
    both = nodes.new("ShaderNodeVectorMath")
    both.operation = "ADD"
    both.location = (x + 600, y)
    links.new(lit, both.inputs[0])
    links.new(glossy, both.inputs[1])
    return both.outputs[0]


def _curves(tree, mu, values, label, location):
    """An RGB Curves node mapping a grey (mu, mu, mu) to ``values`` (n,3) at the cosines ``mu``
    (n,), linear between them."""
    node = tree.nodes.new("ShaderNodeRGBCurve")
    node.label = label
    node.location = location
    mapping = node.mapping
    for channel in range(3):
        curve = mapping.curves[channel]  # (R, G, B; the fourth, the combined curve C, stays the identity)
        while len(curve.points) < len(mu):
            curve.points.new(0.5, 0.5)
        for point, x, y in zip(curve.points, mu, values[:, channel]):
            point.location = (float(x), float(y))
            point.handle_type = "VECTOR"
    mapping.update()
    return node


def plus_highlights(tree, shader, emission, location):
    """A socket: the Emission shader ``emission`` plus ``shader``'s glossy layers (a Principled
    BSDF of its inputs with HIGHLIGHT_INPUTS), which EEVEE lights by the lamps; where the flat
    switch is on, ``emission`` alone."""
    nodes, links = tree.nodes, tree.links
    x, y = location
    layer = nodes.new("ShaderNodeBsdfPrincipled")
    layer.label = "Highlights (the lamps', drawn live)"
    layer.location = (x, y - 300)
    for prop in ("distribution", "subsurface_method"):
        setattr(layer, prop, getattr(shader, prop))
    for socket in shader.inputs:
        own = layer.inputs.get(socket.name)
        if own is None or not hasattr(own, "default_value") or socket.name in HIGHLIGHT_INPUTS:
            continue
        if socket.is_linked:
            links.new(socket.links[0].from_socket, own)
        else:
            own.default_value = socket.default_value
    for name, value in HIGHLIGHT_INPUTS.items():
        if name in layer.inputs:
            layer.inputs[name].default_value = value
    return shader_or_flat(tree, layer, emission, flat_switch(tree, (x + 200, y + 250)), (x + 200, y))
