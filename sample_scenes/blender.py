"""Any SampleScene as Blender objects (needs ``bpy``; the rest of sample_scenes does not).

    import bpy
    from sample_scenes import cube_enclosure
    from sample_scenes.blender import to_blender
    objects = to_blender(cube_enclosure.build(reflectivity=0.3))   # one object per part

One object per part, one quad per patch (the patch's own corners, same winding, so Blender's
face normals are the patch normals), and one Principled BSDF material per distinct
(reflectivity, emission): Base Color = reflectivity, Specular IOR Level 0 (no specular layer:
Lambertian, as the sample scenes are), Emission Color x Emission Strength = emittance -- how the
extension reads materials back (``addon/blender_read/materials.py``). Unlike
``python -m addon --scene NAME`` this takes any variant, not only registry names.
"""
from __future__ import annotations

import numpy as np


def _material(bpy, name, reflectivity, emission):
    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    node = m.node_tree.nodes.get("Principled BSDF")
    node.inputs["Base Color"].default_value = (*map(float, reflectivity), 1.0)
    strength = float(np.max(emission))
    colour = np.asarray(emission, float) / strength if strength > 0 else np.zeros(3)
    node.inputs["Emission Color"].default_value = (*map(float, colour), 1.0)
    node.inputs["Emission Strength"].default_value = strength
    node.inputs["Specular IOR Level"].default_value = 0.0
    m.diffuse_color = (*map(float, reflectivity), 1.0)
    return m


def _patch_quads(sample):
    """(P,4) vertex indices of each patch's quad, checked against its two triangles."""
    P = sample.patch_count
    quads = 4 * np.arange(P)[:, None] + np.arange(4)
    t = sample.triangles
    ok = (
        len(t) == 2 * P
        and np.array_equal(sample.triangle_patch, np.repeat(np.arange(P), 2))
        and np.array_equal(t[0::2], quads[:, [0, 1, 2]])
        and np.array_equal(t[1::2], quads[:, [0, 2, 3]])
    )
    if not ok:
        raise ValueError("to_blender expects the sample_scenes layout: patch p = vertices 4p..4p+3, "
                         "triangles (0,1,2), (0,2,3)")
    return quads


def to_blender(sample, collection=None, prefix=None):
    """Create the objects of ``sample`` in ``collection`` (default: the scene's); return them."""
    import bpy

    prefix = sample.name if prefix is None else prefix
    collection = collection or bpy.context.scene.collection
    quads = _patch_quads(sample)
    rows = np.round(np.concatenate([sample.reflectivity, sample.emission], axis=1), 9)
    unique_rows, material_of_patch = np.unique(rows, axis=0, return_inverse=True)
    material_of_patch = material_of_patch.ravel()
    materials = [_material(bpy, f"{prefix} material {k}", row[:3], row[3:]) for k, row in enumerate(unique_rows)]
    objects = []
    for k, part in enumerate(sample.part_names):
        patches = np.flatnonzero(sample.patch_part == k)
        n = patches.size
        corners = sample.vertices[quads[patches].ravel()]
        mesh = bpy.data.meshes.new(f"{prefix} {part}")
        mesh.vertices.add(4 * n)
        mesh.vertices.foreach_set("co", corners.astype(np.float32).ravel())
        mesh.loops.add(4 * n)
        mesh.loops.foreach_set("vertex_index", np.arange(4 * n, dtype=np.int32))
        mesh.polygons.add(n)
        mesh.polygons.foreach_set("loop_start", np.arange(0, 4 * n, 4, dtype=np.int32))
        used, local = np.unique(material_of_patch[patches], return_inverse=True)
        for m in used:
            mesh.materials.append(materials[m])
        mesh.polygons.foreach_set("material_index", local.ravel().astype(np.int32))
        mesh.update(calc_edges=True)
        mesh.validate()
        obj = bpy.data.objects.new(f"{prefix} {part}", mesh)
        collection.objects.link(obj)
        objects.append(obj)
    return objects
