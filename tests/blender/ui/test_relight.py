"""Relighting in Blender (addon/ui/relight.py, bpy_free/relit.py, blender_write/relight_store.py):
a solve with per-light results, the sources' strengths and colours changed, and
``radiosity.relight`` gives within noise what a fresh solve of the changed scene gives, for every
source kind (a point lamp off, an area lamp hidden, the sun, the sky and an emissive material
tinted), traces no ray, rewrites every output the run wrote, survives save and reopen and undo,
and refuses in one line, changing nothing, where there is nothing to relight.

The joint-noise statistic is the core's (tests/core/test_relighting.py): with d_j the difference
of the relit and the fresh patch values, T = sum_j A_j |d_j|^2 / (A_T (mse_relit + mse_fresh)) has
expectation 1; z = (T - 1) over its standard error sqrt(2 / n_eff), widened 2x for the patches'
shared paths; |z| < 5 passes, and the solve's own picture, not relit, must fail it (the test can
see the change)."""
import bpy
import numpy as np
import pytest

from addon.blender_write import relight_store
from addon.blender_write.results import previous_results
from addon.ui import relight as relight_ui

from . import relight_scene as rs

# (the joint-noise statistic, a solve through the operator and a spy on the core's solves: relight_scene's)
Z = rs.Z
_z, _solve, _spy_solves = rs.joint_noise_z, rs.solve, rs.spy_solves


def _only(kind):
    """Changes one source kind (relight_scene.change's change of it)."""
    def bulb():
        bpy.data.objects["Bulb"].data.energy = 0.0

    def panel():
        bpy.data.objects["Panel"].hide_render = True

    def sun():
        sun = bpy.data.objects["Sun"].data
        sun.energy, sun.color = 6.0, (1.0, 0.7, 0.4)

    def world():
        node = next(n for n in bpy.context.scene.world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
        node.inputs["Color"].default_value = (0.1, 0.3, 1.0, 1.0)
        node.inputs["Strength"].default_value = 4.0

    def glow():
        node = bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"]
        node.inputs["Emission Color"].default_value = (1.0, 0.3, 0.2, 1.0)
        node.inputs["Emission Strength"].default_value = 8.0

    def everything():
        rs.change(bpy.context)

    return locals()[kind]


@pytest.mark.parametrize("kind", ["bulb", "panel", "sun", "world", "glow", "everything"])
def test_a_relit_scene_is_a_fresh_solve_of_it_within_their_joint_noise(blender, monkeypatch, kind):
    settings = rs.build(blender)
    settings.target_error = 2.0
    _solve(monkeypatch, seed=7)
    solved, area = rs.patch_values()
    _only(kind)()
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit, _ = rs.patch_values()
    relit_mse = relight_ui.assess(bpy.context.scene).error.mse
    fresh_output = _solve(monkeypatch, seed=8)
    fresh, _ = rs.patch_values()
    result = fresh_output.result
    z = _z(relit, fresh, relit_mse, result.measured_mse, result.reflected_variance, area)
    assert abs(z) < Z, z
    # the picture before relighting is not the changed scene's: the statistic sees the change
    z_before = _z(solved, fresh, relit_mse, result.measured_mse, result.reflected_variance, area)
    assert z_before > Z, z_before


def _attributes(kind="color"):
    out = {}
    for obj in relight_store.result_collection(bpy.context.scene, create=False).objects:
        for a in obj.data.attributes:
            if a.name.startswith("Radiosity"):
                data = np.empty(len(a.data) * 4, np.float32)
                a.data.foreach_get("color", data)
                out[(obj.name, a.name)] = data
    return out


@pytest.mark.parametrize("output,light", [("TEXTURED", False), ("BOTH", True), ("VERTEX", True), ("FACE", False)])
def test_relight_traces_no_ray_and_rewrites_every_output_the_run_wrote(blender, monkeypatch, output, light):
    from addon.core.scene import raytrace

    settings = rs.build(blender, output)
    settings.light_output = light
    if output == "TEXTURED":  # (a glossy room: EEVEE's light less the lamps' is written and relit too)
        bpy.data.materials["White"].node_tree.nodes["Principled BSDF"].inputs["Specular IOR Level"].default_value = 0.5
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    before = _attributes()
    assert bpy.ops.radiosity.relight() == {"FINISHED"}  # at the solved strengths: the solve's own picture
    for key, values in _attributes().items():
        np.testing.assert_allclose(values, before[key], rtol=1e-5, atol=1e-6, err_msg=str(key))

    def no_rays(*args, **kwargs):
        raise AssertionError("relight traced a ray")

    for name in ("first_hit", "first_hit_barycentric"):
        monkeypatch.setattr(raytrace.RayTracer, name, no_rays)
        monkeypatch.setattr(raytrace.RegionTracer, name, no_rays)
    rs.change(blender)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    after = _attributes()
    assert set(after) == set(before)
    targets = {t[0] for t in relight_store.meta_of(bpy.context.scene)["targets"]}
    # (TEXTURED at the panel's defaults is live: the bounced light Cycles' output reads is relit too, and with the
    # sun and a glossy room the light less the lamps' that EEVEE's output reads)
    expected = {"FACE": {"Radiosity"}, "TEXTURED": {"Radiosity", "Radiosity Patches", "Radiosity Light",
                                                    "Radiosity Bounced Light", "Radiosity Light Less Lamps"},
                "BOTH": {"Radiosity", "Radiosity Patches", "Radiosity Light"},
                "VERTEX": {"Radiosity", "Radiosity Light"}}[output]
    assert targets == expected
    for key in after:
        if key[1] in targets:
            assert not np.allclose(after[key], before[key]), key  # every output the run wrote moved


def test_live_flat_light_and_its_bounced_part_are_relit_as_the_solve_wrote_them(blender, monkeypatch):
    """Textured above the smooth colours' patch bound, live (the panel's default): the light is
    written a patch each ('Radiosity Light', FACE) and so is the part Cycles' output reads
    ('Radiosity Bounced Light', each group's light less its direct light); at the solved
    strengths relight writes both back as the solve did (its groups add up to the whole), and a
    change moves both. Before, relight wrote the whole light into the attribute that held the
    bounced part."""
    from addon.bpy_free import options

    monkeypatch.setattr(options, "SMOOTH_MAX_PATCHES", 4)
    settings = rs.build(blender, "TEXTURED")
    assert settings.live_lamps
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    targets = {tuple(t) for t in relight_store.meta_of(bpy.context.scene)["targets"]}
    assert {("Radiosity Light", "irradiance", "FACE"), ("Radiosity Bounced Light", "bounced_irradiance", "FACE")} <= targets
    before = _attributes()
    bounced = {k: v for k, v in before.items() if k[1] == "Radiosity Bounced Light"}
    light = {k: v for k, v in before.items() if k[1] == "Radiosity Light"}
    assert bounced and all((bounced[(o, "Radiosity Bounced Light")] <= v + 1e-6).all() for (o, _), v in light.items())
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    for key, values in _attributes().items():
        np.testing.assert_allclose(values, before[key], rtol=1e-5, atol=1e-6, err_msg=str(key))
    rs.change(blender)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    after = _attributes()
    for key in list(bounced) + list(light):
        assert not np.allclose(after[key], before[key]), key


def test_relight_follows_each_weight_exactly(blender):
    """Doubling one lamp adds exactly its stored values once more: the recombination is linear."""
    rs.build(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    meta = relight_store.meta_of(bpy.context.scene)
    stored, _ = relight_store.load(bpy.context.scene, meta)
    before = _attributes()
    bpy.data.objects["Bulb"].data.energy *= 2.0
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    bulb = meta["names"].index("Bulb")
    for name in meta["objects"]:
        flat = np.moveaxis(stored.arrays[name]["flat"], 0, 2)  # (stored channel-major: (3,S,n))
        expected = np.maximum(flat.sum(axis=0) + flat[bulb], 0)
        got = np.repeat(expected, stored.sizes[name], axis=0)
        values = _attributes()[(name, "Radiosity")].reshape(-1, 4)[:, :3]
        np.testing.assert_allclose(values, got, rtol=1e-5, atol=1e-6)
        assert not np.allclose(values, before[(name, "Radiosity")].reshape(-1, 4)[:, :3])


def test_save_reopen_relight_is_the_same_and_undo_takes_a_relight_back(blender, tmp_path):
    rs.build(blender, "TEXTURED")
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    rs.change(blender)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    relit = _attributes()
    path = str(tmp_path / "relit.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    relight_store.forget()  # as a new session: the arrays come from the file
    bpy.ops.wm.open_mainfile(filepath=path)
    # read as the file opened (the first relight then reads no attribute)
    assert relight_store.meta_of(bpy.context.scene)["token"] in relight_store._CACHE
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    after = _attributes()
    assert set(after) == set(relit)
    for key in after:
        np.testing.assert_array_equal(after[key], relit[key])
    # undo: a relight is one undo step
    bpy.ops.ed.undo_push(message="relit")
    bpy.data.objects["Sun"].data.energy = 10.0
    bpy.ops.ed.undo_push(message="sun")
    assert bpy.ops.radiosity.relight("EXEC_DEFAULT", True) == {"FINISHED"}
    brighter = _attributes()
    assert any(not np.array_equal(brighter[k], relit[k]) for k in relit)
    assert bpy.ops.ed.undo() == {"FINISHED"}
    undone = _attributes()
    for key in undone:
        np.testing.assert_array_equal(undone[key], relit[key])


def _scene_state():
    return ({o.name: tuple(o.location) for o in bpy.data.objects},
            {k: v.tobytes() for k, v in _attributes().items()} if relight_store.result_collection(
                bpy.context.scene, create=False) else {})


def test_relight_without_per_light_results_or_after_they_were_deleted_says_so_and_changes_nothing(blender):
    rs.build(blender)
    state = _scene_state()
    with pytest.raises(RuntimeError, match=r"^Error: Radiosity: no per-light results to relight: solve with "
                                           r"Per-light results On or Automatic first\n?$"):
        bpy.ops.radiosity.relight()
    assert _scene_state() == state
    bpy.context.scene.radiosity.per_source = "OFF"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    state = _scene_state()
    with pytest.raises(RuntimeError, match="no per-light results to relight"):
        bpy.ops.radiosity.relight()
    assert _scene_state() == state
    bpy.context.scene.radiosity.per_source = "ON"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    relight_store.forget()
    room = bpy.data.objects["Room Radiosity"]
    room.data.attributes.remove(room.data.attributes[relight_store.attribute_name("flat", 0)])
    rs.change(blender)
    state = _scene_state()
    with pytest.raises(RuntimeError, match=r"'Room Radiosity' lost its per-source values \(flat\): solve again"):
        bpy.ops.radiosity.relight()
    assert _scene_state() == state
    bpy.data.objects.remove(bpy.data.objects["Strip Radiosity"])
    state = _scene_state()
    with pytest.raises(RuntimeError, match="the result object 'Strip Radiosity' is gone: solve again to relight"):
        bpy.ops.radiosity.relight()
    assert _scene_state() == state


def test_live_a_lamp_turned_relights_at_once_and_only_then(blender):
    rs.build(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    before = _attributes()
    bpy.data.objects["Bulb"].data.energy = 60.0
    relight_ui._STATE["pending"] = False
    bpy.context.view_layer.update()  # the depsgraph handler runs
    assert relight_ui._STATE["pending"]  # a relight is due
    relight_ui.live_tick()
    assert not relight_ui._STATE["pending"]
    after = _attributes()
    assert any(not np.array_equal(after[k], before[k]) for k in before)
    bpy.data.objects["Room"].location.x += 0.0  # nothing of a source: no relight due
    bpy.context.view_layer.update()
    assert not relight_ui._STATE["pending"]


def test_a_moved_lamp_is_stale_and_update_solves_only_its_light(blender, monkeypatch):
    settings = rs.build(blender)
    settings.target_error = 2.0
    _solve(monkeypatch, seed=7)
    scene = bpy.context.scene
    assert relight_ui.assess(scene).stale == set()
    bpy.data.objects["Bulb"].location = (0.3, 0.6, 0.4)
    bpy.context.view_layer.update()  # (as the interface does after an edit)
    outcome = relight_ui.assess(scene)
    assert outcome.stale == {"Bulb"}
    assert outcome.state(outcome.meta["names"].index("Bulb")) == "stale"
    assert "stale: Bulb (Update)" in outcome.text()
    bpy.data.objects["Sun"].data.energy = 4.0  # and a strength changed: relit, not stale
    calls = _spy_solves(monkeypatch)
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert calls == [("Bulb",)]
    assert relight_ui.assess(scene).stale == set()
    updated, area = rs.patch_values()
    updated_mse = relight_ui.assess(scene).error.mse
    monkeypatch.undo()
    fresh_output = _solve(monkeypatch, seed=9)
    fresh, _ = rs.patch_values()
    result = fresh_output.result
    assert abs(_z(updated, fresh, updated_mse, result.measured_mse, result.reflected_variance, area)) < Z


def test_a_geometry_change_or_an_added_lamp_makes_update_solve_everything(blender, monkeypatch):
    rs.build(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    scene = bpy.context.scene
    names = tuple(relight_store.meta_of(scene)["names"])
    bpy.data.objects["Strip"].location.z += 0.1
    bpy.context.view_layer.update()
    assert relight_ui.assess(scene).stale == set(names)
    calls = _spy_solves(monkeypatch)
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert calls == [names]
    rs.lamp("POINT", "Extra", (0.5, 0.2, 0.5), 10.0)
    bpy.context.view_layer.update()
    outcome = relight_ui.assess(scene)
    assert outcome.added == ["Extra"] and "Extra added since the solve" in outcome.text()
    assert bpy.ops.radiosity.update() == {"FINISHED"}
    assert "Extra" in calls[-1]
    assert bpy.ops.radiosity.update() == {"FINISHED"}  # nothing stale: no solve
    assert len(calls) == 2


def _groups(context, choice):
    from addon.blender_read.selection import read_selection
    from addon.bpy_free import relit
    from addon.bpy_free.patches import make_patches
    from addon.bpy_free.scene_notes import scene_and_notes

    objects, _ = read_selection(context)
    patches = make_patches(objects, 0.25)
    scene, _ = scene_and_notes(patches)
    notes = []
    return relit.groups_for(scene, patches, choice, notes), notes


def test_automatic_keeps_per_light_results_from_2_to_8_sources_and_light_groups_join_sources(blender):
    rs.build(blender)
    groups, notes = _groups(blender, "AUTO")
    assert set(groups.names) == {"Bulb", "Panel", "Sun", "World", "Glow"} and notes == []
    for k in range(4):
        rs.lamp("POINT", f"Extra {k}", (0.2 + 0.2 * k, 0.5, 0.5), 5.0)
    groups, notes = _groups(blender, "AUTO")
    assert groups is None and notes[0].startswith("per-light results left out: 9 sources x ")
    assert len(_groups(blender, "ON")[0].names) == 9
    assert _groups(blender, "OFF")[0] is None
    # Blender's light groups: the artist's own grouping, shared by lamps, the world and emitting objects
    for k in range(4):
        bpy.data.objects[f"Extra {k}"].lightgroup = "Extras"
    bpy.data.objects["Strip"].lightgroup = "Extras"
    bpy.context.scene.world.lightgroup = "Sky"
    groups, notes = _groups(blender, "AUTO")
    assert set(groups.names) == {"Bulb", "Panel", "Sun", "Sky", "Extras"} and notes == []
    # one source: nothing to recombine that the solve's own result does not hold
    for name in ["Bulb", "Panel", "Sun"] + [f"Extra {k}" for k in range(4)]:
        bpy.data.objects.remove(bpy.data.objects[name])
    bpy.context.scene.world = None
    bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 3.0
    assert _groups(blender, "AUTO")[0] is None and len(_groups(blender, "ON")[0].names) == 1


def test_a_light_group_relights_as_one(blender):
    """Two lamps of one light group scale together: both doubled doubles the group's light."""
    rs.build(blender)
    bpy.data.objects["Bulb"].lightgroup = "Lamps"
    bpy.data.objects["Panel"].lightgroup = "Lamps"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    meta = relight_store.meta_of(bpy.context.scene)
    assert "Lamps" in meta["names"] and "Bulb" not in meta["names"]
    bpy.data.objects["Bulb"].data.energy *= 2
    bpy.data.objects["Panel"].data.energy *= 2
    outcome = relight_ui.assess(bpy.context.scene)
    w = outcome.weights[meta["names"].index("Lamps")]
    np.testing.assert_allclose(w, 2.0)
    assert outcome.state(meta["names"].index("Lamps")) == "relit"


def test_a_colour_channel_solved_dark_cannot_be_relit_and_is_stale(blender):
    """A red lamp turned white: its green and blue light was never solved (0 x anything is 0), so
    its source is stale rather than wrongly relit; Relight says so."""
    rs.build(blender)
    bpy.data.objects["Bulb"].data.color = (1.0, 0.0, 0.0)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    bpy.data.objects["Bulb"].data.color = (1.0, 0.5, 0.5)
    outcome = relight_ui.assess(bpy.context.scene)
    bulb = outcome.meta["names"].index("Bulb")
    assert outcome.state(bulb) == "stale" and "stale: Bulb (Update)" in outcome.text()
    bpy.data.objects["Bulb"].data.color = (0.5, 0.0, 0.0)  # within what was solved: relit
    outcome = relight_ui.assess(bpy.context.scene)
    assert outcome.state(bulb) == "relit" and outcome.stale == set() and outcome.unsolved == set()


def test_a_live_emitter_s_copy_follows_its_material_on_relight(blender):
    """Live lamps: an emitting material's copy emits with its own shader (it lights the other
    results in the render; every ray but the camera's sees that emission alone), so Relight sets
    both to the source's now; before,
    only the baked copies' emission term followed, and a live glow kept its solved strength."""
    settings = rs.build(blender, output="TEXTURED")
    settings.live_lamps = True
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    copy = next(o for o in previous_results(bpy.context.scene) if o["radiosity_source"] == "Strip").data.materials[0]
    shader = copy.node_tree.nodes["Principled BSDF"]
    assert shader.inputs["Emission Strength"].default_value == 3.0
    rs.change(bpy.context)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    assert shader.inputs["Emission Strength"].default_value == 5.0
    assert tuple(shader.inputs["Emission Color"].default_value) == pytest.approx((1.0, 0.3, 0.2, 1.0))
    # (and the light it is to every ray but the camera's: colour x strength)
    seen = next(n for n in copy.node_tree.nodes if n.label == "Emission")
    assert seen.inputs["Scale"].default_value == 5.0
    assert tuple(seen.inputs[0].default_value) == pytest.approx((1.0, 0.3, 0.2))
