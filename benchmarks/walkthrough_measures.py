"""The walkthrough's numbers, on arrays (numpy only): Cycles' samples for a share of the solve's
time, and each picture's error against the reference view by view and over the whole walk.

A view's numbers are sums (luminance of the picture and the reference over the surface pixels,
their absolute and squared differences, per object), so that the walk's numbers are ratios of
sums over every view: each surface pixel of the walk weighs the same.
"""
from __future__ import annotations

import numpy as np

from benchmarks import picture_metrics as pm

LEAST_VIEW_PIXELS = 100  # an object's pixels in a view before its brightness there is reported
LEAST_WALK_PIXELS = 500  # ... over the walk


# --------------------------------------------------------------------------- Cycles at the solve's time

def line_through(line, samples, wall):
    """The time line (seconds of 1 sample, seconds a further sample) scaled to pass through the
    last render measured (``samples`` took ``wall``): a machine shared with other work runs every
    part of a render slower or faster alike, and the fixed part (syncing the scene, the
    denoiser) is most of a render at a few samples, so it is kept in proportion."""
    first, per_sample = line
    scale = wall / max(first + (samples - 1) * per_sample, 1e-9)
    return (first * scale, per_sample * scale)


def samples_within(seconds, line, most=1 << 16):
    """The samples whose render takes ``seconds`` on ``line``: at least 1, at most ``most``."""
    first, per_sample = line
    return int(min(max(1, round(1 + (seconds - first) / max(per_sample, 1e-6))), most))


def next_samples(total, spent, views_left, line, last=None, most=1 << 16):
    """Samples for the next view, so that the views left share what is left of ``total`` seconds
    (``spent`` so far), on the timing ``line`` moved through the ``last`` (samples, wall) render."""
    if last is not None:
        line = line_through(line, *last)
    return samples_within(max(total - spent, 0.0) / max(views_left, 1), line, most)


# --------------------------------------------------------------------------- the solve's own noise

def object_noise(objects):
    """Each object's own noise in the solve: the standard deviation of its area-weighted mean light
    over that mean, from its patches' measured variances (the patches' errors taken as independent,
    the channels as moving together), a dict name -> float. ``objects``: (name, area (P,),
    radiosity (P,3), variance (P,3)) of each object. A small dim object's light is noisier than the
    solve's error over the scene says: its brightness in a picture is known no better than this."""
    out = {}
    for name, area, radiosity, variance in objects:
        area = np.asarray(area, np.float64)
        mean = float(np.sum(area * np.asarray(radiosity, np.float64).mean(axis=1)))
        sd = np.sqrt(np.maximum(np.asarray(variance, np.float64), 0.0)).mean(axis=1)
        out[name] = float(np.sqrt(np.sum((area * sd) ** 2)) / mean) if mean > 0 else float("nan")
    return out


# --------------------------------------------------------------------------- a view's numbers

def view_sums(image, first, second, object_id, mask, count):
    """The sums of one picture in one view against the reference (the mean of ``first`` and
    ``second``, its two independent halves) over ``mask``: a dict of floats and per-object lists
    (``count`` objects)."""
    ref = 0.5 * (np.asarray(first, np.float64) + np.asarray(second, np.float64))
    y, r = pm.luminance(image)[mask], pm.luminance(ref)[mask]
    variance = pm.reference_variance(first, second)[mask]
    ids = np.asarray(object_id)[mask]
    halves = [np.bincount(ids, pm.luminance(h)[mask], minlength=count).tolist() for h in (first, second)]
    return {"pixels": int(mask.sum()), "picture": float(y.sum()), "reference": float(r.sum()),
            "absolute": float(np.abs(y - r).sum()), "square": float(((y - r) ** 2).sum()), "variance": float(variance.sum()),
            "object_pixels": np.bincount(ids, minlength=count).tolist(),
            "object_picture": np.bincount(ids, y, minlength=count).tolist(),
            "object_reference": np.bincount(ids, r, minlength=count).tolist(),
            "object_first": halves[0], "object_second": halves[1]}


def reference_sums(first, second, mask):
    """The reference's own error, from its halves: sum of |(Y1 - Y2) / 2| and of Y over ``mask``
    (``picture_metrics.halves_error`` as sums)."""
    ref = 0.5 * (np.asarray(first, np.float64) + np.asarray(second, np.float64))
    d = 0.5 * (pm.luminance(first) - pm.luminance(second))[mask]
    return {"absolute": float(np.abs(d).sum()), "reference": float(pm.luminance(ref)[mask].sum())}


def numbers(sums, names, least):
    """Error, RMS error with the reference's noise out, brightness and the worst object (at least
    ``least`` pixels) of one view's or several views' summed ``sums``; per object its brightness,
    pixels and the reference's own uncertainty there (half its halves' difference over their mean)."""
    pixels = np.asarray(sums["object_pixels"], float)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.asarray(sums["object_picture"]) / np.asarray(sums["object_reference"])
        first, second = np.asarray(sums["object_first"]), np.asarray(sums["object_second"])
        spread = np.abs(first - second) / (first + second)
    seen = np.flatnonzero((pixels >= least) & np.isfinite(ratio))
    mean_ref = sums["reference"] / max(sums["pixels"], 1)
    square = max(sums["square"] - sums["variance"], 0.0) / max(sums["pixels"], 1)
    worst = max(seen, key=lambda i: abs(ratio[i] - 1.0)) if len(seen) else None
    return {"error": sums["absolute"] / sums["reference"], "rms": float(np.sqrt(square)) / mean_ref,
            "brightness": sums["picture"] / sums["reference"],
            "worst": None if worst is None else [names[worst], float(ratio[worst])],
            "objects": {names[i]: [float(ratio[i]), int(pixels[i]), float(spread[i])] for i in seen}}


def added(views):
    """The element-wise sum of several views' ``view_sums`` (or ``reference_sums``)."""
    out = {}
    for sums in views:
        for key, value in sums.items():
            if isinstance(value, list):
                out[key] = (np.asarray(out.get(key, 0.0)) + np.asarray(value)).tolist()
            else:
                out[key] = out.get(key, 0) + value
    return out


def walk_numbers(kind_views, names):
    """Per view and over the walk: ``numbers`` of each view's sums, then of their sum."""
    return {"views": [numbers(s, names, LEAST_VIEW_PIXELS) for s in kind_views],
            "walk": numbers(added(kind_views), names, LEAST_WALK_PIXELS)}


def reference_error(views):
    """Per view and over the walk: the reference's own relative mean absolute error."""
    return {"views": [s["absolute"] / s["reference"] for s in views],
            "walk": (lambda s: s["absolute"] / s["reference"])(added(views))}
