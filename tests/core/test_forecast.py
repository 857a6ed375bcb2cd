"""The time prediction: a path's bounces, the refusal of near-white closed scenes, the pilot's
forecast of where a run stops, and the prediction a run updates from its measured error."""
import math

import numpy as np
import pytest

from addon.core import predict, relative_rms_to_mse, solve
from addon.core import forecast as fc
from addon.core.scene.diagnostics import MAX_BOUNCES, check_bounces, expected_bounces
from addon.core.methods import TwoWay
from addon.core.settings import Settings
from addon.core.solver import chosen_method
from addon.core.methods.automatic import MEASURED_MARGIN
from addon.core.estimate import plan
from addon.core.estimate.plan import MIN_MEASURED_CHUNKS

from boxes import box_scene, open_box_with_card

# a closed box of coloured walls, a ceiling that emits (the Cornell box's colours, grey)
WALLS = [0.7, 0.7, 0.6, 0.25, 0.7, 0.7]
CEILING_LIGHT = [0, 1, 0, 0, 0, 0]


def test_bounces_of_a_closed_box_are_the_walks_and_light_leaving_an_open_scene_shortens_them():
    """In a closed box of one reflectivity every ray meets a front face: a bounce goes on with
    probability R exactly, 1 / (1 - R) bounces; from an open box, light escapes, and paths are
    shorter than the paper's 1 / (1 - R_ave)."""
    for R in (0.5, 0.999, 0.9999999):
        scene, _, _ = box_scene([R] * 6, CEILING_LIGHT, n=3)
        assert expected_bounces(scene) == pytest.approx(1 / (1 - R), rel=1e-6)
    scene = open_box_with_card(0.9999)
    assert 1 < expected_bounces(scene) < 20  # (the paper's formula: 10,000)


def test_a_near_white_closed_room_is_refused_with_its_bounces_not_run_for_ever():
    """Base colour 0.9999999 in a closed emitting room: ten million bounces a path. The solve
    refuses it in one message naming the bounces and the limit, before any path (on a time
    limit here, so that a solve that runs instead fails this test in seconds)."""
    scene, _, _ = box_scene([0.9999999] * 6, CEILING_LIGHT, n=2)
    target = relative_rms_to_mse(predict(scene), 0.05)
    for method in ("auto", "walk", "two_way"):
        with pytest.raises(ValueError, match=r"bounces about 10,000,000 times.*refused above 1,000,000 bounces"):
            solve(scene, target_mse=target, stop_rule="measured", method=method, max_seconds=5.0)
    # below the limit, the bounces are the estimate's (an open scene of the same colour runs)
    assert check_bounces(box_scene([0.99999] * 6, CEILING_LIGHT, n=2)[0], "finite", 1e-3) == pytest.approx(1e5, rel=1e-4)
    assert check_bounces(open_box_with_card(0.9999999), "finite", 1e-3) < MAX_BOUNCES


def test_a_near_white_forecast_is_a_finite_time_for_the_runs_least_paths():
    """Below the limit (10,000 bounces a path) the pilot finishes little: the forecast is still
    a finite time, for at least the chunks the measured stop rule needs."""
    scene, _, _ = box_scene([0.9999] * 6, CEILING_LIGHT, n=2)
    target = relative_rms_to_mse(predict(scene), 0.05)
    f = fc.forecast(scene, Settings.for_mse(scene, target, method="walk", threads=2, stop_rule="measured"),
                    bounces=check_bounces(scene, "finite", 1e-3))
    assert math.isfinite(f.seconds) and f.seconds > 0 and math.isfinite(f.rays) and f.rays >= f.paths * 1000
    assert f.pilot_seconds < 2 * fc.PILOT_SECONDS


@pytest.mark.parametrize("relative_rms", [0.05, 0.02])
def test_the_forecast_paths_are_within_2x_of_where_the_run_stops(relative_rms):
    """The pilot's variance per path (batch means of a few of the run's chunks) and the run's
    chunk plan give the paths the run's measured stop rule ends at: within 2x of a real run's
    (Automatic, the two-way iteration here; fixed seeds), and its rays alike. (The paper's
    formula, a quarter of which the estimate planned, is 2-5x off for the two-way iteration.)"""
    scene, _, _ = box_scene(WALLS, CEILING_LIGHT, n=6)
    target = relative_rms_to_mse(predict(scene), relative_rms)
    method = choose_method(scene, target_mse=target)
    assert method == "two_way"
    f = fc.forecast(scene, Settings.for_mse(scene, target, method=method, threads=2, seed=1, stop_rule="measured"))
    r = solve(scene, target_mse=target, method=method, stop_rule="measured", threads=2, seed=0)
    assert r.stopped == "target"
    assert 0.5 <= f.paths / r.paths <= 2.0, (f.paths, r.paths)
    assert 0.5 <= f.rays / r.rays <= 2.0, (f.rays, r.rays)
    assert f.measured and 0.5 <= f.chunks / r.chunks <= 2.0, (f.chunks, r.chunks)
    # (the run's first chunks of the plan's size, then those its first sized, then those it sized again:
    # chunks.RESIZE_AFTER, RESIZE_AGAIN_FROM)
    sizes = r.chunk_sizes
    assert len(sizes) == r.chunks and sum(sizes) == r.paths and set(sizes[:plan.RESIZE_AFTER]) == {f.chunk}
    assert len(set(sizes[plan.RESIZE_AFTER:plan.RESIZE_AGAIN_FROM])) == 1 and len(set(sizes[plan.RESIZE_AGAIN_FROM:])) <= 1


def test_a_run_predicts_its_end_from_its_measured_error_as_it_goes():
    """From its second chunk on, a run stopping on its measured error says the paths it is
    expected to end at (whole chunks, at least MIN_MEASURED_CHUNKS) and the seconds left; the
    fraction done is the share of them. The first finite prediction is within 2x of the end."""
    scene, _, _ = box_scene(WALLS, CEILING_LIGHT, n=6)
    target = relative_rms_to_mse(predict(scene), 0.01)
    seen = []
    r = solve(scene, target_mse=target, method="walk", stop_rule="measured", threads=2, seed=2,
              progress=lambda fraction, stats: seen.append((fraction, dict(stats))))
    assert r.stopped == "target" and r.chunks > MIN_MEASURED_CHUNKS  # (the error, not the least chunks, ends it)
    chunk = r.paths // r.chunks
    assert math.isnan(seen[0][1]["expected_paths"]) and math.isnan(seen[0][1]["seconds_left"])
    known = [(fraction, s) for fraction, s in seen if s["expected_paths"] == s["expected_paths"]]
    assert len(known) == len(seen) - 1
    first = known[0][1]["expected_paths"]
    assert 0.5 <= first / r.paths <= 2.0, (first, r.paths)
    for fraction, s in known:
        assert s["expected_paths"] % chunk == 0 and s["expected_paths"] >= MIN_MEASURED_CHUNKS * chunk
        assert fraction == pytest.approx(min(1.0, s["paths"] / s["expected_paths"]))
        assert s["seconds_left"] >= 0 and math.isfinite(s["seconds_left"])
    assert known[-1][1]["expected_paths"] == r.paths and known[-1][1]["seconds_left"] == 0


def test_a_walk_pilot_keeps_its_variance_per_path_and_the_two_way_scales_it_with_its_chunks():
    """A walk's paths are independent: the pilot's variance per path is the run's at any chunk
    size. The two-way iteration's falls as chunks grow, as v_inf (1 + G P / n)."""
    assert TwoWay().variance_scale(1000, 4000, 4000) == 1.0
    assert TwoWay().variance_scale(1000, 4000, 16000) == pytest.approx((1 + 12 / 16) / (1 + 12 / 4))
    assert fc.pilot_size(1000, 5.0, budget=1 << 20) == (1000, fc.PILOT_CHUNKS)
    chunk, chunks = fc.pilot_size(10**6, 5.0, budget=1 << 20)
    assert chunks == 2 and chunk * chunks * 5.0 <= 1 << 20
    assert np.isfinite(fc.raw_rate(box_scene(WALLS, CEILING_LIGHT, n=2)[0]))


# ---------------------------------------------------------------------------------------------
# Automatic with per-source results: measured
# ---------------------------------------------------------------------------------------------

def _lamp_box(lamps):
    """A closed colour box of 8 x 8 patches a face (where Automatic runs the two-way iteration
    at 400,000 paths) lit by ``lamps`` point lamps under its ceiling, each its own group."""
    from boxes import box_rectangles, rectangles_to_mesh

    from addon.core import PatchScene
    from addon.core.lights.lights import PointLight

    colours = np.array([(0.7, 0.7, 0.7), (0.5, 0.5, 0.5), (0.8, 0.3, 0.2), (0.2, 0.7, 0.3), (0.6, 0.6, 0.6), (0.4, 0.4, 0.8)])
    origin, u, v, face = box_rectangles((1, 1, 1), n=8)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    side = int(np.ceil(np.sqrt(lamps)))
    spots = [(x, y) for x in np.linspace(0.2, 0.8, side) for y in np.linspace(0.2, 0.8, side)][:lamps]
    lights = [PointLight(np.array([x, y, 0.85]), np.full(3, 1.0 / lamps), name=f"lamp {k}") for k, (x, y) in enumerate(spots)]
    return PatchScene(V, T, TP, colours[face], np.zeros((len(face), 3)), lights)


def choose_method(scene, target_mse=None, **fields):
    """The method Automatic runs for a solve of these settings (the solver's choice, pilots and all)."""
    settings = Settings(method="auto", **fields)
    return chosen_method(scene, settings if target_mse is None else Settings.for_mse(scene, target_mse, settings))


def _fake_forecast(costs, calls):
    """A forecast that records its settings (and budget) and returns, per method, (variance per
    path, seconds per path) from ``costs`` (None: its pilot measured nothing)."""
    def forecast(scene, settings, budget=fc.PILOT_RAYS, **_):
        kw = {f: getattr(settings, f) for f in settings.__dataclass_fields__}
        kw["budget"] = budget
        calls.append(kw)
        cost = costs[kw["method"]]
        return fc.Forecast(paths=1e5, rays=1e6, seconds=1.0, chunk=1000, chunks=100.0,
                           variance_per_path=math.nan if cost is None else cost[0], rays_per_path=10.0,
                           seconds_per_path=1e-5 if cost is None else cost[1], setup_seconds=0.0, pilot_chunk=1000,
                           pilot_chunks=0 if cost is None else 4, pilot_seconds=1.0, measured=cost is not None)
    return forecast


def test_automatic_with_per_source_results_runs_what_the_pilots_measure_cheaper(monkeypatch):
    """Per-source results cost the two-way iteration a share of every group on every ray and
    the walk hardly anything: where Automatic's rule picks the two-way iteration, a per-source
    solve compares the two by pilots with per-source results (time per path x variance per path),
    and runs the cheaper; without per-source results nothing is measured, as before."""
    from addon.core import source_groups

    scene = _lamp_box(4)
    groups = source_groups(scene)
    calls = []
    # the two-way iteration: a quarter of the variance, twice the time a path: it stays
    monkeypatch.setattr(fc, "forecast", _fake_forecast({"two_way": (1.0, 2e-5), "walk": (4.0, 1e-5)}, calls))
    assert choose_method(scene, paths=400_000) == "two_way" and calls == []
    assert choose_method(scene, paths=400_000, per_source=True, groups=groups, threads=2, seed=3) == "two_way"
    assert [c["method"] for c in calls] == ["two_way", "walk"]
    assert all(c["per_source"] and c["groups"] is groups and c["seed"] == 3 for c in calls)
    assert calls[0]["direct_light"] == "gathered" and calls[1]["direct_light"] == "shot"
    # with many groups its time a path grows past the walk's at the same error: the walk runs
    monkeypatch.setattr(fc, "forecast", _fake_forecast({"two_way": (1.0, 8e-5), "walk": (4.0, 1e-5)}, calls))
    assert choose_method(scene, paths=400_000, per_source=True, groups=groups) == "walk"
    # ... but not where the two are within the pilots' noise (the margin): the rule's choice stays
    monkeypatch.setattr(fc, "forecast", _fake_forecast({"two_way": (1.0, 5e-5), "walk": (4.0, 1e-5)}, calls))
    assert 5e-5 / 4e-5 < MEASURED_MARGIN
    assert choose_method(scene, paths=400_000, per_source=True, groups=groups) == "two_way"
    # a pilot that measures nothing even on an eighth of the budget is the dearer
    calls.clear()
    monkeypatch.setattr(fc, "forecast", _fake_forecast({"two_way": None, "walk": (4.0, 1e-5)}, calls))
    assert choose_method(scene, paths=400_000, per_source=True, groups=groups) == "walk"
    assert [c["budget"] for c in calls] == [fc.PILOT_RAYS, fc.PILOT_RAYS // 8, fc.PILOT_RAYS]
    # under a short time limit the pilots would take it: the rule's choice, nothing measured
    calls.clear()
    assert choose_method(scene, paths=400_000, per_source=True, groups=groups, max_seconds=30.0) == "two_way"
    assert calls == []
    # one group is the total: nothing to measure
    calls.clear()
    one = _lamp_box(1)
    assert choose_method(one, paths=400_000, per_source=True, groups=source_groups(one)) == "two_way" and calls == []
    # a scene where the rule picks the walk measures nothing
    assert choose_method(scene, paths=2_000, per_source=True, groups=groups) == "walk" and calls == []


def test_a_per_source_automatic_solve_runs_the_method_its_real_pilots_found_cheaper(monkeypatch):
    """The same with real pilots, in a box of 64 lamps: the solve runs the walk where its
    measured cost at the same error is below the two-way iteration's by the margin, else the
    two-way iteration (whichever it is on this machine), with per-source results."""
    scene = _lamp_box(64)
    seen = []
    real = fc.forecast

    def spy(scene, settings, **kw):
        seen.append((settings.method, settings.per_source, real(scene, settings, **kw)))
        return seen[-1][2]

    monkeypatch.setattr(fc, "forecast", spy)
    r = solve(scene, paths=400_000, method="auto", per_source=True, threads=2, seed=1)
    last = {method: f for method, _, f in seen}
    assert set(last) == {"two_way", "walk"} and all(per_source for _, per_source, _ in seen)
    cost = {m: fc.cost_at_same_error(f) for m, f in last.items()}
    assert r.method == ("walk" if cost["two_way"] > MEASURED_MARGIN * cost["walk"] else "two_way"), cost
    assert r.per_source.count == 64
