"""Principled BSDF materials read as the light they return into the room (base colour plus the
specular and metallic layers' hemispherical albedo), with one note per material."""

import bpy
import numpy as np
import pytest

from addon.blender_read import images
from addon.blender_read.materials import _LAYERS_COUNTED as LAYERS, material_colours, surface_terms, transport_terms
from addon.blender_read.selection import read_selection
from addon.bpy_free import pipeline
from addon.core.materials import principled as core

from ..conftest import box_arrays, make_object, read_colours, result_objects
from ..test_extension import configure
from .test_selection import _unchanged_after_error

HIGHLIGHTS = ("view-dependent highlights (shown as under even light, at the camera's angle on a dielectric, else as "
              "their average over view directions; with Live lamps, the lamps' drawn by the renderer)")


def default_material(name, base, **inputs):
    """A Principled BSDF at Blender's defaults but for ``base`` and the named inputs."""
    m = bpy.data.materials.new(name)
    node = m.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*base, 1.0)
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    return m


def test_a_default_principled_material_returns_more_than_its_base_colour(blender):
    """Roughness 0.5, IOR 1.5, Specular IOR Level 0.5: the specular layer's light on top of the
    base colour scaled by what that layer leaves; a saturated floor's weak channel the most."""
    floor = (0.3, 0.1, 0.02)
    R, _, _ = material_colours(default_material("Floor", floor))
    # solved: the light passed on in the room, under Cycles' default Filter Glossy (1)
    assert blender.scene.cycles.blur_glossy == 1.0
    expected = core.principled_albedo(core.PrincipledInputs(base=floor, filter_glossy=1.0))
    np.testing.assert_allclose(R, expected, rtol=1e-6)  # (Blender keeps the colour in float32)
    assert R[2] > 3 * floor[2] and R[0] > floor[0]
    scale, offset = surface_terms(bpy.data.materials["Floor"])  # as the camera sees it
    np.testing.assert_allclose(scale, 0.9388, atol=2e-3)  # 1 - the layering estimate, cosine-weighted
    np.testing.assert_allclose(offset, 0.0598, atol=2e-3)  # the specular layer's multiscatter albedo
    *terms, (share, alpha) = transport_terms(bpy.data.materials["Floor"])
    np.testing.assert_allclose(terms, [scale, [0.0440] * 3], atol=2e-3)
    # its glossy lobe: all of the offset (a dielectric), alpha roughness squared widened by Filter Glossy
    np.testing.assert_allclose(share, terms[1], rtol=1e-9)
    assert 0.25 < alpha < 0.5
    blender.scene.cycles.blur_glossy = 0.0  # no Filter Glossy: the light passed on is the light seen
    np.testing.assert_allclose(material_colours(bpy.data.materials["Floor"])[0], scale * floor + offset, rtol=1e-6)
    # Specular IOR Level 0 (no specular layer) and the Diffuse BSDF: the base colour itself
    R, _, notes = material_colours(default_material("Matte", floor, **{"Specular IOR Level": 0.0}))
    np.testing.assert_allclose(R, floor, rtol=1e-6)
    assert not notes
    # metallic: an F82 conductor whose colour is the base colour (white: all the light)
    R, _, _ = material_colours(default_material("Chrome", (1, 1, 1), Metallic=1.0))
    np.testing.assert_allclose(R, 1.0, atol=1e-9)
    gold = (0.9, 0.6, 0.2)
    R, _, _ = material_colours(default_material("Gold", gold, Metallic=1.0, Roughness=0.3))
    np.testing.assert_allclose(R, core.principled_albedo(core.PrincipledInputs(base=gold, metallic=1.0,
                                                                               roughness=0.3)), rtol=1e-6)
    blender.scene.cycles.blur_glossy = 1.0


def test_textures_and_colour_attributes_carry_the_specular_light_per_patch(blender):
    """An image texture's pixels and a colour attribute's colours are base colours: each patch
    gets scale * its mean + offset, as the material's own value does."""
    m = default_material("Painted", (0.1, 0.1, 0.1))
    tree = m.node_tree
    image = bpy.data.images.new("Paint", 2, 1, float_buffer=True)
    image.pixels.foreach_set(np.array([0.6, 0.2, 0.05, 1, 0.2, 0.4, 0.02, 1], np.float32))
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    a = default_material("Tinted", (0.1, 0.1, 0.1))
    attribute = a.node_tree.nodes.new("ShaderNodeVertexColor")
    a.node_tree.links.new(attribute.outputs["Color"], a.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    lamp = default_material("Lamp", (0.5, 0.5, 0.5), **{"Emission Strength": 1.0})
    box = make_object("Box", v, f, [m, a, lamp], face_materials=[0, 1, 2, 1, 1, 1])
    box.data.uv_layers.new(name="UVMap")
    colours = box.data.color_attributes.new("Col", "FLOAT_COLOR", "CORNER")
    colours.data.foreach_set("color", np.tile([0.05, 0.3, 0.6, 1.0], len(colours.data)).astype(np.float32))
    box.data.color_attributes.active_color = colours
    box.select_set(True)
    objects, _ = read_selection(blender)
    (o,) = objects
    # (a dielectric's terms do not depend on its base; solved under the default Filter Glossy)
    scale, offset = core.surface_terms(core.PrincipledInputs(filter_glossy=1.0))
    pixels = images.linear_pixels(image)
    np.testing.assert_allclose(o.slot_textures[0][0], pixels * scale + offset, rtol=1e-6)
    expected = np.array([0.05, 0.3, 0.6]) * scale + offset
    np.testing.assert_allclose(o.slot_colours[1], np.broadcast_to(expected, o.slot_colours[1].shape), rtol=1e-6)
    assert o.slot_textures[1] is None and o.slot_colours[0] is None


def test_each_patch_carries_its_materials_glossy_lobe_into_the_solved_scene(blender):
    """A Principled box (roughness 0.3) and a Diffuse BSDF box: the first's patches carry the
    glossy share and alpha its material's terms give (without Filter Glossy, alpha 0.3 squared),
    the second's none; the core scene gets them."""
    from addon.bpy_free.patches import make_patches

    blender.scene.cycles.blur_glossy = 0.0

    shiny = default_material("Shiny", (0.2, 0.3, 0.4), Roughness=0.3)
    matte = bpy.data.materials.new("Matte")
    tree = matte.node_tree
    tree.nodes.remove(tree.nodes["Principled BSDF"])
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    tree.links.new(diffuse.outputs[0], tree.nodes["Material Output"].inputs["Surface"])
    for k, material in enumerate([shiny, matte]):
        v, f = box_arrays((2 * k, 0, 0), (2 * k + 1, 1, 1), inward=False)
        make_object(f"Box {k}", v, f, [material]).select_set(True)
    lamp = default_material("Lamp", (0.5, 0.5, 0.5), **{"Emission Strength": 1.0})
    v, f = box_arrays((0, 0, 3), (1, 1, 3.1), inward=False)
    make_object("Lamp", v, f, [lamp]).select_set(True)
    objects, _ = read_selection(blender)
    patches = make_patches(objects, 0.5)
    share, alpha = patches.glossy
    _, _, (expected, expected_alpha) = transport_terms(shiny)
    names = [o.name for o in objects]
    offsets = np.cumsum([0] + [m.patch_count for m in patches.meshes])
    rows = {name: slice(offsets[k], offsets[k + 1]) for k, name in enumerate(names)}
    np.testing.assert_allclose(share[rows["Box 0"]], np.broadcast_to(expected, share[rows["Box 0"]].shape), rtol=1e-6)
    np.testing.assert_allclose(alpha[rows["Box 0"]], expected_alpha, rtol=1e-6)
    assert expected_alpha == pytest.approx(0.09) and expected.min() > 0.02
    assert not share[rows["Box 1"]].any()
    scene = patches.patch_scene()
    np.testing.assert_allclose(scene.glossy.share, np.minimum(share, scene.reflectivity))
    blender.scene.cycles.blur_glossy = 1.0


def test_one_note_per_material_naming_only_what_it_uses(blender):
    """Two objects share a default material, a second default material says the same: one note
    names both; a glass and a matte material: the glass's own note, none for the matte."""
    shared = default_material("Plaster", (0.7, 0.7, 0.7))
    other = default_material("Wood", (0.4, 0.2, 0.1))
    glass = default_material("Glass", (0.9, 0.9, 0.9), **{"Transmission Weight": 1.0})
    matte = default_material("Matte", (0.5, 0.5, 0.5), **{"Specular IOR Level": 0.0})
    lamp = default_material("Lamp", (0.5, 0.5, 0.5), **{"Emission Strength": 2.0, "Specular IOR Level": 0.0})
    for k, materials in enumerate([[shared], [shared], [other, matte], [glass], [lamp]]):
        v, f = box_arrays((2 * k, 0, 0), (2 * k + 1, 1, 1), inward=False)
        make_object(f"Box {k}", v, f, materials, face_materials=[0, 0, 0, 0, 0, len(materials) - 1]).select_set(True)
    _, notes = read_selection(blender)
    principled_notes = [n for n in notes if "Principled" in n]
    assert principled_notes == [
        f"materials 'Plaster', 'Wood': Principled specular {LAYERS}; not modelled: {HIGHLIGHTS}",
        f"material 'Glass': Principled specular {LAYERS}; not modelled: {HIGHLIGHTS}, light through transmission (only "
        "its reflection counted)",
    ]
    assert not any("'Matte'" in n or "'Lamp'" in n for n in notes)


def test_a_white_metal_is_refused_as_a_reflectivity_of_one_and_nothing_changes(blender):
    """A metallic white returns all the light (without Filter Glossy, which loses some of it after a
    diffuse bounce): refused as a base colour of 1 is, with the same reason, the scene unchanged; a
    white dielectric at roughness 0.5 returns 0.9986 (Cycles' own furnace render: 0.998) and is
    accepted."""
    blender.scene.cycles.blur_glossy = 0.0
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    box = make_object("Box", v, f, [default_material("Chrome", (1, 1, 1), Metallic=1.0),
                                    default_material("Glow", (0.5, 0.5, 0.5), **{"Emission Strength": 1.0})],
                      face_materials=[0, 1, 0, 0, 0, 0])
    box.select_set(True)
    configure(blender)
    _unchanged_after_error(blender, r"'Box': material 'Chrome' has a reflectivity \(base colour, with what a "
                                    r"Principled BSDF's other layers return\) of 1\. .*reflectivity below 1")
    blender.scene.cycles.blur_glossy = 1.0  # Cycles' default: the metal passes on 0.84 of the light
    objects, _ = read_selection(blender)
    assert 0.83 < objects[0].face_reflectivity.max() < 0.85
    blender.scene.cycles.blur_glossy = 0.0
    bpy.data.materials["Chrome"].node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 0.0
    objects, _ = read_selection(blender)
    assert 0.99 < objects[0].face_reflectivity.max() < 0.9995


def test_closed_principled_box_solves_to_emission_over_one_minus_the_albedo(blender):
    """A closed box emitting S everywhere, every face a default Principled BSDF of base b: the
    exact radiosity is S / (1 - R) with R the Principled albedo (any patch, any form factors).
    Each patch's error against it, in units of its own batch-means standard error, stays in a
    band that 24 independent normal z-scores leave with probability 1e-4 (the colour channels of
    a patch move together: one z-score a patch, green), and their mean square within the 1e-4
    tails of a chi-square of 24 degrees of freedom over 24; the base colour alone (what was read
    before) is many standard errors away."""
    S, base = 1.0, np.array([0.55, 0.4, 0.15])
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Closed", v, f, [default_material("Glow", base, **{"Emission Color": (1, 1, 1, 1),
                                                                   "Emission Strength": S})]).select_set(True)
    R = core.principled_albedo(core.PrincipledInputs(base=tuple(base), filter_glossy=1.0))
    objects, _ = read_selection(blender)
    settings = pipeline.SolveSettings(paths=400_000, patch_size=0.5, seed=11, threads=1)
    out = pipeline.run_solve(objects, settings)
    B, variance = out.result.radiosity, out.result.reflected_variance
    assert B.shape == (24, 3)
    z = ((B - S / (1 - R)) / np.sqrt(variance))[:, 1]
    assert np.abs(z).max() < 4.6
    assert 0.26 < np.mean(z ** 2) < 2.45  # the standard errors are of the right size
    before = (B - S / (1 - base)) / np.sqrt(variance)
    assert np.abs(before).mean() > 10


def test_cycles_bakes_the_closed_principled_box_to_the_same_light(blender):
    """Cycles' DIFFUSE bake (direct + indirect, no colour: the light arriving, which in the closed
    box is S / (1 - R)) of the box above agrees with the Principled albedo that the reader solves,
    Filter Glossy included, within 4 standard errors of the bake's mean (from its spread over the
    corners); the hemispherical albedo without Filter Glossy and the base colour are more than 5 off."""
    from benchmarks.cycles_comparison import configure_bake

    S, base = 1.0, np.array([0.55, 0.4, 0.15])
    bm_v, bm_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    obj = make_object("Closed", bm_v, bm_f, [default_material("Glow", base, **{"Emission Color": (1, 1, 1, 1),
                                                                               "Emission Strength": S})])
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=5)
    bpy.ops.object.mode_set(mode="OBJECT")
    obj.data.color_attributes.new("Bake", "FLOAT_COLOR", "CORNER")
    obj.data.color_attributes.active_color = obj.data.color_attributes["Bake"]
    obj.select_set(True)
    scene = blender.scene
    configure_bake(scene, threads=1)
    scene.cycles.glossy_bounces = 64
    scene.cycles.samples = 16
    scene.render.bake.target = "VERTEX_COLORS"
    scene.render.bake.use_pass_color = False
    assert bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}) == {"FINISHED"}
    _, baked = read_colours(obj.data, "Bake")
    H = baked[:, :3].astype(np.float64)
    mean, error = H.mean(axis=0), H.std(axis=0, ddof=1) / np.sqrt(len(H))
    R = core.principled_albedo(core.PrincipledInputs(base=tuple(base), filter_glossy=1.0))
    assert np.all(np.abs(mean - S / (1 - R)) < 4 * error), (mean, S / (1 - R), error)
    unblurred = core.principled_albedo(core.PrincipledInputs(base=tuple(base)))
    assert np.all(np.abs(mean - S / (1 - unblurred)) > 5 * error)
    assert np.all(np.abs(mean - S / (1 - base)) > 5 * error)


def test_cycles_bakes_a_sunlit_metal_floors_lobe_on_a_wall_as_the_solve_sends_it(blender):
    """A unit metal floor (Metallic 1, base 0.8, Roughness 0.6: all its reflection glossy, a wide
    lobe that GGX partly sends below the surface) lit by a sun at 45 degrees, and a near-black
    Diffuse wall 0.5 m beyond it facing it (no Filter Glossy). The light the floor sends to the
    wall, row by row over its middle (y in [0.25, 0.75], 16 rows of 0.125 m), as the two-way
    iteration solves it and as Cycles' DIFFUSE bake (direct and indirect, no colour) of the wall
    finds it: every row within 4.5 standard errors of both, plus 6% (the amount is the
    hemispherical mean, not the albedo at 45 degrees). The floor reflecting its light evenly (no
    lobe) sends the middle rows under half of it."""
    import math

    from benchmarks.cycles_comparison import configure_bake

    from addon.core.solver import solve

    scene = blender.scene
    metal = default_material("Metal", (0.8, 0.8, 0.8), Metallic=1.0, Roughness=0.6)
    dark = default_material("Dark", (0.05, 0.05, 0.05), **{"Specular IOR Level": 0.0})
    floor = make_object("Floor", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], [metal])
    wall = make_object("Wall", [(1.5, -0.5, 0), (1.5, -0.5, 2), (1.5, 1.5, 2), (1.5, 1.5, 0)], [(0, 1, 2, 3)], [dark])
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 1.0, 0.0
    light = bpy.data.objects.new("Sun", sun)
    scene.collection.objects.link(light)
    light.rotation_euler = (0.0, math.radians(-45.0), 0.0)  # travelling along (1, 0, -1) / sqrt 2
    scene.world = bpy.data.worlds.new("Black")
    scene.world.color = (0, 0, 0)
    if scene.world.node_tree is not None:  # (Blender 5 gives a new world a grey Background node)
        scene.world.node_tree.nodes["Background"].inputs["Color"].default_value = (0, 0, 0, 1)
    scene.cycles.blur_glossy = 0.0
    for o in (floor, wall):
        o.select_set(True)
    blender.view_layer.objects.active = floor
    objects, _ = read_selection(blender)
    out = pipeline.run_solve(objects, pipeline.SolveSettings(paths=800_000, patch_size=0.125, seed=3, threads=2))
    assert out.result.method == "two_way"
    patches = out.patches
    first = sum(m.patch_count for o, m in zip(objects, patches.meshes) if o.name != "Wall")  # (the floor's first)
    wall_rows = slice(first, first + 256) if [o.name for o in objects] == ["Floor", "Wall"] else None
    assert wall_rows is not None
    corners = patches.combined.vertices[patches.combined.triangles].mean(axis=1)
    centre = np.zeros((patches.combined.patch_count, 3))
    np.add.at(centre, patches.combined.triangle_patch, corners)
    centre = (centre / np.bincount(patches.combined.triangle_patch)[:, None])[wall_rows]
    direct = math.sqrt(0.5) / math.pi  # the sun's own light on the wall
    middle = (centre[:, 1] > 0.25) & (centre[:, 1] < 0.75)
    row = np.floor(centre[:, 2] / 0.125).astype(int)

    def profile(H, variance):
        """(16,) each row's mean over the middle less the sun's own, (16,) its standard error."""
        mean = np.array([H[middle & (row == r)].mean() for r in range(16)]) - direct
        error = np.array([np.sqrt(variance[middle & (row == r)].sum()) / (middle & (row == r)).sum() for r in range(16)])
        return mean, error

    ours, our_error = profile(out.result.irradiance[wall_rows, 0], out.result.irradiance_variance[wall_rows, 0])
    plain = solve(patches.patch_scene().with_materials(patches.reflectivity, patches.emission, glossy=None),
                  paths=800_000, seed=3, exit_point="hit", method="two_way")
    flat, _ = profile(plain.irradiance[wall_rows, 0], plain.irradiance_variance[wall_rows, 0])
    # Cycles: the wall cut into 1/16 m squares, baked at its corners
    bpy.ops.object.select_all(action="DESELECT")
    wall.select_set(True)
    blender.view_layer.objects.active = wall
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=31)
    bpy.ops.object.mode_set(mode="OBJECT")
    wall.data.color_attributes.new("Bake", "FLOAT_COLOR", "POINT")
    wall.data.color_attributes.active_color = wall.data.color_attributes["Bake"]
    configure_bake(scene, threads=2)
    scene.cycles.samples = 256
    scene.render.bake.target, scene.render.bake.use_pass_color = "VERTEX_COLORS", False
    assert bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "INDIRECT"}) == {"FINISHED"}
    _, baked = read_colours(wall.data, "Bake")
    co = np.empty(len(wall.data.vertices) * 3)
    wall.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    across = (co[:, 1] > 0.25 - 1e-6) & (co[:, 1] < 0.75 + 1e-6)
    level = np.rint(co[:, 2] * 16).astype(int)
    value = baked[:, 0].astype(np.float64)
    at = [value[across & (level == k)] for k in range(33)]
    # a row's mean by the trapezoid rule over its three vertex levels; its error from their spread across y
    weights = (0.25, 0.5, 0.25)
    cycles = np.array([sum(w * at[2 * r + i].mean() for i, w in enumerate(weights)) for r in range(16)]) - direct
    cycles_error = np.array([np.sqrt(sum((w * at[2 * r + i].std(ddof=1)) ** 2 / at[2 * r + i].size
                                         for i, w in enumerate(weights))) for r in range(16)])
    allowed = 4.5 * np.hypot(our_error, cycles_error) + 0.06 * cycles
    assert (np.abs(ours - cycles) < allowed).all(), np.c_[ours, cycles, allowed]
    assert (flat[4:8] < 0.5 * cycles[4:8]).all(), np.c_[ours, cycles, flat]
