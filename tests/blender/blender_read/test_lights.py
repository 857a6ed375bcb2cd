"""Blender's lights and world read as the core's light sources, in Cycles' units."""
import math
import re

import bpy
import numpy as np
import pytest

from addon.blender_read import SceneError, lights as lights_io
from addon.blender_read.selection import read_selection
from addon.core.lights.lights import AreaLight, PointLight, SunLight, WorldLight

from ..conftest import box_arrays, build_test_scene, make_object, principled, result_objects


def _lamp(kind, name="L", location=(0.5, 0.5, 0.8), rotation=(0, 0, 0), scale=(1, 1, 1), **settings):
    data = bpy.data.lights.new(name, kind)
    for key, value in settings.items():
        setattr(data, key, value)
    obj = bpy.data.objects.new(name, data)
    obj.location, obj.rotation_euler, obj.scale = location, rotation, scale
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _read(context):
    notes = []
    lights = lights_io.read_lights(context.evaluated_depsgraph_get(), notes)
    return lights, notes


def test_each_kind_in_cycles_units(blender):
    """Point and spot: intensity P / (4 pi^2); area: exitance P / (pi A) with the object's scale in
    A; sun: irradiance S / pi along the object's -Z; spot cone from size and blend as Cycles'
    smoothstep."""
    _lamp("POINT", "Point", energy=100.0, color=(1.0, 0.5, 0.25), shadow_soft_size=0.0)
    _lamp("SPOT", "Spot", energy=50.0, spot_size=math.radians(60), spot_blend=0.2, shadow_soft_size=0.1)
    _lamp("AREA", "Square", energy=80.0, shape="SQUARE", size=2.0, scale=(2, 1, 1))
    _lamp("AREA", "Disk", energy=10.0, shape="DISK", size=0.5)
    _lamp("SUN", "Sun", energy=3.0, angle=math.radians(5), rotation=(math.radians(30), 0, 0))
    lights, notes = _read(bpy.context)
    by = {light.name: light for light in lights}
    assert set(by) == {"Point", "Spot", "Square", "Disk", "Sun"} and not notes
    point = by["Point"]
    assert isinstance(point, PointLight) and point.radius == 0 and point.spot is None
    np.testing.assert_allclose(point.intensity, np.array([1.0, 0.5, 0.25]) * 100 / (4 * math.pi**2))
    np.testing.assert_allclose(point.position, [0.5, 0.5, 0.8], atol=1e-6)
    spot = by["Spot"]
    np.testing.assert_allclose(spot.intensity, 50 / (4 * math.pi**2))
    assert spot.radius == pytest.approx(0.1)
    cos_outer = math.cos(math.radians(30))
    assert spot.spot.cos_outer == pytest.approx(cos_outer)
    assert spot.spot.cos_inner == pytest.approx(cos_outer + (1 - cos_outer) * 0.2)
    np.testing.assert_allclose(spot.spot.axis, [0, 0, -1], atol=1e-6)
    square = by["Square"]
    assert isinstance(square, AreaLight) and not square.ellipse
    assert square.area == pytest.approx(8.0)  # 2 x 2 m, scaled twice along x
    np.testing.assert_allclose(square.exitance, 80 / (math.pi * 8.0))
    disk = by["Disk"]
    assert disk.ellipse and disk.area == pytest.approx(math.pi * 0.25**2)
    sun = by["Sun"]
    assert isinstance(sun, SunLight) and sun.angle == pytest.approx(math.radians(5))
    np.testing.assert_allclose(sun.irradiance, 3 / math.pi)
    np.testing.assert_allclose(sun.direction, [0, math.sin(math.radians(30)), -math.cos(math.radians(30))], atol=1e-6)


def test_exposure_temperature_normalize_and_an_uneven_spot_as_cycles_reads_them(blender):
    """Cycles' strength is colour (x the blackbody colour with Temperature on) x power x
    2^exposure; without Normalize the power is not divided by the light's own area (a point of
    radius 0: 4; radius r: 4 pi r^2; an area light its area; a sun of angle a: pi sin^2(a/2)).
    A spot scaled unevenly gets an elliptical cone (the inverse matrix, z turned); Cast Shadow
    is carried to the core."""
    _lamp("POINT", "Exposed", energy=10.0, exposure=2.0, shadow_soft_size=0.0)
    _lamp("POINT", "Raw", energy=10.0, normalize=False, shadow_soft_size=0.0)
    _lamp("POINT", "Raw ball", energy=10.0, normalize=False, shadow_soft_size=0.2)
    warm = _lamp("POINT", "Warm", energy=10.0, use_temperature=True, temperature=3000.0, shadow_soft_size=0.0)
    _lamp("AREA", "Raw panel", energy=10.0, normalize=False, shape="RECTANGLE", size=2.0, size_y=0.5)
    _lamp("SUN", "Raw sun", energy=2.0, normalize=False, angle=math.radians(10))
    _lamp("SPOT", "Oval", energy=10.0, spot_size=math.radians(50), scale=(2.0, 1.0, 1.0), use_shadow=False)
    _lamp("SPOT", "Even", energy=10.0, spot_size=math.radians(50), scale=(3.0, 3.0, 3.0))
    lights, notes = _read(bpy.context)
    by = {light.name: light for light in lights}
    unit = 10.0 / (4 * math.pi**2)
    np.testing.assert_allclose(by["Exposed"].intensity, 4 * unit)
    np.testing.assert_allclose(by["Raw"].intensity, 4 * unit)
    np.testing.assert_allclose(by["Raw ball"].intensity, 4 * math.pi * 0.2**2 * unit)
    blackbody = np.array(warm.data.temperature_color[:3])
    assert blackbody[0] > blackbody[2]  # warm
    np.testing.assert_allclose(by["Warm"].intensity, blackbody * unit)
    np.testing.assert_allclose(by["Raw panel"].exitance, 10.0 / math.pi)
    np.testing.assert_allclose(by["Raw sun"].irradiance, 2.0 / math.pi * math.pi * math.sin(math.radians(5)) ** 2)
    oval, even = by["Oval"], by["Even"]
    assert even.spot.to_local is None and oval.spot.to_local is not None
    np.testing.assert_allclose(oval.spot.to_local, np.diag([0.5, 1.0, -1.0]), atol=1e-6)
    assert oval.spot.bounding_cos() < oval.spot.cos_outer
    assert not oval.casts_shadow and even.casts_shadow and by["Raw"].casts_shadow
    assert by["Raw ball"].soft_falloff  # Blender's default; Cycles' disc facing each receiver


def test_a_lamp_that_casts_no_shadow_lights_through_and_says_how(blender):
    """A closed room with a point light above a board: Cast Shadow off lights the floor under
    the board as if the board were not there (the solve gathers the direct light and says so);
    on, the floor there is darker."""
    from addon.bpy_free import pipeline

    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", room_v, room_f, [principled("White", (0.5, 0.5, 0.5))]).select_set(True)
    board_v = np.array([[0.25, 0.25, 0.5], [0.75, 0.25, 0.5], [0.75, 0.75, 0.5], [0.25, 0.75, 0.5]])
    make_object("Board", board_v, [(0, 1, 2, 3)], [principled("Black", (0.0, 0.0, 0.0))]).select_set(True)
    lamp = _lamp("POINT", "Bulb", location=(0.5, 0.5, 0.8), energy=40.0)
    s = blender.scene.radiosity
    s.target_error, s.patch_size, s.threads = 10.0, 0.25, 1

    def floor_centre():
        assert bpy.ops.radiosity.solve() == {"FINISHED"}
        room = next(o for o in result_objects() if o.name.startswith("Room"))
        colours = np.empty(len(room.data.color_attributes["Radiosity"].data) * 4, np.float32)
        room.data.color_attributes["Radiosity"].data.foreach_get("color", colours)
        faces = np.array([p.center for p in room.data.polygons])
        centre = (np.abs(faces[:, 2]) < 1e-6) & (np.abs(faces[:, 0] - 0.5) < 0.25) & (np.abs(faces[:, 1] - 0.5) < 0.25)
        face_colours = colours.reshape(-1, 4)[[p.loop_start for p in room.data.polygons], 0]
        objects, _ = read_selection(blender)
        return face_colours[centre].mean(), pipeline.estimate(objects, s.solve_settings())["notes"]

    shadowed, _ = floor_centre()
    lamp.data.use_shadow = False
    through, notes = floor_centre()
    assert any("'Bulb' casts no shadow" in note for note in notes)
    # Unshadowed, the centre floor adds its direct light, 0.5 x 40 / (4 pi^2) x cos / d^2 averaged
    # over it: 0.72 (its indirect light grows too). Each mean is of 4 patches at a 10% target
    # (about 5% of about 0.65 and 1.4): the difference's sd is about 0.08, half of 0.72 is 4.5 sd.
    assert through - shadowed > 0.5 * 0.72


def test_lights_left_out_or_refused_are_named(blender):
    hidden = _lamp("POINT", "Hidden", energy=10.0)
    hidden.hide_render = True
    _lamp("POINT", "Dark", energy=0.0)
    no_diffuse = _lamp("POINT", "Glossy only", energy=10.0)
    no_diffuse.visible_diffuse = False
    lights, notes = _read(bpy.context)
    assert lights == []
    assert any("'Dark' has no power" in n for n in notes)
    assert any("'Glossy only' is not visible to diffuse rays" in n for n in notes)
    assert not any("Hidden" in n for n in notes)  # hidden from render: not in the render, not here
    _lamp("POINT", "Negative", energy=-5.0)
    with pytest.raises(lights_io.LightError, match="'Negative' has a negative power"):
        _read(bpy.context)


def test_area_spread_below_180_is_refused(blender):
    _lamp("AREA", "Narrow", energy=10.0, spread=math.radians(60))
    with pytest.raises(lights_io.LightError, match="'Narrow': a spread below 180 degrees"):
        _read(bpy.context)


def test_the_world_colour_and_strength(blender):
    world = bpy.data.worlds.new("Sky")
    blender.scene.world = world
    if not world.use_nodes:
        world.use_nodes = True
    background = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    background.inputs["Color"].default_value = (0.2, 0.3, 0.4, 1.0)
    background.inputs["Strength"].default_value = 2.0
    notes = []
    sky = lights_io.read_world(blender.scene, notes)
    assert isinstance(sky, WorldLight) and sky.image is None and not notes
    np.testing.assert_allclose(sky.irradiance, [0.4, 0.6, 0.8], rtol=1e-6)
    background.inputs["Strength"].default_value = 0.0
    assert lights_io.read_world(blender.scene, []) is None


def _world_image(blender, name, image, strength):
    """A new world ``name`` lighting the scene by ``image`` (an Environment Texture) at ``strength``."""
    world = bpy.data.worlds.new(name)
    blender.scene.world = world
    if not world.use_nodes:
        world.use_nodes = True
    tree = world.node_tree
    background = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBackground")
    environment = tree.nodes.new("ShaderNodeTexEnvironment")
    environment.image = image
    tree.links.new(environment.outputs["Color"], background.inputs["Color"])
    background.inputs["Strength"].default_value = strength
    return world


def test_an_environment_image_is_read_top_row_first(blender):
    """An equirectangular image lights by its pixels, top row first (Blender stores the bottom
    row first), in linear colour."""
    image = bpy.data.images.new("Env", 8, 4, float_buffer=True)
    pixels = np.zeros((4, 8, 4), np.float32)
    pixels[3] = (1.0, 0.5, 0.25, 1.0)  # Blender's last row: the top of the image, the zenith
    image.pixels.foreach_set(pixels.ravel())
    _world_image(blender, "Env", image, 2.0)
    sky = lights_io.read_world(blender.scene, [])
    assert sky.image.shape == (4, 8, 3)
    np.testing.assert_allclose(sky.image[0], np.tile([2.0, 1.0, 0.5], (8, 1)))
    assert not sky.image[1:].any()


def test_a_room_lit_by_a_lamp_alone_solves_and_a_bad_lamp_changes_nothing(blender):
    """A closed room with no emissive material, lit by a point light inside: it solves and
    lights the walls; a negative lamp is refused with its name and the scene is unchanged."""
    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", room_v, room_f, [principled("White", (0.6, 0.6, 0.6))]).select_set(True)
    _lamp("POINT", "Bulb", location=(0.5, 0.5, 0.5), energy=40.0)
    objects, notes = read_selection(blender)
    assert [type(light).__name__ for light in objects.lights] == ["PointLight"]
    s = blender.scene.radiosity
    s.target_error, s.patch_size, s.threads = 10.0, 0.25, 1
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    (room,) = result_objects()
    c = np.empty(len(room.data.color_attributes["Radiosity"].data) * 4, np.float32)
    room.data.color_attributes["Radiosity"].data.foreach_get("color", c)
    # the walls' radiosity: R times what they receive, about 0.6 x 40 / (4 pi^2) / 0.25 m^2 directly
    assert c.reshape(-1, 4)[:, :3].mean() > 0.5
    before = sorted(o.name for o in bpy.data.objects)
    bpy.data.objects["Bulb"].data.energy = -1.0
    with pytest.raises(RuntimeError, match="'Bulb' has a negative power"):
        bpy.ops.radiosity.solve()
    assert sorted(o.name for o in bpy.data.objects) == before


def test_the_sources_and_their_shares_are_listed(blender):
    """The estimate, the last run and the command line list the sources that took part with
    each kind's share of the power."""
    from addon.bpy_free import pipeline

    build_test_scene()
    _lamp("POINT", "Bulb", location=(0.5, 0.5, 0.5), energy=4.0)
    blender.scene.radiosity.patch_size, blender.scene.radiosity.threads = 0.25, 1
    objects, _ = read_selection(blender)
    value = pipeline.estimate(objects, blender.scene.radiosity.solve_settings())
    # the lamp quad under the ceiling, both its sides: 2 x 0.09 m^2 x mean(4, 3.5, 3) = 0.63; the
    # bulb 4 x 4 pi / (4 pi^2) = 1.27
    bulb = 4.0 / math.pi
    lamp = 2 * 0.09 * 3.5
    assert value["sources"] == f"1 point light {bulb / (bulb + lamp):.0%}, emissive faces {lamp / (bulb + lamp):.0%}"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert blender.scene.radiosity.last_sources == value["sources"]
    # and where the light went, from the run's own accounts
    assert re.fullmatch(r"light: \d+\.\d% absorbed by surfaces( \(\d+\.\d% on the back of faces\))?, "
                        r"\d+\.\d% left the scene", blender.scene.radiosity.last_light_account)


def test_the_rest_of_the_scene_blocks_and_reflects_without_results(blender):
    """Selected objects get results; the other visible objects block and reflect light (meshed
    coarser) and get none; the option leaves them out. The floor under an unselected block is in
    its shadow only while the block takes part."""
    from addon.bpy_free import pipeline

    build_test_scene()
    for name in ("Block",):
        bpy.data.objects[name].select_set(False)
    s = blender.scene.radiosity
    s.patch_size, s.threads, s.target_error, s.output = 0.1, 1, 5.0, "FACE"

    def floor_under_block():
        assert bpy.ops.radiosity.solve() == {"FINISHED"}
        assert sorted(o["radiosity_source"] for o in result_objects()) == ["Lamp", "Room"]
        room = bpy.data.objects["Room Radiosity"].data
        colours = np.empty(len(room.color_attributes["Radiosity"].data) * 4, np.float32)
        room.color_attributes["Radiosity"].data.foreach_get("color", colours)
        corners = np.empty(len(room.loops), np.int32)
        room.loops.foreach_get("vertex_index", corners)
        co = np.empty(len(room.vertices) * 3, np.float32)
        room.vertices.foreach_get("co", co)
        points = co.reshape(-1, 3)[corners]
        under = (points[:, 2] < 1e-3) & (points[:, 0] > 0.25) & (points[:, 0] < 0.45) & (points[:, 1] > 0.25) & (points[:, 1] < 0.45)
        return colours.reshape(-1, 4)[under, :3].mean()

    objects, _ = read_selection(blender)
    value = pipeline.estimate(objects, s.solve_settings())
    assert value["objects"] == 2 and value["others"] == 1
    shadowed = floor_under_block()
    s.use_scene_objects = False
    objects, _ = read_selection(blender)
    assert pipeline.estimate(objects, s.solve_settings())["others"] == 0
    lit = floor_under_block()
    assert shadowed < 0.5 * lit


def test_light_and_indirect_outputs_beside_the_radiosity(blender):
    """With 'Light only' and 'Indirect light' on, each result object also carries the light
    arriving ('Radiosity Light': times the base colour it is the reflected radiosity) and the
    light after a bounce ('Radiosity Indirect': below the light arriving, above 0 in a closed
    room on average)."""
    build_test_scene()
    s = blender.scene.radiosity
    s.patch_size, s.threads, s.target_error, s.output = 0.25, 1, 5.0, "FACE"
    s.light_output = s.indirect_output = True
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    room = bpy.data.objects["Room Radiosity"].data
    names = set(room.color_attributes.keys())
    assert {"Radiosity", "Radiosity Light", "Radiosity Indirect"} <= names

    def colours(name):
        a = room.color_attributes[name]
        c = np.empty(len(a.data) * 4, np.float32)
        a.data.foreach_get("color", c)
        return c.reshape(-1, 4)[:, :3].astype(np.float64)

    B, light, indirect = colours("Radiosity"), colours("Radiosity Light"), colours("Radiosity Indirect")
    # the room emits nothing: B = R H per channel, R white (0.7) or red (0.6, 0.1, 0.1)
    lit = (light > 0).all(axis=1)  # (the floor under the block gets no light)
    assert lit.mean() > 0.8
    ratio = B[lit] / light[lit]
    white = np.abs(ratio - 0.7).max(axis=1) < 1e-4
    red = np.abs(ratio - [0.6, 0.1, 0.1]).max(axis=1) < 1e-4
    assert (white | red).all() and white.any() and red.any()
    assert 0 < indirect.mean() < light.mean()


def test_lights_that_cannot_light_the_selection_are_named(blender):
    """A lamp inside a closed box of its own, and a sun over a closed room: the estimate names
    them (nothing of their light reaches the front of a face)."""
    from addon.bpy_free import patches as patch_making
    from addon.bpy_free.scene_notes import scene_and_notes

    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", room_v, room_f, [principled("White", (0.6, 0.6, 0.6))]).select_set(True)
    shell_v, shell_f = box_arrays((0.4, 0.4, 0.4), (0.6, 0.6, 0.6), inward=False)
    make_object("Shell", shell_v, shell_f, [principled("Grey", (0.5, 0.5, 0.5))]).select_set(True)
    _lamp("POINT", "Trapped", location=(0.5, 0.5, 0.5), energy=10.0)
    _lamp("SUN", "Sun", location=(0, 0, 3), energy=2.0)
    objects, _ = read_selection(blender)
    made = patch_making.make_patches(objects, 0.25)
    _, notes = scene_and_notes(made)
    assert any(n.startswith("light 'Trapped': 100% of its light meets the back of faces; it sits inside") for n in notes), notes
    assert any(n.startswith("light 'Sun'") and "no light entered" in n for n in notes), notes


def _textured_wall(blender, mapping_scale=None, clamp_white=False):
    """A 1 x 1 m wall (x, z) lit by an emissive panel in front, its material's base colour an
    image: left half red, right half blue (optionally through a Mapping node's scale)."""
    image = bpy.data.images.new("Halves", 64, 4, float_buffer=True)
    pixels = np.zeros((4, 64, 4), np.float32)
    pixels[:, :32] = (0.8, 0.0, 0.0, 1.0)
    pixels[:, 32:] = (0.0, 0.0, 0.8, 1.0)
    if clamp_white:
        pixels[:, 0] = (1.0, 1.0, 1.0, 1.0)
    image.pixels.foreach_set(pixels.ravel())
    material = principled("Painted", (0.5, 0.5, 0.5))
    tree = material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    if mapping_scale is not None:
        mapping = tree.nodes.new("ShaderNodeMapping")
        mapping.inputs["Scale"].default_value = (mapping_scale, 1.0, 1.0)
        coordinates = tree.nodes.new("ShaderNodeTexCoord")
        tree.links.new(coordinates.outputs["UV"], mapping.inputs["Vector"])
        tree.links.new(mapping.outputs["Vector"], texture.inputs["Vector"])
    wall = make_object("Wall", [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], [(0, 1, 2, 3)], [material])
    uv = wall.data.uv_layers.new(name="UVMap")
    uv.data.foreach_set("uv", np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32).ravel())
    panel = make_object("Panel", [(0, -1, 0), (0, -1, 1), (1, -1, 1), (1, -1, 0)], [(0, 1, 2, 3)],
                        [principled("Glow", (0.5, 0.5, 0.5), (1, 1, 1), 2.0)])
    for o in (wall, panel):
        o.select_set(True)
    return wall


def test_an_image_texture_colours_each_patch_by_its_own_uv_footprint(blender):
    """Base colour from an image through the UV map: each patch takes the image's mean over
    its own part of UV space (left patches red, right ones blue), not one average for the whole
    material; a Mapping node's scale of 2 repeats the image, so every patch is half and half."""
    from addon.bpy_free import patches as patch_making

    _textured_wall(blender)
    objects, notes = read_selection(blender)
    wall = next(o for o in objects if o.name == "Wall")
    made = patch_making.make_patches([wall], 0.25)
    x = made.combined.vertices[made.combined.triangles].mean(axis=1)[:, 0]
    centre_x = np.bincount(made.combined.triangle_patch, weights=x) / np.bincount(made.combined.triangle_patch)
    R = made.reflectivity
    left = centre_x < 0.5
    assert R.shape[0] == 16 and left.sum() == 8
    # exact but for the half texel (1/128) where bilinear filtering blends the halves and the
    # repeat: at most (1/128) / 0.25 / 2 of a patch's colour, 0.0125 of 0.8
    np.testing.assert_allclose(R[left], [[0.8, 0, 0]] * 8, atol=0.0125)
    np.testing.assert_allclose(R[~left], [[0, 0, 0.8]] * 8, atol=0.0125)
    assert not any("comes from image" in n for n in notes)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    import addon

    addon.register()
    _textured_wall(bpy.context, mapping_scale=2.0)
    objects, _ = read_selection(bpy.context)
    wall = next(o for o in objects if o.name == "Wall")
    R2 = patch_making.make_patches([wall], 0.5).reflectivity
    np.testing.assert_allclose(R2, [[0.4, 0.0, 0.4]] * len(R2), atol=0.03)


def test_a_texture_too_bright_is_refused_or_clamped(blender):
    _textured_wall(blender, clamp_white=True)
    with pytest.raises(SceneError, match="image texture of material 'Painted' has pixels of 1"):
        read_selection(blender)
    blender.scene.radiosity.clamp_reflectivity = True
    objects, notes = read_selection(blender)
    assert any("pixels above 0.99 were clamped" in n for n in notes)


def test_a_colour_attribute_feeding_the_base_colour_is_averaged_per_patch(blender):
    """A point colour attribute, red at x = 0 and blue at x = 1, drives the base colour: each
    patch takes the mean over its own footprint, the linear interpolation's value at its
    centre (red fading into blue across the wall), not one colour for the material."""
    from addon.bpy_free import patches as patch_making

    material = principled("Painted", (0.5, 0.5, 0.5))
    tree = material.node_tree
    attribute = tree.nodes.new("ShaderNodeVertexColor")
    attribute.layer_name = "Paint"
    tree.links.new(attribute.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    wall = make_object("Wall", [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], [(0, 1, 2, 3)], [material])
    paint = wall.data.color_attributes.new("Paint", "FLOAT_COLOR", "POINT")
    paint.data.foreach_set("color", np.array([(0.8, 0, 0, 1), (0, 0, 0.8, 1), (0, 0, 0.8, 1), (0.8, 0, 0, 1)],
                                              np.float32).ravel())
    panel = make_object("Panel", [(0, -1, 0), (0, -1, 1), (1, -1, 1), (1, -1, 0)], [(0, 1, 2, 3)],
                        [principled("Glow", (0.5, 0.5, 0.5), (1, 1, 1), 2.0)])
    for o in (wall, panel):
        o.select_set(True)
    objects, notes = read_selection(blender)
    made = patch_making.make_patches([next(o for o in objects if o.name == "Wall")], 0.25)
    x = made.combined.vertices[made.combined.triangles].mean(axis=1)[:, 0]
    centre_x = np.bincount(made.combined.triangle_patch, weights=x) / np.bincount(made.combined.triangle_patch)
    expected = np.column_stack([0.8 * (1 - centre_x), np.zeros_like(centre_x), 0.8 * centre_x])
    np.testing.assert_allclose(made.reflectivity, expected, atol=1e-9)
    assert not any("Paint" in n for n in notes)


def test_an_emission_texture_is_averaged_per_patch_times_its_strength(blender):
    """Emission colour from an image (left half white, right half black) at strength 3: the
    left patches emit 3, the right ones nothing (up to the half texel blended at the seam)."""
    from addon.bpy_free import patches as patch_making

    image = bpy.data.images.new("Sign", 64, 4, float_buffer=True)
    pixels = np.zeros((4, 64, 4), np.float32)
    pixels[:, :32] = 1.0
    pixels[..., 3] = 1.0
    image.pixels.foreach_set(pixels.ravel())
    material = principled("Neon", (0.5, 0.5, 0.5), (1, 1, 1), 3.0)
    tree = material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Emission Color"])
    sign = make_object("Sign", [(0, 0, 0), (1, 0, 0), (1, 0, 1), (0, 0, 1)], [(0, 1, 2, 3)], [material])
    sign.data.uv_layers.new(name="UVMap").data.foreach_set(
        "uv", np.array([(0, 0), (1, 0), (1, 1), (0, 1)], np.float32).ravel())
    sign.select_set(True)
    objects, notes = read_selection(blender)
    made = patch_making.make_patches(objects, 0.25)
    x = made.combined.vertices[made.combined.triangles].mean(axis=1)[:, 0]
    centre_x = np.bincount(made.combined.triangle_patch, weights=x) / np.bincount(made.combined.triangle_patch)
    left = centre_x < 0.5
    np.testing.assert_allclose(made.emission[left], 3.0, atol=3 * 0.0125 / 0.8 + 1e-9)
    np.testing.assert_allclose(made.emission[~left], 0.0, atol=3 * 0.0125 / 0.8 + 1e-9)
    assert not any("comes from image" in n for n in notes)


def _room_under_a_world_image(blender, image):
    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    room_f = room_f[1:]  # open at the top: the sky comes in
    make_object("Room", room_v, room_f, [principled("White", (0.6, 0.6, 0.6))]).select_set(True)
    _world_image(blender, "Grey sky", image, 0.05)
    blender.scene.radiosity.patch_size, blender.scene.radiosity.threads = 0.5, 1


def test_a_missing_world_image_is_an_error_naming_the_world_and_the_file(blender):
    """An environment image whose file is not found has no pixels: its sky was solved as a
    white sky of strength 1 (the socket's white times the strength, 'world 100%') while a note
    said the world gave no light. Its light is unknown (Cycles draws it magenta): the run is
    refused, naming the world, the image and the path, and nothing is written."""
    image = bpy.data.images.new("sky.hdr", 4, 4, float_buffer=True)
    image.source, image.filepath = "FILE", "//textures/sky.hdr"
    _room_under_a_world_image(blender, image)
    with pytest.raises(lights_io.LightError, match=r"^world 'Grey sky': its environment image 'sky.hdr' has no pixels "
                                                   r"\(file not found: .*textures/sky.hdr\); find the file"):
        lights_io.read_world(blender.scene, [])
    before = sorted(o.name for o in bpy.data.objects)
    with pytest.raises(RuntimeError, match="world 'Grey sky': its environment image 'sky.hdr' has no pixels"):
        bpy.ops.radiosity.solve()
    assert sorted(o.name for o in bpy.data.objects) == before and not result_objects()
    # At strength 0 the world gives no light whatever its image: no error.
    blender.scene.world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    assert lights_io.read_world(blender.scene, []) is None


@pytest.mark.parametrize("kind, setting, value, field", [
    ("POINT", "location", (math.nan, 0.5, 0.5), "location"),
    ("SUN", "scale", (math.nan, 1.0, 1.0), "rotation or scale"),
    ("POINT", "shadow_soft_size", math.nan, "radius"),
    ("SPOT", "spot_size", math.nan, "spot size"),
    ("AREA", "size", math.nan, "size"),
    ("SUN", "angle", math.nan, "angle"),
])
def test_a_light_with_a_setting_that_is_not_a_number_is_named(blender, kind, setting, value, field):
    """A lamp at a NaN location (a driver, a script) was taken: its light went nowhere, the room
    came out black and the warning blamed the lamp's placement. It is refused by name and
    setting, the scene unchanged."""
    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", room_v, room_f, [principled("White", (0.6, 0.6, 0.6))]).select_set(True)
    lamp = _lamp(kind, "Lamp", location=(0.5, 0.5, 0.5), energy=10.0)
    setattr(lamp if setting in ("location", "scale") else lamp.data, setting, value)
    with pytest.raises(lights_io.LightError, match=f"^light 'Lamp': its {field} is not a finite number"):
        _read(blender)
    before = sorted(o.name for o in bpy.data.objects)
    with pytest.raises(RuntimeError, match=f"light 'Lamp': its {field} is not a finite number"):
        bpy.ops.radiosity.solve()
    assert sorted(o.name for o in bpy.data.objects) == before and not result_objects()
