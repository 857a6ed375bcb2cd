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


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
def test_facing_by_patch_normal_is_facing_by_triangle_normal(estimator):
    """In a scene of parallelograms the random exit's facing test reads the hit patch's normal
    (from the leave table) instead of the triangle's: the two triangles of a parallelogram are
    coplanar, so with the same random numbers every path is the same, back-side hits included."""
    from boxes import box_rectangles, rectangles_to_mesh
    from addon.core import PatchScene

    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    keep = face != 1  # open at the top
    # A card facing down at half height: rays from above hit its back.
    origin = np.vstack([origin[keep], [[0.3, 0.3, 0.5]]])
    u, v = np.vstack([u[keep], [[0, 0.4, 0]]]), np.vstack([v[keep], [[0.4, 0, 0]]])
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    E = np.zeros(P)
    E[:4] = 1.0
    scene = PatchScene(V, T, TP, np.full(P, 0.6), E)
    by_patch = WalkTables(scene, estimator, 1e-3, "random")
    by_triangle = WalkTables(scene, estimator, 1e-3, "random")
    assert by_patch.facing_by_patch
    by_triangle.facing_by_patch = False
    by_triangle.facing_rows = scene.geometry.triangle_normal_rows
    a = walk_chunk(by_patch, 20_000, np.random.default_rng(7))
    b = walk_chunk(by_triangle, 20_000, np.random.default_rng(7))
    assert a.ended["blocked"] > 100 and a.ended["escaped"] > 100
    assert a.rays == b.rays and a.ended == b.ended
    np.testing.assert_array_equal(a.incident, b.incident)
