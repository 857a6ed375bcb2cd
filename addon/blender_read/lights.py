"""Reading Blender's lights and world as the core's light sources, in Cycles' units.

Cycles (intern/cycles/scene/light.cpp, kernel/light/*.h) takes a lamp's strength as colour x
power and turns it into radiance; a diffuse surface of albedo R then shows R / pi times the
irradiance. The radiosity written is what a Cycles bake shows (an emissive material of strength
S has radiance S), so a light's quantities in the core's units are (docs/lights.md):

- point and spot, power P: intensity P / (4 pi^2) (Cycles' eval_fac 1 / (4 pi) of a point, over
  pi); a radius r is a sphere of that intensity; a spot's mask is Cycles' smoothstep of
  (cos - cos(size / 2)) / ((1 - cos(size / 2)) blend);
- area, power P over its area A (object scale included): exitance P / (pi A);
- sun, strength S (W/m^2): irradiance S / pi;
- world, colour C x strength S: the radiance C S of the sky, an unoccluded plane's W = C S.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from ..core.lights.lights import AreaLight, PointLight, Spot, SunLight, WorldLight
from .images import pixels_of

POINT_INTENSITY = 1.0 / (4.0 * math.pi**2)  # per watt
AREA_EXITANCE = 1.0 / math.pi  # per watt per square metre
SUN_IRRADIANCE = 1.0 / math.pi  # per W/m^2 of strength


class LightError(ValueError):
    """A light the solve cannot use; the message names it."""


def read_lights(depsgraph, notes):
    """The core lights of every light object that renders in the view layer (selected or not,
    as Cycles lights them). Zero power: left out, with a note; negative or not finite: refused."""
    lights = []
    for instance in depsgraph.object_instances:
        obj = instance.object
        if obj.type != "LIGHT":
            continue
        original = obj.original
        if getattr(original, "hide_render", False):
            continue
        if not getattr(original, "visible_diffuse", True):
            notes.append(f"light '{original.name}' is not visible to diffuse rays (Ray Visibility): left out, "
                         "as Cycles leaves it out of diffuse light")
            continue
        light = read_light(obj.data, np.array(instance.matrix_world), original.name, notes)
        if light is not None:
            lights.append(light)
    return lights


def read_light(data, matrix, name, notes):
    """One Blender light (``bpy.types.Light``) at ``matrix`` (4,4) world as a core light, or None."""
    colour = np.array(data.color[:3], dtype=np.float64)
    if getattr(data, "use_temperature", False):  # Cycles multiplies the colour by the blackbody's
        colour = colour * np.array(data.temperature_color[:3], dtype=np.float64)
    power = float(data.energy) * 2.0 ** float(getattr(data, "exposure", 0.0))
    what = "strength" if data.type == "SUN" else "power"
    if not (np.isfinite(colour).all() and math.isfinite(power)):
        raise LightError(f"light '{name}': its colour or {what} is not a finite number")
    if power < 0 or (colour < 0).any():
        raise LightError(f"light '{name}' has a negative {what} or colour: a light cannot take light away")
    if power == 0 or not colour.any():
        notes.append(f"light '{name}' has no {what}: left out")
        return None
    if getattr(data, "use_nodes", False):
        notes.append(f"light '{name}': its node tree is not read; its colour and {what} were used")
    # Without Normalize, Cycles does not divide the power by the light's area (its own area of a
    # point light of radius 0 is 4, of a sun of angle 0 is 1).
    unnormalized = not getattr(data, "normalize", True)
    shadow = bool(getattr(data, "use_shadow", True))
    _check_finite(name, data, matrix)
    position = matrix[:3, 3]
    axes = matrix[:3, :3]
    down = -axes[:, 2] / np.linalg.norm(axes[:, 2])  # lights shine along their local -Z
    if data.type in ("POINT", "SPOT"):
        intensity = colour * power * POINT_INTENSITY
        spot = None
        if data.type == "SPOT":
            cos_outer = math.cos(0.5 * float(data.spot_size))
            cos_inner = cos_outer + (1.0 - cos_outer) * float(data.spot_blend)
            spot = Spot(axis=down, cos_outer=cos_outer, cos_inner=min(cos_inner, 1.0), to_local=_spot_frame(axes, name))
        radius = float(getattr(data, "shadow_soft_size", 0.0))
        if unnormalized:
            intensity = intensity * (4.0 * math.pi * radius**2 if radius > 0 else 4.0)
        soft = bool(getattr(data, "use_soft_falloff", False))
        return PointLight(position, intensity, radius=radius, spot=spot, name=name, casts_shadow=shadow, soft_falloff=soft)
    if data.type == "AREA":
        if float(getattr(data, "spread", math.pi)) < math.pi - 1e-6:
            raise LightError(f"area light '{name}': a spread below 180 degrees is not supported; set Spread to 180")
        shape = data.shape
        size_u = float(data.size)
        size_v = float(data.size_y) if shape in ("RECTANGLE", "ELLIPSE") else size_u
        half_u = 0.5 * size_u * axes[:, 0]
        half_v = 0.5 * size_v * axes[:, 1]
        ellipse = shape in ("DISK", "ELLIPSE")
        area = 4.0 * float(np.linalg.norm(np.cross(half_u, half_v))) * (math.pi / 4.0 if ellipse else 1.0)
        if not area > 0:
            notes.append(f"area light '{name}' has no area: left out")
            return None
        exitance = colour * power * AREA_EXITANCE / (1.0 if unnormalized else area)
        return AreaLight(position, half_u, half_v, down, exitance, ellipse=ellipse, name=name, casts_shadow=shadow)
    if data.type == "SUN":
        angle = float(data.angle)
        disc = math.pi * math.sin(0.5 * angle) ** 2 if angle > 0 else 1.0
        return SunLight(down, colour * power * SUN_IRRADIANCE * (disc if unnormalized else 1.0), angle=angle, name=name,
                        casts_shadow=shadow)
    notes.append(f"light '{name}' of type {data.type} is not supported: left out")
    return None


# The settings each kind of light reads, by the name the user sees.
SIZES = {"POINT": {"radius": "shadow_soft_size"},
         "SPOT": {"radius": "shadow_soft_size", "spot size": "spot_size", "spot blend": "spot_blend"},
         "AREA": {"size": "size", "size Y": "size_y"},
         "SUN": {"angle": "angle"}}


def _check_finite(name, data, matrix):
    """LightError naming the light and the setting where its place or a size is NaN or infinite
    (from a driver or a script): its light would go nowhere, leaving the scene dark."""
    if not np.isfinite(matrix[:3, 3]).all():
        raise LightError(f"light '{name}': its location is not a finite number (NaN or infinite)")
    if not np.isfinite(matrix[:3, :3]).all():
        raise LightError(f"light '{name}': its rotation or scale is not a finite number (NaN or infinite)")
    for label, attribute in SIZES.get(data.type, {}).items():
        if not math.isfinite(float(getattr(data, attribute, 0.0))):
            raise LightError(f"light '{name}': its {label} is not a finite number (NaN or infinite)")


def _spot_frame(axes, name):
    """A spot's ``to_local`` where its object is scaled unevenly (Cycles then makes the cone
    elliptical: the inverse matrix, z turned towards the axis), else None (a round cone)."""
    scales = np.linalg.svd(axes, compute_uv=False)
    if not scales.min() > 1e-9 * scales.max():
        raise LightError(f"spot light '{name}' is scaled to nothing along an axis: its cone has no shape")
    if scales.max() - scales.min() <= 1e-6 * scales.max():
        return None
    return np.linalg.inv(axes) * np.array([1.0, 1.0, -1.0])[:, None]


def read_world(scene, notes):
    """The world as a core WorldLight: its Background node's colour x strength (or the world
    colour without nodes), an environment image by its pixels; None where it gives no light."""
    later = world_later(scene, notes)
    return None if later is None else later()


def world_later(scene, notes):
    """``read_world`` as its nodes give it (bpy), a function that makes its WorldLight (no bpy:
    any thread; an environment image's pixels read there); None where it gives no light."""
    world = scene.world
    if world is None:
        return None
    colour, strength, image = _background(world, notes)
    if not (np.isfinite(colour).all() and math.isfinite(strength)):
        raise LightError(f"world '{world.name}': its colour or strength is not a finite number")
    if strength < 0 or (colour < 0).any():
        raise LightError(f"world '{world.name}' has a negative colour or strength")
    if not _gives_light(colour, strength, image):
        return None
    name = world.name
    if image is not None:
        pixels = image_pixels(image, name)
        return lambda: WorldLight(image=pixels() * strength, name=name)
    return lambda: WorldLight(irradiance=colour * strength, name=name)


def world_gives_light(scene):
    """Whether ``read_world`` finds light in the scene's world (without reading an image's pixels)."""
    if scene.world is None:
        return False
    colour, strength, image = _background(scene.world, [])
    valid = np.isfinite(colour).all() and math.isfinite(strength) and strength >= 0 and not (colour < 0).any()
    return bool(valid and _gives_light(colour, strength, image))


def _gives_light(colour, strength, image):
    return strength > 0 and (image is not None or bool(colour.any()))


# The nodes ``blender_write.eevee_world`` adds to the world for EEVEE (named so): never read here.
EEVEE_WORLD_PREFIX = "Radiosity EEVEE "


def added_for_eevee(node) -> bool:
    return node.name.startswith(EEVEE_WORLD_PREFIX)


def world_output(tree):
    """The world output Cycles renders (Blender's choice for Cycles: an output for Cycles before
    one for every engine, the active one first), or else the first output that is not
    ``added_for_eevee``; None where there is none."""
    chosen = tree.get_output_node("CYCLES")
    if chosen is not None:
        return chosen
    return next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld" and not added_for_eevee(n)), None)


def _background(world, notes):
    """(colour (3,), strength, image or None) of the world's surface."""
    tree = world.node_tree
    if bpy.app.version < (5, 0, 0) and not world.use_nodes:  # (Blender 5 always uses the nodes)
        tree = None
    if tree is None:
        return np.array(world.color[:3], dtype=np.float64), 1.0, None
    output = world_output(tree)
    link = output.inputs["Surface"].links[0] if output is not None and output.inputs["Surface"].is_linked else None
    if link is None:
        return np.zeros(3), 0.0, None
    node = link.from_node
    if node.bl_idname != "ShaderNodeBackground":
        notes.append(f"world '{world.name}': its {node.name} node is not read; the world gives no light here")
        return np.zeros(3), 0.0, None
    strength_socket = node.inputs["Strength"]
    if strength_socket.is_linked:
        notes.append(f"world '{world.name}': its strength is linked to a node; its default value was used")
    strength = float(strength_socket.default_value)
    colour_socket = node.inputs["Color"]
    if colour_socket.is_linked:
        source = colour_socket.links[0].from_node
        if source.bl_idname == "ShaderNodeTexEnvironment" and source.image is not None:
            if source.inputs["Vector"].is_linked:
                notes.append(f"world '{world.name}': the mapping of its environment image is not read; "
                             "the image was used unrotated")
            return np.ones(3), strength, source.image
        notes.append(f"world '{world.name}': its colour comes from a {source.name} node, not read; "
                     "the socket's own colour was used")
    return np.array(colour_socket.default_value[:3], dtype=np.float64), strength, None


def image_pixels(image, world_name):
    """A function giving the (H, W, 3) linear pixels of an equirectangular image, top row first
    (Blender stores the bottom row first), in float64 (no bpy: any thread). An image without
    pixels (a missing file) is a LightError naming it (here): the sky's light is then unknown
    (Cycles renders it magenta), and no made-up sky is solved."""
    made = pixels_of(image)
    if made is None:
        path = bpy.path.abspath(image.filepath) if image.filepath else ""
        where = f"file not found: {path}" if path else "no file"
        raise LightError(f"world '{world_name}': its environment image '{image.name}' has no pixels ({where}); "
                         "find the file (File > External Data) or unlink the image")
    name = image.name

    def pixels():
        linear = made.read()[0].astype(np.float64)
        if not np.isfinite(linear).all() or (linear < 0).any():
            raise LightError(f"world '{world_name}': its environment image '{name}' has pixels that are "
                             "negative or not finite")
        return linear[::-1]

    return pixels
