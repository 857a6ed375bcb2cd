"""solve(): runs the random walks in chunks over threads, to a path count or an error target.

Chunk k of a run draws its random numbers from its own stream, SeedSequence(seed, spawn_key=(k,)),
(a group of small chunks traced together, see ``chunks_per_group``, from its first chunk's), and
chunk tallies are added in chunk order, so a run's result depends only on the seed and the
chunk plan, never on the number of threads or on timing: bitwise reproducible.

Chunks are also the independent batches of the a-posteriori error estimate ("batch means"):
with K chunks of n_k paths giving per-chunk estimates b^(k), the per-path variance of each
patch is estimated by sum_k n_k (b^(k) - b)^2 / (K - 1), and the MSE of the result by its
area-weighted mean over patches (and channels) divided by N.
"""
from __future__ import annotations

import math
import os
import threading
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from .error_model import check_estimator, check_positive, predict
from .estimators import EXIT_POINTS, EXIT_RANDOM, FINITE, WalkTables, walk_chunks

STOP_PATHS = "paths"
STOP_TARGET = "target"
STOP_CANCELLED = "cancelled"
STOP_TIME_LIMIT = "time_limit"
STOP_RULES = ("predicted", "measured")
SAMPLINGS = ("independent", "stratified")

# A chunk aims at about this many rays: many wavefront steps (estimators.WAVEFRONT_PATHS
# rays each), so that the few short steps at its end, when its last paths run out, cost
# little; few enough that progress and the batch error estimate come often (cancel is
# honoured at every step).
RAYS_PER_CHUNK = 1 << 20
MAX_CHUNK_PATHS = 1 << 19
MIN_CHUNK_PATHS = 128
# The batch estimate wants this many chunks in a run when the run is small.
MIN_CHUNKS = 32
# Small chunks end in many steps of few rays each, which cost numpy's per-step work for little
# tracing: up to GROUP_MAX_CHUNKS chunks are traced as one wavefront (estimators.walk_chunks)
# while a group's chunks have fewer rays than GROUP_RAYS, or GROUP_RAYS_COUNTED in the walk of
# interchangeable paths (whose steps also cost a pass over the patches: it gains up to chunks of
# about 60k rays, where the other walks, which keep every account per chunk in a group, gain
# below about 16k rays and lose about 7% at 57k). A group is a power of two of chunks, so that
# a run of MIN_CHUNKS chunks makes an even number of tasks for the threads: 2 (16 chunks a group)
# for the smallest runs, where steps cost more than threads gain, and 8 (4 a group) from runs of
# about 10^6 rays. Its scores take at most GROUP_SCORES float64s (channels x patches a chunk).
GROUP_RAYS = 1 << 16
GROUP_RAYS_COUNTED = 1 << 18
GROUP_MAX_CHUNKS = 16
GROUP_SCORES = 1 << 22
# With stop_rule="measured": never stop on fewer chunks than this, nor run past this many
# times the predicted paths (unless paths= is given as the cap).
MIN_MEASURED_CHUNKS = 8
MEASURED_CAP_FACTOR = 64
POLL_SECONDS = 0.05


@dataclass
class SolveResult:
    radiosity: np.ndarray          # (P,3) B = E + b
    reflected: np.ndarray          # (P,3) b
    reflected_variance: np.ndarray  # (P,3) batch-means estimate of Var(b), NaN below 2 chunks
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

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else math.nan


def chunk_paths_for(expected_path_length, planned_paths):
    by_rays = int(RAYS_PER_CHUNK / max(expected_path_length, 1.0))
    by_batches = math.ceil(planned_paths / MIN_CHUNKS)
    return int(min(MAX_CHUNK_PATHS, max(MIN_CHUNK_PATHS, min(by_rays, by_batches))))


def chunks_per_group(tables, chunk_paths, expected_path_length):
    """How many chunks a task traces together (estimators.walk_chunks): 1 unless the chunks
    are small, else a power of two (see GROUP_RAYS). It depends on the walk and the chunk plan
    alone, never on the threads, so runs stay bitwise reproducible."""
    chunk_rays = max(1.0, chunk_paths * expected_path_length)
    group_rays = GROUP_RAYS_COUNTED if tables.exchangeable else GROUP_RAYS
    by_scores = GROUP_SCORES // (tables.channels * tables.patch_count)
    most = int(min(GROUP_MAX_CHUNKS, group_rays // chunk_rays, by_scores))
    return 1 << (most.bit_length() - 1) if most > 1 else 1


class _Accumulator:
    """Sums chunk tallies in chunk order, with what the batch error estimate needs."""

    def __init__(self, scene, tables, prediction):
        C, P = tables.channels, scene.patch_count
        self.scene = scene
        self.channels = C
        self.incident = np.zeros((C, P))
        self.incident_sq = np.zeros((C, P))  # sum_k I_k^2 / n_k
        self.emitted = np.zeros(C)
        self.absorbed = np.zeros(C)
        self.escaped = np.zeros(C)
        self.blocked = np.zeros(C)
        self.undistributed = np.zeros(C)
        self.ended = {}
        self.paths = 0
        self.rays = 0
        self.chunks = 0
        # b_j = (R_j Phi_T / A_j) I_j / N
        self.score = tables.reflectivity * (scene.total_power / scene.patch_area)  # (C,P)
        self.weight = scene.patch_area / scene.total_area
        self._mse_weight = None  # (C*P,) score^2 A_j / (C A_T), made on first use
        self._mse_at = (0, math.nan)  # (chunks, measured_mse at that many chunks)

    def add(self, tally):
        self.incident += tally.incident
        square = np.square(tally.incident)  # (in place from here: no more (C,P) temporaries)
        square /= tally.paths
        self.incident_sq += square
        self.emitted += tally.emitted
        self.absorbed += tally.absorbed
        self.escaped += tally.escaped
        self.blocked += tally.blocked
        self.undistributed += tally.undistributed
        for key, value in tally.ended.items():
            self.ended[key] = self.ended.get(key, 0) + value
        self.paths += tally.paths
        self.rays += tally.rays
        self.chunks += 1

    def reflected(self):
        if self.paths == 0:
            return np.zeros((self.scene.patch_count, 3))
        b = (self.score * self.incident / self.paths).T
        return np.repeat(b, 3, axis=1) if self.channels == 1 else b

    def variance_of_mean(self):
        """Batch-means estimate of Var(b_j) per channel and patch, (C,P); NaN below 2 chunks."""
        if self.chunks < 2:
            return np.full_like(self.incident, math.nan)
        variance = self._spread()
        variance *= self.score**2
        variance /= (self.chunks - 1) * self.paths
        return variance

    def _spread(self):
        """sum_k I_k^2 / n_k - I^2 / N per channel and patch (C,P), at least 0: N (chunks - 1)
        times the batch variance of I / N. (A new array, computed in place.)"""
        spread = np.square(self.incident)
        spread /= self.paths
        np.subtract(self.incident_sq, spread, out=spread)
        np.maximum(spread, 0.0, out=spread)
        return spread

    def reflected_variance(self):
        v = self.variance_of_mean().T
        return np.repeat(v, 3, axis=1) if self.channels == 1 else v

    def measured_mse(self):
        """Batch-means estimate of the MSE of the current result (its variance part): the
        area-weighted mean over patches (and channels) of variance_of_mean, computed as one sum
        of its spread times score^2 A_j / (C A_T). Kept for the chunk count it was made at."""
        if self.chunks < 2:
            return math.nan
        if self._mse_at[0] == self.chunks:
            return self._mse_at[1]
        if self._mse_weight is None:
            self._mse_weight = (self.score**2 * (self.weight / self.channels)).ravel()
        # (einsum, not a BLAS dot: OpenBLAS's threads would spin beside the walks' threads)
        spread_sum = float(np.einsum("i,i->", self._spread().ravel(), self._mse_weight))
        mse = spread_sum / ((self.chunks - 1) * self.paths)
        self._mse_at = (self.chunks, mse)
        return mse

    def energy(self):
        """Power balance of the run in the scene's units, per channel (3,)."""
        scale = self.scene.total_power / self.paths if self.paths else 0.0
        expand = (lambda a: np.repeat(a, 3)) if self.channels == 1 else (lambda a: a)
        # Absorbed as the paths tallied it (what arrived at each hit minus what left it, plus
        # what back sides stopped): the accounts balance path by path, so emitted = absorbed +
        # escaped + undistributed to rounding. Its expectation is sum_j (1 - R_j) I_j + blocked.
        absorbed = self.absorbed + self.blocked
        return {
            "emitted": expand(self.emitted * scale),
            "absorbed": expand(absorbed * scale),
            "escaped": expand(self.escaped * scale),
            "undistributed": expand(self.undistributed * scale),
            "blocked": expand(self.blocked * scale),
        }


def _check_solve_arguments(scene, estimator, paths, target_mse, threshold, exit_point, stop_rule, max_seconds, threads, sampling):
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
    stop_rule="predicted",
    progress=None,
    should_stop=None,
    max_seconds=None,
    threads=None,
    sampling="independent",
):
    """Radiosity of ``scene`` by shooting random walks.

    Runs ``paths`` paths, or, with ``target_mse``, the paths formula (2)/(3) predicts for it
    (``stop_rule="predicted"``) or until the batch estimate meets it (``"measured"``, capped
    by ``paths`` if given, else 64 times the prediction). ``sampling="stratified"`` (beyond
    the paper) allots each chunk's paths to sources in proportion to power and draws the first
    ray from a randomly shifted low-discrepancy set: same expectation, usually less noise;
    the predicted path counts are derived for the paper's plain ``"independent"`` sampling.
    ``progress(fraction, stats)`` and
    ``should_stop()`` are called from the calling thread between chunks; ``max_seconds``
    bounds the wall time. A stopped run returns the complete chunks it has.
    """
    _check_solve_arguments(scene, estimator, paths, target_mse, threshold, exit_point, stop_rule, max_seconds, threads, sampling)
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative whole number; got {seed!r}")
    threads = int(threads or min(os.cpu_count() or 1, 8))
    paths = None if paths is None else int(paths)  # numpy integers welcome
    start = time.perf_counter()

    prediction = predict(scene, estimator, target_mse=target_mse, threshold=threshold)
    measured_rule = stop_rule == "measured"
    if measured_rule:
        planned = prediction.paths_for(target_mse)
        cap = paths if paths is not None else MEASURED_CAP_FACTOR * planned
    else:
        planned = paths if paths is not None else prediction.paths_for(target_mse)
        cap = planned
    chunk = chunk_paths_for(prediction.expected_path_length, planned)
    tables = WalkTables(scene, estimator, threshold, exit_point, stratified=sampling == "stratified")
    total = _Accumulator(scene, tables, prediction)
    abort = threading.Event()
    seed_root = int(seed)

    def run_chunks(k, sizes):
        # Chunks k, k+1, ... of a group (estimators.walk_chunks) draw from the generator of
        # their first chunk.
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed_root, spawn_key=(k,))))
        return walk_chunks(tables, sizes, rng, abort)

    def chunk_size(k):
        return min(chunk, cap - k * chunk)

    chunk_count = math.ceil(cap / chunk)
    group = chunks_per_group(tables, chunk, prediction.expected_path_length)
    # Running the predicted paths for a target ends as "target"; running given paths, "paths".
    done_rule = STOP_TARGET if (paths is None and not measured_rule) else STOP_PATHS
    stopped = None
    pending = deque()
    next_chunk = 0
    executor = ThreadPoolExecutor(max_workers=threads, thread_name_prefix="radiosity")
    try:
        while stopped is None:
            # Keep every thread busy, with one chunk queued beyond those running.
            while next_chunk < chunk_count and len(pending) < threads + 1:
                sizes = [chunk_size(k) for k in range(next_chunk, min(next_chunk + group, chunk_count))]
                pending.append(executor.submit(run_chunks, next_chunk, sizes))
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
                    elapsed = time.perf_counter() - start
                    mse_now = total.measured_mse()
                    fraction = total.paths / cap
                    if measured_rule and mse_now > 0:  # NaN compares False
                        fraction = max(fraction, target_mse / mse_now)
                    progress(
                        min(1.0, fraction),
                        {
                            "paths": total.paths,
                            "rays": total.rays,
                            "seconds": elapsed,
                            "rays_per_second": total.rays / elapsed if elapsed > 0 else math.nan,
                            "measured_mse": mse_now,
                            "predicted_mse": prediction.mse_for(total.paths),
                        },
                    )
            # (The batch estimate costs passes over the patches: made only where it is used.)
            if measured_rule and total.chunks >= MIN_MEASURED_CHUNKS and total.measured_mse() <= target_mse:
                stopped = STOP_TARGET
            elif total.paths >= cap:
                stopped = done_rule
            else:
                stopped = _interrupted(should_stop, max_seconds, start)
    finally:
        # Chunks still running are abandoned at their next step; their partial tallies are dropped.
        abort.set()
        for future in pending:
            future.cancel()
        executor.shutdown(wait=True)

    seconds = time.perf_counter() - start
    reflected = total.reflected()
    radiosity = scene.emission + reflected
    n = total.paths
    return SolveResult(
        radiosity=radiosity,
        reflected=reflected,
        reflected_variance=total.reflected_variance(),
        paths=n,
        rays=total.rays,
        seconds=seconds,
        mean_path_length=total.rays / n if n else math.nan,
        predicted_mse=prediction.mse_for(n),
        measured_mse=total.measured_mse(),
        stopped=stopped,
        estimator=estimator,
        threshold=threshold if estimator != FINITE else None,
        exit_point=exit_point,
        sampling=sampling,
        seed=seed_root,
        threads=threads,
        chunks=total.chunks,
        energy=total.energy() if n else {},
        path_ends=dict(total.ended),
        prediction=prediction,
    )


def _interrupted(should_stop, max_seconds, start):
    if should_stop is not None and should_stop():
        return STOP_CANCELLED
    if max_seconds is not None and time.perf_counter() - start >= max_seconds:
        return STOP_TIME_LIMIT
    return None
