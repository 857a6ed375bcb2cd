"""How large the two-way iteration's chunks are: its variance per path grows as they shrink.

Beyond the paper. A two-way chunk's variance per path falls as the chunk grows (its last, sparse
generations and the roulette that ends them carry a smaller share of its light), as
v_inf (1 + G P / n) for chunks of n paths over P patches. A run to an error target stops on its
measured error, on at least MEASURED_STOP_CHUNKS chunks (K): its chunks are sized so that the
stop rule is expected to pass on about that many, at the fewest paths. The plan's chunks are
sized on the paper's guess (``balanced_chunk``); after RESIZE_AFTER of them the rest on what they
measured, at the suite's growth (``later_chunk``); where that changed their size, again from
RESIZE_AGAIN_FROM on, on the growth the two sizes measured (``measured_growth``) and the stop rule's
bound as the chunks are expected to read it (``again_chunk``, ``plan.expected_bound``).
"""
from __future__ import annotations

import math

from ..estimate.plan import MEASURED_STOP_CHUNKS, MEASURED_STOP_Z, chunk_variances, expected_bound, expected_increments

# The variance per path in chunks of n paths over P patches, as v_inf (1 + TWO_WAY_GROWTH P / n):
# fitted over chunk sizes 4x apart, 6-30 in the suite and sample scenes (docs/performance.md,
# "The time prediction").
TWO_WAY_GROWTH = 12.0
# Growths measured on a run (``measured_growth``) are held to this: the suite's largest few times over.
TWO_WAY_MOST_GROWTH = 100.0
# Chunks are sized again (again_chunk) only where the measured error is worth this many independent
# terms (Batches.spread_terms): each increment then known to sqrt(2 / terms), 6%, or better.
AGAIN_TERMS = 500.0
# Two chunk sizes tell a growth where TWO_WAY_GROWTH would put their variances per path this far apart.
SIZES_APART = 1.1


def balanced_chunk(patch_count, planned_paths):
    """The chunk of n paths at which the fewest chunks a measured stop reads (MEASURED_STOP_CHUNKS
    of them, K) hold the paths the plan's run takes at that size, its variance per path grown
    as (1 + G P / n) (TWO_WAY_GROWTH): K n = N (1 + G P / n), for N the plan's paths. Smaller
    chunks need more paths for the same error; larger ones run past it."""
    k, n = MEASURED_STOP_CHUNKS, float(planned_paths)
    return math.ceil((n + math.sqrt(n * n + 4.0 * k * TWO_WAY_GROWTH * patch_count * n)) / (2.0 * k))


def later_chunk(patch_count, first, done, variance, target_mse, least, most):
    """The smallest chunk n from ``least`` to ``most`` at which a run whose first ``done`` chunks
    of ``first`` paths measured ``variance`` per path is expected to meet ``target_mse`` on the
    fewest chunks the stop rule reads (MEASURED_STOP_CHUNKS, K): the rest of them of n paths,
    their variance per path as (1 + G P / n) (TWO_WAY_GROWTH, the suite's middle: a scene whose
    growth differs runs a few more chunks), the batch estimate of chunks of two sizes as Batches
    makes it (``later_estimate``: each chunk's spread counts alike, and the smaller chunks' larger
    variance per path weighs more than in the true error, which it then covers); ``most`` where
    none does; ``first``, at most ``most``, where nothing is measured to size on. A plan's paths are
    the paper's guess for the walk, often several times off; a run starts on the plan's chunks and
    sizes the rest on what they measured."""
    if MEASURED_STOP_CHUNKS <= done or not (variance > 0 and target_mse > 0):
        return min(first, most)
    return _smallest(lambda n: later_estimate(patch_count, first, done, variance, n) <= target_mse, least, most)


def measured_growth(patch_count, first, later, first_variance, later_variance):
    """G of the variance per path v_inf (1 + G P / n) through the variances per path measured at
    two chunk sizes, from 0 to TWO_WAY_MOST_GROWTH; None where the sizes are too near to tell
    (their (1 + G P / n) within SIZES_APART of each other at TWO_WAY_GROWTH)."""
    a, b = patch_count / float(first), patch_count / float(later)
    apart = (1.0 + TWO_WAY_GROWTH * b) / (1.0 + TWO_WAY_GROWTH * a)
    if not (first_variance > 0 and later_variance > 0) or abs(math.log(apart)) < math.log(SIZES_APART):
        return None
    r = later_variance / first_variance
    if (r - 1.0) * (b - a) <= 0:  # (the variance did not grow as the chunks shrank: none to see)
        return 0.0
    denominator = b - r * a  # (G = (r - 1) / (b - r a); r beyond b / a: more than any G makes)
    return TWO_WAY_MOST_GROWTH if (r - 1.0) * denominator <= 0 else min((r - 1.0) / denominator, TWO_WAY_MOST_GROWTH)


def again_chunk(patch_count, sizes, increments, terms, target_mse, running, least, most):
    """The smallest chunk n from ``least`` to ``most`` at which the measured stop rule's bound
    (``plan.expected_bound``) is expected to meet ``target_mse`` on MEASURED_STOP_CHUNKS chunks (K):
    the first of ``sizes`` paths, measured (``increments``, ``terms``), then those of ``running``
    paths, the rest of n paths. The variances per path those measured (``plan.chunk_variances``),
    the last one's taken MEASURED_STOP_Z of its noise up (a chi-square of ``terms``), grown as
    (1 + G P / n) for the G they measured (``measured_growth``; TWO_WAY_GROWTH where the sizes were
    too near). ``most`` where none meets it; the last size where there is nothing to size, or where
    the error is held by fewer than AGAIN_TERMS terms (a few patches beside a small source: each
    increment too noisy to read a growth from, and small chunks there heavy-tailed)."""
    rest = MEASURED_STOP_CHUNKS - len(sizes) - len(running)
    if rest <= 0 or not (target_mse > 0 and terms >= AGAIN_TERMS):
        return int(sizes[-1])
    bound = again_bound(patch_count, sizes, increments, terms, running)
    return _smallest(lambda n: bound(n) <= target_mse, least, most)


def again_bound(patch_count, sizes, increments, terms, running):
    """n -> the stop rule's bound ``again_chunk`` expects on MEASURED_STOP_CHUNKS chunks, the rest
    after ``sizes`` and ``running`` of n paths (its variance model, above)."""
    rest = MEASURED_STOP_CHUNKS - len(sizes) - len(running)
    v = chunk_variances(sizes, increments)
    later = float(sizes[-1])
    up = v[-1] * (1.0 + MEASURED_STOP_Z * math.sqrt(2.0 / terms))
    growth = measured_growth(patch_count, sizes[0], later, v[0], up)
    growth = TWO_WAY_GROWTH if growth is None else growth
    at = lambda n: up * (1.0 + growth * patch_count / n) / (1.0 + growth * patch_count / later)  # noqa: E731
    known, variances = list(sizes) + list(running), list(v) + [at(n) for n in running]
    return lambda n: expected_bound(known + [n] * rest, variances + [at(n)] * rest, increments, terms)


def _smallest(meets, least, most):
    """The smallest n from ``least`` to ``most`` that ``meets`` (true from some n on: it bisects);
    ``most`` where none does or ``least`` is not below it."""
    if least >= most:
        return int(most)
    if meets(least):
        return int(least)
    if not meets(most):
        return int(most)
    low, high = least, most
    while high - low > 1:
        middle = (low + high) // 2
        low, high = (low, middle) if meets(middle) else (middle, high)
    return int(high)


def later_estimate(patch_count, chunk, done, variance, n):
    """The expected batch estimate (Batches.measured_mse) on MEASURED_STOP_CHUNKS chunks (K), the
    first ``done`` of ``chunk`` paths and ``variance`` per path, the rest of n paths and that
    variance grown as (1 + G P / n) (TWO_WAY_GROWTH): the mean of their ``plan.expected_increments``
    over the paths, (sum_k v_k - sum_k n_k v_k / N) / ((K - 1) N)."""
    rest = MEASURED_STOP_CHUNKS - done
    v = variance * (1.0 + TWO_WAY_GROWTH * patch_count / n) / (1.0 + TWO_WAY_GROWTH * patch_count / chunk)
    sizes = [chunk] * done + [n] * rest
    return float(expected_increments(sizes, [variance] * done + [v] * rest).mean()) / float(sum(sizes))
