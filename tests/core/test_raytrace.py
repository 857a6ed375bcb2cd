"""The ray tracer's two queries agree, its hit point by distance is its hit point by barycentric
coordinates, and Embree's geometric normal has our orientation."""
import numpy as np

from addon.core.lights.sampling import cosine_directions, points_on_patches
from boxes import box_scene


def _rays(scene, count, seed):
    rng = np.random.default_rng(seed)
    patch = rng.integers(0, scene.patch_count, count)
    u = rng.random((4, count), dtype=np.float32)
    g = scene.geometry
    return points_on_patches(g, patch, None, u[0], u[1]), cosine_directions(g, patch, u[2], u[3])


def test_barycentric_query_matches_first_hit_and_normal_orientation():
    scene, _, _ = box_scene([0.5] * 6, [1.0] * 6, size=(1.0, 2.0, 0.5), n=3)
    origins, directions = _rays(scene, 20_000, seed=3)
    # Rays into the box hit front sides; started a little behind their patch (outside the
    # box), the same rays cross it from behind.
    for behind in (False, True):
        o = np.ascontiguousarray(origins - 0.01 * directions) if behind else origins
        d = directions
        hit = scene.tracer.first_hit(o, d)
        hit_b, bu, bv, t, ng = scene.tracer.first_hit_barycentric(o, d)
        np.testing.assert_array_equal(hit, hit_b)
        ok = hit >= 0
        assert ok.mean() > 0.99
        facing = np.einsum("ij,ij->i", d[ok], scene.geometry.triangle_normal[hit[ok]]) < 0
        assert not facing.any() if behind else facing.all()
        dot = np.einsum("ij,ij->i", ng[ok], scene.geometry.triangle_normal[hit[ok]])
        # Ng is parallel to our unit normal and points the same way, for every hit.
        assert (dot > 0).all()
        assert ((bu[ok] >= 0) & (bv[ok] >= 0) & (bu[ok] + bv[ok] <= 1 + 1e-6)).all()
        # origin + t direction and the barycentric point are the same point (to float32's
        # rounding at the scene's unit size); a miss has t = inf.
        c = scene.geometry.triangle_corners[hit[ok]].astype(np.float64)
        by_barycentric = c[:, 0] + bu[ok, None] * (c[:, 1] - c[:, 0]) + bv[ok, None] * (c[:, 2] - c[:, 0])
        by_distance = o[ok] + t[ok, None].astype(np.float64) * d[ok]
        assert np.abs(by_distance - by_barycentric).max() < 1e-6
        assert np.isinf(t[~ok]).all()
