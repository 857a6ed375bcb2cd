"""Materials read into colours: a surface shader's base colour and emission, and the image
textures and colour attributes read per patch instead of a material's one value (bpy).

Units: emission = emission colour x strength, reflectivity = the light a surface returns (a
closed box emitting S with albedo R gives S / (1 - R), as Cycles): a Diffuse BSDF's colour, a
Principled BSDF's scale * base colour + offset with the light of its other layers as energy
(core.principled), per patch where the base colour is; solved as passed on from surface to surface
(``transport_terms``, Cycles' Filter Glossy), shown as the camera sees it (``surface_terms``).
"""

from __future__ import annotations

import bpy
import numpy as np

from ..core.materials import principled
from . import SceneError
from . import images
from .images import texture_of

DEFAULT_GREY = (0.8, 0.8, 0.8)  # an object without a material


def _text(colour):
    return "(" + ", ".join(f"{c:.3g}" for c in colour) + ")"


def _linked_colour(socket, node, name, notes, what, emitting=False):
    """The colour of a socket driven by a link: an image's average (an ``images.Average``, known
    once its pixels are read) or a checker's when that is known, else the socket's own default;
    always with a note saying which (none where ``notes`` is None). An emission colour
    (``emitting``) from an image without pixels is a SceneError: no made-up light is solved."""
    quiet, notes = notes is None, [] if notes is None else notes
    default = np.array(socket.default_value[:3], dtype=np.float64)
    source = socket.links[0].from_node
    while source.bl_idname == "NodeReroute" and source.inputs[0].is_linked:
        source = source.inputs[0].links[0].from_node
    if source.bl_idname == "ShaderNodeTexImage" and source.image is not None:
        pixels = images.pixels_of(source.image)
        if pixels is not None:
            note = f"{what}: '{name}' comes from image '{source.image.name}'; its average colour "
            return images.Average(pixels, None if quiet else note)
        if emitting:
            path = bpy.path.abspath(source.image.filepath) if source.image.filepath else ""
            raise SceneError(f"{what}: its '{name}' comes from image '{source.image.name}', which has no pixels "
                             f"({f'file not found: {path}' if path else 'no file'}); its light is unknown: find the "
                             "file (File > External Data) or unlink the image")
        notes.append(f"{what}: '{name}' comes from image '{source.image.name}', which has no pixels "
                     f"(missing file?); the socket's colour {_text(default)} was used")
        return default
    if source.bl_idname == "ShaderNodeTexChecker":
        a, b = source.inputs["Color1"], source.inputs["Color2"]
        if not a.is_linked and not b.is_linked:
            average = 0.5 * (np.array(a.default_value[:3]) + np.array(b.default_value[:3]))
            notes.append(f"{what}: '{name}' comes from checker texture '{source.name}'; "
                         f"the average of its two colours {_text(average)} was used")
            return average
    if source.bl_idname == "ShaderNodeRGB":
        return np.array(source.outputs[0].default_value[:3], dtype=np.float64)
    notes.append(f"{what}: '{name}' of '{node.name}' is driven by '{source.name}', whose average "
                 f"is not known here; the socket's own colour {_text(default)} was used")
    return default


def _socket_colour(node, name, notes, what, per_patch=(), emitting=False):
    socket = node.inputs.get(name)
    if socket is None:
        return np.zeros(3)
    if socket.is_linked:  # sockets read per patch need no note about their average
        return _linked_colour(socket, node, name, None if name in per_patch else notes, what, emitting)
    value = socket.default_value
    return np.array(value[:3], dtype=np.float64)


def _socket_float(node, name, notes, what, default=0.0):
    socket = node.inputs.get(name)
    if socket is None:
        return default
    if socket.is_linked:
        notes.append(f"{what}: '{name}' of '{node.name}' is connected (texture?); its own value "
                     f"{float(socket.default_value):.3g} was used")
    return float(socket.default_value)


def _surface_shader(tree):
    output = None
    for target in ("CYCLES", "ALL", "EEVEE"):
        try:
            output = tree.get_output_node(target)
        except Exception:  # noqa: BLE001 - older API variants
            output = None
        if output is not None:
            break
    if output is None:
        output = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"), None)
    if output is None:
        return None
    socket = output.inputs.get("Surface")
    node = None
    while socket is not None and socket.is_linked:
        node = socket.links[0].from_node
        if node.bl_idname == "NodeReroute":
            socket = node.inputs[0]
            node = None
            continue
        break
    return node


_SUPPORTED = ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeEmission")


def material_colours(material, per_patch=()):
    """(reflectivity (3,), emission (3,), notes) of a material; ``per_patch`` names the sockets
    read per patch (``_per_patch_sockets``), whose averages get no note.

    Principled BSDF: its base colour with the light of its other layers as passed on in the room
    (``transport_terms``), emission colour x strength, and a note naming what is not modelled.
    Diffuse BSDF: colour.  Emission: colour x strength, no reflection.  No node tree: the viewport colour.  No
    material: grey 0.8.  Linked (textured) inputs use the socket's default and add a note.
    """
    notes, later = material_reading(material, per_patch)
    reflectivity, emission, *_ = later(notes)
    return reflectivity, emission, notes


def _known(reflectivity, emission):
    return lambda _notes: (reflectivity, emission, np.ones(3), np.zeros(3), None)


def material_reading(material, per_patch=()):
    """(notes, later) of a material (``material_colours``) as its nodes give them (bpy), and
    ``later(notes)`` -> (reflectivity, emission, scale, offset, lobe) (``transport_terms``) once
    its images' averages are known (no bpy: any thread), their notes added to ``notes``."""
    notes = []
    if material is None:
        return notes, _known(np.array(DEFAULT_GREY), np.zeros(3))
    what = f"material '{material.name}'"
    tree = material.node_tree
    uses_nodes = tree is not None
    if uses_nodes and bpy.app.version < (5, 0, 0):
        uses_nodes = bool(material.use_nodes)
    if not uses_nodes:
        return notes, _known(np.array(material.diffuse_color[:3], dtype=np.float64), np.zeros(3))
    node = _surface_shader(tree)
    if node is None or node.bl_idname not in _SUPPORTED:
        found = next((n for n in tree.nodes if n.bl_idname in _SUPPORTED), None)
        kind = "nothing" if node is None else f"'{node.name}'"
        if found is None:
            notes.append(f"{what}: surface is {kind}, no Principled/Diffuse/Emission node; viewport colour used")
            return notes, _known(np.array(material.diffuse_color[:3], dtype=np.float64), np.zeros(3))
        notes.append(f"{what}: surface is {kind}; used node '{found.name}'")
        node = found
    if node.bl_idname == "ShaderNodeBsdfDiffuse":
        colour = _socket_colour(node, "Color", notes, what, per_patch)
        return notes, lambda more: (images.colour(colour, more), np.zeros(3), np.ones(3), np.zeros(3), None)
    base, fields = np.zeros(3), None
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        base = _socket_colour(node, "Base Color", notes, what, per_patch)
        fields = _principled_fields(node, notes, what, filter_glossy())
        notes.extend(_principled_note(node, fields, what))
    name, strength_name = EMISSION[node.bl_idname]
    name = name if name in node.inputs else "Emission"
    strength = _socket_float(node, strength_name, notes, what, 1.0)
    emission = _socket_colour(node, name, notes, what, per_patch, emitting=strength != 0)

    def later(more):
        if fields is None:  # (an Emission node)
            return np.zeros(3), images.colour(emission, more) * strength, np.ones(3), np.zeros(3), None
        colour = images.colour(base, more)
        inputs = principled.PrincipledInputs(base=tuple(float(v) for v in colour), **fields)
        scale, offset = principled.surface_terms(inputs)
        return (scale * colour + offset, images.colour(emission, more) * strength, scale, offset,
                principled.glossy_terms(inputs))

    return notes, later


def _socket_rgb(node, name, notes, what):
    socket = node.inputs.get(name)
    if socket is None:
        return (1.0, 1.0, 1.0)
    if socket.is_linked:
        notes.append(f"{what}: '{name}' of '{node.name}' is connected (texture?); its own value "
                     f"{_text(socket.default_value[:3])} was used")
    return tuple(float(v) for v in socket.default_value[:3])


def filter_glossy():
    """The scene's Cycles Filter Glossy (its default 1 without Cycles): it dims lobes after a diffuse bounce."""
    cycles = getattr(bpy.context.scene, "cycles", None)
    return max(float(getattr(cycles, "blur_glossy", 1.0)), 0.0)


def _principled_fields(node, notes, what, blur):
    """The fields of core.principled.PrincipledInputs of a Principled BSDF node but its base
    colour (a dict), for light that reaches it by a diffuse bounce under Filter Glossy ``blur``."""
    def value(name, default):
        return _socket_float(node, name, notes, what, default) if name in node.inputs else default

    return dict(
        metallic=value("Metallic", 0.0),
        roughness=value("Roughness", 0.5),
        ior=value("IOR", 1.5),
        specular_ior_level=value("Specular IOR Level", 0.5),
        specular_tint=_socket_rgb(node, "Specular Tint", notes, what),
        transmission=value("Transmission Weight", 0.0),
        coat=value("Coat Weight", 0.0),
        coat_roughness=value("Coat Roughness", 0.03),
        coat_ior=value("Coat IOR", 1.5),
        coat_tint=_socket_rgb(node, "Coat Tint", notes, what),
        multiscatter=getattr(node, "distribution", "MULTI_GGX") == "MULTI_GGX",
        filter_glossy=blur,
    )


def surface_terms(material, blur=0.0):
    """(scale (3,), offset (3,)) of a material: the light it returns is ``scale * base colour +
    offset`` for the base colour of each point (its image texture or colour attribute); (1, 0) for
    anything but a Principled BSDF. As the camera sees the surface (``blur`` 0); ``transport_terms``
    for the light it passes on in the room."""
    inputs = _material_inputs(material, blur)
    return (np.ones(3), np.zeros(3)) if inputs is None else principled.surface_terms(inputs)


def view_terms(material):
    """``core.principled.view_terms`` of a Principled BSDF's material (the terms as a viewer at
    each cosine sees it), or None for anything else."""
    inputs = _material_inputs(material, 0.0)
    return None if inputs is None else principled.view_terms(inputs)


def transport_terms(material):
    """``surface_terms`` of the light passed on from surface to surface (under Filter Glossy): solved;
    and the glossy lobe's (share, alpha) (core.principled.glossy_terms; None but for a Principled BSDF)."""
    inputs = _material_inputs(material, filter_glossy())
    if inputs is None:
        return np.ones(3), np.zeros(3), None
    return (*principled.surface_terms(inputs), principled.glossy_terms(inputs))


def _material_inputs(material, blur):
    """The PrincipledInputs of a material's terms; its base colour read only where they depend
    on it (metallic), so a dielectric's image is not read (nor converted) for them."""
    node = shader_node(material)
    if node is None or node.bl_idname != "ShaderNodeBsdfPrincipled":
        return None
    what = f"material '{material.name}'"
    fields = _principled_fields(node, [], what, blur)
    if float(np.clip(fields["metallic"], 0.0, 1.0)) <= 1e-5:  # (core.principled leaves the metallic layer out)
        return principled.PrincipledInputs(base=(0.0, 0.0, 0.0), **fields)
    image = _linked_image(node.inputs["Base Color"])
    base = images.last_average(image) if image is not None else None
    if base is None:
        base = images.colour(_socket_colour(node, "Base Color", [], what), [])
    return principled.PrincipledInputs(base=tuple(float(v) for v in base), **fields)


def _linked_image(socket):
    """The image of the Image Texture node driving ``socket`` (through reroutes), or None."""
    source = socket.links[0].from_node if socket.is_linked else None
    while source is not None and source.bl_idname == "NodeReroute" and source.inputs[0].is_linked:
        source = source.inputs[0].links[0].from_node
    return source.image if source is not None and source.bl_idname == "ShaderNodeTexImage" else None


#: The tail shared by Principled notes; notes that differ only in the material merge (``selection.merged_notes``).
_LAYERS_COUNTED = ("reflection counted at its hemispherical albedo (the direct light's sent along its lobe where it "
                   "first lands, with the hit exit; the rest as diffuse light)")


def _principled_note(node, p, what):
    """One note naming what a Principled BSDF (its ``_principled_fields`` ``p``) has that is not
    modelled, or none."""
    def used(name, cutoff=1e-5):
        socket = node.inputs.get(name)
        return socket is not None and (socket.is_linked or float(socket.default_value) > cutoff)

    eta, _ = principled.specular_eta_f0(p["ior"], p["specular_ior_level"])
    counted = [name for name, on in (("coat", used("Coat Weight")), ("metallic", used("Metallic")),
                                     ("specular", eta != 1.0)) if on]
    missing = [("view-dependent highlights (shown as under even light, at the camera's angle on a dielectric, else "
                "as their average over view directions; with Live lamps, the lamps' drawn by the renderer)")] if counted else []
    if used("Transmission Weight"):
        missing.append("light through transmission (only its reflection counted)")
    if used("Subsurface Weight"):
        missing.append("subsurface scattering (taken as diffuse)")
    if used("Sheen Weight"):
        missing.append("sheen")
    if used("Anisotropic"):
        missing.append("anisotropy")
    if used("Thin Film Thickness"):
        missing.append("thin film")
    alpha = node.inputs.get("Alpha")
    if alpha is not None and (alpha.is_linked or float(alpha.default_value) < 1.0):
        missing.append("alpha (taken as opaque)")
    if not missing:
        return []
    head = f"Principled {' and '.join(counted)} {_LAYERS_COUNTED}; " if counted else "Principled: "
    return [f"{what}: {head}not modelled: {', '.join(missing)}"]


#: The socket of each shader that gives the base colour, and the emission colour and strength.
BASE = {"ShaderNodeBsdfPrincipled": "Base Color", "ShaderNodeBsdfDiffuse": "Color"}
EMISSION = {"ShaderNodeBsdfPrincipled": ("Emission Color", "Emission Strength"),
             "ShaderNodeEmission": ("Color", "Strength")}


def shader_node(material):
    """The surface shader node of a material that uses nodes, or None."""
    if material is None or material.node_tree is None:
        return None
    if bpy.app.version < (5, 0, 0) and not material.use_nodes:
        return None
    return _surface_shader(material.node_tree)


def material_attribute(material):
    """The name of the colour attribute driving a material's base colour ('' for the active
    one), or None."""
    node = shader_node(material)
    if node is None or node.bl_idname not in BASE or not node.inputs[BASE[node.bl_idname]].is_linked:
        return None
    link = node.inputs[BASE[node.bl_idname]].links[0]
    source = link.from_node
    if source.bl_idname == "ShaderNodeVertexColor" and link.from_socket.name == "Color":
        return source.layer_name
    if source.bl_idname == "ShaderNodeAttribute" and source.attribute_type == "GEOMETRY" \
            and link.from_socket.name == "Color":
        return source.attribute_name
    return None


def material_texture(material):
    """The image texture of a material's base colour, read per patch (``texture_of``), or None."""
    node = shader_node(material)
    if node is None or node.bl_idname not in BASE:
        return None
    return texture_of(node.inputs[BASE[node.bl_idname]])


def material_emission_texture(material):
    """(pixels, affine, UV map, strength) of an image texture driving a material's emission
    colour (Principled 'Emission Color', or an Emission node's 'Color'), its strength a plain
    value; or None."""
    node = shader_node(material)
    if node is None or node.bl_idname not in EMISSION:
        return None
    colour, strength = (node.inputs.get(name) for name in EMISSION[node.bl_idname])
    if colour is None or strength is None or strength.is_linked:
        return None
    texture = texture_of(colour)
    return None if texture is None else (*texture, float(strength.default_value))


def slot_tables(obj, notes):
    """Per material slot (at least one row): its material's name, base-colour texture, colour
    attribute and emission texture (each or None; a texture's pixels as ``images.Pixels``) and
    its ``later`` (``material_reading``), for ``slot_values``."""
    materials = [slot.material for slot in obj.material_slots] or [None]
    textures, attributes, emission_textures, laters = [], [], [], []
    for material in materials:
        texture, attribute = material_texture(material), material_attribute(material)
        emission = material_emission_texture(material)
        node = shader_node(material)
        per_patch = set()
        if texture is not None or attribute is not None:
            per_patch.add(BASE[node.bl_idname])
        if emission is not None:
            per_patch.add(EMISSION[node.bl_idname][0])
        more, later = material_reading(material, per_patch)
        notes.extend(more)
        textures.append(texture)
        attributes.append(attribute)
        emission_textures.append(emission)
        laters.append(later)
    names = tuple("(no material)" if m is None else m.name for m in materials)
    return names, tuple(textures), tuple(attributes), tuple(emission_textures), tuple(laters)


def slot_values(laters, textures, emission_textures, notes, memo=None):
    """Reflectivity (S,3), emission (S,3), base-colour and emission textures and surface terms
    (scale, offset, lobe) of the slots of ``slot_tables`` (no bpy: any thread; their images read
    here). A base-colour texture's pixels come back as reflectivity (scale * colour + offset)."""
    R, E = np.empty((len(laters), 3)), np.empty((len(laters), 3))
    made, emitted, terms = [], [], []
    for k, (later, texture, emission) in enumerate(zip(laters, textures, emission_textures)):
        R[k], E[k], scale, offset, lobe = later(notes)
        if texture is not None:
            pixels = texture[0].read()[0]
            if not (np.all(scale == 1) and np.all(offset == 0)):
                pixels = images.scaled(pixels, scale, offset, memo)
            texture = (pixels, *texture[1:])
        made.append(texture)
        emitted.append(None if emission is None else (emission[0].read()[0], *emission[1:]))
        terms.append((scale, offset, lobe))
    return R, E, tuple(made), tuple(emitted), tuple(terms)
