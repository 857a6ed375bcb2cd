"""Chunk tallies summed in chunk order, with the batch-means estimate of the result's error.

Chunks are the independent batches of the a-posteriori error estimate ("batch means"): with K
chunks of n_k paths giving per-chunk estimates b^(k), the per-path variance of each patch is
estimated by sum_k n_k (b^(k) - b)^2 / (K - 1), and the MSE of the result by its area-weighted
mean over patches (and channels) divided by N.

That sum of squares is also the sum of K - 1 increments, one a chunk from the second on (the
weighted Helmert decomposition, Welford's update): chunk k adds n_k N_<k / N_<=k (b^(k) - b_<k)^2,
its distance from the chunks before it. Area-weighted, each increment is one scalar sample of the
per-path variance, independent of the others for Gaussian tallies; their spread says how well
the estimate is known (few chunks, heavy tails, error in one common mode), which a stop rule
needs (mse_upper_bound).

Where the caller replaces some source groups' direct light after the solve with an estimate of
its own (``Replaced``: the display's lamp means), the solve's estimate of that part is not in the
result: the sums of squares, the increments and so the measured error are of the rest, which the
stop rule holds to the target less the share left for the replacement's own error; the caller
adds that error once it has made the replacement (docs/errors.md, "What the target is measured on").
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .per_source import GroupBatches

# measured_mse sums this many patches at a time.
MSE_BLOCK = 1 << 16


@dataclass(frozen=True)
class Replaced:
    """Source ``groups`` whose direct light the caller puts in place of the solve's after it, and
    the ``share`` of the target's MSE left for that estimate's error (the solve keeps the rest)."""

    groups: tuple
    share: float


class Batches:
    """Sums chunk tallies in chunk order, with what the batch error estimate needs (``replaced``:
    a Replaced, or None)."""

    def __init__(self, scene, tables, increments=False, replaced=None):
        C, P = tables.channels, scene.patch_count
        # Per source: each group's sums too (per_source.GroupBatches), or None.
        self.groups = None if tables.groups is None else GroupBatches(scene, tables, tables.groups.whole)
        self.scene = scene
        self.channels = C
        self.incident = np.zeros((C, P))
        self.incident_sq = np.zeros((C, P))  # sum_k I_k^2 / n_k
        self.direct = None  # (C,P) the part of ``incident`` straight from the sources, where chunks gather it apart
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
        self.weight = scene.area_share
        self._mse_at = (0, math.nan)  # (chunks, measured_mse at that many chunks)
        self._mean_at = (0, math.nan)  # (chunks, mean_reflected at that many chunks)
        # Area-weighted Helmert increments of the sum of squares, one a chunk from the second on:
        # a pass over the patches a chunk, made only for a run that stops on its measured error.
        self.increments = [] if increments else None
        self.replaced = replaced
        self.left_out = None  # (C,P) the replaced groups' direct light summed, where chunks gather it apart

    def add(self, tally):
        kept, left = self._kept(tally)
        if self.increments is not None and self.paths > 0:
            self.increments.append(self._increment(tally.paths, kept))
        self.incident += tally.incident
        if left is not None:
            self.left_out = left if self.left_out is None else np.add(self.left_out, left, out=self.left_out)
        if tally.direct is not None:
            self.direct = tally.direct.copy() if self.direct is None else np.add(self.direct, tally.direct, out=self.direct)
        if self.groups is not None:
            self.groups.add(tally)
        for c, row in enumerate(kept):  # a channel at a time: a (P,) temporary, not (C,P)
            square = np.square(row)
            square /= tally.paths
            self.incident_sq[c] += square
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

    def _kept(self, tally):
        """((C,P) what of ``tally``'s incident power stays in the result, (C,P) the rest or None):
        all of it, less the replaced groups' direct light where the chunk kept each group's apart."""
        if self.replaced is None or tally.direct_groups is None:
            return tally.incident, None
        left = tally.direct_groups[list(self.replaced.groups)].sum(axis=0)
        return tally.incident - left, left

    def _kept_sum(self, k, rows):
        """(rows,) the kept incident power of channel k summed over the chunks so far (a new array)."""
        return self.incident[k, rows] - self.left_out[k, rows] if self.left_out is not None else self.incident[k, rows].copy()

    def kept_share(self):
        """The share of the target's MSE the solve's own error is held to: all of it, less the
        replacement's share where its groups' direct light is left out of the sums."""
        return 1.0 - self.replaced.share if self.left_out is not None else 1.0

    def _score(self, k, rows=slice(None)):
        """R_jk Phi_T / A_j of channel k at patches ``rows`` (all of them: (P,)), a new array."""
        return self._reflectivity[k, rows] * (self.scene.total_power / self.scene.patch_area[rows])

    def _columns(self, column, dtype=np.float64, plus=None):
        """(P,3) of ``column(k)`` (P,) float64 for each channel (a grey scene's one in all three),
        plus ``plus`` (P,3) if given: made a channel at a time, so that a million patches' results
        take two (P,) temporaries rather than (C,P) ones."""
        out = np.empty((self.scene.patch_count, 3), dtype)
        for c in range(3):
            if c == 0 or self.channels == 3:
                values = column(c if self.channels == 3 else 0)
            if plus is None:
                out[:, c] = values
            else:
                out[:, c] = values + plus[:, c]
        return out

    def _reflected(self, k):
        b = self._score(k)
        b *= self.incident[k]
        b /= self.paths
        return b

    def reflected(self):
        """(P,3) b = R_j Phi_T I_j / (A_j N), the reflected radiosity."""
        if self.paths == 0:
            return np.zeros((self.scene.patch_count, 3))
        return self._columns(self._reflected)

    def radiosity(self, dtype=np.float64):
        """(P,3) B = E + b of ``dtype`` (the live view asks for float32 while the walks hold
        their sums); in float64 bit for bit E + reflected()."""
        if self.paths == 0:
            return self.scene.emission.astype(dtype)
        return self._columns(self._reflected, dtype, plus=self.scene.emission)

    def irradiance(self, incident=None):
        """(P,3) H, the light arriving at each patch over pi (B = E + R H): incident power over
        area (of ``incident`` (C,P) where given, a part of it)."""
        incident = self.incident if incident is None else incident
        if self.paths == 0:
            return np.zeros((self.scene.patch_count, 3))

        def column(k):
            h = incident[k] * (self.scene.total_power / self.scene.patch_area)
            h /= self.paths
            return h

        return self._columns(column)

    def direct_irradiance(self):
        """(P,3) the direct light's part of ``irradiance``, where every chunk gathered it apart
        (the two-way iteration, the gathered walk); else None."""
        direct = self.direct
        if direct is None and self.groups is not None and self.groups.direct is not None:
            direct = self.groups.direct.sum(axis=0)
        return None if direct is None or self.paths == 0 else self.irradiance(direct)

    def _variance(self, k):
        variance = self._spread(k)
        score = self._score(k)
        score *= score  # (score**2)
        variance *= score
        variance /= (self.chunks - 1) * self.paths
        return variance

    def reflected_variance(self):
        """(P,3) batch-means estimate of Var(b_j) per patch and channel; NaN below 2 chunks."""
        if self.chunks < 2:
            return np.full((self.scene.patch_count, 3), math.nan)
        return self._columns(self._variance)

    def irradiance_variance(self, dtype=np.float32):
        """(P,3) batch-means estimate of Var(H_j), the arriving light's, per patch and channel
        (also where the reflectivity is 0, which reflected_variance cannot say); NaN below 2
        chunks. Float32 by default: a variance is known to a few digits, and it is a (P,3) more."""
        if self.chunks < 2:
            return np.full((self.scene.patch_count, 3), math.nan, dtype)

        def column(k):
            variance = self._spread(k)
            variance *= np.square(self.scene.total_power / self.scene.patch_area)
            variance /= (self.chunks - 1) * self.paths
            return variance

        with np.errstate(over="ignore"):
            out = self._columns(column, dtype)
        if np.isinf(out).any():  # light above about 1e19 (float32's square root): its variance kept in float64
            out = self._columns(column)
        return out

    def _spread(self, k, rows=slice(None)):
        """sum_k I_k^2 / n_k - I^2 / N of channel k at patches ``rows`` (all of them: (P,)), at
        least 0: N (chunks - 1) times the batch variance of I / N. (A new array, computed in place.)"""
        spread = np.square(self._kept_sum(k, rows))
        spread /= self.paths
        np.subtract(self.incident_sq[k, rows], spread, out=spread)
        np.maximum(spread, 0.0, out=spread)
        return spread

    def measured_mse(self):
        """Batch-means estimate of the MSE of the current result (its variance part): the
        area-weighted mean over patches (and channels) of reflected_variance, summed as spread
        times score^2 A_j / (C A_T) a block of patches at a time (no (C,P) array: it is asked
        after every chunk, while the walks hold their sums). Kept for the chunk count it was made at."""
        if self.chunks < 2:
            return math.nan
        if self._mse_at[0] == self.chunks:
            return self._mse_at[1]
        spread_sum = 0.0
        for k, rows, weight in self._squared_score_weights():
            # (einsum, not a BLAS dot: OpenBLAS's threads would spin beside the walks' threads)
            spread_sum += float(np.einsum("i,i->", self._spread(k, rows), weight))
        mse = spread_sum / ((self.chunks - 1) * self.paths)
        self._mse_at = (self.chunks, mse)
        return mse

    def spread_terms(self):
        """The number of independent terms measured_mse's sum over patches and channels is worth,
        (sum t)^2 / sum t^2 of its terms t (inf without error): few where a few patches hold the
        error, whose estimate is then as noisy as a chi-square of that many degrees of freedom.
        From two chunks it reads a third of the true number (a term's square is 3 times its
        variance's): on the safe side."""
        first = second = 0.0
        for k, rows, weight in self._squared_score_weights():
            term = self._spread(k, rows)
            term *= weight
            first += float(term.sum())
            second += float(np.einsum("i,i->", term, term))
        return first * first / second if second > 0 else math.inf

    def mean_reflected(self):
        """The area-weighted mean over patches (and channels) of the reflected radiosity so far,
        sum_j A_j b_j / A_T = Phi_T sum_j R_j I_j / (A_T N) (the scene's hidden patches left out,
        as from the measured MSE): what a relative error on the measured scale is relative to.
        NaN before any path."""
        if self.paths == 0:
            return math.nan
        if self._mean_at[0] != self.chunks:
            scene = self.scene
            # (the hidden patches left out: sum_j w_j b_j, w_j the area share, b_j = R_j Phi_T I_j / (A_j N))
            seen = self._reflectivity if scene.hidden is None else np.where(scene.hidden, 0.0, self._reflectivity)
            reflected = sum(float(np.einsum("i,i->", seen[k], self.incident[k])) for k in range(self.channels))
            self._mean_at = (self.chunks, reflected * scene.total_power / (scene.seen_area * self.paths * self.channels))
        return self._mean_at[1]

    def _increment(self, n, kept):
        """sum over patches (and channels) of A_j / (C A_T) score^2 n N / (N + n) (I_k / n - I / N)^2:
        what a chunk of n paths whose ``kept`` incident power (C,P) is I_k adds to the area-weighted
        sum of squares of the chunks so far (N)."""
        N = self.paths
        total = 0.0
        for k, rows, weight in self._squared_score_weights():
            gap = kept[k, rows] / n
            gap -= self._kept_sum(k, rows) / N
            np.square(gap, out=gap)
            total += float(np.einsum("i,i->", gap, weight))
        return total * (n * N / (N + n))

    def _squared_score_weights(self):
        """(channel k, rows, score^2 A_j / (C A_T) of those rows) a block of MSE_BLOCK patches at a
        time: the weights of the area-weighted mean of squared errors, never a (C,P) array."""
        for start in range(0, self.scene.patch_count, MSE_BLOCK):
            rows = slice(start, start + MSE_BLOCK)
            area_share = self.weight[rows] / self.channels
            for k in range(self.channels):
                weight = self._score(k, rows)
                weight *= weight  # (score**2)
                weight *= area_share
                yield k, rows, weight

    def mse_upper_bound(self, z):
        """The measured MSE (the increments' mean over N: measured_mse to rounding) plus ``z``
        standard errors of it, from the increments' spread: large where they disagree, as when
        a rare chunk carries most of the error or chunks are few. NaN below 3 chunks or without
        increments."""
        if self.increments is None or len(self.increments) < 2:
            return math.nan
        mean = float(np.mean(self.increments))
        spread = float(np.std(self.increments, ddof=1)) / math.sqrt(len(self.increments))
        return (mean + z * spread) / self.paths

    def let_go_of_squares(self):
        """The measured MSE, then the sums of squares let go of (a (C,P) array less while the
        results are made; reflected_variance must be made before)."""
        mse = self.measured_mse()
        self.incident_sq = None
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
