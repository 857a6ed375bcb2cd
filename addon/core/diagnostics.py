"""Checks that trace a few rays before a solve: emitting patches whose light leaves the scene."""
from __future__ import annotations

import numpy as np

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
    missed = scene.tracer.first_hit(origins, directions) < 0
    return emitting, missed.reshape(-1, RAYS_PER_EMITTER).mean(axis=1)
