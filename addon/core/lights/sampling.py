"""Sampling for shooting random walks: sources by power, points on patches, cosine directions.

All functions are vectorised over paths and take the uniform random numbers they consume as
arguments, so that they are deterministic and testable.
"""
from __future__ import annotations

import threading

import numpy as np

from ..mesh.faces import ranks_in_runs

TWO_PI = np.float32(2.0 * np.pi)
Z_TOP = np.float32(1.0 - 2.0**-24)  # z = Z_TOP - 2 u: the midpoints of float32's [0, 1) grid
LAST_BELOW_ONE = np.nextafter(1.0, 0.0)
FLOAT32_BELOW_ONE = np.nextafter(np.float32(1.0), np.float32(0.0))
# SourceTable.sample draws multinomial counts when there are at least this many paths per
# source (a binomial draw per source costs about as much as this many per-path choices).
MULTINOMIAL_PATHS_PER_SOURCE = 8


def channel_sum(values):
    """(P,) sums of the three channels of (P,3) ``values``, (v0 + v1) + v2: bit for bit
    ``values.sum(axis=1)`` (numpy adds three items in order), at a tenth of its cost."""
    total = values[:, 0] + values[:, 1]
    total += values[:, 2]
    return total


def source_weights(patch_area, emission, light_power=None, back=None):
    """(S,) what a source is chosen in proportion to: its power summed over the channels, the
    patches' (A_i E_i, twice that where ``back`` (P,) bool: emitters whose back emits too) first,
    then the lights' emitters'."""
    power = patch_area * channel_sum(emission)
    if back is not None:
        power[back] *= 2.0
    if light_power is None or not len(light_power):
        return power
    return np.concatenate([power, channel_sum(light_power)])


class SourceTable:
    """Chooses sources with probability Phi_i / Phi_T, from (S,) ``power`` (source_weights):
    ids below the patch count are emitting patches, the others the lights' emitters.

    A guide table (the cutpoint method) makes each choice O(1) on average: bucket m of M
    equal buckets of [0,1) stores the first source whose cumulative probability passes
    m / M, and a short vectorised walk finishes the search.
    """

    def __init__(self, power):
        self.ids = np.flatnonzero(power > 0)
        cumulative = np.cumsum(power[self.ids])
        self.cdf = cumulative / cumulative[-1]
        self.cdf[-1] = 1.0
        self.probability = power[self.ids] / cumulative[-1]
        self._lock = threading.Lock()
        buckets = self.ids.size
        self.guide = np.searchsorted(self.cdf, np.arange(buckets) / buckets, side="right")

    def stratified(self, count, rng):
        """``count`` sources allotted in proportion to power, and the first ray's uniforms.

        Systematic sampling: the points (k + u0) / count of one random u0 pick the sources, so
        source i gets floor or ceil of count p_i paths, exactly count p_i on average (the
        estimator keeps its expectation). Paths come out grouped by source; the m paths of a
        source take Halton points 0..m-1 (bases 2, 3, 5, 7) for (point, point, direction,
        direction), all shifted by one random vector modulo 1 (Cranley-Patterson), so each
        path's numbers are still uniform. Returns (patch (count,), uniforms (4, count) float32).
        """
        u = (np.arange(count) + rng.random()) / count
        np.minimum(u, LAST_BELOW_ONE, out=u)  # (count - 1 + r) / count can round up to 1
        patch = self.choose(u)
        k = np.searchsorted(self.cdf, u, side="right")
        start = np.searchsorted(k, k, side="left")  # first path of each path's source
        index = np.arange(count) - start
        shift = rng.random(4)
        points = np.take(self._halton_table(count), index, axis=1) + shift[:, None]
        points -= np.floor(points)
        return patch, points.astype(np.float32)

    def _halton_table(self, count):
        """Halton points 0..count-1 in bases 2, 3, 5, 7, computed once and kept (4, n)."""
        table = getattr(self, "_halton", None)
        if table is None or table.shape[1] < count:
            with self._lock:
                table = getattr(self, "_halton", None)
                if table is None or table.shape[1] < count:
                    table = self._halton = halton(np.arange(count), (2, 3, 5, 7))
        return table

    def sample(self, count, rng):
        """``count`` independent source choices (the walks treat paths alike whatever their
        order).

        With few sources, the counts per source are one multinomial draw (the joint law of
        ``count`` independent choices, without their order), O(sources), and the paths come
        grouped by source (rays leaving one patch together are coherent); otherwise each path
        draws its own uniform, O(count).
        """
        if self.draws_counts(count):
            return np.repeat(self.ids, self.counts(count, rng))
        return self.choose(rng.random(count))

    def draws_counts(self, count):
        """Whether :meth:`sample` draws ``count`` choices as counts per source."""
        return self.ids.size * MULTINOMIAL_PATHS_PER_SOURCE <= count

    def counts(self, count, rng):
        """The number of paths from each source (in the order of ``ids``) among ``count``
        independent choices: one multinomial draw, the numbers :meth:`sample` draws when
        :meth:`draws_counts`."""
        return rng.multinomial(count, self.probability)

    def choose(self, u):
        """Source id for each uniform u in [0, 1): the first k with u < cdf[k]."""
        k = self.guide[(u * self.guide.size).astype(np.int64)]
        behind = np.flatnonzero(self.cdf[k] <= u)
        while behind.size:
            k[behind] += 1
            behind = behind[self.cdf[k[behind]] <= u[behind]]
        return self.ids[k]


def halton(index, bases):
    """Radical inverses of the integers ``index`` in each base: (len(bases), n) float64."""
    index = np.asarray(index, dtype=np.int64)
    out = np.zeros((len(bases), index.size))
    for row, base in enumerate(bases):
        i = index.copy()
        f = 1.0 / base
        while i.any():
            out[row] += f * (i % base)
            i //= base
            f /= base
    return out


# Sobol' sequence direction numbers of Joe & Kuo (2008, new-joe-kuo-6.21201), dimensions 2 to
# 10: (s, a, m_1..m_s); dimension 1 is the van der Corput sequence.
JOE_KUO = ((1, 0, (1,)), (2, 1, (1, 3)), (3, 1, (1, 3, 1)), (3, 2, (1, 1, 1)), (4, 1, (1, 1, 3, 3)),
           (4, 4, (1, 3, 5, 13)), (5, 2, (1, 1, 5, 5, 17)), (5, 4, (1, 1, 5, 5, 5)), (5, 7, (1, 1, 7, 11, 19)))
SOBOL_DIMENSIONS = 1 + len(JOE_KUO)


class GrowingTable:
    """Points 0..count-1 of a sequence, ``make(n)`` giving the first n (rows, n), computed once
    and kept, grown (at least doubled) under a lock when more are asked for."""

    def __init__(self, make):
        self._make, self._table, self._lock = make, None, threading.Lock()

    def rows(self, count):
        table = self._table
        if table is None or table.shape[1] < count:
            with self._lock:
                table = self._table
                if table is None or table.shape[1] < count:
                    table = self._table = self._make(max(count, 2 * (0 if table is None else table.shape[1]), 64))
        return table


def sobol_directions(bits=32):
    """(SOBOL_DIMENSIONS, bits) uint32: v_k of each dimension, the k-th bit of an index's
    contribution (x_i = XOR of v_k over the set bits k of i)."""
    v = np.zeros((SOBOL_DIMENSIONS, bits), dtype=np.uint64)
    v[0] = [1 << (bits - 1 - k) for k in range(bits)]
    for d, (s, a, m) in enumerate(JOE_KUO, start=1):
        m = list(m)
        for k in range(s, bits):  # m_k = 2a_1 m_{k-1} ^ 4a_2 m_{k-2} ^ ... ^ 2^s m_{k-s} ^ m_{k-s}
            x = m[k - s] ^ (m[k - s] << s)
            for i in range(1, s):
                x ^= ((a >> (s - 1 - i)) & 1) * (m[k - i] << i)
            m.append(x)
        v[d] = [m[k] << (bits - 1 - k) for k in range(bits)]
    return v.astype(np.uint32)


def _sobol(n):
    v, index = sobol_directions(), np.arange(n, dtype=np.int64)
    table = np.zeros((SOBOL_DIMENSIONS, n), dtype=np.uint32)
    for k in range(int(n - 1).bit_length()):
        table[:, (index >> k) & 1 == 1] ^= v[:, k:k + 1]
    return table


# Sobol' points 0..n-1, (SOBOL_DIMENSIONS, n) uint32 fractions of 2^32.
SOBOL = GrowingTable(_sobol)


def stratified_by_patch(patch, patch_count, rows, rng, dtype=np.float64):
    """(len(rows), n) ``dtype`` in [0, 1) (float32: the points' first 24 bits, so never 1): for samples of patches ``patch`` (n,), grouped by patch
    (each patch's samples one run), sample k of its patch's run takes Sobol' point k in the
    dimensions ``rows``, XORed with a random 32-bit shift of its own for each patch and
    dimension (a random digital shift: each point is uniform, a patch's points stay a
    low-discrepancy set, and patches stay independent of each other)."""
    counts = np.bincount(patch, minlength=patch_count)
    runs = counts.compress(counts > 0)  # the samples of each patch that has any, in order
    rank = ranks_in_runs(runs)
    table = SOBOL.rows(int(runs.max(initial=1)))
    shift = rng.integers(0, 1 << 32, size=(len(rows), runs.size), dtype=np.uint32)  # (a patch with no sample draws none)
    points = table[list(rows)].take(rank, axis=1)
    points ^= np.repeat(shift, runs, axis=1)
    return unit_floats(points, dtype)


def shifted_float32(points):
    """float64 ``points`` (changed in place), each a point in [0, 1) plus a shift in [0, 1)
    (Cranley-Patterson), wrapped modulo 1 into float32 in [0, 1): a float64 just below 1 would
    round to 1 as float32."""
    points -= points >= 1.0
    out = points.astype(np.float32)
    np.minimum(out, FLOAT32_BELOW_ONE, out=out)
    return out


def unit_floats(points, dtype=np.float64):
    """uint32 ``points`` (shifted Sobol' points, changed in place) as ``dtype`` in [0, 1):
    float32 takes their first 24 bits, so never rounds up to 1."""
    if dtype == np.float32:
        points >>= 8
        return points.astype(np.float32) * np.float32(2.0**-24)
    return points * 2.0**-32


def choose_triangles(geometry, patch, u):
    """A triangle of each patch, chosen with probability proportional to its area.

    Patches of one or two triangles (the common case: quads) need one comparison; larger
    patches search their cumulative areas.
    """
    first = geometry.patch_first_triangle.take(patch, mode="wrap")
    if geometry.max_triangles_per_patch == 1:
        return first
    triangle = first + (u >= geometry.patch_first_fraction.take(patch, mode="wrap"))
    if geometry.max_triangles_per_patch > 2:
        many = np.flatnonzero(geometry.patch_triangle_count[patch] > 2)
        if many.size:
            p = patch[many]
            k = np.searchsorted(geometry.triangle_key, p + u[many].astype(np.float64), side="right")
            last = first[many] + geometry.patch_triangle_count[p] - 1
            triangle[many] = np.clip(k, first[many], last)
    return triangle


def points_on_triangles(geometry, triangle, u1, u2):
    """Uniform points on the given triangles, already pushed off the surface along its normal.

    The square [0,1)^2 is folded onto the triangle (u1 + u2 > 1 reflects), which is uniform
    and needs no square root. float32 (n,3), centred coordinates.
    """
    return np.ascontiguousarray(triangle_point_rows(geometry, triangle, u1, u2).T)


def triangle_point_rows(geometry, triangle, u1, u2):
    """:func:`points_on_triangles` as (3,n) rows, one coordinate per row."""
    fold = (u1 + u2) > 1
    return barycentric_point_rows(geometry, triangle, np.where(fold, 1 - u1, u1), np.where(fold, 1 - u2, u2))


def barycentric_point_rows(geometry, triangle, a, b):
    """The points corner0 + a edge1 + b edge2 of the given triangles' leaving frames (inset
    from the edges, pushed off along the normal): (3,n) float32 rows, unit space."""
    frame = np.take(geometry.triangle_frame, triangle, axis=1)  # one gather: (9,n)
    return frame_points(frame, a, b)


def frame_points(frame, a, b):
    """corner + a edge_a + b edge_b from gathered (>=9,n) frame rows [corner, edge_a, edge_b],
    computed in place in ``frame`` (a fresh gather): (3,n) float32 rows, a view of it."""
    frame[3:6] *= a
    frame[6:9] *= b
    points = frame[0:3]
    points += frame[3:6]
    points += frame[6:9]
    return points


def points_on_patches(geometry, patch, u_triangle, u1, u2):
    """Uniform points on the given patches (pushed off along the normal), float32 (n,3).

    Parallelogram patches take corner + u1 a + u2 b; others choose a triangle by area
    (``u_triangle``, which may be None when every patch is a parallelogram) and a point on it.
    """
    return np.ascontiguousarray(patch_point_rows(geometry, patch, u_triangle, u1, u2).T)


def patch_point_rows(geometry, patch, u_triangle, u1, u2):
    """:func:`points_on_patches` as (3,n) rows (points of partly buried patches drawn on their
    visible part: the uniforms are remapped in place, :meth:`.visibility.Buried.remap`)."""
    if geometry.buried is not None:
        geometry.buried.remap(patch, u_triangle, u1, u2)
    if geometry.all_parallelograms:
        return frame_points(np.take(geometry.parallelogram_frame, patch, axis=1), u1, u2)
    points = triangle_point_rows(geometry, choose_triangles(geometry, patch, u_triangle), u1, u2)
    if geometry.any_parallelograms:
        some = np.flatnonzero(geometry.patch_parallelogram[patch])
        if some.size:
            frame = np.take(geometry.parallelogram_frame, patch[some], axis=1)
            points[:, some] = frame_points(frame, u1[some], u2[some])
    return points


def cosine_directions(geometry, patch, u1, u2, normalize=True):
    """Directions about each patch's normal with density cos(theta)/pi. float32 (n,3).

    A uniform point s on the unit sphere, added to the normal, gives the direction n + s of a
    uniform point on the unit sphere resting on the surface, and such directions are
    cosine-distributed (Malley's method seen from the sphere). One gather, no frame.

    z = (1 - 2^-24) - 2 u1 takes the midpoints of u1's float32 grid: symmetric about 0 and
    never +-1, so s is never exactly -n for an axis-aligned normal (n + s = 0 would be no
    direction at all). The ray tracer needs no unit length: with ``normalize=False`` (what the
    walks use) the directions keep the length |n + s| in (0, 2].
    """
    d = np.take(geometry.patch_normal_rows, patch, axis=1)  # (3,n)
    add_sphere_points(d, u1, u2)
    if normalize:
        d /= np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
    return np.ascontiguousarray(d.T)


def add_sphere_points(rows, u1, u2):
    """Adds to each column of ``rows`` (3,n) a uniform point s of the unit sphere, made from
    z = (1 - 2^-24) - 2 u1 and the angle 2 pi u2: turns gathered unit normals n into the
    cosine-distributed directions n + s (see :func:`cosine_directions`), in place."""
    z = u1 * np.float32(-2.0)
    z += Z_TOP
    r = z * z
    np.subtract(1, r, out=r)
    np.sqrt(r, out=r)
    phi = u2 * TWO_PI
    term = np.cos(phi)
    term *= r
    rows[0] += term
    np.sin(phi, out=term)
    term *= r
    rows[1] += term
    rows[2] += z
    return rows


def draw_sources(sources, sizes, rng, stratified=False):
    """Every path's source for chunks of ``sizes`` paths, each chunk's drawn for it alone (a
    sample may come out grouped by source): (source, its chunk or None for one chunk, the
    stratified first rays' uniforms or None)."""
    first_uniforms = None
    if stratified:
        drawn = [sources.stratified(n, rng) for n in sizes]
        source = np.concatenate([d[0] for d in drawn])
        first_uniforms = np.concatenate([d[1] for d in drawn], axis=1)
    else:
        source = np.concatenate([sources.sample(n, rng) for n in sizes])
    source_chunk = np.repeat(np.arange(len(sizes), dtype=np.int32), sizes) if len(sizes) > 1 else None
    return source, source_chunk, first_uniforms


class SourceRuns:
    """The sources of chunks of ``sizes`` paths drawn as counts per source (the same numbers
    ``draw_sources`` draws when every chunk's source table draws counts): the chunk-ordered
    paths come in runs, one per chunk and source, and a wavefront takes them in order."""

    def __init__(self, sources, sizes, rng):
        counts = np.concatenate([sources.counts(n, rng) for n in sizes])
        self.end = np.cumsum(counts)
        self.start = self.end - counts
        self.chunk = np.repeat(np.arange(len(sizes)), sources.ids.size)
        self.source = np.tile(sources.ids, len(sizes))

    def add_window(self, live, first, last):
        """Adds paths ``first`` to ``last`` (exclusive) to the (chunks, patches) counts ``live``:
        from each run overlapping them, as many as overlap (O(runs overlapping), not O(paths))."""
        i = np.searchsorted(self.end, first, side="right")
        j = np.searchsorted(self.start, last, side="left")
        overlap = np.minimum(self.end[i:j], last) - np.maximum(self.start[i:j], first)
        live[self.chunk[i:j], self.source[i:j]] += overlap  # one run per chunk and source


# Halton points 0..n-1 in bases 2, 3, 5, 7, (4, n) float64.
HALTON = GrowingTable(lambda n: halton(np.arange(n), (2, 3, 5, 7)))


def systematic_counts(power, rays, shift):
    """Rays per patch for ``rays`` rays allotted in proportion to ``power`` (P,) by the points
    (k + shift) / rays, k < rays, of [0, 1): floor or ceil of rays p_j each, rays p_j on average."""
    cdf = np.cumsum(power)
    edges = np.ceil(cdf / cdf[-1] * rays - shift).astype(np.int64)
    # From the last patch with power on, every point is below: rays - shift would round to
    # rays - 1 for a shift within 2^-53 of 1.
    edges[cdf == cdf[-1]] = rays
    return np.diff(edges, prepend=0)
