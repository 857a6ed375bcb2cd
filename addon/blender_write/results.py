"""Results written into Blender: one object per source object in the scene's results collection,
its colour attributes ('Radiosity', and the extra ones), shown by a material of its own (bpy).

A re-run replaces the previous results only once the new ones are all built."""

from __future__ import annotations

import bpy
import numpy as np

from ..core.mesh import meshing
from . import eevee_world
from . import materials as textured
from ..blender_read.objects import SOURCE_PROPERTY, is_result_object

COLLECTION_NAME = "Radiosity"
ATTRIBUTE_NAME = "Radiosity"
PATCH_ATTRIBUTE_NAME = "Radiosity Patches"  # the flat per-patch colours when both are written
LIGHT_ATTRIBUTE_NAME = "Radiosity Light"  # the light arriving, which the textured materials multiply
# live lamps: the light arriving less what the renderer draws live, which the Cycles output multiplies
BOUNCED_ATTRIBUTE_NAME = textured.BOUNCED_ATTRIBUTE
# live lamps: the light arriving less the lamps' alone, which the EEVEE output's specular layer reflects as a surface's
# own colour does (EEVEE draws the lamps' highlights)
LAMPLESS_ATTRIBUTE_NAME = textured.LAMPLESS_ATTRIBUTE
OUR_ATTRIBUTES = (ATTRIBUTE_NAME, PATCH_ATTRIBUTE_NAME, LIGHT_ATTRIBUTE_NAME, BOUNCED_ATTRIBUTE_NAME,
                  LAMPLESS_ATTRIBUTE_NAME, "Radiosity Indirect")
MATERIAL_NAME = "Radiosity Result"
COLLECTION_PROPERTY = "radiosity_results"  # custom property marking a scene's results collection
RESULT_SUFFIX = " Radiosity"
MATERIAL_PROPERTY = "radiosity_result_material"  # marks the material we made


def result_material(flat_attribute=ATTRIBUTE_NAME, live=False):
    """The material that shows the 'Radiosity' attribute as emission, or ``flat_attribute``
    where the panel's flat switch is on (ours, never a user's material that happens to have the
    same name; rebuilt each run, for the run's attribute names); ``live`` (live lamps): seen by
    the camera and the rays leaving its hits alone, as the live materials' solved light."""
    material = next((m for m in bpy.data.materials if MATERIAL_PROPERTY in m.keys() and m.node_tree is not None),
                    None)
    if material is None:
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
    emission = textured.emission_output(tree, attribute.outputs["Color"], flat_attribute, (-150, 0))
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    output.location = (300, 0)
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    if live:
        textured.camera_only(tree, emission, (-150, 250))
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


def rgba(values):
    values = np.asarray(values, dtype=np.float32).reshape(-1, 3)
    out = np.ones((len(values), 4), dtype=np.float32)
    out[:, :3] = values
    return out.ravel()


def _cornerrgba(patch_mesh, patch_values):
    """``_rgba`` of per-patch values on every corner of its patch (flat colours), made per patch
    and then repeated: no per-corner float64 copy."""
    return np.repeat(rgba(patch_values).reshape(-1, 4), patch_mesh.face_sizes, axis=0).ravel()


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


def write_colours(mesh, patch_mesh, face_colours, smooth_colours, output):
    """Add the colour attributes, both on the CORNER domain: flat per patch, and/or the smooth
    light (one value a polygon corner: creases keep a value on each side)."""
    names = []
    output = "BOTH" if output == "TEXTURED" else output  # (its materials read the light besides)
    smooth = output == "VERTEX" or (output == "BOTH" and smooth_colours is not None)
    if smooth:  # the smooth light is what is shown where it is written
        attr = mesh.color_attributes.new(ATTRIBUTE_NAME, "FLOAT_COLOR", "CORNER")
        attr.data.foreach_set("color", rgba(smooth_colours))
        names.append(attr.name)
    if output in ("FACE", "BOTH"):
        name = PATCH_ATTRIBUTE_NAME if smooth else ATTRIBUTE_NAME
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
        attr.data.foreach_set("color", _cornerrgba(patch_mesh, face_colours))
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
        attr.data.foreach_set("color", rgba(meshing.point_average(patch_mesh, face_values)))
    else:
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
        attr.data.foreach_set("color", _cornerrgba(patch_mesh, face_values))
    main = mesh.color_attributes.get(ATTRIBUTE_NAME)
    if main is not None:
        mesh.color_attributes.active_color = main
    return attr.name


def write_light(mesh, values, domain, name=LIGHT_ATTRIBUTE_NAME):
    """The light arriving, which the textured materials read (or ``name``'s part of it): (C,3) a
    polygon corner each on the CORNER domain, or (P,3) a patch each on the FACE domain (16 bytes a patch)."""
    if domain == "CORNER":
        attr = mesh.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
    else:
        attr = mesh.attributes.new(name, "FLOAT_COLOR", "FACE")
    attr.data.foreach_set("color", rgba(values))


def write_layers(mesh, layers, notes, name):
    """The source's UV maps, colour attributes and shading (``surface_layers.ResultLayers``) on the
    result mesh, under their own names, the same ones active; a UV map or colour attribute named
    as one of ours is left out (said so)."""
    for uv_name, values in layers.uv:
        if uv_name in OUR_ATTRIBUTES:
            notes.append(f"'{name}': its UV map '{uv_name}' has the name of a result's colours; "
                         "its result leaves it out")
            continue
        layer = mesh.uv_layers.new(name=uv_name, do_init=False)
        layer.uv.foreach_set("vector", values.ravel())
    if layers.active_uv in mesh.uv_layers:
        mesh.uv_layers.active = mesh.uv_layers[layers.active_uv]
    if layers.render_uv in mesh.uv_layers:
        mesh.uv_layers[layers.render_uv].active_render = True
    for colour_name, values in layers.colours:
        if colour_name in OUR_ATTRIBUTES:
            notes.append(f"'{name}': its colour attribute '{colour_name}' has the name of a result's; "
                         "its result leaves it out")
            continue
        attr = mesh.color_attributes.new(colour_name, "FLOAT_COLOR", "CORNER")
        attr.data.foreach_set("color", values.ravel())
    # the source's shading (a new mesh is smooth everywhere: live lamps would light a box's
    # sides with its top's normal near their shared edge)
    if layers.normals is None:
        mesh.shade_flat()
    else:
        mesh.normals_split_custom_set(layers.normals)


def _show_colours(mesh, render_colour):
    """'Radiosity' active (what the solid view shows); the source's default colour attribute
    the render's (what a Color Attribute node without a name reads in a copied material)."""
    colours = mesh.color_attributes
    main = colours.get(ATTRIBUTE_NAME)
    if main is not None:
        colours.active_color = main
    render = colours.get(render_colour) if render_colour and render_colour not in OUR_ATTRIBUTES else main
    if render is not None:
        try:
            colours.render_color_index = next(i for i, a in enumerate(colours) if a.name == render.name)
        except (AttributeError, StopIteration):  # older API
            pass


def show_results_in_views(live=False):
    """Let the 3D views' solid shading colour objects by their colour attribute; with live
    results, Material Preview lit by the scene's lamps and world, as the render (the results'
    EEVEE output is emission, which no light changes: the rest of the scene and the background)."""
    for screen in bpy.data.screens:
        for area in screen.areas:
            if area.type != "VIEW_3D":
                continue
            for space in area.spaces:
                if space.type == "VIEW_3D":
                    space.shading.color_type = "VERTEX"
                    if live:
                        space.shading.use_scene_lights = space.shading.use_scene_world = True


def _result_object(output_data, index, output_mode, layers, light, notes, materials_for, material):
    """The result object of source ``index``: its mesh, the source's UV maps and colour
    attributes, the colours, and its materials (``materials_for(slot names)`` for the textured
    output, else ``material``)."""
    arrays, pm = output_data.patches.objects[index], written_mesh(output_data, index)
    faces, points = output_data.face_colours[index], output_data.smooth_colours[index]
    if not all(v is None or np.isfinite(v).all() for v in (faces, points, light, *_live_of(output_data, index))):
        raise ValueError(f"the result for '{arrays.name}' is not finite")
    name = arrays.name + RESULT_SUFFIX
    mesh = build_mesh(name, pm)
    obj = bpy.data.objects.new(name, mesh)  # vertices are in world space
    try:
        _fill_result(obj, output_data, index, output_mode, layers, light, notes, materials_for, material)
    except Exception:
        _remove_objects([obj])
        raise
    return obj


def _fill_result(obj, output_data, index, output_mode, layers, light, notes, materials_for, material):
    """What ``_result_object`` writes on its new object ``obj``."""
    arrays, pm, mesh = output_data.patches.objects[index], written_mesh(output_data, index), obj.data
    faces, points = output_data.face_colours[index], output_data.smooth_colours[index]
    if layers is not None:
        write_layers(mesh, layers, notes, arrays.name)
    write_colours(mesh, pm, faces, points, output_mode)
    for extra_name, per_object in getattr(output_data, "extra", {}).items():
        write_extra(mesh, pm, extra_name, per_object[index], output_mode)
    textured_output = output_mode == "TEXTURED" and light is not None and layers is not None
    if textured_output:
        write_light(mesh, light, output_data.light_domain)
        for values, attribute in zip(_live_of(output_data, index), (BOUNCED_ATTRIBUTE_NAME, LAMPLESS_ATTRIBUTE_NAME)):
            if values is not None:
                write_light(mesh, values, output_data.light_domain, attribute)
    _show_colours(mesh, layers.render_colour if layers is not None else "")
    if textured_output:
        for slot_material in materials_for(layers.slot_names):
            mesh.materials.append(slot_material)
        mesh.polygons.foreach_set("material_index", layers.patch_slot.astype(np.int32))
    else:
        mesh.materials.append(material)


def written_mesh(output_data, index):
    """The PatchMesh source ``index``'s result is written on: the display's cells where it split them."""
    shown = getattr(output_data, "shown", None)
    return output_data.patches.meshes[index] if shown is None else shown.meshes[index]


def _live_of(output_data, index):
    """Source ``index``'s light arriving less what the renderer draws live, and less what EEVEE
    draws (the lamps'), each or None (not live; no lamps)."""
    live = getattr(output_data, "live_lamps", False)
    return tuple(colours[index] if live and colours else None
                 for colours in (getattr(output_data, name, None) for name in ("bounced_colours", "lampless_colours")))


def write_results(context, output_data, output_mode, scene=None):
    """Replace the previous results with one object per source object.

    All new objects are built first and only then swapped in for the old ones, so a failure
    part-way leaves the previous results as they were (never a half-written set).
    ``output_data`` is a pipeline.SolveOutput; ``scene`` the scene that was solved (by default
    the context's).  Returns the new objects.
    """
    scene = scene if scene is not None else context.scene
    created = []
    made = {}  # source material name -> its textured copy (or None), made once a run
    notes = getattr(output_data, "notes", [])
    layers_of = (getattr(output_data, "layers", None) or output_data.patches.layers
                 or [None] * len(output_data.patches.objects))
    light_of = getattr(output_data, "light_colours", None) or [None] * len(layers_of)
    smooth_written = output_mode in ("VERTEX", "BOTH", "TEXTURED") and any(
        p is not None for p in output_data.smooth_colours)
    flat_name = PATCH_ATTRIBUTE_NAME if smooth_written and output_mode != "VERTEX" else ATTRIBUTE_NAME
    live = getattr(output_data, "live_lamps", False)  # (the lamps light the textured materials' own shaders in Cycles)
    lamps = live and any(c is not None for c in getattr(output_data, "lampless_colours", None) or [])
    try:
        material = result_material(flat_name, live)
        for index, (arrays, faces) in enumerate(zip(output_data.patches.objects, output_data.face_colours)):
            if faces is None:  # an object of the rest of the scene: it took part, gets no result
                continue
            obj = _result_object(output_data, index, output_mode, layers_of[index], light_of[index], notes,
                                 lambda slots: textured.result_materials(slots, LIGHT_ATTRIBUTE_NAME, flat_name,
                                                                         material, notes, made, live, lamps), material)
            created.append(obj)
            obj[SOURCE_PROPERTY] = arrays.name
    except Exception:
        _remove_objects(created)
        for copy in made.values():
            if copy is not None and copy.users == 0:
                bpy.data.materials.remove(copy)
        raise
    remove_previous_results(scene)
    textured.remove_unused_textured()
    for source_name, copy in made.items():  # the names the old ones had
        if copy is not None:
            copy.name = source_name + textured.TEXTURED_SUFFIX
    collection = result_collection(scene)
    for obj in created:
        collection.objects.link(obj)
        obj.name = obj.data.name = obj[SOURCE_PROPERTY] + RESULT_SUFFIX  # the names the old ones had
    if any(copy is not None and copy.get(textured.HIGHLIGHTS_PROPERTY) for copy in made.values()):
        eevee_world.camera_only(scene.world)  # (EEVEE's world probe would light the highlights' layers too)
        notes.extend(eevee_world.reflection_notes(scene))
    elif scene.world is not None:
        eevee_world.restore(scene.world)
    show_results_in_views(live)
    return created
