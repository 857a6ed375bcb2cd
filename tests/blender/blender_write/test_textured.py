"""The textured output (the default): result meshes keep the sources' UV maps and colour
attributes, and a copy of each material shows its own surface colour times the smooth light
arriving, plus its emission; the flat per-patch view stays beside it."""
import bpy
import numpy as np
import pytest

from addon.bpy_free import options
from addon.cli.preview import render_preview

from ..blender_read.test_lights import _lamp
from ..conftest import box_arrays, make_object, mesh_arrays, principled, read_colours, result_objects, solve_outputs

SQUARES = 16  # checker squares a metre: four a 0.25 m patch's side


def _checker_image(name="Checker", size=128, light=(0.8, 0.8, 0.8), dark=(0.1, 0.1, 0.1)):
    image = bpy.data.images.new(name, size, size, float_buffer=True)
    cell = size // SQUARES
    squares = (np.arange(size)[:, None] // cell + np.arange(size)[None, :] // cell) % 2
    pixels = np.ones((size, size, 4), np.float32)
    pixels[..., :3] = np.where(squares[..., None] == 1, light, dark)
    image.pixels.foreach_set(pixels.ravel())
    return image


def _checker_floor(uv_maps=(("UVMap", (1.0, 1.0, 0.0, 0.0)),), active=None, render=None):
    """A 1 x 1 m floor whose Principled base colour is a checker image read through its UV map
    (each map: u = a x + c, v = b y + d), lit by a point lamp above."""
    material = principled("Floor", (0.5, 0.5, 0.5))
    tree = material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = _checker_image()
    uv_node = tree.nodes.new("ShaderNodeUVMap")
    uv_node.uv_map = uv_maps[0][0]
    tree.links.new(uv_node.outputs["UV"], texture.inputs["Vector"])
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    floor = make_object("Floor", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], [material])
    corners = np.array([(0, 0), (1, 0), (1, 1), (0, 1)], float)
    for name, (a, b, c, d) in uv_maps:
        layer = floor.data.uv_layers.new(name=name)
        layer.data.foreach_set("uv", (corners * [a, b] + [c, d]).astype(np.float32).ravel())
    if active:
        floor.data.uv_layers.active = floor.data.uv_layers[active]
    if render:
        floor.data.uv_layers[render].active_render = True
    floor.select_set(True)
    _lamp("POINT", "Bulb", location=(0.5, 0.5, 1.0), energy=20.0, shadow_soft_size=0.0)
    return floor, material


def _solve(blender, patch_size=0.25, live_lamps=False, **settings):
    """The results of a solve at these settings; baked unless ``live_lamps`` (most tests here
    read the light the solve wrote: live, the lamps' part of it is the renderer's)."""
    s = blender.scene.radiosity
    s.patch_size, s.target_error, s.threads, s.live_lamps = patch_size, 5.0, 1, live_lamps
    for key, value in settings.items():
        setattr(s, key, value)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    return {o["radiosity_source"]: o for o in result_objects()}


def _material_state(material):
    tree = material.node_tree
    return (sorted((n.name, n.bl_idname) for n in tree.nodes),
            sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier)
                   for l in tree.links), material.name)


def test_the_result_keeps_every_uv_map_and_colour_attribute_at_the_same_surface_points(blender):
    """Two UV maps (the second active for editing, the first for render) and a colour attribute
    on points, all affine in position: at every corner of the result (16 patches, 64 corners, and the
    display's smaller cells where the lamp's light changes) each map and the colours equal the source's at that point, under the same names, with the
    same maps active."""
    floor, _ = _checker_floor((("UVMap", (0.5, 0.5, 0.1, 0.2)), ("Detail", (3.0, 2.0, 0.0, 0.5))),
                              active="Detail", render="UVMap")
    paint = floor.data.color_attributes.new("Paint", "FLOAT_COLOR", "POINT")
    co = np.array([v.co[:] for v in floor.data.vertices])
    paint.data.foreach_set("color", np.column_stack([co[:, 0], co[:, 1], 0.5 + 0 * co[:, 0],
                                                     np.ones(len(co))]).astype(np.float32).ravel())
    mesh = _solve(blender)["Floor"].data
    assert [l.name for l in mesh.uv_layers] == ["UVMap", "Detail"]
    assert mesh.uv_layers.active.name == "Detail"
    assert [l.name for l in mesh.uv_layers if l.active_render] == ["UVMap"]
    points, _, corners = mesh_arrays(mesh)
    xy = points[corners, :2].astype(np.float64)
    assert len(corners) >= 64
    for name, (a, b, c, d) in (("UVMap", (0.5, 0.5, 0.1, 0.2)), ("Detail", (3.0, 2.0, 0.0, 0.5))):
        uv = np.empty(len(corners) * 2, np.float32)
        mesh.uv_layers[name].uv.foreach_get("vector", uv)
        np.testing.assert_allclose(uv.reshape(-1, 2), xy * [a, b] + [c, d], atol=1e-5)
    domain, colours = read_colours(mesh, "Paint")
    assert domain == "CORNER"
    np.testing.assert_allclose(colours[:, :3], np.column_stack([xy, np.full(len(xy), 0.5)]), atol=1e-5)
    # what the solid view shows, and the render's default colours: the source's
    assert mesh.color_attributes.active_color.name == "Radiosity"
    assert mesh.color_attributes[mesh.color_attributes.render_color_index].name == "Paint"


def test_a_checker_floor_s_result_material_reads_the_same_image_through_the_uv_map(blender):
    """The result material is a copy of the floor's, cut down to what drives its base colour
    (the same image through the same UV Map node), times the 'Radiosity Light' attribute, into an
    Emission shader; the user's material is unchanged; a second run replaces our material
    rather than piling another beside it, and the flat per-patch view stays as 'Radiosity
    Patches'."""
    floor, material = _checker_floor()
    before = _material_state(material)
    result = _solve(blender)["Floor"]
    (ours,) = result.data.materials
    assert ours.name == "Floor Radiosity" and ours is not material
    tree = ours.node_tree
    (texture,) = [n for n in tree.nodes if n.bl_idname == "ShaderNodeTexImage"]
    assert texture.image == floor.data.materials[0].node_tree.nodes["Image Texture"].image
    uv_node = texture.inputs["Vector"].links[0].from_node
    assert uv_node.bl_idname == "ShaderNodeUVMap" and uv_node.uv_map == "UVMap" and "UVMap" in result.data.uv_layers
    attributes = {(n.attribute_type, n.attribute_name) for n in tree.nodes if n.bl_idname == "ShaderNodeAttribute"}
    assert attributes == {("GEOMETRY", "Radiosity Light"), ("GEOMETRY", "Radiosity Patches"),
                          ("VIEW_LAYER", "radiosity.show_patches")}
    output = tree.get_output_node("CYCLES")
    assert output.inputs["Surface"].links[0].from_node.bl_idname == "ShaderNodeEmission"
    assert not [n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled"]
    assert _material_state(material) == before
    assert {"Radiosity", "Radiosity Patches", "Radiosity Light"} <= {a.name for a in result.data.color_attributes}
    _solve(blender)
    ours = [m for m in bpy.data.materials if "radiosity_textured_from" in m.keys()]
    assert [m.name for m in ours] == ["Floor Radiosity"]
    assert _material_state(material) == before


def test_a_material_without_a_known_surface_shader_falls_back_with_a_note(blender, monkeypatch):
    """A Glossy BSDF's result shows the baked colours ('Radiosity Result'), and a note says why."""
    floor, _ = _checker_floor()
    glossy = bpy.data.materials.new("Shiny")
    tree = glossy.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    node = tree.nodes.new("ShaderNodeBsdfGlossy")
    tree.links.new(node.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    block = make_object("Block", [(0.2, 0.2, 0.1), (0.4, 0.2, 0.1), (0.4, 0.4, 0.1), (0.2, 0.4, 0.1)],
                        [(0, 1, 2, 3)], [glossy])
    block.select_set(True)
    outputs = solve_outputs(monkeypatch)
    results = _solve(blender)
    reports = outputs[0].notes  # (what the operator reports once the results are written)
    assert [m.name for m in results["Block"].data.materials] == ["Radiosity Result"]
    assert [m.name for m in results["Floor"].data.materials] == ["Floor Radiosity"]
    assert any("'Shiny'" in r and "not a Principled" in r for r in reports), reports


def test_above_the_smooth_limit_the_textures_take_each_patch_s_own_light(blender, monkeypatch):
    """Past SMOOTH_MAX_PATCHES the light is written flat, one value a patch on the FACE domain
    (16 bytes a patch), and the material still reads the texture: a note says so."""
    monkeypatch.setattr(options, "SMOOTH_MAX_PATCHES", 4)
    outputs = solve_outputs(monkeypatch)
    _checker_floor()
    mesh = _solve(blender)["Floor"].data
    assert any(n.startswith("smooth colours left out at 16 patches (Textured makes them up to 4")
               and "each patch's own light" in n for n in outputs[0].notes), outputs[0].notes
    light = mesh.attributes["Radiosity Light"]
    assert light.domain == "FACE" and len(light.data) == len(mesh.polygons) == 16
    assert mesh.materials[0].name == "Floor Radiosity"
    assert mesh.color_attributes["Radiosity"].domain == "CORNER"


def _linear(srgb):
    return np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)


def _srgb(linear):
    return np.where(linear <= 0.0031308, 12.92 * linear, 1.055 * linear ** (1 / 2.4) - 0.055)



def _top_camera(scene, location, ortho_scale, pixels):
    """An orthographic camera looking down from ``location`` as the scene's, a square image of
    ``pixels`` a side rendered on one thread."""
    data = bpy.data.cameras.new("Top")
    data.type, data.ortho_scale = "ORTHO", ortho_scale
    camera = bpy.data.objects.new("Top", data)
    camera.location = location
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.resolution_x = scene.render.resolution_y = pixels
    scene.render.threads_mode, scene.render.threads = "FIXED", 1


def _preview_centres(blender, tmp_path, name="preview.png", exposure=None, sources=("Floor",), samples=4):
    """The linear grey of the centre pixel of each checker square, (SQUARES, SQUARES), from the
    preview of the results of ``sources`` rendered from above at 8 pixels a square at ``samples``
    (``exposure``: by default, the brightest square's light just below white)."""
    scene = blender.scene
    if scene.camera is None:
        _top_camera(scene, (0.5, 0.5, 2.0), 1.0, 8 * SQUARES)
    light = np.empty(0)
    for obj in result_objects():
        attr = obj.data.attributes.get("Radiosity Light") or obj.data.color_attributes.get("Radiosity")
        values = np.empty(len(attr.data) * 4, np.float32)
        attr.data.foreach_get("color", values)
        light = np.concatenate([light, values.reshape(-1, 4)[:, :3].ravel()])
    if exposure is None:
        exposure = float(np.log2(0.9 / (0.8 * light.max())))
    path = str(tmp_path / name)
    render_preview(path, [o for o in bpy.data.objects if o.name in sources], width=8 * SQUARES, samples=samples,
                   exposure=exposure)
    image = bpy.data.images.load(path)
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    grey = _linear(pixels.reshape(8 * SQUARES, 8 * SQUARES, 4)[..., :3].mean(axis=2))
    return grey[4::8, 4::8]


def _light_of(obj, name="Radiosity Light"):
    """(C,3) the result's 'Radiosity Light' colours (or ``name``'s)."""
    light = obj.data.attributes[name]
    values = np.empty(len(light.data) * 4, np.float32)
    light.data.foreach_get("color", values)
    return values.reshape(-1, 4)[:, :3]


def _neighbour_ratios(centres):
    """Brighter over darker of every two neighbouring squares."""
    pairs = [(centres[:, 1:], centres[:, :-1]), (centres[1:], centres[:-1])]
    return np.concatenate([(np.maximum(a, b) / np.minimum(a, b)).ravel() for a, b in pairs])


def test_the_preview_shows_the_texture_at_pixel_resolution(blender, tmp_path):
    """A checker floor (light 0.8, dark 0.1; four squares a patch's side) under a point lamp,
    solved with the default output and previewed from above at 8 pixels a square: neighbouring
    squares' centre pixels differ by the texture's 8:1 (the light changes by a few percent
    over a square's width, the 8-bit picture by under 1%: within 15%); a flat or smooth patch
    colour cannot show squares smaller than the patch (ratio near 1)."""
    _checker_floor()
    _solve(blender)
    centres = _preview_centres(blender, tmp_path)
    assert centres.min() > 0
    assert 8 / 1.15 < np.median(_neighbour_ratios(centres)) < 8 * 1.15, np.median(_neighbour_ratios(centres))


@pytest.mark.parametrize("live", [False, True])
def test_the_flat_switch_shows_the_paper_s_patches_without_a_new_run(blender, tmp_path, live):
    """The panel's 'Flat patches (paper)' switches every result material to the flat per-patch
    colours: the 4 x 4 squares inside each 0.25 m patch come out equal (within the 8-bit
    picture's dithered rounding: two steps), and the checker shows again once it is off; with
    live lamps too (the camera then sees the flat colours, not its shader's gather)."""
    _checker_floor()
    floor = _solve(blender, live_lamps=live)["Floor"]
    blender.scene.radiosity.show_patches = True
    # (live, 'Radiosity Bounced Light' holds no lamp light: both pictures exposed by the flat colours, whose
    # patches' means the light squares (0.8 against a mean of 0.45) pass by 1.8x)
    flat_max = read_colours(floor.data, "Radiosity Patches")[1][:, :3].max()
    exposure = float(np.log2(0.9 / (2.0 * flat_max))) if live else None
    flat = _preview_centres(blender, tmp_path, "flat.png", exposure)
    codes = np.round(255 * _srgb(flat))  # (the 8-bit picture's own steps, dithered by one each way)
    per_patch = codes.reshape(4, 4, 4, 4).transpose(0, 2, 1, 3).reshape(16, 16)
    assert (np.ptp(per_patch, axis=1) <= 2).all()
    blender.scene.radiosity.show_patches = False
    textured = _preview_centres(blender, tmp_path, "textured.png", exposure)
    assert np.median(_neighbour_ratios(textured)) > 8 / 1.15


def test_an_emitter_s_result_shows_its_emission_colour_times_strength(blender, tmp_path):
    """A black glowing floor (Principled, base 0, emission (0.5, 0.25, 0.1) x 2): its result
    material adds emission colour x strength to the (black) surface times the light, so the
    preview shows (1.0, 0.5, 0.2) (the 8-bit picture: within 1.5% and one dithered step). The
    wall beside it faces away, so no patch reflects any light (before, filtering that noise-free
    zero light divided 0 by 0 and the run failed)."""
    material = principled("Glow", (0.0, 0.0, 0.0), (0.5, 0.25, 0.1), 2.0)
    floor = make_object("Floor", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], [material])
    floor.select_set(True)
    make_object("Wall", [(0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)], [(0, 3, 2, 1)],
                [principled("White", (0.7, 0.7, 0.7))]).select_set(True)
    _solve(blender)
    scene = blender.scene
    _top_camera(scene, (0.5, 0.4, 2.0), 0.5, 16)
    path = str(tmp_path / "glow.png")
    render_preview(path, [o for o in bpy.data.objects if o.name in ("Floor", "Wall")], width=16, samples=4)
    image = bpy.data.images.load(path)
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    rgb = _linear(pixels.reshape(-1, 4)[:, :3]).mean(axis=0)
    np.testing.assert_allclose(rgb, [1.0, 0.5, 0.2], rtol=0.015, atol=2e-3)


def test_a_source_attribute_named_as_ours_is_left_out_with_a_note(blender, monkeypatch):
    """A floor carrying its own colour attribute 'Radiosity' (a copy of an old result, say): the
    result's 'Radiosity' is the solve's light, not the copy, and a note says the source's was
    left out."""
    floor, _ = _checker_floor()
    paint = floor.data.color_attributes.new("Radiosity", "FLOAT_COLOR", "POINT")
    paint.data.foreach_set("color", np.tile([0.0, 1.0, 0.0, 1.0], len(floor.data.vertices)).astype(np.float32))
    outputs = solve_outputs(monkeypatch)
    mesh = _solve(blender)["Floor"].data
    assert [a.name for a in mesh.color_attributes].count("Radiosity") == 1
    _, values = read_colours(mesh, "Radiosity")
    assert not np.allclose(values[:, :3], [0.0, 1.0, 0.0])  # (the grey floor's light, not the green copy)
    assert any("'Floor': its colour attribute 'Radiosity'" in n for n in outputs[0].notes), outputs[0].notes


def test_a_principled_floor_s_copy_shows_its_specular_light_beside_its_base_colour(blender):
    """A Principled BSDF at its default specular level returns more than its base colour (its
    specular layer's light): baked, the copy's reflectivity node carries the material's own terms
    (their mean over the views), not the identity (which showed the floor darker than its
    render); live under a lamp, its EEVEE output shows them as the camera sees them
    (``glossy_layers.as_viewed``: two RGB Curves of the view cosine, the glossy albedo rising
    towards grazing), whose cosine-weighted means over the views are those terms (within 0.5% of
    the offset)."""
    from addon.blender_read.materials import surface_terms

    floor, material = _checker_floor()
    material.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.5
    copy = _solve(blender)["Floor"].data.materials[0]
    node = next(n for n in copy.node_tree.nodes if n.label == "Reflectivity")
    scale, offset = surface_terms(material)
    assert np.allclose(node.inputs[1].default_value[:], scale, atol=1e-6)
    assert np.allclose(node.inputs[2].default_value[:], offset, atol=1e-6)
    assert not any(n.bl_idname == "ShaderNodeRGBCurve" for n in copy.node_tree.nodes)
    copy = _solve(blender, live_lamps=True)["Floor"].data.materials[0]
    curves = {n.label: n.mapping for n in copy.node_tree.nodes if n.bl_idname == "ShaderNodeRGBCurve"}
    x = np.linspace(0.0, 1.0, 2001)
    for label, terms in (("Base colour's weight as viewed", scale), ("Glossy layers' albedo as viewed", offset)):
        mapping = curves[label]
        for c in range(3):
            values = np.array([mapping.evaluate(mapping.curves[c], float(v)) for v in x])
            assert abs(np.trapz(2 * x * values, x) - terms[c]) < 0.005 * offset[c]
    grazing, facing = (curves["Glossy layers' albedo as viewed"].evaluate(curves["Glossy layers' albedo as viewed"].curves[0], v)
                       for v in (0.05, 1.0))
    assert grazing > 3 * facing and min(offset) > 0.01 and max(scale) < 1.0


def test_at_the_panels_defaults_the_results_are_live_and_material_preview_shows_the_scenes_lamps(blender):
    """Live lamps is the default (the picture closest to Cycles' at equal time,
    docs/picture.md): a solve at the panel's defaults gives each textured copy its own shader for
    the lamp to light, and the 3D views' Material Preview is switched to the scene's lamps and
    world (its studio light would light the live results in their place). A baked run leaves
    Material Preview's lighting as the user set it."""
    _checker_floor()
    views = [space for screen in bpy.data.screens for area in screen.areas if area.type == "VIEW_3D"
             for space in area.spaces if space.type == "VIEW_3D"]
    assert views
    for space in views:
        space.shading.use_scene_lights = space.shading.use_scene_world = False
    s = blender.scene.radiosity
    assert s.live_lamps and s.output == "TEXTURED"
    _solve(blender, live_lamps=False)
    assert not any(space.shading.use_scene_lights or space.shading.use_scene_world for space in views)
    s.property_unset("live_lamps")
    s.patch_size, s.target_error = 0.25, 5.0
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    copy = {o["radiosity_source"]: o for o in result_objects()}["Floor"].data.materials[0]
    assert copy.get("radiosity_live_lamps")
    assert "ShaderNodeBsdfPrincipled" in {n.bl_idname for n in copy.node_tree.nodes}
    assert all(space.shading.use_scene_lights and space.shading.use_scene_world for space in views)


def test_live_lamps_leave_the_lamps_own_light_to_the_renderer_and_show_the_same_picture(blender, tmp_path):
    """Live lamps: a lone floor under a point lamp has no light but the lamp's own, so its
    'Radiosity Bounced Light' (what Cycles' output reads) is 0, while 'Radiosity Light' holds
    the whole light as a baked run's does (what exporters and EEVEE read: each corner within
    1% of the baked one's largest; before, it was the bounced light) (within 1% of the baked one: the solve's and the lamps' patch means,
    each from its own points; the lamp's light drawn by the renderer, each pixel's; the emission is
    seen by the camera alone and lights nothing), its material adds its own Principled shader for
    the lamp to light; the preview (Cycles, no bounces, denoised) shows the checker's 8:1 and,
    square by square, the baked preview's picture within 5% (the solve's 5% patches against the
    renderer's pixels; Lambertian: Specular IOR Level 0)."""
    floor, material = _checker_floor()
    material.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    baked_light = _light_of(_solve(blender)["Floor"])
    exposure = float(np.log2(0.9 / (0.8 * baked_light.max())))
    baked = _preview_centres(blender, tmp_path, "baked.png", exposure)
    results = _solve(blender, live_lamps=True)
    assert np.abs(_light_of(results["Floor"], "Radiosity Bounced Light")).max() < 0.01 * baked_light.max()
    assert np.abs(_light_of(results["Floor"]) - baked_light).max() < 0.01 * baked_light.max()
    copy = results["Floor"].data.materials[0]
    nodes = copy.node_tree.nodes
    kinds = {n.bl_idname for n in nodes}
    assert {"ShaderNodeBsdfPrincipled", "ShaderNodeAddShader", "ShaderNodeMixShader", "ShaderNodeLightPath"} <= kinds
    emission = next(n for n in nodes if n.bl_idname == "ShaderNodeEmission")
    assert _solved_light_leaves_camera_hits(emission)
    assert material.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value == 0  # (the user's untouched)
    live = _preview_centres(blender, tmp_path, "live.png", exposure)
    assert 8 / 1.15 < np.median(_neighbour_ratios(live)) < 8 * 1.15
    ratio = live / baked
    assert 0.95 < np.median(ratio) < 1.05 and np.percentile(np.abs(ratio - 1), 90) < 0.05, np.percentile(ratio, [5, 50, 95])


def test_live_lamps_leave_an_emitting_material_s_own_light_to_the_renderer_too(blender, tmp_path):
    """Live lamps with an emitting material: a checker floor lit by a glowing Principled panel
    standing beside it (no lamp; Lambertian: Specular IOR Level 0) has no light but the panel's
    own, so its 'Radiosity Bounced Light' is 0 (within 2% of the baked one: the solve's and the live
    patch means, each from its own points); the panel's copy keeps its own emission, which lights
    the floor in the render (the floor's solved light is seen by the camera alone), sampled as a
    light by the preview (its 16 samples, denoised); the preview shows the baked picture's
    brightness within 5% and the exact light's shape within each checker colour within 4%
    (measured 1.7-2.4% for either picture; 5.6% with the panel's emission not sampled)."""
    floor, material = _checker_floor()
    material.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    bpy.data.objects.remove(bpy.data.objects["Bulb"])
    glow = principled("Glow", (0.0, 0.0, 0.0), (1.0, 1.0, 1.0), 20.0)
    make_object("Panel", [(1.3, 0.0, 0.0), (1.3, 1.0, 0.0), (1.3, 1.0, 0.8), (1.3, 0.0, 0.8)], [(0, 3, 2, 1)],
                [glow]).select_set(True)
    baked_light = _light_of(_solve(blender, target_error=1.0)["Floor"])
    exposure = float(np.log2(0.9 / (0.8 * baked_light.max())))
    shown = dict(sources=("Floor", "Panel"), samples=16)
    baked = _preview_centres(blender, tmp_path, "baked.png", exposure, **shown)
    results = _solve(blender, live_lamps=True)
    assert np.abs(_light_of(results["Floor"], "Radiosity Bounced Light")).max() < 0.02 * baked_light.max()
    panel = results["Panel"].data.materials[0].node_tree.nodes
    assert next(n for n in panel if n.bl_idname == "ShaderNodeBsdfPrincipled").inputs["Emission Strength"].default_value == 20
    floor_nodes = results["Floor"].data.materials[0].node_tree.nodes
    emission = next(n for n in floor_nodes if n.bl_idname == "ShaderNodeEmission")
    assert _solved_light_leaves_camera_hits(emission)
    live = _preview_centres(blender, tmp_path, "live.png", exposure, **shown)
    ratio = live / baked
    assert 0.95 < np.median(ratio) < 1.05, np.percentile(ratio, [5, 50, 95])
    shape = live / _panel_form_factors()  # (the exact light's shape: each checker colour's own constant)
    squares = np.add.outer(np.arange(SQUARES), np.arange(SQUARES)) % 2 == 0
    for colour in (squares, ~squares):
        assert np.std(shape[colour]) < 0.04 * np.median(shape[colour]), np.percentile(shape[colour], [5, 50, 95])


def _panel_form_factors():
    """(SQUARES, SQUARES) the form factor from each checker square's centre (as the camera
    from above sees the squares, row 0 at y = 1) to the panel at x = 1.3: the contour integral
    over its four edges (a differential area to a polygon)."""
    x = (np.arange(SQUARES) + 0.5) / SQUARES
    X, Y = np.meshgrid(x, 1 - x)
    points = np.stack([X, Y, np.zeros_like(X)], -1)
    R = np.array([(1.3, 0.0, 0.0), (1.3, 0.0, 0.8), (1.3, 1.0, 0.8), (1.3, 1.0, 0.0)])[None, None] - points[:, :, None]
    total = 0.0
    for i in range(4):
        a, b = R[:, :, i], R[:, :, (i + 1) % 4]
        normal = np.cross(a, b)
        angle = np.arccos(np.clip((a * b).sum(-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1), -1, 1))
        total = total + angle * normal[..., 2] / np.linalg.norm(normal, axis=-1)
    return np.abs(total) / (2 * np.pi)


def test_live_results_light_nothing_again_in_a_render_with_bounces(blender, tmp_path, monkeypatch):
    """Live lamps: a result is what the camera sees; any other ray sees nothing of it but an
    emitter's own light (the glowing panel's test above: its light reaches the floor so). A
    checker floor under a white hood (walls and a ceiling, Lambertian) with a point lamp inside:
    the live preview rendered with 4 bounces shows the picture it shows with none, square by
    square within 3% (the same samples: only the bounces differ). Before, the renderer's bounces
    lit the floor a second time from the lamp-lit hood, light the solve had already put into the
    floor's 'Radiosity Light' (1.5x on the dark squares; the light ones were white)."""
    from addon.cli import preview

    _, material = _checker_floor()
    material.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    hood_v, hood_f = box_arrays((-0.5, -0.5, 0.0), (1.5, 1.5, 2.5), inward=True)
    white = principled("White", (0.8, 0.8, 0.8))
    white.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    hood = make_object("Hood", hood_v, [f for f in hood_f if any(hood_v[i][2] > 0 for i in f)], [white])
    hood.select_set(True)
    results = _solve(blender, live_lamps=True)
    assert results["Floor"].data.materials[0].get("radiosity_live_lamps")
    shown = dict(sources=("Floor", "Hood"), samples=16)
    still = _preview_centres(blender, tmp_path, "none.png", **shown)
    settings = preview.preview_settings

    def with_bounces(scene, *args, **kwargs):
        changes = settings(scene, *args, **kwargs)
        changes.set(scene.cycles, "max_bounces", 4)
        changes.set(scene.cycles, "diffuse_bounces", 4)
        return changes

    monkeypatch.setattr(preview, "preview_settings", with_bounces)
    bounced = _preview_centres(blender, tmp_path, "four.png", **shown)
    ratio = bounced / still
    assert 0.97 < np.median(ratio) < 1.03 and np.percentile(np.abs(ratio - 1), 90) < 0.03, np.percentile(ratio, [5, 50, 95])


def test_live_lamps_leave_the_worlds_light_to_the_renderer_too(blender, tmp_path):
    """Live lamps under a world: a checker floor lit by the world alone (no lamp; Lambertian) has
    no light but the world's own, so its 'Radiosity Bounced Light' is 0 (within 2% of the baked one: the
    solve's and the live patch means, each from its own rays); the preview keeps the scene's
    world, whose light the renderer draws on the floor (16 samples, denoised), and shows the baked
    picture within 5% square by square. Before, the world's light stayed in the light the
    Cycles output reads and the preview drew it with a black world: a render with the scene's
    world lit the floor twice."""
    _, material = _checker_floor()
    material.node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    bpy.data.objects.remove(bpy.data.objects["Bulb"])
    world = bpy.data.worlds.new("Sky")
    if world.node_tree is None:  # (Blender 4: nodes made on use_nodes; Blender 5 always has them)
        world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.5, 0.6, 0.7, 1.0)
    blender.scene.world = world
    baked_light = _light_of(_solve(blender)["Floor"])
    exposure = float(np.log2(0.9 / (0.8 * baked_light.max())))
    baked = _preview_centres(blender, tmp_path, "baked.png", exposure, samples=16)
    results = _solve(blender, live_lamps=True)
    assert np.abs(_light_of(results["Floor"], "Radiosity Bounced Light")).max() < 0.02 * baked_light.max()
    live = _preview_centres(blender, tmp_path, "live.png", exposure, samples=16)
    assert blender.scene.world == world  # (the preview's own put back)
    ratio = live / baked
    assert 0.95 < np.median(ratio) < 1.05 and np.percentile(np.abs(ratio - 1), 90) < 0.05, np.percentile(ratio, [5, 50, 95])


def _solved_light_leaves_camera_hits(emission):
    """Whether the Emission shader's strength (a live copy's solved light) is 1 on the rays that
    leave a camera hit (Ray Depth 1) or where the flat switch is on, and 0 on camera rays."""
    node = emission.inputs["Strength"].links[0].from_node
    sources = [s.links[0].from_node for s in node.inputs[:2]]
    depth = next((n for n in sources if n.bl_idname == "ShaderNodeMath"), None)
    return (node.bl_idname == "ShaderNodeMath" and node.operation == "MAXIMUM" and depth is not None
            and depth.operation == "COMPARE" and depth.inputs[1].default_value == 1.0
            and depth.inputs[0].links[0].from_socket.name == "Ray Depth"
            and any(n.bl_idname == "ShaderNodeAttribute" and n.attribute_name == "radiosity.show_patches" for n in sources))


def _glossy_floor_and_lit_wall(base):
    """A glossy floor (Principled, base colour ``base``, roughness 0.3, default specular) and a
    white Lambertian wall at x = 1 lit by an area lamp that faces it."""
    floor_material = principled("Glossy Floor", (base, base, base))
    node = floor_material.node_tree.nodes["Principled BSDF"]
    node.inputs["Specular IOR Level"].default_value = 0.5
    node.inputs["Roughness"].default_value = 0.3
    make_object("Floor", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], [floor_material]).select_set(True)
    make_object("Wall", [(1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0)], [(0, 1, 2, 3)],
                [principled("White", (0.8, 0.8, 0.8))]).select_set(True)
    _lamp("AREA", "Panel", location=(0.55, 0.5, 0.6), rotation=(0.0, np.radians(-90.0), 0.0), energy=30.0, size=0.3)


def _oblique_camera(angle, scale, pixels=48):
    """An orthographic camera looking along +x at ``angle`` degrees from the floor's normal,
    centred on the floor (every floor point then mirrors the wall), ``scale`` metres across.
    Returns the (rows, columns) slices of the image the floor fills, a pixel in from its edges."""
    from mathutils import Vector

    scene, a = bpy.context.scene, np.radians(angle)
    look, up = np.array([np.sin(a), 0.0, -np.cos(a)]), np.array([np.cos(a), 0.0, np.sin(a)])
    data = bpy.data.cameras.new("Oblique")
    data.type, data.ortho_scale = "ORTHO", scale
    camera = bpy.data.objects.new("Oblique", data)
    camera.location = tuple(np.array([0.5, 0.5, 0.0]) - 3.0 * look)
    camera.rotation_euler = Vector(look).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.resolution_x = scene.render.resolution_y = pixels
    scene.render.threads_mode, scene.render.threads = "FIXED", 1
    bpy.context.view_layer.update()
    axes = np.array(camera.matrix_world.to_3x3())
    assert np.allclose(-axes[:, 2], look, atol=1e-6) and np.allclose(axes[:, 1], up, atol=1e-6)
    size = scale / pixels  # (rows bottom up: row r spans [(r - pixels/2) size, (r + 1 - pixels/2) size] about the centre)
    half_rows, half_columns = np.cos(a) / 2 / size, min(0.5, scale / 2) / size
    return (slice(int(np.ceil(pixels / 2 - half_rows)) + 1, int(np.floor(pixels / 2 - 1 + half_rows))),
            slice(int(np.ceil(pixels / 2 - half_columns)) + 1, int(np.floor(pixels / 2 - 1 + half_columns))))


def _cycles_reference(path, samples=256):
    """(H,W) linear grey of the sources (result objects hidden) rendered with Cycles' own
    light transport to an EXR: 8 bounces, no glossy blur, no denoising."""
    scene = bpy.context.scene
    results = result_objects()
    for o in results:
        o.hide_render = True
    scene.render.engine = "CYCLES"
    c = scene.cycles
    c.device, c.samples, c.use_denoising, c.use_adaptive_sampling, c.seed = "CPU", samples, False, False, 1
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = 8
    c.blur_glossy, c.sample_clamp_indirect = 0.0, 0.0
    settings = scene.render.image_settings
    kept = settings.file_format, settings.color_depth
    settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(path)
    try:
        bpy.ops.render.render(write_still=True)
    finally:
        for o in results:
            o.hide_render = False
        settings.file_format, settings.color_depth = kept  # (the preview's PNG stays 8-bit sRGB)
    image = bpy.data.images.load(str(path))
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    h, w = scene.render.resolution_y, scene.render.resolution_x
    return pixels.reshape(h, w, 4)[..., :3].mean(axis=2)


def test_live_results_show_a_glossy_floor_mirroring_the_lit_wall_as_cycles_renders_it(blender, tmp_path):
    """Live lamps: a result's specular layer is drawn by the renderer, mirroring the other results
    (the preview's one bounce: a ray leaving a camera hit sees a result's shader lit by the lamps
    plus its solved light after a bounce; a deeper ray sees nothing of it but its own emission).
    A glossy grey floor (base 0.4) mirrors a lamp-lit white wall, seen at 45 and at 75 degrees:
    against Cycles' render of the scene (256 samples), each of four bands of the floor, far from
    the wall to near, is within 6% (the preview's 16 denoised samples and the solve's 2% on
    0.125 m patches; measured 0.996-1.005). Before, the floor showed its specular layer's mean
    over views of the light arriving: 0.57-0.94 of the render at 45 degrees, 0.22-0.80 at 75."""
    _glossy_floor_and_lit_wall(0.4)
    results = _solve(blender, patch_size=0.125, target_error=2.0, live_lamps=True)
    ratios = {}
    for angle, scale in ((45, 1.5), (75, 0.5)):
        rows, columns = _oblique_camera(angle, scale)
        reference = _cycles_reference(tmp_path / f"reference_{angle}.exr")[rows, columns]
        exposure = float(np.log2(0.5 / reference.max()))
        path = str(tmp_path / f"live_{angle}.png")
        render_preview(path, [bpy.data.objects["Floor"], bpy.data.objects["Wall"]], width=48, samples=16,
                       exposure=exposure)
        image = bpy.data.images.load(path)
        pixels = np.empty(len(image.pixels), np.float32)
        image.pixels.foreach_get(pixels)
        shown = _linear(pixels.reshape(48, 48, 4)[..., :3]).mean(axis=2)[rows, columns] / 2.0 ** exposure
        bands = np.array_split(np.arange(reference.shape[0]), 4)
        ratios[angle] = np.array([shown[b].mean() / reference[b].mean() for b in bands])
    assert all(np.all(np.abs(r - 1) < 0.06) for r in ratios.values()), ratios
    nodes = results["Floor"].data.materials[0].node_tree.nodes
    emission = next(n for n in nodes if n.bl_idname == "ShaderNodeEmission")
    assert _solved_light_leaves_camera_hits(emission)
    outputs = sorted(n.target for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    assert outputs == ["CYCLES", "EEVEE"]  # (EEVEE: the baked display as emission, lit by nothing of its own)


def test_live_results_gather_the_steep_light_a_lit_plate_throws_on_the_wall_beside_it(blender, tmp_path):
    """Live lamps: a camera hit gathers the light of the results its bounce meets, each lit by the
    lamps as the renderer draws them plus its solved light after a bounce, so light that changes
    within a patch keeps its shape. A white plate 3 cm from a white wall, lit from above by an
    area lamp, throws its light on a band of the wall a few centimetres high: against Cycles'
    render of the scene (256 samples), each of eight bands of the wall above the plate, 6 cm
    high, is within 6% (the preview's 16 denoised samples; measured 0.98-1.01). Before, the wall
    showed its patches' smooth solved light, which spreads the band over its 0.25 m patches:
    0.88 of the render at the plate, 1.13 a patch higher, 0.69 at the wall's top edge."""
    from mathutils import Vector

    white = principled("White", (0.8, 0.8, 0.8))
    make_object("Wall", [(1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0)], [(0, 1, 2, 3)], [white]).select_set(True)
    plate_v, plate_f = box_arrays((0.4, 0.0, 0.48), (0.97, 1.0, 0.5), inward=False)
    make_object("Plate", plate_v, plate_f, [white]).select_set(True)
    _lamp("AREA", "Panel", location=(0.6, 0.5, 0.95), energy=30.0, size=0.3)
    scene, pixels = blender.scene, 48
    data = bpy.data.cameras.new("Front")
    data.type, data.ortho_scale = "ORTHO", 0.5
    camera = bpy.data.objects.new("Front", data)
    camera.location = (-2.0, 0.5, 0.75)
    camera.rotation_euler = Vector((1.0, 0.0, 0.0)).to_track_quat("-Z", "Y").to_euler()
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.resolution_x = scene.render.resolution_y = pixels
    scene.render.threads_mode, scene.render.threads = "FIXED", 1
    rows = columns = slice(1, 47)  # (the wall above the plate, y 0.25-0.75: rows bottom up, z = 0.5 + (r + 0.5) / 96)
    reference = _cycles_reference(tmp_path / "reference.exr")[rows, columns]
    _solve(blender, target_error=2.0, live_lamps=True)
    exposure = float(np.log2(0.5 / reference.max()))
    path = str(tmp_path / "live.png")
    render_preview(path, [bpy.data.objects["Wall"], bpy.data.objects["Plate"]], width=pixels, samples=16, exposure=exposure)
    image = bpy.data.images.load(path)
    values = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(values)
    shown = _linear(values.reshape(pixels, pixels, 4)[..., :3]).mean(axis=2)[rows, columns] / 2.0 ** exposure
    bands = np.array_split(np.arange(reference.shape[0]), 8)
    ratio = np.array([shown[b].mean() / reference[b].mean() for b in bands])
    assert np.all(np.abs(ratio - 1) < 0.06), ratio
