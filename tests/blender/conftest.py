"""Fixtures for the tests that run the extension in the ``bpy`` module (headless)."""

import os
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

import bpy  # noqa: E402  - these tests need the bpy module (pip install bpy)

import addon  # noqa: E402


@pytest.fixture
def blender():
    """An empty factory scene with the extension registered; unregistered after."""
    addon.unregister()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    yield bpy.context
    addon.unregister()


# ---------------------------------------------------------------------------
# A small test scene built from known arrays: a closed box (inward faces),
# a light quad below the ceiling and a block on the floor.
# ---------------------------------------------------------------------------

BOX = 1.0
LIGHT_EMISSION = np.array([4.0, 3.5, 3.0])  # colour x strength


def principled(name, base, emission=(0, 0, 0), strength=0.0):
    m = bpy.data.materials.new(name)
    node = m.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Emission Color"].default_value = (*emission, 1.0)
    node.inputs["Emission Strength"].default_value = strength
    node.inputs["Specular IOR Level"].default_value = 0.0  # Lambertian: read back as the base colour
    return m


def make_object(name, vertices, faces, materials=(), face_materials=None, location=(0, 0, 0), scale=(1, 1, 1)):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in vertices], [], [tuple(f) for f in faces])
    for m in materials:
        mesh.materials.append(m)
    if face_materials is not None:
        mesh.polygons.foreach_set("material_index", np.asarray(face_materials, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    obj.scale = scale
    bpy.context.scene.collection.objects.link(obj)
    return obj


def box_arrays(lo, hi, inward):
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    v = np.array(
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    outward = [(3, 2, 1, 0), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    faces = [tuple(reversed(f)) for f in outward] if inward else outward
    return v, faces


def build_test_scene():
    """Objects with known world-space arrays; returns {name: (vertices, faces, R, E)}.

    R and E are per-face reflectivity and emission the extension should read.
    """
    white = (0.7, 0.7, 0.7)
    red = (0.6, 0.1, 0.1)
    room_v, room_f = box_arrays((0, 0, 0), (BOX, BOX, BOX), inward=True)
    room = make_object("Room", room_v, room_f,
                       [principled("White", white), principled("Red", red)], [0, 0, 0, 1, 0, 0])
    h = BOX - 0.01
    light_v = np.array([[0.35, 0.35, h], [0.65, 0.35, h], [0.65, 0.65, h], [0.35, 0.65, h]])
    light = make_object("Lamp", light_v, [(0, 3, 2, 1)],
                        [principled("Emitter", (0.5, 0.5, 0.5), LIGHT_EMISSION / 4.0, 4.0)])
    block_v, block_f = box_arrays((0.2, 0.2, 0.0), (0.5, 0.5, 0.3), inward=False)
    block = make_object("Block", block_v, block_f)  # no material: grey 0.8
    for o in (room, light, block):
        o.select_set(True)
    R_room = np.array([white, white, white, red, white, white])

    def f32(a):  # Blender stores positions and colours in float32
        return np.asarray(a, dtype=np.float32).astype(np.float64)

    spec = {
        "Block": (f32(block_v), block_f, np.full((6, 3), 0.8), np.zeros((6, 3))),
        "Lamp": (f32(light_v), [(0, 3, 2, 1)], f32([[0.5, 0.5, 0.5]]), LIGHT_EMISSION[None]),
        "Room": (f32(room_v), room_f, f32(R_room), np.zeros((6, 3))),
    }
    return spec


def read_colours(mesh, name):
    attr = mesh.color_attributes[name]
    c = np.empty(len(attr.data) * 4, dtype=np.float32)
    attr.data.foreach_get("color", c)
    return attr.domain, c.reshape(-1, 4)


def mesh_arrays(mesh):
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    sizes = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    corners = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    return co.reshape(-1, 3), sizes, corners


def result_objects():
    return sorted(
        (o for o in bpy.data.objects if "radiosity_source" in o.keys()), key=lambda o: o["radiosity_source"]
    )


def solve_outputs(monkeypatch):
    """The outputs (pipeline.SolveOutput) of every solve the operator or the command line runs from
    here on (blender_write.solve_job.run's), in a list that grows as they finish."""
    from addon.blender_write import solve_job

    outputs = []
    run = solve_job.run

    def recorded(*args, **kwargs):
        finished = run(*args, **kwargs)
        if finished.output is not None:
            outputs.append(finished.output)
        return finished

    monkeypatch.setattr(solve_job, "run", recorded)
    return outputs
