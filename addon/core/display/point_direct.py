"""Direct light at the shown mesh's corners: the light's shape inside a patch.

A patch's solved light is its mean over the patch, and the smooth display (``smoothing``)
interpolates means: a lamp's hot spot narrower than a patch, or the edge of the sun's patch
through a window, comes out as wide as the patches. The light straight from a lamp, the sun or
an emitting patch is cheap at a point (a point lamp's or the sun's at a point is one shadow ray,
exact), so the display takes it point by point, as the classic two-pass methods' final gather
does for direct light, and keeps the solve for the rest:

    L = corners(H - M) + D

D the direct light at every corner of the shading triangles (the lamps by ``SAMPLES`` stratified
shadow rays shared among them, each ray to one lamp drawn by what it would give the corner
unoccluded, ``lamp_choice``: the rays do not multiply with the lamps; each sun by as many of
its own; each emitting material's patches by as many samples, each a shadow ray to a point of a
patch chosen by power and nearness and, near them, a cosine ray, weighed by the power heuristic:
``direct_points.emitters_at``), M each patch's
area-weighted mean of D's linear interpolation, H the solved (filtered)
light, and corners() the mean-preserving smooth corner values (``Surface.corner_values``).
Every patch's mean is still its solved
value (float error; ``Surface.corner_values``' own guarantee), or within its slack (two
standard errors) where the caller gives it (``slack``: a patch the solve's noise set apart
shows its neighbours' continuous light, not a square of its own), so the display moves no
light beyond the solve's noise; what D adds is the light's shape within the patch.
The sky stays in H - M (soft light, which a point estimate would need many rays for).

Beside an emitter a corner's light is heavy-tailed: a corner whose standard error (measured on
pairs of neighbouring strata where a sample draws one of several lamps or emitting patches:
``sample_rounds.paired_error``) passes NOISE_SHARE of its patch's brightest corner's light (or
of the patch's solved light where that is more: noise beside more light is not seen) is sampled again with MORE_SAMPLES times the
samples (RETRIES times). (Giving up on the patches still above it, their smooth display beside
their neighbours' shaped one, drew blocks on the Cornell box's walls by its light.) Where M
passes H (the interpolation of a peak above its mean, or the solve's noise) the patch's D is
scaled down to H, its shape kept: H - M is never negative, and the display one smoothing of it
(the negative part smoothed apart had spread below black and cost a third smoothing's memory);
where M passes OVERSHOOT times H (a corner a centimetre from an emitter) it shows corners(H)
alone.

With live lamps (``light_corners``) the renderer draws the lamps', suns', emitting materials' and
the world's own light pixel by pixel, and the light shown is H less each patch's mean of it
(``live_sources``), smooth.

A corner is evaluated a hundredth of the way from its point towards its patch's centre (inside
the patch: a point on the edge shared with a wall standing on it would graze the wall); the
corners at a flat surface's inner point, clear of anything else, share one evaluation
(``shared_corners``: one light there, half the shadow rays). A corner inside another object (a
floor's corner under a box; ``visibility.buried_at``) takes the mean of its patch's corners that
are not: the camera never sees it, and a dark corner would spread a dark rim onto the visible part.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np

from .direct_points import Points, chosen_lamps, emitting, sky_at
from ..lights.lamp_choice import LampChoice
from ..lights.lights import SunLight, WorldLight
from ..names import EXIT_RANDOM, FINITE
from .sample_rounds import Part, rounds, sampled
from .shared_corners import shared_rows
from ..methods.tables import WalkTables
from ..scene.visibility import buried_at

SAMPLES = 16  # shadow rays a corner, for the lamps (a group's) and per emitting material
MORE_SAMPLES = 8  # times the samples where a corner's light is noisier than NOISE_SHARE
RETRIES = 2  # (16, 128, 1,024 samples)
NOISE_SHARE = 0.04  # of the light of the patch's brightest corner: a standard error the eye would see
OVERSHOOT = 2.0  # a patch's direct light's interpolated mean over its solved light beyond which it is not shown
INWARD = 0.01  # of the way from a corner to its patch's centre

# Sobol' dimensions of a corner's sample: a point of a lamp (2, read as u[3:5]), an emitting
# patch (u[5]) and a point of it (u[6:9]).
DIMENSIONS = (0, 1, 2, 3, 4, 5, 6, 7, 8)


@dataclass
class CornerDirect:
    """Direct light at the corners of the shading triangles: ``corners`` (T,3,3) (or (G,T,3,3)
    per source group), and each patch's mean of its linear interpolation ``means`` (P,3) (or
    (G,P,3))."""

    corners: np.ndarray
    means: np.ndarray


def corner_direct(surface, scene, triangles, samples=SAMPLES, seed=0, light_group=None, patch_group=None, groups=0,
                  deadline=None, light=None):
    """The direct light (``CornerDirect``; None where ``has_direct`` is not) at the corners of
    ``triangles`` (T,3) (of ``scene.vertices``; ``surface`` is ``smoothing.Surface.of`` them)
    from every lamp and sun and emitting patch of ``scene``. Given
    ``groups`` > 0, ``light_group`` (L,) the group of each light and ``patch_group`` (P,) of
    each emitting patch: each group's light apart, its lamps drawn among themselves (their sum
    is the whole's light; the whole's own draws all its lamps at once). ``deadline`` (a
    ``time.perf_counter()`` reading): the noisy corners sampled again as time allows
    (``sample_rounds``). ``light`` (P,3): each patch's solved light, which a corner's noise is
    also measured against (a source's noise beside much more light is not seen)."""
    if not has_direct(scene):
        return None
    P = scene.patch_count
    keys, first, corner_key = np.unique(surface.point.ravel().astype(np.int64) * P + np.repeat(surface.triangle_patch, 3),
                                        return_index=True, return_inverse=True)
    patch = keys % P
    position = scene.vertices[np.asarray(triangles).ravel()[first]]
    del first
    # (a flat surface's inner points one evaluation each, which their corners share: shared_corners)
    rows, read, towards = shared_rows(surface, scene.geometry, keys // P, patch, position, INWARD)
    del keys
    value = points_direct(surface, scene, position[rows], patch[rows], samples, seed, light_group, patch_group, groups,
                          deadline, light, towards=towards)
    corners = value[..., read[corner_key.ravel()], :].reshape(value.shape[:-2] + (-1, 3, 3))
    return CornerDirect(corners, patch_means(surface, corners))


def points_direct(surface, scene, position, patch, samples=SAMPLES, seed=0, light_group=None, patch_group=None, groups=0,
                  deadline=None, light=None, retries=None, towards=None):
    """([G,]n,3) the direct light at the points ``position`` (n,3, moved in place: INWARD, towards
    ``towards`` (n,3), by default their patches' centres) of ``patch`` (n,), as ``corner_direct``
    takes it at corners (float32 without groups), the noisy ones sampled again ``retries`` times
    (None: RETRIES)."""
    # (in place: four (n,3) temporaries were most of this stage's memory)
    towards = surface.patch_centroid[patch] if towards is None else np.array(towards, np.float64)
    towards -= position
    towards *= INWARD
    position += towards
    del towards
    shown = None if light is None else np.asarray(light).sum(axis=1)[patch]
    value = direct_at(scene, position, patch, samples, seed, light_group, patch_group, groups, deadline, shown=shown,
                      retries=retries)
    _fill_buried(scene.geometry, position, patch, value)
    if not groups:  # (the whole's corners as written, float32: the memory of the largest scenes)
        value = value.astype(np.float32)
    return value


def has_direct(scene):
    """Whether ``scene`` has a lamp or a sun or an emitting patch (the sky alone stays smooth)."""
    return bool(scene.emission.any()) or has_lamps(scene)


def has_lamps(scene):
    """Whether ``scene`` has a lamp or a sun (a light other than the world)."""
    return any(not isinstance(light, WorldLight) for light in scene.lights.lights)


def patch_means(surface, corners):
    """([G,]P,3) each patch's area-weighted mean of the linear interpolation of ``corners``
    ([G,]T,3,3)."""
    if corners.ndim == 4:
        return np.stack([patch_means(surface, part) for part in corners])
    return np.stack([surface.corner_means(np.ascontiguousarray(corners[:, :, c], dtype=np.float64).ravel())
                     for c in range(3)], axis=1)


def _unit_points(g, position, patch):
    """(3,n) unit-space points of world ``position`` (n,3) of ``patch``, in its region's frame."""
    unit = (position - g.centre) / g.diagonal
    if g.regions is not None:
        unit -= g.regions.centre[g.regions.of(patch)]
    return unit.T


class _Corners:
    """A block of corners as ``adaptive_light``'s lamps and emitters read sample points: unit-space
    origins (pushed off), normals, offsets, surface points and world positions; ``anchor`` and
    ``local`` as ``direct_points.Points``'."""

    def __init__(self, g, rows, surface_unit, world, anchor=None, local=None):
        self.rows, self.anchor, self.local = rows, anchor, local
        self.normal = g.patch_normal_rows.take(rows, axis=1).astype(np.float64)
        self.offset = g.ray_offsets(rows, np.float64)
        self.surface = surface_unit
        self.x = surface_unit + self.normal * self.offset
        self.world = world

    def offset_of(self, live):
        return self.offset[live] if np.ndim(self.offset) else self.offset


def light_sources(scene, light_group, patch_group, groups, sky=False, lamps_only=False):
    """[(group, add, paired)] each group's lamps, one of them drawn for each sample by what they
    would give its point (``lamp_choice``; each sun apart: ``_lamp_sources``), each emitting group (and each world:
    ``sky``) as ``add(tables, points, u, value)`` adds its light at sample points
    (``adaptive_light``), in the order of the lights; ``paired``: a choice among lamps or
    emitting patches, whose error is measured on pairs of its strata (``sample_rounds.sampled``).
    ``lamps_only``: the lamps and suns alone (no emitting group, no world)."""
    power = scene.patch_area * scene.emission.mean(axis=1)
    emitter_group = np.zeros(scene.patch_count, np.int64) if not groups else np.asarray(patch_group, np.int64)
    parts, lamps = [], {}
    for k, light in enumerate(scene.lights.lights):
        group = int(light_group[k]) if groups else 0
        if isinstance(light, WorldLight):
            if sky:
                parts.append((group, partial(sky_at, worlds=[light]), False))
            continue
        if group not in lamps:  # (a group's lamps one source, where its first lamp is)
            lamps[group] = []
            parts.append((group, lamps[group], None))
        lamps[group].append(light)
    parts = [part for group, add, paired in parts
             for part in (_lamplight_sources(group, add) if paired is None else [(group, add, paired)])]
    for group in ([] if lamps_only else np.unique(emitter_group[power > 0])):
        mine = np.where(emitter_group == group, power, 0.0)
        parts.append((group, emitting(scene, mine), True))
    return parts


def _lamplight_sources(group, lamps):
    """[(group, add, paired)] a group's lamps: each sun a source of its own (its light is seldom
    what it would be unoccluded: through a window, most corners of a room see none of it; drawn
    with the lamps it took their samples: 2.6x the rays in the window room), the other lamps one
    source, a lamp drawn for each sample (``lamp_choice``)."""
    placed = [light for light in lamps if not isinstance(light, SunLight)]
    out = []
    for light in lamps:
        if isinstance(light, SunLight) or len(placed) == 1:
            out.append((group, partial(chosen_lamps, choice=LampChoice([light])), False))
        elif light is placed[0]:
            out.append((group, partial(chosen_lamps, choice=LampChoice(placed)), True))
    return out


def direct_at(scene, position, patch, samples, seed, light_group, patch_group, groups, deadline=None, spent=None,
              shown=None, retries=None):
    """([G,]n,3) the direct light at world points ``position`` (n,3) of ``patch`` (n,), each
    group's lamps and each emitting group apart (``_part_at``), added up into its group's row;
    retries within ``deadline`` (``sample_rounds``), of the points noisy beside ``shown`` (n,) too."""
    tables = WalkTables(scene, FINITE, 1e-3, EXIT_RANDOM)
    out = np.zeros((max(groups, 1), len(patch), 3))
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(1 << 28,))))
    sources = light_sources(scene, light_group, patch_group, groups)
    with tables.numpy_turn:
        parts = [_part_at(tables, position, patch, rng, add, paired, shown) for _, add, paired in sources]
        means = rounds(parts, len(patch), samples, RETRIES if retries is None else retries, MORE_SAMPLES, deadline, spent)
    for (group, _, _), mean in zip(sources, means):
        out[group] += mean
    return out if groups else out[0]


def _part_at(tables, position, patch, rng, add, paired=False, shown=None):
    """The ``sample_rounds.Part`` of one group's lamps or one emitting group
    (``add(tables, points, u, value)``) at the points: a corner is noisy where its standard
    error passes NOISE_SHARE of its patch's brightest corner's light (beside an emitter the
    light is heavy-tailed), or of the light ``shown`` (n,) at it where that is more."""
    g = tables.geometry

    def sample(rows, count):
        def points(block, local, u):
            at = rows[block]
            unit = _unit_points(g, position[at], patch[at])[:, local]
            anchor = (position[at], g.patch_normal_rows.take(patch[at], axis=1).T.astype(np.float64), 0.0)
            return _Corners(g, patch[at][local], unit, position[at].T[:, local], anchor, local)
        return sampled(tables, len(rows), count, rng, add, points, DIMENSIONS, np.float32, paired)  # (as shown)

    def noise(value, error):
        grey = value.sum(axis=1)
        brightest = np.zeros(patch.max(initial=0) + 1)
        np.maximum.at(brightest, patch, grey)
        allowed = NOISE_SHARE * (brightest[patch] if shown is None else np.maximum(brightest[patch], shown))
        return np.divide(error, allowed, out=np.where(error > 0, np.inf, 0.0), where=allowed > 0)

    return Part(sample, noise)


def inside_other(g, position, patch):
    """(n,) bool: whether each world point ``position`` (n,3) of ``patch`` (n,) lies inside another
    object (``visibility.buried_at``, a ray offset off its patch)."""
    out = np.zeros(len(patch), bool)
    if g.buried is None:
        return out
    candidates = np.flatnonzero(np.isin(patch, np.concatenate([g.buried.patch, g.buried.whole])))
    if candidates.size:
        rows = patch[candidates]
        pushed = _unit_points(g, position[candidates], rows) + g.patch_normal_rows.take(rows, axis=1) * g.ray_offsets(rows, np.float64)
        out[candidates[buried_at(g, pushed, rows)]] = True
    return out


def _fill_buried(g, position, patch, value):
    """Gives each corner inside another object (``inside_other``) the mean of its patch's
    corners that are not (0 where none is), in place; ``value`` ([G,]n,3)."""
    inside = np.flatnonzero(inside_other(g, position, patch))
    if not inside.size:
        return
    seen = np.ones(len(patch), bool)
    seen[inside] = False
    count = np.bincount(patch, weights=seen, minlength=g.patch_count)
    for part in value.reshape((-1,) + value.shape[-2:]):
        for c in range(3):
            total = np.bincount(patch, weights=part[:, c] * seen, minlength=g.patch_count)
            part[inside, c] = np.divide(total, count, out=np.zeros_like(total), where=count > 0)[patch[inside]]


def scaled(surface, direct, factor, in_place=False):
    """``direct`` times per-patch ``factor`` (P,3) (a reflectivity: the reflected light's share);
    ``in_place``: ``direct`` itself, changed (the memory of a copy)."""
    if not in_place:
        return CornerDirect(direct.corners * factor[surface.triangle_patch][:, None, :], direct.means * factor)
    direct.corners *= factor[surface.triangle_patch][:, None, :]
    direct.means *= factor
    return direct


def shown(surface, values, direct, parts=None, part_direct=None, dtype=np.float64, slack=None):
    """(T,3,3) the corners shown for per-patch ``values`` (P,3) whose direct part is ``direct``
    (None: ``Surface.corner_values`` alone): corners(values - M) + D (the module's docstring),
    D scaled on the patches where M passes the value (``_fitted``); ``slack`` (P,3): how far
    each patch's mean may stay from ``values`` (``slack.slack_of``; None: exact). With ``parts`` (S,P,3), each
    group's values as linear maps of the whole's make them (adding up to ``values``: the largest the
    whole less the others, ``parts_corners``), and
    ``part_direct`` their CornerDirect, also (S,T,3,3) each group's corners, adding up to the
    whole's. Made in float64, given as ``dtype`` (the parts; the whole too where there are none:
    float32, as they are written, half the memory)."""
    maps = parts is not None
    if direct is None:
        if not maps:
            return surface.corner_values(values, dtype=dtype, slack=slack)
        whole, apply = surface.corner_values(values, return_filter=True, slack=slack)
        return whole, parts_corners(whole, apply, parts, dtype)
    scale = _fitted(values, direct.means)
    shown_corners, apply = surface.corner_values(values - direct.means * scale, return_filter=True, slack=slack) if maps \
        else (surface.corner_values(values - direct.means * scale, dtype=dtype, slack=slack), None)
    each = parts_corners(shown_corners, apply, parts - part_direct.means * scale, dtype) if maps else None
    _add_kept(shown_corners, direct.corners, scale, surface.triangle_patch)
    if not maps:
        return shown_corners
    for part, corners in zip(each, part_direct.corners):
        _add_kept(part, corners, scale, surface.triangle_patch)
    return shown_corners, each


def parts_corners(whole, apply, parts, dtype=np.float64):
    """(S,T,3,k) the corners of ``parts`` (S,P,k), which add up to the values whose corners are
    ``whole`` (T,3,k, float64) and whose ``apply`` (a ``LinearCorners``, or a map of one) is given:
    every part but the largest mapped, given as ``dtype``, and the largest the whole less their sum
    as given, so that the parts add up to the whole to its own rounding (one map fewer; mapped alone it
    would be the same to float error)."""
    parts = np.asarray(parts)
    if len(parts) < 2:
        return apply(parts, dtype)
    last = int(np.argmax(np.abs(parts).reshape(len(parts), -1).sum(axis=1)))
    others = np.flatnonzero(np.arange(len(parts)) != last)
    mapped = apply(parts[others], dtype)
    out = np.empty((len(parts),) + mapped.shape[1:], dtype)
    out[others] = mapped
    rest = np.array(whole, np.float64)  # (a copy: the whole is the caller's)
    for part in mapped:
        rest -= part
    out[last] = rest
    return out


def _fitted(values, means):
    """(P,3) each patch's scale of its direct light: 1, or its value over its direct light's
    interpolated mean where that is more (the shape kept, the mean the patch's: nothing of the
    rest below 0), 0 where the mean passes OVERSHOOT times the value."""
    scale = np.divide(values, means, out=np.ones_like(values), where=means > values)
    scale[(means > OVERSHOOT * values).any(axis=1)] = 0.0
    return scale


def _add_kept(out, corners, scale, triangle_patch, block=1 << 16):
    """``out`` (T,3,3) += ``corners`` (T,3,3) times their patch's ``scale`` (P,3), a block of
    triangles at a time (a scaled copy of the corners was the largest array of the smoothing)."""
    if (scale == 1).all():
        out += corners
        return
    for start in range(0, len(corners), block):
        rows = slice(start, start + block)
        out[rows] += corners[rows] * scale[triangle_patch[rows]][:, None, :]


def light_corners(surface, scene, light, direct, live=False, dtype=np.float64, slack=None):
    """(T,3,3) the light arriving ``light`` (``arriving``) shown at the corners with the direct
    light's shape (``shown``, given as ``dtype``; ``direct`` the CornerDirect of every source;
    ``slack`` its standard errors); ``live``: smooth alone (the renderer draws every lamp's, sun's,
    emitter's and the world's own light)."""
    return shown(surface, light, None if live else direct, dtype=dtype, slack=slack)
