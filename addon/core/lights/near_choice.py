"""Which emitting patch a gathering sample's shadow ray looks at: by power, and by nearness.

Chosen by power alone, the point on a long emitter near a receiver (a cove's light strip a few
centimetres from a wall and a ceiling) is most often far along it, where its light is weak, and
now and then right beside the receiver, where it is 1/d^2 strong: a heavy-tailed estimate. Here
each receiving patch j chooses a cluster c of emitting patches from a defensive mixture,

    q_jc = (1 - NEAR_SHARE) Phi_c / Phi_E + NEAR_SHARE g_jc / sum_c' g_jc',
    g_jc = Phi_c / (pi d_jc^2 + A_c)      (the cluster's power times a bounded form factor),

d_jc the distance between the receiver's and the cluster's centres, and then a patch s of the
cluster by power; the lights keep their share of the power. The choice's probability,
P_E q_jc Phi_s / Phi_c, is what the samples divide by and what multiple importance sampling
weighs the shadow rays by (``density``), so the estimate stays unbiased whatever g says; the
mixture's power half bounds the variance at twice that of a choice by power alone. (Cycles'
light tree chooses among a mesh light's triangles by the same kind of bound.)

The table is (P, K) for K clusters; K is the emitting patches' count up to MAX_TABLE / P
(contiguous runs along a Morton curve through their centres beyond that), and the choice is the
power's alone where K < 2.
"""
from __future__ import annotations

import weakref

import numpy as np

from .sampling import patch_point_rows

# The mixture's weight on nearness; the rest is by power.
NEAR_SHARE = 0.5
# The most receiver x cluster entries kept (two float64 tables of this many).
MAX_TABLE = 1 << 19
# A receiver chooses by nearness where that makes some cluster this many times likelier than by
# power; elsewhere the choice by power stands (it costs less).
NEAR_GAIN = 1.5
# Morton curve resolution per axis, for clustering emitting patches beyond MAX_TABLE / P.
MORTON_BITS = 10


_made = weakref.WeakKeyDictionary()  # scene -> (choice, table, NearChoice): a solve's gatherings share one


def near_choice(scene, choice):
    """The NearChoice of ``scene`` for the sources' ``choice`` (P_s), made once a scene."""
    known = _made.get(scene)
    if known is not None and known[1] == MAX_TABLE and np.array_equal(known[0], choice):
        return known[2]
    made = NearChoice(scene, choice)
    _made[scene] = (choice.copy(), MAX_TABLE, made)
    return made


def patch_centres(scene):
    """(P,3) world-space points in the middle of the patches (each one's (0.5, 0.5) point: the
    centre of a parallelogram, a middle point of others; nearness needs no more), float64."""
    g, P = scene.geometry, scene.patch_count
    patch = np.arange(P)
    half = np.full(P, 0.5, np.float32)
    points = patch_point_rows(g, patch, half.copy(), half.copy(), half.copy())
    return g.to_world(points.T.astype(np.float64), patch)


def _morton(points, bits=MORTON_BITS):
    """(n,) Morton codes of (n,3) points over their bounding box."""
    low, high = points.min(axis=0), points.max(axis=0)
    cells = ((points - low) / np.maximum(high - low, 1e-300) * ((1 << bits) - 1)).astype(np.int64)
    code = np.zeros(len(points), dtype=np.int64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
    return code


class NearChoice:
    """The receivers' choices of emitting patches (see the module); ``active`` False where
    there are fewer than two clusters (then the choice by power stands)."""

    def __init__(self, scene, choice):
        P = scene.patch_count
        emitters = np.flatnonzero(choice[:P] > 0)
        self.patch_count, self.choice = P, choice
        self.emitter_share = float(choice[emitters].sum())  # P_E
        K = min(emitters.size, MAX_TABLE // max(P, 1))
        self.active = K >= 2 and self.emitter_share > 0
        self.form = None  # (P,) below, wherever there is a cluster: a lone small emitter's receivers read it too
        if K < 1 or self.emitter_share <= 0:
            return
        centres = patch_centres(scene)
        if emitters.size > K:  # (contiguous runs of a space-filling curve: compact clusters)
            emitters = emitters[np.argsort(_morton(centres[emitters]), kind="stable")]
            cluster = (np.arange(emitters.size) * K) // emitters.size
        else:
            cluster = np.arange(emitters.size)
        power = choice[emitters]
        cluster_power = np.bincount(cluster, weights=power, minlength=K)
        self.cluster_of = np.full(choice.size, -1, dtype=np.int64)
        self.cluster_of[emitters] = cluster
        # within a cluster, by power: each cluster's cumulative run ends at 1, offset by its index
        inner = np.cumsum(power) - np.repeat(np.cumsum(cluster_power) - cluster_power, np.bincount(cluster, minlength=K))
        within = power / cluster_power[cluster]  # Phi_s / Phi_c, in the order of ``emitters``
        self.inner_cdf = inner / cluster_power[cluster] + cluster
        self.inner_cdf[np.r_[np.flatnonzero(np.diff(cluster)), emitters.size - 1]] = np.arange(K) + 1.0
        self.emitters = emitters
        self.within_of = np.zeros(choice.size)
        self.within_of[emitters] = within
        area = np.bincount(cluster, weights=scene.patch_area[emitters], minlength=K)
        middle = np.stack([np.bincount(cluster, weights=power * centres[emitters, k], minlength=K)
                           for k in range(3)], axis=1) / cluster_power[:, None]
        self.K = K
        self.q = np.empty((P, K))
        self.form = np.empty(P)  # sum_c A_c / (pi d_jc^2 + A_c): a bound on the receiver's form factor to the emitters
        for rows in np.array_split(np.arange(P), max(1, (P * K) >> 18)):  # (memory: blocks of receivers)
            d2 = ((centres[rows, None, :] - middle[None]) ** 2).sum(axis=2)
            g = cluster_power / (np.pi * d2 + area)
            self.form[rows] = np.minimum((area / (np.pi * d2 + area)).sum(axis=1), 1.0)
            self.q[rows] = (1 - NEAR_SHARE) * cluster_power / cluster_power.sum() + NEAR_SHARE * g / g.sum(axis=1, keepdims=True)
        self.q /= self.q.sum(axis=1, keepdims=True)
        self.rows = (self.q / (cluster_power / cluster_power.sum())).max(axis=1) > NEAR_GAIN  # (P,) near receivers
        # row j's cdf offset by j: one sorted array; q is what its steps are, as stored
        self.row_cdf = (np.cumsum(self.q, axis=1) + np.arange(P)[:, None]).ravel()
        self.row_cdf[self.K - 1::self.K] = np.arange(P) + 1.0
        self.q = np.diff(np.concatenate([np.arange(P)[:, None], self.row_cdf.reshape(P, self.K)], axis=1), axis=1)
        lights = np.arange(P, choice.size)
        lights = lights[choice[P:] > 0]
        self.lights = lights
        if lights.size:
            light_cdf = np.cumsum(choice[lights])
            self.light_cdf = light_cdf / light_cdf[-1]
            self.light_cdf[-1] = 1.0

    def choose(self, patch, u, table):
        """(n,) the source each sample of receiving ``patch`` (n,) looks at, from its uniform u;
        ``table`` (sampling.SourceTable, by power) where the receiver is not near."""
        u = np.asarray(u, dtype=np.float64)
        near = self.rows.take(patch)
        source = np.empty(u.size, dtype=np.int64)
        far = np.flatnonzero(~near)
        if far.size:
            source[far] = table.choose(u[far])
        on = near & (u < self.emitter_share)
        if on.any():
            j = patch[on].astype(np.int64)
            v = np.minimum(u[on] / self.emitter_share, np.nextafter(1.0, 0.0))
            k = np.minimum(np.searchsorted(self.row_cdf, j + v, side="right") - j * self.K, self.K - 1)
            at = j * self.K + k
            before = np.where(k > 0, self.row_cdf[np.maximum(at - 1, 0)] - j, 0.0)
            # where v falls within its cluster's stretch picks the patch (the sample stays stratified)
            w = np.clip((v - before) / np.maximum(self.q[j, k], 1e-300), 0.0, np.nextafter(1.0, 0.0))
            s = np.minimum(np.searchsorted(self.inner_cdf, k + w, side="right"), self.emitters.size - 1)
            source[on] = self.emitters[s]
        off = np.flatnonzero(near & ~on)
        if off.size:
            v = (u[off] - self.emitter_share) / (1.0 - self.emitter_share)
            source[off] = self.lights[np.minimum(np.searchsorted(self.light_cdf, v, side="right"), self.lights.size - 1)]
        return source

    def probability(self, patch, source):
        """(n,) the chance that a sample of ``patch`` looks at emitting patch ``source``."""
        cluster = self.cluster_of.take(source)
        near = self.emitter_share * self.q[patch, np.maximum(cluster, 0)] * self.within_of.take(source) * (cluster >= 0)
        return np.where(self.rows.take(patch), near, self.choice.take(source))
