"""Checks that trace a few rays before a solve: sources whose light leaves the scene or meets only back faces."""
from __future__ import annotations

import math

import numpy as np

from ..names import BIASED_INFINITE
from .rays import meets_front
from ..lights.sampling import cosine_directions, points_on_patches

# Rays per emitting patch, and at most this many in all (the emitters with most power first).
RAYS_PER_EMITTER = 32
MAX_RAYS = 1 << 16


def escaping_light(scene, seed=0):
    """(emitting patches (n,), the share of each one's cosine rays that meet nothing (n,)):
    an emitter that sees nothing from either side (a plane far above a scene) sends all its
    light out of the scene. Where its back emits too (``PatchScene.back_emits``), half its rays
    leave the back. Only patches with the most power, up to MAX_RAYS rays."""
    emitting = np.flatnonzero(scene.patch_power > 0)
    if not emitting.size:
        return emitting, np.zeros(0)
    emitting = emitting[np.argsort(-scene.patch_power[emitting], kind="stable")][: MAX_RAYS // RAYS_PER_EMITTER]
    g = scene.geometry
    rng = np.random.default_rng(seed)
    patch = np.repeat(emitting, RAYS_PER_EMITTER).astype(np.int32)
    u = rng.random((5, patch.size), dtype=np.float32)
    origins = points_on_patches(g, patch, u[4], u[0], u[1])
    directions = cosine_directions(g, patch, u[2], u[3])
    back = np.flatnonzero(scene.back_emits[patch] & np.tile(np.arange(RAYS_PER_EMITTER) % 2 == 1, emitting.size))
    directions[back] *= -1.0
    origins[back] -= g.patch_normal[patch[back]] * (2 * np.reshape(g.ray_offsets(patch[back]), (-1, 1)))
    missed = g.surface_tracer.first_hit(origins, directions, g.region_of(patch)) < 0
    return emitting, missed.reshape(-1, RAYS_PER_EMITTER).mean(axis=1)


RAYS_PER_LIGHT = 1024
# A light's first look: where one of these rays meets the front of a face, its light reaches the
# scene and no more are cast (500 lamps looked at with RAYS_PER_LIGHT each took a second).
FIRST_RAYS = 64


def light_fates(scene, seed=0):
    """(L,2) for each light of the scene: the share of its rays that meet nothing, and the share
    that meet the back of a face (a light inside a closed object, a sun or sky outside a closed
    room: none of it reaches a front side). Every light's FIRST_RAYS are cast at once; a light
    one of whose rays meets a front side is measured on them, the others on RAYS_PER_LIGHT."""
    lights = scene.lights
    if not len(lights):
        return np.zeros((0, 2))
    rng = np.random.default_rng(seed)
    everyone = np.arange(len(lights))
    fates = _fates(scene, everyone, FIRST_RAYS, rng)
    for k in np.flatnonzero(fates.sum(axis=1) >= 1.0):
        fates[k] = _fates(scene, np.array([k]), RAYS_PER_LIGHT, rng)[0]
    return fates


def _fates(scene, which, count, rng):
    """(len(which), 2) (missed, back) of ``count`` rays of each of the lights ``which``
    (``light_fates``), traced together."""
    lights, g = scene.lights, scene.geometry
    rows = []
    for k in which:
        first, last = lights.first[k], lights.first[k + 1]
        power = lights.power[first:last].mean(axis=1)
        chosen = first + np.searchsorted(np.cumsum(power) / power.sum(), rng.random(count), side="right")
        rows.append(np.minimum(chosen, last - 1))
    rows = np.concatenate(rows)
    origins, directions = lights.unit_rays(rows, rng.random((4, rows.size), dtype=np.float32), g)
    o, d = origins.astype(np.float32), directions.astype(np.float32)
    hit, _, _, _, normal = g.surface_tracer.first_hit_barycentric(np.ascontiguousarray(o.T), np.ascontiguousarray(d.T),
                                                                  lights.regions(rows, g))
    met = hit >= 0
    back = met & ~meets_front(d, normal)
    return np.stack([(~met).reshape(len(which), count).mean(axis=1), back.reshape(len(which), count).mean(axis=1)], axis=1)


# Rays the back-light check draws from the sources (by power), the bounces it follows, and the
# rays it casts from the back side of each face found lit from behind.
BACK_RAYS = 1 << 13
BACK_BOUNCES = 8
BEHIND_RAYS = 64


def _trace(g, origins, directions, region=None):
    """(patch (n,) int, -1 for a miss; met the front (n,) bool) of rays (n,3) float32, unit space
    (``region``: their origins' region frames, where the scene has regions)."""
    if g.patch_grids is not None:
        triangle, u, v, _, normal = g.patch_grids.tracer.first_hit_barycentric(origins, directions)
        patch = g.patch_grids.hit_patches(triangle, u, v)
    else:
        triangle, _, _, _, normal = g.tracer.first_hit_barycentric(origins, directions, region)
        patch = g.triangle_patch.take(triangle, mode="wrap")
    patch = np.where(triangle >= 0, patch, -1)
    return patch, (patch >= 0) & meets_front(directions.T, normal)


def _leave(g, patch, rng, behind=False):
    """Rays (n,3) float32 from uniform points of ``patch``, cosine-distributed about its normal,
    or with ``behind`` about the opposite of it from the back side."""
    u = rng.random((4, patch.size), dtype=np.float32)
    origins = points_on_patches(g, patch, u[0], u[1], u[2])
    directions = cosine_directions(g, patch, u[3], rng.random(patch.size, dtype=np.float32))
    if behind:
        origins = origins - (2.0 * g.ray_offset) * g.patch_normal[patch]
        directions = -directions
    return np.ascontiguousarray(origins, np.float32), np.ascontiguousarray(directions, np.float32)


def back_light(scene, receives, seed=0):
    """Where light meets the back of faces, and whether that matters to the selection.

    BACK_RAYS rays leave the sources by power and bounce on (weighted by each patch's grey
    reflectivity, up to BACK_BOUNCES times) until they escape or meet a back side.
    ``receives`` (P,) bool marks the patches that get results. A face met from behind is *in
    view of the selection* when rays leaving its back side meet the front of a receiving patch
    (a receiver sees that back side, black where Cycles would show it lit), or none of them
    escapes (a region closed by back sides: a room built inside out); otherwise the light met
    it from outside every receiver (a sky under a room's floor) and is nobody's concern, as is
    an emitting back (``PatchScene.back_emits``: a panel's, lit by the ceiling over it).

    Returns (source (n,) rows of ``scene.source_power`` (patches, then the lights' emitters),
    patch (n,), share (n,) of the total power, in_view (n,) bool) for each ray met from behind."""
    g = scene.geometry
    rng = np.random.default_rng(seed)
    power = scene.source_power.mean(axis=1)
    rows = np.minimum(np.searchsorted(np.cumsum(power) / power.sum(), rng.random(BACK_RAYS), side="right"),
                      power.size - 1)
    P = scene.patch_count
    origins = np.empty((rows.size, 3), np.float32)
    directions = np.empty((rows.size, 3), np.float32)
    from_patch = rows < P
    region = None if g.regions is None else np.zeros(rows.size, np.int32)
    if from_patch.any():
        origins[from_patch], directions[from_patch] = _leave(g, rows[from_patch].astype(np.int32), rng)
        # (half the light of an emitter whose back emits too leaves its back, as in the solve)
        if scene.back_emits.any():
            back = np.flatnonzero(from_patch & scene.back_emits[np.minimum(rows, P - 1)] & (rng.random(rows.size) < 0.5))
            origins[back], directions[back] = _leave(g, rows[back].astype(np.int32), rng, behind=True)
        if region is not None:
            region[from_patch] = g.region_of(rows[from_patch])
    if (~from_patch).any():
        lit = rows[~from_patch] - P
        o, d = scene.lights.unit_rays(lit, rng.random((4, lit.size), dtype=np.float32), g)
        origins[~from_patch], directions[~from_patch] = o.T, d.T
        if region is not None:
            region[~from_patch] = scene.lights.regions(lit, g)
    weight = np.full(rows.size, 1.0 / rows.size)
    source = rows
    found = []
    for _ in range(BACK_BOUNCES):
        patch, front = _trace(g, origins, directions, region)
        back = (patch >= 0) & ~front
        found.append((source[back], patch[back], weight[back]))
        source, patch, weight = source[front], patch[front], weight[front] * scene.grey_reflectivity[patch[front]]
        if not source.size:
            break
        origins, directions = _leave(g, patch.astype(np.int32), rng)
        region = g.region_of(patch)
    source, patch, weight = (np.concatenate(a) for a in zip(*found))
    lit = np.unique(patch)
    behind = np.repeat(lit, BEHIND_RAYS).astype(np.int32)
    seen, front = _trace(g, *_leave(g, behind, rng, behind=True), g.region_of(behind))
    sees_receiver = (front & receives[np.maximum(seen, 0)]).reshape(-1, BEHIND_RAYS).any(axis=1)
    escapes = (seen < 0).reshape(-1, BEHIND_RAYS).any(axis=1)
    in_view = np.zeros(P, dtype=bool)
    # (an emitter whose back emits absorbs there: surfaces are one-sided, and no face is flipped)
    in_view[lit] = (sees_receiver | ~escapes) & ~scene.back_emits[lit]
    return source, patch, weight, in_view[patch]


# Rays of the path-length probe.
BOUNCE_RAYS = 1 << 14
# A scene whose light bounces more than this many times on average before it is absorbed is
# refused: the shortest run that measures its error (MIN_MEASURED_CHUNKS chunks of
# MIN_CHUNK_PATHS paths, 1,024 paths) would trace over a billion rays, a path's bounces one
# after another.
MAX_BOUNCES = 1e6


def expected_bounces(scene, seed=0):
    """The hits a finite path is expected to make, 1 / (1 - s): s, a bounce's chance to go on,
    from cosine rays leaving patches in proportion to area, as the product of meeting a front
    face and that face's reflectivity (R_bar). Unlike the paper's 1 / (1 - R_ave) it sees light
    leave an open scene; it is exact for a closed scene of one reflectivity."""
    g = scene.geometry
    rng = np.random.default_rng(seed)
    area = scene.patch_area / scene.total_area
    patch = np.minimum(np.searchsorted(np.cumsum(area), rng.random(BOUNCE_RAYS), side="right"),
                       scene.patch_count - 1).astype(np.int32)
    u = rng.random((5, patch.size), dtype=np.float32)
    origins = points_on_patches(g, patch, u[4], u[0], u[1])
    directions = cosine_directions(g, patch, u[2], u[3])
    hit, u1, u2, _, normal = g.surface_tracer.first_hit_barycentric(origins, directions, g.region_of(patch))
    front = (hit >= 0) & meets_front(np.ascontiguousarray(directions.T), normal)
    grids = g.patch_grids
    met = grids.hit_patches(hit, u1, u2) if grids is not None else g.triangle_patch[np.maximum(hit, 0)]
    survival = np.where(front, scene.grey_reflectivity[np.maximum(met, 0)], 0.0)
    s = float(survival.mean())
    return 1.0 / (1.0 - s) if s < 1 else np.inf


def check_bounces(scene, estimator, threshold, seed=0):
    """ValueError if a path would bounce more than MAX_BOUNCES times on average (a closed scene
    of base colours within 10^-6 of 1); else the expected bounces (the paper's estimate where
    no reflectivity comes near the limit, the probe's where one does)."""
    if float(scene.grey_reflectivity.max()) < 1.0 - 1.0 / MAX_BOUNCES:
        return 1.0 / (1.0 - scene.average_reflectivity)
    bounces = expected_bounces(scene, seed)
    if estimator == BIASED_INFINITE and bounces > 1:
        bounces = min(bounces, 1.0 + math.log(threshold) / math.log1p(-1.0 / bounces))
    if bounces > MAX_BOUNCES:
        raise ValueError(
            f"the light bounces about {bounces:,.0f} times before it is absorbed (average reflectivity "
            f"{scene.average_reflectivity:.7g}, in a closed scene): a solve is refused above "
            f"{MAX_BOUNCES:,.0f} bounces (its shortest measured run, 1,024 paths, would trace over a billion "
            "rays, a path's bounces one after another). Lower the base colours: 0.999 gives about 1,000 bounces")
    return bounces
