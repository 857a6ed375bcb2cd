"""Stochastic Jacobi iteration (method="jacobi"): unbiased against the exact references, its
accounts balanced, bitwise reproducible, its error measured by batch means."""
import math

import numpy as np
import pytest
from boxes import box_scene, open_box_with_card
from test_first_shot import _box_with_one_emitter
from test_lights import _box, _solid_angles

from addon.core import solve
from addon.core.lights.sampling import systematic_counts
from addon.core.lights.lights import AreaLight, PointLight, SunLight, WorldLight
from addon.core.estimate.reference import solve_radiosity_system

Z = 5.0


def _z_summary(result, exact):
    z = ((result.radiosity - exact) / np.sqrt(result.reflected_variance)).ravel()
    return np.abs(z).max(), np.mean(z**2), z.size


@pytest.mark.parametrize("direct_light", ["shot", "gathered"])
def test_jacobi_is_the_direct_solve(direct_light):
    """Per patch and channel against the exact discrete solution of a closed colour box lit by
    one ceiling patch, in batch-means standard errors: no |z| above 5 over the 288 values, and
    their mean square near 31/29 (32 chunks: t with 31 degrees of freedom; bound 5 standard
    errors of a chi-square mean, widened by 1.2 for the t's heavier tail)."""
    scene, exact = _box_with_one_emitter()
    r = solve(scene, paths=400_000, seed=1, method="jacobi", direct_light=direct_light)
    assert r.chunks == 32 and r.method == "jacobi" and r.path_ends["generations"] > 32
    worst, mean_square, n = _z_summary(r, exact)
    assert worst < Z
    assert abs(mean_square - 31 / 29) < 5 * math.sqrt(2 / n) * 1.2


@pytest.mark.parametrize("method", ["jacobi", "two_way"])
def test_a_closed_box_of_uniform_emission_and_reflectivity_is_e_over_one_minus_r(method):
    """Every patch emits E and reflects R: B = E / (1 - R) everywhere, exactly; the Russian
    roulette that ends each chunk keeps the expectation (R = 0.8: about 50 generations). The
    two-way iteration (test_two_way) too."""
    R, E = 0.8, 1.0
    scene, _, _ = box_scene([(R, R, R)] * 6, [(E, E, E)] * 6, n=3)
    r = solve(scene, paths=200_000, seed=2, method=method)
    z = (r.radiosity[:, 0] - E / (1 - R)) / np.sqrt(r.reflected_variance[:, 0])
    assert np.abs(z).max() < Z


@pytest.mark.parametrize("method", ["jacobi", "two_way"])
def test_a_point_light_in_a_closed_box_is_the_direct_solve(method):
    """The lights' rays start generation 0 as they start the walk's paths (Jacobi), or the
    light's direct light is gathered (two-way): against the discrete solution with the point
    light's exact first bounce, I Omega / A (test_lights). (Seed 4: since the direct light's
    samples are stratified, seed 3 draws one two-way patch at |z| 6.2, from its generations; over
    48 seeds of this box 1 of 2,592 patch values passed 5, mean t^2 1.07, docs/performance.md.)"""
    from test_lights import R_FACES

    position, intensity = np.array([0.3, 0.7, 0.5]), 2.0
    scene, rectangles, F = _box(lights=[PointLight(position, np.full(3, intensity))])
    direct = R_FACES.repeat(9) * intensity * _solid_angles(position, rectangles) / scene.patch_area
    exact = solve_radiosity_system(F, scene.reflectivity, direct)[:, 0]
    r = solve(scene, paths=600_000 if method == "jacobi" else 200_000, seed=4, method=method)
    z = (r.reflected[:, 0] - exact) / np.sqrt(r.reflected_variance[:, 0])
    assert np.abs(z).max() < Z


@pytest.mark.parametrize("direct_light", ["shot", "gathered"])
def test_jacobi_balances_its_energy_and_is_bitwise_reproducible_across_threads(direct_light):
    """An open box with a card, an emissive patch and a light of every kind: what the run emits
    is the scene's Phi_T and it is absorbed, escapes or is blocked, exactly (the roulette's
    gains and losses count as absorbed, as a walk's deaths do); one thread and two give the
    same bits."""
    base = open_box_with_card()
    lights = [
        PointLight(np.array([0.5, 0.5, 0.3]), np.array([1.0, 0.8, 0.6]), radius=0.05),
        AreaLight(np.array([0.7, 0.3, 0.9]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), np.array([0, 0, -1.0]), np.full(3, 2.0)),
        SunLight(np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]), np.full(3, 1.5), angle=0.1),
        WorldLight(irradiance=np.array([0.2, 0.3, 0.4])),
    ]
    scene = base.with_materials(base.reflectivity, base.emission, lights=lights)
    a = solve(scene, paths=100_000, seed=11, method="jacobi", direct_light=direct_light, threads=1)
    b = solve(scene, paths=100_000, seed=11, method="jacobi", direct_light=direct_light, threads=2)
    assert np.array_equal(a.radiosity, b.radiosity) and a.rays == b.rays
    e = a.energy
    np.testing.assert_allclose(e["emitted"].mean(), scene.total_power, rtol=1e-9)
    np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)
    assert (e["escaped"] > 0).all() and (e["blocked"] > 0).all()
    assert np.isnan(a.predicted_mse)  # the paper's formulas do not predict it


def test_systematic_counts_give_each_patch_floor_or_ceil_of_its_share():
    rng = np.random.default_rng(0)
    power = rng.random(1000) * (rng.random(1000) < 0.7)
    for rays in (1, 7, 1000, 12_345):
        for shift in (0.0, 0.5, 1 - 2**-53, rng.random()):
            counts = systematic_counts(power, rays, shift)
            share = power / power.sum() * rays
            assert counts.sum() == rays and (counts >= 0).all()
            assert (counts >= np.floor(share) - 1e-9).all() and (counts <= np.ceil(share) + 1e-9).all()
            assert (counts[power == 0] == 0).all()
    # Over the shift, each patch gets exactly its share on average.
    shifts = (np.arange(4096) + 0.5) / 4096
    mean = np.mean([systematic_counts(power[:20], 7, s) for s in shifts], axis=0)
    np.testing.assert_allclose(mean, power[:20] / power[:20].sum() * 7, atol=1 / 4096 + 1e-12)


def test_jacobi_stops_on_the_measured_error_and_refuses_unknown_methods():
    scene, _ = _box_with_one_emitter()
    target = 4e-6
    r = solve(scene, target_mse=target, seed=4, method="jacobi")
    assert r.stopped == "target" and r.measured_mse <= target
    with pytest.raises(ValueError, match="method"):
        solve(scene, paths=1000, method="jacobian")
