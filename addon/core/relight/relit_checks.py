"""What a recombination's error cannot say, from the statistics a per-source solve keeps
(``estimate.per_source.PerSource``): each group's batches with light and its share of the samples.

A group's batch variance is its own error only where its light is in 2 batches or more (the
rule the whole solve's error follows); a group that drew no path has 0 light and 0 variance, an
estimate of nothing. At the solve's strengths the solve's own error covers such a group (its
light, whatever it is, is in the total as sampled); relit to a larger share of the power than its
share of the samples, nothing does. ``unmeasured`` names those groups where their share is more
than the error of the rest; ``over_target`` the groups a re-solve must hold to part of the target
for a recombination past it to meet it. No bpy.
"""
from __future__ import annotations

import math

import numpy as np

# A share above the sampled one by no more than this is the same share (float rounding).
SHARE_ROUNDING = 1e-9
# A recombination past its target: the groups left are held to this share of the target MSE and the
# re-solved ones to the rest (an even split: re-solved to the whole target, they would put it past again).
REST_SHARE = 0.5


def relative_error(per_source, weights, scale):
    """The measured relative RMS error of the recombination with ``weights`` over ``scale``
    (NaN where there is no light to be relative to)."""
    return math.sqrt(per_source.mse(weights)) / scale if scale > 0 else math.nan


def unmeasured(per_source, weights, scale):
    """The names of the groups whose light the recombination with ``weights`` (S,3) cannot give an
    error for: lit in fewer than 2 batches, relit to a larger share of the power than their share
    of the samples, and that share above the relative error of the rest (over ``scale``, the
    recombination's mean): were all their light missing, more than the error says."""
    lit, sampled = per_source.lit_batches, per_source.sampled_share
    if lit is None or sampled is None:  # (results kept before these were)
        return ()
    w = np.array(weights, np.float64)
    relit = (w * per_source.power).sum(axis=1)
    share = relit / relit.sum() if relit.sum() > 0 else np.zeros_like(relit)
    suspect = (lit < 2) & (share > sampled * (1.0 + SHARE_ROUNDING))
    w[suspect] = 0.0
    rest = relative_error(per_source, w, scale)
    return tuple(name for name, bad, part in zip(per_source.names, suspect, share) if bad and not part <= rest)


def dark(per_source, weights):
    """Whether no group ``weights`` keeps on lit a reflecting patch in any batch: no reflected
    light (the paper's b_ave, made from the power, would not say)."""
    on = (np.asarray(weights, np.float64) > 0).any(axis=1)
    return per_source.lit_batches is not None and not (per_source.lit_batches[on] > 0).any()


def over_target(per_source, weights, scale, target):
    """The names of the fewest groups, the largest own error first, whose error left out brings
    the recombination with ``weights`` (its mean ``scale``) within REST_SHARE of the relative
    ``target``'s MSE, their light to be re-solved to the other share; () where it is within the
    target or there is none."""
    if target is None or not relative_error(per_source, weights, scale) > target:
        return ()
    target = target * math.sqrt(REST_SHARE)
    w = np.array(weights, np.float64)
    C = per_source.covariance.shape[0]
    own = np.mean([w[:, c] ** 2 * np.diagonal(per_source.covariance[c if C == 3 else 0]) for c in range(3)], axis=0)
    names = []
    for s in np.argsort(-own, kind="stable"):
        if own[s] <= 0 or relative_error(per_source, w, scale) <= target:
            break
        names.append(per_source.names[s])
        w[s] = 0.0
    return tuple(names)
