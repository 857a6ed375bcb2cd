"""The picture benchmark's interiors are what they say (bpy): objects, lamps, sky, a packed
image texture on a UV-mapped floor the product reads per patch, default Principled materials, a
camera inside; and the benchmark's pixel map sees what Cycles renders."""
import math

import bpy
import numpy as np
import pytest

from addon.blender_read.lights import read_world
from addon.blender_read.materials import texture_of
from benchmarks import interior_scene, picture


@pytest.fixture(params=sorted(interior_scene.SCENES))
def interior(request):
    info = interior_scene.build(request.param)
    yield info
    bpy.ops.wm.read_factory_settings(use_empty=True)


def _inside(point, room, margin=0.0):
    lo, hi = np.asarray(room[0], float), np.asarray(room[1], float)
    return bool(((np.asarray(point) > lo + margin) & (np.asarray(point) < hi - margin)).all())


def test_every_named_object_exists_and_the_camera_is_inside_the_room(interior):
    scene = bpy.context.scene
    assert all(bpy.data.objects[n].type == "MESH" for n in interior.meshes)
    assert all(bpy.data.objects[n].type == "LIGHT" for n in interior.lamps)
    assert scene.camera is not None and scene.camera.name == interior.camera
    assert _inside(scene.camera.location, interior.room, margin=0.1)
    assert (scene.render.resolution_x, scene.render.resolution_y) == interior_scene.RESOLUTION
    for name in ("Floor", "Ceiling", "Wall West", "Wall East", "Wall North"):
        assert name in interior.surfaces


def test_materials_are_default_principled_but_for_base_colour_and_emission(interior):
    fresh = bpy.data.materials.new("fresh").node_tree.nodes["Principled BSDF"]
    defaults = {s.name: s.default_value for s in fresh.inputs if hasattr(s, "default_value")}
    changed_allowed = {"Base Color", "Emission Color", "Emission Strength"}
    for name in interior.meshes:
        for material in bpy.data.objects[name].data.materials:
            node = material.node_tree.nodes["Principled BSDF"]
            for socket in node.inputs:
                if socket.name in changed_allowed or not hasattr(socket, "default_value"):
                    continue
                value, default = socket.default_value, defaults[socket.name]
                assert np.allclose(np.ravel(value), np.ravel(default)), (name, socket.name)
    emitting = {n for n in interior.meshes
                if bpy.data.objects[n].data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value > 0}
    assert emitting == set(interior.emitters)


def test_the_floor_texture_is_a_packed_image_on_a_uv_map_the_product_reads(interior):
    floor = bpy.data.objects[interior.textured]
    node = floor.data.materials[0].node_tree.nodes["Principled BSDF"]
    texture = node.inputs["Base Color"].links[0].from_node
    assert texture.bl_idname == "ShaderNodeTexImage" and texture.image.packed_file is not None
    found = texture_of(node.inputs["Base Color"])
    assert found is not None and found[0].read()[0].std() > 0.01  # the product reads its pixels (not one colour)
    uv = np.empty(2 * len(floor.data.loops), np.float32)
    floor.data.uv_layers["UVMap"].data.foreach_get("uv", uv)
    co = np.array([floor.data.vertices[l.vertex_index].co[:] for l in floor.data.loops])
    top = np.isclose(co[:, 2], 0.0)
    size = np.asarray(interior.room[1], float)
    scale = {"window_room": size[:2], "lamp_room": (4.0, 4.0), "loft": (6.0, 3.0)}[interior.name]
    assert top.any()
    assert np.allclose(uv.reshape(-1, 2)[top], co[top, :2] / np.asarray(scale), atol=1e-5)  # laid flat, metres over its span


def test_the_window_room_has_its_window_sun_sky_and_lamps():
    info = interior_scene.build("window_room")
    kinds = sorted(bpy.data.objects[n].data.type for n in info.lamps)
    assert kinds == ["AREA", "POINT", "SUN"]
    point = bpy.data.objects["Ceiling Lamp"]
    assert point.location.z == pytest.approx(info.room[1][2] - 0.25)
    for piece in ("Wall South Left", "Wall South Right", "Wall South Sill", "Lintel"):
        assert piece in info.surfaces
    sky = read_world(bpy.context.scene, [])
    assert sky is not None and np.all(np.asarray(sky.irradiance) > 0)
    ball = bpy.data.objects["Ball"]
    assert ball.modifiers["Subdivision"].levels >= 1
    evaluated = ball.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    assert len(evaluated.vertices) > 4 * len(ball.data.vertices)
    # the window is open: from the room's middle towards it the rays leave; towards a wall they do not
    corners, _, _ = picture.mesh_triangles([bpy.data.objects[n] for n in info.meshes])
    centre = np.array([[2.5, 2.0, 1.5]] * 2)
    to = np.array([[2.5, -0.5, 1.55], [0.5, -0.5, 1.55]]) - centre
    hit, _ = picture.first_hits(corners, centre, to / np.linalg.norm(to, axis=1, keepdims=True))
    assert hit[0] < 0 and hit[1] >= 0


def test_the_lamp_room_is_closed_and_lit_by_a_spot_and_a_strip():
    info = interior_scene.build("lamp_room")
    assert [bpy.data.objects[n].data.type for n in info.lamps] == ["SPOT"]
    assert info.emitters == ["Light Strip"] and bpy.context.scene.world is None
    corners, _, _ = picture.mesh_triangles([bpy.data.objects[n] for n in info.meshes])
    k = np.arange(500) + 0.5  # directions spread over the sphere (a Fibonacci lattice)
    z = 1 - 2 * k / 500
    phi = math.pi * (1 + 5**0.5) * k
    d = np.stack([np.sqrt(1 - z**2) * np.cos(phi), np.sqrt(1 - z**2) * np.sin(phi), z], axis=1)
    origin = np.broadcast_to(np.array(bpy.context.scene.camera.location), d.shape)
    hit, _ = picture.first_hits(corners, origin, d)
    assert (hit >= 0).all()


def test_the_loft_has_its_window_sun_sky_lamps_and_pendant():
    info = interior_scene.build("loft")
    assert sorted(bpy.data.objects[n].data.type for n in info.lamps) == ["POINT", "SPOT", "SUN"]
    assert info.emitters == ["Pendant"]
    sky = read_world(bpy.context.scene, [])
    assert sky is not None and np.all(np.asarray(sky.irradiance) > 0)
    pendant = np.array([v.co[:] for v in bpy.data.objects["Pendant"].data.vertices])
    assert _inside(pendant.min(axis=0), info.room) and _inside(pendant.max(axis=0), info.room)  # hangs in the air
    # the window is open: towards it from the room's middle the rays leave; towards the north wall they do not
    corners, _, _ = picture.mesh_triangles([bpy.data.objects[n] for n in info.meshes])
    centre = np.array([[1.7, 2.5, 1.5]] * 2)
    to = np.array([[1.7, -0.5, 1.5], [1.7, 5.5, 1.5]]) - centre
    hit, _ = picture.first_hits(corners, centre, to / np.linalg.norm(to, axis=1, keepdims=True))
    assert hit[0] < 0 and hit[1] >= 0


def test_the_pixel_map_sees_the_objects_cycles_renders(interior):
    """Each object emitting its own index + 1 (nothing else lit, lamps hidden), one sample at the
    pixel centre: Cycles' pixels against the ray-cast object ids."""
    scene = bpy.context.scene
    width, height = 80, 60
    objects = [bpy.data.objects[n] for n in interior.meshes]
    for k, obj in enumerate(objects):
        m = bpy.data.materials.new(f"id {k}")
        node = m.node_tree.nodes["Principled BSDF"]
        node.inputs["Base Color"].default_value = (0, 0, 0, 1)
        node.inputs["Specular IOR Level"].default_value = 0.0
        node.inputs["Emission Color"].default_value = (1, 1, 1, 1)
        node.inputs["Emission Strength"].default_value = float(k + 1)
        obj.data.materials.clear()
        obj.data.materials.append(m)
    for name in interior.lamps:
        bpy.data.objects[name].hide_render = True
    scene.world = None
    picture.configure_cycles(scene, 1)
    scene.cycles.max_bounces = 0
    scene.cycles.filter_width = 0.01
    scene.render.resolution_x, scene.render.resolution_y = width, height
    image, _ = picture.render_exr(scene)
    rendered = np.rint(image[..., 0]).astype(int) - 1
    origins, directions = picture.camera_rays(scene.camera, width, height)
    corners, owner, _ = picture.mesh_triangles(objects)
    hit, _ = picture.first_hits(corners, origins, directions)
    cast = np.where(hit >= 0, owner[np.maximum(hit, 0)], -1).reshape(height, width)
    assert np.allclose(image[..., 0], np.rint(image[..., 0]), atol=1e-3)  # linear values, as emitted
    assert (rendered == cast).mean() > 0.97
    assert len(np.unique(cast)) >= 5


def test_the_reference_cache_key_is_the_scenes_content_not_the_session():
    first = (interior_scene.build("window_room"), picture.scene_fingerprint())[1]
    bpy.data.objects.new("unrelated", None)  # other IDs made before the build shift their session numbers
    again = (interior_scene.build("window_room"), picture.scene_fingerprint())[1]
    assert again == first
    bpy.data.objects["Ceiling Lamp"].data.energy *= 1.01
    assert picture.scene_fingerprint() != first


def test_the_product_solves_the_light_paths_the_reference_renders():
    # Cycles at default light paths (Filter Glossy 1) rendered last must not change what the
    # solve passes on: a default Principled wall passes on what the reference (Filter Glossy 0) shows.
    from addon.blender_read.materials import surface_terms, transport_terms

    interior_scene.build("window_room")
    scene = bpy.context.scene
    picture.configure_cycles(scene, 1, unbiased=False)
    wall = bpy.data.materials["Wall Paint"]
    assert not np.allclose(transport_terms(wall)[1], surface_terms(wall)[1], rtol=0.05)
    settings = picture.prepare_product(scene, "TEXTURED", seed=3)
    assert scene.cycles.blur_glossy == 0.0
    assert np.allclose(transport_terms(wall)[1], surface_terms(wall)[1], rtol=1e-12)
    assert (settings.seed, settings.output, settings.target_error) == (3, "TEXTURED", picture.TARGET_ERROR)
    bpy.ops.wm.read_factory_settings(use_empty=True)
