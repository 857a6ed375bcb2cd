"""The direct light at sample points of patches by shadow rays, source by source: every lamp and
sun (``lamps_at``), one lamp drawn by what it gives (``chosen_lamps``), the sky along a cosine ray
(``sky_at``), an emitting patch drawn by power (``emitters_at``). The display's direct light at
corners (``display.point_direct``) and the Detail's refinement (``refine.adaptive_light``) read
them; the first shot (``first_shot``) traces their rays."""
from __future__ import annotations

import numpy as np

from ..lights.sampling import patch_point_rows
from ..methods.first_shot import SEEN_BEFORE, trace

# Sobol' dimensions of a sample: its point on the patch (2) and triangle (1), a point of a light
# or a direction of the sky (2), an emitting patch (1) and its point (3).
SAMPLE_DIMENSIONS = (0, 1, 7, 2, 3, 4, 5, 6, 8)


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


def emitters_at(tables, points, scene, emitters, power, u, value):
    """Adds the light of an emitting patch chosen by power (a point of it, a shadow ray): of its
    front, or of its back where that emits (``scene.back_emits``)."""
    g, rows = tables.geometry, points.rows
    source = emitters.choose(u[5])
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
    if not live.size:
        return
    hit, hit_patch, front, t = trace(tables, points.x[:, live], e[:, live], g.region_of(rows[live]))
    reach = length[live] - points.offset_of(live) * cos_x[live]
    met = ((hit >= 0) & (hit_patch == source[live]) & (front == facing[live])) | (hit < 0) | (t >= reach * SEEN_BEFORE)
    s = source[live]
    weight = cos_x[live] * np.abs(cos_y[live]) / (np.pi * (length[live] * g.diagonal) ** 2) * scene.patch_area[s]
    value[:, live] += scene.emission[s].T * (weight / (power[s] / power.sum()) * met)
