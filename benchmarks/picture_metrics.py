"""The picture benchmark's measures, on arrays (numpy only): which pixels are surfaces, the
relative mean absolute error of luminance on them, each object's brightness, the reference's own
error from two independent halves, and where an image's error lies.

Images are (H, W, 3) linear RGB, row 0 at the top; an id image is (H, W) int, -1 for nothing.
"""
from __future__ import annotations

import numpy as np

# Rec. 709 / sRGB primaries, linear light: the luminance Blender's colour management uses.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def luminance(image):
    """(H, W) luminance of (H, W, 3) linear RGB."""
    return np.asarray(image, np.float64) @ LUMINANCE


def dilate(mask, steps=1):
    """``mask`` grown by ``steps`` pixels to its 8 neighbours (a pixel filter's reach)."""
    out = np.asarray(mask, bool).copy()
    for _ in range(steps):
        grown = out.copy()
        grown[1:] |= out[:-1]
        grown[:-1] |= out[1:]
        grown[:, 1:] |= out[:, :-1]
        grown[:, :-1] |= out[:, 1:]
        grown[1:, 1:] |= out[:-1, :-1]
        grown[:-1, :-1] |= out[1:, 1:]
        grown[1:, :-1] |= out[:-1, 1:]
        grown[:-1, 1:] |= out[1:, :-1]
        out = grown
    return out


def surface_mask(object_id, excluded_objects=(), lamp_pixels=None, margin=1):
    """Pixels that show a reflecting surface: an object is seen (id >= 0), not one of
    ``excluded_objects`` (emitters), no lamp in front (``lamp_pixels``), and none of these
    within ``margin`` pixels (Cycles' pixel filter blends a pixel with its neighbours)."""
    object_id = np.asarray(object_id)
    other = (object_id < 0) | np.isin(object_id, list(excluded_objects))
    if lamp_pixels is not None:
        other |= np.asarray(lamp_pixels, bool)
    return ~dilate(other, margin)


def relative_mae(image, reference, mask):
    """Mean absolute luminance error over ``mask`` divided by the reference's mean luminance there."""
    y, r = luminance(image)[mask], luminance(reference)[mask]
    return float(np.abs(y - r).sum() / r.sum())


def reference_variance(first, second):
    """(H, W) unbiased estimate of the variance of the luminance of (first + second) / 2, two
    independent renders of the same expectation: ((Y1 - Y2) / 2)^2."""
    return (0.5 * (luminance(first) - luminance(second))) ** 2


def relative_rms(image, reference, mask, variance=None):
    """Root mean square luminance error over ``mask`` over the reference's mean luminance there;
    with the reference's per-pixel ``variance``, that variance is taken out of the mean square
    (an image whose noise is independent of the reference's: their squared errors add), so the
    result estimates the error against the truth whatever the reference's own noise."""
    y, r = luminance(image)[mask], luminance(reference)[mask]
    square = (y - r) ** 2
    if variance is not None:
        square = square - np.asarray(variance)[mask]
    return float(np.sqrt(max(square.mean(), 0.0)) / r.mean())


def object_means(image, object_id, mask, count):
    """(count, 3) mean RGB of each object's pixels in ``mask`` (NaN for an object not seen)."""
    ids = np.asarray(object_id)[mask]
    values = np.asarray(image, np.float64)[mask]
    pixels = np.bincount(ids, minlength=count).astype(np.float64)
    sums = np.stack([np.bincount(ids, values[:, c], minlength=count) for c in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return sums / pixels[:, None]


def object_pixels(object_id, mask, count):
    return np.bincount(np.asarray(object_id)[mask], minlength=count)


def halves_error(first, second, mask):
    """The relative MAE of the mean of two independent, equally noisy renders against the
    truth, estimated from their difference: (h1 + h2) / 2 - truth has the spread of
    (h1 - h2) / 2 (for noise symmetric about the truth)."""
    mean = 0.5 * (np.asarray(first, np.float64) + np.asarray(second, np.float64))
    d = 0.5 * (luminance(first) - luminance(second))[mask]
    return float(np.abs(d).sum() / luminance(mean)[mask].sum())


def patch_means(image, patch_id, mask):
    """``image`` made flat per patch: each pixel in ``mask`` the mean of its patch's pixels in
    ``mask`` (what exact per-patch values would show at best); the rest left as it is."""
    out = np.array(image, np.float64)
    ids = np.asarray(patch_id)[mask]
    _, inverse = np.unique(ids, return_inverse=True)
    pixels = np.bincount(inverse).astype(np.float64)
    values = out[mask]
    means = np.stack([np.bincount(inverse, values[:, c]) for c in range(3)], axis=1) / pixels[:, None]
    out[mask] = means[inverse]
    return out


def boundaries(ids):
    """Pixels whose 4-neighbour has another id (a step between patches, or objects)."""
    ids = np.asarray(ids)
    out = np.zeros(ids.shape, bool)
    across = ids[1:] != ids[:-1]
    out[1:] |= across
    out[:-1] |= across
    along = ids[:, 1:] != ids[:, :-1]
    out[:, 1:] |= along
    out[:, :-1] |= along
    return out


def error_shares(image, reference, mask, regions, variance=None):
    """For each named region (a boolean image): (share of the surface pixels, share of the
    absolute luminance error, share of the squared error less the reference's ``variance``
    where given), all over ``mask``."""
    difference = luminance(image) - luminance(reference)
    error = np.abs(difference)
    square = difference**2 - (0.0 if variance is None else np.asarray(variance))
    total, total_square, pixels = error[mask].sum(), square[mask].sum(), mask.sum()
    out = {}
    for name, region in regions.items():
        inside = mask & region
        out[name] = (float(inside.sum() / pixels), float(error[inside].sum() / total),
                     float(square[inside].sum() / total_square))
    return out


def exposure_for(reference, mask, grey=0.35):
    """A display exposure in stops mapping the median surface luminance to ``grey`` (the
    product's own preview exposure rule)."""
    return float(np.log2(grey / np.median(luminance(reference)[mask])))


def to_display(image, exposure):
    """(H, W, 3) uint8 sRGB of linear ``image`` at ``exposure`` stops, clipped (Standard view)."""
    x = np.clip(np.asarray(image, np.float64) * 2.0**exposure, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    return (srgb * 255 + 0.5).astype(np.uint8)


def error_display(image, reference, mask, scale=0.5):
    """(H, W, 3) uint8 false colour of |luminance error| over the mean surface luminance
    (black 0, white ``scale`` and above, the metric's weighting); outside ``mask`` dark grey."""
    from matplotlib import colormaps

    mean = luminance(reference)[mask].mean()
    e = np.clip(np.abs(luminance(image) - luminance(reference)) / (scale * mean), 0.0, 1.0)
    out = (colormaps["inferno"](e)[..., :3] * 255 + 0.5).astype(np.uint8)
    out[~mask] = 40
    return out
