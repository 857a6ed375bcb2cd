"""Small shader-node builders the result materials are made of (bpy)."""

from __future__ import annotations

# The panel's switch to the flat per-patch colours, read by every result material from the scene
# (a View Layer attribute: looked up in the view layer, then the scene).
FLAT_SWITCH = "radiosity.show_patches"


def feed(links, shader, socket_name, target, default):
    """Link what drives the shader's ``socket_name`` into ``target``, or set its value."""
    socket = shader.inputs.get(socket_name) if socket_name else None
    if socket is not None and socket.is_linked:
        links.new(socket.links[0].from_socket, target)
    else:
        value = tuple(socket.default_value)[:3] if socket is not None else default
        target.default_value = tuple(float(v) for v in value)


def times_light(tree, surface, attribute, location):
    """A socket: the output of ``surface`` (a node) times the colour attribute ``attribute``."""
    x, y = location
    light = tree.nodes.new("ShaderNodeAttribute")
    light.attribute_type = "GEOMETRY"
    light.attribute_name = attribute
    light.location = (x, y - 250)
    lit = tree.nodes.new("ShaderNodeVectorMath")
    lit.operation = "MULTIPLY"
    lit.location = (x + 200, y)
    tree.links.new(surface.outputs[0], lit.inputs[0])
    tree.links.new(light.outputs["Color"], lit.inputs[1])
    return lit.outputs[0]


def output_node(tree, target, surface, location):
    """A Material Output node for ``target`` (ALL, CYCLES, EEVEE) showing ``surface`` (a socket),
    the active one for its target."""
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.location = location
    output.target = target
    tree.links.new(surface, output.inputs["Surface"])
    output.is_active_output = True
    return output


def flat_switch(tree, location):
    """An Attribute node reading the panel's FLAT_SWITCH from the view layer (1: flat colours)."""
    switch = tree.nodes.new("ShaderNodeAttribute")
    switch.attribute_type = "VIEW_LAYER"
    switch.attribute_name = FLAT_SWITCH
    switch.label = "Flat patches (paper)"
    switch.location = location
    return switch


def shader_or_flat(tree, shader, emission, switch, location):
    """A socket: ``shader`` plus the Emission shader ``emission``, or where the flat switch
    (``switch``, its attribute node) is on, ``emission`` alone."""
    nodes, links = tree.nodes, tree.links
    x, y = location
    added = nodes.new("ShaderNodeAddShader")
    added.location = (x, y)
    links.new(emission.outputs["Emission"], added.inputs[0])
    links.new(shader.outputs[0], added.inputs[1])
    mix = nodes.new("ShaderNodeMixShader")
    mix.location = (x + 200, y)
    links.new(switch.outputs["Fac"], mix.inputs["Fac"])
    links.new(added.outputs[0], mix.inputs[1])
    links.new(emission.outputs["Emission"], mix.inputs[2])
    return mix.outputs[0]
