"""Smooth display of per-patch light: corner values without seams, and a noise filter.

Both work on the scene's triangles as the solver sees them (world positions, the patch of each
triangle), whatever object each came from.

Welding. Corners are joined by position, not by vertex index: two vertices closer than ``weld``
on every axis are one point (eight grids of cell 2*weld, shifted by half a cell on each axis, and
their cells' minimum labels propagated to a fixed point), so pieces of different objects that touch
share their corners. Points more than 2*sqrt(3)*weld apart are never joined in one step.

Creases. Every corner carries its patch's normal (the area-weighted mean of the patch's triangle
normals). A corner's value is built only from the corners at its point whose normal is within
``crease_angle`` of its own: a wall and the ceiling keep their own values at their shared edge,
and back-to-back faces never mix. Points whose normals all lie within half the angle of their mean
are smooth (every pair compatible) and take one sum per point; only the other points ("crease
points") are handled pair by pair, so memory stays linear in the triangles.

Mean preservation (``corner_values``). The corners start as the area-weighted average of the
compatible corners around them (a continuous field). Then, ``iterations`` times, each patch's
missing light (its value less the area-weighted mean of the linear interpolation over its
triangles) is spread the same way, continuously, over the corners around it (over-relaxed by 1.5,
values clipped at 0). A last step scales each patch's corners by value / mean, which makes every
patch's mean exactly its value (float error) whatever the iteration count and whatever the mesh;
what the iterations buy is small jumps left by that last step where a continuous answer exists
(benchmarks/results/smoothing.md); a sharp step of light across a smooth joint has no
non-negative continuous answer, and keeps part of its step. Every step keeps values
non-negative (averages of non-negative values, a clip at 0, a non-negative scale); negative
values (a signed estimator's noise) count as 0, non-finite ones are refused.

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
"""
from dataclasses import dataclass

import numpy as np

from .welding import run_starts, weld_points

CREASE_ANGLE = 30.0  # degrees, as Blender's auto smooth
WELD_FRACTION = 1e-4  # of the median patch's side
NOISE_CUTOFF = 3.0  # standard errors beyond which a neighbour is real detail, not noise
ITERATIONS = 10
RELAXATION = 1.5  # over-relaxed corrections leave smaller jumps for the same iterations


# A corner's value never falls below this share of the darkest patch meeting at it (a valley may
# dip below its patches, as a smooth surface through their means must; black it may not).
LOWEST_SHARE = 0.5


@dataclass
class Surface:
    """The scene's triangles as one welded surface, built once for any number of value sets.

    point          (T,3) welded point of every triangle corner
    triangle_area  (T,)  area of each triangle
    patch_area     (P,)  area of each patch
    patch_normal   (P,3) unit normal of each patch (the normal each of its corners carries)
    patch_centroid (P,3) area-weighted centre of each patch
    """
    point: np.ndarray
    triangle_patch: np.ndarray
    triangle_area: np.ndarray
    patch_area: np.ndarray
    patch_normal: np.ndarray
    patch_centroid: np.ndarray
    cos_crease: float
    smooth_point: np.ndarray  # (n,) bool: every pair of corners at the point compatible
    pairs: tuple  # (corner, other corner) flat indices, compatible, at crease points

    @property
    def patch_count(self):
        return len(self.patch_area)

    @classmethod
    def of(cls, vertices, triangles, triangle_patch, patch_count=None, crease_angle=CREASE_ANGLE, weld=None):
        """``vertices`` (V,3) world positions, ``triangles`` (T,3) vertex indices, ``triangle_patch``
        (T,) patch of each triangle; ``weld`` a length (default WELD_FRACTION of the median
        patch's side, at least float32 rounding of the coordinates)."""
        vertices = np.asarray(vertices, np.float64)
        triangles = np.asarray(triangles)
        triangle_patch = np.asarray(triangle_patch)
        if not 0.0 <= crease_angle <= 180.0:
            raise ValueError(f"crease angle {crease_angle} is not between 0 and 180 degrees")
        P = int(patch_count if patch_count is not None else (triangle_patch.max() + 1 if len(triangle_patch) else 0))
        first = vertices[triangles[:, 0]]
        cross = np.cross(vertices[triangles[:, 1]] - first, vertices[triangles[:, 2]] - first)
        triangle_area = 0.5 * np.linalg.norm(cross, axis=1)
        patch_area = np.bincount(triangle_patch, weights=triangle_area, minlength=P)
        normal = np.stack([np.bincount(triangle_patch, weights=cross[:, k], minlength=P) for k in range(3)], axis=1)
        length = np.linalg.norm(normal, axis=1, keepdims=True)
        patch_normal = np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)
        if weld is None:
            side = np.sqrt(np.median(patch_area[patch_area > 0])) if (patch_area > 0).any() else 1.0
            extent = np.abs(vertices).max() if len(vertices) else 1.0
            weld = max(WELD_FRACTION * side, 4 * np.finfo(np.float32).eps * extent)
        centroid = np.zeros((P, 3))
        for k in range(3):  # over axes, not elements
            centre = vertices[triangles, k].mean(axis=1) * triangle_area
            centroid[:, k] = np.bincount(triangle_patch, weights=centre, minlength=P)
        del centre, first, cross
        centroid = np.divide(centroid, patch_area[:, None], out=np.zeros((P, 3)),
                             where=patch_area[:, None] > 0)
        point = weld_points(vertices, weld)[triangles]
        cos_crease = float(np.cos(np.radians(crease_angle)))
        smooth_point, pairs = _crease_pairs(point, triangle_patch, patch_normal, cos_crease)
        return cls(point, triangle_patch, triangle_area, patch_area, patch_normal, centroid, cos_crease,
                   smooth_point, pairs)

    # -- corner values -------------------------------------------------------------------------
    def _averaging(self):
        """What step (a) needs, fixed for the surface: per corner weight, the reciprocal of the
        compatible weight around it (0 where it is zero), the crease corners and their pairs
        renumbered among them."""
        point = self.point.ravel()
        w = np.repeat(self.triangle_area, 3)
        total = np.bincount(point, weights=w, minlength=len(self.smooth_point))[point]
        crease = np.flatnonzero(~self.smooth_point[point])
        c, o = self.pairs
        local = np.searchsorted(crease, c)
        if len(crease):
            total[crease] = np.bincount(local, weights=w[o], minlength=len(crease))
        inverse = np.divide(1.0, total, out=np.zeros_like(total), where=total > 0)
        return point, w, inverse, crease, local, o

    def _average_corners(self, x, averaging):
        """(a): every corner's value (T*3,) the area-weighted mean of the compatible corners at
        its point; 0 where they all have zero area."""
        point, w, inverse, crease, local, o = averaging
        wx = w * x
        out = np.bincount(point, weights=wx, minlength=len(self.smooth_point))[point]
        if len(crease):
            out[crease] = np.bincount(local, weights=wx[o], minlength=len(crease))
        out *= inverse
        return out

    def _corner_lowest(self, x, averaging):
        """(T*3,) the lowest of the compatible corners' values ``x`` at each corner's point."""
        point, _, _, crease, local, o = averaging
        around = np.full(len(self.smooth_point), np.inf)
        np.minimum.at(around, point, x)
        lowest = around[point]
        if len(crease):
            pairs = np.full(len(crease), np.inf)
            np.minimum.at(pairs, local, x[o])
            lowest[crease] = pairs
        return lowest

    def _patch_means(self, x):
        """Area-weighted mean (P,) of the linear interpolation of corner values (T*3,)."""
        tri = x.reshape(-1, 3).sum(axis=1) * (self.triangle_area / 3.0)
        sums = _sum(self.triangle_patch, tri, self.patch_count)
        return np.divide(sums, self.patch_area, out=np.zeros_like(sums), where=self.patch_area > 0)

    def corner_values(self, patch_values, iterations=ITERATIONS):
        """Per triangle corner values (T,3,k) of per-patch values (P,k): continuous across
        compatible corners, the area-weighted mean of each patch's linear interpolation equal to
        its value (negative values taken as 0), non-negative."""
        # a signed estimator's slightly negative patches show as black: light is never negative
        values = np.maximum(_checked(patch_values, self.patch_count, "patch values"), 0.0)
        corner_patch = np.repeat(self.triangle_patch, 3)
        averaging = self._averaging()
        out = np.empty((len(self.triangle_patch), 3, values.shape[1]))
        for k in range(values.shape[1]):  # one colour channel at a time: a third of the memory
            channel = np.ascontiguousarray(values[:, k])
            out[:, :, k] = self._corner_channel(channel, corner_patch, averaging, iterations).reshape(-1, 3)
        return out

    def _corner_channel(self, values, corner_patch, averaging, iterations):
        x = self._average_corners(values[corner_patch], averaging)
        floor = LOWEST_SHARE * self._corner_lowest(values[corner_patch], averaging)
        for _ in range(int(iterations)):
            # each patch's missing light, spread continuously over the corners around it
            missing = (values - self._patch_means(x))[corner_patch]
            x += RELAXATION * self._average_corners(missing, averaging)
            # a bright patch beside dim ones would push its neighbours' far corners down to black:
            # never below a share of the darkest patch meeting there (the last scale keeps means)
            np.maximum(x, floor, out=x)
        means = self._patch_means(x)
        # exact at last: a patch whose corners all came to zero keeps its own value, flat
        scale = np.divide(values, means, out=np.ones_like(values), where=means > 0)
        x *= scale[corner_patch]
        flat = np.flatnonzero((means <= 0)[corner_patch])
        x[flat] = values[corner_patch[flat]]
        return x

    # -- noise ---------------------------------------------------------------------------------
    def neighbours(self, block=1 << 18):
        """Patch pairs (p, q), p != q, both directions, sorted by p: sharing a welded point,
        normals within the crease angle. Made a block of points at a time (``block`` candidate
        pairs), so memory goes with the patches, not with the points' valences squared."""
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

    def fill_from_neighbours(self, patch_values, missing):
        """Per-patch values (P,k) with those flagged ``missing`` (P,k) replaced, per channel, by
        the area-weighted mean of the neighbours' (``neighbours``) that are not; a patch with no
        such neighbour keeps its own. (For values that show nowhere,
        such as the light arriving at a black patch, but join their neighbours' corners.)"""
        values = _checked(patch_values, self.patch_count, "patch values")
        missing = np.asarray(missing, bool).reshape(values.shape)
        if not missing.any():
            return values
        p, q = self.neighbours()
        out = values.copy()
        for c in range(values.shape[1]):  # over channels, not elements
            give = missing[p, c] & ~missing[q, c]
            weight = _sum(p[give], self.patch_area[q[give]], self.patch_count)
            total = _sum(p[give], self.patch_area[q[give]] * values[q[give], c], self.patch_count)
            fill = missing[:, c] & (weight > 0)
            out[fill, c] = total[fill] / weight[fill]
        return out

    def filter_noise(self, patch_values, patch_variances, cutoff=NOISE_CUTOFF, bound=False):
        """Noise-filtered per-patch values (P,k) from values and the variances of their estimates
        (P,k); patches with a NaN or infinite variance are left as they are and not used. With
        ``bound``, also the largest change each patch may have been given (P,k)."""
        values = _checked(patch_values, self.patch_count, "patch values")
        var = np.asarray(patch_variances, np.float64).reshape(values.shape)
        known = np.isfinite(var).all(axis=1) & (var >= 0).all(axis=1)
        largest = float(np.abs(values).max()) if values.size else 0.0
        if not largest > 0:  # no light anywhere (nothing reached a reflecting patch): nothing to filter
            return (values.copy(), np.zeros_like(values)) if bound else values.copy()
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
        fitted = self._local_fit(values, pooled, known, p, q, k)
        out = np.clip(fitted, values - limit, values + limit)
        out = np.where(values >= 0, np.maximum(out, 0.0), out)
        return (out, limit) if bound else out

    def _local_fit(self, values, var, known, p, q, k):
        """Each patch's value from a weighted least-squares plane (value = a + gradient . offset,
        in the patch's tangent plane) through itself and its neighbours q, weights k / var:
        a gradient across the neighbourhood moves no patch."""
        n = self.patch_normal
        axis = np.eye(3)[np.argmin(np.abs(n), axis=1)]
        t1 = np.cross(n, axis)
        t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-300)
        t2 = np.cross(n, t1)
        design = np.zeros((3, len(p)))  # 1 and the neighbour's offset along t1 and t2
        design[0] = 1.0
        for a in range(3):  # over axes, not elements
            offset = self.patch_centroid[q, a] - self.patch_centroid[p, a]
            design[1] += offset * t1[p, a]
            design[2] += offset * t2[p, a]
        del offset
        # a little ridge on the gradient keeps a row of neighbours (an edge) solvable
        ridge = 1e-3 * self.patch_area
        out = values.copy()
        P = len(values)
        for c in range(values.shape[1]):  # over colour channels, not elements
            own = np.where(known, 1.0 / var[:, c], 0.0)
            w = k / var[q, c]
            M = np.empty((P, 3, 3))
            for i in range(3):
                for j in range(i, 3):
                    M[:, i, j] = M[:, j, i] = _sum(p, w * design[i] * design[j], P)
            rhs = np.stack([_sum(p, w * values[q, c] * design[i], P) for i in range(3)], axis=1)
            M[:, 0, 0] += own
            rhs[:, 0] += own * values[:, c]
            M[:, 1, 1] += ridge * M[:, 0, 0]
            M[:, 2, 2] += ridge * M[:, 0, 0]
            solvable = known & (M[:, 0, 0] > 0)
            fit = np.linalg.solve(np.where(solvable[:, None, None], M, np.eye(3)), rhs[:, :, None])[:, 0, 0]
            out[:, c] = np.where(solvable, fit, values[:, c])
        return out


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
        total = _sum(p[give], var[q[give], c], len(var))
        out[:, c] = np.where(zero & (count > 0), total / np.maximum(count, 1), var[:, c])
    return out


def _sum(index, weights, n):
    """np.bincount's sums as floats, also when there is nothing to sum."""
    return np.bincount(index, weights=weights, minlength=n).astype(np.float64, copy=False)


def _checked(values, P, what):
    values = np.asarray(values, np.float64)
    values = values.reshape(len(values), -1) if values.ndim != 2 else values
    if len(values) != P:
        raise ValueError(f"{what}: {len(values)} rows for {P} patches")
    if not np.isfinite(values).all():
        raise ValueError(f"{what} are not all finite")
    return values


def _crease_pairs(point, triangle_patch, patch_normal, cos_crease):
    """(smooth point flags (n,), compatible (corner, other) pairs at the other points); a
    corner's normal is its patch's."""
    p = point.ravel()
    cp = np.repeat(triangle_patch, 3)
    n = int(p.max()) + 1 if len(p) else 0
    mean = np.stack([np.bincount(p, weights=patch_normal[cp, k], minlength=n) for k in range(3)], axis=1)
    length = np.linalg.norm(mean, axis=1, keepdims=True)
    mean = np.divide(mean, length, out=np.zeros_like(mean), where=length > 0)
    dot = np.zeros(len(p))
    for k in range(3):  # over axes, not elements
        dot += patch_normal[cp, k] * mean[p, k]
    half = np.cos(0.5 * np.arccos(np.clip(cos_crease, -1.0, 1.0)))
    lowest = np.full(n, np.inf)
    np.minimum.at(lowest, p, dot)
    del dot
    smooth = (lowest >= half) & (length[:, 0] > 0)
    corners = np.flatnonzero(~smooth[p])
    if len(corners) == 0:
        return smooth, (np.zeros(0, np.int64), np.zeros(0, np.int64))
    corners = corners[np.argsort(p[corners], kind="stable")]
    starts = run_starts(p[corners])
    sizes = np.diff(np.r_[starts, len(corners)])
    square = sizes * sizes
    first = np.repeat(starts, square)
    size = np.repeat(sizes, square)
    rank = np.arange(len(first)) - np.repeat(np.cumsum(square) - square, square)
    c, o = corners[first + rank // size], corners[first + rank % size]
    keep = np.einsum("ij,ij->i", patch_normal[cp[c]], patch_normal[cp[o]]) >= cos_crease
    return smooth, (c[keep], o[keep])


def corner_values(vertices, triangles, triangle_patch, patch_values, crease_angle=CREASE_ANGLE, iterations=ITERATIONS):
    """Smooth per-corner values (T,3,k) of per-patch values (P,k) (``Surface.corner_values``)."""
    surface = Surface.of(vertices, triangles, triangle_patch, len(patch_values), crease_angle)
    return surface.corner_values(patch_values, iterations)


def filter_noise(vertices, triangles, triangle_patch, patch_values, patch_variances, crease_angle=CREASE_ANGLE,
                 cutoff=NOISE_CUTOFF):
    """Noise-filtered per-patch values (P,k) (``Surface.filter_noise``)."""
    surface = Surface.of(vertices, triangles, triangle_patch, len(patch_values), crease_angle)
    return surface.filter_noise(patch_values, patch_variances, cutoff)


def polygon_corner_values(corners, triangles, triangle_patch, corner_patch, corner_point):
    """(n,3) the value at each polygon corner (its patch ``corner_patch`` (n,), its point
    ``corner_point`` (n,), indices of the same arrays as ``triangles``), read from ``corners``
    (T,3,3) at a corner of one of the patch's triangles at that point (every such corner holds the
    same value: the patch's triangles share its normal, so one crease group at each point).
    ValueError where a polygon corner is no corner of its patch's triangles."""
    points = int(max(triangles.max(initial=0), np.max(corner_point, initial=0))) + 1
    key = (np.asarray(triangle_patch, np.int64)[:, None] * points + triangles).ravel()
    order = np.argsort(key, kind="stable")
    wanted = np.asarray(corner_patch, np.int64) * points + corner_point
    at = np.minimum(np.searchsorted(key, wanted, sorter=order), key.size - 1)
    found = order[at]
    if not np.array_equal(key[found], wanted):
        raise ValueError("a polygon corner is not a corner of its patch's triangles")
    return np.asarray(corners).reshape(-1, np.asarray(corners).shape[-1])[found]

