"""How a solve splits its paths into chunks and when it stops: what every method shares.

A method sizes its own chunks (``methods``); here are the sizes all start from, the stop rules'
numbers, and the plan a solve makes of them: the paths it runs at most and a chunk's paths.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .error_model import MAX_PATHS, mse_to_relative_rms, predict, relative_rms_to_mse
from ..names import MEASURED, SCALE_PAPER

# A chunk aims at about this many rays: enough wavefront steps that its last short ones cost
# little, few enough that progress and the batch error estimate come often.
RAYS_PER_CHUNK = 1 << 20
MAX_CHUNK_PATHS = 1 << 19
MIN_CHUNK_PATHS = 128
# The batch estimate wants this many chunks in a run when the run is small.
MIN_CHUNKS = 32
# With stop_rule="measured": never stop on fewer chunks than this, nor run past this many
# times the planned paths (unless paths= is given as the cap).
MIN_MEASURED_CHUNKS = 8
MEASURED_CAP_FACTOR = 64
# With stop_rule="measured" the run stops once the measured MSE plus MEASURED_STOP_Z of its own
# standard errors (Batches.mse_upper_bound) meets the target, on at least MEASURED_STOP_CHUNKS
# chunks: the estimate alone, read after every chunk, stops on its first lucky low reading, and
# few or heavy-tailed chunks make such readings common.
MEASURED_STOP_Z = 2.0
MEASURED_STOP_CHUNKS = 12
# A run whose chunks were sized on a guess of its paths reads this many before it sizes the rest
# (Method.later_chunk): the first of them run, the others wait.
RESIZE_AFTER = 2
# A method whose variance per path changes with its chunk (``Method.again_chunk``) sizes them once
# more, on what the first RESIZE_AGAIN_AFTER chunks measured (the first of the later size among
# them: how the variance changed with the size), for the chunks from RESIZE_AGAIN_FROM on; those
# between run meanwhile, on any number of threads the same.
RESIZE_AGAIN_AFTER = RESIZE_AFTER + 1
RESIZE_AGAIN_FROM = RESIZE_AGAIN_AFTER + 2


@dataclass(frozen=True)
class ChunkPlan:
    """How a solve splits its paths: the paper's prediction, the target as the paper's MSE
    (``target_mse``, None without one), the stop rule, the most paths it runs (``cap``) and the
    paths of a chunk."""

    prediction: object
    target_mse: float | None
    measured_rule: bool
    cap: int
    chunk: int


def paper_target(scene, settings):
    """The paper's MSE of ``settings.target_error`` on ``scene`` (None without a target): the
    one place the relative target becomes an MSE, which formulas (2)/(3) take."""
    if settings.target_error is None:
        return None
    return relative_rms_to_mse(predict(scene, settings.estimator, threshold=settings.threshold), settings.target_error)


def chunk_plan(scene, method, settings):
    """The chunk plan of a solve of ``method`` (a ``methods`` method) with ``settings`` (a
    settings.Settings). A method whose error the paper's formulas do not predict stops on its
    measured error."""
    target_mse, paths = paper_target(scene, settings), settings.paths
    prediction = predict(scene, settings.estimator, target_mse=target_mse, threshold=settings.threshold)
    measured_rule = settings.stop_rule == MEASURED or (not method.predicted and target_mse is not None)
    if measured_rule:
        planned = method.planned_paths(prediction.paths_for(target_mse))
        cap = paths if paths is not None else min(MEASURED_CAP_FACTOR * planned, MAX_PATHS)
    else:
        planned = paths if paths is not None else prediction.paths_for(target_mse)
        cap = planned
    chunk = method.chunk_paths(scene.patch_count, prediction.expected_path_length, planned,
                               settings.max_seconds is not None, guessed=measured_rule and paths is None)
    return ChunkPlan(prediction, target_mse, measured_rule, int(cap), int(chunk))


def chunk_paths_for(expected_path_length, planned_paths, min_chunks=MIN_CHUNKS):
    """A chunk of about RAYS_PER_CHUNK rays, at least ``min_chunks`` of them in the plan."""
    by_rays = int(RAYS_PER_CHUNK / max(expected_path_length, 1.0))
    by_batches = math.ceil(planned_paths / min_chunks)
    return int(min(MAX_CHUNK_PATHS, max(MIN_CHUNK_PATHS, min(by_rays, by_batches))))


def paths_to_target(paths, measured_mse, target_mse, chunk, cap):
    """The paths a run stopping on its measured error is expected to end at, from its MSE after
    ``paths`` (which falls as 1 / paths): whole chunks, at least MEASURED_STOP_CHUNKS, at most
    ``cap``. NaN MSE (fewer than 2 chunks) or target: NaN; a target of 0 (nothing reflected yet)
    with an error: the cap."""
    if not measured_mse >= 0 or paths <= 0 or not target_mse >= 0:
        return math.nan
    if target_mse == 0 and measured_mse > 0:
        return float(cap)
    needed = paths * measured_mse / target_mse if measured_mse > 0 else 0.0
    chunks = max(MEASURED_STOP_CHUNKS, math.ceil(needed / chunk))
    return float(min(cap, chunks * chunk))


def resizes(plan, settings):
    """Whether a run of ``plan`` sizes its chunks after its first RESIZE_AFTER: a measured stop
    at a target, on a guess of its paths (no paths, chunk or time limit given)."""
    return plan.measured_rule and plan.target_mse is not None and settings.paths is None \
        and settings.chunk_paths is None and settings.max_seconds is None


def resize_inputs(total, target_mse):
    """(variance per path, MSE) a run's later chunks are sized for after its first ones
    (``total``, Batches): the measured variance at the upper end of its own noise
    (MEASURED_STOP_Z standard errors of a chi-square of ``spread_terms`` degrees of freedom),
    and ``target_mse`` less what the stop rule's bound adds to the estimate at
    MEASURED_STOP_CHUNKS chunks of that noise. None where nothing is measured yet."""
    mse = total.measured_mse()
    if not mse > 0:
        return None
    noise = math.sqrt(2.0 / total.spread_terms())
    variance = mse * total.paths * (1.0 + MEASURED_STOP_Z * noise)
    return variance, target_mse / (1.0 + MEASURED_STOP_Z * noise / math.sqrt(MEASURED_STOP_CHUNKS - 1))


def chunk_variances(sizes, increments):
    """(K,) the variance per path each of the chunks of ``sizes`` paths measured, from the Batches'
    ``increments`` (K - 1 of them, one a chunk from the second on), whose expectation is
    (N v_k + n_k V) / (N + n_k) for a chunk of n_k paths and v_k a path after N paths of mean
    variance a path V = sum_i n_i v_i / N (``expected_increments``). The first chunk has no increment
    of its own: it is given the second's, of its size."""
    sizes = np.asarray(sizes, np.float64)
    if len(sizes) < 2 or len(increments) < len(sizes) - 1 or sizes[0] != sizes[1]:
        raise ValueError(f"chunk_variances needs two first chunks of one size and an increment a chunk from the second on; "
                         f"got sizes {sizes.tolist()}, {len(increments)} increments")
    v = np.empty(len(sizes))
    v[0] = v[1] = increments[0]  # (two chunks alike: E = v)
    paths, weighted = sizes[0] + sizes[1], (sizes[0] + sizes[1]) * increments[0]
    for k in range(2, len(sizes)):
        n = sizes[k]
        v[k] = ((paths + n) * increments[k - 1] - n * weighted / paths) / paths
        paths, weighted = paths + n, weighted + n * v[k]
    return v


def expected_increments(sizes, variances):
    """(K - 1,) the expected Batches increments of chunks of ``sizes`` paths and ``variances`` per
    path: (N v_k + n_k V) / (N + n_k), N the paths before chunk k and V their variance a path,
    sum_i n_i v_i / N. Their mean over N is the batch estimate's expectation."""
    out, paths, weighted = [], float(sizes[0]), float(sizes[0]) * float(variances[0])
    for n, v in zip(sizes[1:], variances[1:]):
        out.append((paths * v + n * weighted / paths) / (paths + n))
        paths, weighted = paths + n, weighted + n * v
    return np.asarray(out)


def expected_bound(sizes, variances, read, terms, z=MEASURED_STOP_Z):
    """What the measured stop rule's bound (``Batches.mse_upper_bound``) is expected to read on
    chunks of ``sizes`` paths and ``variances`` per path, whose first increments are ``read``
    (their values as measured): the increments' mean plus ``z`` standard errors of it, over the
    paths; the increments yet to come at their expectation (``expected_increments``), and their
    spread that of the expectations plus each one's own noise (a chi-square of ``terms`` degrees
    of freedom, ``Batches.spread_terms``)."""
    increments = expected_increments(sizes, variances)
    increments[:len(read)] = read
    mean = float(increments.mean())
    coming = (len(increments) - len(read)) / len(increments)
    spread = math.sqrt(float(increments.var(ddof=1)) + coming * mean * mean * 2.0 / terms)
    return (mean + z * spread / math.sqrt(len(increments))) / float(np.sum(sizes))


def target_now(plan, target_error, error_scale, mean_reflected):
    """The MSE a measured stop holds a run to: the plan's paper MSE on the paper's scale; on the
    measured scale the same relative error of the run's own mean reflected radiosity b_now,
    (target_error b_now)^2. NaN (never met) before any path; 0 while nothing is reflected
    (meets_target waits for light)."""
    if error_scale == SCALE_PAPER:
        return plan.target_mse
    return (target_error * mean_reflected) ** 2


def relative_error(mse, error_scale, prediction, mean_reflected):
    """An MSE as a relative RMS error on ``error_scale`` (no error: 0; NaN where unknown)."""
    if error_scale == SCALE_PAPER:
        return mse_to_relative_rms(prediction, mse)
    if mse == 0:
        return 0.0
    return math.sqrt(mse) / mean_reflected if mse > 0 and mean_reflected > 0 else math.nan


def meets_target(total, target_mse):
    """Whether a run's batches (``Batches``) meet ``target_mse`` by the measured stop rule. (The
    batch estimate costs passes over the patches: read only where the rule is used.) Never while
    nothing is reflected: no error about no light measures nothing (a gathering that has not yet
    found a narrow spot's cone)."""
    return total.chunks >= MEASURED_STOP_CHUNKS and total.measured_mse() <= target_mse \
        and target_bound(total) <= target_mse and total.mean_reflected() > 0


def target_bound(total):
    """The bound the measured stop rule holds to the target: the batches' MSE plus
    MEASURED_STOP_Z of its standard errors."""
    return total.mse_upper_bound(MEASURED_STOP_Z)
