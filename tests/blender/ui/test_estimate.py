"""The estimate before a run: rays where the run ends, and near-white rooms (a finite time and a
warning, or a refusal naming the bounces)."""

import math

import bpy
import pytest

from addon.ui import estimate
from addon.bpy_free import pipeline
from addon.blender_read.selection import read_selection
from addon.blender_write import solve_job

from ..conftest import box_arrays, build_test_scene, make_object, principled


@pytest.mark.parametrize("patch_size, error", [(0.05, 5.0), (0.1, 2.0)])
def test_the_estimate_rays_are_within_2x_of_the_runs(blender, patch_size, error):
    """Default settings (Automatic: the two-way iteration here, stopping on its measured error):
    the estimate's rays are within 2x of what the run traces (it planned the two-way iteration
    from the walk's formula and a calibration solve's rays a path: 2.1-2.7x over here)."""
    build_test_scene()
    s = blender.scene.radiosity
    s.patch_size, s.target_error, s.threads, s.seed = patch_size, error, 2, 0
    value = estimate.compute(blender)
    objects, _ = read_selection(blender)
    out = pipeline.run_solve(objects, s.solve_settings())
    assert value["method"] == out.result.method == "two_way" and out.result.stopped == "target"
    assert 0.5 <= value["rays"] / out.result.rays <= 2.0, (value["rays"], out.result.rays)
    assert 0.5 <= value["paths"] / out.result.paths <= 2.0
    assert math.isfinite(value["seconds"]) and value["seconds"] > 0 and value["measured"]


def near_white_room(base):
    """A closed 1 m room of base colour ``base`` whose ceiling emits, selected."""
    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    room = make_object("Room", room_v, room_f, [principled("White", (base,) * 3),
                                                principled("Emitter", (base,) * 3, (1, 1, 1), 4.0)], [0, 1, 0, 0, 0, 0])
    room.select_set(True)


def test_a_near_white_room_is_refused_before_a_run_naming_the_bounces(blender):
    """Base colour 0.9999999 passes the colour checks (below 1) but makes paths of eight million
    bounces (in float32): the estimate says so and the solve refuses it in one line, changing nothing (with
    a time limit here, so that a solve that runs fails this test in seconds, not hours)."""
    near_white_room(0.9999999)
    s = blender.scene.radiosity
    s.threads, s.time_limit = 2, 5.0
    value = estimate.compute(blender)
    assert "bounces about 8,388,608 times" in value.get("error", ""), value  # (1 / (1 - R) in float32)
    before = set(bpy.data.objects.keys())
    finished = solve_job.run(bpy.context)
    assert finished.status == "CANCELLED"
    assert "refused above 1,000,000 bounces" in finished.error and "\n" not in finished.error
    assert set(bpy.data.objects.keys()) == before


def test_a_nearly_white_room_below_the_limit_is_warned_with_a_finite_time(blender):
    """Base colour 0.99999 (100,000 bounces a path): the estimate predicts a finite time, past a
    minute, and the warning says the bounces drive it and where the limit is."""
    near_white_room(0.99999)
    blender.scene.radiosity.threads = 2
    value = estimate.compute(blender)
    assert "error" not in value, value
    assert math.isfinite(value["seconds"]) and value["seconds"] > pipeline.SLOW_SECONDS
    assert value["bounces"] == pytest.approx(1e5, rel=0.01)
    assert f"bounces about {value['bounces']:,.0f} times" in value["warning"] and "refused" in value["warning"]
    assert value["pilot_seconds"] < 10


def test_the_estimate_is_within_2x_of_the_runs_real_time_its_colours_included(blender):
    """The test room with its emitting panel, a point lamp and an area lamp, 2 cm patches, the
    default settings (the textured output: the smooth light with every lamp's and emitter's direct
    light at the corners): the estimate's time is within 2x of the run's real time (meshing, solve
    and colours), and the run says that time (SolveOutput.seconds). (Before, the estimate left
    the colours out.)"""
    import time

    build_test_scene()
    for name, kind, location, energy in (("Bulb", "POINT", (0.7, 0.3, 0.6), 30.0), ("Panel", "AREA", (0.3, 0.7, 0.9), 40.0)):
        lamp = bpy.data.objects.new(name, bpy.data.lights.new(name, kind))
        lamp.data.energy, lamp.location = energy, location
        bpy.context.scene.collection.objects.link(lamp)
    s = blender.scene.radiosity
    s.patch_size, s.threads, s.seed = 0.02, 2, 0
    value = estimate.compute(blender)
    objects, _ = read_selection(blender)
    started = time.perf_counter()
    out = pipeline.run_solve(objects, s.solve_settings())
    wall = time.perf_counter() - started
    assert 0.5 <= value["seconds"] / wall <= 2.0, (value["seconds"], wall, value["display_seconds"], out.result.seconds)
    assert 0 < wall - out.seconds < 0.05
