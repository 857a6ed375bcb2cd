"""solve(): the random walks in chunks, on threads, to a path count or an error target.

Chunk tallies are added in chunk order, so a run's result depends only on the seed and the chunk
plan, never on the number of threads or on timing: bitwise reproducible. The chunks are also the
batches of the run's error estimate (``batches``).
"""
from __future__ import annotations

import math
import os
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .batches import Batches
from .diagnostics import check_bounces
from .error_model import check_estimator, check_positive, predict
from .first_shot import Gathering, fate_shares, gather_samples, pilot_irradiance
from .two_way import GENERATION_RAYS, direct_samples, rays_per_path
from .names import (
    AUTO,
    EXIT_POINTS,
    DIRECT_LIGHTS,
    EXIT_RANDOM,
    FINITE,
    GATHERED,
    INDEPENDENT,
    MEASURED,
    METHODS,
    PREDICTED,
    SAMPLINGS,
    SHOT,
    STOP_CANCELLED,
    STOP_PATHS,
    STOP_RULES,
    STOP_TARGET,
    STOP_TIME_LIMIT,
    TWO_WAY,
    WALK,
)
from .cluster import ClusterRunner, WalkParameters, cluster_address
from .runners import ThreadRunner
from .speedups import Speedups
from .tables import WalkTables

# A chunk aims at about this many rays: enough wavefront steps that its last short ones cost
# little, few enough that progress and the batch error estimate come often.
RAYS_PER_CHUNK = 1 << 20
MAX_CHUNK_PATHS = 1 << 19
MIN_CHUNK_PATHS = 128
# The batch estimate wants this many chunks in a run when the run is small.
MIN_CHUNKS = 32
# Grouped chunks: up to GROUP_MAX_CHUNKS chunks (a power of two, so that a run of MIN_CHUNKS
# chunks makes an even number of tasks) are traced as one wavefront while a group has fewer rays
# than GROUP_RAYS (GROUP_RAYS_COUNTED for interchangeable paths, whose steps also pass over the
# patches), and its scores take at most GROUP_SCORES float64s.
GROUP_RAYS = 1 << 16
GROUP_RAYS_COUNTED = 1 << 18
GROUP_MAX_CHUNKS = 16
# Stochastic Jacobi iteration groups chunks up to this many first rays in a group.
GROUP_PATHS_JACOBI = 1 << 16
GROUP_SCORES = 1 << 22
# With stop_rule="measured": never stop on fewer chunks than this, nor run past this many
# times the predicted paths (unless paths= is given as the cap).
MIN_MEASURED_CHUNKS = 8
# With the direct light gathered, chunks are planned for this fraction of the paper's predicted
# paths (it needs several times fewer: docs/performance.md).
GATHERED_PLAN_DIVISOR = 4
MEASURED_CAP_FACTOR = 64
# With stop_rule="measured" the run stops once the measured MSE plus MEASURED_STOP_Z of its own
# standard errors (Batches.mse_upper_bound) meets the target, on at least MEASURED_STOP_CHUNKS
# chunks: the estimate alone, read after every chunk, stops on its first lucky low reading, and
# few or heavy-tailed chunks make such readings common.
MEASURED_STOP_Z = 2.0
MEASURED_STOP_CHUNKS = 12
# The two-way iteration needs this many first-generation rays a patch in a chunk: with fewer,
# what a generation passes on is mostly its own noise, which the next generation's gathering
# reads, and its gain over the walk per ray goes (the closed Cornell box, 2,940-535,815
# patches: from 4 rays a patch 2.3-3.2x the walk's, at one ray 0.82-1.21;
# benchmarks/results/auto_method.md). Its chunks get them as far as TWO_WAY_MAX_CHUNK_PATHS and
# MIN_MEASURED_CHUNKS chunks in the plan allow; method="auto" takes the walk where they do not,
# and in scenes of more than AUTO_MAX_PATCHES: a two-way chunk holds several (C,P) arrays, and
# this bound keeps a two-way solve through the operator under 1 GiB, as the walk keeps a million
# patches (docs/performance.md, memory_two_way_sizes.md).
TWO_WAY_RAYS_PER_PATCH = 4
AUTO_MAX_PATCHES = 3 << 17
# ... and grow on to this many, within TWO_WAY_MIN_CHUNKS chunks of the plan: the noise a
# generation passes on keeps falling (the figure 4 room, 16M paths: 8, 16 and 32 rays a patch,
# 1.0, 0.83 and 0.67 of the variance per path, the time alike; docs/performance.md).
TWO_WAY_CHUNK_RAYS_PER_PATCH = 32
# A small plan's two-way chunks: half as many as the walk's, twice as large. A chunk's variance
# per path falls as it grows (its last, sparse generations and the roulette that ends them carry
# a smaller share of its light): at 2M paths 13% less in the Cornell box and 10% in the empty
# room than in 32 chunks, 2-3% more in 8 (docs/performance.md); 16 leave the batch estimate 15
# degrees of freedom.
TWO_WAY_MIN_CHUNKS = 16
# A chunk's gathering samples and rays go a block at a time (first_shot.SAMPLE_BLOCK,
# two_way.RAY_BLOCK); what it holds at once beyond a block is its samples' points and values.
TWO_WAY_MAX_CHUNK_PATHS = 1 << 20
POLL_SECONDS = 0.05


def planned_paths(predicted_paths, direct_light, method=WALK):
    """The paths a solve stopping on its measured error plans its chunks for: the paper's
    prediction, or with the direct light gathered or an iteration (Jacobi, two-way) a fraction of it."""
    if direct_light == GATHERED or method != WALK:
        return max(1, predicted_paths // GATHERED_PLAN_DIVISOR)
    return predicted_paths


def method_direct_light(method, direct_light=None):
    """The direct light a method uses when none is asked for: the two-way iteration always
    gathers it; the walks shoot it, as the paper does."""
    if direct_light is None:
        return GATHERED if method == TWO_WAY else SHOT
    if method == TWO_WAY and direct_light != GATHERED:
        raise ValueError(f"method='{TWO_WAY}' gathers its direct light: direct_light must be '{GATHERED}' (or None); "
                         f"got {direct_light!r}")
    return direct_light


@dataclass
class SolveResult:
    radiosity: np.ndarray          # (P,3) B = E + b
    reflected: np.ndarray          # (P,3) b
    reflected_variance: np.ndarray  # (P,3) batch-means estimate of Var(b), NaN below 2 chunks
    irradiance: np.ndarray         # (P,3) H, the light arriving (B = E + R H): Cycles' DIFFUSE bake without colour
    paths: int
    rays: int
    seconds: float
    mean_path_length: float
    predicted_mse: float
    measured_mse: float
    stopped: str
    estimator: str
    threshold: float | None
    exit_point: str
    sampling: str
    seed: int
    threads: int
    chunks: int
    energy: dict = field(default_factory=dict)
    path_ends: dict = field(default_factory=dict)
    prediction: object = None
    speedups: object = None  # the speed-ups the walk used (Speedups, resolved)
    direct_light: str = SHOT
    method: str = WALK
    gather_rays: int = 0  # per chunk, with the direct light gathered

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else math.nan


@dataclass(frozen=True)
class ChunkPlan:
    """How a solve splits its paths: the paper's prediction, the stop rule, the most paths it
    runs (``cap``) and the paths of a chunk."""

    prediction: object
    measured_rule: bool
    cap: int
    chunk: int


def chunk_plan(scene, estimator=FINITE, *, paths=None, target_mse=None, threshold=1e-3, stop_rule=PREDICTED,
               direct_light=SHOT, method=WALK, max_seconds=None):
    """The chunk plan of a solve with these arguments (``method`` resolved, not "auto")."""
    prediction = predict(scene, estimator, target_mse=target_mse, threshold=threshold)
    beyond_formulas = direct_light == GATHERED or method != WALK
    measured_rule = stop_rule == MEASURED or (beyond_formulas and target_mse is not None)
    if measured_rule:
        planned = planned_paths(prediction.paths_for(target_mse), direct_light, method)
        cap = paths if paths is not None else MEASURED_CAP_FACTOR * planned
    else:
        planned = paths if paths is not None else prediction.paths_for(target_mse)
        cap = planned
    if method == TWO_WAY:
        chunk = two_way_chunk_paths(scene.patch_count, prediction.expected_path_length, planned, max_seconds is not None)
    else:
        chunk = chunk_paths_for(prediction.expected_path_length, planned)
    return ChunkPlan(prediction, measured_rule, int(cap), int(chunk))


def paths_to_target(paths, measured_mse, target_mse, chunk, cap):
    """The paths a run stopping on its measured error is expected to end at, from its MSE after
    ``paths`` (which falls as 1 / paths): whole chunks, at least MEASURED_STOP_CHUNKS, at most
    ``cap``. NaN MSE (fewer than 2 chunks): NaN."""
    if not measured_mse >= 0 or paths <= 0:
        return math.nan
    needed = paths * measured_mse / target_mse
    chunks = max(MEASURED_STOP_CHUNKS, math.ceil(needed / chunk))
    return float(min(cap, chunks * chunk))


def chunk_paths_for(expected_path_length, planned_paths, min_chunks=MIN_CHUNKS):
    by_rays = int(RAYS_PER_CHUNK / max(expected_path_length, 1.0))
    by_batches = math.ceil(planned_paths / min_chunks)
    return int(min(MAX_CHUNK_PATHS, max(MIN_CHUNK_PATHS, min(by_rays, by_batches))))


def two_way_chunk_paths(patch_count, expected_path_length, planned_paths, time_limited=False):
    """A two-way chunk: the usual rays (a small plan in TWO_WAY_MIN_CHUNKS chunks), or more: up
    to TWO_WAY_CHUNK_RAYS_PER_PATCH first-generation rays a patch (GENERATION_RAYS a path)
    within TWO_WAY_MIN_CHUNKS chunks of the plan, and at least TWO_WAY_RAYS_PER_PATCH within
    MIN_MEASURED_CHUNKS; never more than TWO_WAY_MAX_CHUNK_PATHS. Under a time limit, the usual
    rays (about RAYS_PER_CHUNK): a chunk of a million paths can take longer than the limit, and
    a run stopped before its first chunk has nothing to give."""
    usual = chunk_paths_for(rays_per_path(expected_path_length), planned_paths, TWO_WAY_MIN_CHUNKS)
    if time_limited:
        return usual
    paths_for = lambda rays: math.ceil(rays * patch_count / GENERATION_RAYS)  # noqa: E731
    grown = min(paths_for(TWO_WAY_CHUNK_RAYS_PER_PATCH), math.ceil(planned_paths / TWO_WAY_MIN_CHUNKS))
    enough = min(paths_for(TWO_WAY_RAYS_PER_PATCH), math.ceil(planned_paths / MIN_MEASURED_CHUNKS))
    return int(min(TWO_WAY_MAX_CHUNK_PATHS, max(usual, grown, enough)))


def first_generation_rays(patch_count, chunk_paths):
    """The rays a patch gets, on average, in a two-way chunk's first generation."""
    return GENERATION_RAYS * chunk_paths / patch_count


def choose_method(scene, estimator=FINITE, *, paths=None, target_mse=None, threshold=1e-3, max_seconds=None):
    """What method="auto" runs: the two-way iteration where its chunks can give each patch
    TWO_WAY_RAYS_PER_PATCH first-generation rays (at error targets that plan at least
    MIN_MEASURED_CHUNKS such chunks; under a time limit, in chunks of the usual size) in a scene
    of at most AUTO_MAX_PATCHES patches, else the paper's walk, which then needs fewer rays to
    the same error."""
    if scene.patch_count > AUTO_MAX_PATCHES:
        return WALK
    prediction = predict(scene, estimator, target_mse=target_mse, threshold=threshold)
    planned = paths if paths is not None else planned_paths(prediction.paths_for(target_mse), GATHERED, TWO_WAY)
    chunk = two_way_chunk_paths(scene.patch_count, prediction.expected_path_length, planned, max_seconds is not None)
    return TWO_WAY if first_generation_rays(scene.patch_count, chunk) >= TWO_WAY_RAYS_PER_PATCH else WALK


def chunks_per_group(tables, chunk_paths, expected_path_length):
    """How many chunks a task traces together (walk.walk_chunks): 1 unless the chunks are small
    and grouped chunks are on, else a power of two. It depends on the walk and the chunk plan
    alone, never on the threads, so runs stay bitwise reproducible."""
    if not tables.speedups.grouped_chunks:
        return 1
    chunk_rays = max(1.0, chunk_paths * expected_path_length)
    group_rays = GROUP_RAYS_COUNTED if tables.speedups.interchangeable else GROUP_RAYS
    if tables.jacobi:  # (a Jacobi group's wavefront is a generation: its first has a ray a path)
        chunk_rays, group_rays = chunk_paths, GROUP_PATHS_JACOBI
    by_scores = GROUP_SCORES // (tables.channels * tables.patch_count)
    most = int(min(GROUP_MAX_CHUNKS, group_rays // chunk_rays, by_scores))
    return 1 << (most.bit_length() - 1) if most > 1 else 1


def _check_solve_arguments(scene, estimator, paths, target_mse, threshold, exit_point, stop_rule, max_seconds, threads, sampling, direct_light, method):
    check_estimator(estimator, threshold)
    check_positive("paths", paths, integer=True)
    check_positive("target_mse", target_mse)
    check_positive("max_seconds", max_seconds)
    check_positive("threads", threads, integer=True)
    if paths is None and target_mse is None:
        raise ValueError("give paths (a path count) or target_mse (an error target)")
    if exit_point not in EXIT_POINTS:
        raise ValueError(f"exit_point must be one of {', '.join(EXIT_POINTS)}; got {exit_point!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {', '.join(SAMPLINGS)}; got {sampling!r}")
    if method not in METHODS:
        raise ValueError(f"method must be one of {', '.join(METHODS + (AUTO,))}; got {method!r}")
    if direct_light not in DIRECT_LIGHTS:
        raise ValueError(f"direct_light must be one of {', '.join(DIRECT_LIGHTS)}; got {direct_light!r}")
    if direct_light == SHOT and scene.lights.gathered_only():
        why = "; ".join(f"light '{name}' {reason}" for name, reason in scene.lights.gathered_only())
        raise ValueError(f"{why}: a shooting walk cannot carry its direct light; use direct_light='{GATHERED}' "
                         "(shadow rays from each patch)")
    if stop_rule not in STOP_RULES:
        raise ValueError(f"stop_rule must be one of {', '.join(STOP_RULES)}; got {stop_rule!r}")
    if stop_rule == "measured" and target_mse is None:
        raise ValueError("stop_rule='measured' needs a target_mse")


def solve(
    scene,
    estimator=FINITE,
    *,
    paths=None,
    target_mse=None,
    threshold=1e-3,
    seed=0,
    exit_point=EXIT_RANDOM,
    stop_rule=PREDICTED,
    progress=None,
    should_stop=None,
    max_seconds=None,
    threads=None,
    sampling=INDEPENDENT,
    speedups=None,
    direct_light=None,
    cluster=None,
    method=WALK,
    chunk_paths=None,
):
    """Radiosity of ``scene`` by shooting random walks.

    Runs ``paths`` paths, or, with ``target_mse``, the paths formula (2)/(3) predicts for it
    (``stop_rule="predicted"``) or until the batch estimate meets it (``"measured"``, capped
    by ``paths`` if given, else 64 times the prediction). ``direct_light="gathered"`` (beyond the
    paper, ``first_shot``) gathers each patch's direct light by shadow rays and walks only its
    reflection; the paper's formulas do not predict its error, so with ``target_mse`` it always
    stops on the measured error. ``cluster`` (a ``dask.distributed.Client`` or a scheduler
    address, ``tcp://host:port`` or ``tls://host:port``, trusted like this machine) runs the chunks on
    a Dask cluster instead of threads: bitwise the same result. ``sampling="stratified"`` (beyond
    the paper) allots each chunk's paths to sources in proportion to power and draws the first
    ray from a randomly shifted low-discrepancy set: same expectation, usually less noise;
    the predicted path counts are derived for the paper's plain ``"independent"`` sampling.
    ``method="two_way"`` (beyond the paper, ``two_way``) carries the light generation by
    generation, every ray used as a shooting and a gathering estimate about a control variate,
    its direct light always gathered (``direct_light`` None: the method's own, gathered for it,
    shot for the walks); its error, too, is measured, never predicted. ``method="auto"`` runs
    it where its chunks give every patch enough rays, else the walk (:func:`choose_method`;
    ``SolveResult.method`` says which ran).
    ``progress(fraction, stats)`` and ``should_stop()`` are called from the calling thread
    between chunks (``stats["radiosity"](dtype)`` gives the result so far); ``max_seconds`` bounds the wall time. A stopped run returns the complete
    chunks it has. ``speedups`` (:class:`.speedups.Speedups`) switches speed-ups on or off.
    ``chunk_paths`` replaces the plan's chunk size (the estimate's pilot: ``forecast``).
    """
    if method == AUTO and (paths is not None or target_mse is not None):
        check_estimator(estimator, threshold)
        check_positive("paths", paths, integer=True)
        check_positive("target_mse", target_mse)
        method = choose_method(scene, estimator, paths=paths, target_mse=target_mse, threshold=threshold, max_seconds=max_seconds)
    if method in METHODS:
        direct_light = method_direct_light(method, direct_light)
    _check_solve_arguments(scene, estimator, paths, target_mse, threshold, exit_point, stop_rule, max_seconds, threads, sampling, direct_light, method)
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative whole number; got {seed!r}")
    if speedups is not None and not isinstance(speedups, Speedups):
        raise ValueError(f"speedups must be a Speedups; got {speedups!r}")
    if isinstance(cluster, str):
        cluster = cluster_address(cluster)  # (its form, before any work; connecting comes later)
    check_bounces(scene, estimator, threshold)
    threads = int(threads or min(os.cpu_count() or 1, 8))
    paths = None if paths is None else int(paths)  # numpy integers welcome
    start = time.perf_counter()

    plan = chunk_plan(scene, estimator, paths=paths, target_mse=target_mse, threshold=threshold, stop_rule=stop_rule,
                      direct_light=direct_light, method=method, max_seconds=max_seconds)
    prediction, measured_rule, cap, chunk = plan.prediction, plan.measured_rule, plan.cap, plan.chunk
    check_positive("chunk_paths", chunk_paths, integer=True)
    if chunk_paths is not None:
        chunk = int(chunk_paths)
    gathered = direct_light == GATHERED
    beyond_formulas = gathered or method != WALK  # the paper's formulas do not predict their error
    tables = WalkTables(scene, estimator, threshold, exit_point, sampling, speedups)
    tables.method = method
    if method == TWO_WAY:
        tables.gathering = Gathering(scene, direct_samples(chunk, scene))
        with tables.numpy_turn:  # (the samples allotted partly by a pilot's direct light)
            pilot = pilot_irradiance(tables, tables.gathering, int(seed))
        tables.gathering = Gathering(scene, direct_samples(chunk, scene, pilot))
    elif gathered:
        tables.gathering = Gathering(scene, gather_samples(chunk, prediction.expected_path_length, scene))
    if gathered:
        with tables.numpy_turn:  # (it casts, and a cast lets go of the turn while it traces)
            tables.gathering.fate_shares = fate_shares(tables, int(seed))
    total = Batches(scene, tables, increments=measured_rule)
    chunk_count = math.ceil(cap / chunk)
    group = 1 if gathered else chunks_per_group(tables, chunk, prediction.expected_path_length)
    # Running the predicted paths for a target ends as "target"; running given paths, "paths".
    done_rule = STOP_TARGET if (paths is None and not measured_rule) else STOP_PATHS
    stopped = None
    pending = deque()
    next_chunk = 0
    if cluster is None:
        runner = ThreadRunner(threads)
    else:
        gather = tuple(tables.gathering.samples.tolist()) if gathered else None
        fates = tuple(tables.gathering.fate_shares) if gathered else None
        parameters = WalkParameters(estimator, float(threshold), exit_point, sampling, tables.speedups, gather, method, fates)
        runner = ClusterRunner(cluster, scene, parameters)
        threads = runner.threads
    try:
        runner.start(tables, int(seed))
        while stopped is None:
            while next_chunk < chunk_count and len(pending) < runner.slots:
                sizes = [min(chunk, cap - k * chunk) for k in range(next_chunk, min(next_chunk + group, chunk_count))]
                pending.append(runner.submit(next_chunk, sizes))
                next_chunk += len(sizes)
            if not pending:
                stopped = done_rule
                break
            tallies = None
            while tallies is None and stopped is None:
                try:
                    tallies = pending[0].result(timeout=POLL_SECONDS)
                except TimeoutError:
                    stopped = _interrupted(should_stop, max_seconds, start)
            if stopped:
                break
            pending.popleft()
            for tally in tallies:  # progress once per chunk
                total.add(tally)
                if progress is not None:
                    progress(*_progress(total, prediction, cap, target_mse if measured_rule else None, start, chunk))
            # (The batch estimate costs passes over the patches: made only where it is used.)
            if measured_rule and total.chunks >= MEASURED_STOP_CHUNKS and total.measured_mse() <= target_mse \
                    and total.mse_upper_bound(MEASURED_STOP_Z) <= target_mse:
                stopped = STOP_TARGET
            elif total.paths >= cap:
                stopped = done_rule
            else:
                stopped = _interrupted(should_stop, max_seconds, start)
    finally:
        runner.stop(pending)  # tasks still running are abandoned; their partial tallies dropped
        pending.clear()  # (their futures hold a tally, or a traceback and the walk's arrays in it)
        tallies = tally = None  # (the last ones added, summed already)

    n = total.paths
    # (one (P,3) result at a time, the sums of squares let go of once the error is estimated)
    reflected_variance = total.reflected_variance()
    measured_mse = total.let_go_of_squares()
    reflected = total.reflected()
    return SolveResult(
        radiosity=scene.emission + reflected,
        reflected=reflected,
        reflected_variance=reflected_variance,
        irradiance=total.irradiance(),
        paths=n,
        rays=total.rays,
        seconds=time.perf_counter() - start,
        mean_path_length=total.rays / n if n else math.nan,
        predicted_mse=math.nan if beyond_formulas else prediction.mse_for(n),
        measured_mse=measured_mse,
        stopped=stopped,
        estimator=estimator,
        threshold=threshold if estimator != FINITE else None,
        exit_point=exit_point,
        sampling=sampling,
        seed=int(seed),
        threads=threads,
        chunks=total.chunks,
        energy=total.energy() if n else {},
        path_ends=dict(total.ended),
        prediction=prediction,
        speedups=tables.speedups,
        direct_light=direct_light,
        method=method,
        gather_rays=round(2 * tables.gathering.samples.sum()) if gathered else 0,
    )


def _progress(total, prediction, cap, measured_target, start, chunk):
    """(fraction, stats) for ``progress``: the share of the paths the run is expected to end at
    (the cap; with the measured stop rule, where the bound it stops on says it will meet the
    target), and the seconds left at the run's pace so far (NaN until it is known)."""
    elapsed = time.perf_counter() - start
    mse_now = total.measured_mse()
    expected = float(cap)
    if measured_target is not None:
        bound = total.mse_upper_bound(MEASURED_STOP_Z)
        expected = paths_to_target(total.paths, bound if bound == bound else mse_now, measured_target, chunk, cap)
    fraction = total.paths / expected if expected > 0 else 0.0  # (NaN > 0 is False)
    left = (expected - total.paths) * elapsed / total.paths if total.paths else math.nan
    return min(1.0, fraction), {
        "paths": total.paths,
        "rays": total.rays,
        "seconds": elapsed,
        "rays_per_second": total.rays / elapsed if elapsed > 0 else math.nan,
        "measured_mse": mse_now,
        "expected_paths": expected,  # NaN while unknown
        "seconds_left": max(0.0, left) if left == left else math.nan,
        "predicted_mse": prediction.mse_for(total.paths),
        # The result so far, (P,3) B, computed only if called (a pass over the patches).
        "radiosity": total.radiosity,  # (dtype=np.float64)
    }


def _interrupted(should_stop, max_seconds, start):
    if should_stop is not None and should_stop():
        return STOP_CANCELLED
    if max_seconds is not None and time.perf_counter() - start >= max_seconds:
        return STOP_TIME_LIMIT
    return None
