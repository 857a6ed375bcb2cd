"""The scene's light sources as relighting reads them (bpy): each lamp's, the world's and each
emissive material's emission (strength x colour, what relighting scales) and signature (all the
rest that shapes its light: place, shape, size, spot angles, the world's other nodes), and a
signature of the solved objects' geometry."""

from __future__ import annotations

import hashlib

import bpy
import numpy as np

from .objects import is_result_object
from .lights import added_for_eevee, world_gives_light
from .materials import EMISSION, shader_node
from .objects import SOURCE_TYPES

# The lamp settings besides strength and colour that shape its light (by type).
LAMP_SHAPE = ("type", "shadow_soft_size", "spot_size", "spot_blend", "show_cone", "size", "size_y", "shape", "angle",
              "normalize", "use_shadow", "use_soft_falloff", "spread")


def _digest(values):
    return hashlib.blake2b(repr(values).encode(), digest_size=8).hexdigest()


def _rounded(values):
    return tuple(round(float(v), 6) for v in values)


def lamp_emission(obj):
    """(3,) the lamp's colour x strength as the solve reads it; 0 where it is hidden or off."""
    data = obj.data
    if obj.hide_render or not obj.visible_get() or not getattr(obj, "visible_diffuse", True):
        return np.zeros(3)
    colour = np.array(data.color[:3], np.float64)
    if getattr(data, "use_temperature", False):
        colour = colour * np.array(data.temperature_color[:3], np.float64)
    return colour * float(data.energy) * 2.0 ** float(getattr(data, "exposure", 0.0))


def lamp_signature(obj):
    data = obj.data
    shape = tuple(getattr(data, name) for name in LAMP_SHAPE if hasattr(data, name))
    return _digest((_rounded(v for row in obj.matrix_world for v in row), shape))


def background_node(world):
    tree = world.node_tree
    if tree is None:
        return None
    return next((n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground"), None)


def world_emission(world):
    """(3,) the world's background colour x strength (an image: its strength)."""
    node = background_node(world)
    if node is None:
        return np.array(world.color[:3], np.float64)
    colour = np.ones(3) if node.inputs["Color"].is_linked else np.array(node.inputs["Color"].default_value[:3])
    strength = 1.0 if node.inputs["Strength"].is_linked else float(node.inputs["Strength"].default_value)
    return colour * strength


def world_signature(world):
    """Every node of the world but its background's colour and strength."""
    tree = world.node_tree
    if tree is None:
        return "no nodes"
    background = background_node(world)
    parts = []
    for node in sorted((n for n in tree.nodes if not added_for_eevee(n)), key=lambda n: n.name):
        image = getattr(node, "image", None)
        inputs = [(s.name, _value(s)) for s in node.inputs
                  if not (node == background and s.name in ("Color", "Strength"))]
        parts.append((node.bl_idname, node.name, image.name if image is not None else "", inputs))
    parts.append(sorted((l.from_node.name, l.from_socket.name, l.to_node.name, l.to_socket.name) for l in tree.links
                        if not added_for_eevee(l.to_node)))
    return _digest(parts)


def _value(socket):
    value = getattr(socket, "default_value", None)
    try:
        return _rounded(value)
    except TypeError:
        return round(float(value), 6) if isinstance(value, float) else str(value)


def material_emission(material):
    """(3,) the material's emission colour x strength (a linked factor counts as 1)."""
    node = shader_node(material) if material is not None else None
    if node is None or node.bl_idname not in EMISSION:
        return np.zeros(3)
    colour, strength = (node.inputs[name] for name in EMISSION[node.bl_idname])
    c = np.ones(3) if colour.is_linked else np.array(colour.default_value[:3], np.float64)
    return c * (1.0 if strength.is_linked else float(strength.default_value))


def current(scene, members):
    """{(kind, name): (emission (3,), signature or None)} of ``members`` [(kind, name)] as the
    scene has them now (None: gone)."""
    out = {}
    for kind, name in members:
        if kind == "light":
            obj = scene.objects.get(name)
            out[(kind, name)] = (None, None) if obj is None or obj.type != "LIGHT" else (lamp_emission(obj),
                                                                                         lamp_signature(obj))
        elif kind == "world":
            world = scene.world
            ok = world is not None and world.name == name
            out[(kind, name)] = (world_emission(world), world_signature(world)) if ok else (None, None)
        else:
            material = bpy.data.materials.get(name)
            out[(kind, name)] = (None, None) if material is None else (material_emission(material), "")
    return out


def snapshot(scene):
    """What every possible source is now ({(kind, name): (emission, signature)}): taken when a
    solve starts, so that its strengths are the ones it solved with."""
    members = [("light", o.name) for o in scene.objects if o.type == "LIGHT"]
    members += [("world", scene.world.name)] if scene.world is not None else []
    members += [("material", m.name) for m in bpy.data.materials if material_emission(m).any()]
    return current(scene, members)


def added_lamps(scene, known):
    """Names of the lamps that light the scene now and are not among ``known`` names."""
    return sorted(o.name for o in scene.objects
                  if o.type == "LIGHT" and o.name not in known and lamp_emission(o).any())


def new_light(scene, members, solved, rest_of_scene):
    """What lights the scene now that a solve of the objects named ``solved`` did not have, its
    sources ``members`` [(kind, name)]: the world lit where it was not a source ("world W"), a
    material that emits on a solved object and was not ("material M"), and with ``rest_of_scene``
    (which then takes part) an object since added that emits ("object O")."""
    known, solved = set(members), set(solved)
    out = []
    if scene.world is not None and ("world", scene.world.name) not in known and world_gives_light(scene):
        out.append(f"world {scene.world.name}")
    for obj in sorted(scene.objects, key=lambda o: o.name):
        if obj.name in solved:
            out += [f"material {m.name}" for m in _emitting(obj) if ("material", m.name) not in known]
        elif rest_of_scene and obj.type in SOURCE_TYPES and not obj.hide_render and not is_result_object(obj) \
                and _emitting(obj):
            out.append(f"object {obj.name}")
    return list(dict.fromkeys(out))


def _emitting(obj):
    """The materials that emit on faces of ``obj`` (a mesh's slots that no face uses left out)."""
    slots = [slot.material for slot in getattr(obj, "material_slots", ())]
    emitting = [k for k, m in enumerate(slots) if m is not None and material_emission(m).any()]
    if emitting and obj.type == "MESH" and len(slots) > 1:
        index = np.zeros(len(obj.data.polygons), np.int32)
        obj.data.polygons.foreach_get("material_index", index)
        used = set(np.unique(np.minimum(index, len(slots) - 1)).tolist())
        emitting = [k for k in emitting if k in used]
    return [slots[k] for k in emitting]


def geometry_signature(scene, names):
    """A digest of the named objects' world placement, geometry and materials' base colours
    (what every source's result depends on); objects gone count as a change."""
    digest = hashlib.blake2b(digest_size=12)
    for name in names:
        obj = scene.objects.get(name)
        if obj is None:
            digest.update(b"gone " + name.encode())
            continue
        digest.update(np.array([v for row in obj.matrix_world for v in row], np.float32).tobytes())
        mesh = obj.data if obj.type == "MESH" else None
        if mesh is not None:
            co = np.empty(len(mesh.vertices) * 3, np.float32)
            mesh.vertices.foreach_get("co", co)
            digest.update(co.tobytes())
            digest.update(np.int64(len(mesh.polygons)).tobytes())
            for material in mesh.materials:
                node = shader_node(material) if material is not None else None
                base = node.inputs[0] if node is not None and len(node.inputs) else None
                digest.update(repr(_value(base) if base is not None else None).encode())
    return digest.hexdigest()
