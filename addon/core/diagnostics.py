"""Checks that trace a few rays before a solve: sources whose light leaves the scene or meets only back faces."""
from __future__ import annotations

import math

import numpy as np

from .names import BIASED_INFINITE
from .rays import meets_front
from .sampling import cosine_directions, points_on_patches

# Rays per emitting patch, and at most this many in all (the emitters with most power first).
RAYS_PER_EMITTER = 32
MAX_RAYS = 1 << 16


def escaping_light(scene, seed=0):
    """(emitting patches (n,), the share of each one's cosine rays that meet nothing (n,)):
    an emitter facing away from everything (a plane left facing up above a scene) sends all
    its light out of the scene. Only patches with the most power, up to MAX_RAYS rays."""
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
    missed = g.surface_tracer.first_hit(origins, directions) < 0
    return emitting, missed.reshape(-1, RAYS_PER_EMITTER).mean(axis=1)


RAYS_PER_LIGHT = 1024


def light_fates(scene, seed=0):
    """(L,2) for each light of the scene: the share of its rays that meet nothing, and the share
    that meet the back of a face (a light inside a closed object, a sun or sky outside a closed
    room: none of it reaches a front side)."""
    lights = scene.lights
    if not len(lights):
        return np.zeros((0, 2))
    g = scene.geometry
    rng = np.random.default_rng(seed)
    fates = []
    for k in range(len(lights)):
        first, last = lights.first[k], lights.first[k + 1]
        power = lights.power[first:last].mean(axis=1)
        rows = first + np.searchsorted(np.cumsum(power) / power.sum(), rng.random(RAYS_PER_LIGHT), side="right")
        rows = np.minimum(rows, last - 1)
        origins, directions = lights.unit_rays(rows, rng.random((4, RAYS_PER_LIGHT), dtype=np.float32), g)
        o, d = origins.astype(np.float32), directions.astype(np.float32)
        hit, _, _, _, normal = g.surface_tracer.first_hit_barycentric(np.ascontiguousarray(o.T), np.ascontiguousarray(d.T))
        met = hit >= 0
        back = met & ~meets_front(d, normal)
        fates.append((float(np.mean(~met)), float(np.mean(back))))
    return np.array(fates)


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
    hit, u1, u2, _, normal = g.surface_tracer.first_hit_barycentric(origins, directions)
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
