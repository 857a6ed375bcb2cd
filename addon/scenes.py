"""Built-in sample scenes, built in code (bpy)."""

from __future__ import annotations

import bpy
import numpy as np


def _material(name, base, emission=(0, 0, 0), strength=0.0):
    material = bpy.data.materials.get(name) or bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    node = material.node_tree.nodes.get("Principled BSDF")
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Emission Color"].default_value = (*emission, 1.0)
    node.inputs["Emission Strength"].default_value = strength
    material.diffuse_color = (*base, 1.0)
    return material


def mesh_object(name, vertices, faces, materials=(), face_materials=None, collection=None):
    """An object from vertex and face lists (faces as lists of vertex indices)."""
    mesh = bpy.data.meshes.new(name)
    vertices = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
    sizes = np.array([len(f) for f in faces], dtype=np.int32)
    corners = np.concatenate([np.asarray(f, dtype=np.int32) for f in faces])
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", vertices.ravel())
    mesh.loops.add(len(corners))
    mesh.loops.foreach_set("vertex_index", corners)
    mesh.polygons.add(len(sizes))
    mesh.polygons.foreach_set("loop_start", np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int32))
    mesh.update(calc_edges=True)
    mesh.validate()
    for m in materials:
        mesh.materials.append(m)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(face_materials, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def _box(x0, y0, x1, y1, height, angle=0.0):
    """Closed box on the floor, rotated about z; faces wound outwards."""
    c = np.array([(x0 + x1) / 2, (y0 + y1) / 2])
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]]) - c
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    xy = corners @ rot.T + c
    v = np.concatenate([np.c_[xy, np.zeros(4)], np.c_[xy, np.full(4, height)]])
    faces = [(3, 2, 1, 0), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return v, faces


def cornell_box(size=2.0, light_strength=12.0):
    """A Cornell-style box, open at the front (-y), light in the ceiling.

    Walls face inwards.  Returns the created objects (all selected) and sets
    up a camera looking in.
    """
    s = size
    white = _material("Cornell White", (0.73, 0.73, 0.73))
    red = _material("Cornell Red", (0.63, 0.065, 0.05))
    green = _material("Cornell Green", (0.14, 0.45, 0.09))
    light = _material("Cornell Light", (0.78, 0.78, 0.78), (1.0, 0.85, 0.6), light_strength)
    v = np.array(
        [[0, 0, 0], [s, 0, 0], [s, s, 0], [0, s, 0], [0, 0, s], [s, 0, s], [s, s, s], [0, s, s]], float
    )
    # floor (up), ceiling (down), back (towards -y), left red (+x), right green (-x)
    faces = [(0, 1, 2, 3), (4, 7, 6, 5), (3, 2, 6, 7), (0, 3, 7, 4), (1, 5, 6, 2)]
    room = mesh_object("Room", v, faces, [white, red, green], [0, 0, 0, 1, 2])
    a = 0.13 * s
    h = s - 1e-3 * s
    lv = np.array(
        [[s / 2 - a, s / 2 - a, h], [s / 2 + a, s / 2 - a, h], [s / 2 + a, s / 2 + a, h], [s / 2 - a, s / 2 + a, h]]
    )
    lamp = mesh_object("Light", lv, [(0, 3, 2, 1)], [light])
    bv, bf = _box(0.53 * s, 0.15 * s, 0.83 * s, 0.45 * s, 0.3 * s, angle=-0.29)
    short = mesh_object("Short Box", bv, bf, [white])
    tv, tf = _box(0.17 * s, 0.45 * s, 0.47 * s, 0.75 * s, 0.6 * s, angle=0.29)
    tall = mesh_object("Tall Box", tv, tf, [white])
    objects = [room, lamp, short, tall]

    camera_data = bpy.data.cameras.new("Camera")
    camera_data.lens = 45
    camera = bpy.data.objects.new("Camera", camera_data)
    bpy.context.scene.collection.objects.link(camera)
    camera.location = (s / 2, -1.4 * s, s / 2)
    camera.rotation_euler = (np.pi / 2, 0.0, 0.0)
    bpy.context.scene.camera = camera
    bpy.context.scene.render.resolution_x = bpy.context.scene.render.resolution_y = 1024  # the box is square

    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = room
    return objects


SCENES = {"cornell": cornell_box}
