"""sampling="stratified" (beyond the paper): sources allotted in proportion to power and a
randomly shifted Halton set for the first ray. Same expectation, less noise."""
import numpy as np
import pytest

from addon.core import solve
from addon.core.estimate.reference import area_weighted_mse, solve_radiosity_system
from addon.core.lights.sampling import SourceTable, source_weights
from boxes import box_scene


@pytest.fixture(scope="module")
def box():
    scene, F, _ = box_scene([0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0], (1.0, 1.4, 0.8), n=4)
    return scene, solve_radiosity_system(F, scene.reflectivity, scene.emission)


def test_allotment_is_floor_or_ceil_of_the_expected_count():
    rng = np.random.default_rng(0)
    area = rng.uniform(0.1, 2, 50)
    emission = rng.uniform(0, 1, (50, 3))
    table = SourceTable(source_weights(area, emission))
    for count in (7, 1000, 65536):
        patch, u = table.stratified(count, rng)
        counts = np.bincount(patch, minlength=50)[table.ids]
        expected = count * table.probability
        assert (counts >= np.floor(expected) - 1e-9).all() and (counts <= np.ceil(expected) + 1e-9).all()
        assert u.shape == (4, count) and u.min() >= 0 and u.max() < 1


def test_a_shift_just_below_one_stays_inside_the_table():
    """(count - 1 + r) / count rounds to 1.0 for r within ~count 2^-53 of 1: the last path
    still gets the last source."""

    class AlmostOne:
        def random(self, size=None):
            return np.nextafter(1.0, 0.0) if size is None else np.full(size, 0.5)

    table = SourceTable(source_weights(np.ones(3), np.ones((3, 3))))
    patch, u = table.stratified(3, AlmostOne())  # an IndexError before the clamp
    assert patch[-1] == 2 and ((patch >= 0) & (patch < 3)).all()


def test_sample_draws_the_law_of_independent_choices():
    """SourceTable.sample (multinomial counts with few sources, per-path choices otherwise)
    gives each source its share: a chi-square test of the counts against count p_i."""
    rng = np.random.default_rng(2)
    area = rng.uniform(0.1, 2, 40)
    emission = np.zeros((40, 3))
    emission[::3] = rng.uniform(0.1, 1, (14, 3))
    table = SourceTable(source_weights(area, emission))
    for count in (20, 100_000):  # per-path choices, then multinomial counts
        total = np.zeros(table.ids.size)
        rounds = 200_000 // count
        for _ in range(rounds):
            patch = table.sample(count, rng)
            assert patch.size == count
            if count >= 100_000:
                assert (np.diff(patch) >= 0).all()  # multinomial counts come grouped by source
            total += np.bincount(patch, minlength=40)[table.ids]
        expected = rounds * count * table.probability
        chi2 = ((total - expected) ** 2 / expected).sum()
        dof = table.ids.size - 1
        assert chi2 < dof + 5 * np.sqrt(2 * dof), chi2


def test_first_ray_uniforms_are_uniform():
    """Each path's four numbers are uniform (random shift modulo 1): their means over many
    chunks are 1/2 within the standard error of a uniform."""
    table = SourceTable(source_weights(np.ones(3), np.ones((3, 3))))
    rng = np.random.default_rng(1)
    first_path = np.array([table.stratified(10, rng)[1][:, 0] for _ in range(20_000)])
    assert np.abs(first_path.mean(axis=0) - 0.5).max() < 5 * np.sqrt(1 / 12 / 20_000)


@pytest.mark.parametrize("estimator, kw", [("finite", {}), ("biased_infinite", {"threshold": 1e-9})])
def test_stratified_is_unbiased(box, estimator, kw):
    scene, B = box
    r = solve(scene, estimator=estimator, paths=400_000, seed=3, sampling="stratified", **kw)
    assert r.chunks >= 32 and r.sampling == "stratified"
    z = (r.reflected[:, 0] - (B[:, 0] - scene.emission[:, 0])) / np.sqrt(r.reflected_variance[:, 0])
    # 96 patches, variances from >= 32 batches (t, >= 31 d.o.f.): P(max |t| > 5) < 3e-3
    assert np.abs(z).max() < 5.0, np.abs(z).max()


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
def test_stratified_hit_exit_agrees_with_independent_sampling(box, estimator):
    """exit_point="hit" (particle tracing) estimates the continuous solution, not the discrete
    one: stratified and independent runs must agree with each other, patch by patch, within
    their batch variances (t with >= 31 d.o.f. each; 96 patches: P(max |z| > 5) < 3e-3)."""
    scene, _ = box
    runs = [
        solve(scene, estimator=estimator, paths=300_000, seed=5, sampling=sampling, exit_point="hit", threshold=1e-9)
        for sampling in ("independent", "stratified")
    ]
    assert all(r.chunks >= 32 for r in runs)
    difference = runs[0].reflected[:, 0] - runs[1].reflected[:, 0]
    z = difference / np.sqrt(runs[0].reflected_variance[:, 0] + runs[1].reflected_variance[:, 0])
    assert np.abs(z).max() < 5.0, np.abs(z).max()


def test_stratified_lowers_the_error(box):
    scene, B = box
    mse = {}
    for sampling in ("independent", "stratified"):
        mse[sampling] = np.array(
            [area_weighted_mse(solve(scene, estimator="finite", paths=50_000, seed=s, sampling=sampling).radiosity, B, scene.patch_area) for s in range(10)]
        )
    gap = mse["independent"].mean() - mse["stratified"].mean()
    se = np.sqrt(mse["independent"].var(ddof=1) / 10 + mse["stratified"].var(ddof=1) / 10)
    assert gap > 3 * se, (mse["independent"].mean(), mse["stratified"].mean(), se)


def test_stratified_is_reproducible_across_threads(box):
    scene, _ = box
    a = solve(scene, estimator="biased_infinite", paths=30_000, seed=4, threads=1, sampling="stratified")
    b = solve(scene, estimator="biased_infinite", paths=30_000, seed=4, threads=2, sampling="stratified")
    assert np.array_equal(a.radiosity, b.radiosity)
    with pytest.raises(ValueError, match="sampling"):
        solve(scene, estimator="finite", paths=10, sampling="sobol")
