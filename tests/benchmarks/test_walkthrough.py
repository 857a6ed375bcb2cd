"""The walkthrough benchmark's pure parts, without a render: where its cameras stand, Cycles'
samples for a share of the solve's time, the numbers from arrays, and its reports; and that its
baked display finds the product's stored light in the result materials it makes."""

import numpy as np
import pytest

from benchmarks import walkthrough_measures as wm
from benchmarks import walkthrough_report as report
from benchmarks import walkthrough_scenes as scenes
from benchmarks import walkthrough_views as wv

NEW = {"skylight_hall": (scenes.HALL_VIEWS, scenes.HALL_AIR, scenes.hall_obstacles()),
       "studio_flat": (scenes.FLAT_VIEWS, [((0.0, 0.0, 0.0), scenes.FLAT)], scenes.flat_obstacles())}


def wall_distance(point, air, step=0.01):
    """Metres from a point to the air's boundary, along the floor's four directions and up and down."""
    out = []
    for d in np.vstack([np.eye(3), -np.eye(3)]):
        t = 0.0
        while wv.inside(np.asarray(point) + (t + step) * d, air)[0]:
            t += step
        out.append(t)
    return min(out)


@pytest.mark.parametrize("name", sorted(NEW))
def test_the_new_interiors_views_stand_in_the_air_clear_of_walls_and_furniture(name):
    views, air, obstacles = NEW[name]
    assert len(views) == 10
    for view in views:
        assert wv.placement_problems(view.location, air, obstacles) == [], view.label
        assert np.linalg.norm(np.subtract(view.target, view.location)) > 0.5
        assert 1.2 <= view.location[2] <= 1.7  # eye height, standing or seated
    assert len({wv.compass(v) for v in views}) >= 5  # looking every way, not all down the room
    close = [v.label for v in views if wall_distance(v.location, air) < 0.5]
    assert len(close) >= 2  # some close to a wall


@pytest.mark.parametrize("name", sorted(NEW))
def test_the_new_interiors_obstacles_hold_their_furniture_and_lamps(name):
    _, air, obstacles = NEW[name]
    furniture = scenes.HALL_FURNITURE if name == "skylight_hall" else scenes.FLAT_FURNITURE
    parts = sum(len(boxes) for boxes in furniture.values())
    assert len(obstacles) >= parts + 3
    lamps = scenes.HALL_LAMPS if name == "skylight_hall" else scenes.FLAT_LAMPS
    for position in lamps.values():  # no camera inside a lamp
        assert "inside obstacle" in " ".join(wv.placement_problems(position, air, obstacles))


def test_a_camera_outside_the_room_in_furniture_or_at_a_wall_is_refused():
    air = [((0.0, 0.0, 0.0), (4.0, 3.0, 2.5))]
    table = [((1.0, 1.0, 0.0), (2.0, 2.0, 0.8))]
    assert wv.placement_problems((2.5, 1.5, 1.6), air, table) == []
    assert wv.placement_problems((5.0, 1.5, 1.6), air, table) == ["outside the room"]
    assert wv.placement_problems((0.1, 1.5, 1.6), air, table) != []  # 10 cm from the west wall
    assert wv.placement_problems((1.5, 1.5, 0.5), air, table)[0].startswith("inside obstacle 0")
    assert "obstacle 0" in wv.placement_problems((1.5, 1.5, 0.9), air, table)[0]  # 10 cm above the table
    l_shape = [((0.0, 0.0, 0.0), (6.0, 2.0, 3.0)), ((4.0, 0.0, 0.0), (6.0, 6.0, 3.0))]
    assert wv.placement_problems((5.0, 2.0, 1.6), l_shape, []) == []  # where the wings meet: no wall there
    assert wv.placement_problems((2.0, 4.0, 1.6), l_shape, []) == ["outside the room"]  # the L's missing corner
    assert wv.placement_problems((3.9, 2.1, 1.6), l_shape, []) != []  # the inner corner


def test_placed_views_stand_clear_spread_out_and_look_at_something_away():
    air = [((0.0, 0.0, 0.0), (5.0, 4.0, 2.7))]
    obstacles = [((1.8, 1.6, 0.0), (3.2, 2.4, 0.76)), ((0.5, 3.1, 0.0), (2.5, 3.9, 0.85)), ((3.6, 1.0, 2.2), (4.0, 1.4, 2.6))]
    targets = [np.array([3.8, 1.2, 2.45]), *wv.wall_middles(air[0])]
    views = wv.auto_views(air, obstacles, targets, 10)
    assert len(views) == 10
    spots = np.array([v.location for v in views])
    for view in views:
        assert wv.placement_problems(view.location, air, obstacles, 0.25) == []
        assert np.linalg.norm(np.subtract(view.target, view.location)[:2]) >= 1.5
    gaps = np.linalg.norm(spots[:, None] - spots[None], axis=2) + np.eye(10) * 99
    assert gaps.min() > 0.8  # spread over the room, not bunched
    assert len({wv.compass(v) for v in views}) >= 4
    with pytest.raises(ValueError, match="places for a camera"):
        wv.auto_views([((0.0, 0.0, 0.0), (0.8, 0.8, 2.5))], [], targets, 10)


def test_walls_are_told_from_furniture_by_their_span():
    room = ((0.0, 0.0, 0.0), (5.0, 4.0, 2.7))
    assert wv.spans_room(((-0.15, -0.15, -0.1), (0.0, 4.15, 2.8)), room)  # a wall
    assert wv.spans_room(((-0.15, -0.15, -0.1), (5.15, 4.15, 0.0)), room)  # the floor
    assert not wv.spans_room(((0.5, 3.1, 0.0), (2.5, 3.9, 0.85)), room)  # a sofa
    assert not wv.spans_room(((0.0, 0.0, 0.0), (5.0, 0.4, 1.0)), room)  # a long bench


# --------------------------------------------------------------------------- samples at the solve's time

def render_time(samples, view):
    """A render's seconds: a fixed part (scene sync, denoiser) and a part a sample; from the
    fifth view on the machine is busier (another job started) and everything is slower."""
    return 2.0 + 0.05 * samples if view < 4 else 3.0 + 0.1 * samples


@pytest.mark.parametrize("budget", [40.0, 120.0, 600.0])
def test_the_ten_views_share_the_solves_time(budget):
    line = (render_time(1, 0), (render_time(4, 0) - render_time(1, 0)) / 3)  # timed before, on a quiet machine
    spent, last, used = 0.0, None, []
    for k in range(10):
        n = wm.next_samples(budget, spent, 10 - k, line, last)
        wall = render_time(n, k)
        spent, last = spent + wall, (n, wall)
        used.append(n)
    # the views after the slowdown take what is left: the total within 1% (and a slow sample's rounding)
    assert abs(spent - budget) <= 0.01 * budget + 0.1
    assert used[-1] < used[0] and min(used) >= 1


def test_a_budget_below_one_sample_gives_one_sample_and_the_cap_holds():
    line = (2.0, 0.05)
    assert wm.next_samples(5.0, 0.0, 10, line) == 1  # half a second a view: less than the fixed part
    assert wm.next_samples(1e6, 0.0, 1, line, most=64) == 64
    assert wm.next_samples(20.0, 30.0, 2, line) == 1  # over budget already
    assert wm.samples_within(3.0, (2.0, 0.05)) == 21
    assert wm.line_through((2.0, 0.05), 21, 6.0) == pytest.approx((4.0, 0.1))  # twice as slow, every part


# --------------------------------------------------------------------------- numbers from arrays

def scene_arrays(seed=0, height=200, width=300, noise=0.2):
    """A truth of two objects (left 0, right 1), its reference halves with independent noise."""
    rng = np.random.default_rng(seed)
    truth = np.ones((height, width, 3))
    truth[:, width // 2:] *= 2.0
    object_id = np.zeros((height, width), int)
    object_id[:, width // 2:] = 1
    halves = [truth * (1 + noise * rng.standard_normal((height, width, 1))) for _ in range(2)]
    return truth, halves, object_id


def test_a_views_numbers_are_its_error_brightness_and_worst_object():
    truth, _, object_id = scene_arrays()
    mask = np.ones(object_id.shape, bool)
    picture = truth.copy()
    picture[object_id == 0] *= 1.1  # one object 10% bright
    sums = wm.view_sums(picture, truth, truth, object_id, mask, 2)
    n = wm.numbers(sums, ["left", "right"], 100)
    assert n["error"] == pytest.approx(0.1 * 1 / 3)  # 0.1 on a third of the light
    assert n["brightness"] == pytest.approx(3.1 / 3)
    assert n["worst"] == ["left", pytest.approx(1.1)]
    assert n["objects"]["right"] == [pytest.approx(1.0), object_id.size // 2, 0.0]
    assert n["rms"] == pytest.approx(np.sqrt(0.5 * 0.1**2) / 1.5)
    high, low = truth.copy(), truth.copy()
    high[object_id == 1] *= 1.1
    low[object_id == 1] *= 0.9  # the reference's halves 10% apart on the right object
    n = wm.numbers(wm.view_sums(truth, high, low, object_id, mask, 2), ["left", "right"], 100)
    assert n["objects"]["right"][2] == pytest.approx(0.1) and n["objects"]["left"][2] == 0.0


def test_the_rms_error_takes_the_references_noise_out():
    truth, halves, object_id = scene_arrays(noise=0.2)
    mask = np.ones(object_id.shape, bool)
    n = wm.numbers(wm.view_sums(truth, *halves, object_id, mask, 2), ["left", "right"], 100)
    # the exact picture against a noisy reference: mean |e| of the halves' mean, sigma 0.2 / sqrt(2)
    # relative to each pixel (light-weighted); its estimate's standard error is about 3e-4
    assert n["error"] == pytest.approx(0.2 / np.sqrt(2) * np.sqrt(2 / np.pi), abs=0.003)
    # the noise taken out: what is left is the estimate's own spread, sigma^2 / sqrt(N) ~ 2e-4 in the square
    assert n["rms"] < 0.03
    assert wm.reference_error([wm.reference_sums(*halves, mask)])["walk"] == pytest.approx(n["error"], rel=0.05)


def test_the_walks_numbers_weigh_every_surface_pixel_alike():
    truth, _, object_id = scene_arrays()
    small = np.zeros(object_id.shape, bool)
    small[:10, :10] = True  # a view with 100 pixels of the left object
    full = np.ones(object_id.shape, bool)
    views = [wm.view_sums(truth * 2.0, truth, truth, object_id, small, 2),  # twice as bright
             wm.view_sums(truth, truth, truth, object_id, full, 2)]  # exact
    walk = wm.walk_numbers(views, ["left", "right"])
    assert walk["views"][0]["error"] == pytest.approx(1.0) and walk["views"][1]["error"] == 0.0
    assert walk["walk"]["error"] == pytest.approx(100 / (full.size * 1.5 + 100))
    assert walk["walk"]["objects"]["left"][1] == object_id.size // 2 + 100


# --------------------------------------------------------------------------- the solve's own noise

def table_in_a_room():
    """A 2 x 2 x 1.5 m room (inward quads, 0.25 m) lit by a ceiling square, a 4 cm thick table top
    floating in it (outward quads): (PatchScene, quads (P,4,3), mask of the table top's underside)."""
    from addon.core import PatchScene

    def box(lower, upper, n, inward):
        lower, upper, quads = np.asarray(lower, float), np.asarray(upper, float), []
        for axis in range(3):
            a, b = (axis + 1) % 3, (axis + 2) % 3
            da, db = np.zeros(3), np.zeros(3)
            da[a], db[b] = (upper[a] - lower[a]) / n[a], (upper[b] - lower[b]) / n[b]
            for side in (0, 1):
                for i in range(n[a]):
                    for j in range(n[b]):
                        o = lower.copy()
                        o[axis] = upper[axis] if side else lower[axis]
                        o = o + i * da + j * db
                        q = [o, o + da, o + da + db, o + db]  # normal along +axis
                        quads.append(q if (side == 1) != inward else q[::-1])
        return np.array(quads)

    room = box((0, 0, 0), (2, 2, 1.5), (8, 8, 6), inward=True)
    quads = np.concatenate([room, box((0.6, 0.6, 0.8), (1.4, 1.4, 0.84), (4, 4, 1), inward=False)])
    P, inside = len(quads), np.arange(len(quads)) < len(room)
    centre = quads.mean(axis=1)
    light = inside & (centre[:, 2] == 1.5) & (np.abs(centre[:, 0] - 1) < 0.3) & (np.abs(centre[:, 1] - 1) < 0.3)
    R = np.where(light, 0.0, np.where(inside, 0.7, 0.3))[:, None].repeat(3, axis=1)
    E = np.where(light, 5.0, 0.0)[:, None].repeat(3, axis=1)
    triangles = (4 * np.arange(P)[:, None] + np.array([[0, 1, 2, 0, 2, 3]])).reshape(-1, 3)
    scene = PatchScene(quads.reshape(-1, 3), triangles, np.repeat(np.arange(P), 2), R, E)
    normal = np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0])
    return scene, quads, ~inside & (normal[:, 2] < 0)


def test_an_objects_own_noise_is_the_sum_of_its_patches_variances():
    area = np.array([1.0, 2.0, 1.0])
    light = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0], [0.0, 0.0, 0.0]])
    variance = np.array([[0.04] * 3, [0.01] * 3, [0.09] * 3])
    noise = wm.object_noise([("Bench", area, light, variance), ("Dark", area, 0 * light, variance)])
    assert noise["Bench"] == pytest.approx(np.sqrt(0.2**2 + (2 * 0.1) ** 2 + 0.3**2) / 5.0)
    assert np.isnan(noise["Dark"])  # no light: no relative noise


def test_an_objects_own_noise_is_its_lights_spread_over_seeds():
    """The underside of a table top in a lit room, solved by the two-way iteration with 24 seeds:
    the spread of its mean light is what ``object_noise`` says from one solve's variances (their
    median over the seeds). The sample deviation of 24 values has a relative standard error of
    1/sqrt(46) = 0.15: three of them either side."""
    from addon.core import solve

    scene, quads, under = table_in_a_room()
    area = np.linalg.norm(np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0]), axis=1)[under]
    means, said = [], []
    for seed in range(24):
        r = solve(scene, paths=40_000, seed=seed, method="two_way")
        means.append(np.sum(area * r.radiosity[under].mean(axis=1)))
        said.append(wm.object_noise([("Under", area, r.radiosity[under], r.reflected_variance[under])])["Under"])
    measured = np.std(means, ddof=1) / np.mean(means)
    assert 1 - 3 * 0.15 < measured / np.median(said) < 1 + 3 * 0.15


def test_a_tables_patches_fall_in_their_face_groups():
    """A table top on a leg standing on the floor: the legs are the sides below the lit
    underside; the legs' feet (on the floor: no light) do not count as an underside."""
    from benchmarks.walkthrough_patches import face_groups

    _, quads, _ = table_in_a_room()
    top = quads[-48:]  # the table top's 6 faces: 4 x 4 patches on its top and underside, 4 on each side
    low, high = np.array([0.7, 0.7, 0.0]), np.array([0.75, 0.75, 0.8])
    feet = np.array([[low, [low[0], high[1], 0], [high[0], high[1], 0], [high[0], low[1], 0]]])  # facing down
    side = np.array([[low, [high[0], low[1], 0], [high[0], low[1], 0.8], [low[0], low[1], 0.8]]])  # facing -y
    quads = np.concatenate([top, feet, side])  # and a leg of its own
    lit = np.ones(len(quads), bool)
    lit[-2] = False  # the feet, on the floor
    groups = face_groups(quads, lit)
    normal_z = np.cross(top[:, 1] - top[:, 0], top[:, 3] - top[:, 0])[:, 2]
    assert (groups[:len(top)][normal_z > 0] == "top").all() and (groups[:len(top)][normal_z < 0] == "underside").all()
    assert (groups[:len(top)][normal_z == 0] == "sides").all() and (normal_z == 0).sum() == 16  # its edges
    assert groups[-2] == "underside" and groups[-1] == "legs"


# --------------------------------------------------------------------------- the reports

def analysed():
    truth, halves, object_id = scene_arrays()
    mask = np.ones(object_id.shape, bool)
    names = ["Floor", "Wall"]
    kinds = {kind: {**wm.walk_numbers([wm.view_sums(truth * f, *halves, object_id, mask, 2)] * 2, names), "seconds": [1.0, 2.0]}
             for kind, f in (("eevee", 2.0), ("baked", 0.7), ("cycles", 1.0))}
    views = [{"location": [1, 1, 1.6], "target": [3, 3, 1], "lens": 18.0, "label": label, "surface_pixels": int(mask.sum())}
             for label in ("door", "window")]
    return {"interior": "test_room", "views": views, "kinds": kinds,
            "reference_error": wm.reference_error([wm.reference_sums(*halves, mask)] * 2), "reference_seconds": [60.0, 60.0],
            "solve": 12.5, "stats": {"patches": 1234, "patch_size": 0.25, "error": 4.9, "method": "two-way", "live_lamps": True,
                                     "solver_seconds": 10.0, "object_noise": {"Floor": 0.012, "Wall": 0.083}},
            "unlive_stats": None, "samples": [3, 4],
            "run": {"command": "python -m benchmarks.walkthrough", "seconds": 600.0, "loads": [2.0, 3.0], "reference_samples": 64,
                    "size": [240, 180], "eevee_samples": 16, "baked_samples": 16, "preview_samples": 64, "target": 5.0,
                    "sheet": "walkthrough_test_room.png"}}, (truth, halves, object_id, mask)


def test_the_pages_give_each_pictures_numbers():
    a, _ = analysed()
    page = report.interior_page(a)
    eevee = a["kinds"]["eevee"]["walk"]
    assert f"| {report.percent(eevee['error'])} | {report.percent(eevee['rms'])} | {eevee['brightness']:.2f} |" in page
    assert "2. window" in page and "walkthrough_test_room.json" in page and "(walkthrough_test_room.png)" in page
    assert "the solve took **12.5 s**" in page and "samples by view 3, 4" in page
    assert "the product's own (±) |" in page and "| 0.083 |" in page  # each object's own noise in the solve
    del a["stats"]["object_noise"]  # (a run from before it was measured)
    assert "the product's own" not in report.interior_page(a)
    summary = report.summary_page({"test_room": a})
    assert "[test_room](walkthrough_test_room.md)" in summary and f"{eevee['brightness']:.2f}" in summary


def test_the_contact_sheet_is_small(tmp_path):
    _, (truth, halves, object_id, mask) = analysed()
    m = {"refs": [{"first": halves[0], "second": halves[1]}] * 3,
         "images": {"eevee": [(truth * 2, 1.0)] * 3, "cycles": [(truth, 1.0)] * 3}}
    path = tmp_path / "sheet.png"
    report.contact_sheet(m, [mask] * 3, path)
    from PIL import Image

    with Image.open(path) as sheet:
        assert sheet.size == (4 * report.TILE[0], 14 + 3 * report.TILE[1])
    assert path.stat().st_size < 60_000


# --------------------------------------------------------------------------- the stored light, found (bpy)

@pytest.mark.parametrize("live", [False, True])
def test_the_baked_display_shows_the_result_materials_stored_light(live):
    import bpy

    from addon.blender_write import materials, results
    from benchmarks import interior_scene, walkthrough_displays as shown

    bpy.ops.wm.read_factory_settings(use_empty=True)
    source = interior_scene.principled("Paint", (0.8, 0.5, 0.2))
    made = [materials.textured_material(source, "Radiosity Light", "Radiosity Patches", live=live),
            results.result_material(live=live)]
    if live:  # (with lamps: the lamps' highlights drawn live, the terms as viewed)
        made.append(materials.textured_material(source, "Radiosity Light", "Radiosity Patches",
                                                materials.surface_terms(source), live=True, lamps=True))
        assert made[-1].get(materials.HIGHLIGHTS_PROPERTY)
    for material in made:
        copy = shown.baked_material(material)
        attributes = {n.attribute_name for n in copy.node_tree.nodes if n.bl_idname == "ShaderNodeAttribute"}
        assert materials.LAMPLESS_ATTRIBUTE not in attributes
        for curves in (n.mapping for n in copy.node_tree.nodes if n.bl_idname == "ShaderNodeRGBCurve"):
            assert all(np.ptp([p.location[1] for p in curves.curves[c].points]) == 0 for c in range(3))
        outputs = [n for n in copy.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
        assert len(outputs) == 1 and outputs[0].target == "ALL"
        emission = outputs[0].inputs["Surface"].links[0].from_node
        assert emission.bl_idname == "ShaderNodeEmission" and not emission.inputs["Strength"].is_linked
        mix = emission.inputs["Color"].links[0].from_node
        assert mix.bl_idname == "ShaderNodeMix"  # the colour the result's own Emission shader takes
        assert mix.inputs[7].links[0].from_node.attribute_name in ("Radiosity Patches", "Radiosity")
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_set_takes_name_value_and_its_run_keeps_pictures_of_its_own(capsys):
    """``--set NAME=VALUE`` (a panel setting of the product's solves): without a value one line; the
    kept pictures of such a run are not the default run's."""
    import argparse

    from benchmarks import walkthrough as wt

    with pytest.raises(SystemExit):
        wt.main(["--interior", "studio_flat", "--set", "detail"])
    assert "--set takes NAME=VALUE; got 'detail'" in capsys.readouterr().err
    run = argparse.Namespace(quick=False, seed=0, set=["detail=HIGH"])
    assert wt.image_tag(run) == "_detail-HIGH" and wt.image_tag(argparse.Namespace(quick=False, seed=0, set=[])) == ""
