"""What a chunk of paths tallies: power incident per patch, power accounts and path ends.

Weights are relative: a path from source i starts with per-channel weight E_ic / E_bar_i (1 in a
grey scene), and the true carried power is that weight times Phi_T / N. A chunk tallies the
power *incident* on each patch's front side, I_j; the reflected radiosity is
b_j = R_j I_j (Phi_T / N) / A_j. In a group of chunks traced together every path carries its
chunk, and the live paths stay in chunk order, so that a chunk's account is a sum over one
contiguous run of paths.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Scored hits are kept per step and added up (one bincount) every this many hits, or every
# this many per patch if that is fewer: a bincount costs a pass over the patches.
SCORE_FLUSH = 1 << 18
SCORE_FLUSH_PER_PATCH = 4

PATH_ENDS = ("escaped", "blocked", "absorbed", "threshold")


@dataclass
class ChunkTally:
    """What one batch of paths produced, in relative weights (multiply by Phi_T / N).

    The power accounts balance path by path: every unit of weight a path starts with ends
    absorbed at a hit (the weight arriving minus the weight leaving), escaped, blocked or,
    for the biased estimator, undistributed; so emitted = absorbed + escaped + blocked +
    undistributed to rounding, in every channel.
    """

    paths: int
    rays: int
    incident: np.ndarray                 # (C,P) power incident on each patch's front side
    emitted: np.ndarray                  # (C,) total starting weight
    absorbed: np.ndarray                 # (C,) weight arriving at front hits minus weight leaving them
    escaped: np.ndarray                  # (C,) carried by rays that hit nothing
    blocked: np.ndarray                  # (C,) carried by rays that hit a back side
    undistributed: np.ndarray            # (C,) left on paths cut by the threshold
    ended: dict = field(default_factory=dict)  # path counts by how they ended
    incident_groups: np.ndarray | None = None  # (S,C,P) incident by source group (per-source solves)
    direct: np.ndarray | None = None  # (C,P) the part of ``incident`` straight from the sources, where gathered apart
    direct_groups: np.ndarray | None = None  # (S,C,P) the same by source group (per-source solves)


class Accounts:
    """The power accounts and path ends of a group of G chunks, (G,C) and (G,) each."""

    def __init__(self, chunks, channels):
        zeros = lambda: np.zeros((chunks, channels))  # noqa: E731
        self.emitted, self.absorbed, self.escaped, self.blocked, self.undistributed = (zeros() for _ in range(5))
        self.ended = {name: np.zeros(chunks, dtype=np.int64) for name in PATH_ENDS}
        self.rays = np.zeros(chunks, dtype=np.int64)

    def tallies(self, sizes, incident):
        """One ChunkTally per chunk of ``sizes`` paths, from (C,G,P) ``incident``."""
        return [
            ChunkTally(
                paths=n,
                rays=int(self.rays[k]),
                # (float64, contiguous, its own: a lone chunk's sums are its tally, a group's are copied)
                incident=incident[:, k].astype(np.float64, copy=incident.shape[1] > 1),
                emitted=self.emitted[k],
                absorbed=self.absorbed[k],
                escaped=self.escaped[k],
                blocked=self.blocked[k],
                undistributed=self.undistributed[k],
                ended={name: int(counts[k]) for name, counts in self.ended.items()},
            )
            for k, n in enumerate(sizes)
        ]


class Scores:
    """The hits of a chunk (or group), kept per step and summed per patch (one bincount per
    channel) whenever SCORE_FLUSH_PER_PATCH times the patch count of them have gathered, at
    most SCORE_FLUSH: (C,P) float64 sums of weights, or int64 counts of unweighted hits. Big
    scenes gather the hits of many steps per bincount; small scenes add every step's hits
    while they are still in cache. The first sums are the sums: nothing is zeroed first."""

    def __init__(self, channels, patch_count):
        self.shape = (channels, patch_count)
        self.incident = None  # until the first flush
        self.patches, self.weights, self.count = [], [], 0
        self.flush_at = min(SCORE_FLUSH, SCORE_FLUSH_PER_PATCH * patch_count)

    def add(self, patch, weights):
        self.patches.append(patch)
        if weights is not None:
            self.weights.append(weights)
        self.count += patch.size
        if self.count >= self.flush_at:
            self.flush()

    def flush(self):
        if not self.patches:
            return
        patches = np.concatenate(self.patches)
        C, P = self.shape
        if not self.weights:
            sums = np.bincount(patches, minlength=P)[None]
            if self.incident is None:
                self.incident = sums
            else:
                for c in range(C):
                    self.incident[c] += sums[c]
        else:
            w = np.concatenate(self.weights, axis=1)
            first = self.incident is None
            if first:
                self.incident = np.empty((C, P))
            for c in range(C):  # a channel at a time: one (P,) temporary, not (C,P)
                sums = np.bincount(patches, weights=w[c], minlength=P)
                if first:
                    self.incident[c] = sums
                else:
                    self.incident[c] += sums
        self.patches, self.weights, self.count = [], [], 0

    def total(self):
        """(C,P) float64 sums, or int64 counts where no hit carried a weight."""
        self.flush()
        if self.incident is None:
            return np.zeros(self.shape)
        return self.incident


def chunk_starts(chunk, G):
    """Where each chunk's run begins in ``chunk`` (in chunk order), and its end: (G+1,)."""
    return np.searchsorted(chunk, np.arange(G + 1, dtype=chunk.dtype))


def chunk_counts(chunk, G):
    """(G,) number of entries of each chunk in ``chunk`` (in chunk order)."""
    return np.diff(chunk_starts(chunk, G))


def chunk_sums(weights, chunk, G):
    """(G,C) sums of the columns of ``weights`` (C,n) by their chunk (n,), which comes in
    chunk order: one contiguous run of columns per chunk. None is weight 1 on one channel."""
    start = chunk_starts(chunk, G)
    if weights is None:
        return np.diff(start).astype(np.float64)[:, None]
    sums = np.zeros((G, weights.shape[0]))
    filled = start[:-1] < start[1:]
    if filled.any():
        # Each non-empty run, up to the next one's start (empty runs between take no columns).
        sums[filled] = np.add.reduceat(weights, start[:-1][filled], axis=1).T
    return sums


def weight_sum(weights, mask):
    """Sum of the carried weights of the masked paths, per channel (the masked paths are
    usually few: their columns are picked out first)."""
    if weights is None:
        return np.array([float(np.count_nonzero(mask))])
    return weights.compress(mask, axis=1).sum(axis=1)


def total_weight(weights, n):
    """Total carried weight per channel, (C,): n paths of weight 1 where weights is None."""
    return np.array([float(n)]) if weights is None else weights.sum(axis=1)
