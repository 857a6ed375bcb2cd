"""Reproducibility, runs to an error target, progress, cancel and time limits."""
import math
import time

import numpy as np
import pytest

from addon.core import predict, solve
from addon.core.estimate.plan import chunk_paths_for
from boxes import box_scene


@pytest.fixture(scope="module")
def scene():
    s, _, _ = box_scene([0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0], (1.0, 1.4, 0.8), n=3)
    return s


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_bitwise_reproducible_whatever_the_threads(scene, estimator, exit_point):
    runs = [solve(scene, estimator=estimator, paths=50_000, seed=7, threads=t, exit_point=exit_point) for t in (1, 2, 2)]
    for r in runs[1:]:
        assert np.array_equal(r.radiosity, runs[0].radiosity)
        assert r.rays == runs[0].rays
    other = solve(scene, estimator=estimator, paths=50_000, seed=8, threads=2, exit_point=exit_point)
    assert not np.array_equal(other.radiosity, runs[0].radiosity)


def test_predicted_stop_rule_runs_the_predicted_paths(scene):
    target = 1e-4
    p = predict(scene, "finite", target_mse=target)
    r = solve(scene, estimator="finite", target_mse=target, seed=1)
    assert r.paths == p.paths and r.stopped == "target"
    assert r.predicted_mse == pytest.approx(p.mse_per_path / p.paths)
    assert r.predicted_mse <= target


def test_given_paths_end_as_paths_even_with_a_target(scene):
    """With both paths= and target_mse= under the predicted rule, paths= is what runs."""
    r = solve(scene, estimator="finite", paths=3_000, target_mse=1.0, seed=1)
    assert r.paths == 3_000 and r.stopped == "paths"


def test_numpy_numbers_are_accepted(scene):
    r = solve(scene, estimator="biased_infinite", paths=np.int64(2_000), threshold=np.float32(1e-3), seed=np.int64(3))
    assert r.paths == 2_000
    p = predict(scene, "finite", target_mse=np.float32(1e-4))
    assert p.paths == predict(scene, "finite", target_mse=float(np.float32(1e-4))).paths
    with pytest.raises(ValueError, match="paths"):
        solve(scene, estimator="finite", paths=np.float64(10.0))
    with pytest.raises(ValueError, match="paths"):
        solve(scene, estimator="finite", paths=np.bool_(True))


def test_measured_stop_rule_stops_at_the_target(scene):
    target = 2e-4
    r = solve(scene, estimator="biased_infinite", target_mse=target, stop_rule="measured", seed=2)
    assert r.stopped == "target"
    assert r.measured_mse <= target
    assert r.chunks >= 8


def test_progress_reports_and_reaches_one(scene):
    seen = []
    solve(scene, estimator="finite", paths=100_000, seed=3, progress=lambda f, stats: seen.append((f, dict(stats))))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert seen[-1][1]["paths"] == 100_000
    assert all(k in seen[-1][1] for k in ("rays", "seconds", "rays_per_second", "measured_mse"))


@pytest.mark.parametrize("grey", [True, False])
def test_the_result_so_far_is_the_result_bit_for_bit(scene, grey):
    """stats["radiosity"]() after the last chunk is the returned B, bit for bit (made a channel at
    a time for the live view); in float32, the same rounded."""
    if grey:
        scene = scene.with_materials(np.repeat(scene.reflectivity.mean(axis=1, keepdims=True), 3, axis=1), scene.emission)
    last = {}
    r = solve(scene, estimator="finite", paths=20_000, seed=3, progress=lambda f, stats: last.update(stats))
    assert np.array_equal(last["radiosity"](), r.radiosity)
    assert np.array_equal(last["radiosity"](np.float32), r.radiosity.astype(np.float32))


def test_cancel_returns_complete_chunks(scene):
    calls = {"n": 0}

    def stop_after_two_progress_calls():
        return calls["n"] >= 2

    def count(fraction, stats):
        calls["n"] += 1

    r = solve(scene, estimator="finite", paths=5_000_000, seed=4, progress=count, should_stop=stop_after_two_progress_calls)
    assert r.stopped == "cancelled"
    assert 0 < r.paths < 5_000_000
    chunk = chunk_paths_for(predict(scene, "finite").expected_path_length, 5_000_000)
    assert r.chunks == 2 and r.paths == 2 * chunk
    assert np.isfinite(r.radiosity).all() and (r.radiosity >= 0).all()
    # What it returns is an estimate from whole chunks: the energy still balances path by path.
    assert sum(r.path_ends.values()) == r.paths


def test_time_limit(scene):
    start = time.perf_counter()
    r = solve(scene, estimator="finite", paths=50_000_000, seed=5, max_seconds=0.3)
    assert r.stopped == "time_limit"
    assert time.perf_counter() - start < 5.0
    assert r.paths < 50_000_000


def test_zero_reflectivity_traces_one_bounce(scene):
    black = scene.with_materials(np.zeros(scene.patch_count), scene.emission)
    r = solve(black, estimator="finite", paths=10_000, seed=6)
    assert r.rays == 10_000 and np.array_equal(r.radiosity, black.emission)
    p = predict(black, "finite", target_mse=1e-6)
    assert p.paths == 1 and p.mse_per_path == 0


@pytest.mark.parametrize("scale, offset", [(1e-4, 0.0), (1e4, 0.0), (1.0, 1e5)])
def test_scale_and_position_do_not_matter(scale, offset):
    """Ray offsets are relative to the scene and geometry is centred before float32: the
    same scene scaled or moved far away gives the same radiosity within the noise."""
    base, _, _ = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], (1.0, 1.4, 0.8), n=3)
    moved, _, _ = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], (1.0, 1.4, 0.8), n=3, offset=(offset,) * 3, scale=scale)
    a = solve(base, estimator="finite", paths=200_000, seed=9)
    b = solve(moved, estimator="finite", paths=200_000, seed=10)
    # Radiosity is power per area: scaling lengths by s scales B of the same emittance by 1.
    z = (a.reflected - b.reflected) / np.sqrt(a.reflected_variance + b.reflected_variance)
    assert np.abs(z[:, 0]).max() < 4.5
    assert b.path_ends["escaped"] == 0 and b.path_ends["blocked"] == 0


def test_batch_estimate_is_made_only_where_it_is_used(scene, monkeypatch):
    """The batch MSE costs passes over the patches: a run without progress under the predicted
    rule makes it once, for its result; with progress, once per chunk; and it is the
    area-weighted mean of the per-patch batch variances either way."""
    from addon.core.estimate.batches import Batches

    made = []
    real = Batches.measured_mse

    def counted(self):
        made.append(self.chunks)
        return real(self)

    monkeypatch.setattr(Batches, "measured_mse", counted)
    r = solve(scene, estimator="finite", paths=40_000, seed=2, threads=2)
    assert r.chunks >= 32 and made == [r.chunks]
    made.clear()
    calls = []
    p = solve(scene, estimator="finite", paths=40_000, seed=2, threads=2, progress=lambda f, s: calls.append(s["measured_mse"]))
    assert made == list(range(1, p.chunks + 1)) + [p.chunks]
    assert p.measured_mse == r.measured_mse == calls[-1]
    variance = p.reflected_variance.mean(axis=1)  # per patch, over channels
    expected = float((variance * scene.patch_area).sum() / scene.total_area)
    assert p.measured_mse == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
def test_measured_stop_rule_reads_the_estimate_once_a_group(scene, monkeypatch, estimator):
    """Under the measured rule the estimate is read after each task's chunks are all added:
    the run stops as soon as it meets the target there, on whole chunks."""
    from addon.core.estimate import plan
    from addon.core.estimate.batches import Batches

    made = []
    real = Batches.measured_mse
    monkeypatch.setattr(Batches, "measured_mse", lambda self: (made.append(self.chunks), real(self))[1])
    target = 3 * predict(scene, estimator, paths=200_000).predicted_mse
    r = solve(scene, estimator=estimator, target_mse=target, stop_rule="measured", seed=5, threads=1)
    assert r.stopped == "target" and r.measured_mse <= target
    # Read once at RESIZE_AFTER chunks (the later chunks' size), at MIN_MEASURED_CHUNKS and after,
    # once per task, then for the result.
    sized = [plan.RESIZE_AFTER] if r.method == "two_way" else []  # (the two-way iteration's chunks: Method.later_chunk)
    assert made[-2:] == [r.chunks, r.chunks] and made[:len(sized)] == sized and made[len(sized)] >= plan.MIN_MEASURED_CHUNKS
    assert all(b > a for a, b in zip(made[:-1], made[1:-1]))


def test_batch_estimate_of_a_colour_scene_is_the_mean_over_channels():
    R = [[0.3, 0.5, 0.7], [0.6, 0.2, 0.4], [0.7, 0.7, 0.1], [0.5, 0.5, 0.5], [0.4, 0.6, 0.2], [0.65, 0.3, 0.5]]
    E = [[0, 0, 0], [1.0, 0.5, 2.0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]]
    colour, _, _ = box_scene(R, E, (1.0, 1.4, 0.8), n=2)
    assert not colour.is_grey
    r = solve(colour, estimator="finite", paths=20_000, seed=4, threads=1)
    variance = r.reflected_variance.mean(axis=1)
    expected = float((variance * colour.patch_area).sum() / colour.total_area)
    assert r.measured_mse == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("block", [7, 1 << 16])
def test_measured_mse_is_the_area_weighted_mean_of_the_variance(scene, monkeypatch, block):
    """The batch estimate's MSE, summed a block of patches at a time, is the area- and
    channel-mean of each patch's batch-means variance of the mean (to rounding)."""
    from addon.core.estimate import batches

    monkeypatch.setattr(batches, "MSE_BLOCK", block)
    r = solve(scene, estimator="finite", paths=40_000, seed=5)
    weight = scene.patch_area / scene.patch_area.sum()
    expected = float((r.reflected_variance * weight[:, None]).sum() / 3)
    assert r.measured_mse == pytest.approx(expected, rel=1e-12)
