"""The Detail setting's refinement from the solve's own estimates (core.adaptive_solve): after the
direct-light refinement (adaptive_patches), solves at a looser target split the patches whose
solved light differs from their neighbours' by more than its noise, before the solve the user
asked for runs on the final mesh (pipeline.run_solve)."""
from __future__ import annotations

import hashlib
import time
from dataclasses import replace

import numpy as np

from ..core import methods, solve
from ..core.estimate.plan import MEASURED_STOP_CHUNKS, chunk_plan
from ..core.refine.adaptive_light import DETAILS
from ..core.refine.adaptive_solve import refine_by_solve
from ..core.names import AUTO
from . import adaptive_patches
from .settings import method_for, prediction_for
from .scene_notes import scene_and_notes

LOOSER = 2.0  # their error, about the user's target times this (a quarter of the paths)
SHARE = 0.2  # of a time limit, each refining solve's at most
# Of a time limit: refining steps start only within the first REFINING (each rebuilds the scene and
# solves), and the final solve has at least FINAL (else it may not finish its first batch).
REFINING, FINAL = 0.4, 0.5


def refined(objects, patches, settings, progress=None, should_stop=None, on_prediction=None):
    """(patches refined as ``settings.detail`` says: by the direct light, then by up to
    ``adaptive_patches.ROUNDS``
    looser solves, the settings for the final solve: what is left of a time limit, and the
    method the refining solves ran where "auto" asked for a choice)."""
    first_count = patches.combined.patch_count
    patches = adaptive_patches.refined(objects, patches, settings.detail, settings.seed, layers=True,
                                       should_stop=should_stop)
    if settings.detail == adaptive_patches.OFF or not adaptive_patches.ROUNDS or patches.cells is None:
        return patches, settings
    started, method = time.perf_counter(), None
    budget = int(DETAILS[settings.detail].budget * first_count)
    for round_ in range(adaptive_patches.ROUNDS):
        late = settings.max_seconds and time.perf_counter() - started > REFINING * settings.max_seconds
        if late or (should_stop is not None and should_stop()) or patches.combined.patch_count + 3 > budget:
            break
        scene, _ = scene_and_notes(patches)
        if method is None:  # (chosen for the user's target: a looser one would choose otherwise)
            method = method_for(scene, settings).method
        resolved = replace(settings, method=method)
        chunk = _chunk(scene, resolved)
        loose = _loose(resolved, chunk)
        prediction, _ = prediction_for(scene, loose)
        if on_prediction is not None:  # (the live view draws this step's mesh)
            on_prediction(prediction, int(scene.patch_count), patches)
        step_started = time.perf_counter()
        core = loose.core(scene, seed=_seed(settings.seed, round_),
                          chunk_paths=None if chunk is None else _quarter(chunk))
        result = solve(scene, core, progress=progress, should_stop=should_stop)
        if result.stopped == "cancelled":
            break
        cells, step = refine_by_solve(patches.cells, patches.meshes, result.irradiance, result.irradiance_variance,
                                      DETAILS[settings.detail], scene.geometry.diagonal, first_count,
                                      receives=[o.receives for o in patches.objects], keep_whole=_buried(scene))
        step.update(level=len(patches.refinement), first=first_count, solve=True, paths=int(result.paths),
                    solve_seconds=result.seconds, seconds=time.perf_counter() - step_started)
        steps = patches.refinement + [step]
        if not step["split"]:
            patches = replace(patches, refinement=steps)
            break
        patches = adaptive_patches.of_cells(objects, patches, cells, _geometry_key(cells), steps, layers=True,
                                            detail=settings.detail)
    return patches, _final(settings, method, started)


def _chunk(scene, settings):
    """The chunk of the solve at the user's error target (None with a path count)."""
    if settings.paths:
        return None
    core = settings.core(scene)
    return chunk_plan(scene, methods.create(settings.method, core.direct_light), core).chunk


def _quarter(chunk):
    return max(1, int(chunk) // int(LOOSER ** 2))


def _loose(settings, chunk):
    """The refining solves' settings: a quarter of the paths (about twice the error), no
    per-light results, a share of the time limit. With an error target, the fewest chunks the
    final solve runs (MEASURED_STOP_CHUNKS), each a quarter of its chunk: a looser target stopped
    on its measured error needed more paths than the final solve (the window room at 4%: 2.0 M
    paths in 93 small chunks, against 1.16 M in 12 at 2%)."""
    paths = int(settings.paths) // int(LOOSER ** 2) if settings.paths else MEASURED_STOP_CHUNKS * _quarter(chunk)
    return replace(settings, paths=max(1, paths), max_seconds=settings.max_seconds * SHARE if settings.max_seconds else None)


def _final(settings, method, started):
    """The final solve's settings: the time limit less what refining took (at least FINAL of
    it); the method chosen for the refining solves where "auto" was asked (its choice is not
    made again; with per-light results it is, measured with them)."""
    if method is not None and settings.method == AUTO and settings.per_source == "OFF":
        settings = replace(settings, method=method)
    if settings.max_seconds:
        left = settings.max_seconds - (time.perf_counter() - started)
        settings = replace(settings, max_seconds=max(left, settings.max_seconds * FINAL))
    return settings


def _seed(seed, round_):
    """A seed of each refining solve's own (its noise does not repeat in the final solve's)."""
    return int(np.random.SeedSequence([int(seed), 1 + round_]).generate_state(1)[0] >> 1)


def _buried(scene):
    """(P,) bool: patches another object runs into (they stay whole, as in the direct light's
    refinement), or None."""
    buried = scene.geometry.buried
    if buried is None:
        return None
    out = np.zeros(scene.patch_count, bool)
    out[np.concatenate([buried.patch, buried.whole]).astype(np.int64)] = True
    return out


def _geometry_key(cells):
    digest = hashlib.blake2b(digest_size=16)
    for c in cells:
        digest.update(np.ascontiguousarray(c.points).tobytes())
        digest.update(np.ascontiguousarray(c.corners).tobytes())
    return "solve-refined:" + digest.hexdigest()


def predicted_seconds(patches, final_seconds):
    """The predicted time of the refining solves and the final one: each refining solve about
    1 / LOOSER**2 of the final's paths on a mesh no larger (a time limit: its share)."""
    if not getattr(patches, "refinement", None) or not adaptive_patches.ROUNDS:
        return final_seconds
    return final_seconds * (1.0 + adaptive_patches.ROUNDS / LOOSER ** 2)
