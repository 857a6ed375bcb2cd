"""Per-source tallies and results: each source group's light from the same rays, summed chunk
by chunk with what the error of any recombination of them needs (``relight`` recombines them).

The chunks are the batches (``batches``), and the groups' batch means share paths, so the batch
variance of sum_s w_s b_s is w^T V w, V the groups' batch covariance. Its area-weighted mean over
patches (the measured MSE) needs only, per channel,
M_st = sum_j W_j (sum_k I_sj^(k) I_tj^(k) / n_k - I_sj I_tj / N), W_j = (R_j Phi_T / A_j)^2 A_j / A_T:
(3,S,S) numbers, kept as the chunks come in. With every w_s = 1 it is the solve's own measured
MSE (to rounding).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .error_model import mean_reflected_radiosity


def power_share(power):
    """(S,) each group's share of (S,3) ``power`` summed over the channels: its share of a solve's
    samples, which draw sources (and gather toward them) in proportion to it."""
    total = power.sum(axis=1)
    return total / total.sum() if total.sum() > 0 else np.zeros(len(total))


class GroupBatches:
    """The groups' incident power summed over chunks (S,C,P), with the cross sums of their batch
    covariance (C,S,S), weighted as the measured MSE weights patches."""

    def __init__(self, scene, tables, groups):
        C, P, S = tables.channels, scene.patch_count, groups.count
        self.groups, self.channels = groups, C
        self.incident = np.zeros((S, C, P))
        self.direct = None  # (S,C,P) of it straight from the sources, where chunks gather it apart
        self.cross = np.zeros((C, S, S))  # sum_k sum_j W_j I_sj^(k) I_tj^(k) / n_k
        self.lit = np.zeros(S, np.int64)  # the batches each group's light reached a reflecting patch in
        score = tables.reflectivity * (scene.total_power / scene.patch_area)  # (C,P)
        self.root_weight = score * np.sqrt(scene.area_share)  # sqrt(W_j)

    def add(self, tally):
        """Adds a chunk's ``incident_groups`` (S,C,P) of ``tally.paths`` paths."""
        self.incident += tally.incident_groups
        if tally.direct_groups is not None:
            self.direct = tally.direct_groups.copy() if self.direct is None else \
                np.add(self.direct, tally.direct_groups, out=self.direct)
        lit = np.zeros(self.groups.count, bool)
        for c in range(self.channels):
            x = tally.incident_groups[:, c] * self.root_weight[c]
            lit |= x.any(axis=1)
            # (einsum, not a BLAS product: OpenBLAS's threads would spin beside the walks' threads)
            self.cross[c] += np.einsum("sp,tp->st", x, x) / tally.paths
        self.lit += lit

    def spread(self, paths):
        """(C,S,S) M: the cross sums less those of the means, N (chunks - 1) times the batch
        covariance's area-weighted mean over patches."""
        spread = self.cross.copy()
        for c in range(self.channels):
            x = self.incident[:, c] * self.root_weight[c]
            spread[c] -= np.einsum("sp,tp->st", x, x) / paths
        return spread

    def results(self, scene, total, target_error, measured_scale=False):
        """The PerSource of the run ``total`` (batches.Batches) made (``measured_scale``: with
        each group's own mean reflected radiosity, which its relit error is then relative to)."""
        S, N = self.groups.count, total.paths
        radiosity = np.empty((S, scene.patch_count, 3))
        irradiance = self.irradiance(scene, self.incident, N)
        patch_group = self.groups.patch_group(scene.patch_count)
        for s in range(S):
            radiosity[s] = scene.reflectivity * irradiance[s]
            radiosity[s] += np.where((patch_group == s)[:, None], scene.emission, 0.0)
        covariance = self.spread(N) / ((total.chunks - 1) * N) if total.chunks > 1 else np.full((self.channels, S, S), math.nan)
        direct = None if self.direct is None else self.irradiance(scene, self.direct, N)
        means = None
        if measured_scale:  # (area-weighted over patches: Batches.mean_reflected's, group by group)
            means = np.einsum("spc,pc,p->sc", irradiance, scene.reflectivity, scene.area_share)
        power = group_power(scene, self.groups)
        return PerSource(self.groups.names, radiosity, irradiance, power, covariance, scene_scale(scene), target_error,
                         patch_group, self.groups.light_group, direct, means, self.lit.copy(),
                         power_share(power))

    def irradiance(self, scene, incident, paths):
        """(S,P,3) the irradiance of incident power (S,C,P) summed over ``paths`` paths."""
        out = np.zeros((incident.shape[0], scene.patch_count, 3))
        if paths:
            for c in range(3):
                out[:, :, c] = incident[:, c if self.channels == 3 else 0] * (scene.total_power / scene.patch_area) / paths
        return out


def group_power(scene, groups):
    """(S,3) the power of each group at the solve's strengths: its patches' A_i E_i and its
    lights' emitters'."""
    power = np.zeros((groups.count, 3))
    source_power = scene.source_power
    emitting = groups.source_group >= 0
    np.add.at(power, groups.source_group[emitting], source_power[emitting])
    return power


def scene_scale(scene):
    """b_ave per unit of Phi_T: what the relative RMS error is relative to, for any power."""
    R_ave = scene.average_reflectivity
    return mean_reflected_radiosity(1.0, scene.total_area, R_ave)


@dataclass
class PerSource:
    """A per-source solve's results: ``names`` (S,) of the groups; ``radiosity`` and
    ``irradiance`` (S,P,3) of each group alone at the solve's strengths (its emitting patches'
    E in its radiosity), summing to the solve's own over groups; ``power`` (S,3) each group's
    power; ``covariance`` (C,S,S) the area-weighted mean over patches of the groups' batch
    covariance of the reflected radiosity (C = 1 for a grey scene, whose channels are alike;
    NaN below 2 chunks); ``scale`` b_ave per unit of power; the solve's ``target_error`` or None;
    ``patch_group`` (P,) int32 the group of each patch's own emission (-1: none), or None;
    ``light_group`` (L,) int32 the group of each light, or None."""

    names: tuple
    radiosity: np.ndarray
    irradiance: np.ndarray
    power: np.ndarray
    covariance: np.ndarray
    scale: float
    target_error: float | None = None  # the solve's relative error target (of the light at its strengths)
    patch_group: np.ndarray | None = None
    light_group: np.ndarray | None = None
    direct_irradiance: np.ndarray | None = None  # (S,P,3) of ``irradiance`` straight from the sources, where gathered apart
    # (S,3) each group's area-weighted mean reflected radiosity, where the solve held its error to
    # its own mean (error_scale "measured"): the relit error is then relative to theirs recombined
    reflected_means: np.ndarray | None = None
    # (S,) the batches each group lit a reflecting patch in; (S,) its share of its solve's samples (relit_checks)
    lit_batches: np.ndarray | None = None
    sampled_share: np.ndarray | None = None

    @property
    def count(self):
        return len(self.names)

    def mse(self, weights):
        """The measured MSE of the reflected radiosity recombined with ``weights`` (S,3)."""
        weights = np.asarray(weights, np.float64)
        C = self.covariance.shape[0]
        return float(np.mean([weights[:, c] @ self.covariance[c if C == 3 else 0] @ weights[:, c] for c in range(3)]))

    def mean_reflected(self, weights):
        """What the relative RMS error is relative to at the powers ``weights`` give: the groups'
        own mean reflected radiosities recombined (``reflected_means``), else b_ave (``paper_mean``)."""
        if self.reflected_means is None:
            return self.paper_mean(weights)
        return float((np.asarray(weights, np.float64) * self.reflected_means).sum(axis=0).mean())

    def paper_mean(self, weights):
        """The paper's b_ave at the powers ``weights`` give."""
        return self.scale * float((np.asarray(weights, np.float64) * self.power).sum(axis=0).mean())
