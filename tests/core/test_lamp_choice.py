"""The display's choice among lamps (addon/core/lights/lamp_choice.py): all lamps looked at at once as
each looks at itself, a weight above 0 wherever a lamp can light a point (the estimate stays
unbiased), a point lamp's weight its own light, and samples drawn by weight."""
import numpy as np

from addon.core.lights.lamp_choice import LampChoice
from addon.core.lights.lights import AreaLight, PointLight, Spot, SunLight


def _elliptical_spot():
    matrix = np.diag([1.0, -2.0, -1.0])  # (a light scaled unevenly, its z along -z: an elliptical cone about -z)
    return Spot(np.array([0.0, 0.0, -1.0]), np.cos(0.6), np.cos(0.4), to_local=np.linalg.inv(matrix))


def _lamps():
    """One of every kind the display meets, scattered about the unit cube's middle."""
    round_spot = Spot(np.array([0.0, 0.6, -0.8]), np.cos(0.7), np.cos(0.5))
    return [
        PointLight(np.array([0.3, 0.4, 0.9]), np.array([1.0, 0.8, 0.6]), name="point"),
        PointLight(np.array([0.7, 0.2, 0.8]), np.array([0.5, 0.5, 0.9]), radius=0.08, name="sphere"),
        PointLight(np.array([0.5, 0.5, 0.95]), np.array([2.0, 1.0, 1.0]), spot=round_spot, name="spot"),
        PointLight(np.array([0.2, 0.8, 0.85]), np.ones(3), radius=0.05, spot=round_spot, name="sphere spot"),
        AreaLight(np.array([0.6, 0.7, 0.9]), np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.15, 0.0]),
                  np.array([0.0, 0.0, -1.0]), np.array([3.0, 2.0, 1.0]), name="rectangle"),
        AreaLight(np.array([0.4, 0.2, 0.7]), np.array([0.0, 0.1, 0.05]), np.array([0.12, 0.0, 0.0]),
                  np.array([0.0, 0.447, -0.894]), np.array([1.0, 1.0, 2.0]), ellipse=True, name="ellipse"),
        SunLight(np.array([0.3, 0.2, -0.933]) / np.linalg.norm([0.3, 0.2, -0.933]), np.array([1.0, 0.9, 0.8]), angle=0.1,
                 name="sun"),
        PointLight(np.array([0.9, 0.9, 0.6]), np.ones(3), radius=0.1, soft_falloff=True, name="soft"),
        PointLight(np.array([0.1, 0.5, 0.9]), np.ones(3), spot=_elliptical_spot(), name="elliptical spot"),
    ]


def _points(rng, n):
    """(n,3) points in the unit cube and (n,3) unit normals in every direction."""
    normal = rng.normal(size=(n, 3))
    return rng.uniform(0.0, 1.0, (n, 3)), normal / np.linalg.norm(normal, axis=1, keepdims=True)


def test_all_lamps_at_once_are_each_lamps_own_gather():
    """LampChoice.gather (each kind vectorised over its samples) against every lamp's own gather
    at the same points and uniforms: the same directions, distances and light to float error."""
    rng = np.random.default_rng(0)
    choice = LampChoice(_lamps())
    x, normal = _points(rng, 4000)
    u = rng.random((2, 4000), dtype=np.float32)
    lamp = rng.integers(0, len(choice), 4000)
    towards, distance, value = choice.gather(lamp, x.T, normal.T, u)
    for k, light in enumerate(choice.lamps):
        at = np.flatnonzero(lamp == k)
        assert at.size > 300
        own = light.gather(x.T[:, at], normal.T[:, at], u[:, at])
        np.testing.assert_allclose(towards[:, at], own[0], rtol=1e-12, atol=1e-12, err_msg=light.name)
        np.testing.assert_allclose(distance[at], own[1], rtol=1e-12, err_msg=light.name)
        np.testing.assert_allclose(value[:, at], own[2], rtol=1e-10, atol=1e-12 * own[2].max(), err_msg=light.name)


def test_a_lamp_that_can_light_a_point_or_a_patch_has_a_weight_above_0():
    """For every kind, at random points facing every way: wherever one of 64 uniforms of the lamp
    gives light, its weight is above 0 (a lamp left out would bias the estimate); and at points
    standing for a sphere of 0.1 about them, wherever a point of that sphere gets light."""
    rng = np.random.default_rng(1)
    choice = LampChoice(_lamps())
    x, normal = _points(rng, 3000)
    u = rng.random((2, 64), dtype=np.float32)
    for spread in (0.0, 0.1):
        weights = choice.weights(x, normal, spread)
        assert np.isfinite(weights).all() and (weights >= 0).all()
        offset = rng.normal(size=(3000, 3))
        at = x + spread * rng.uniform(0, 1, (3000, 1)) * offset / np.linalg.norm(offset, axis=1, keepdims=True)
        for k, light in enumerate(choice.lamps):
            lit = np.zeros(3000, bool)
            for j in range(64):
                lit |= light.gather(at.T, normal.T, np.repeat(u[:, j:j + 1], 3000, axis=1))[2].any(axis=0)
            assert lit.sum() > 100, light.name
            assert (weights[k, lit] > 0).all(), (light.name, spread, int((weights[k, lit] == 0).sum()))


def test_a_point_lamps_and_a_round_spots_weight_is_its_light():
    """Weighed at a point (no spread), a point lamp or a round spot weighs its grey light there
    unoccluded, I cos / d^2 times the mask (float32): among such lamps a choice by weight makes
    every sample's estimate the sum of their light."""
    rng = np.random.default_rng(2)
    lamps = [light for light in _lamps() if light.name in ("point", "spot")]
    choice = LampChoice(lamps)
    x, normal = _points(rng, 2000)
    weights = choice.weights(x, normal)
    for k, light in enumerate(choice.lamps):
        grey = light.gather(x.T, normal.T, np.zeros((2, 2000), np.float32))[2].mean(axis=0)
        assert (grey > 0).sum() > 300
        np.testing.assert_allclose(weights[k], grey, rtol=2e-5, atol=1e-7 * grey.max())


def test_samples_choose_lamps_by_their_weights_and_by_power_where_none_can_light():
    """Four lamps' chances at three points: the draws of 40,000 uniforms each fall on each lamp
    within 4 binomial standard errors of its weight's share, never on a lamp of weight 0, the
    chance given is the share; at a point of no weight, by the lamps' power."""
    lamps = [PointLight(np.zeros(3), np.full(3, p)) for p in (1.0, 2.0, 3.0, 4.0)]
    choice = LampChoice(lamps)
    weights = np.array([[1.0, 0.0, 0.0], [3.0, 2.0, 0.0], [0.0, 2.0, 0.0], [6.0, 0.0, 0.0]])
    n = 40_000
    local = np.repeat(np.arange(3), n)
    u = np.random.default_rng(3).random(3 * n)
    lamp, chance = choice.choose(weights, local, u)
    power = np.array([float(np.mean(light.intensity)) for light in choice.lamps])
    expected = np.column_stack([weights[:, :2] / weights[:, :2].sum(axis=0), power / power.sum()])
    for point in range(3):
        counts = np.bincount(lamp[local == point], minlength=4)
        share = expected[:, point]
        assert (counts[share == 0] == 0).all()
        np.testing.assert_array_less(np.abs(counts - n * share), 4 * np.sqrt(n * share * (1 - share)) + 1e-9)
        np.testing.assert_allclose(chance[local == point], share[lamp[local == point]], rtol=1e-12)
