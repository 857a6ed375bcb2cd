"""Smooth display of per-patch light (addon/core/display/smoothing.py): seamless across objects, creases
kept, each patch's mean preserved, non-negative, and a noise filter that lowers the error against
exact references.

Statistical bands: per seed, the ratio of the filtered to the raw mean squared error against the
exact discrete solution (a closed box of rectangles: exact form factors, direct linear solve); over
S seeds the mean ratio plus Z of its standard errors must stay below 1. The deterministic parts
(means, seams, creases, the bias bound) are checked to float error.
"""
import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.mesh import meshing
from addon.core.display import slack, smoothing
from addon.core.estimate.reference import rectangle_form_factors, solve_radiosity_system
from boxes import box_rectangles, rectangles_to_mesh, small_source_box

Z = 4.5
SEEDS = 8


def _grid(nx, ny, origin, ex, ey, dtype=np.float64):
    """A welded quad grid (one object): points, quads, triangles, triangle patch, patch centres."""
    i, j = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), indexing="ij")
    points = (np.asarray(origin, np.float64) + np.outer(i.ravel() / nx, ex) + np.outer(j.ravel() / ny, ey)).astype(dtype)
    a = (i[:-1, :-1] * (ny + 1) + j[:-1, :-1]).ravel()
    quads = np.stack([a, a + ny + 1, a + ny + 2, a + 1], axis=1)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
    patch = np.repeat(np.arange(len(quads)), 2)
    return points.astype(np.float64), quads, triangles, patch


def _today_vertex_colours(points, quads, triangles, patch, values):
    """The glue's vertex colours today: per object, the area-weighted average of the patches
    around each of the object's own vertices (meshing.point_average)."""
    corners = points[triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    patch_area = np.bincount(patch, weights=area)
    mesh = meshing.PatchMesh(points, np.full(len(quads), 4), quads.ravel(), np.arange(len(quads)),
                             triangles, patch, patch_area)
    return meshing.point_average(mesh, values)


def _combine(*objects):
    """The scene's triangles as the solver gets them: objects' vertices one after the other."""
    vertices, triangles, patch = [], [], []
    v0 = p0 = 0
    for points, quads, tris, tp in objects:
        vertices.append(points)
        triangles.append(tris + v0)
        patch.append(tp + p0)
        v0 += len(points)
        p0 += len(quads)
    return np.concatenate(vertices), np.concatenate(triangles), np.concatenate(patch)


def _centres(points, quads):
    return points[quads].mean(axis=1)


def _patch_means(vertices, triangles, patch, corner_values, P):
    """Area-weighted mean of the linear interpolation over each patch, computed independently."""
    c = vertices[triangles]
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    sums = np.stack([np.bincount(patch, weights=area * corner_values[:, :, k].mean(axis=1), minlength=P)
                     for k in range(corner_values.shape[2])], axis=1)
    return sums / np.bincount(patch, weights=area, minlength=P)[:, None]


# ---------------------------------------------------------------------------------------------
# Seams, creases
# ---------------------------------------------------------------------------------------------

def _two_wall_pieces():
    """Two coplanar pieces of wall, separate objects meeting along x = 1, the second placed by a
    float32 world matrix (its corners off by float rounding), a light peaked near the joint."""
    a = _grid(8, 8, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    b = _grid(8, 8, (1, 0, 0), (1, 0, 0), (0, 1, 0), dtype=np.float32)
    values = []
    for points, quads, _, _ in (a, b):
        c = _centres(points, quads)
        light = np.exp(-((c[:, 0] - 1.1) ** 2 + (c[:, 1] - 0.5) ** 2) / 0.1)
        values.append(0.1 + light[:, None] * [1.0, 0.6, 0.3])
    return a, b, values


def _spread_at_joint(points_of_corner, corner_values):
    """Largest difference between corner values at the same point of the joint x = 1."""
    on = np.abs(points_of_corner[:, 0] - 1.0) < 1e-6
    y = np.round(points_of_corner[on, 1], 6)
    keys, group = np.unique(y, return_inverse=True)
    spread = 0.0
    for k in range(corner_values.shape[1]):
        hi = np.full(len(keys), -np.inf)
        lo = np.full(len(keys), np.inf)
        np.maximum.at(hi, group, corner_values[on, k])
        np.minimum.at(lo, group, corner_values[on, k])
        spread = max(spread, float((hi - lo).max()))
    return spread


def test_two_objects_meeting_coplanar_share_their_corners():
    """At the joint of two objects the corner values agree (the iterations' residual jump: 0.14%
    of the peak); today's per-object vertex averages leave a seam there."""
    a, b, values = _two_wall_pieces()
    V, T, TP = _combine(a, b)
    patch_values = np.concatenate(values)
    corners = smoothing.corner_values(V, T, TP, patch_values)
    peak = patch_values.max()
    ours = _spread_at_joint(V[T].reshape(-1, 3), corners.reshape(-1, 3))
    assert ours < 0.01 * peak, ours / peak
    today = [_today_vertex_colours(*obj, v) for obj, v in zip((a, b), values)]
    seam = _spread_at_joint(np.concatenate([a[0], b[0]]), np.concatenate(today))
    assert seam > 0.05 * peak, seam / peak
    assert ours < seam / 10


def test_weld_joins_float_rounding_not_gaps():
    """Corners off by float32 rounding are one point; pieces a millimetre apart (a real gap, 1% of
    a patch side) are not."""
    a = _grid(4, 4, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    touching = _grid(4, 4, (1, 0, 0), (1, 0, 0), (0, 1, 0), dtype=np.float32)
    apart = _grid(4, 4, (1.001, 0, 0), (1, 0, 0), (0, 1, 0))
    for other, joined in ((touching, 5), (apart, 0)):
        V, T, TP = _combine(a, other)
        surface = smoothing.Surface.of(V, T, TP)
        points = len(np.unique(surface.point))
        assert points == 2 * 25 - joined


def _floor_and_wall(angle_degrees=90.0):
    """One object: a floor (z = 0) and a wall rising from its edge y = 0 at ``angle`` to the
    floor, sharing the edge's vertices (merged by index, as one mesh)."""
    n = 4
    floor = _grid(n, n, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    t = np.radians(angle_degrees)
    wall = _grid(n, n, (0, 0, 0), (0, np.cos(t), np.sin(t)), (1, 0, 0))
    both = np.concatenate([floor[0], wall[0]])
    points, index = np.unique(np.round(both, 9), axis=0, return_inverse=True)
    index = index.ravel()
    quads = np.concatenate([index[floor[1]], index[len(floor[0]) + wall[1]]])
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3)
    patch = np.repeat(np.arange(len(quads)), 2)
    return points, quads, triangles, patch, len(floor[1])


def test_crease_keeps_each_surface_its_own_light():
    """A wall lit at 1 meeting a floor at 0.2 along a shared edge: every floor corner is 0.2 and
    every wall corner 1 (nothing leaks across the 90 degree edge); today's vertex average puts a
    line of 0.6 along the edge on both."""
    points, quads, triangles, patch, floor_count = _floor_and_wall(90.0)
    values = np.where(np.arange(len(quads)) < floor_count, 0.2, 1.0)[:, None] * [1.0, 1.0, 1.0]
    corners = smoothing.corner_values(points, triangles, patch, values)
    expected = values[patch][:, None, :] * np.ones((1, 3, 1))
    np.testing.assert_allclose(corners, expected, rtol=1e-12)
    today = _today_vertex_colours(points, quads, triangles, patch, values)
    on_edge = np.unique(quads[:floor_count])[np.abs(points[np.unique(quads[:floor_count]), 1]) < 1e-12]
    assert np.all((today[on_edge, 0] > 0.25) & (today[on_edge, 0] < 0.95)), today[on_edge, 0]


def test_a_covers_outline_keeps_each_side_its_own_light():
    """A flat 6 x 6 grid whose middle 2 x 2 cells lie under a cover (the gap over a light panel)
    at 25 times the rest's light: as at a crease, every corner outside is 1 and every corner inside
    25, the outline's too (joined, the outline's corners took the gap's light into the room's cells
    and the gap's corners dipped toward the room's)."""
    points, quads, triangles, patch = _grid(6, 6, (0.0, 0.0, 0.0), (3.0, 0.0, 0.0), (0.0, 3.0, 0.0))
    centre = _centres(points, quads)
    covered = (np.abs(centre[:, 0] - 1.5) < 0.5) & (np.abs(centre[:, 1] - 1.5) < 0.5)
    assert covered.sum() == 4
    values = np.where(covered, 25.0, 1.0)[:, None] * [1.0, 0.9, 0.8]
    surface = smoothing.Surface.of(points, triangles, patch, len(quads), covered=covered)
    corners = surface.corner_values(values)
    expected = values[patch][:, None, :] * np.ones((1, 3, 1))
    np.testing.assert_allclose(corners, expected, rtol=1e-12)
    joined = smoothing.Surface.of(points, triangles, patch, len(quads)).corner_values(values)
    assert joined[~covered[patch]].max() > 5.0 and joined[covered[patch]].min() < 15.0
    assert smoothing.Surface.of(points, triangles, patch, len(quads), covered=np.zeros(len(quads), bool)).covered is None


def test_shallow_fold_is_smoothed_across():
    """Below the crease angle (a 160 degree fold: normals 20 degrees apart) the edge is one smooth
    surface: light changing linearly across the fold gets the same corner values on both sides of
    it (the iterations' residual jump: 0.5% of the peak on this coarse mesh); a step of light
    across the fold is blended (each side's edge moves toward the other)."""
    points, quads, triangles, patch, floor_count = _floor_and_wall(160.0)
    centre = points[quads].mean(axis=1)
    along = np.where(np.arange(len(quads)) < floor_count, -centre[:, 1], np.linalg.norm(centre[:, 1:], axis=1))
    at = points[triangles].reshape(-1, 3)
    on = np.abs(at[:, 1]) < 1e-12
    values = (1.0 + along)[:, None] * [1.0, 1.0, 1.0]
    ramp = smoothing.corner_values(points, triangles, patch, values).reshape(-1, 3)
    for x in np.unique(np.round(at[on, 0], 9)):
        here = ramp[on][np.round(at[on, 0], 9) == x, 0]
        assert here.max() - here.min() < 0.01 * values.max(), here
    step = np.where(np.arange(len(quads)) < floor_count, 0.2, 1.0)[:, None] * [1.0, 1.0, 1.0]
    blended = smoothing.corner_values(points, triangles, patch, step).reshape(-1, 3)
    floor_corner = on & (np.repeat(patch, 3) < floor_count)
    assert (blended[floor_corner, 0] > 0.25).all() and (blended[on & ~floor_corner, 0] < 0.95).all()


# ---------------------------------------------------------------------------------------------
# Mean preservation, non-negativity, bad input
# ---------------------------------------------------------------------------------------------

def _random_mesh(seed):
    """A jittered, folded grid (creases where the height jumps) plus an overlapping second object;
    patches of one to three triangles; values exponential, a fifth of them zero."""
    rng = np.random.default_rng(seed)
    n = 12
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    xy = np.stack([i.ravel(), j.ravel()], axis=1) + rng.uniform(-0.3, 0.3, ((n + 1) ** 2, 2))
    z = rng.choice([0.0, 0.0, 0.0, 1.5], (n + 1) ** 2)
    points = np.column_stack([xy, z])
    a = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    tris = np.concatenate([np.stack([a, a + n + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + 1], 1)])
    tris = tris[rng.permutation(len(tris))]
    patch = np.sort(rng.integers(0, len(tris) // 2, len(tris)))
    patch = np.unique(patch, return_inverse=True)[1]
    other = points[:60] + [0.5, 0.5, 0.0]
    other_tris = tris[np.all(tris < 60, axis=1)]
    V = np.concatenate([points, other])
    T = np.concatenate([tris, other_tris + len(points)])
    TP = np.concatenate([patch, patch.max() + 1 + np.arange(len(other_tris))])
    P = TP.max() + 1
    values = rng.exponential(1.0, (P, 3)) * (rng.random((P, 1)) > 0.2)
    return V, T, TP, values


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("iterations", [1, 10])
def test_each_patch_keeps_its_mean_and_values_stay_non_negative(seed, iterations):
    V, T, TP, values = _random_mesh(seed)
    corners = smoothing.corner_values(V, T, TP, values, iterations=iterations)
    assert corners.shape == (len(T), 3, 3)
    assert (corners >= 0).all()
    means = _patch_means(V, T, TP, corners, len(values))
    np.testing.assert_allclose(means, values, rtol=1e-12, atol=1e-15 * values.max())
    # and it is smooth: not the flat patch values themselves
    assert np.abs(corners - values[TP][:, None, :]).max() > 0.1


def _point_spread(vertices, triangles, corners):
    """(largest over the points of the spread of the corner values meeting at a point, per channel max)."""
    key = np.unique(np.round(vertices[triangles].reshape(-1, 3), 9), axis=0, return_inverse=True)[1].ravel()
    flat = corners.reshape(-1, corners.shape[2])
    hi = np.full((key.max() + 1, flat.shape[1]), -np.inf)
    lo = np.full_like(hi, np.inf)
    np.maximum.at(hi, key, flat)
    np.minimum.at(lo, key, flat)
    return float((hi - lo).max())


def test_a_patch_within_its_noise_of_its_neighbours_shows_their_light_not_a_square():
    """A wall of even light (1) whose estimates are noisy (standard error 0.1, the light of one
    patch read 1.15, of another 0.9): held to its exact mean, each of them shows a square, its
    corners scaled apart from its neighbours' at its edges; given each patch's standard error as
    the slack, every patch's mean stays within it of its value and the corners meet at every
    point as one light (no jump). A real step (a patch at 3, far beyond its noise) keeps its mean
    to within its slack; the means are exact without one."""
    points, quads, triangles, patch = _grid(8, 8, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    values = np.ones((len(quads), 3))
    values[27], values[44] = 1.15, 0.9
    error = np.full_like(values, 0.1)
    exact = smoothing.corner_values(points, triangles, patch, values)
    loose = smoothing.corner_values(points, triangles, patch, values, slack=error)
    np.testing.assert_allclose(_patch_means(points, triangles, patch, exact, len(quads)), values, rtol=1e-12)
    assert _point_spread(points, triangles, exact) > 0.02  # (the squares' edges: 4% of the light)
    means = _patch_means(points, triangles, patch, loose, len(quads))
    assert (np.abs(means - values) <= error + 1e-12).all()
    assert _point_spread(points, triangles, loose) < 1e-3  # (what ten steps leave beyond the slack: 4e-5)
    stepped = values.copy()
    stepped[27] = 3.0
    means = _patch_means(points, triangles, patch, smoothing.corner_values(points, triangles, patch, stepped, slack=error),
                         len(quads))
    assert abs(means[27, 0] - 3.0) <= 0.1 + 1e-12 and (np.abs(means - stepped) <= error + 1e-12).all()


def test_the_slack_is_its_standard_errors_and_the_direct_light_kept_apart_keeps_its_means():
    """slack_of: SLACK_ERRORS standard errors of the variances; none (NaN) where none was measured;
    at most the light gathered after a bounce where the direct part is known apart (0 there: exact)."""
    variance = np.array([[0.04, 0.09, np.nan], [np.inf, -1.0, 0.0]])
    given = slack.slack_of(variance)
    np.testing.assert_allclose(given[0, :2], slack.SLACK_ERRORS * np.array([0.2, 0.3]))
    assert np.isnan(given[0, 2]) and np.isnan(given[1, :2]).all() and given[1, 2] == 0.0
    capped = slack.slack_of(np.full((2, 3), 0.04), indirect=np.array([[0.0, 0.05, 1.0], [-1.0, 0.0, 0.3]]))
    error = slack.SLACK_ERRORS * 0.2
    np.testing.assert_allclose(capped, [[0.0, min(error, 0.05), min(error, 1.0)], [0.0, 0.0, min(error, 0.3)]])


def test_bad_values_are_refused_with_one_line_and_negative_light_is_none():
    V, T, TP, values = _random_mesh(0)
    surface = smoothing.Surface.of(V, T, TP)
    signed = values - 0.5  # a signed estimator's noise: negative light shows as none
    corners = surface.corner_values(signed)
    assert (corners >= 0).all()
    np.testing.assert_allclose(_patch_means(V, T, TP, corners, len(values)), np.maximum(signed, 0.0),
                               rtol=1e-12, atol=1e-15 * values.max())
    with pytest.raises(ValueError, match="not all finite"):
        surface.corner_values(np.where(values > 1, np.nan, values))
    with pytest.raises(ValueError, match="rows for"):
        surface.corner_values(values[:-1])


# ---------------------------------------------------------------------------------------------
# Noise
# ---------------------------------------------------------------------------------------------

SIZE = (1.0, 1.3, 0.7)
R_FACES, E_FACES = [0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0]


def _exact_box(n):
    origin, u, v, face = box_rectangles(SIZE, n=n)
    R, E = np.asarray(R_FACES)[face], np.asarray(E_FACES)[face]
    V, T, TP = rectangles_to_mesh(origin, u, v)
    scene = PatchScene(V, T, TP, R, E)
    return scene, rectangle_form_factors(origin, u, v)


def _filtered_errors(scene, F, paths):
    """Per seed: raw and filtered mean squared error per patch against the exact solution, and
    the filtered error and its bound per patch."""
    exact = solve_radiosity_system(F, scene.reflectivity, scene.emission) - scene.emission
    exact = exact.reshape(len(exact), -1)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch)
    raw, filtered, errors, bounds = [], [], [], []
    for seed in range(SEEDS):
        r = solve(scene, estimator="finite", paths=paths, seed=300 + seed, threads=2)
        x = r.reflected.reshape(exact.shape)
        out, limit = surface.filter_noise(x, r.reflected_variance.reshape(exact.shape), bound=True)
        assert (np.abs(out - x) <= limit * (1 + 1e-12)).all()  # the stated bias bound holds
        assert (out >= 0).all()
        raw.append(((x - exact) ** 2).mean())
        filtered.append(((out - exact) ** 2).mean())
        errors.append(out - exact)
        bounds.append(limit)
    return np.array(raw), np.array(filtered), np.array(errors), np.array(bounds)


@pytest.mark.parametrize("case, paths", [
    ("box", 20_000), ("box", 200_000), ("corner_lamp", 20_000), ("corner_lamp", 200_000),
])
def test_noise_filter_lowers_the_error_against_the_exact_solution(case, paths):
    """Against the exact discrete solution, per patch mean squared error after the filter is below
    the raw estimate's (which is today's face colour), at low and high path counts, with a broad
    light (the box lit by its ceiling) and a small lamp in a corner (steep gradients); and the
    filtered error's mean over seeds stays within the stated bias bound (plus noise)."""
    scene, F = _exact_box(6) if case == "box" else small_source_box(8, corner=True)
    raw, filtered, errors, bounds = _filtered_errors(scene, F, paths)
    ratio = filtered / raw
    band = Z * ratio.std(ddof=1) / np.sqrt(SEEDS)
    assert ratio.mean() + band < 1.0, (ratio.mean(), band)
    bias = np.abs(errors.mean(axis=0))
    allowed = bounds.mean(axis=0) + Z * errors.std(axis=0, ddof=1) / np.sqrt(SEEDS)
    assert (bias <= allowed).all()


def test_noise_filter_keeps_a_step_and_flattens_noise():
    """Synthetic estimates with known variance: a step of 40 standard errors between two halves of
    a wall stays sharp (patches beside the step no worse than raw), the flat halves get less noisy."""
    a = _grid(20, 20, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    V, T, TP = _combine(a)
    c = _centres(a[0], a[1])
    truth = np.where(c[:, 0] < 0.5, 1.0, 3.0)[:, None] * [1.0, 1.0, 1.0]
    sigma = 0.05
    surface = smoothing.Surface.of(V, T, TP)
    beside = np.abs(c[:, 0] - 0.5) < 0.06
    raw, out_flat, raw_step, out_step = [], [], [], []
    for seed in range(SEEDS):
        x = truth + np.random.default_rng(seed).normal(0.0, sigma, truth.shape)
        out = surface.filter_noise(x, np.full(truth.shape, sigma ** 2))
        raw.append(((x - truth)[~beside] ** 2).mean())
        out_flat.append(((out - truth)[~beside] ** 2).mean())
        raw_step.append(((x - truth)[beside] ** 2).mean())
        out_step.append(((out - truth)[beside] ** 2).mean())
    ratio = np.array(out_flat) / np.array(raw)
    assert ratio.mean() + Z * ratio.std(ddof=1) / np.sqrt(SEEDS) < 0.5, ratio
    step = np.array(out_step) / np.array(raw_step)
    assert step.mean() - Z * step.std(ddof=1) / np.sqrt(SEEDS) < 1.0, step


def test_patches_without_a_variance_are_left_alone():
    a = _grid(6, 6, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    V, T, TP = _combine(a)
    x = np.random.default_rng(1).random((36, 3))
    var = np.full((36, 3), np.nan)
    out = smoothing.Surface.of(V, T, TP).filter_noise(x, var)
    np.testing.assert_array_equal(out, x)


def test_patches_no_path_reached_are_filtered_not_kept_black():
    """Sparse hits: each patch's estimate a Poisson count of mean 4 over 4 (variance estimate
    value / 4, zero where nothing arrived). The black speckles (about 2% of the patches) are
    raised toward their neighbours instead of anchoring them at zero, and the error drops."""
    a = _grid(30, 30, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    V, T, TP = _combine(a)
    surface = smoothing.Surface.of(V, T, TP)
    lam = 4.0
    ratios, speckles = [], []
    for seed in range(SEEDS):
        x = np.random.default_rng(seed).poisson(lam, (900, 1)) / lam * [1.0, 1.0, 1.0]
        out = surface.filter_noise(x, x / lam)
        black = x[:, 0] == 0
        assert black.any()
        speckles.append(out[black, 0].mean())
        ratios.append(((out - 1.0) ** 2).mean() / ((x - 1.0) ** 2).mean())
    ratios = np.array(ratios)
    assert ratios.mean() + Z * ratios.std(ddof=1) / np.sqrt(SEEDS) < 1.0, ratios
    assert min(speckles) > 0.3, speckles


def test_polygon_corners_read_the_value_of_their_patchs_triangle_corner():
    """Quads fanned into two triangles each: every polygon corner reads the value its patch's
    triangles hold at that point; a corner that is no corner of its patch's triangles is refused."""
    from addon.core.mesh.faces import polygon_corner_values

    rng = np.random.default_rng(5)
    quads = rng.permutation(40).reshape(10, 4)  # (10 patches, their 4 points)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    patch = np.concatenate([np.arange(10), np.arange(10)])
    corners = rng.random((20, 3, 3))
    point_value = {}
    for t in range(20):  # make the corners of one patch at one point agree, as smoothing's do
        for k in range(3):
            corners[t, k] = point_value.setdefault((patch[t], triangles[t, k]), corners[t, k])
    got = polygon_corner_values(corners, triangles, patch, np.repeat(np.arange(10), 4), quads.ravel())
    expected = np.array([point_value[(p, v)] for p, v in zip(np.repeat(np.arange(10), 4), quads.ravel())])
    np.testing.assert_array_equal(got, expected)
    with pytest.raises(ValueError, match="not a corner of its patch"):
        polygon_corner_values(corners, triangles, patch, np.array([0]), np.array([quads[1, 0]]))


def test_a_bright_patch_beside_dim_ones_never_pushes_a_corner_to_black():
    """A closed box of 4 x 4 patches a face lit by a point lamp near its ceiling (the patch under
    it several times its neighbours): no corner goes black, every one above a quarter of the
    darkest patch (before, 42 of 1,728 corners came out exactly 0 while no patch was below 5.4),
    and each patch keeps its mean."""
    from boxes import box_rectangles, rectangles_to_mesh

    from addon.core import PatchScene, solve
    from addon.core.lights.lights import PointLight

    origin, u, v, _ = box_rectangles((1, 1, 1), n=4)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = TP.max() + 1
    scene = PatchScene(V, T, TP, np.full(P, 0.6), np.zeros(P), [PointLight(np.array([0.4, 0.45, 0.8]), np.full(3, 3.0))])
    values = np.maximum(solve(scene, paths=20_000, seed=1).reflected, 0.0)
    surface = smoothing.Surface.of(V, T, TP, P)
    corners = surface.corner_values(values)
    # (the floor is half the darkest patch at a point; the last exact scale of a patch may take
    # its corners a little lower: 0.41 of the darkest patch here)
    assert corners.min() > 0.25 * values.min(), corners.min() / values.min()
    means = (corners.sum(axis=1) / 3 * surface.triangle_area[:, None])
    np.testing.assert_allclose(np.stack([np.bincount(TP, weights=means[:, c], minlength=P) for c in range(3)], 1)
                               / surface.patch_area[:, None], values, rtol=1e-9)


def test_light_falling_off_faster_than_a_patch_can_follow_shows_no_bands():
    """Light falling off 4.2x from one patch to the next (as on a ceiling beside a wall a strip
    lights) has no continuous answer that keeps every patch's mean without swinging: the
    iterations pushed corners up and down row after row (far corners up to 2.8x the near ones
    of their patch), seen as bands. Where they turn a patch's corners against the plain average of the
    patches around each corner, that patch and its neighbours keep the plain average, scaled to
    their means: along the fall-off every patch's corners fall, no patch's near corners rise above
    the patch's before it, each patch keeps its mean, and parts made with the fixed weights add
    up to the whole."""
    points, quads, triangles, patch = _grid(12, 4, (0, 0, 0), (12, 0, 0), (0, 4, 0))
    x = _centres(points, quads)[:, 0]
    values = np.exp(-x / 0.7)[:, None] * np.array([1.0, 0.8, 0.6])
    surface = smoothing.Surface.of(points, triangles, patch, len(quads))
    corners, apply = surface.corner_values(values, return_filter=True)
    np.testing.assert_allclose(surface.corner_means(corners[..., 0].ravel()), values[:, 0], rtol=1e-9)
    corner_x = points[triangles][..., 0]  # (T,3)
    near = np.full(len(quads), np.inf)
    far = np.full(len(quads), -np.inf)
    left = corner_x == np.floor(x[patch])[:, None]
    np.minimum.at(near, np.repeat(patch, 3)[left.ravel()], corners[..., 0][left])
    np.maximum.at(far, np.repeat(patch, 3)[~left.ravel()], corners[..., 0][~left])
    lit = values[:, 0] > 1e-4
    assert np.all(far[lit] <= near[lit]), np.round(far[lit] / near[lit], 3)
    order = np.lexsort((x, _centres(points, quads)[:, 1]))
    rising = (near[order][1:] > near[order][:-1] * (1 + 1e-9)) & (np.diff(x[order]) > 0) & lit[order][1:]
    assert not rising.any()
    assert any(len(record["rings"]) for record in apply.records)
    parts = np.stack([0.3 * values, 0.7 * values])
    np.testing.assert_allclose(apply(parts).sum(axis=0), corners, rtol=0, atol=1e-12 * corners.max())
    # a channel that does not ring on its own (a gentle ramp) takes the plain average where another
    # rings, so that no patch's colour changes at the border of that zone
    values[:, 2] = 0.5 + 0.01 * x
    corners, apply = surface.corner_values(values, return_filter=True)
    rings = [record["rings"] for record in apply.records]
    assert len(rings[0]) and all(np.array_equal(r, rings[0]) for r in rings[1:])
    np.testing.assert_allclose(surface.corner_means(corners[..., 2].ravel()), values[:, 2], rtol=1e-9)


def test_no_light_anywhere_filters_to_no_light():
    """Every patch 0 with a zero variance (a scene whose light reaches no reflecting patch, such as a
    glowing black floor beside a wall facing away): the filter gives 0s, not NaN (before, the
    variance floor was 1e-12 of the largest value squared, 0 here, and 0 / 0 stopped the run)."""
    points, quads, triangles, patch = _grid(4, 4, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    zeros = np.zeros((len(quads), 3))
    out = smoothing.filter_noise(points, triangles, patch, zeros, zeros)
    assert np.array_equal(out, zeros)


@pytest.mark.parametrize("hits", [0.3, 1.0])
def test_the_noise_filter_moves_no_light_where_hits_are_sparse(hits):
    """Patches of equal light, each estimated from 8 batches of Poisson hits (``hits`` a batch on
    average) with the batch-means variance, as a solve measures it (it grows with the value):
    over seeds the filtered patches' mean equals the raw estimates' mean (both unbiased) within
    Z standard errors of the paired difference."""
    a = _grid(30, 30, (0, 0, 0), (1, 0, 0), (0, 1, 0))
    V, T, TP = _combine(a)
    surface = smoothing.Surface.of(V, T, TP)
    shift, raw_error, filtered_error = [], [], []
    for seed in range(SEEDS):
        batches = np.random.default_rng(400 + seed).poisson(hits, (900, 8)) / hits
        x = batches.mean(axis=1)[:, None] * [1.0, 1.0, 1.0]
        var = (batches.var(axis=1, ddof=1) / 8)[:, None] * [1.0, 1.0, 1.0]
        out = surface.filter_noise(x, var)
        shift.append(out.mean() - x.mean())
        raw_error.append(((x - 1.0) ** 2).mean())
        filtered_error.append(((out - 1.0) ** 2).mean())
    shift = np.array(shift)
    assert abs(shift.mean()) < Z * shift.std(ddof=1) / np.sqrt(SEEDS), shift
    assert np.mean(filtered_error) < np.mean(raw_error)


# ---------------------------------------------------------------------------------------------
# Fixed weights: the whole's filter and corners applied to its parts (each source's light)
# ---------------------------------------------------------------------------------------------

def _lamp_box_parts():
    """A closed box of 4 x 4 patches a face lit by a point lamp near its ceiling and a dim one
    low (bright patches beside dim ones: clips and floors happen), solved with each lamp's light
    apart: (surface, the whole's reflected light and variance, each lamp's (2,P,3))."""
    from boxes import box_rectangles, rectangles_to_mesh

    from addon.core import PatchScene, solve
    from addon.core.lights.lights import PointLight

    origin, u, v, _ = box_rectangles((1, 1, 1), n=4)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = TP.max() + 1
    lamps = [PointLight(np.array([0.4, 0.45, 0.8]), np.array([3.0, 2.4, 1.5]), name="high"),
             PointLight(np.array([0.7, 0.2, 0.15]), np.array([0.2, 0.3, 0.5]), name="low")]
    scene = PatchScene(V, T, TP, np.full(P, 0.6), np.zeros(P), lamps)
    r = solve(scene, paths=20_000, seed=1, per_source=True, threads=2)
    parts = r.per_source.irradiance * scene.reflectivity
    return smoothing.Surface.of(V, T, TP, P), r.reflected, r.reflected_variance, parts


def test_the_noise_filter_with_its_weights_fixed_is_linear_and_its_parts_add_up_to_the_filtered_whole():
    surface, whole, variance, parts = _lamp_box_parts()
    values = np.maximum(whole, 0.0)
    filtered, limit, apply = surface.filter_noise(values, variance, bound=True, return_filter=True)
    # the filtered values are today's, to the bit; the clips were used (a share of the fit's change)
    assert np.array_equal(filtered, surface.filter_noise(values, variance))
    assert np.array_equal(limit, surface.filter_noise(values, variance, bound=True)[1])
    assert (apply.share < 1).any() and (apply.share > 0).any()
    scale = np.abs(filtered).max()
    np.testing.assert_allclose(apply(values), filtered, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(apply(parts).sum(axis=0), filtered, rtol=0, atol=1e-13 * scale)
    rng = np.random.default_rng(2)
    x, y = rng.normal(size=values.shape), rng.normal(size=values.shape)
    np.testing.assert_allclose(apply(2.5 * x - 0.7 * y), 2.5 * apply(x) - 0.7 * apply(y), rtol=0, atol=1e-12)
    # one part alone with weight 1 is the whole: the filter of the whole
    np.testing.assert_allclose(apply(values[None])[0], filtered, rtol=0, atol=1e-13 * scale)
    with pytest.raises(ValueError, match=r"shape \(P, k\)"):
        apply(values[:-1])


def test_the_filtered_light_and_its_corners_add_up_over_parts_with_negative_light_as_none():
    """filter_light (the whole at least 0) then corner_values, each with the whole's weights,
    clips, floors and scales: the parts' corners add up to the whole's, also where the whole is
    negative (a signed estimator's noise) and where corners were floored."""
    surface, whole, variance, parts = _lamp_box_parts()
    shift = 1.3 * whole.min(axis=0)
    signed = whole - shift
    parts = parts - shift / 2  # (two parts: they add up to ``signed``)
    assert (signed < 0).any()
    filtered, apply = surface.filter_light(signed, variance, return_filter=True)
    assert np.array_equal(filtered, surface.filter_noise(np.maximum(signed, 0.0), variance))
    np.testing.assert_allclose(apply(parts).sum(axis=0), filtered, rtol=0, atol=1e-13 * filtered.max())
    corners, corner_apply = surface.corner_values(filtered, return_filter=True)
    assert np.array_equal(corners, surface.corner_values(filtered))
    assert any(len(f) for record in corner_apply.records for f in record["floored"])
    np.testing.assert_allclose(corner_apply(apply(parts)).sum(axis=0), corners, rtol=0, atol=1e-12 * corners.max())
    rng = np.random.default_rng(3)
    x, y = rng.normal(size=filtered.shape), rng.normal(size=filtered.shape)
    np.testing.assert_allclose(corner_apply(x + 3 * y), corner_apply(x) + 3 * corner_apply(y), rtol=0, atol=1e-11)


def test_the_light_arriving_at_black_channels_fills_from_neighbours_linearly():
    """arriving_light: where a channel's reflectivity is 0 the light is the neighbours'; as a
    linear map of the parts it adds up to the whole's, which is what the pipeline shows."""
    surface, _, variance, parts = _lamp_box_parts()
    P = surface.patch_count
    reflectivity = np.full((P, 3), 0.6)
    reflectivity[::3, 1] = 0.0  # green black on a third of the patches
    irradiance = parts.sum(axis=0) / 0.6
    light, apply = surface.arriving_light(irradiance, variance, reflectivity, return_filter=True)
    assert np.array_equal(light, surface.arriving_light(irradiance, variance, reflectivity))
    filled, fill = surface.fill_from_neighbours(irradiance, reflectivity <= 0, return_filter=True)
    assert np.array_equal(filled, surface.fill_from_neighbours(irradiance, reflectivity <= 0))
    assert not np.allclose(filled[::3, 1], irradiance[::3, 1])
    np.testing.assert_allclose(fill(irradiance), filled, rtol=0, atol=1e-13 * filled.max())
    np.testing.assert_allclose(apply(parts / 0.6).sum(axis=0), light, rtol=0, atol=1e-13 * light.max())


@pytest.mark.parametrize("seen", [True, False])
def test_a_partly_buried_patch_keeps_its_light_on_the_part_seen(seen):
    """Slabs that run into each other (``overlap_boxes``: the edge patches half, the corner ones a
    quarter inside a neighbour, their visible parts exact rectangles), with light climbing
    toward the room's corner where they meet (a cove beside a lamp). Each inner patch's mean of
    the smooth light over its visible rectangle (a 64 x 64 midpoint grid) is its value: within
    (1/CELLS + 1/64) of its corners' spread (each visible cell stands for itself by its centre,
    exact but for the cells across a triangle's diagonal, and so does the grid). Held over the
    whole patch instead (``seen=False``, as before), the part seen is 20% too dark, the buried
    part taking its share of the slope."""
    from overlap_boxes import slab_scene, visible_rectangles
    from addon.core.display.covered import seen_parts
    from addon.core.scene.visibility import CELLS

    scene, origin, u, v, inner = slab_scene(0.5, 1.0)
    values = np.exp(-4.0 * np.linalg.norm(origin + 0.5 * (u + v) - 1.0, axis=1))[:, None] * np.array([1.0, 0.8, 0.6])
    parts = seen_parts(scene, scene.triangles, scene.triangle_patch)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count,
                                   **(parts if seen else dict(hidden=parts["hidden"])))
    corners = surface.corner_values(values)[:, :, 0].reshape(-1, 2, 3)  # (P, its two triangles, corners)
    vo, vu, vv = visible_rectangles(origin, u, v)
    grid = (np.arange(64) + 0.5) / 64
    a, b = (x.ravel() for x in np.meshgrid(grid, grid, indexing="ij"))
    rows = np.flatnonzero(inner)
    points = vo[rows, None] + a[:, None] * vu[rows, None] + b[:, None] * vv[rows, None]  # (n, 4096, 3)
    s = np.einsum("npk,nk->np", points - origin[rows, None], u[rows]) / (u[rows] ** 2).sum(1)[:, None]
    t = np.einsum("npk,nk->np", points - origin[rows, None], v[rows]) / (v[rows] ** 2).sum(1)[:, None]
    (c0, c1, c2), (_, c2_, c3) = (corners[rows, k].T[:, :, None] for k in (0, 1))
    # rectangles_to_mesh's triangles: corners (0, 1, 2) where s >= t, (0, 2, 3) where not
    shown = np.where(s >= t, c0 + s * (c1 - c0) + t * (c2 - c1), c0 + s * (c2_ - c3) + t * (c3 - c0)).mean(axis=1)
    spread = np.ptp(corners[rows].reshape(len(rows), -1), axis=1)
    off = np.abs(shown - values[rows, 0]) > (1 / CELLS + 1 / 64) * spread
    assert (scene.geometry.buried.slot[rows] >= 0).sum() == 72
    if seen:
        assert not off.any()
    else:
        assert off.sum() > 20 and (shown / values[rows, 0]).min() < 0.8


def test_the_visible_corner_weights_are_the_same_a_few_cells_at_a_time(monkeypatch):
    """``covered.visible_corner_weights`` locates the visible cells a block of patches at a time:
    blocks of 100 cells give the same weights as one block, and each partly buried patch's
    weights add up to its visible area (f_j times its area)."""
    from overlap_boxes import slab_scene
    from addon.core.display import covered

    scene = slab_scene(0.5, 1.0)[0]
    args = (scene.geometry, scene.vertices, scene.triangles, scene.triangle_patch)
    whole = covered.visible_corner_weights(*args)
    monkeypatch.setattr(covered, "BLOCK", 100)
    assert np.array_equal(covered.visible_corner_weights(*args), whole)
    seen = np.bincount(scene.triangle_patch, weights=whole.sum(axis=1), minlength=scene.patch_count)
    np.testing.assert_allclose(seen, scene.patch_area, rtol=1e-12)


def test_the_lowest_corners_patch_is_the_one_a_stable_sort_finds_ties_and_hidden_patches_included():
    """The patch whose corner is the lowest at each point (what a floor is a share of), found
    without a sort, against the stable sort by (point, value) it replaced: on the folded mesh
    (crease points), values with ties, some patches hidden (inf), the same patch at every corner."""
    from addon.core.mesh.welding import run_starts

    V, T, TP, values = _random_mesh(2)
    values = np.round(values, 1)  # (ties)
    hidden = np.zeros(len(values), bool)
    hidden[::7] = True
    surface = smoothing.Surface.of(V, T, TP, len(values), hidden=hidden)
    corner_patch = np.repeat(TP, 3)
    averaging = surface._averaging()
    point, _, _, crease, local, o = averaging
    assert len(crease) > 0
    for k in range(3):
        x = np.where(hidden[corner_patch], np.inf, values[corner_patch, k])
        order = np.lexsort((x, point))
        first = order[run_starts(point[order])]
        lowest_corner = np.empty(len(surface.smooth_point), np.int64)
        lowest_corner[point[first]] = first
        expected = lowest_corner[point]
        order = np.lexsort((x[o], local))
        first = order[run_starts(local[order])]
        expected[crease[local[first]]] = o[first]
        got = surface._corner_lowest_patch(np.ascontiguousarray(values[:, k]), corner_patch, averaging)
        assert np.array_equal(got, corner_patch[expected])


def test_the_corners_are_made_on_the_local_threads_with_the_same_bits(monkeypatch):
    """The whole's corners a colour channel a thread, its parts' (the fixed-weight maps) a part a
    thread: with two threads both make corners at once (each one's first averaging waits for the
    other's), and the corners, the records and the parts' corners are the same bit for bit as on
    one thread (a channel's and a part's steps are their own); above THREADED_CORNERS corners,
    on the calling thread alone."""
    import threading

    from addon.core.distributed import runners

    V, T, TP, values = _random_mesh(3)
    parts = np.stack([0.25 * values, 0.75 * values, values])
    surface = smoothing.Surface.of(V, T, TP, len(values))
    average, seen, waited, meet = smoothing.Surface._average_corners, set(), set(), threading.Barrier(2, timeout=20)

    def averaged(self, x, averaging):
        ident = threading.get_ident()
        seen.add(ident)
        if threads == 2 and len(waited) < 2 and ident not in waited:  # (the first two threads to average)
            waited.add(ident)
            meet.wait()  # (a second thread that never averages breaks the barrier: the test fails)
        return average(self, x, averaging)

    monkeypatch.setattr(smoothing.Surface, "_average_corners", averaged)
    made = []
    for threads in (1, 2):
        seen.clear()
        with runners.local_threads(threads):
            corners, apply = surface.corner_values(values, return_filter=True)
            made.append((corners, apply(parts, np.float32), apply.records))
        assert (len(seen) == 1) if threads == 1 else (len(seen) >= 2), (threads, len(seen))
    # above THREADED_CORNERS (memory), a channel and a part at a time on the calling thread
    monkeypatch.setattr(smoothing, "THREADED_CORNERS", 3 * len(T) - 1)
    seen.clear()
    threads = 0  # (no barrier)
    with runners.local_threads(2):
        corners, apply = surface.corner_values(values, return_filter=True)
        made.append((corners, apply(parts, np.float32), apply.records))
    assert seen == {threading.get_ident()}
    (one, one_parts, one_records), (two, two_parts, two_records) = made[:2]
    assert np.array_equal(made[2][0], one) and np.array_equal(made[2][1], one_parts)
    assert np.array_equal(one, two) and np.array_equal(one_parts, two_parts) and two_parts.dtype == np.float32
    for a, b in zip(one_records, two_records):
        assert a.keys() == b.keys()
        for key in a:
            same = [np.array_equal(x, y) for x, y in zip(a[key], b[key])] if key == "floored" else [np.array_equal(a[key], b[key])]
            assert all(same), key


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_parts_add_up_to_the_whole_to_its_rounding_and_each_is_its_own_map(dtype):
    """``point_direct.parts_corners``: of three parts (one with negative patches, one the largest), two are
    mapped and the largest is the whole's corners less theirs; each is its own map's value to the
    dtype's rounding, and their sum is the whole's corners to the rounding of the last (the maps
    alone left their sum a few float errors of each part away)."""
    from addon.core.display import point_direct

    points, quads, triangles, patch = _grid(10, 6, (0, 0, 0), (5, 0, 0), (0, 3, 0))
    x = _centres(points, quads)[:, 0]
    rng = np.random.default_rng(4)
    parts = np.stack([np.exp(-x / 1.3)[:, None] * [1.0, 0.7, 0.4], 0.2 + 0.05 * rng.random((len(quads), 3)),
                      0.02 * rng.standard_normal((len(quads), 3))])
    whole_values = parts.sum(axis=0)
    surface = smoothing.Surface.of(points, triangles, patch, len(quads))
    whole, apply = surface.corner_values(whole_values, return_filter=True)
    out = point_direct.parts_corners(whole, apply, parts, dtype)
    assert out.dtype == dtype and out.shape == (3,) + whole.shape
    eps = np.finfo(dtype).eps
    for part, alone in zip(out, apply(parts, np.float64)):
        np.testing.assert_allclose(part, alone, rtol=0, atol=8 * eps * whole.max())
    np.testing.assert_allclose(out.astype(np.float64).sum(axis=0), whole, rtol=0, atol=2 * eps * whole.max())
    assert np.array_equal(point_direct.parts_corners(whole, apply, parts[:1], dtype), apply(parts[:1], dtype))
