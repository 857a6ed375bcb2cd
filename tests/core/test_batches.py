"""The light arriving at each patch (H in B = E + rho H) and its measured variance, also on black
patches (rho = 0), where the reflected light's variance says nothing: what the textured output's
smooth light is filtered with (addon/core/estimate/batches.py ``irradiance_variance``)."""
import math

import numpy as np
import pytest

from addon.core import solve
from addon.core.estimate.reference import solve_radiosity_system
from boxes import CEILING, FLOOR, LEFT, box_scene

N = 6  # patches a side: 36 a face


def _black_floor_box(glow=1.0):
    """A closed box: black floor, a red wall (green and blue 0), grey walls, a glowing ceiling."""
    R = np.full((6, 3), 0.6)
    R[FLOOR] = 0.0
    R[LEFT] = (0.7, 0.0, 0.0)
    E = np.zeros((6, 3))
    E[CEILING] = glow
    return box_scene(R, E, n=N)


@pytest.mark.parametrize("method", ["walk", "two_way"])
def test_the_light_arriving_has_a_variance_from_the_same_batches(method):
    """Where rho > 0 the variance of H is the reflected light's over rho^2 (the same batches, in
    float32); where rho = 0 (the black floor, the red wall's green and blue), which the
    reflected light's variance cannot say, it is a finite, non-negative number too."""
    scene, F, face = _black_floor_box()
    result = solve(scene, estimator="finite", paths=20_000, seed=3, method=method, threads=1)
    assert result.irradiance_variance.shape == (scene.patch_count, 3)
    rho = scene.reflectivity
    lit = rho > 0
    np.testing.assert_allclose(result.irradiance_variance[lit], result.reflected_variance[lit] / rho[lit] ** 2,
                               rtol=1e-5)
    assert np.isfinite(result.irradiance_variance).all() and (result.irradiance_variance >= 0).all()
    assert (result.irradiance_variance[~lit] > 0).any()


def test_the_walks_light_on_black_patches_errs_by_its_measured_variance():
    """The paper's walks tally the light arriving at every hit, black patches too: there the
    errors against the exact H (F B, a direct linear solve) are the size the variance says. The
    mean of z^2 over the 36 floor patches is 1 within 3 standard errors (sqrt(2/36) for normal
    z, widened by the batch estimate's own spread, 2/(K-1) in relative variance for K chunks).
    (The two-way iteration gathers a black patch's direct light with a thousandth of the
    samples, a heavy-tailed estimate: the textured output does not lean on it, see
    tests/bpy_free/test_pipeline.py.)"""
    scene, F, face = _black_floor_box()
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    H_exact = F @ B
    result = solve(scene, estimator="finite", paths=60_000, seed=3, method="walk", threads=1)
    floor = face == FLOOR
    z2 = (result.irradiance[floor] - H_exact[floor]) ** 2 / result.irradiance_variance[floor]
    mean_z2 = float(z2.mean(axis=1).mean())  # (the grey floor's three channels are one sample)
    K = result.chunks
    band = 3 * np.sqrt(2 / floor.sum() + 2 / (K - 1))
    assert abs(mean_z2 - 1) < band, (mean_z2, band, K)


def test_the_variance_of_light_beyond_float32s_square_root_is_kept_whole():
    """Emission of 1e30: H^2 passes float32's largest (3.4e38), and the variance came out
    infinite (numpy's "overflow encountered in cast"), which the noise filter then smoothed
    with. It is the unit scene's times 1e60 (the paths do not depend on the scale), in float64
    there; float32 where it fits."""
    import warnings

    scene, _, _ = _black_floor_box()
    unit = solve(scene, estimator="finite", paths=20_000, seed=3, method="two_way", threads=1)
    bright_scene, _, _ = _black_floor_box(glow=1e30)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        bright = solve(bright_scene, estimator="finite", paths=20_000, seed=3, method="two_way", threads=1)
    assert unit.irradiance_variance.dtype == np.float32
    assert np.isfinite(bright.irradiance_variance).all()
    np.testing.assert_allclose(bright.irradiance_variance / 1e60, unit.irradiance_variance, rtol=1e-5,
                               atol=1e-6 * float(unit.irradiance_variance.max()))



def _tally(n, incident):
    from addon.core.estimate.tallies import ChunkTally
    zero = np.zeros(3)
    return ChunkTally(n, 0, incident, zero, zero, zero, zero, zero)


def test_chunks_of_two_sizes_are_estimated_as_later_chunk_expects():
    """A run whose later chunks are smaller (two_way_sizes.later_chunk) is read by the same batch
    estimate: each chunk's spread counts alike, so its expectation is
    (sum_k v_k - sum_k n_k v_k / N) / ((K - 1) N) for chunks of n_k paths and variance v_k per
    path (``two_way_sizes.later_estimate``, what later_chunk sizes them by). Synthetic tallies:
    Gaussian incident power of variance n_k v_k about its mean at every patch, RESIZE_AFTER
    chunks of 6,000 paths, the rest of 1,500 with the variance per path TWO_WAY_GROWTH makes of
    it; 400 replicas, their mean within 4 standard errors of it."""
    from addon.core.estimate import plan
    from addon.core.estimate.batches import Batches
    from addon.core.methods import two_way_sizes
    from addon.core.methods.tables import WalkTables

    scene, _, _ = _black_floor_box()
    tables = WalkTables(scene, "finite", 1e-3, "random")
    P, K, m, big, small = scene.patch_count, plan.MEASURED_STOP_CHUNKS, plan.RESIZE_AFTER, 6000, 1500
    grown = (1 + two_way_sizes.TWO_WAY_GROWTH * P / small) / (1 + two_way_sizes.TWO_WAY_GROWTH * P / big)
    spread = 1e-3 * np.sqrt(np.random.default_rng(0).uniform(0.5, 2.0, (3, P)))  # (a patch's noise a path)
    # the variance a path that chunks of one size measure: two one-path chunks +a and -a read sum W a^2
    unit = Batches(scene, tables)
    unit.add(_tally(1, spread))
    unit.add(_tally(1, -spread))
    variance = unit.measured_mse()
    mean = 1e-3 * np.ones((3, P))
    rng, readings = np.random.default_rng(7), []
    for _ in range(400):
        total = Batches(scene, tables)
        for k in range(K):
            n, v = (big, 1.0) if k < m else (small, grown)
            total.add(_tally(n, n * mean + np.sqrt(n * v) * spread * rng.standard_normal((3, P))))
        readings.append(total.measured_mse())
    readings = np.asarray(readings)
    expected = two_way_sizes.later_estimate(P, big, m, variance, small)
    assert grown > 1.5  # (the small chunks' variance a path well above the large ones')
    assert abs(readings.mean() - expected) <= 4 * readings.std(ddof=1) / np.sqrt(readings.size), (readings.mean(), expected)


def test_the_increments_of_chunks_of_three_sizes_give_each_chunks_variance_a_path():
    """What a run that sizes its chunks twice reads (``plan.chunk_variances``,
    ``plan.expected_increments``): synthetic tallies, Gaussian incident power of variance n_k v_k
    about its mean, two chunks of 6,000 paths, three of 3,000, seven of 1,500, each size its own
    variance a path; over 400 replicas the increments' means are ``expected_increments``' and the
    variances read from them the chunks' own, each within 4 standard errors; their mean over the
    paths is the batch estimate (to rounding), which ``later_estimate`` gives for two sizes."""
    from addon.core.estimate import plan
    from addon.core.estimate.batches import Batches
    from addon.core.methods import two_way_sizes
    from addon.core.methods.tables import WalkTables

    scene, _, _ = _black_floor_box()
    tables = WalkTables(scene, "finite", 1e-3, "random")
    P = scene.patch_count
    sizes = [6000] * 2 + [3000] * 3 + [1500] * 7
    per_path = {6000: 1.0, 3000: 1.3, 1500: 1.9}
    spread = 1e-3 * np.sqrt(np.random.default_rng(0).uniform(0.5, 2.0, (3, P)))
    unit = Batches(scene, tables)
    unit.add(_tally(1, spread))
    unit.add(_tally(1, -spread))
    v = unit.measured_mse()  # (the variance a path of a chunk of per_path 1)
    variances = [v * per_path[n] for n in sizes]
    mean = 1e-3 * np.ones((3, P))
    rng, increments, read, estimates = np.random.default_rng(3), [], [], []
    for _ in range(400):
        total = Batches(scene, tables, increments=True)
        for n in sizes:
            total.add(_tally(n, n * mean + np.sqrt(n * per_path[n]) * spread * rng.standard_normal((3, P))))
        increments.append(total.increments)
        read.append(plan.chunk_variances(sizes, total.increments))
        estimates.append(total.measured_mse())
        assert np.mean(total.increments) / total.paths == pytest.approx(total.measured_mse(), rel=1e-9)
    for got, want in ((np.asarray(increments), plan.expected_increments(sizes, variances)),
                      (np.asarray(read), np.asarray(variances))):
        error = got.std(axis=0, ddof=1) / np.sqrt(len(got))
        assert np.all(np.abs(got.mean(axis=0) - want) <= 4 * error), (got.mean(axis=0) / want)
    # the increments' expected mean over N is the batch estimate's expectation, as later_estimate has it
    N, vs = sum(sizes), np.asarray(variances)
    batch = (vs.sum() - (np.asarray(sizes) * vs).sum() / N) / ((len(sizes) - 1) * N)
    assert np.mean(plan.expected_increments(sizes, variances)) / N == pytest.approx(batch, rel=1e-12)
    assert np.mean(estimates) == pytest.approx(batch, rel=4 * np.std(estimates) / np.sqrt(len(estimates)) / batch)
    two = [6000] * 2 + [1500] * 10
    grown = (1 + two_way_sizes.TWO_WAY_GROWTH * P / 1500) / (1 + two_way_sizes.TWO_WAY_GROWTH * P / 6000)
    assert np.mean(plan.expected_increments(two, [v] * 2 + [v * grown] * 10)) / sum(two) == pytest.approx(
        two_way_sizes.later_estimate(P, 6000, 2, v, 1500), rel=1e-12)


def test_the_expected_bound_is_the_stop_rules_bound_on_chunks_as_expected():
    """``plan.expected_bound`` of increments all read is ``Batches.mse_upper_bound`` of them; with
    none read and no noise (terms inf) the mean of ``expected_increments`` plus z standard errors of
    their spread; a noisier reading (fewer terms) bounds higher."""
    from addon.core.estimate import plan
    from addon.core.estimate.batches import Batches
    from addon.core.methods.tables import WalkTables

    scene, _, _ = _black_floor_box()
    tables = WalkTables(scene, "finite", 1e-3, "random")
    rng = np.random.default_rng(5)
    sizes = [4000] * 2 + [2000] * 10
    total = Batches(scene, tables, increments=True)
    for n in sizes:
        total.add(_tally(n, n * 1e-3 + np.sqrt(n) * 1e-3 * rng.standard_normal((3, scene.patch_count))))
    variances = [1.0] * len(sizes)
    assert plan.expected_bound(sizes, variances, total.increments, 100.0) == pytest.approx(
        total.mse_upper_bound(plan.MEASURED_STOP_Z), rel=1e-12)
    variances = [1.0] * 2 + [1.5] * 10
    inc = plan.expected_increments(sizes, variances)
    bare = plan.expected_bound(sizes, variances, [], math.inf)
    assert bare == pytest.approx((inc.mean() + plan.MEASURED_STOP_Z * inc.std(ddof=1) / math.sqrt(inc.size)) / sum(sizes), rel=1e-12)
    assert plan.expected_bound(sizes, variances, [], 50.0) > bare
