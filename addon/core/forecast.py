"""The time a solve will take, measured before it: a short pilot of the same solve.

The paper's formulas (2)/(3) predict the walk's error, not the two-way iteration's or the
gathered walk's, and a run with the measured stop rule ends where its own batch estimate meets
the target. So the forecast runs a few chunks of the solve the settings ask for (its method,
estimator, exit point, sampling), at most PILOT_RAYS rays, and reads from them what the run
will meet: the variance per path (batch means), the rays per path and the seconds per path on
this machine. The paths the run ends at follow from the solve's own chunk plan and stop rule
(whole chunks, at least MEASURED_STOP_CHUNKS, at most the cap).

A pilot's chunks are the run's when they fit in the budget; else smaller. A walk's paths are
independent, so its variance per path does not depend on the chunk; the two-way iteration's
falls as its chunks grow (what a chunk's sparse last generations and their roulette carry is
noise of the chunk, not of a path), and is scaled as its method says (``Method.variance_scale``).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from . import methods
from .chunks import run as run_chunks
from .estimate.grouping import groups_for
from .names import PREDICTED
from .estimate.plan import (
    MEASURED_STOP_CHUNKS,
    MIN_CHUNK_PATHS,
    MIN_MEASURED_CHUNKS,
    RESIZE_AFTER,
    chunk_plan,
    paths_to_target,
    resizes,
    target_now,
)

# A pilot traces about this many rays (about a second on two threads) ...
PILOT_RAYS = 1 << 20
# ... in at most this many chunks (the batch estimate the run stops on, at its fewest), at
# least 2 (a batch variance), and stops after this long whatever it has.
PILOT_CHUNKS = MIN_MEASURED_CHUNKS
PILOT_SECONDS = 3.0
# Without a pilot chunk (paths of a million bounces), a solve's ray rate is taken as this share
# of Embree's own on the probe's rays, per thread (benchmarks/results/throughput_methods.md).
SOLVE_SHARE_OF_RAW_RATE = 0.5


@dataclass(frozen=True)
class Forecast:
    """What a solve is expected to take: ``paths`` in ``chunks`` chunks of ``chunk``, ``rays``,
    ``seconds``; and what the pilot measured (``measured`` False: no pilot chunk finished in
    time, the error not measured: the run's least paths or the paper's)."""

    paths: float
    rays: float
    seconds: float
    chunk: int
    chunks: float
    variance_per_path: float  # at the run's chunk size (NaN for a path count)
    rays_per_path: float
    seconds_per_path: float
    setup_seconds: float
    pilot_chunk: int
    pilot_chunks: int
    pilot_seconds: float
    measured: bool
    time_limited: bool = False  # the time limit ends the run before ``seconds``
    short_of_target: float = 1.0  # the relative error the path cap ends the run at, over the target's (1: met)

    @property
    def rays_per_second(self):
        return self.rays_per_path / self.seconds_per_path if self.seconds_per_path > 0 else math.nan


def pilot_size(chunk, rays_per_path, budget=PILOT_RAYS):
    """(chunk paths, chunks) of a pilot: the run's chunks, as many as fit in ``budget`` rays
    (2 to PILOT_CHUNKS); where 2 do not fit, 2 smaller ones that do."""
    chunk_rays = chunk * rays_per_path
    chunks = int(min(PILOT_CHUNKS, max(2, budget // max(chunk_rays, 1.0))))
    return int(max(1, min(chunk, budget // (chunks * rays_per_path)))), chunks


def raw_rate(scene, rays=1 << 14, seed=0):
    """Embree's rays per second on cosine rays from the patches (one thread)."""
    from .lights.sampling import cosine_directions, points_on_patches

    g = scene.geometry
    rng = np.random.default_rng(seed)
    patch = rng.integers(0, scene.patch_count, rays).astype(np.int32)
    u = rng.random((5, rays), dtype=np.float32)
    origins, directions = points_on_patches(g, patch, u[4], u[0], u[1]), cosine_directions(g, patch, u[2], u[3])
    region = g.region_of(patch)
    g.surface_tracer.first_hit(origins, directions, region)  # (built, warm)
    start = time.perf_counter()
    g.surface_tracer.first_hit(origins, directions, region)
    return rays / max(time.perf_counter() - start, 1e-9)


def forecast(scene, settings, *, bounces=None, budget=PILOT_RAYS, should_stop=None):
    """The Forecast of ``solve(scene, settings)`` (``settings.method`` a method, not "auto";
    ``bounces`` the expected bounces of a path, diagnostics.check_bounces; with per-source results
    the pilot keeps each group's light apart, as the run will; on the measured error scale the
    target is the pilot's own mean's, as the run's will be). ``should_stop()`` ends the pilot early
    (a run starting): the forecast is then from what it has."""
    chosen = methods.create(settings.method, settings.direct_light)
    plan = chunk_plan(scene, chosen, settings)
    pilot_settings = settings.but(direct_light=chosen.direct_light, max_seconds=None, cluster=None,
                                  groups=groups_for(scene, settings.per_source, settings.groups))
    bounces = bounces if bounces is not None else plan.prediction.expected_path_length
    guess = chosen.rays_per_path(bounces)
    pilot_chunk, pilot_chunks = pilot_size(plan.chunk, guess, budget)
    start = time.perf_counter()

    def run(chunk, chunks, limit):
        """(result, seconds to its last finished chunk, or all it took if it finished none)."""
        began, finished = time.perf_counter(), []
        r = run_chunks(scene, pilot_settings.but(paths=chunk * chunks, chunk_paths=chunk, target_error=None,
                                                stop_rule=PREDICTED), chosen,
                       progress=lambda fraction, stats: finished.append(time.perf_counter() - began),
                       should_stop=lambda: time.perf_counter() - began > limit or bool(should_stop and should_stop()))
        everything = time.perf_counter() - began
        return r, finished[-1] if finished and r.chunks < chunks else everything

    # Two solves of two small chunks: the first builds what the scene keeps (its ray tracer's scene
    # and tables: a run builds them too), the second is a solve's own fixed cost.
    small = min(pilot_chunk, MIN_CHUNK_PATHS)
    (_, cold), (_, warm) = run(small, 2, PILOT_SECONDS / 4), run(small, 2, PILOT_SECONDS / 4)
    r, seconds = run(pilot_chunk, pilot_chunks, PILOT_SECONDS)
    workers = r.threads
    measured = r.chunks >= 2
    variance = math.nan
    if measured:
        variance = r.measured_mse * r.paths * chosen.variance_scale(scene.patch_count, pilot_chunk, plan.chunk)
    if r.chunks:  # (stopped by PILOT_SECONDS, it has what it finished)
        rays_per_path, setup = r.rays / r.paths, cold
        per_path = max(seconds - warm, 0.5 * seconds) / r.paths
    else:  # not a chunk in PILOT_SECONDS (paths of many bounces): the bounces and Embree's raw rate,
        # and at least the time the pilot's chunks took without finishing
        rays_per_path, setup = guess, 0.0
        per_path = max(guess / (raw_rate(scene, seed=settings.seed) * SOLVE_SHARE_OF_RAW_RATE * workers),
                       seconds / (pilot_chunk * min(workers, pilot_chunks)))
    expected, short, chunks = _expected_paths(scene, settings, plan, chosen, variance, r)
    seconds = setup + per_path * expected
    limited = settings.max_seconds is not None and seconds > settings.max_seconds
    return Forecast(paths=expected, rays=expected * rays_per_path, seconds=seconds,
                    chunk=plan.chunk, chunks=chunks, variance_per_path=variance,
                    rays_per_path=rays_per_path, seconds_per_path=per_path, setup_seconds=setup,
                    pilot_chunk=pilot_chunk, pilot_chunks=r.chunks, pilot_seconds=time.perf_counter() - start,
                    measured=measured, time_limited=limited, short_of_target=short)


def _expected_paths(scene, settings, plan, chosen, variance, r):
    """(paths, short_of, chunks) a run of ``plan`` is expected to end at, from the pilot's
    ``variance`` per path at the plan's chunk and its result ``r`` (the mean a measured target is
    relative to): the cap where it runs given paths; whole chunks to its target, its first of the
    first of the plan's size and the rest as it sizes them (``Method.later_chunk``), where it
    stops on its error."""
    short, chunks = 1.0, None
    if settings.paths is not None or not plan.measured_rule:
        expected = float(plan.cap)
    elif variance == variance:
        target = target_now(plan, settings.target_error, settings.error_scale, r.mean_reflected)
        if settings.replaced_direct is not None and r.per_source is not None and r.per_source.direct_irradiance is not None:
            target *= 1.0 - settings.replaced_direct.share  # (what the run keeps is held to the rest: estimate.batches.Replaced)
        expected, short = paths_to_target(1, variance, target, plan.chunk, plan.cap), short_of(variance, target, plan.cap)
        if chosen.sizes_later_chunks and resizes(plan, settings):  # (its first chunks, then the rest of ``later``)
            P, first = scene.patch_count, plan.chunk
            later = chosen.later_chunk(P, first, RESIZE_AFTER, variance, target, first)
            rest = paths_to_target(1, variance * chosen.variance_scale(P, first, later), target, later, plan.cap)
            expected = float(min(plan.cap, RESIZE_AFTER * (first - later) + rest))
            chunks = RESIZE_AFTER + (expected - RESIZE_AFTER * first) / later
    else:  # at least the chunks the measured rule needs, at most the cap
        expected = float(min(plan.cap, max(MEASURED_STOP_CHUNKS * plan.chunk, plan.prediction.paths_for(plan.target_mse))))
    return expected, short, expected / plan.chunk if chunks is None else chunks


def short_of(variance, target, cap):
    """The relative error a run of ``variance`` per path ends at after ``cap`` paths, over the
    ``target`` MSE's: 1 where it meets the target first; inf where nothing is reflected."""
    if variance <= target * cap:
        return 1.0
    return math.sqrt(variance / (target * cap)) if target > 0 else math.inf


def measured_choice(scene, settings, candidates, *, budget=PILOT_RAYS, margin=1.0):
    """(the cheapest of ``candidates`` (method names), {name: Forecast}): a pilot of each
    (``forecast`` of ``settings`` with that method) measures its time to the same error on this
    machine: the forecast seconds to the target, else the variance per path times the seconds
    per path; the first candidate unless another costs less than 1 / ``margin`` of it. A pilot
    that measured no error (not two chunks in PILOT_SECONDS: per source, rays cost more than the
    budget assumes) is run again on an eighth of the budget; a candidate that still measured none
    is dearer than one that did; none measured: the first."""
    def pilot(name, rays):
        direct_light = methods.direct_light_for(name, settings.direct_light, scene.lights)
        return forecast(scene, settings.but(method=name, direct_light=direct_light), budget=rays)

    forecasts = {}
    for name in candidates:
        forecasts[name] = pilot(name, budget)
        if not forecasts[name].measured:
            forecasts[name] = pilot(name, budget // 8)
    measured = [name for name in candidates if forecasts[name].measured]
    if not measured:
        return candidates[0], forecasts
    targeted = settings.target_error is not None
    cost = {name: cost_at_same_error(forecasts[name], targeted) for name in measured}
    cheapest = min(measured, key=cost.get)
    first = candidates[0]
    if first in cost and cost[first] <= margin * cost[cheapest]:
        return first, forecasts
    return cheapest, forecasts


def cost_at_same_error(f, targeted=False):
    """What a Forecast's run costs at a given error: its seconds to its target (``targeted``),
    else its variance per path times its seconds per path (the seconds to a unit variance)."""
    return f.seconds if targeted else f.variance_per_path * f.seconds_per_path
