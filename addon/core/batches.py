"""Chunk tallies summed in chunk order, with the batch-means estimate of the result's error.

Chunks are the independent batches of the a-posteriori error estimate ("batch means"): with K
chunks of n_k paths giving per-chunk estimates b^(k), the per-path variance of each patch is
estimated by sum_k n_k (b^(k) - b)^2 / (K - 1), and the MSE of the result by its area-weighted
mean over patches (and channels) divided by N.
"""
from __future__ import annotations

import math

import numpy as np


class Batches:
    """Sums chunk tallies in chunk order, with what the batch error estimate needs."""

    def __init__(self, scene, tables):
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
        # b_j = (R_j Phi_T / A_j) I_j / N: the score R_j Phi_T / A_j made where it is used (_score),
        # not kept beside the tallies (a (C,P) array less through the solve)
        self._reflectivity = tables.reflectivity  # (C,P)
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

    def _score(self):
        """(C,P) R_j Phi_T / A_j, a new array."""
        return self._reflectivity * (self.scene.total_power / self.scene.patch_area)

    def reflected(self):
        if self.paths == 0:
            return np.zeros((self.scene.patch_count, 3))
        b = self._score()
        b *= self.incident
        b /= self.paths  # (in place: one (C,P) array, the same numbers)
        return np.repeat(b.T, 3, axis=1) if self.channels == 1 else b.T

    def radiosity(self, dtype=np.float64):
        """(P,3) B = E + b of ``dtype``, made a channel at a time (two (P,) temporaries rather
        than (C,P) ones: the live view asks for it while the walks hold their own sums); in
        float64 bit for bit E + reflected()."""
        emission = self.scene.emission
        out = np.empty((self.scene.patch_count, 3), dtype)
        if self.paths == 0:
            out[:] = emission
            return out
        per_area = self.scene.total_power / self.scene.patch_area
        for c in range(3):
            k = c if self.channels == 3 else 0
            b = self._reflectivity[k] * per_area
            b *= self.incident[k]
            b /= self.paths
            b += emission[:, c]
            out[:, c] = b
        return out

    def irradiance(self):
        """(P,3) H, the light arriving at each patch over pi (B = E + R H): incident power over area."""
        if self.paths == 0:
            return np.zeros((self.scene.patch_count, 3))
        h = self.incident * (self.scene.total_power / self.scene.patch_area)
        h /= self.paths
        return np.repeat(h.T, 3, axis=1) if self.channels == 1 else h.T

    def variance_of_mean(self):
        """Batch-means estimate of Var(b_j) per channel and patch, (C,P); NaN below 2 chunks."""
        if self.chunks < 2:
            return np.full_like(self.incident, math.nan)
        variance = self._spread()
        score = self._score()
        score *= score  # (score**2)
        variance *= score
        del score
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
            score = self._score()
            score *= score  # (score**2)
            score *= self.weight / self.channels
            self._mse_weight = score.ravel()
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
