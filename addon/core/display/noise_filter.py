"""The noise filter of smooth display (``smoothing.Surface``), and its fixed-weight form.

Noise (``filter_noise``). Each patch's value is re-estimated from itself and its neighbours
(patches sharing a welded point, normals within the crease angle) by a weighted least-squares
plane in the patch's tangent plane (value = a + gradient . offset of the neighbour's centroid;
the estimate is a). Weights are k over the neighbourhood's mean variance (where hits are sparse
a patch's own grows with its value: weighting by it took light away), k = max(0, 1 - d^2 /
c^2), d^2 the largest over channels of (v_p - v_q)^2 / (s_p^2 + s_q^2), s^2 the measured
(batch-means) variances: neighbours within their noise of the patch are used, neighbours more than c standard errors away (real
detail: a shadow edge, a hot spot) are not used at all, and a linear gradient across the
neighbourhood (light falling off along a wall) is fitted, not averaged away. Bias bound: the
result is clipped to v_p +- c * max over used neighbours of sqrt(s_p^2 + s_q^2), per channel, so
no patch moves by more than c combined standard errors of the estimates it was compared with,
whatever the light (``filter_noise(..., bound=True)`` returns that limit); non-negative values
stay non-negative (clipped at 0). A zero variance (a patch no path reached) is replaced by the
mean of its neighbours' (and the bound with it), so a black speckle neither anchors its neighbours
nor stays black. Patches without a variance (NaN: fewer than two batches) are left as they are.

Fixed weights. The filter's weights and clips come from the values and variances; with
``return_filter`` they are held fixed and the filter is a linear map (``LinearFilter``) whose value
at the values is their filtered values: parts of the values (each source's light) filter to parts
that add up to the filtered whole.
"""
import numpy as np

from ..mesh.welding import run_starts

NOISE_CUTOFF = 3.0  # standard errors beyond which a neighbour is real detail, not noise
FIT_BLOCK = 1 << 16  # neighbour pairs a local fit sums at a time (about 100 bytes of temporaries each)


class NoiseFilter:
    """The noise filter's methods of ``smoothing.Surface`` (its patches, areas, normals, centroids
    and welded points)."""

    def neighbours(self, block=1 << 18):
        """Patch pairs (p, q), p != q, both directions, sorted by p: sharing a welded point,
        normals within the crease angle. Made a block of points at a time (``block`` candidate
        pairs), so memory goes with the patches, not with the points' valences squared. Made once
        a surface (the filters of the light arriving and the reflected light, the fills, read them)."""
        made = self.__dict__.get("_neighbour_pairs")
        if made is None:
            made = self.__dict__["_neighbour_pairs"] = self._neighbours(block)
        return made

    def _neighbours(self, block):
        """``neighbours``, made."""
        P = max(self.patch_count, 1)
        code = np.unique(self.point.ravel().astype(np.int64) * P + np.repeat(self.triangle_patch, 3))
        point, patch = code // P, code % P
        del code
        starts = run_starts(point)
        sizes = np.diff(np.r_[starts, len(point)])
        ends = np.cumsum(sizes * sizes)
        found = []
        lo = 0
        while lo < len(starts):
            hi = max(int(np.searchsorted(ends, ends[lo] - sizes[lo] ** 2 + block, "right")), lo + 1)
            s, n = starts[lo:hi], sizes[lo:hi]
            square = n * n
            first = np.repeat(s, square)
            size = np.repeat(n, square)
            rank = np.arange(len(first)) - np.repeat(np.cumsum(square) - square, square)
            a, b = patch[first + rank // size], patch[first + rank % size]
            keep = (a != b) & (np.einsum("ij,ij->i", self.patch_normal[a], self.patch_normal[b]) >= self.cos_crease)
            found.append(np.unique(a[keep] * P + b[keep]))
            lo = hi
        pair = np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)
        small = np.int32 if P < 2 ** 31 else np.int64
        return (pair // P).astype(small), (pair % P).astype(small)

    def fill_from_neighbours(self, patch_values, missing, return_filter=False):
        """Per-patch values (P,k) with those flagged ``missing`` (P,k) replaced, per channel, by
        the area-weighted mean of the neighbours' (``neighbours``) that are not; a patch with no
        such neighbour keeps its own. (For values that show nowhere,
        such as the light arriving at a black patch, but join their neighbours' corners.) With
        ``return_filter``, also the fill as a linear map of (P,k) or (S,P,k) (``LinearFilter``)."""
        values = checked_rows(patch_values, self.patch_count, "patch values")
        missing = np.asarray(missing, bool).reshape(values.shape)
        if not missing.any():
            return (values, LinearFilter.identity(values.shape)) if return_filter else values
        p, q = self.neighbours()
        out = values.copy()
        own, pair = np.ones_like(values), np.zeros((len(p), values.shape[1]))
        for c in range(values.shape[1]):  # over channels, not elements
            give = missing[p, c] & ~missing[q, c]
            weight = sums_by(p[give], self.patch_area[q[give]], self.patch_count)
            total = sums_by(p[give], self.patch_area[q[give]] * values[q[give], c], self.patch_count)
            fill = missing[:, c] & (weight > 0)
            out[fill, c] = total[fill] / weight[fill]
            if return_filter:
                own[fill, c] = 0.0
                pair[give, c] = np.where(fill[p[give]], self.patch_area[q[give]] / np.maximum(weight[p[give]], 1e-300), 0.0)
        return (out, LinearFilter(p, q, own, pair, np.ones_like(values))) if return_filter else out

    def filter_light(self, patch_values, patch_variances, return_filter=False):
        """``filter_noise`` of the values taken as at least 0 (light is never negative: a signed
        estimator's noise about 0). With ``return_filter``, also ``apply`` (``Chain``): linear,
        the whole's negative patches 0 in every part, so that parts add up to the whole's
        filtered values."""
        values = checked_rows(patch_values, self.patch_count, "patch values")
        filtered = self.filter_noise(np.maximum(values, 0.0), patch_variances, return_filter=return_filter)
        if not return_filter:
            return filtered
        return filtered[0], Chain(values > 0, filtered[1])

    def arriving_light(self, irradiance, variance, reflectivity, return_filter=False):
        """(P,3) the light arriving at each patch (H: B = E + rho H), at least 0, its noise
        filtered as the reflected light's is, from its own batch-means variance. Where a
        channel's reflectivity is 0 the light shows nowhere (the surface is black there) but joins
        the neighbours' corners, and the two-way iteration gathers it with a thousandth of the
        samples (a heavy-tailed estimate): there it is the neighbours' (``fill_from_neighbours``).
        With ``return_filter``, also ``apply`` (``Chain``): the same steps as a linear map, the
        fill's and the filter's weights those of these values."""
        irradiance = checked_rows(irradiance, self.patch_count, "irradiance")
        black = np.asarray(reflectivity) <= 0
        light = np.maximum(irradiance, 0.0)
        variance = np.asarray(variance, np.float64)
        fill = None
        if black.any():
            light, fill = self.fill_from_neighbours(light, black, return_filter=True)
            # as noisy as the neighbours it came from: never an anchor for them
            measured = np.isfinite(variance)
            filled = self.fill_from_neighbours(np.where(measured, variance, 0.0), black | ~measured)
            variance = np.where(black & measured, filled, variance)
        filtered = self.filter_noise(light, variance, return_filter=return_filter)
        if not return_filter:
            return filtered
        return filtered[0], Chain(irradiance > 0, *([fill] if fill is not None else []), filtered[1])

    def filter_noise(self, patch_values, patch_variances, cutoff=NOISE_CUTOFF, bound=False, return_filter=False):
        """Noise-filtered per-patch values (P,k) from values and the variances of their estimates
        (P,k); patches with a NaN or infinite variance are left as they are and not used. With
        ``bound``, also the largest change each patch may have been given (P,k). With
        ``return_filter``, also ``apply``: the filter with these values' weights and clips held
        fixed, a linear map of (P,k) or (S,P,k) arrays (``LinearFilter``) whose value at
        ``patch_values`` is the filtered values (float error), so that parts of the values
        (each source's) filter to parts that add up to the filtered whole."""
        values = checked_rows(patch_values, self.patch_count, "patch values")
        var = np.asarray(patch_variances, np.float64).reshape(values.shape)
        known = np.isfinite(var).all(axis=1) & (var >= 0).all(axis=1)
        largest = float(np.abs(values).max()) if values.size else 0.0
        if not largest > 0:  # no light anywhere (nothing reached a reflecting patch): nothing to filter
            out = (values.copy(), np.zeros_like(values)) if bound else (values.copy(),)
            return _with_filter(out, LinearFilter.identity(values.shape), return_filter, bound)
        floor = 1e-12 * largest ** 2
        p, q = self.neighbours()
        var = _unmeasured_from_neighbours(np.where(known[:, None], var, np.nan), p, q)
        var = np.where(known[:, None], np.maximum(var, floor), np.inf)
        d2 = np.zeros(len(p))
        for c in range(values.shape[1]):  # over colour channels, not elements
            np.maximum(d2, (values[p, c] - values[q, c]) ** 2 / (var[p, c] + var[q, c]), out=d2)
        k = np.where(known[p] & known[q], np.clip(1.0 - d2 / cutoff ** 2, 0.0, None), 0.0)
        del d2
        used = k > 0
        pooled = _pooled(var, known, p, q)
        p, q, k = p[used], q[used], k[used]
        limit = np.zeros_like(values)
        if len(p):
            runs = run_starts(p)
            for c in range(values.shape[1]):
                limit[p[runs], c] = cutoff * np.sqrt(np.maximum.reduceat(var[p, c] + var[q, c], runs))
        fitted, weights = self._local_fit(values, pooled, known, p, q, k, operator=return_filter)
        out = np.clip(fitted, values - limit, values + limit)
        out = np.where(values >= 0, np.maximum(out, 0.0), out)
        if not return_filter:
            return (out, limit) if bound else out
        # the clips as a fixed share of the fit's change: out = v + share (fit - v)
        change = fitted - values
        share = np.divide(out - values, change, out=np.ones_like(change), where=change != 0)
        apply = LinearFilter(p, q, weights[0], weights[1], share)
        return _with_filter((out, limit) if bound else (out,), apply, True, bound)

    def _local_fit(self, values, var, known, p, q, k, operator=False):
        """Each patch's value from a weighted least-squares plane (value = a + gradient . offset,
        in the patch's tangent plane) through itself and its neighbours q, weights k / var:
        a gradient across the neighbourhood moves no patch. Returns (fit, weights): with
        ``operator``, weights = (own (P,k), pair (n,k)), the fit as a sum over values (fit_p =
        own_p v_p + sum_q pair_pq v_q); else None. The pairs' sums are made FIT_BLOCK pairs at a
        time (the pairs' temporaries were the peak memory of the largest scenes' smoothing)."""
        P, C = values.shape
        frame = self._tangents()
        ridge = 1e-3 * self.patch_area  # (a little ridge on the gradient keeps a row of neighbours solvable)
        out = values.copy()
        if operator:
            own_weight, pair_weight = np.empty_like(values), np.empty((len(p), C))
        for c in range(C):  # over colour channels, not elements
            m, rhs = np.zeros((P, 3, 3)), np.zeros((P, 3))
            for block in _blocks(len(p)):
                pb, qb = p[block], q[block]
                lo, hi = int(pb[0]), int(pb[-1]) + 1  # (p sorted: the block's patches are a run)
                local = pb - lo
                design = self._design(pb, qb, frame)
                w = k[block] / var[qb, c]
                for i in range(3):
                    wd = w * design[i]
                    rhs[lo:hi, i] += sums_by(local, wd * values[qb, c], hi - lo)
                    for j in range(i, 3):
                        m[lo:hi, i, j] += sums_by(local, wd * design[j], hi - lo)
            for i, j in ((1, 0), (2, 0), (2, 1)):
                m[:, i, j] = m[:, j, i]
            own = np.where(known, 1.0 / var[:, c], 0.0)
            m[:, 0, 0] += own
            rhs[:, 0] += own * values[:, c]
            m[:, 1, 1] += ridge * m[:, 0, 0]
            m[:, 2, 2] += ridge * m[:, 0, 0]
            solvable = known & (m[:, 0, 0] > 0)
            m[~solvable] = np.eye(3)
            fit = np.linalg.solve(m, rhs[:, :, None])[:, 0, 0]
            out[:, c] = np.where(solvable, fit, values[:, c])
            if operator:
                # a = g . rhs, g the first row of M's inverse (M is symmetric)
                g = np.linalg.solve(m, np.broadcast_to(np.eye(3)[:, :1], (P, 3, 1)))[:, :, 0]
                g[~solvable] = 0.0
                own_weight[:, c] = np.where(solvable, g[:, 0] * own, 1.0)
                for block in _blocks(len(p)):
                    pb, qb = p[block], q[block]
                    design = self._design(pb, qb, frame)
                    pair_weight[block, c] = k[block] / var[qb, c] * (
                        g[pb, 0] * design[0] + g[pb, 1] * design[1] + g[pb, 2] * design[2])
        return out, ((own_weight, pair_weight) if operator else None)

    def _tangents(self):
        """(t1, t2) (P,3) each: a frame of each patch's tangent plane."""
        n = self.patch_normal
        axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
        t1 = np.cross(n, axis)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-300)
        return t1, np.cross(n, t1)

    def _design(self, p, q, frame):
        """(3, n) 1 and the neighbour's offset along p's tangents t1 and t2, of pairs (p, q)."""
        t1, t2 = frame
        design = np.zeros((3, len(p)))
        design[0] = 1.0
        for a in range(3):  # over axes, not elements
            offset = self.patch_centroid[q, a] - self.patch_centroid[p, a]
            design[1] += offset * t1[p, a]
            design[2] += offset * t2[p, a]
        return design


class LinearFilter:
    """The noise filter with its weights held fixed: ``apply(x)`` = x + share (own x + sum over
    neighbour pairs (p, q) of pair x_q - x), per patch and channel, for x (P,k) or (S,P,k) (each of
    S parts alike); linear in x. ``share`` (P,k) is what the clips left of each patch's change."""

    def __init__(self, p, q, own, pair, share):
        self.p, self.q, self.own, self.pair, self.share = p, q, own, pair, share

    @classmethod
    def identity(cls, shape):
        empty = np.zeros(0, np.int32)
        return cls(empty, empty, np.ones(shape), np.zeros((0, shape[1])), np.zeros(shape))

    def __call__(self, x):
        x = np.asarray(x, np.float64)
        if x.shape[-2:] != self.own.shape:
            raise ValueError(f"the filter takes values of shape (P, k) = {self.own.shape} (or (S, P, k)); got {x.shape}")
        if x.ndim == 3:
            return np.stack([self(part) for part in x])
        P = len(x)
        out = x.copy()
        for c in range(x.shape[1]):  # over colour channels, not elements
            fit = self.own[:, c] * x[:, c] + sums_by(self.p, self.pair[:, c] * x[self.q, c], P)
            out[:, c] += self.share[:, c] * (fit - x[:, c])
        return out


class Chain:
    """Linear maps one after the other, after zeroing where ``keep`` (P,k) is False: a whole's
    steps (at least 0, a fill, a filter) applied to each of its parts (P,k) or (S,P,k)."""

    def __init__(self, keep, *steps):
        self.keep, self.steps = keep, steps

    def __call__(self, x):
        x = np.where(self.keep, np.asarray(x, np.float64), 0.0)
        for step in self.steps:
            x = step(x)
        return x


def _with_filter(out, apply, return_filter, bound):
    """filter_noise's return: the filtered values, then the bound with ``bound``, then ``apply``."""
    out = out + ((apply,) if return_filter else ())
    return out if len(out) > 1 else out[0]


def _pooled(var, known, p, q):
    """Each patch's variance as the mean of its own and its known neighbours', for the fit's weights
    (a patch's own grows with its value where hits are sparse: weighting by it lost light)."""
    P = len(var)
    finite = np.where(known[:, None], var, 0.0)
    count = np.bincount(p, weights=known[q].astype(np.float64), minlength=P) + known
    pooled = np.stack([np.bincount(p, weights=finite[q, c], minlength=P) + finite[:, c] for c in range(var.shape[1])], axis=1)
    return np.where(known[:, None], pooled / np.maximum(count, 1)[:, None], var)


def _unmeasured_from_neighbours(var, p, q):
    """Variances (P,k) where a zero (a patch no path reached: its batches all agree on nothing)
    is replaced by the mean of its neighbours' non-zero ones, so that it neither anchors its
    neighbours nor stays as it is when they disagree with it."""
    zero = (var == 0).all(axis=1)
    if not zero.any():
        return var
    out = var.copy()
    give = (~zero[q]) & zero[p] & np.isfinite(var[q]).all(axis=1)
    count = np.bincount(p[give], minlength=len(var))
    for c in range(var.shape[1]):
        total = sums_by(p[give], var[q[give], c], len(var))
        out[:, c] = np.where(zero & (count > 0), total / np.maximum(count, 1), var[:, c])
    return out


def _blocks(n, size=FIT_BLOCK):
    """Slices of ``size`` of n pairs."""
    return [slice(start, min(n, start + size)) for start in range(0, n, size)]


def sums_by(index, weights, n):
    """np.bincount's sums as floats, also when there is nothing to sum."""
    return np.bincount(index, weights=weights, minlength=n).astype(np.float64, copy=False)


def checked_rows(values, P, what):
    """``values`` as (P, k) float64 rows, one a patch; ValueError naming ``what`` where they are not
    one a patch or not finite."""
    values = np.asarray(values, np.float64)
    values = values.reshape(len(values), -1) if values.ndim != 2 else values
    if len(values) != P:
        raise ValueError(f"{what}: {len(values)} rows for {P} patches")
    if not np.isfinite(values).all():
        raise ValueError(f"{what} are not all finite")
    return values
