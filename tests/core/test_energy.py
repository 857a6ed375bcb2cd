"""Energy balance from each run's own accounting: emitted = absorbed + escaped (+ undistributed).

The scene is open (the box has no ceiling, so rays escape), coloured, and holds a one-sided
card that rays hit from behind (absorbed there: radiosity leaves only the front side).
"""
import numpy as np
import pytest

from addon.core import PatchScene, Speedups, solve
from boxes import box_rectangles, rectangles_to_mesh


@pytest.fixture(scope="module")
def open_scene():
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    keep = face != 1  # no ceiling
    origin, u, v, face = origin[keep], u[keep], v[keep], face[keep]
    # A card at half height facing down (normal -z): rays from the floor hit its front,
    # rays from above (off the walls) can hit its back.
    card_o, card_u, card_v = np.array([[0.3, 0.3, 0.5]]), np.array([[0, 0.4, 0]]), np.array([[0.4, 0, 0]])
    origin = np.vstack([origin, card_o])
    u, v = np.vstack([u, card_u]), np.vstack([v, card_v])
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    rng = np.random.default_rng(3)
    R = rng.uniform(0.2, 0.8, (P, 3))
    E = np.zeros((P, 3))
    E[:4] = [2.0, 1.5, 1.0]  # the floor emits
    return PatchScene(V, T, TP, R, E)


def test_biased_infinite_balance_is_exact(open_scene):
    r = solve(open_scene, estimator="biased_infinite", paths=50_000, threshold=1e-3, seed=1)
    e = r.energy
    assert (e["escaped"] > 0).all() and (e["blocked"] > 0).all() and (e["undistributed"] > 0).all()
    np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)


@pytest.mark.parametrize("counted", [True, False])
def test_finite_balance(open_scene, counted):
    """(A grey finite walk from random points: its hits counted per patch and outcome at
    each step, as in small scenes, or its survivors sorted by patch, as in big ones.)"""
    grey = open_scene.with_materials(open_scene.grey_reflectivity, open_scene.emission.mean(axis=1))
    N = 200_000
    r = solve(grey, estimator="finite", paths=N, seed=2, speedups=Speedups(counted=counted))
    assert r.speedups.counted == counted
    e = r.energy
    assert (e["escaped"] > 0).all() and (e["blocked"] > 0).all()
    # Every path ends exactly once: absorbed at a hit, escaped, or blocked by a back side.
    assert sum(r.path_ends.values()) == N
    # Emitted power is the scene's Phi_T exactly in a grey scene.
    np.testing.assert_allclose(e["emitted"], grey.total_power, rtol=1e-12)
    # The run's own accounts balance exactly: a path's power is absorbed where it dies.
    np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)
    scale = grey.total_power / N
    died = r.path_ends["absorbed"] * scale
    np.testing.assert_allclose(e["absorbed"] - e["blocked"], died, rtol=1e-12)
    # The expected absorption sum_j (1 - R_j) I_j (+ blocked), which the radiosity implies,
    # matches the deaths within the binomial noise of the survival tests: variance
    # sum_j I_j R_j (1 - R_j) (in path units).
    incident = r.reflected[:, 0] * grey.patch_area / grey.grey_reflectivity / scale
    R = grey.grey_reflectivity
    sd = np.sqrt((incident * R * (1 - R)).sum()) * scale
    expected_absorbed = ((1 - R) * incident).sum() * scale
    assert abs(expected_absorbed - died) < 4 * sd


def test_colour_finite_balance(open_scene):
    """In colour the finite walk re-weights survivors by R_c / R_bar: a hit absorbs the weight
    arriving minus the weight leaving (negative where R_c > R_bar), so each run's accounts
    still balance exactly, channel by channel. Their expectation is the absorption the
    radiosity implies, sum_j (1 - R_jc) I_jc: over 10 seeds the mean difference of each
    channel is within 5 standard errors of zero (estimated from the seeds; t with 9 d.o.f.:
    P(|t| > 5) < 1e-3)."""
    R = open_scene.reflectivity
    difference = []
    for seed in range(10):
        r = solve(open_scene, estimator="finite", paths=40_000, seed=seed)
        e = r.energy
        np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)
        # Incident power per patch and channel: I = b A / R.
        incident = r.reflected * open_scene.patch_area[:, None] / R
        implied = ((1 - R) * incident).sum(axis=0) + e["blocked"]
        difference.append((e["absorbed"] - implied) / e["emitted"])
    difference = np.array(difference)
    standard_error = difference.std(axis=0, ddof=1) / np.sqrt(len(difference))
    assert (standard_error > 0).all()
    assert (np.abs(difference.mean(axis=0)) < 5 * standard_error).all(), (difference.mean(axis=0), standard_error)
