"""The sampling primitives: sources by power, uniform points, cosine directions."""
import numpy as np

from addon.core.lights.sampling import (
    SourceTable,
    choose_triangles,
    source_weights,
    cosine_directions,
    points_on_triangles,
)
from boxes import box_scene


def test_sources_follow_power_exactly_at_bucket_edges():
    area = np.array([1.0, 2.0, 1.0, 4.0, 0.5])
    emission = np.array([[0, 0, 0], [1, 1, 1], [3, 0, 0], [1e-9, 0, 0], [2, 2, 2]], float)
    table = SourceTable(source_weights(area, emission))
    assert list(table.ids) == [1, 2, 3, 4]
    # The choice is exactly "first k with u < cdf[k]": check against searchsorted on a fine grid.
    u = np.linspace(0, 1, 200_001, endpoint=False)
    u = np.concatenate([u, table.cdf[:-1], np.nextafter(table.cdf[:-1], 0), [np.nextafter(1.0, 0)]])
    expected = table.ids[np.searchsorted(table.cdf, u, side="right")]
    assert np.array_equal(table.choose(u), expected)


def test_sources_frequencies():
    rng = np.random.default_rng(0)
    area = rng.uniform(0.1, 2, 500)
    emission = rng.uniform(0, 1, (500, 3)) * (rng.random((500, 1)) < 0.3)
    table = SourceTable(source_weights(area, emission))
    n = 2_000_000
    counts = np.bincount(table.choose(rng.random(n)), minlength=500)[table.ids]
    expected = n * table.probability
    chi2 = ((counts - expected) ** 2 / expected).sum()
    dof = table.ids.size - 1
    assert chi2 < dof + 5 * np.sqrt(2 * dof)


def test_cosine_directions_moments():
    """cos(theta) has density 2 c on [0,1]: E[c] = 2/3, E[c^2] = 1/2; azimuth uniform."""
    scene, _, _ = box_scene([0.5] * 6, [1] * 6, n=1)
    g = scene.geometry
    n = 1_000_000
    rng = np.random.default_rng(1)
    patch = rng.integers(0, 6, n)
    u = rng.random((2, n), dtype=np.float32)
    d = cosine_directions(g, patch, u[0], u[1]).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1, atol=1e-6)
    c = np.einsum("ij,ij->i", d, g.patch_normal[patch])
    assert c.min() >= -1e-6
    # Standard errors: sd(c) = 1/sqrt(18), sd(c^2) = 1/sqrt(12)
    assert abs(c.mean() - 2 / 3) < 5 / np.sqrt(18 * n)
    assert abs((c**2).mean() - 0.5) < 5 / np.sqrt(12 * n)
    # Tangential components average to zero (uniform azimuth), per patch orientation.
    tangential = d - c[:, None] * g.patch_normal[patch]
    assert np.abs(tangential.mean(axis=0)).max() < 5 * np.sqrt(0.25 / n)
    # The walks' unnormalised directions point the same way.
    raw = cosine_directions(g, patch, u[0], u[1], normalize=False).astype(np.float64)
    length = np.linalg.norm(raw, axis=1)
    assert length.min() > 0 and length.max() <= 2 + 1e-6
    np.testing.assert_allclose(raw / length[:, None], d, atol=1e-6)


def test_cosine_directions_never_vanish_at_the_grid_ends():
    """u1 = 0 and u1 = 1 - 2^-24 (the ends of float32's grid) give z = +-(1 - 2^-24), never
    +-1: for a normal along an axis, n + s is never zero (that would be no direction)."""
    scene, _, _ = box_scene([0.5] * 6, [1] * 6, n=1)
    g = scene.geometry
    ends = np.array([0.0, 1 - 2.0**-24], np.float32)
    u1 = np.repeat(ends, 1000)
    u2 = np.tile(np.linspace(0, 1, 1000, endpoint=False, dtype=np.float32), 2)
    for patch in range(6):
        d = cosine_directions(g, np.full(u1.size, patch), u1, u2, normalize=False).astype(np.float64)
        assert (np.einsum("ij,j->i", d, g.patch_normal[patch]) > 0).all()  # into the hemisphere


def test_points_are_uniform_on_patches():
    scene, _, _ = box_scene([0.5] * 6, [1] * 6, size=(2.0, 1.0, 1.0), n=1)
    g = scene.geometry
    n = 400_000
    rng = np.random.default_rng(2)
    patch = np.zeros(n, dtype=np.int64)  # the floor: [0,2] x [0,1] at z = 0
    u = rng.random((3, n), dtype=np.float32)
    p = g.to_world(points_on_triangles(g, choose_triangles(g, patch, u[0]), u[1], u[2]))
    # Pushed off the floor by the ray offset, inside the rectangle, uniform in x and y.
    np.testing.assert_allclose(p[:, 2], g.ray_offset * g.diagonal, rtol=1e-3, atol=1e-6)
    assert p[:, 0].min() >= -1e-6 and p[:, 0].max() <= 2 + 1e-6
    for coordinate, length in ((0, 2.0), (1, 1.0)):
        hist = np.histogram(p[:, coordinate], bins=20, range=(0, length))[0]
        expected = n / 20
        assert ((hist - expected) ** 2 / expected).sum() < 19 + 5 * np.sqrt(38)


def test_parallelogram_and_triangle_patches_sample_alike():
    """Rectangles made of two triangles are sampled as parallelograms; the same rectangle
    split into four triangles goes through the triangle path: both uniform on the patch."""
    from addon.core import PatchScene
    from addon.core.lights.sampling import points_on_patches

    # Patch 0: rectangle [0,2]x[0,1] as two triangles; patch 1: rectangle [0,2]x[2,3] as
    # four triangles around its centre; patch 2: a lone triangle.
    V = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0],
                  [0, 2, 0], [2, 2, 0], [2, 3, 0], [0, 3, 0], [1, 2.5, 0],
                  [3, 0, 0], [4, 0, 0], [3, 1, 0]], float)
    T = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 8], [5, 6, 8], [6, 7, 8], [7, 4, 8], [9, 10, 11]])
    scene = PatchScene(V, T, [0, 0, 1, 1, 1, 1, 2], [0.5, 0.5, 0.5], [1, 0, 0])
    g = scene.geometry
    assert list(g.patch_parallelogram) == [True, False, False]
    n = 300_000
    rng = np.random.default_rng(4)
    for patch_index, (x0, y0) in ((0, (0, 0)), (1, (0, 2))):
        patch = np.full(n, patch_index)
        u = rng.random((3, n), dtype=np.float32)
        p = g.to_world(points_on_patches(g, patch, u[0], u[1], u[2]))
        assert p[:, 0].min() >= x0 - 1e-6 and p[:, 0].max() <= x0 + 2 + 1e-6
        assert p[:, 1].min() >= y0 - 1e-6 and p[:, 1].max() <= y0 + 1 + 1e-6
        hist = np.histogram2d(p[:, 0], p[:, 1], bins=(8, 4), range=((x0, x0 + 2), (y0, y0 + 1)))[0].ravel()
        expected = n / 32
        assert ((hist - expected) ** 2 / expected).sum() < 31 + 5 * np.sqrt(62)


def test_channel_sum_is_numpys_sum_bit_for_bit():
    """Source powers (and colour walks' mean emission) add the three channels as
    (v0 + v1) + v2, which is what values.sum(axis=1) computes: the same numbers to the bit, so
    the sources drawn do not change."""
    from addon.core.lights.sampling import channel_sum

    rng = np.random.default_rng(3)
    for dtype in (np.float64, np.float32):
        values = rng.random((50_000, 3)) * rng.choice([1e-30, 1e-3, 1.0, 7.0, 1e3, 1e30], (50_000, 3))
        values = values.astype(dtype)
        np.testing.assert_array_equal(channel_sum(values), values.sum(axis=1))
        np.testing.assert_array_equal(channel_sum(values) / 3, values.mean(axis=1))
        # ... and not the other grouping, which differs somewhere on such data.
        assert not np.array_equal(values[:, 0] + (values[:, 1] + values[:, 2]), values.sum(axis=1))


# The first 8 Sobol' points in 10 dimensions, times 64: scipy.stats.qmc.Sobol(10, scramble=False)
# (the same Joe & Kuo direction numbers) gives these points, in Gray-code order.
SOBOL_FIRST_8 = [[0, 0, 0, 0, 0, 0, 0, 0, 0, 0], [32] * 10, [16, 48, 48, 48, 16, 16, 48, 16, 16, 16],
                 [48, 16, 16, 16, 48, 48, 16, 48, 48, 48], [8, 40, 24, 8, 8, 24, 40, 40, 40, 56],
                 [40, 8, 56, 40, 40, 56, 8, 8, 8, 24], [24, 24, 40, 56, 24, 8, 24, 56, 56, 40],
                 [56, 56, 8, 24, 56, 40, 56, 24, 24, 8]]


def test_sobol_points_are_joe_and_kuos_and_nets():
    """The table's first points are scipy's; the first 2^m points of every dimension fall one in
    each interval of 2^-m, and dimensions 0 and 1 together one in each of the 2^m boxes of
    every shape 2^-a x 2^-(m-a) (a (0,m,2)-net)."""
    from addon.core.lights.sampling import SOBOL

    u = SOBOL.rows(1024)[:, :1024] * 2.0**-32
    assert (u[:, :8].T * 64).tolist() == SOBOL_FIRST_8
    for m in range(1, 11):
        n = 2**m
        for row in u[:, :n]:
            assert np.unique((row * n).astype(int)).size == n
        for a in range(m + 1):
            boxes = (u[0, :n] * 2**a).astype(int) * 2 ** (m - a) + (u[1, :n] * 2 ** (m - a)).astype(int)
            assert np.unique(boxes).size == n


def test_stratified_points_are_uniform_evenly_spread_and_independent_between_patches():
    """stratified_by_patch: 8 samples of patch 0 keep the net (one in each eighth of every
    dimension); over 4,000 draws, one sample's coordinate is uniform (chi-square over 16 bins
    within 5 standard deviations of its mean) and uncorrelated with another patch's (within 5
    standard errors of zero)."""
    from addon.core.lights.sampling import stratified_by_patch

    patch = np.repeat(np.arange(3, dtype=np.int32), [8, 0, 5])
    rng = np.random.default_rng(7)
    u = stratified_by_patch(patch, 3, range(10), rng)
    assert u.shape == (10, 13) and u.min() >= 0 and u.max() < 1
    for row in u[:, :8]:
        assert np.unique((row * 8).astype(int)).size == 8
    draws = np.array([stratified_by_patch(patch, 3, (2, 5), rng)[:, [3, 10]] for _ in range(4000)])  # (4000, 2, 2)
    counts = np.bincount((draws[:, 0, 0] * 16).astype(int), minlength=16)
    chi2 = ((counts - 250.0) ** 2 / 250.0).sum()
    assert abs(chi2 - 15) < 5 * np.sqrt(30)
    r = np.corrcoef(draws[:, 1, 0], draws[:, 1, 1])[0, 1]
    assert abs(r) < 5 / np.sqrt(4000)


def test_shifted_points_wrap_into_float32_below_one():
    """A point plus its shift, modulo 1, as float32: exactly the float64 remainder where float32
    holds it, and never 1.0 where a float64 just below 1 would round up to it."""
    from addon.core.lights.sampling import shifted_float32

    point = np.array([0.25, 0.75, 0.5, 1 - 2.0**-53, 0.0, 1 - 2.0**-30])
    shift = np.array([0.5, 0.5, 0.5 - 2.0**-40, 0.0, 1 - 2.0**-53, 0.5])
    out = shifted_float32(point + shift)
    assert out.dtype == np.float32 and np.all(out < 1.0) and np.all(out >= 0.0)
    np.testing.assert_array_equal(out[:2], np.float32([0.75, 0.25]))
    assert out[3] == out[4] == np.nextafter(np.float32(1), np.float32(0))  # (both round to 1.0f before the clamp)
    np.testing.assert_allclose(out, np.mod(point + shift, 1.0), atol=2.0**-24)
