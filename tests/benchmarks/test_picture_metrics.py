"""The picture benchmark's measures on synthetic images with known answers (numpy only)."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from benchmarks import picture_metrics as pm
from benchmarks.picture import camera_rays, lamp_distances


def grey(values):
    """(H, W, 3) image whose every channel, hence luminance, is ``values``."""
    values = np.asarray(values, np.float64)
    return np.repeat(values[..., None], 3, axis=-1)


def test_luminance_weighs_the_primaries_as_rec709():
    image = np.array([[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 1.0, 1.0]]])
    assert np.allclose(pm.luminance(image), [[0.2126, 0.7152, 0.0722, 1.0]])


def test_dilate_grows_by_one_pixel_a_step_and_stops_at_the_border():
    mask = np.zeros((7, 7), bool)
    mask[3, 3] = True
    assert pm.dilate(mask, 1).sum() == 9 and pm.dilate(mask, 1)[2:5, 2:5].all()
    assert pm.dilate(mask, 2).sum() == 25
    corner = np.zeros((4, 4), bool)
    corner[0, 0] = True
    assert pm.dilate(corner).sum() == 4


def test_surface_mask_leaves_out_background_emitters_lamps_and_their_neighbours():
    ids = np.zeros((6, 8), int)
    ids[:, 0] = -1       # background column
    ids[:, 6:] = 2       # an emitter
    lamp = np.zeros(ids.shape, bool)
    lamp[0, 3] = True
    mask = pm.surface_mask(ids, excluded_objects=[2], lamp_pixels=lamp)
    expected = np.ones(ids.shape, bool)
    expected[:, :2] = False          # background and the column beside it
    expected[:, 5:] = False          # emitter and the column beside it
    expected[0:2, 2:5] = False       # the lamp pixel and its 8 neighbours
    assert np.array_equal(mask, expected)
    assert np.array_equal(pm.surface_mask(ids, [2], lamp, margin=0), (ids >= 0) & (ids != 2) & ~lamp)


def test_relative_mae_counts_only_the_mask():
    reference = grey(np.full((10, 10), 2.0))
    image = reference.copy()
    mask = np.zeros((10, 10), bool)
    mask[:, :6] = True
    image[:, :3] += 0.4            # half of the masked pixels 0.4 too bright
    image[:, 8:] = 100.0           # outside the mask: ignored
    assert pm.relative_mae(image, reference, mask) == pytest.approx(0.5 * 0.4 / 2.0)


def test_halves_error_is_half_the_halves_difference():
    rng = np.random.default_rng(1)
    truth = rng.uniform(0.5, 2.0, (20, 30))
    noise = rng.normal(0.0, 0.1, truth.shape)
    mask = np.ones(truth.shape, bool)
    expected = np.abs(noise).sum() / truth.sum()  # (h1 + h2) / 2 = truth, (h1 - h2) / 2 = noise
    assert pm.halves_error(grey(truth + noise), grey(truth - noise), mask) == pytest.approx(expected)


def test_relative_rms_with_the_reference_variance_estimates_the_error_against_the_truth():
    rng = np.random.default_rng(7)
    shape = (400, 500)
    truth = rng.uniform(0.5, 1.5, shape)
    sigma_reference, sigma_image = 0.3, 0.1  # a reference noisier than the image measured
    first = truth + rng.normal(0.0, sigma_reference, shape)
    second = truth + rng.normal(0.0, sigma_reference, shape)
    reference = 0.5 * (first + second)
    image = truth + rng.normal(0.0, sigma_image, shape)
    mask = np.ones(shape, bool)
    variance = pm.reference_variance(grey(first), grey(second))
    corrected = pm.relative_rms(grey(image), grey(reference), mask, variance)
    raw = pm.relative_rms(grey(image), grey(reference), mask)
    mean, n = truth.mean(), truth.size
    # per pixel (e - r)^2 - d^2 with e ~ N(0, si^2), r, d ~ N(0, sr^2 / 2) independent
    var_q = 2 * (sigma_image**2 + sigma_reference**2 / 2) ** 2 + 2 * (sigma_reference**2 / 2) ** 2
    se = math.sqrt(var_q / n) / (2 * sigma_image) / mean  # delta method for the square root
    assert abs(corrected - sigma_image / mean) < 4 * se
    assert raw == pytest.approx(math.sqrt(sigma_image**2 + sigma_reference**2 / 2) / mean, rel=0.02)
    assert raw - corrected > 50 * se  # without the correction the reference's noise dominates


def test_object_means_average_each_objects_masked_pixels():
    ids = np.array([[0, 0, 1, 1], [0, 0, 1, 1]])
    image = np.zeros((2, 4, 3))
    image[..., 0] = [[1, 3, 10, 20], [5, 7, 30, 1000]]
    image[..., 2] = 2.0
    mask = np.ones(ids.shape, bool)
    mask[1, 3] = False  # the outlier is not a surface pixel
    means = pm.object_means(image, ids, mask, 3)
    assert np.allclose(means[0], [4.0, 0.0, 2.0]) and np.allclose(means[1], [20.0, 0.0, 2.0])
    assert np.isnan(means[2]).all()
    assert list(pm.object_pixels(ids, mask, 3)) == [4, 3, 0]


def test_patch_means_flatten_each_patch_and_leave_the_rest():
    patch = np.array([[0, 0, 1, 1, -1]])
    image = grey([[1.0, 3.0, 10.0, 30.0, 7.0]])
    mask = patch >= 0
    flat = pm.patch_means(image, patch, mask)
    assert np.allclose(flat[..., 1], [[2.0, 2.0, 20.0, 20.0, 7.0]])


def test_boundaries_mark_both_sides_of_a_step():
    ids = np.zeros((3, 6), int)
    ids[:, 3:] = 1
    b = pm.boundaries(ids)
    assert np.array_equal(np.flatnonzero(b[0]), [2, 3]) and b[:, 2:4].all() and b.sum() == 6


def test_error_shares_of_a_partition_sum_to_one_and_take_the_variance_out():
    reference = grey(np.full((4, 4), 1.0))
    image = reference.copy()
    image[:2] += 0.2   # top half: error 0.2 a pixel
    image[2:] += 0.1   # bottom half: 0.1
    mask = np.ones((4, 4), bool)
    top = np.zeros((4, 4), bool)
    top[:2] = True
    variance = np.where(top, 0.0, 0.01)  # all of the bottom's squared error is the reference's noise
    shares = pm.error_shares(image, reference, mask, {"top": top, "bottom": ~top}, variance)
    assert shares["top"][0] == pytest.approx(0.5)
    assert shares["top"][1] == pytest.approx(2 / 3) and shares["bottom"][1] == pytest.approx(1 / 3)
    assert shares["top"][2] == pytest.approx(1.0) and shares["bottom"][2] == pytest.approx(0.0, abs=1e-12)


def test_display_maps_linear_light_to_srgb_bytes_at_an_exposure():
    image = grey([[0.0, 0.18, 0.5, 1.0, 4.0]])
    assert list(pm.to_display(image, 0.0)[0, :, 0]) == [0, 118, 188, 255, 255]
    assert pm.to_display(image, 1.0)[0, 2, 0] == 255
    mask = np.ones((1, 5), bool)
    assert pm.exposure_for(image, mask) == pytest.approx(math.log2(0.35 / 0.5))


def test_camera_rays_go_through_the_pixel_centres_of_a_perspective_camera():
    camera = SimpleNamespace(data=SimpleNamespace(sensor_width=36.0, lens=18.0), matrix_world=np.eye(4))
    origins, directions = camera_rays(camera, 4, 2)
    d = directions.reshape(2, 4, 3)
    slope = d[..., :2] / -d[..., 2:]
    half = 18.0 / 18.0  # tan of half the horizontal field of view: sensor / 2 over lens
    assert np.allclose(slope[0, :, 0], [-0.75 * half, -0.25 * half, 0.25 * half, 0.75 * half])
    assert np.allclose(slope[:, 0, 1], [0.25 * half, -0.25 * half])  # 4:2 -> half the height; row 0 at the top
    assert np.allclose(np.linalg.norm(directions, axis=1), 1.0) and np.allclose(origins, 0.0)


def test_lamp_distances_see_a_point_lamps_sphere_and_an_area_lamps_square():
    origins = np.zeros((3, 3))
    directions = np.array([[0.0, 0.0, -1.0], [0.0, 0.6, -0.8], [0.0, 1.0, 0.0]])
    point = SimpleNamespace(data=SimpleNamespace(type="POINT", shadow_soft_size=0.5), matrix_world=np.array(
        [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -3.0], [0, 0, 0, 1]]))
    t = lamp_distances([point], origins, directions)
    assert t[0] == pytest.approx(2.5) and np.isinf(t[1:]).all()
    area = SimpleNamespace(data=SimpleNamespace(type="AREA", shape="SQUARE", size=1.0, size_y=1.0), matrix_world=np.array(
        [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -2.0], [0, 0, 0, 1]], float))
    t = lamp_distances([area], origins, directions)
    assert t[0] == pytest.approx(2.0) and np.isinf(t[1:]).all()  # 0.6 / 0.8 * 2 = 1.5 > 0.5: outside
