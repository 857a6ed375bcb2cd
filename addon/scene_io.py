"""Reading the Blender scene into arrays and writing results back (bpy glue).

No numerics here beyond reshaping: the arrays go to ``pipeline`` and come back.

Units: emission = emission colour x strength, reflectivity = base colour, so
the radiosity written is what Cycles' COMBINED bake gives for the same
Lambertian scene (a closed box emitting S with albedo R gives S / (1 - R)).
"""

from __future__ import annotations

import bpy
import numpy as np

from .core import meshing
from .blender_read import lights as lights_io
from .blender_read.images import image_average, linear_pixels
from .bpy_free.patches import ObjectArrays

#: With "Clamp bright colours" on, reflectivity above this is lowered to it (the random walks
#: need R < 1; without the setting, a base colour of 1 or more is refused).
MAX_REFLECTIVITY = 0.99

COLLECTION_NAME = "Radiosity"
ATTRIBUTE_NAME = "Radiosity"
POINT_ATTRIBUTE_NAME = "Radiosity Vertex"  # the POINT colours when both are written
MATERIAL_NAME = "Radiosity Result"
SOURCE_PROPERTY = "radiosity_source"  # custom property marking result objects
COLLECTION_PROPERTY = "radiosity_results"  # custom property marking a scene's results collection
DEFAULT_GREY = (0.8, 0.8, 0.8)
RESULT_SUFFIX = " Radiosity"


class SceneError(ValueError):
    """Bad input found while reading the scene: a message for the user."""


# ---------------------------------------------------------------------------
# Materials
# ---------------------------------------------------------------------------

def _text(colour):
    return "(" + ", ".join(f"{c:.3g}" for c in colour) + ")"


def _linked_colour(socket, node, name, notes, what, emitting=False):
    """The colour of a socket driven by a link: an image's or a checker's average when that is
    known, else the socket's own default; always with a note saying which. An emission colour
    (``emitting``) from an image without pixels is a SceneError: no made-up light is solved."""
    default = np.array(socket.default_value[:3], dtype=np.float64)
    source = socket.links[0].from_node
    while source.bl_idname == "NodeReroute" and source.inputs[0].is_linked:
        source = source.inputs[0].links[0].from_node
    if source.bl_idname == "ShaderNodeTexImage" and source.image is not None:
        average = image_average(source.image)
        if average is not None:
            notes.append(f"{what}: '{name}' comes from image '{source.image.name}'; "
                         f"its average colour {_text(average)} was used")
            return average
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


def texture_of(socket):
    """(pixels, affine (2,3), UV map name or '') of an image texture driving ``socket`` through
    a UV map and at most one affine Mapping node, or None where it is anything else."""
    if not socket.is_linked:
        return None
    node = socket.links[0].from_node
    while node.bl_idname == "NodeReroute" and node.inputs[0].is_linked:
        node = node.inputs[0].links[0].from_node
    if node.bl_idname != "ShaderNodeTexImage" or node.image is None or node.projection != "FLAT":
        return None
    affine, uv_name = np.eye(2, 3), ""
    vector = node.inputs["Vector"]
    if vector.is_linked:
        link = vector.links[0]
        if link.from_node.bl_idname == "ShaderNodeMapping":
            affine = _mapping_affine(link.from_node)
            if affine is None or not link.from_node.inputs["Vector"].is_linked:
                return None
            link = link.from_node.inputs["Vector"].links[0]
        if link.from_node.bl_idname == "ShaderNodeUVMap":
            uv_name = link.from_node.uv_map
        elif not (link.from_node.bl_idname == "ShaderNodeTexCoord" and link.from_socket.name == "UV"):
            return None
    pixels = linear_pixels(node.image)
    if pixels is None:
        return None
    return pixels, affine, uv_name


def _mapping_affine(node):
    """The 2D affine map of a Mapping node (Point or Texture type, rotation about Z only, no
    linked inputs), or None."""
    if node.vector_type not in ("POINT", "TEXTURE"):
        return None
    inputs = {name: node.inputs[name] for name in ("Location", "Rotation", "Scale")}
    if any(socket.is_linked for socket in inputs.values()):
        return None
    location = np.array(inputs["Location"].default_value[:2], dtype=np.float64)
    rx, ry, rz = inputs["Rotation"].default_value[:3]
    if abs(rx) > 1e-9 or abs(ry) > 1e-9:
        return None
    scale = np.array(inputs["Scale"].default_value[:2], dtype=np.float64)
    rotation = np.array([[np.cos(rz), -np.sin(rz)], [np.sin(rz), np.cos(rz)]])
    linear = rotation @ np.diag(scale)
    if node.vector_type == "TEXTURE":  # the inverse of Point
        if abs(np.linalg.det(linear)) < 1e-12:
            return None
        inverse = np.linalg.inv(linear)
        return np.column_stack([inverse, -inverse @ location])
    return np.column_stack([linear, location])


def _socket_colour(node, name, notes, what, per_patch=(), emitting=False):
    socket = node.inputs.get(name)
    if socket is None:
        return np.zeros(3)
    if socket.is_linked:  # sockets read per patch need no note about their average
        return _linked_colour(socket, node, name, [] if name in per_patch else notes, what, emitting)
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

    Principled BSDF: base colour, emission colour x strength.  Diffuse BSDF:
    colour.  Emission: colour x strength, no reflection.  No node tree: the
    viewport colour.  No material: grey 0.8.  Linked (textured) inputs use
    the socket's default and add a note.
    """
    notes = []
    if material is None:
        return np.array(DEFAULT_GREY), np.zeros(3), notes
    what = f"material '{material.name}'"
    tree = material.node_tree
    uses_nodes = tree is not None
    if uses_nodes and bpy.app.version < (5, 0, 0):
        uses_nodes = bool(material.use_nodes)
    if not uses_nodes:
        return np.array(material.diffuse_color[:3], dtype=np.float64), np.zeros(3), notes
    node = _surface_shader(tree)
    if node is None or node.bl_idname not in _SUPPORTED:
        found = next((n for n in tree.nodes if n.bl_idname in _SUPPORTED), None)
        kind = "nothing" if node is None else f"'{node.name}'"
        if found is None:
            notes.append(f"{what}: surface is {kind}, no Principled/Diffuse/Emission node; viewport colour used")
            return np.array(material.diffuse_color[:3], dtype=np.float64), np.zeros(3), notes
        notes.append(f"{what}: surface is {kind}; used node '{found.name}'")
        node = found
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        reflectivity = _socket_colour(node, "Base Color", notes, what, per_patch)
        name = "Emission Color" if "Emission Color" in node.inputs else "Emission"
        strength = _socket_float(node, "Emission Strength", notes, what, 1.0)
        emission = _socket_colour(node, name, notes, what, per_patch, emitting=strength != 0) * strength
    elif node.bl_idname == "ShaderNodeBsdfDiffuse":
        reflectivity = _socket_colour(node, "Color", notes, what, per_patch)
        emission = np.zeros(3)
    else:  # Emission
        reflectivity = np.zeros(3)
        strength = _socket_float(node, "Strength", notes, what, 1.0)
        emission = _socket_colour(node, "Color", notes, what, per_patch, emitting=strength != 0) * strength
    return reflectivity, emission, notes


#: The socket of each shader that gives the base colour, and the emission colour and strength.
_BASE = {"ShaderNodeBsdfPrincipled": "Base Color", "ShaderNodeBsdfDiffuse": "Color"}
_EMISSION = {"ShaderNodeBsdfPrincipled": ("Emission Color", "Emission Strength"),
             "ShaderNodeEmission": ("Color", "Strength")}


def _shader_node(material):
    """The surface shader node of a material that uses nodes, or None."""
    if material is None or material.node_tree is None:
        return None
    if bpy.app.version < (5, 0, 0) and not material.use_nodes:
        return None
    return _surface_shader(material.node_tree)


def material_attribute(material):
    """The name of the colour attribute driving a material's base colour ('' for the active
    one), or None."""
    node = _shader_node(material)
    if node is None or node.bl_idname not in _BASE or not node.inputs[_BASE[node.bl_idname]].is_linked:
        return None
    link = node.inputs[_BASE[node.bl_idname]].links[0]
    source = link.from_node
    if source.bl_idname == "ShaderNodeVertexColor" and link.from_socket.name == "Color":
        return source.layer_name
    if source.bl_idname == "ShaderNodeAttribute" and source.attribute_type == "GEOMETRY" \
            and link.from_socket.name == "Color":
        return source.attribute_name
    return None


def material_texture(material):
    """The image texture of a material's base colour, read per patch (``texture_of``), or None."""
    node = _shader_node(material)
    if node is None or node.bl_idname not in _BASE:
        return None
    return texture_of(node.inputs[_BASE[node.bl_idname]])


def material_emission_texture(material):
    """(pixels, affine, UV map, strength) of an image texture driving a material's emission
    colour (Principled 'Emission Color', or an Emission node's 'Color'), its strength a plain
    value; or None."""
    node = _shader_node(material)
    if node is None or node.bl_idname not in _EMISSION:
        return None
    colour, strength = (node.inputs.get(name) for name in _EMISSION[node.bl_idname])
    if colour is None or strength is None or strength.is_linked:
        return None
    texture = texture_of(colour)
    return None if texture is None else (*texture, float(strength.default_value))


def _slot_tables(obj, notes):
    """Reflectivity, emission, material name, base-colour texture, colour attribute and
    emission texture (each or None) of each material slot (at least one row)."""
    materials = [slot.material for slot in obj.material_slots] or [None]
    R = np.empty((len(materials), 3))
    E = np.empty((len(materials), 3))
    textures, attributes, emission_textures = [], [], []
    for k, material in enumerate(materials):
        texture, attribute = material_texture(material), material_attribute(material)
        emission = material_emission_texture(material)
        node = _shader_node(material)
        per_patch = set()
        if texture is not None or attribute is not None:
            per_patch.add(_BASE[node.bl_idname])
        if emission is not None:
            per_patch.add(_EMISSION[node.bl_idname][0])
        R[k], E[k], more = material_colours(material, per_patch)
        textures.append(texture)
        attributes.append(attribute)
        emission_textures.append(emission)
        notes.extend(more)
    names = tuple("(no material)" if m is None else m.name for m in materials)
    return R, E, names, tuple(textures), tuple(attributes), tuple(emission_textures)


# ---------------------------------------------------------------------------
# Reading objects
# ---------------------------------------------------------------------------

#: Object types whose evaluated geometry becomes a mesh (curves, text, surfaces and metaballs
#: as Blender tessellates them for display and render).
SOURCE_TYPES = ("MESH", "CURVE", "FONT", "SURFACE", "META")


def is_result_object(obj) -> bool:
    return obj is not None and SOURCE_PROPERTY in obj.keys()


def source_objects(context):
    """Selected mesh objects that take part, sorted by name (the patch order)."""
    selected = getattr(context, "selected_objects", None)
    if selected is None:  # window-less contexts (timers): the view layer's selection
        selected = [o for o in context.view_layer.objects if o.select_get()]
    objs = [o for o in selected if o.type in SOURCE_TYPES and not is_result_object(o)]
    return sorted(objs, key=lambda o: o.name)


def _get(collection, attr, count, dtype, width=1):
    out = np.empty(count * width, dtype=dtype)
    if count:
        collection.foreach_get(attr, out)
    return out.reshape(-1, width) if width > 1 else out


def _per_face(table, slot):
    """(F,3) the rows of a per-slot table for each face: where every slot has the same values
    (one material), one row broadcast to every face (a read-only view, no memory per face)."""
    if (table == table[0]).all():
        return np.broadcast_to(table[0], (len(slot), table.shape[1]))
    return table[slot]


def read_object(obj, depsgraph, notes) -> ObjectArrays | None:
    """Arrays of one object: evaluated (modifiers), world space, outward winding."""
    return _read_evaluated(obj.evaluated_get(depsgraph), obj.matrix_world, obj.name, obj.session_uid, notes)


def read_instances(parents, depsgraph, notes):
    """Mesh instances made by the given objects -- collection instances, geometry-nodes
    instances, instancing on vertices or faces -- each as its own arrays, named 'Parent [k]'
    and tied to its parent (for the check that the source still exists)."""
    by_uid = {p.session_uid: p for p in parents}
    out, counts, other = [], {}, {}
    for inst in depsgraph.object_instances:
        if not inst.is_instance or inst.parent is None:
            continue
        parent = inst.parent.original
        if parent.session_uid not in by_uid:
            continue
        obj = inst.object
        if parent.type != "MESH" and obj.original == parent:
            continue  # a curve's or text's own tessellation, already read through to_mesh
        if obj.type not in SOURCE_TYPES or is_result_object(obj.original):
            other[parent.name] = other.get(parent.name, 0) + (obj.type not in SOURCE_TYPES)
            continue
        k = counts.get(parent.name, 0)
        counts[parent.name] = k + 1
        arrays = _read_evaluated(obj, inst.matrix_world.copy(), f"{parent.name} [{k}]", parent.session_uid, notes)
        if arrays is not None:
            out.append(arrays)
    for name, n in other.items():
        if n:
            notes.append(f"'{name}': {n} instances that are not meshes were skipped")
    return out


def _read_evaluated(evaluated, matrix_world, name, uid, notes) -> ObjectArrays | None:
    mesh = evaluated.to_mesh()
    try:
        V = len(mesh.vertices)
        F = len(mesh.polygons)
        if F == 0:
            if not _has_instances(evaluated):
                notes.append(f"'{name}' has no faces and was skipped")
            return None
        # (indices stay int32, as Blender keeps them: half of int64's memory)
        co = _get(mesh.vertices, "co", V, np.float32, 3).astype(np.float64)
        face_sizes = _get(mesh.polygons, "loop_total", F, np.int32)
        loop_start = _get(mesh.polygons, "loop_start", F, np.int32)
        material_index = _get(mesh.polygons, "material_index", F, np.int32)
        loop_vertex = _get(mesh.loops, "vertex_index", len(mesh.loops), np.int32)
        # corners face by face (loop_start is normally already in order)
        if (F and loop_start[0] != 0) or np.any(loop_start[1:] < loop_start[:-1]):
            raise SceneError(f"'{name}': unexpected corner order")
        del loop_start
        corner_verts = loop_vertex
        mesh.calc_loop_triangles()
        T = len(mesh.loop_triangles)
        triangles = _get(mesh.loop_triangles, "vertices", T, np.int32, 3)
        triangle_face = _get(mesh.loop_triangles, "polygon_index", T, np.int32)
        R_slots, E_slots, slot_names, textures, attributes, emission_textures = _slot_tables(evaluated, notes)
        triangle_uv = None
        if any(t is not None for t in (*textures, *emission_textures)):
            triangle_uv, kept = _triangle_uv(mesh, T, (*textures, *emission_textures), name, notes)
            textures, emission_textures = kept[: len(textures)], kept[len(textures):]
        slot_colours = _attribute_colours(mesh, T, triangles, attributes, name, notes)
    finally:
        evaluated.to_mesh_clear()
    M = np.array(matrix_world, dtype=np.float64)
    vertices = co @ M[:3, :3].T + M[:3, 3]
    if np.linalg.det(M[:3, :3]) < 0:  # negative scale: keep normals outward
        corner_verts = meshing.reverse_faces(face_sizes, corner_verts)
        triangles = triangles[:, ::-1].copy()
        if triangle_uv is not None:
            triangle_uv = triangle_uv[:, ::-1].copy()
        slot_colours = tuple(None if c is None else c[:, ::-1].copy() for c in slot_colours)
    slot = np.clip(material_index, 0, len(R_slots) - 1)
    return ObjectArrays(
        name=name,
        uid=int(uid),
        face_slot=slot,
        slot_names=slot_names,
        vertices=vertices,
        face_sizes=face_sizes,
        corner_verts=corner_verts,
        triangles=triangles,
        triangle_face=triangle_face,
        face_reflectivity=_per_face(R_slots, slot),
        face_emission=_per_face(E_slots, slot),
        triangle_uv=triangle_uv,
        slot_textures=textures if triangle_uv is not None else (),
        slot_emission_textures=emission_textures if triangle_uv is not None else (),
        slot_colours=slot_colours if any(c is not None for c in slot_colours) else (),
    )


def _attribute_colours(mesh, T, triangles, attributes, name, notes):
    """Per slot, (T,3,3) linear colours of the colour attribute its base colour reads, at the
    loop triangles' corners; None for slots without one (or whose attribute is missing, said so)."""
    out = []
    loops = None
    for attribute in attributes:
        if attribute is None:
            out.append(None)
            continue
        layer = mesh.color_attributes.get(attribute) if attribute else mesh.color_attributes.active_color
        if layer is None or layer.domain not in ("CORNER", "POINT"):
            notes.append(f"'{name}': colour attribute '{attribute}' not found (or not on corners or points); "
                         "the base colour's own value was used")
            out.append(None)
            continue
        values = np.empty(len(layer.data) * 4, dtype=np.float32)
        layer.data.foreach_get("color", values)  # (scene linear, for byte colours too)
        rgb = values.reshape(-1, 4)[:, :3].astype(np.float64)
        if layer.domain == "CORNER":
            if loops is None:
                loops = _get(mesh.loop_triangles, "loops", T, np.int32, 3).astype(np.int64)
            out.append(rgb[loops])
        else:
            out.append(rgb[triangles])
    return tuple(out)


def _triangle_uv(mesh, T, textures, name, notes):
    """((T,3,2) UVs of the loop triangles' corners, the textures kept): one UV map, the one the
    textures name (or the render map); textures naming another are averaged instead, said so."""
    wanted = {t[2] for t in textures if t is not None}
    layer_name = next(iter(wanted)) if len(wanted) == 1 else ""
    layer = mesh.uv_layers.get(layer_name) if layer_name else None
    layer = layer or getattr(mesh.uv_layers, "active_render", None) or mesh.uv_layers.active
    if layer is None:
        notes.append(f"'{name}' has no UV map: its image textures were averaged over the whole image")
        return None, (None,) * len(textures)
    loops = len(mesh.loops)
    uv = np.empty(loops * 2, dtype=np.float32)
    layer.uv.foreach_get("vector", uv)
    triangle_loops = _get(mesh.loop_triangles, "loops", T, np.int32, 3).astype(np.int64)
    kept = []
    for t in textures:
        if t is not None and t[2] and t[2] != layer.name:
            notes.append(f"'{name}': a texture reads UV map '{t[2]}' beside '{layer.name}'; it was averaged")
            t = None
        kept.append(t)
    return uv.reshape(-1, 2).astype(np.float64)[triangle_loops], tuple(kept)


def _has_instances(evaluated):
    try:
        geometry = evaluated.evaluated_geometry()  # held: the point cloud lives in it
        points = geometry.instances_pointcloud()
        return points is not None and len(points.points) > 0
    except Exception:  # noqa: BLE001 - older Blender: no evaluated_geometry
        return False


def _describe(obj):
    kind = obj.type.lower()
    if obj.type == "EMPTY" and obj.instance_type == "COLLECTION" and obj.instance_collection is not None:
        return f"'{obj.name}' instances collection '{obj.instance_collection.name}', which holds no mesh"
    return f"'{obj.name}' is a {kind}"


def read_rest_of_scene(context, depsgraph, notes):
    """Arrays of the visible mesh objects that are not selected (not hidden from render, not
    results): they block and reflect light and get no results (``receives`` False)."""
    selected = {o.session_uid for o in source_objects(context)}
    rest = []
    for obj in sorted(context.view_layer.objects, key=lambda o: o.name):
        if obj.type not in SOURCE_TYPES or obj.session_uid in selected or is_result_object(obj) or obj.hide_render:
            continue
        arrays = read_object(obj, depsgraph, [])
        if arrays is not None:
            arrays.receives = False
            rest.append(arrays)
    return rest


def skipped_objects(context):
    """Selected objects that are not meshes (and not results): they take no part."""
    selected = getattr(context, "selected_objects", None)
    if selected is None:
        selected = [o for o in context.view_layer.objects if o.select_get()]
    return sorted((o for o in selected if o.type not in SOURCE_TYPES), key=lambda o: o.name)


def _materials_where(o, bad_faces):
    """Names of the materials of object arrays ``o`` on the faces flagged in ``bad_faces``."""
    slots = np.unique(o.face_slot[bad_faces]) if o.face_slot is not None else []
    return ", ".join(f"'{o.slot_names[k]}'" for k in slots) if len(slots) else "a material"


def read_selection(context):
    """(objects, notes) for the selected meshes; SceneError for bad input.

    Raises, naming the objects and materials, when nothing usable is selected, when no
    selected face emits, or when materials hold values the solver cannot use: NaN,
    negative colours or strengths, and reflectivity (base colour) of 1 or more -- unless
    the scene's "Clamp bright colours" setting is on, which lowers those to
    MAX_REFLECTIVITY and says so.
    """
    notes = []
    candidates = source_objects(context)
    others = skipped_objects(context)
    if not candidates and not others:
        raise SceneError("Select one or more mesh objects (result objects in 'Radiosity' do not count)")
    settings = getattr(context.scene, "radiosity", None)
    clamp = bool(getattr(settings, "clamp_reflectivity", False))
    depsgraph = context.evaluated_depsgraph_get()
    objects = []
    for obj in candidates:
        arrays = read_object(obj, depsgraph, notes)
        if arrays is not None:
            objects.append(arrays)
    # Instances (collection instances, geometry nodes, instancing on vertices or faces) are
    # realised: each instance is read as an object of its own.
    instances = read_instances([*candidates, *others], depsgraph, notes)
    objects.extend(instances)
    receivers = len(objects)
    if getattr(settings, "use_scene_objects", False) and objects:
        objects.extend(read_rest_of_scene(context, depsgraph, notes))
    instancers = {o.uid for o in instances}
    skipped = [o for o in others if o.session_uid not in instancers]
    if not receivers:
        if skipped and not candidates:
            raise SceneError("No mesh among the selected objects: " + "; ".join(_describe(o) for o in skipped))
        raise SceneError("The selected mesh objects have no faces")
    for o in skipped:
        notes.append(_describe(o) + ": skipped")
    for o in objects:
        for name, values in (("base colour", o.face_reflectivity), ("emission", o.face_emission)):
            bad = ~np.isfinite(values).all(axis=1)
            if bad.any():
                raise SceneError(f"'{o.name}': the {name} of material {_materials_where(o, bad)} is not a "
                                 "finite number (NaN or infinite, from a driver or a script?)")
        bad = (o.face_emission < 0).any(axis=1)
        if bad.any():
            raise SceneError(f"'{o.name}': material {_materials_where(o, bad)} has a negative emission "
                             "(colour or strength)")
        bad = (o.face_reflectivity < 0).any(axis=1)
        if bad.any():
            raise SceneError(f"'{o.name}': material {_materials_where(o, bad)} has a negative base colour")
        bright = (o.face_reflectivity >= 1).any(axis=1)
        if bright.any() and not clamp:
            value = float(o.face_reflectivity[bright].max())
            raise SceneError(
                f"'{o.name}': material {_materials_where(o, bright)} has a base colour of {value:.3g}. "
                "Radiosity needs a reflectivity below 1: a surface that reflects all the light it gets "
                "never lets a random walk end in a closed room (and above 1 it creates light). "
                f"Lower the base colour below 1, or turn on 'Clamp bright colours' to use {MAX_REFLECTIVITY}"
            )
        o.slot_textures = _checked_textures(o, clamp, notes)
        over = (o.face_reflectivity > MAX_REFLECTIVITY).any(axis=1)
        if over.any() and clamp:
            notes.append(f"'{o.name}': base colours of material {_materials_where(o, over)} above "
                         f"{MAX_REFLECTIVITY} were clamped to {MAX_REFLECTIVITY} ('Clamp bright colours' is on)")
            o.face_reflectivity = np.minimum(o.face_reflectivity, MAX_REFLECTIVITY)
    try:
        lights = lights_io.read_lights(depsgraph, notes)
        world = lights_io.read_world(context.scene, notes)
    except lights_io.LightError as exc:
        raise SceneError(str(exc)) from exc
    if world is not None:
        lights.append(world)
    if not lights and not any(np.any(o.face_emission > 0) for o in objects):
        raise SceneError(
            "No emitter among the selected objects (nor the rest of the scene) and no light: give a material "
            "an emission strength > 0 (Principled BSDF 'Emission Strength' or an Emission shader), add a "
            "light, or give the world a colour"
        )
    # unique notes, in order
    return Selection(objects, lights), list(dict.fromkeys(notes))


def _checked_textures(o, clamp, notes):
    """The object's textures with the base colour's rules: finite and not negative, below 1
    unless 'Clamp bright colours' lowers them to MAX_REFLECTIVITY (said so)."""
    for slot, colours in enumerate(o.slot_colours):
        if colours is not None:
            where = f"'{o.name}': the colour attribute of material '{o.slot_names[slot]}'"
            if not np.isfinite(colours).all() or (colours < 0).any():
                raise SceneError(f"{where} has colours that are negative or not finite")
            if colours.max() >= 1 and not clamp:
                raise SceneError(f"{where} has colours of {float(colours.max()):.3g}: a reflectivity needs to stay "
                                 f"below 1. Darken them, or turn on 'Clamp bright colours' to use {MAX_REFLECTIVITY}")
    if clamp:
        o.slot_colours = tuple(None if c is None else np.minimum(c, MAX_REFLECTIVITY) for c in o.slot_colours)
    for slot, texture in enumerate(o.slot_emission_textures):
        if texture is not None and (not np.isfinite(texture[0]).all() or (texture[0] < 0).any() or texture[3] < 0):
            raise SceneError(f"'{o.name}': the emission texture of material '{o.slot_names[slot]}' has pixels or a "
                             "strength that are negative or not finite")
    checked = []
    for slot, texture in enumerate(o.slot_textures):
        if texture is not None:
            pixels, affine, uv = texture
            where = f"'{o.name}': the image texture of material '{o.slot_names[slot]}'"
            if not np.isfinite(pixels).all() or (pixels < 0).any():
                raise SceneError(f"{where} has pixels that are negative or not finite")
            if pixels.max() >= 1:
                if not clamp:
                    raise SceneError(f"{where} has pixels of {float(pixels.max()):.3g}: a reflectivity needs to "
                                     "stay below 1. Darken the image, or turn on 'Clamp bright colours' to use "
                                     f"{MAX_REFLECTIVITY}")
                notes.append(f"{where}: pixels above {MAX_REFLECTIVITY} were clamped ('Clamp bright colours' is on)")
                pixels = np.minimum(pixels, MAX_REFLECTIVITY)
            texture = (pixels, affine, uv)
        checked.append(texture)
    return tuple(checked)


class Selection(list):
    """The selected objects' arrays (a list of ObjectArrays), with the lights that light them
    (``lights``: the core's light sources of the scene's lamps and world)."""

    def __init__(self, objects=(), lights=()):
        super().__init__(objects)
        self.lights = tuple(lights)


# ---------------------------------------------------------------------------
# Writing results
# ---------------------------------------------------------------------------

MATERIAL_PROPERTY = "radiosity_result_material"  # marks the material we made


def result_material():
    """The material that shows the 'Radiosity' attribute as emission (ours, never a user's
    material that happens to have the same name)."""
    for material in bpy.data.materials:
        if MATERIAL_PROPERTY in material.keys() and material.node_tree is not None:
            return material
    material = bpy.data.materials.new(MATERIAL_NAME)
    material[MATERIAL_PROPERTY] = True
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = "GEOMETRY"
    attribute.attribute_name = ATTRIBUTE_NAME
    attribute.location = (-400, 0)
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    emission.location = (-150, 0)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.location = (100, 0)
    tree.links.new(attribute.outputs["Color"], emission.inputs["Color"])
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    material.diffuse_color = (1.0, 1.0, 1.0, 1.0)
    return material


def result_collection(scene, create=True):
    """The scene's results collection: "Radiosity" for the first scene solved, "Radiosity.001"
    and so on for others, so that each scene of a file keeps its own results. Found by a
    marker among the scene's top-level collections (the name may be taken or changed)."""
    for collection in scene.collection.children:
        if collection.get(COLLECTION_PROPERTY):
            return collection
    if not create:
        return None
    collection = bpy.data.collections.new(COLLECTION_NAME)
    collection[COLLECTION_PROPERTY] = True
    scene.collection.children.link(collection)
    return collection


def previous_results(scene=None):
    """The result objects a re-run in ``scene`` (default: the context's) replaces: marked
    objects in that scene's results collection only. A result the user copied or moved
    elsewhere is theirs, and other scenes' results are theirs: both are left alone."""
    collection = result_collection(scene if scene is not None else bpy.context.scene, create=False)
    if collection is None:
        return []
    return [o for o in collection.objects if is_result_object(o)]


def _remove_objects(objects):
    for obj in objects:
        mesh = obj.data
        bpy.data.objects.remove(obj, do_unlink=True)
        if mesh is not None and mesh.users == 0:
            bpy.data.meshes.remove(mesh)


def remove_previous_results(scene=None):
    _remove_objects(previous_results(scene))


def _rgba(values):
    values = np.asarray(values, dtype=np.float32).reshape(-1, 3)
    out = np.ones((len(values), 4), dtype=np.float32)
    out[:, :3] = values
    return out.ravel()


def _corner_rgba(patch_mesh, patch_values):
    """``_rgba`` of per-patch values on every corner of its patch (flat colours), made per patch
    and then repeated: no per-corner float64 copy."""
    return np.repeat(_rgba(patch_values).reshape(-1, 4), patch_mesh.face_sizes, axis=0).ravel()


def build_mesh(name, patch_mesh: meshing.PatchMesh):
    """A Blender mesh whose faces are the patches (foreach_set only)."""
    mesh = bpy.data.meshes.new(name)
    pm = patch_mesh
    mesh.vertices.add(len(pm.points))
    mesh.vertices.foreach_set("co", pm.points.astype(np.float32).ravel())
    mesh.loops.add(len(pm.corner_verts))
    mesh.loops.foreach_set("vertex_index", pm.corner_verts.astype(np.int32))
    mesh.polygons.add(pm.patch_count)
    mesh.polygons.foreach_set("loop_start", pm.face_starts.astype(np.int32))
    mesh.update()
    return mesh


def write_colours(mesh, patch_mesh, face_colours, point_colours, output):
    """Add the colour attributes: CORNER (flat per patch) and/or POINT."""
    names = []
    if output in ("FACE", "BOTH"):
        attr = mesh.color_attributes.new(ATTRIBUTE_NAME, "FLOAT_COLOR", "CORNER")
        attr.data.foreach_set("color", _corner_rgba(patch_mesh, face_colours))
        names.append(attr.name)
    if output in ("VERTEX", "BOTH"):
        name = ATTRIBUTE_NAME if output == "VERTEX" else POINT_ATTRIBUTE_NAME
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
        attr.data.foreach_set("color", _rgba(point_colours))
        names.append(attr.name)
    main = mesh.color_attributes.get(ATTRIBUTE_NAME)
    mesh.color_attributes.active_color = main
    try:
        mesh.color_attributes.render_color_index = mesh.color_attributes.active_color_index
    except AttributeError:  # older API
        pass
    return names


def write_extra(mesh, patch_mesh, name, face_values, output):
    """One more attribute (the light alone, the indirect light) on the main one's domain."""
    if output == "VERTEX":
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "POINT")
        attr.data.foreach_set("color", _rgba(meshing.point_average(patch_mesh, face_values)))
    else:
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
        attr.data.foreach_set("color", _corner_rgba(patch_mesh, face_values))
    main = mesh.color_attributes.get(ATTRIBUTE_NAME)
    if main is not None:
        mesh.color_attributes.active_color = main
    return attr.name


def show_attribute_in_solid_view():
    """Let the 3D views' solid shading colour objects by their colour attribute."""
    for screen in bpy.data.screens:
        for area in screen.areas:
            if area.type != "VIEW_3D":
                continue
            for space in area.spaces:
                if space.type == "VIEW_3D":
                    space.shading.color_type = "VERTEX"


def write_results(context, output_data, output_mode, scene=None):
    """Replace the previous results with one object per source object.

    All new objects are built first and only then swapped in for the old ones, so a failure
    part-way leaves the previous results as they were (never a half-written set).
    ``output_data`` is a pipeline.SolveOutput; ``scene`` the scene that was solved (by default
    the context's).  Returns the new objects.
    """
    scene = scene if scene is not None else context.scene
    created = []
    try:
        material = result_material()
        for index, (arrays, pm, faces, points) in enumerate(zip(
            output_data.patches.objects,
            output_data.patches.meshes,
            output_data.face_colours,
            output_data.point_colours,
        )):
            if faces is None:  # an object of the rest of the scene: it took part, gets no result
                continue
            if not (np.isfinite(faces).all() and (points is None or np.isfinite(points).all())):
                raise ValueError(f"the result for '{arrays.name}' is not finite")
            name = arrays.name + RESULT_SUFFIX
            mesh = build_mesh(name, pm)
            obj = bpy.data.objects.new(name, mesh)  # vertices are in world space
            created.append(obj)
            write_colours(mesh, pm, faces, points, output_mode)
            for extra_name, per_object in getattr(output_data, "extra", {}).items():
                write_extra(mesh, pm, extra_name, per_object[index], output_mode)
            mesh.materials.append(material)
            obj[SOURCE_PROPERTY] = arrays.name
    except Exception:
        _remove_objects(created)
        raise
    remove_previous_results(scene)
    collection = result_collection(scene)
    for obj in created:
        collection.objects.link(obj)
        obj.name = obj.data.name = obj[SOURCE_PROPERTY] + RESULT_SUFFIX  # the names the old ones had
    show_attribute_in_solid_view()
    return created
