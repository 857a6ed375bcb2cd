"""Where adaptive patches split (:mod:`.adaptive` splits them): the direct light of the candidates'
children, before any walk.

For every candidate cell (all first patches, then the children just made), the direct light of
its would-be children is estimated by shadow rays to every source (each lamp and the sun at
every sample point, no choice by power; emitting patches and the sky by their own samples),
twice independently; a cell splits when its children differ by more than a visible share of
the local light (and of a floor relative to the scene's mean, so dark corners do not eat the
budget) and by more than the two estimates' own noise. The splits repeat down to a smallest
size (``levels`` splits of the first patches, children no smaller than SMALLEST_SIDE of the
scene) or a patch budget. Cells that another object runs into (partly buried,
``visibility``) stay whole.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import dataclass

import numpy as np

from .adaptive import cells_of, patch_mesh, split
from ..display.direct_points import SAMPLE_DIMENSIONS, Points, emitting, lamps_at, sky_at
from ..scene.geometry_build import build_geometry
from ..lights.lights import WorldLight
from ..names import EXIT_RANDOM, FINITE
from ..lights.sampling import stratified_by_patch
from ..scene.scene import PatchScene
from ..methods.tables import WalkTables

NOISE_Z = 3.0  # standard errors a difference must pass to be light, not the estimate's noise
# Children at least this share of the scene's diagonal on a side: patches smaller than 1e-3 of it
# take ray offsets of their own (geometry_build.local_offsets), which turns the walk's grids off.
SMALLEST_SIDE = 2e-3
BLOCK = 1 << 18  # samples traced at a time


@dataclass(frozen=True)
class Detail:
    """How far refinement goes: ``levels`` splits of the first patches at most, a cell splits
    when its children's direct light differs by ``contrast`` of the local light (or of ``floor``
    times the scene's mean), the patches at most ``budget`` times the first count."""

    levels: int
    contrast: float
    floor: float = 0.2
    budget: float = 3.0
    samples: int = 4  # points per child and estimate (two estimates)


DETAILS = {
    "LOW": Detail(levels=1, contrast=0.5, budget=1.5),
    "MEDIUM": Detail(levels=2, contrast=0.25, budget=2.5),
    "HIGH": Detail(levels=3, contrast=0.12, budget=4.0),
}


@dataclass
class Refined:
    """The result of :func:`refine_by_direct_light`."""

    meshes: list  # PatchMesh per object
    origins: list  # (P_k,) the first mesh's patch of each patch, per object
    cells: list  # Cells per object
    steps: list  # per step: {"level", "candidates", "split", "patches", "seconds"}
    stopped: bool = False  # should_stop() ended it early


def direct_estimates(scene, patches, samples, seed, replicas=2):
    """(replicas, n, 3): independent estimates of the direct irradiance of ``patches`` (n,)
    of ``scene``, each the mean of ``samples`` stratified points of the patch, every point
    looking at every lamp and the sun by a shadow ray (their light needs no choice among
    them), at the sky by a cosine ray and at an emitting patch chosen by power."""
    patches = np.asarray(patches, np.int64)
    tables = WalkTables(scene, FINITE, 1e-3, EXIT_RANDOM)
    P = scene.patch_count
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(1 << 29,))))
    lamps = [light for light in scene.lights.lights if not isinstance(light, WorldLight)]
    worlds = [light for light in scene.lights.lights if isinstance(light, WorldLight)]
    power = scene.patch_area * scene.emission.mean(axis=1)
    emitters = emitting(scene, power) if (power > 0).any() else None  # (their light: shadow and cosine rays)
    out = np.zeros((replicas, len(patches), 3))
    rows_sorted = np.repeat(np.sort(patches), samples)
    with tables.numpy_turn:
        for r in range(replicas):
            for block in range(0, len(rows_sorted), BLOCK):
                rows = rows_sorted[block:block + BLOCK]
                u = stratified_by_patch(rows, P, SAMPLE_DIMENSIONS, rng, dtype=np.float32)
                points = Points(tables.geometry, rows, u)
                value = np.zeros((3, rows.size))
                lamps_at(tables, points, lamps, u, value)
                if worlds:
                    sky_at(tables, points, worlds, u, value)
                if emitters is not None:
                    emitters(tables, points, u=u, value=value)
                sums = np.stack([np.bincount(rows, weights=value[c], minlength=P) for c in range(3)], axis=1)
                out[r] += sums[patches] / samples
    return out


def _combined_scene(meshes, origins, base_scene):
    """The PatchScene of ``meshes``, each patch with the materials of the first scene's patch
    it lies in (its emission per area: the same power), the same lights and aim."""
    offsets = np.cumsum([0] + [len(m.points) for m in meshes])
    vertices = np.concatenate([m.points for m in meshes])
    triangles = np.concatenate([np.asarray(m.triangles, np.int64) + offsets[k] for k, m in enumerate(meshes)])
    patch_offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    triangle_patch = np.concatenate([np.asarray(m.triangle_patch, np.int64) + patch_offsets[k] for k, m in enumerate(meshes)])
    origin = np.concatenate(origins)
    # (no probes for buried parts: the cells they would find stay whole already, and the probes took
    # most of a step's time)
    geometry = build_geometry(vertices, triangles, triangle_patch, int(patch_offsets[-1]), visible_parts=False)
    return PatchScene(vertices, triangles, triangle_patch, base_scene.reflectivity[origin], base_scene.emission[origin],
                      lights=base_scene.lights.lights, aim=base_scene.lights.aim,
                      glossy=None if base_scene.glossy is None else base_scene.glossy.take(origin), _geometry=geometry), patch_offsets


def _trial(cells, candidate, base_offsets, base_scene):
    """The scene with every candidate split (no balance) and, for its children: (their patches
    in it, their parent as object << 40 | cell)."""
    trial = [split(c, k, balance=False) for c, k in zip(cells, candidate)]
    made = [patch_mesh(t, conforming=False) for t, _ in trial]
    origins = [o + base_offsets[k] for k, (_, o) in enumerate(made)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene, patch_offsets = _combined_scene([m for m, _ in made], origins, base_scene)
    children, parents = [], []
    for k, ((_, parent), cand) in enumerate(zip(trial, candidate)):
        rows = np.flatnonzero(cand[parent])
        children.append(rows + patch_offsets[k])
        parents.append(parent[rows] + (int(k) << 40))
    return scene, np.concatenate(children), np.concatenate(parents)


def _scores(children, parents, estimates, detail, mean_light):
    """(the parents (n,), each one's change over what it must pass to split (n,)): its children's
    spread against the visible share of the local light and their estimates' noise."""
    value = estimates.mean(axis=0)
    noise = ((estimates[0] - estimates[1]) / 2) ** 2  # variance of each child's mean
    group = np.unique(parents)
    index = np.searchsorted(group, parents)
    n = len(group)
    high, low = np.full(n, -np.inf), np.full(n, np.inf)
    np.maximum.at(high, index, value)
    np.minimum.at(low, index, value)
    sizes = np.bincount(index, minlength=n)
    local = np.bincount(index, weights=value, minlength=n) / sizes
    pooled = np.bincount(index, weights=noise, minlength=n) / sizes
    visible = detail.contrast * np.maximum(local, detail.floor * mean_light)
    score = (high - low) / np.maximum(visible, NOISE_Z * np.sqrt(2 * pooled))
    return group, score


def refine_by_direct_light(meshes, base_scene, detail: Detail, seed=0, receives=None, should_stop=None):
    """Split the patches of ``meshes`` (one PatchMesh per object, ``base_scene`` their
    PatchScene: materials and lights) where their direct light changes (see the module's
    docstring), ``detail`` deciding how far. ``receives`` (per object, bool): only those
    objects' patches split. Returns :class:`Refined`."""
    receives = [True] * len(meshes) if receives is None else list(receives)
    base_offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    cells = [cells_of(m) for m in meshes]
    limit = int(detail.budget * base_offsets[-1])
    smallest = (SMALLEST_SIDE * base_scene.geometry.diagonal) ** 2 * 4  # (a cell's area: its children's four)
    # cells another object runs into stay whole (their buried children would get no light, and a
    # black patch beside lit ones rings in the smooth colours): those of a first patch partly buried
    buried, whole = base_scene.geometry.buried, np.zeros(base_offsets[-1], bool)
    if buried is not None:
        whole[np.concatenate([buried.patch, buried.whole]).astype(np.int64)] = True
    mean_light, steps, stopped = None, [], False
    for level in range(detail.levels):
        started = time.perf_counter()
        candidate = [(c.level == level) & ~c.frozen & bool(r) & ~whole[c.origin + base_offsets[k]]
                     & (patch_mesh(c, conforming=False)[0].patch_area >= smallest) for k, (c, r) in enumerate(zip(cells, receives))]
        count = sum(c.count for c in cells)
        if not any(c.any() for c in candidate) or count + 3 > limit:
            break
        scene, children, parents = _trial(cells, candidate, base_offsets, base_scene)
        if should_stop is not None and should_stop():
            stopped = True
            break
        estimates = direct_estimates(scene, children, detail.samples, [seed, level]).mean(axis=2)  # (2,n) grey
        if mean_light is None:
            area = scene.patch_area[children]
            mean_light = float((estimates.mean(axis=0) * area).sum() / max(area.sum(), 1e-300))
        group, score = _scores(children, parents, estimates, detail, mean_light)
        chosen = np.flatnonzero(score > 1)
        room = max(0, (limit - count) // 3)
        if chosen.size > room:  # the largest changes first
            chosen = chosen[np.argsort(-score[chosen], kind="stable")[:room]]
        for k in range(len(cells)):
            marked = np.zeros(cells[k].count, bool)
            marked[group[chosen][group[chosen] >> 40 == k] & ((1 << 40) - 1)] = True
            if marked.any():
                cells[k], _ = split(cells[k], marked)
        steps.append({"level": level, "candidates": int(len(group)), "split": int(chosen.size),
                      "patches": int(sum(c.count for c in cells)), "seconds": time.perf_counter() - started})
        if chosen.size == 0:
            break
    made = [patch_mesh(c) for c in cells]
    return Refined([m for m, _ in made], [o for _, o in made], cells, steps, stopped)
