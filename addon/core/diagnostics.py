"""Checks that trace a few rays before a solve: sources whose light leaves the scene or meets only back faces."""
from __future__ import annotations

import numpy as np

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
