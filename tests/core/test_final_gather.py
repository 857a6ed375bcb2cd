"""The final gather of the display (addon/core/display/final_gather.py): each patch's bounced light
taken again along cosine rays from the solved light, against exact form factors (a closed box of
4 x 4 rectangles a face) and the discrete radiosity system solved directly; combined with the
solve's estimate by their variances, each source group's parts along the same rays."""
import numpy as np
import pytest
from boxes import CEILING, box_scene

from addon.core import Settings, solve
from addon.core.display import final_gather
from addon.core.estimate.grouping import source_groups
from addon.core.estimate.reference import solve_radiosity_system
from addon.core.scene.threads import local_threads


@pytest.fixture(scope="module")
def box():
    """A closed 1 x 1 x 1 box of 4 x 4 patches a face, R 0.6, one ceiling patch glowing."""
    scene, F, face = box_scene([0.6] * 6, [0.0, 1.0, 0.0, 0.0, 0.0, 0.0], n=4)
    emission = np.zeros(scene.patch_count)
    emission[np.flatnonzero(face == CEILING)[5]] = 10.0
    return scene.with_materials(scene.reflectivity, emission), F, face


def _t_bound(count, dof, once_in=1000):
    """|z| beyond which one of ``count`` t-distributed values (``dof`` degrees of freedom) lies once in
    ``once_in`` draws (a normal bound for many degrees of freedom), by simulation."""
    rng = np.random.default_rng(0)
    largest = np.abs(rng.standard_t(dof, size=(4000, count))).max(axis=1)
    return float(np.quantile(largest, 1 - 1 / once_in)) if once_in < 4000 else float(largest.max())


def test_the_gather_estimates_the_form_factors_times_the_values_within_its_own_variance(box):
    """Values varying from patch to patch (a ramp and a spike): each patch's gathered mean against F @ values,
    the z-scores by the gather's own variance: none beyond a t bound, their mean square not above 1 by
    more than four standard errors of a chi-square's."""
    scene, F, _ = box
    P = scene.patch_count
    rng = np.random.default_rng(3)
    values = np.stack([np.linspace(0.1, 1.0, P), rng.random(P), np.where(np.arange(P) % 7 == 0, 5.0, 0.2)], axis=1)
    mean, variance, parts = final_gather.gather(scene, values, rays=256, seed=11)
    assert parts is None
    exact = F @ values
    z = (mean - exact) / np.sqrt(variance)
    assert np.abs(z).max() < _t_bound(z.size, 255, 4000), np.abs(z).max()
    dof = z.size
    # (the rays are stratified, so their sample variance over n is an upper estimate: it does not understate the error)
    assert np.mean(z * z) < 1.0 + 4 * np.sqrt(2.0 / dof)


def test_the_same_bits_on_one_thread_and_two(box):
    scene, _, _ = box
    values = np.random.default_rng(1).random((scene.patch_count, 3))
    with local_threads(1):
        one = final_gather.gather(scene, values, rays=32, seed=5)
    with local_threads(2):
        two = final_gather.gather(scene, values, rays=32, seed=5)
    assert all(np.array_equal(a, b) for a, b in zip(one[:2], two[:2]))


def test_a_solve_gathered_again_is_the_discrete_solution_within_its_variance_and_its_parts_add_up(box):
    """A per-source two-way solve of the box (the glowing patch one group): the gathered result's
    light against the direct solve of B = E + R F B, z-scores by the solve's own variance (the
    combination is no further from the truth than the solve's errors allow: the gather carries
    them averaged); the group's parts add up to the whole's; the variance given the filter is at
    most the solve's."""
    scene, F, _ = box
    groups = source_groups(scene)
    settings = Settings(method="two_way", exit_point="random", paths=60_000, per_source=True, groups=groups,
                        direct_apart=True, seed=2, threads=1, chunk_paths=5_000)
    result = solve(scene, settings)
    assert result.direct_irradiance is not None
    out = final_gather.gathered(scene, result, rays=128, seed=3)
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    H = F @ B
    z = (out.irradiance - H) / np.sqrt(result.irradiance_variance)
    assert np.abs(z).max() < _t_bound(z.size, 11, 1000), np.abs(z).max()
    np.testing.assert_allclose(out.per_source.irradiance.sum(axis=0), out.irradiance, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(out.radiosity, scene.emission[:, None] + scene.reflectivity[:, None] * out.irradiance
                               if scene.reflectivity.ndim == 1 else scene.emission + scene.reflectivity * out.irradiance,
                               rtol=1e-9)
    # the combined variance is at most either's
    assert (out.irradiance_variance <= result.irradiance_variance * (1 + 1e-6) + 1e-30).all()


def test_the_solves_weight_follows_the_variances_one_for_the_three_channels():
    """v_g / (v_s + v_g) of the channels' sums (a patch keeps its colour); 0 where the solve measured
    none, a half where neither varies, 1 on hidden patches."""
    v_s = np.array([[1.0, 0.5, 0.5], [0.0, 0.0, 0.0], [np.nan, np.nan, np.nan]])
    v_g = np.array([[3.0, 2.0, 1.0], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    np.testing.assert_allclose(final_gather._solve_weight(v_s, v_g), [[0.75], [0.5], [0.0]])
    np.testing.assert_allclose(final_gather._solve_weight(v_s, v_g, hidden=np.array([True, False, False])), [[1.0], [0.5], [0.0]])


def test_a_result_without_its_direct_light_apart_or_too_large_is_shown_as_solved(box, monkeypatch):
    """The paper's walk keeps no direct light apart: nothing to gather; nor past MOST_PATCHES."""
    scene, _, _ = box
    walk = solve(scene, Settings(method="walk", paths=2_000, seed=1, threads=1))
    assert walk.direct_irradiance is None and final_gather.gathered(scene, walk) is walk
    two_way = solve(scene, Settings(method="two_way", paths=4_000, direct_apart=True, seed=1, threads=1, chunk_paths=1_000))
    assert two_way.direct_irradiance is not None and final_gather.gathered(scene, two_way) is not two_way
    monkeypatch.setattr(final_gather, "MOST_PATCHES", scene.patch_count - 1)
    assert final_gather.gathered(scene, two_way) is two_way
