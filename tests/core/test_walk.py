"""The walk's shortcuts for grey scenes give what the general colour code gives."""
import numpy as np
import pytest

from addon.core.estimators import WalkTables, walk_chunk
from boxes import box_scene


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_grey_biased_weights_are_the_accumulated_reflectivity(exit_point):
    # Different reflectivities per face (0.99 ... 0.3), one emitting face, threshold mid-way.
    scene, _, _ = box_scene([0.3, 0.5, 0.7, 0.9, 0.6, 0.99], [0, 2.0, 0, 0, 0, 0], n=2)
    assert scene.is_grey
    fast = WalkTables(scene, "biased_infinite", 1e-3, exit_point)
    general = WalkTables(scene, "biased_infinite", 1e-3, exit_point)
    assert fast.weight_is_accumulated
    general.weight_is_accumulated = False  # the colour code path, on one channel
    a = walk_chunk(fast, 4000, np.random.default_rng(5))
    b = walk_chunk(general, 4000, np.random.default_rng(5))
    assert a.rays == b.rays and a.ended == b.ended  # the same random numbers, the same paths
    assert a.ended["threshold"] > 0
    np.testing.assert_allclose(a.incident, b.incident, rtol=1e-12)
    for field in ("emitted", "escaped", "blocked", "undistributed"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=1e-12)


def test_grey_mean_reflectivity_is_exact():
    scene, _, _ = box_scene([0.1, 0.7, 0.3, 0.9, 0.6, 0.2], [1.0] * 6)
    np.testing.assert_array_equal(scene.mean_reflectivity, scene.reflectivity[:, 0])
