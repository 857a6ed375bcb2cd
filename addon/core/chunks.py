"""A resolved method's chunks run to the settings' stop: the chunk plan (``estimate.plan``), the
walk tables and the method's state, the runner (this machine's threads or a cluster), the chunks
submitted in order and their tallies added in order (``estimate.batches``), stopped by the plan's
rule, a cancel or the time limit; then the SolveResult.

A run's result depends only on the seed and the chunk plan, never on the number of threads or on
timing: bitwise reproducible. The chunks are also the batches of the run's error estimate.
"""
from __future__ import annotations

import math
import os
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from .distributed.cluster import ClusterRunner, WalkParameters
from .distributed.cluster_connect import cluster_address
from .distributed.runners import ThreadRunner
from .estimate.batches import Batches
from .estimate.plan import (RESIZE_AFTER, RESIZE_AGAIN_AFTER, RESIZE_AGAIN_FROM, chunk_plan, meets_target, paths_to_target,
                            relative_error, resize_inputs, resizes, target_bound, target_now)
from .methods.tables import WalkTables
from .names import (
    FINITE,
    SCALE_MEASURED,
    SCALE_PAPER,
    SHOT,
    STOP_CANCELLED,
    STOP_PATHS,
    STOP_TARGET,
    STOP_TIME_LIMIT,
    WALK,
)

POLL_SECONDS = 0.05


@dataclass
class SolveResult:
    radiosity: np.ndarray          # (P,3) B = E + b
    reflected: np.ndarray          # (P,3) b
    reflected_variance: np.ndarray  # (P,3) batch-means estimate of Var(b), NaN below 2 chunks
    irradiance: np.ndarray         # (P,3) H, the light arriving (B = E + R H): Cycles' DIFFUSE bake without colour
    irradiance_variance: np.ndarray  # (P,3) float32 batch-means estimate of Var(H), NaN below 2 chunks
    paths: int
    rays: int
    seconds: float
    mean_path_length: float
    predicted_mse: float
    measured_mse: float
    mean_reflected: float  # the area-weighted mean of ``reflected`` over patches and channels
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
    per_source: object = None  # estimate.per_source.PerSource (per_source=True), else None
    error_scale: str = SCALE_PAPER  # what relative_error is relative to (names.ERROR_SCALES)
    direct_irradiance: np.ndarray | None = None  # (P,3) H's part straight from the sources, where gathered apart
    chunk_sizes: tuple = ()  # each chunk's paths, in order

    @property
    def relative_error(self):
        """The measured error as a relative RMS on the run's ``error_scale`` (NaN: unknown)."""
        return relative_error(self.measured_mse, self.error_scale, self.prediction, self.mean_reflected)

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else math.nan


def run(scene, settings, method, start=None, progress=None, should_stop=None):
    """The SolveResult of ``method`` (a ``methods`` Method, resolved: no "auto") run on ``scene``
    as ``settings`` (checked by the solver) ask; ``start`` the clock the time limit counts from
    (default now). ``progress(fraction, stats)`` and ``should_stop()`` are called from the calling
    thread between chunks."""
    start = time.perf_counter() if start is None else start
    plan = chunk_plan(scene, method, settings)
    chunk = plan.chunk if settings.chunk_paths is None else int(settings.chunk_paths)
    sized = method.sizes_later_chunks and resizes(plan, settings)  # (its later chunks sized by its first ones)
    tables = WalkTables(scene, settings.estimator, settings.threshold, settings.exit_point, settings.sampling,
                        settings.speedups, groups=settings.groups, direct_apart=settings.direct_apart)
    state = method.create(scene, tables, chunk, int(settings.seed), plan.prediction)
    runner = _runner(scene, settings, method, state)
    # Running the predicted paths for a target ends as "target"; running given paths, "paths".
    done_rule = STOP_TARGET if (settings.paths is None and not plan.measured_rule) else STOP_PATHS
    chunks = _Run(plan, chunk, settings, done_rule, start, method, sized)
    total, stopped = chunks.chunks(scene, state, runner, int(settings.seed), progress, should_stop, settings.max_seconds)
    return _result(scene, total, stopped, chunks, method, chunks.state, settings, runner.threads)


def _runner(scene, settings, method, state):
    """Where the chunks run: this machine's threads, or the cluster's workers, which rebuild
    the method's state from what it is made of."""
    if settings.cluster is None:
        return ThreadRunner(int(settings.threads or min(os.cpu_count() or 1, 8)))
    parameters = WalkParameters(settings.estimator, float(settings.threshold), settings.exit_point, settings.sampling,
                                state.tables.speedups, method.name, method.direct_light, state.spec, settings.groups,
                                state.tables.direct_apart)
    cluster = settings.cluster
    cluster = cluster_address(cluster) if isinstance(cluster, str) else cluster  # (its form; connecting comes later)
    return ClusterRunner(cluster, scene, parameters)


class _Run:
    """A run of a plan's chunks: submitted in order, a group at a time, while the runner has
    room; their tallies added in order; stopped by the plan's rule, a cancel or the time limit.
    A plan sized on a guess of its paths (``sized``: a measured stop, no paths, chunk or time limit
    given) sizes its chunks after its first RESIZE_AFTER (``Method.later_chunk``): the later ones
    wait for them, so that every chunk's size is the same on any number of threads. A method whose
    variance per path changes with the chunk sizes them again from RESIZE_AGAIN_FROM on, on the
    first RESIZE_AGAIN_AFTER (``Method.again_chunk``), the chunks between running meanwhile."""

    def __init__(self, plan, chunk, settings, done_rule, start, method, sized=False):
        self.plan, self.chunk, self.start, self.method = plan, chunk, start, method
        self.measured = plan.measured_rule and plan.target_mse is not None  # (else the run stops on its paths)
        self.target_error, self.error_scale = settings.target_error, settings.error_scale
        self.done_rule = done_rule
        self.replaced = settings.replaced_direct
        self.resize_at = RESIZE_AFTER if sized else None  # (chunks measured when the next ones are sized)
        self.wait_from = self.resize_at  # (the first chunk that waits for that)
        self.again = None  # (a size made at RESIZE_AGAIN_AFTER chunks, taken from chunk wait_from on)
        self.sizes = []  # each chunk's paths, as submitted
        self.state = None

    def target(self, total):
        """The MSE the measured stop rule holds the run to now (None: it stops on its paths): the
        target's, less the share left for a replaced direct light's own error (Batches.kept_share)."""
        if not self.measured:
            return None
        return total.kept_share() * target_now(self.plan, self.target_error, self.error_scale, total.mean_reflected())

    def chunks(self, scene, state, runner, seed, progress, should_stop, max_seconds):
        """(Batches of the chunks added, why the run stopped)."""
        plan, self.state = self.plan, state
        total = Batches(scene, state.tables, increments=plan.measured_rule, replaced=self.replaced)
        group = state.group(self.chunk, plan.prediction.expected_path_length)
        stopped, pending, next_chunk, submitted = None, deque(), 0, 0
        try:
            runner.start(state, seed)
            while stopped is None:
                while submitted < plan.cap and len(pending) < runner.slots and not self._waiting(next_chunk):
                    if self.again is not None and next_chunk >= self.wait_from:
                        self._take(self.again, runner)
                        self.again, group = None, self.state.group(self.chunk, plan.prediction.expected_path_length)
                    sizes = []
                    while len(sizes) < group and submitted < plan.cap:
                        sizes.append(min(self.chunk, plan.cap - submitted))
                        submitted += sizes[-1]
                    self.sizes += sizes
                    pending.append(runner.submit(next_chunk, sizes))
                    next_chunk += len(sizes)
                if not pending:
                    return total, self.done_rule
                tallies = None
                while tallies is None and stopped is None:
                    try:
                        tallies = pending[0].result(timeout=POLL_SECONDS)
                    except TimeoutError:
                        stopped = _interrupted(should_stop, max_seconds, self.start)
                if stopped:
                    break
                pending.popleft()
                stopped = self._add(total, tallies, progress, should_stop, max_seconds)
                if stopped is None and self.resize_at is not None and total.chunks >= self.resize_at:
                    self._resize(scene, total, runner)
                    group = self.state.group(self.chunk, plan.prediction.expected_path_length)
        finally:
            runner.stop(pending)  # tasks still running are abandoned; their partial tallies dropped
            pending.clear()  # (their futures hold a tally, or a traceback and the walk's arrays in it)
        return total, stopped

    def _waiting(self, next_chunk):
        """Whether chunk ``next_chunk`` waits for the first ones to size it."""
        return self.resize_at is not None and next_chunk >= self.wait_from

    def _resize(self, scene, total, runner):
        """The later chunks' size (and the state they read) from the first ones' measured error;
        where that changed it, the chunks from RESIZE_AGAIN_FROM on wait to be sized again
        (``_resize_again``)."""
        if self.resize_at == RESIZE_AGAIN_AFTER:
            return self._resize_again(scene, total)
        self.resize_at, target = None, self.target(total)
        inputs = None if target is None else resize_inputs(total, target)
        if inputs is None:
            return
        variance, target = inputs
        chunk = self.method.later_chunk(scene.patch_count, self.chunk, total.chunks, variance, target, self.plan.chunk)
        if chunk != self.chunk:
            self._take(chunk, runner)
            self.resize_at, self.wait_from = RESIZE_AGAIN_AFTER, RESIZE_AGAIN_FROM

    def _resize_again(self, scene, total):
        """The size of the chunks from ``wait_from`` on, on what the first ones measured, the first
        of the later size among them too (``Method.again_chunk``): taken once the chunks before
        are submitted (``self.again``)."""
        self.resize_at, target = None, self.target(total)
        measured = self.sizes[:total.chunks]
        running = [self.chunk] * max(0, self.wait_from - total.chunks)
        chunk = None if not target else self.method.again_chunk(
            scene.patch_count, measured, total.increments[:len(measured) - 1], total.spread_terms(), target, running,
            self.plan.chunk)
        self.again = None if chunk is None or chunk == self.chunk else chunk

    def _take(self, chunk, runner):
        """Chunks of ``chunk`` paths from the next submitted on, and the state they read."""
        self.state = self.method.resized(self.state, self.chunk, chunk)
        runner.restate(self.state)
        self.chunk = chunk

    def _add(self, total, tallies, progress, should_stop, max_seconds):
        """Adds a task's tallies (progress once per chunk); why the run stops now, or None."""
        for tally in tallies:
            total.add(tally)
            if progress is not None:
                progress(*_progress(total, self, self.start))
        target = self.target(total)
        if target is not None and meets_target(total, target):
            return STOP_TARGET
        if total.paths >= self.plan.cap:
            return self.done_rule
        return _interrupted(should_stop, max_seconds, self.start)


def _result(scene, total, stopped, run, method, state, settings, threads):
    """The SolveResult of a run's batches: one (P,3) result at a time, the sums of squares let
    go of once the error is estimated."""
    n = total.paths
    per_source = None if total.groups is None else total.groups.results(
        scene, total, settings.target_error, measured_scale=settings.error_scale == SCALE_MEASURED)
    reflected_variance = total.reflected_variance()
    irradiance_variance = total.irradiance_variance()
    measured_mse = total.let_go_of_squares()
    mean_reflected = total.mean_reflected()
    reflected = total.reflected()
    prediction = run.plan.prediction
    return SolveResult(
        radiosity=scene.emission + reflected,
        reflected=reflected,
        reflected_variance=reflected_variance,
        irradiance=total.irradiance(),
        direct_irradiance=total.direct_irradiance(),
        irradiance_variance=irradiance_variance,
        paths=n,
        rays=total.rays,
        seconds=time.perf_counter() - run.start,
        mean_path_length=total.rays / n if n else math.nan,
        predicted_mse=prediction.mse_for(n) if method.predicted else math.nan,
        measured_mse=measured_mse,
        mean_reflected=mean_reflected,
        stopped=stopped,
        chunks=total.chunks,
        energy=total.energy() if n else {},
        path_ends=dict(total.ended),
        prediction=prediction,
        speedups=state.tables.speedups,
        direct_light=method.direct_light,
        method=method.name,
        gather_rays=state.gather_rays,
        per_source=per_source,
        estimator=settings.estimator,
        exit_point=settings.exit_point,
        threshold=settings.threshold if settings.estimator != FINITE else None,
        sampling=settings.sampling,
        seed=int(settings.seed),
        threads=threads,
        error_scale=settings.error_scale,
        chunk_sizes=tuple(run.sizes[:total.chunks]),
    )


def _progress(total, run, start):
    """(fraction, stats) for ``progress``: the share of the paths the run is expected to end at
    (the cap; with the measured stop rule, where the bound it stops on says it will meet the
    target), and the seconds left at the run's pace so far (NaN until it is known)."""
    elapsed = time.perf_counter() - start
    mse_now = total.measured_mse()
    prediction, cap = run.plan.prediction, run.plan.cap
    expected = float(cap)
    target = run.target(total)
    if target is not None:
        bound = target_bound(total)
        expected = paths_to_target(total.paths, bound if bound == bound else mse_now, target, run.chunk, cap)
    fraction = total.paths / expected if expected > 0 else 0.0  # (NaN > 0 is False)
    left = (expected - total.paths) * elapsed / total.paths if total.paths else math.nan
    return min(1.0, fraction), {
        "paths": total.paths,
        "rays": total.rays,
        "seconds": elapsed,
        "rays_per_second": total.rays / elapsed if elapsed > 0 else math.nan,
        "measured_mse": mse_now,
        "relative_error": relative_error(mse_now, run.error_scale, prediction, total.mean_reflected()),  # NaN while unknown
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
