"""Objects read into arrays: evaluated (modifiers, curves and text tessellated), world space,
outward winding, with their materials per face, as ``bpy_free.patches.ObjectArrays`` (bpy).

No numerics here beyond reshaping: the arrays go to ``pipeline`` and come back.
"""

from __future__ import annotations

import numpy as np

from ..bpy_free.patches import ObjectArrays
from ..bpy_free.surface_layers import SourceLayers
from ..core.mesh import meshing
from . import SceneError
from .materials import slot_tables, slot_values

SOURCE_PROPERTY = "radiosity_source"  # custom property marking our result objects (blender_write.results)


def is_result_object(obj) -> bool:
    """Whether ``obj`` is one of our result objects (never read as a source)."""
    return obj is not None and SOURCE_PROPERTY in obj.keys()


#: Object types whose evaluated geometry becomes a mesh (curves, text, surfaces and metaballs
#: as Blender tessellates them for display and render).
SOURCE_TYPES = ("MESH", "CURVE", "FONT", "SURFACE", "META")


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


def read_object(obj, depsgraph, notes, layers=True) -> ObjectArrays | None:
    """Arrays of one object: evaluated (modifiers), world space, outward winding; with
    ``layers``, its UV maps and colour attributes for its result (``source_layers``)."""
    return _read_evaluated(obj.evaluated_get(depsgraph), obj.matrix_world, obj.name, obj.session_uid, notes, layers)


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


def _read_evaluated(evaluated, matrix_world, name, uid, notes, layers=True) -> ObjectArrays | None:
    mesh = evaluated.to_mesh()
    try:
        if len(mesh.polygons) == 0:
            if not _has_instances(evaluated):
                notes.append(f"'{name}' has no faces and was skipped")
            return None
        arrays = _mesh_arrays(mesh, name)
        arrays.update(_mesh_materials(evaluated, mesh, arrays["triangles"], name, notes))
        arrays["layers"] = source_layers(mesh, arrays["triangles"]) if layers else None
    finally:
        evaluated.to_mesh_clear()
    return _in_world_space(arrays, matrix_world, name, uid)


def _mesh_arrays(mesh, name):
    """The evaluated mesh's geometry: vertices (object space), faces, corners, loop triangles."""
    V = len(mesh.vertices)
    F = len(mesh.polygons)
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
    mesh.calc_loop_triangles()
    T = len(mesh.loop_triangles)
    triangles = _get(mesh.loop_triangles, "vertices", T, np.int32, 3)
    triangle_face = _get(mesh.loop_triangles, "polygon_index", T, np.int32)
    return {"co": co, "face_sizes": face_sizes, "material_index": material_index, "corner_verts": loop_vertex,
            "triangles": triangles, "triangle_face": triangle_face}


def _mesh_materials(evaluated, mesh, triangles, name, notes):
    """The object's material slots (materials.slot_tables), with the UVs and colour attributes
    that their textures read per patch."""
    T = len(triangles)
    slot_names, textures, attributes, emission_textures, laters = slot_tables(evaluated, notes)
    triangle_uv = None
    if any(t is not None for t in (*textures, *emission_textures)):
        triangle_uv, kept = _triangle_uv(mesh, T, (*textures, *emission_textures), name, notes)
        textures, emission_textures = kept[: len(textures)], kept[len(textures):]
    colours = _attribute_colours(mesh, T, triangles, attributes, name, notes)
    return {"slot_names": slot_names, "textures": textures, "emission_textures": emission_textures,
            "triangle_uv": triangle_uv, "colours": colours, "laters": laters}


def _with_materials(o, a, flipped, notes, memo):
    """Gives object arrays ``o`` their materials' values from what ``_mesh_materials`` read
    (``a``): no bpy, any thread (their images read here); ``flipped``: its winding reversed."""
    R_slots, E_slots, textures, emission_textures, terms = slot_values(
        a["laters"], a["textures"], a["emission_textures"], notes, memo)
    # colour attributes are base colours: the light returned is scale * colour + offset
    colours = tuple(None if c is None else (c[:, ::-1] if flipped else c) for c in a["colours"])
    slot_colours = tuple(None if c is None else c * scale + offset for c, (scale, offset, _) in zip(colours, terms))
    # each slot's glossy lobe (share, alpha), none: (0, 1)
    G_slots = np.array([(0.0, 0.0, 0.0, 1.0) if lobe is None else (*lobe[0], lobe[1]) for *_, lobe in terms])
    o.face_reflectivity = _per_face(R_slots, o.face_slot)
    o.face_emission = _per_face(E_slots, o.face_slot)
    o.face_glossy = _per_face(G_slots, o.face_slot)
    o.slot_textures = textures if o.triangle_uv is not None else ()
    o.slot_emission_textures = emission_textures if o.triangle_uv is not None else ()
    o.slot_colours = slot_colours if any(c is not None for c in slot_colours) else ()
    o.later = None
    return o


def _in_world_space(a, matrix_world, name, uid) -> ObjectArrays:
    """ObjectArrays of a mesh's arrays ``a`` placed by ``matrix_world``, its winding kept
    outward under a negative scale; its materials' values left for later (``with_materials``)."""
    corner_verts, triangles, triangle_uv = a["corner_verts"], a["triangles"], a["triangle_uv"]
    M = np.array(matrix_world, dtype=np.float64)
    vertices = a["co"] @ M[:3, :3].T + M[:3, 3]
    flipped = bool(np.linalg.det(M[:3, :3]) < 0)
    if flipped:  # negative scale: keep normals outward
        corner_verts = meshing.reverse_faces(a["face_sizes"], corner_verts)
        triangles = triangles[:, ::-1].copy()
        if triangle_uv is not None:
            triangle_uv = triangle_uv[:, ::-1].copy()
        if a["layers"] is not None:
            a["layers"] = a["layers"].reversed()
    if a["layers"] is not None:
        a["layers"] = a["layers"].placed(M[:3, :3])
    slot = np.clip(a["material_index"], 0, len(a["slot_names"]) - 1)
    o = ObjectArrays(
        name=name,
        uid=int(uid),
        face_slot=slot,
        slot_names=a["slot_names"],
        vertices=vertices,
        face_sizes=a["face_sizes"],
        corner_verts=corner_verts,
        triangles=triangles,
        triangle_face=a["triangle_face"],
        face_reflectivity=None,
        face_emission=None,
        triangle_uv=triangle_uv,
        layers=a["layers"],
    )
    o.later = lambda target, notes, memo: _with_materials(target, a, flipped, notes, memo)
    return o


def with_materials(o, notes, memo=None):
    """Object arrays ``o`` with their materials' values, where ``read_object`` left them for
    later (no bpy: any thread; their images read here); their notes added to ``notes``."""
    if o.later is not None:
        o.later(o, notes, memo)
    return o


def source_layers(mesh, triangles) -> SourceLayers:
    """Every UV map and colour attribute of an evaluated mesh at its loop triangles' corners
    (float32), with the names its materials read by default, and its shading normals there
    unless every face is flat."""
    T = len(triangles)
    smooth = mesh.normals_domain != "FACE"  # (flat faces alone need no normals: the result is shaded flat)
    if not len(mesh.uv_layers) and not len(mesh.color_attributes) and not smooth:
        return SourceLayers()
    loops = _get(mesh.loop_triangles, "loops", T, np.int32, 3)
    normals = _get(mesh.corner_normals, "vector", len(mesh.loops), np.float32, 3)[loops] if smooth else None
    uv = []
    for layer in mesh.uv_layers:
        values = np.empty(len(mesh.loops) * 2, dtype=np.float32)
        layer.uv.foreach_get("vector", values)
        uv.append((layer.name, values.reshape(-1, 2)[loops]))
    colours = []
    for layer in mesh.color_attributes:
        if layer.domain not in ("CORNER", "POINT"):
            continue
        values = np.empty(len(layer.data) * 4, dtype=np.float32)
        layer.data.foreach_get("color", values)  # (scene linear, for byte colours too)
        colours.append((layer.name, values.reshape(-1, 4)[loops if layer.domain == "CORNER" else triangles]))
    active = mesh.uv_layers.active
    render = next((layer for layer in mesh.uv_layers if layer.active_render), active)
    render_colour = ""
    index = getattr(mesh.color_attributes, "render_color_index", -1)
    if 0 <= index < len(mesh.color_attributes):
        render_colour = mesh.color_attributes[index].name
    return SourceLayers(tuple(uv), tuple(colours), active.name if active else "", render.name if render else "",
                        render_colour, normals)


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


def describe(obj):
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
        arrays = read_object(obj, depsgraph, [], layers=False)
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


