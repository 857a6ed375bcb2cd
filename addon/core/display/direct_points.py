"""The direct light at sample points of patches by shadow rays, source by source: every lamp and
sun (``lamps_at``), one lamp drawn by what it gives (``chosen_lamps``), the sky along a cosine ray
(``sky_at``), the emitting patches by a shadow ray and a cosine ray (``emitters_at``). The
display's direct light at corners (``display.point_direct``) and the Detail's refinement
(``refine.adaptive_light``) read them; the first shot (``first_shot``) traces their rays."""
from __future__ import annotations

import hashlib
import weakref
from functools import partial

import numpy as np

from ..lights.sampling import SourceTable, add_sphere_points, patch_point_rows
from ..lights.near_choice import NearChoice, patch_centres
from ..methods.first_shot import COSINE_SHARE_LEAST, SEEN_BEFORE, trace

# Sobol' dimensions of a sample: its point on the patch (2) and triangle (1), a point of a light,
# a direction of the sky or an emitters' cosine ray (2), an emitting patch (1) and its point (3).
SAMPLE_DIMENSIONS = (0, 1, 7, 2, 3, 4, 5, 6, 8)
_EMITTING = weakref.WeakKeyDictionary()  # scene -> {power's digest: (NearChoice or None, cosine shares)}
# A patch's chance of casting a cosine ray towards emitting patches: this many times its bounded
# form factor to the nearest (cosine_shares), where patches x emitting patches are at most this
# many (more: the least chance everywhere, as the solve's gathering takes them by their area).
NEAREST_SHARE = 3.0
NEAREST_PAIRS = 1 << 24


class Points:
    """A block of sample points of patches ``rows``: unit-space origins (pushed off), normals,
    offsets, surface points and their world positions; ``anchor`` (world points (k,3), their
    normals (k,3), the radius each stands for) and each sample's one of them ``local`` where
    lamps are chosen for them (``chosen_lamps``)."""

    def __init__(self, g, rows, u, anchor=None, local=None):
        self.rows, self.anchor, self.local = rows, anchor, local
        self.x = patch_point_rows(g, rows, u[2], u[0].copy(), u[1].copy()).astype(np.float64)
        self.normal = g.patch_normal_rows.take(rows, axis=1).astype(np.float64)
        self.offset = g.ray_offsets(rows, np.float64)
        self.surface = self.x - self.normal * self.offset
        self.world = g.to_world(self.surface.T, rows).T

    def offset_of(self, live):
        return self.offset[live] if np.ndim(self.offset) else self.offset


def lamps_at(tables, points, lamps, u, value):
    """Adds every lamp's and sun's light at the points (one shadow ray each) to ``value``."""
    g = tables.geometry
    for light in lamps:
        towards, distance, v = light.gather(points.world, points.normal, u[3:5])
        if getattr(light, "casts_shadow", True):
            live = np.flatnonzero(v.any(axis=0))
            seen = np.zeros(points.rows.size, bool)
            if live.size:
                hit, _, _, t = trace(tables, points.x[:, live], towards[:, live], g.region_of(points.rows[live]))
                cosine = np.einsum("in,in->n", points.normal[:, live], towards[:, live])
                reach = distance[live] / g.diagonal - points.offset_of(live) * cosine
                seen[live] = (hit < 0) | (t >= reach * SEEN_BEFORE)
            v = v * seen
        value += v


def chosen_lamps(tables, points, choice, u, value):
    """Adds to ``value`` the light of one lamp or sun a sample (a shadow ray each), the one
    ``choice`` (a ``lamp_choice.LampChoice``) draws by u[5] for the sample's anchor point, over
    the chance of drawing it: in expectation every lamp's light (``lamps_at``) at the cost of one."""
    g = tables.geometry
    if len(choice) == 1:  # (one lamp: every sample its)
        lamp, chance = np.zeros(points.rows.size, np.int64), np.ones(points.rows.size)
    else:
        lamp, chance = choice.choose(choice.weights(*points.anchor), points.local, u[5])
    towards, distance, v = choice.gather(lamp, points.world, points.normal, u[3:5])
    seen = ~choice.casts_shadow[lamp]
    live = np.flatnonzero(~seen & v.any(axis=0))
    if live.size:
        hit, _, _, t = trace(tables, points.x[:, live], towards[:, live], g.region_of(points.rows[live]))
        cosine = np.einsum("in,in->n", points.normal[:, live], towards[:, live])
        reach = distance[live] / g.diagonal - points.offset_of(live) * cosine
        seen[live] = (hit < 0) | (t >= reach * SEEN_BEFORE)
    value += v * (seen / chance)


def sky_at(tables, points, worlds, u, value):
    """Adds the sky's light along one cosine ray a point to ``value``."""
    towards = worlds[0].gather(points.world, points.normal, u[3:5])[0]
    hit = trace(tables, points.x, towards, tables.geometry.region_of(points.rows))[0]
    escaped = np.flatnonzero(hit < 0)
    for world in worlds:
        value[:, escaped] += world.radiance_times_pi(towards[:, escaped])


def emitting(scene, power):
    """``emitters_at`` for the emitting patches ``power`` (P,) > 0: ``add(tables, points, u, value)``;
    their choice and cosine shares made once a scene (the display asks at every round of points)."""
    made = _EMITTING.setdefault(scene, {})
    key = hashlib.blake2b(np.ascontiguousarray(power).tobytes(), digest_size=16).digest()
    if key not in made:
        near = NearChoice(scene, power / power.sum())
        made[key] = (near if near.active else None, cosine_shares(scene, power))
    near, share = made[key]
    return partial(emitters_at, scene=scene, emitters=SourceTable(power), power=power, near=near, share=share)


def cosine_shares(scene, power):
    """(P,) the chance that a sample of each patch casts a cosine ray towards the emitting patches
    ``power`` (P,) > 0 (``emitters_at``): NEAREST_SHARE times the patch's bounded form factor to
    the nearest of them, A_s / (pi d^2 + A_s) between centres, from COSINE_SHARE_LEAST to 1 (the
    shadow rays' estimate is heavy-tailed only where an emitting patch is near for its size:
    beside a panel's edge, not on a floor a cube's height under it, where the cosine rays cost
    4x the rays for a tenth less error); beyond NEAREST_PAIRS pairs, COSINE_SHARE_LEAST."""
    emitting = np.flatnonzero(power > 0)
    share = np.full(scene.patch_count, COSINE_SHARE_LEAST)
    if scene.patch_count * emitting.size > NEAREST_PAIRS:
        return share
    centres = patch_centres(scene)
    area = scene.patch_area[emitting]
    for rows in np.array_split(np.arange(scene.patch_count), max(1, scene.patch_count * emitting.size >> 18)):
        d2 = ((centres[rows, None, :] - centres[None, emitting, :]) ** 2).sum(axis=2)
        share[rows] = np.clip(NEAREST_SHARE * (area / (np.pi * d2 + area)).max(axis=1), COSINE_SHARE_LEAST, 1.0)
    return share


def emitters_at(tables, points, scene, emitters, power, u, value, near=None, share=None):
    """Adds the light of these emitting patches (``power`` (P,), 0 elsewhere) at the points, by a
    shadow ray and a cosine ray weighed by the power heuristic, as the solve's gathering does
    (``first_shot``): the shadow ray to a point of a patch chosen by power (with ``near``, a
    ``near_choice.NearChoice`` of them, by power and by nearness to the point's patch); the cosine
    ray, cast by a point of a patch with the chance ``share`` (P,) (every one without), may meet
    one (u[3] decides, its rest and u[4] the direction). Each sees a patch's front, or its back
    where that emits (``scene.back_emits``). (By shadow rays alone, a ceiling beside a panel hung
    under it saw the panel's light through the slit 1/d^2 strong on a few samples and none on
    the rest: spikes in the display.)"""
    g, rows = tables.geometry, points.rows
    share = np.ones(rows.size) if share is None else share.take(rows)
    source = emitters.choose(u[5]) if near is None else near.choose(rows, u[5], emitters)
    e = patch_point_rows(g, source, u[6], u[7].copy(), u[8].copy()).astype(np.float64)
    normal_s = g.patch_normal_rows.take(source, axis=1).astype(np.float64)
    e -= normal_s * g.ray_offsets(source, np.float64)
    if g.regions is not None:
        e += g.regions.shift(g.regions.of(source)) - g.regions.shift(g.regions.of(rows))
    e -= points.surface
    length = np.sqrt(np.einsum("in,in->n", e, e))
    e /= length
    cos_x = np.einsum("in,in->n", points.normal, e)
    cos_y = -np.einsum("in,in->n", normal_s, e)
    facing = cos_y > 0
    live = np.flatnonzero((cos_x > 0) & (facing | scene.back_emits.take(source)) & (cos_y != 0) & (source != rows))
    if live.size:
        hit, hit_patch, front, t = trace(tables, points.x[:, live], e[:, live], g.region_of(rows[live]))
        reach = length[live] - points.offset_of(live) * cos_x[live]
        met = ((hit >= 0) & (hit_patch == source[live]) & (front == facing[live])) | (hit < 0) | (t >= reach * SEEN_BEFORE)
        s = source[live]
        weight = _weighed(scene, power, near, rows[live], s, cos_x[live], np.abs(cos_y[live]), length[live] * g.diagonal,
                          share[live], 0)
        value[:, live] += scene.emission[s].T * (weight * met)
    cast = np.flatnonzero(u[3] < share)
    if not cast.size:
        return
    towards = add_sphere_points(points.normal[:, cast].astype(np.float32), (u[3][cast] / share[cast]).astype(np.float32),
                                u[4][cast].astype(np.float32)).astype(np.float64)
    towards /= np.sqrt(np.einsum("in,in->n", towards, towards))  # (the normal plus a sphere point: cosine distributed)
    hit, s, front, t = trace(tables, points.x[:, cast], towards, g.region_of(rows[cast]))
    met = np.flatnonzero((hit >= 0) & (power.take(s) > 0) & (front | scene.back_emits.take(s)) & (s != rows[cast]))
    if met.size:
        s, at = s[met], cast[met]
        cos_x = np.einsum("in,in->n", points.normal[:, at], towards[:, met])
        cos_y = np.abs(np.einsum("in,in->n", g.patch_normal_rows.take(s, axis=1).astype(np.float64), towards[:, met]))
        weight = _weighed(scene, power, near, rows[at], s, cos_x, np.maximum(cos_y, 1e-12), t[met] * g.diagonal, share[at], 1)
        value[:, at] += scene.emission[s].T * weight


def _weighed(scene, power, near, receiver, source, cos_x, cos_y, distance, share, technique):
    """(n,) the estimate over E_s of emitting patch s seen from a point of ``receiver`` at
    ``distance`` (world) by the shadow ray (``technique`` 0) or the cosine ray (1), weighed by
    the power heuristic: f p_t / (p_shadow^2 + p_cosine^2), f = cos_x / pi, p_shadow = P_s d^2 /
    (A_s cos_y) (P_s the chance of choosing s), p_cosine = q cos_x / pi (q the chance of casting
    it: ``first_shot._emitter_weight``)."""
    chance = power.take(source) / power.sum() if near is None else near.probability(receiver, source)
    f = cos_x * (1.0 / np.pi)
    densities = (chance * distance ** 2 / (scene.patch_area.take(source) * cos_y), share * f)
    return f * densities[technique] / (densities[0] ** 2 + densities[1] ** 2)
