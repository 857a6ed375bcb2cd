"""Rounds of stratified samples at points or patches, again where a mean is noisier than allowed,
within a deadline where one is given (the display's direct light: ``point_direct``).

Every source (``Part``) first takes ``samples`` samples at every point; then, up to ``retries``
times, the points whose standard error passes what is allowed take ``more`` times as many,
new ones (the mean of the last round stands). With a deadline, a round takes the noisiest points
first, of every source together, as many as the pace each source's rounds have shown leaves
time for; the first round is the least the display needs and always runs.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..distributed.runners import local_thread_count, on_threads
from ..lights.sampling import stratified_by_patch
from ..methods.tables import FreeTurn

BLOCK_SAMPLES = 1 << 15  # samples traced at a time (about 500 bytes of temporaries each)


@dataclass
class Part:
    """One source's sampling: ``sample(rows, count)`` gives ((k,3) means, (k,) standard errors)
    of ``count`` samples at each of the points ``rows``; ``noise(mean, error)`` (n,) each error
    over what is allowed (above 1: sampled again)."""

    sample: Callable
    noise: Callable


@dataclass
class Spent:
    """What rounds took: samples drawn and seconds, in all, and the seconds of their first round."""

    samples: int = 0
    seconds: float = 0.0
    first: float = 0.0


def rounds(parts, n, samples, retries, more, deadline=None, spent=None):
    """[(n,3)] each ``Part``'s means at n points (the module's docstring); ``deadline`` a
    ``time.perf_counter()`` reading or None; ``spent`` (a ``Spent``) adds what they took."""
    spent = Spent() if spent is None else spent
    means, errors, pace = [], [], []
    for part in parts:
        mean, error, seconds = _timed(part, np.arange(n), samples, spent)
        means.append(mean)
        errors.append(error)
        pace.append(seconds / max(n * samples, 1))
        spent.first += seconds
    count = samples
    for _ in range(retries):
        count *= more
        ratios = [part.noise(mean, error) for part, mean, error in zip(parts, means, errors)]
        again = [np.flatnonzero(ratio > 1) for ratio in ratios]
        if deadline is not None:
            again = _within(again, ratios, pace, count, deadline - time.perf_counter())
        if not any(rows.size for rows in again):
            break
        for k, (part, rows) in enumerate(zip(parts, again)):
            if rows.size:
                means[k][rows], errors[k][rows], seconds = _timed(part, rows, count, spent)
                pace[k] = seconds / (rows.size * count)
    return means


def _timed(part, rows, count, spent):
    """``part.sample(rows, count)`` and the seconds it took, added to ``spent``."""
    started = time.perf_counter()
    mean, error = part.sample(rows, count)
    seconds = time.perf_counter() - started
    spent.samples += rows.size * count
    spent.seconds += seconds
    return mean, error, seconds


def _within(again, ratios, pace, count, left):
    """Of the rows each part would sample again (``count`` samples each at its ``pace``), those
    that fit in ``left`` seconds, the noisiest (``ratios``) first (one that does not fit leaves
    the time to cheaper ones after it), sorted."""
    part = np.concatenate([np.full(rows.size, k) for k, rows in enumerate(again)])
    rows = np.concatenate(again)
    ratio = np.concatenate([r[rows_k] for r, rows_k in zip(ratios, again)])
    cost = (count * np.asarray(pace))[part]
    keep = np.zeros(rows.size, bool)
    candidates = np.argsort(-ratio, kind="stable")
    while candidates.size:  # (a part's rows cost alike: at most one pass a part)
        candidates = candidates[cost[candidates] <= left]
        fits = np.cumsum(cost[candidates]) <= left
        keep[candidates[fits]] = True
        left -= cost[candidates[fits]].sum()
        candidates = candidates[~fits]
    return [np.sort(rows[keep & (part == k)]) for k in range(len(again))]


def sampled(tables, n, samples, rng, add, points, dimensions, dtype=np.float64, paired=False):
    """((n,3) the mean of ``samples`` stratified samples of each of n points or patches, (n,) its
    standard error (channels summed)); ``add(tables, points, u, value)`` adds a source's light at
    sample points, ``points(block, local, u)`` a block's sample points (``local`` each sample's
    row in the block), BLOCK_SAMPLES samples at a time, each block's points shared among the local
    threads (``runners.on_threads``): a block's random numbers are drawn in the blocks' order and
    a point's samples are its own, so the bits are the same on any number of threads, and the
    samples in flight one block's. ``paired``: the error of a choice stratified by u[5]
    (``paired_error``), else as if the samples were independent."""
    mean, error = np.empty((n, 3), dtype), np.empty(n, dtype)
    step = max(1, BLOCK_SAMPLES // samples)
    threads = max(1, min(local_thread_count(), step, n))
    pieces, lock = _pieces(n, step, samples, rng, dimensions, threads), threading.Lock()
    # (each thread traces with its own turn at numpy: the blocks' arrays are long, numpy lets go of the GIL)
    mine = tables if threads == 1 else tables.with_turn(FreeTurn())

    def work():
        while True:
            with lock:  # (the blocks drawn in order)
                piece = next(pieces, None)
            if piece is None:
                return
            block, local, u = piece
            value = np.zeros((3, local.size))
            add(mine, points(block, local, u), u=u, value=value)
            value = value.reshape(3, -1, samples)
            mean[block] = value.mean(axis=2).T
            grey = value.sum(axis=0)
            error[block] = paired_error(grey, u[5].reshape(grey.shape)) if paired else grey.std(axis=1, ddof=1) / np.sqrt(samples)

    on_threads(work, threads)
    return mean, error


def _pieces(n, step, samples, rng, dimensions, parts):
    """Blocks of ``step`` of n points, each one's uniforms drawn in turn (``stratified_by_patch``)
    and its points in ``parts`` pieces: (rows, each sample's row in the piece, its uniforms)."""
    for start in range(0, n, step):
        count = min(n, start + step) - start
        local = np.repeat(np.arange(count), samples)
        u = stratified_by_patch(local, count, dimensions, rng, dtype=np.float32)
        size = -(-count // parts)
        for a in range(0, count, size):
            b = min(count, a + size)
            yield slice(start + a, start + b), local[a * samples:b * samples] - a, u[:, a * samples:b * samples]


def paired_error(value, u):
    """(k,) the standard error of the means of (k, s) samples whose ``u`` (k, s) has one sample
    in each of s strata (a Sobol' net's): strata paired with their neighbours, each pair's
    difference its variance (collapsed strata). Samples as independent would see the choice's
    spread itself as noise: among lamps each a stratum, one seen and one hidden gave every
    corner 16 samples' error where the stratified mean has none."""
    order = np.argsort(u, axis=1)
    ranked = np.take_along_axis(value, order, axis=1)
    difference = ranked[:, 0::2] - ranked[:, 1::2]
    return np.sqrt((difference * difference).sum(axis=1)) / value.shape[1]
