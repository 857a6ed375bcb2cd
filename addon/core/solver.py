"""solve(): a scene's radiosity by its method's chunks, on threads or a cluster, to a path count
or an error target.

Its stages: check the arguments, choose the method (``methods``: Automatic's choice, the
direct light), plan the chunks (``plan``), build the state they read (the walk tables and the
method's own), run them, and pack the result. Chunk tallies are added in chunk order, so a
run's result depends only on the seed and the chunk plan, never on the number of threads or on
timing: bitwise reproducible. The chunks are also the batches of the run's error estimate
(``batches``).
"""
from __future__ import annotations

import math
import os
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from . import methods
from .estimate.batches import Batches
from .distributed.cluster import ClusterRunner, WalkParameters
from .distributed.cluster_connect import cluster_address
from .scene.diagnostics import check_bounces
from .estimate.error_model import MAX_PATHS, check_estimator, check_positive
from .names import (
    AUTO,
    ERROR_SCALES,
    EXIT_POINTS,
    EXIT_RANDOM,
    FINITE,
    GATHERED,
    INDEPENDENT,
    MEASURED,
    PREDICTED,
    SAMPLINGS,
    SCALE_MEASURED,
    SCALE_PAPER,
    SHOT,
    STOP_CANCELLED,
    STOP_PATHS,
    STOP_RULES,
    STOP_TARGET,
    STOP_TIME_LIMIT,
    WALK,
)
from .estimate.plan import chunk_plan, meets_target, paths_to_target, relative_error, target_bound, target_now
from .distributed.runners import ThreadRunner
from .estimate.grouping import check_per_source, source_groups
from .methods.speedups import Speedups
from .methods.tables import WalkTables

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
    per_source: object = None  # relighting.PerSource (per_source=True), else None
    error_scale: str = SCALE_PAPER  # what relative_error is relative to (names.ERROR_SCALES)
    direct_irradiance: np.ndarray | None = None  # (P,3) H's part straight from the sources, where gathered apart

    @property
    def relative_error(self):
        """The measured error as a relative RMS on the run's ``error_scale`` (NaN: unknown)."""
        return relative_error(self.measured_mse, self.error_scale, self.prediction, self.mean_reflected)

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else math.nan


def solve(scene, estimator=FINITE, *, paths=None, target_mse=None, threshold=1e-3, seed=0, exit_point=EXIT_RANDOM,
          stop_rule=PREDICTED, progress=None, should_stop=None, max_seconds=None, threads=None, sampling=INDEPENDENT,
          speedups=None, direct_light=None, cluster=None, method=WALK, chunk_paths=None, per_source=False, groups=None,
          error_scale=SCALE_PAPER, direct_apart=False):
    """Radiosity of ``scene`` by its method's chunks (the paper's shooting random walks unless
    ``method`` says otherwise).

    Runs ``paths`` paths, or, with ``target_mse``, the paths formula (2)/(3) predicts for it
    (``stop_rule="predicted"``) or until the batch estimate meets it (``"measured"``, capped
    by ``paths`` if given, else 64 times the prediction). ``error_scale`` says what the error is
    relative to: the paper's b_ave (``"paper"``, a closed scene's mean reflected radiosity, which
    ``target_mse`` is then made with: ``relative_rms_to_mse``), or the run's own mean reflected
    radiosity as it goes (``"measured"``: the same relative error, ``plan.target_now``, where light
    leaves the scene and b_ave overstates the light in it). ``direct_apart``: where chunks gather
    the direct light, its part too (``SolveResult.direct_irradiance``). ``direct_light="gathered"`` (beyond the
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
    it where its chunks give every patch enough rays, else the walk (:func:`.methods.choose`;
    with ``per_source``, where it would run the two-way iteration, pilots of both measure which
    is cheaper on this machine; ``SolveResult.method`` says which ran).
    ``progress(fraction, stats)`` and ``should_stop()`` are called from the calling thread
    between chunks (``stats["radiosity"](dtype)`` gives the result so far); ``max_seconds``
    bounds the wall time. A stopped run returns the complete chunks it has. ``speedups`` (:class:`.speedups.Speedups`) switches speed-ups on or off.
    ``chunk_paths`` replaces the plan's chunk size (the estimate's pilot: ``forecast``).
    ``per_source=True`` also gives each source group's own result from the same rays
    (``SolveResult.per_source``, a relighting.PerSource; ``groups``: grouping.source_groups's,
    default each light, and the patches of each emittance): what relighting.relight recombines.
    """
    start = time.perf_counter()  # (Automatic's pilots, with per-source results, count in the time)
    _check_amounts(estimator, threshold, paths, target_mse, max_seconds, threads, chunk_paths)
    groups = _groups(scene, per_source, groups)
    method = _choose(scene, estimator, method, direct_light, paths, target_mse, threshold, max_seconds,
                     dict(per_source=per_source, groups=groups, exit_point=exit_point, sampling=sampling, threads=threads,
                          seed=seed, stop_rule=stop_rule))
    _check(scene, estimator, threshold, target_mse, seed, exit_point, stop_rule, sampling, speedups, method, error_scale)
    cluster = cluster_address(cluster) if isinstance(cluster, str) else cluster  # (its form; connecting comes later)
    paths = None if paths is None else int(paths)  # (numpy integers welcome)
    plan = chunk_plan(scene, method, estimator, paths=paths, target_mse=target_mse, threshold=threshold,
                      stop_rule=stop_rule, max_seconds=max_seconds)
    chunk = plan.chunk if chunk_paths is None else int(chunk_paths)
    tables = WalkTables(scene, estimator, threshold, exit_point, sampling, speedups, groups=groups, direct_apart=direct_apart)
    state = method.create(scene, tables, chunk, int(seed), plan.prediction)
    runner = _runner(scene, cluster, threads, method, state, estimator, threshold, exit_point, sampling, groups)
    # Running the predicted paths for a target ends as "target"; running given paths, "paths".
    done_rule = STOP_TARGET if (paths is None and not plan.measured_rule) else STOP_PATHS
    run = _Run(plan, chunk, target_mse if plan.measured_rule else None, done_rule, start, error_scale)
    total, stopped = run.chunks(scene, state, runner, int(seed), progress, should_stop, max_seconds)
    return _result(scene, total, stopped, run, method, state, target_mse, estimator=estimator, exit_point=exit_point,
                   threshold=threshold if estimator != FINITE else None, sampling=sampling, seed=int(seed),
                   threads=runner.threads, error_scale=error_scale)


def _choose(scene, estimator, method, direct_light, paths, target_mse, threshold, max_seconds, pilot):
    """The Method the solve runs: Automatic's choice (``methods.automatic``; with per-source
    results, measured by ``pilot``'s arguments) where it is asked for, with the direct light
    asked (None: the method's own)."""
    if method == AUTO:
        method = methods.choose(scene, estimator, paths=paths, target_mse=target_mse, threshold=threshold,
                                max_seconds=max_seconds, direct_light=direct_light, **pilot)
    return methods.create(method, direct_light)


def _check_amounts(estimator, threshold, paths, target_mse, max_seconds, threads, chunk_paths):
    """ValueError, in one line, for an estimator, threshold or amount the solve cannot take."""
    check_estimator(estimator, threshold)
    for name, value, integer in (("paths", paths, True), ("target_mse", target_mse, False),
                                 ("max_seconds", max_seconds, False), ("threads", threads, True),
                                 ("chunk_paths", chunk_paths, True)):
        check_positive(name, value, integer=integer)
    if paths is None and target_mse is None:
        raise ValueError("give paths (a path count) or target_mse (an error target)")
    if paths is not None and paths > MAX_PATHS:
        raise ValueError(f"paths must be at most {MAX_PATHS:,} (2^50: more than any run can trace); got {paths!r}")


def _check(scene, estimator, threshold, target_mse, seed, exit_point, stop_rule, sampling, speedups, method, error_scale):
    """ValueError, in one line, for any other argument the solve cannot run with; else nothing."""
    if exit_point not in EXIT_POINTS:
        raise ValueError(f"exit_point must be one of {', '.join(EXIT_POINTS)}; got {exit_point!r}")
    if sampling not in SAMPLINGS:
        raise ValueError(f"sampling must be one of {', '.join(SAMPLINGS)}; got {sampling!r}")
    if method.direct_light == SHOT and scene.lights.gathered_only():
        why = "; ".join(f"light '{name}' {reason}" for name, reason in scene.lights.gathered_only())
        raise ValueError(f"{why}: a shooting walk cannot carry its direct light; use direct_light='{GATHERED}' "
                         "(shadow rays from each patch)")
    if stop_rule not in STOP_RULES:
        raise ValueError(f"stop_rule must be one of {', '.join(STOP_RULES)}; got {stop_rule!r}")
    if error_scale not in ERROR_SCALES:
        raise ValueError(f"error_scale must be one of {', '.join(ERROR_SCALES)}; got {error_scale!r}")
    if stop_rule == MEASURED and target_mse is None:
        raise ValueError("stop_rule='measured' needs a target_mse")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed must be a non-negative whole number; got {seed!r}")
    if speedups is not None and not isinstance(speedups, Speedups):
        raise ValueError(f"speedups must be a Speedups; got {speedups!r}")
    check_bounces(scene, estimator, threshold)


def _groups(scene, per_source, groups):
    """The SourceGroups a per-source solve tallies (None: no per-source results); ValueError in
    one line where they cannot be."""
    if not per_source:
        if groups is not None:
            raise ValueError("groups are for per-source results: give per_source=True with them")
        return None
    groups = source_groups(scene) if groups is None else groups
    check_per_source(scene, groups)
    return groups


def _runner(scene, cluster, threads, method, state, estimator, threshold, exit_point, sampling, groups=None):
    """Where the chunks run: this machine's threads, or the cluster's workers, which rebuild
    the method's state from what it is made of."""
    if cluster is None:
        return ThreadRunner(int(threads or min(os.cpu_count() or 1, 8)))
    parameters = WalkParameters(estimator, float(threshold), exit_point, sampling, state.tables.speedups, method.name,
                                method.direct_light, state.spec, groups, state.tables.direct_apart)
    return ClusterRunner(cluster, scene, parameters)


class _Run:
    """A run of a plan's chunks: submitted in order, a group at a time, while the runner has
    room; their tallies added in order; stopped by the plan's rule, a cancel or the time limit."""

    def __init__(self, plan, chunk, measured_target, done_rule, start, error_scale):
        self.plan, self.chunk, self.start = plan, chunk, start
        self.measured_target = measured_target  # (None: the run stops on its paths)
        self.done_rule = done_rule
        self.error_scale = error_scale

    def target(self, total):
        """The MSE the measured stop rule holds the run to now (None: it stops on its paths)."""
        if self.measured_target is None:
            return None
        return target_now(self.measured_target, self.error_scale, self.plan.prediction, total.mean_reflected())

    def chunks(self, scene, state, runner, seed, progress, should_stop, max_seconds):
        """(Batches of the chunks added, why the run stopped)."""
        plan, chunk = self.plan, self.chunk
        total = Batches(scene, state.tables, increments=plan.measured_rule)
        count = math.ceil(plan.cap / chunk)
        group = state.group(chunk, plan.prediction.expected_path_length)
        stopped, pending, next_chunk = None, deque(), 0
        try:
            runner.start(state, seed)
            while stopped is None:
                while next_chunk < count and len(pending) < runner.slots:
                    sizes = [min(chunk, plan.cap - k * chunk) for k in range(next_chunk, min(next_chunk + group, count))]
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
        finally:
            runner.stop(pending)  # tasks still running are abandoned; their partial tallies dropped
            pending.clear()  # (their futures hold a tally, or a traceback and the walk's arrays in it)
        return total, stopped

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


def _result(scene, total, stopped, run, method, state, target_mse, **settings):
    """The SolveResult of a run's batches: one (P,3) result at a time, the sums of squares let
    go of once the error is estimated."""
    n = total.paths
    per_source = None if total.groups is None else total.groups.results(
        scene, total, target_mse, measured_scale=settings["error_scale"] == SCALE_MEASURED)
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
        **settings,
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
