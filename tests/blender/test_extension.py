"""The extension in the bpy module: registration, solve, results, errors, files, panel."""

import math

import bpy
import numpy as np
import pytest

import addon
from addon.bpy_free.options import ERROR_SCALE, EXIT_POINT, METHOD, STOP_RULE
from addon.ui import estimate
from addon.bpy_free import pipeline
from addon.blender_read.materials import material_colours, transport_terms
from addon.blender_read.selection import read_selection
from addon.bpy_free import patches, worker
from addon.ui import panel
from addon.core import PatchScene, predict, relative_rms_to_mse, solve
from addon.core.mesh.meshing import concatenate, mesh_patches, triangle_areas

from .conftest import build_test_scene, mesh_arrays, read_colours, result_objects

PATCH_SIZE = 0.25
ERROR = 10.0  # percent


def configure(context, output="FACE", seed=3, threads=1):
    s = context.scene.radiosity
    s.patch_size = PATCH_SIZE
    s.target_error = ERROR
    s.output = output
    s.seed = seed
    s.threads = threads
    return s


# ---------------------------------------------------------------------------
# Registration
# ---------------------------------------------------------------------------

def _trace():
    """Everything the extension could leave behind."""
    names = {n for n in dir(bpy.types) if "radiosity" in n.lower()}
    ops = []
    for op in ("solve", "cancel", "relight", "update"):
        try:
            getattr(bpy.ops.radiosity, op).get_rna_type()
            ops.append(op)
        except KeyError:
            pass
    from addon.ui import operators, properties, relight, relight_update

    registered = [c.__name__ for c in (*properties.classes, *operators.classes, *panel.classes, *relight.classes,
                                       *relight_update.classes) if c.is_registered]
    return {
        "types": names,
        "registered": registered,
        "scene_prop": hasattr(bpy.types.Scene, "radiosity"),
        "ops": ops,
        "depsgraph_handlers": len(bpy.app.handlers.depsgraph_update_post),
        "load_handlers": len(bpy.app.handlers.load_post),
        "timers": bpy.app.timers.is_registered(estimate._start) or bpy.app.timers.is_registered(relight.live_tick),
    }


def test_register_and_unregister_leave_no_trace():
    addon.unregister()
    before = _trace()
    assert before["types"] == set() and not before["scene_prop"] and before["ops"] == []
    assert before["registered"] == []
    for _ in range(2):  # twice: unregister must really undo register
        addon.register()
        during = _trace()
        assert "VIEW3D_PT_radiosity" in during["types"]
        assert "RADIOSITY_OT_solve" in during["types"]
        assert during["registered"] == ["RadiositySettings", "RADIOSITY_OT_solve", "RADIOSITY_OT_cancel", "RADIOSITY_OT_explain",
                                        "VIEW3D_PT_radiosity", "RADIOSITY_OT_relight", "VIEW3D_PT_radiosity_relight",
                                        "RADIOSITY_OT_update"]
        assert during["scene_prop"] and during["ops"] == ["solve", "cancel", "relight", "update"]
        # the estimate's, the live relight's and the world watch's
        assert during["depsgraph_handlers"] == before["depsgraph_handlers"] + 3
        assert during["load_handlers"] == before["load_handlers"] + 2  # (relight's arrays read on open, the world watch)
        addon.unregister()
        assert _trace() == before


# ---------------------------------------------------------------------------
# Solve and results
# ---------------------------------------------------------------------------

def _covered(meshes, names, spec):
    """(the meshes as the operator meshes them: the patches a near surface partly covers split along its
    outline (the lamp 1 cm under the ceiling; core refine.covered_parts, as adaptive_patches.covered),
    (P,) bool the covered ones, the scene's hidden patches, or None)."""
    from addon.core.refine.adaptive import patch_mesh
    from addon.core.refine.covered_parts import covered_split

    made = covered_split(meshes, concatenate(meshes))
    if made is None:
        return meshes, None
    out = []
    for mesh, cell in zip(meshes, made.cells):
        out.append(mesh if cell.level.max(initial=0) == 0 else patch_mesh(cell)[0])
    return out, np.concatenate(made.covered)


def reference(spec, relative_rms=ERROR / 100, seed=3, threads=1, **solve_options):
    """The core on the same patches, meshed from the test's own arrays."""
    names = sorted(spec)
    meshes = [mesh_patches(spec[n][0], [len(f) for f in spec[n][1]], np.concatenate(spec[n][1]), PATCH_SIZE)
              for n in names]
    meshes, hidden = _covered(meshes, names, spec)
    c = concatenate(meshes)
    R = np.concatenate([spec[n][2][m.patch_face] for n, m in zip(names, meshes)])
    E = np.concatenate([spec[n][3][m.patch_face] for n, m in zip(names, meshes)])
    scene = PatchScene(c.vertices, c.triangles, c.triangle_patch, R, E, hidden=hidden)
    target = relative_rms_to_mse(predict(scene), relative_rms)
    solve_options.setdefault("stop_rule", STOP_RULE.default)  # the extension's defaults
    solve_options.setdefault("method", METHOD.default)
    solve_options.setdefault("exit_point", EXIT_POINT.default)
    solve_options.setdefault("error_scale", ERROR_SCALE)
    result = solve(scene, estimator="finite", target_mse=target, seed=seed, threads=threads, **solve_options)
    return names, meshes, c, result


def test_solve_matches_core_on_the_same_patches(blender):
    spec = build_test_scene()
    s = configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    names, meshes, combined, ref = reference(spec)
    objs = result_objects()
    assert [o["radiosity_source"] for o in objs] == names
    assert [o.name for o in objs] == [n + " Radiosity" for n in names]
    assert all(o.users_collection[0].name == "Radiosity" for o in objs)
    for k, (obj, m) in enumerate(zip(objs, meshes)):
        co, sizes, corners = mesh_arrays(obj.data)
        np.testing.assert_array_equal(sizes, m.face_sizes)
        np.testing.assert_array_equal(corners, m.corner_verts)
        np.testing.assert_allclose(co, m.points, atol=1e-6)
        domain, colours = read_colours(obj.data, "Radiosity")
        assert domain == "CORNER"
        expected = np.maximum(ref.radiosity[combined.patch_slice(k)], 0).astype(np.float32)  # (written at least 0)
        # flat per patch: every corner of a patch has the patch's colour
        np.testing.assert_array_equal(colours[:, :3], np.repeat(expected, m.face_sizes, axis=0))
        np.testing.assert_array_equal(colours[:, 3], 1.0)
    assert s.last_paths == ref.paths and s.last_rays == ref.rays
    assert s.last_patches == combined.patch_count
    assert s.last_stopped == "target"
    # the lamp emits: its radiosity is at least its emission; walls get light
    lamp = ref.radiosity[combined.patch_slice(names.index("Lamp"))]
    assert np.all(lamp >= np.array([4.0, 3.5, 3.0]) - 1e-12)
    assert np.all(ref.radiosity[combined.patch_slice(names.index("Room"))].mean(axis=0) > 0)
    # the material shows the attribute as emission
    material = objs[0].data.materials[0]
    attribute = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeAttribute")
    assert attribute.attribute_name == "Radiosity"
    assert objs[0].data.color_attributes.active_color.name == "Radiosity"


def test_stratified_sampling_and_measured_stop_reach_the_core(blender):
    """The panel's Sampling and Stop settings are the core's sampling and stop_rule."""
    spec = build_test_scene()
    s = configure(blender)
    s.method = "walk"  # (sampling is the walks' setting)
    s.sampling = "stratified"
    s.stop_rule = "measured"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    names, meshes, combined, ref = reference(spec, method="walk", sampling="stratified", stop_rule="measured")
    assert ref.sampling == "stratified" and ref.stopped == "target"
    assert s.last_paths == ref.paths and s.last_rays == ref.rays and s.last_stopped == "target"
    assert 0 < s.last_measured_mse <= ref.prediction.target_mse
    for k, obj in enumerate(result_objects()):
        domain, colours = read_colours(obj.data, "Radiosity")
        expected = ref.radiosity[combined.patch_slice(k)].astype(np.float32)
        np.testing.assert_array_equal(colours[:, :3], np.repeat(expected, meshes[k].face_sizes, axis=0))


def test_gathered_direct_light_reaches_the_core_and_the_estimate_plans_for_it(blender):
    """The panel's Direct light 'Gathered' is the core's direct_light="gathered" (bitwise the
    core's result on the same patches); the estimate then shows the paths the run is expected to
    end at and the paper's prediction beside them."""
    spec = build_test_scene()
    s = configure(blender)
    s.method = "walk"  # (the direct light setting is the walks')
    paper = estimate.compute(blender)
    s.direct_light = "gathered"
    value = estimate.compute(blender)
    assert value["direct_light"] == "gathered" and value["paper_paths"] == paper["paper_paths"]
    assert value["rays"] > value["paths"] and value["seconds"] >= value["rays"] / value["rays_per_second"] > 0
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    names, meshes, combined, ref = reference(spec, method="walk", direct_light="gathered")
    assert ref.direct_light == "gathered" and s.last_paths == ref.paths and s.last_rays == ref.rays
    assert s.last_estimator == "finite, direct light gathered"
    for k, obj in enumerate(result_objects()):
        _, colours = read_colours(obj.data, "Radiosity")
        expected = ref.radiosity[combined.patch_slice(k)].astype(np.float32)
        np.testing.assert_array_equal(colours[:, :3], np.repeat(expected, meshes[k].face_sizes, axis=0))


def test_two_way_iteration_reaches_the_core_and_the_estimate_plans_for_it(blender):
    """The panel's Method 'Two-way iteration' is the core's method="two_way" (bitwise the core's
    result on the same patches, its direct light gathered whatever the walks' setting says);
    the estimate shows the paths it is expected to end at (more than two rays each), and the
    last run names the method."""
    spec = build_test_scene()
    s = configure(blender)
    s.method = "walk"
    paper = estimate.compute(blender)
    s.method = "two_way"
    s.direct_light = "shot"  # (the walks' setting: not the two-way iteration's)
    value = estimate.compute(blender)
    assert value["planned"] and value["direct_light"] == "gathered" and value["paper_paths"] == paper["paper_paths"]
    assert value["rays"] > 2 * value["paths"] and value["efficiency"] == paper["efficiency"]
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    names, meshes, combined, ref = reference(spec, method="two_way")
    assert ref.method == "two_way" and s.last_paths == ref.paths and s.last_rays == ref.rays
    assert s.last_estimator == "two-way iteration, direct light gathered" and s.last_stopped == "target"
    assert ref.radiosity.min() < 0  # (its control variate's noise on patches that get almost no light)
    for k, obj in enumerate(result_objects()):
        _, colours = read_colours(obj.data, "Radiosity")
        expected = np.maximum(ref.radiosity[combined.patch_slice(k)], 0).astype(np.float32)  # written at least 0
        np.testing.assert_array_equal(colours[:, :3], np.repeat(expected, meshes[k].face_sizes, axis=0))
    # "Automatic" is the core's method="auto": the estimate names what it takes here, and says so.
    from addon.ui.panel import estimate_lines

    s.method = "auto"
    value = estimate.compute(blender)
    chosen = reference(spec)[3].method  # (the core resolving "auto" on the same patches)
    assert value["automatic"] and value["method"] == chosen and chosen in ("walk", "two_way")
    method_line = dict(estimate_lines(value))["method"]
    assert method_line.endswith("(automatic)") and ("two-way" in method_line.lower()) == (chosen == "two_way")


def test_smooth_colours_are_finite_on_every_corner_and_never_below_the_emission(blender):
    """The smooth light ('Radiosity', shown; the flat one beside it) is written on the CORNER domain,
    one value a polygon corner (a crease keeps a value on each side), finite and at least each
    patch's own emission (reflected light is never below 0)."""
    build_test_scene()
    configure(blender, output="BOTH")
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    for obj in result_objects():
        mesh = obj.data
        _, sizes, _ = mesh_arrays(mesh)
        _, flat = read_colours(mesh, "Radiosity Patches")
        domain, smooth = read_colours(mesh, "Radiosity")
        assert domain == "CORNER" and len(smooth) == len(mesh.loops) == sizes.sum()
        assert np.isfinite(smooth).all() and (smooth[:, :3] >= 0).all()


def test_vertex_only_output_writes_the_smooth_light_named_radiosity(blender):
    build_test_scene()
    configure(blender, output="VERTEX")
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    for obj in result_objects():
        assert [a.name for a in obj.data.color_attributes] == ["Radiosity"]
        assert obj.data.color_attributes["Radiosity"].domain == "CORNER"


def _snapshot():
    out = {}
    for obj in bpy.data.objects:
        if "radiosity_source" in obj.keys():
            continue
        entry = {"matrix": tuple(map(tuple, obj.matrix_world)), "materials": [s.material and s.material.name for s in obj.material_slots]}
        if obj.type == "MESH":
            co, sizes, corners = mesh_arrays(obj.data)
            entry.update(co=co.tobytes(), sizes=sizes.tobytes(), corners=corners.tobytes(),
                         attributes=sorted(a.name for a in obj.data.attributes))
        out[obj.name] = entry
    materials = {}
    for m in bpy.data.materials:
        if m.node_tree is None:
            continue
        materials[m.name] = [
            (n.name, i.name, repr(tuple(i.default_value) if hasattr(i.default_value, "__len__") else i.default_value))
            for n in m.node_tree.nodes for i in n.inputs if hasattr(i, "default_value")
        ]
    return out, materials


def test_originals_are_unchanged_and_rerun_replaces_results(blender):
    build_test_scene()
    configure(blender)
    before = _snapshot()
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    first = [(o.name, o.data.name) for o in result_objects()]
    after_objects, after_materials = _snapshot()
    assert after_objects == before[0]
    for name, values in before[1].items():  # the result material is new, the others the same
        assert after_materials[name] == values
    blender.scene.radiosity.seed = 11
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    second = [(o.name, o.data.name) for o in result_objects()]
    assert second == first  # replaced, not ".001" copies
    assert len(bpy.data.collections["Radiosity"].objects) == 3
    assert not [m for m in bpy.data.meshes if m.name.endswith(".001")]
    assert _snapshot()[0] == before[0]


def test_result_objects_in_the_selection_are_ignored(blender):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    for o in result_objects():
        o.select_set(True)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert len(result_objects()) == 3


def test_negative_scale_and_modifiers_keep_outward_normals(blender):
    spec = build_test_scene()
    block = bpy.data.objects["Block"]
    block.scale = (-1, 1, 1)
    block.location = (0.7, 0, 0)  # mirrored into x in [0.2, 0.5] again
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    mesh = bpy.data.objects["Block Radiosity"].data
    co, sizes, corners = mesh_arrays(mesh)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    centre = co.mean(axis=0)
    for s, n in zip(starts, sizes):
        p = co[corners[s:s + n]].astype(float)
        normal = np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
        assert np.dot(normal, p.mean(axis=0) - centre) > 0  # outward
    _ = spec


def test_textured_and_unusual_materials_are_read_with_notes(blender):
    m = bpy.data.materials.new("Textured")
    tree = m.node_tree
    node = tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (0.2, 0.3, 0.4, 1)
    tex = tree.nodes.new("ShaderNodeTexChecker")
    tree.links.new(tex.outputs["Color"], node.inputs["Base Color"])
    tex.inputs["Color1"].default_value = (0.9, 0.5, 0.1, 1)
    tex.inputs["Color2"].default_value = (0.1, 0.3, 0.5, 1)
    R, E, notes = material_colours(m)
    scale, offset, _ = transport_terms(m)  # a default Principled BSDF: its specular layer's light too
    np.testing.assert_allclose(R, scale * [0.5, 0.4, 0.3] + offset, rtol=1e-6)  # the checker's average
    assert any("Base Color" in n and "average" in n for n in notes)
    d = bpy.data.materials.new("Diffuse")
    d.node_tree.nodes.remove(d.node_tree.nodes["Principled BSDF"])
    diffuse = d.node_tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (0.1, 0.5, 0.2, 1)
    d.node_tree.links.new(diffuse.outputs["BSDF"], d.node_tree.nodes["Material Output"].inputs["Surface"])
    R, E, notes = material_colours(d)
    np.testing.assert_allclose(R, [0.1, 0.5, 0.2], rtol=1e-6)
    np.testing.assert_array_equal(E, 0)
    e = bpy.data.materials.new("Lamp")
    e.node_tree.nodes.remove(e.node_tree.nodes["Principled BSDF"])
    em = e.node_tree.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (1, 0.5, 0.25, 1)
    em.inputs["Strength"].default_value = 8.0
    e.node_tree.links.new(em.outputs["Emission"], e.node_tree.nodes["Material Output"].inputs["Surface"])
    R, E, _ = material_colours(e)
    np.testing.assert_allclose(E, [8, 4, 2])
    np.testing.assert_array_equal(R, 0)
    R, E, _ = material_colours(None)
    np.testing.assert_allclose(R, 0.8)
    # No shader the reader knows (here: nothing linked to the output): the viewport colour.
    v = bpy.data.materials.new("Viewport only")
    v.node_tree.nodes.remove(v.node_tree.nodes["Principled BSDF"])
    v.diffuse_color = (0.3, 0.6, 0.1, 1)
    R, E, notes = material_colours(v)
    np.testing.assert_allclose(R, [0.3, 0.6, 0.1], rtol=1e-6)
    np.testing.assert_array_equal(E, 0)
    assert any("viewport colour" in n for n in notes)


def test_closed_box_gives_cycles_units(blender):
    """A closed box emitting S everywhere with albedo R has B = S / (1 - R),
    in our result and in Cycles' COMBINED bake of the same box."""
    from .conftest import box_arrays, make_object, principled

    S, R = 2.0, 0.5
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    obj = make_object("Closed", v, f, [principled("Glow", (R, R, R), (1, 1, 1), S)])
    obj.select_set(True)
    s = configure(blender)
    s.patch_size = 0.5
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    _, colours = read_colours(result_objects()[0].data, "Radiosity")
    ours = colours[:, :3].mean()
    np.testing.assert_allclose(ours, S / (1 - R), rtol=0.03)

    # Cycles' COMBINED bake of the same box (pure Lambertian: no specular layer)
    obj.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.0
    obj.data.color_attributes.new("Bake", "FLOAT_COLOR", "CORNER")
    obj.data.color_attributes.active_color = obj.data.color_attributes["Bake"]
    for o in bpy.data.objects:
        o.select_set(o == obj)
    blender.view_layer.objects.active = obj
    scene = blender.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.max_bounces = scene.cycles.diffuse_bounces = 64
    scene.render.bake.target = "VERTEX_COLORS"
    assert bpy.ops.object.bake(type="COMBINED") == {"FINISHED"}
    _, baked = read_colours(obj.data, "Bake")
    np.testing.assert_allclose(baked[:, :3].mean(), S / (1 - R), rtol=0.01)
    np.testing.assert_allclose(ours, baked[:, :3].mean(), rtol=0.03)


# ---------------------------------------------------------------------------
# Bad input: reported, nothing changed
# ---------------------------------------------------------------------------

def _expect_error(match):
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.radiosity.solve()


def test_bad_input_is_reported_and_changes_nothing(blender):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    state = _snapshot()
    results = {o.name: read_colours(o.data, "Radiosity")[1].tobytes() for o in result_objects()}
    stats = blender.scene.radiosity.last_paths

    def unchanged():
        assert _snapshot() == state
        assert {o.name: read_colours(o.data, "Radiosity")[1].tobytes() for o in result_objects()} == results
        assert blender.scene.radiosity.last_paths == stats

    for o in bpy.data.objects:
        o.select_set(False)
    _expect_error("Select one or more mesh objects")
    unchanged()

    bpy.data.objects["Room"].select_set(True)
    blender.scene.radiosity.use_scene_objects = False  # the unselected lamp takes no part
    _expect_error("No emitter")
    unchanged()
    blender.scene.radiosity.use_scene_objects = True

    bpy.data.objects["Lamp"].select_set(True)
    lamp_node = bpy.data.materials["Emitter"].node_tree.nodes["Principled BSDF"]
    lamp_node.inputs["Emission Strength"].default_value = -1.0
    state = _snapshot()
    _expect_error("negative emission")
    unchanged()
    lamp_node.inputs["Emission Strength"].default_value = 4.0

    white = bpy.data.materials["White"].node_tree.nodes["Principled BSDF"]
    white.inputs["Base Color"].default_value = (math.nan, 0.5, 0.5, 1.0)
    state = _snapshot()
    _expect_error("not a finite number")
    unchanged()


# ---------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------

def test_saved_blend_reloads_with_the_attribute(blender, tmp_path):
    build_test_scene()
    configure(blender, output="BOTH")
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    saved = {o.name: (read_colours(o.data, "Radiosity")[1].copy(), read_colours(o.data, "Radiosity Patches")[1].copy())
             for o in result_objects()}
    path = str(tmp_path / "result.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    assert not result_objects()
    bpy.ops.wm.open_mainfile(filepath=path)
    objs = result_objects()
    assert sorted(o.name for o in objs) == sorted(saved)
    for o in objs:
        domain, flat = read_colours(o.data, "Radiosity")
        assert domain == "CORNER" and o.data.color_attributes["Radiosity"].data_type == "FLOAT_COLOR"
        np.testing.assert_array_equal(flat, saved[o.name][0])
        np.testing.assert_array_equal(read_colours(o.data, "Radiosity Patches")[1], saved[o.name][1])
    assert bpy.context.scene.radiosity.last_paths > 0


# ---------------------------------------------------------------------------
# Estimate and panel
# ---------------------------------------------------------------------------

def test_estimate_matches_the_core_prediction(blender):
    spec = build_test_scene()
    configure(blender).method = "walk"  # (the paper's prediction is the walks')
    value = estimate.compute(blender)
    names, meshes, combined, _ = reference(spec)
    scene = PatchScene(combined.vertices, combined.triangles, combined.triangle_patch,
                       np.concatenate([spec[n][2][m.patch_face] for n, m in zip(names, meshes)]),
                       np.concatenate([spec[n][3][m.patch_face] for n, m in zip(names, meshes)]))
    p = predict(scene, "finite", target_mse=relative_rms_to_mse(predict(scene), ERROR / 100))
    assert value["patches"] == combined.patch_count
    assert value["paper_paths"] == p.paths
    assert value["paper_rays"] == pytest.approx(p.expected_rays)
    R = p.R_ave
    t = blender.scene.radiosity.threshold
    assert value["relative_efficiency"] == pytest.approx((1 - R) * (1 + math.log(t) / math.log(R)) / (1 + R))
    blender.scene.radiosity.patch_size = PATCH_SIZE / 2
    assert estimate.compute(blender)["patches"] > value["patches"]
    for o in bpy.data.objects:
        o.select_set(False)
    assert "error" in estimate.compute(blender)


class FakeLayout:
    """Stands in for UILayout: records what is drawn, checks props exist."""

    def __init__(self, log=None):
        self.log = [] if log is None else log
        self.enabled = True
        self.active = True

    def _child(self, *args, **kwargs):
        return FakeLayout(self.log)

    column = row = box = split = _child

    def prop(self, data, name, **kwargs):
        assert name in data.bl_rna.properties, name
        self.log.append(("prop", name))

    def label(self, text="", **kwargs):
        self.log.append(("label", text))

    def operator(self, idname, text="", **kwargs):
        module, name = idname.split(".")
        getattr(getattr(bpy.ops, module), name).get_rna_type()
        self.log.append(("operator", idname))
        if text:
            self.log.append(("label", text))  # a line drawn as a button (its tooltip explains it)

        class Properties:
            pass

        return Properties()

    def progress(self, factor=0.0, type="BAR", text=""):
        assert 0.0 <= factor <= 1.0
        self.log.append(("progress", text))


def draw_panel(context):
    class Host:
        layout = FakeLayout()

    panel.VIEW3D_PT_radiosity.draw(Host, context)
    return Host.layout.log


def test_panel_draws_in_empty_normal_and_running_states(blender):
    # empty scene
    log = draw_panel(blender)
    assert ("operator", "radiosity.solve") in log and ("prop", "estimator") in log
    # normal: selection with a fresh estimate in the cache
    build_test_scene()
    configure(blender)
    estimate.STATE.value, estimate.STATE.key = estimate.compute(blender), estimate._key(blender)
    log = draw_panel(blender)
    labels = " ".join(t for k, t in log if k == "label")
    # the artist's decision first: the predicted time, then paths, and formula (4) as a sentence
    assert labels.index("Predicted time:") < labels.index("Paths:") and "Patches:" in labels
    assert "less time than" in labels and "for this error" in labels and "Target MSE" in labels
    assert "Rel. efficiency (4)" not in labels and "R_ave" not in labels
    # error estimate shown for an empty selection
    for o in bpy.data.objects:
        o.select_set(False)
    estimate.STATE.value, estimate.STATE.key = estimate.compute(blender), estimate._key(blender)
    labels = " ".join(t for k, t in draw_panel(blender) if k == "label")
    assert "Select" in labels
    # running: a job that has not finished
    objects, _ = (None, None)
    for name in ("Room", "Lamp", "Block"):
        bpy.data.objects[name].select_set(True)
    objects, _ = read_selection(blender)
    job = worker.SolveJob(objects, blender.scene.radiosity.solve_settings())
    scene = patches.make_patches(objects, PATCH_SIZE).patch_scene()
    prediction, _ = pipeline.prediction_for(scene, job.settings)
    job._on_prediction(prediction, scene.patch_count)
    mse = (0.07 * prediction.mean_reflected_radiosity) ** 2  # a 7% relative error
    job._on_progress(0.4, {"paths": 1000, "rays": 2000, "seconds": 0.1, "rays_per_second": 20000.0,
                           "measured_mse": mse, "relative_error": 0.07})
    worker.set_running_job(job)
    try:
        log = draw_panel(blender)
    finally:
        worker.set_running_job(None)
    assert ("operator", "radiosity.cancel") in log
    assert ("operator", "radiosity.solve") not in log
    assert any(k == "progress" and "40%" in t for k, t in log)
    labels = " ".join(t for k, t in log if k == "label")
    assert "Error now: 7.00% (target 10.00%)" in labels and "Rays/s: 20.0 k" in labels
    # after a run: statistics
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    labels = " ".join(t for k, t in draw_panel(blender) if k == "label")
    assert "Last run" in labels and "Stopped by: target" in labels


# ---------------------------------------------------------------------------
# Worker thread: cancel
# ---------------------------------------------------------------------------

def test_worker_thread_cancels_between_batches(blender):
    build_test_scene()
    configure(blender)
    objects, _ = read_selection(blender)
    settings = blender.scene.radiosity.solve_settings().but(paths=50_000_000)  # far more than the test waits for
    job = worker.SolveJob(objects, settings).start()
    deadline = 60
    import time

    t0 = time.perf_counter()
    while job.snapshot()["paths"] == 0 and time.perf_counter() - t0 < deadline:
        time.sleep(0.01)
    job.cancel()
    job.join(timeout=deadline)
    assert job.done.is_set() and job.error is None
    assert job.output.result.stopped == "cancelled"
    assert 0 < job.output.result.paths < settings.paths
    assert not result_objects()  # nothing written by the worker


def test_worker_reports_core_errors_as_messages(blender):
    build_test_scene()
    configure(blender)
    objects, _ = read_selection(blender)
    # a threshold outside (0, 1): the core refuses
    settings = blender.scene.radiosity.solve_settings().but(estimator="biased_infinite", threshold=2.0)
    job = worker.SolveJob(objects, settings)
    job.run()
    assert job.output is None and "threshold" in job.error and job.traceback is None


# ---------------------------------------------------------------------------
# The modal path (worker thread + timer), driven with stand-in events: the
# bpy module has no window, so Blender itself never calls invoke/modal here.
# ---------------------------------------------------------------------------

class FakeEvent:
    def __init__(self, type, value="NOTHING"):
        self.type = type
        self.value = value


def _modal_operator():
    from addon.ui.operators import RADIOSITY_OT_solve as Op

    class ModalStandIn:
        _started = None
        _timer = None
        _live = None
        _start = Op._start
        _cleanup = Op._cleanup
        _reported = Op._reported
        modal = Op.modal

        def __init__(self):
            self.reports = []

        def report(self, kind, message):
            self.reports.append((sorted(kind)[0], message))

    return ModalStandIn()


def _drive(op, context, cancel=False, seconds=60):
    import time

    t0 = time.perf_counter()
    if cancel:
        while op._started.job.snapshot()["paths"] == 0 and time.perf_counter() - t0 < seconds:
            time.sleep(0.01)
        assert op.modal(context, FakeEvent("ESC", "PRESS")) == {"RUNNING_MODAL"}
    while time.perf_counter() - t0 < seconds:
        state = op.modal(context, FakeEvent("TIMER"))
        if state != {"PASS_THROUGH"}:
            return state
        time.sleep(0.02)
    raise AssertionError("the modal solve did not finish")


def test_modal_solve_cancel_leaves_the_scene_as_before(blender):
    build_test_scene()
    configure(blender)
    s = blender.scene.radiosity
    s.target_error = 0.05  # millions of paths: still running when Esc comes
    before = _snapshot()
    op = _modal_operator()
    assert op._start(blender) is None
    assert worker.running_job() is op._started.job
    assert not bpy.ops.radiosity.solve.poll()  # one solve at a time
    assert _drive(op, blender, cancel=True) == {"CANCELLED"}
    assert worker.running_job() is None
    assert op._started.job.output.result.stopped == "cancelled"
    assert ("INFO", "Radiosity cancelled: the scene is unchanged") in op.reports
    assert not result_objects() and "Radiosity" not in bpy.data.collections
    assert _snapshot() == before and s.last_paths == 0


def test_modal_solve_writes_the_same_result_as_the_synchronous_one(blender):
    build_test_scene()
    configure(blender)
    op = _modal_operator()
    assert op._start(blender) is None
    assert _drive(op, blender) == {"FINISHED"}
    assert worker.running_job() is None
    threaded = {o.name: read_colours(o.data, "Radiosity")[1].copy() for o in result_objects()}
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    synchronous = {o.name: read_colours(o.data, "Radiosity")[1] for o in result_objects()}
    assert threaded.keys() == synchronous.keys()
    for name in threaded:
        np.testing.assert_array_equal(threaded[name], synchronous[name])


def test_modifiers_are_applied(blender):
    build_test_scene()
    block = bpy.data.objects["Block"]
    mod = block.modifiers.new("Array", "ARRAY")
    mod.count = 2
    mod.relative_offset_displace = (0, 1.2, 0)
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    co, sizes, _ = mesh_arrays(bpy.data.objects["Block Radiosity"].data)
    assert co[:, 1].max() > 0.5 + 0.3  # the arrayed copy is there
    block.modifiers.remove(mod)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    co2, sizes2, _ = mesh_arrays(bpy.data.objects["Block Radiosity"].data)
    assert len(sizes2) * 2 == len(sizes)


def test_the_estimate_thread_leaves_bpy_to_the_main_thread(blender, monkeypatch):
    """bpy is not thread-safe: the estimate thread only sets the cache; timers are registered on
    the main thread, and a main-thread timer notices the result and redraws."""
    import threading

    build_test_scene()
    configure(blender)
    calls = []
    real = bpy.app.timers.register

    def register(function, *args, **kwargs):
        calls.append((function.__name__, threading.current_thread() is threading.main_thread()))
        return real(function, *args, **kwargs)

    monkeypatch.setattr(bpy.app.timers, "register", register)
    blender.evaluated_depsgraph_get()  # the new scene evaluated (its updates invalidate the cache)
    assert estimate._start() is None  # the timer's work, called as Blender would: main thread
    estimate.STATE.thread.join(timeout=60)
    assert not estimate.STATE.thread.is_alive()
    assert calls and all(on_main for _name, on_main in calls), calls
    assert estimate.STATE.key == estimate._key(blender) and estimate.STATE.value["patches"] > 0
    # the main-thread poll: done, so it redraws and ends
    poll = getattr(estimate, "_poll", None)
    assert poll is not None and bpy.app.timers.is_registered(poll)
    assert poll() is None


def test_estimate_predicts_time_from_this_machines_ray_rate_and_warns_when_slow(blender):
    """The estimate's time is the expected rays over a ray rate measured on this scene (a pilot of
    the run), with the fixed costs; past a minute it warns, naming the patch size and the target;
    every line of the panel's estimate has a tooltip."""
    from addon.ui import operators
    from addon.ui.panel import estimate_lines

    build_test_scene()
    configure(blender)
    value = estimate.compute(blender)
    assert value["rays_per_second"] > 0 and value["seconds"] >= value["rays"] / value["rays_per_second"]
    assert value["warning"] is None  # a few seconds at most
    for term, _text in estimate_lines(value):
        assert operators.EXPLANATIONS[term]
    blender.scene.radiosity.patch_size = 0.05
    blender.scene.radiosity.target_error = 0.07  # (0.1% is predicted 55-75 s: about twice that)
    slow = estimate.compute(blender)
    assert slow["seconds"] > 60 and "patch size 0.05" in slow["warning"] and "0.07% error target" in slow["warning"]
    assert pipeline.efficiency_sentence(3.6) == "Finite needs 3.6x less time than biased infinite for this error"
    assert pipeline.efficiency_sentence(0.5).startswith("Biased infinite needs 2.0x less time")


def test_live_view_data_refines_while_solving_and_writes_nothing(blender):
    """Headless: a job with the live view on keeps its result so far (the
    data the 3D view draws), refreshed while it solves and ending near the final result; the
    triangles and colours drawn cover every patch; nothing is written into the scene."""
    from addon.ui import live_view

    build_test_scene()
    configure(blender)
    objects, _ = read_selection(blender)
    settings = blender.scene.radiosity.solve_settings().but(relative_rms=0.02)
    job = worker.SolveJob(objects, settings)
    job.live_view = True
    seen = []
    original = job._on_progress

    def watch(fraction, stats):
        original(fraction, stats)
        seen.append(job.live[0])

    job._on_progress = watch
    before = len(bpy.data.objects), len(bpy.data.meshes)
    worker_seconds = worker.LIVE_SECONDS
    worker.LIVE_SECONDS = 0.0  # every batch, for the test
    try:
        job.run()
    finally:
        worker.LIVE_SECONDS = worker_seconds
    assert job.error is None and (len(bpy.data.objects), len(bpy.data.meshes)) == before
    version, radiosity = job.live
    assert version == len(seen) >= 2 and sorted(seen) == seen
    final = job.output.result.radiosity
    assert radiosity.shape == final.shape and radiosity.dtype == np.float32
    np.testing.assert_allclose(radiosity, final, rtol=1e-5, atol=1e-6)  # the last batch's result
    positions, colours = live_view.triangles(job.patches, radiosity)
    T = len(job.patches.combined.triangles)
    assert positions.shape == (3 * T, 3) and colours.shape == (3 * T, 4)
    assert positions.dtype == np.float32 and colours.dtype == np.uint8  # the vertex buffer's formats
    assert (colours[:, 3] == 255).all() and colours[:, :3].max() > 25
    # each corner has its patch's display colour, in steps of 1/255
    patch_of_corner = np.repeat(job.patches.combined.triangle_patch, 3)
    expected = live_view.display_colours(radiosity)[patch_of_corner]
    assert np.abs(colours[:, :3] / 255 - expected).max() <= 0.5 / 255 + 1e-6
    # without the live view (the command line, scripts): no copies made
    quiet = worker.SolveJob(objects, settings)
    quiet.run()
    assert quiet.live == (0, None)
