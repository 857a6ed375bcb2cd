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
points") are handled pair by pair, so memory stays linear in the triangles. A cover's outline (a
panel's under a ceiling: ``refine.covered_parts``) is a crease too: the gap's light stays in the gap.

Mean preservation (``corner_values``). The corners start as the area-weighted average of the
compatible corners around them (a continuous field). Then, ``iterations`` times, each patch's
missing light (its value less the area-weighted mean of the linear interpolation over its
triangles) is spread the same way, continuously, over the corners around it (over-relaxed by 1.5,
values clipped at 0). A last step scales each patch's corners by value / mean, which makes every
patch's mean exactly its value (float error) whatever the iteration count and whatever the mesh;
what the iterations buy is small jumps left by that last step where a continuous answer exists
(benchmarks/results/smoothing.md). Given a ``slack`` (``slack.slack_of``: the solve's
values are estimates), the steps spread only the light missing beyond it and the last step takes
each mean only as far as to within it of the value: a patch whose value is its neighbours' plus
noise shows their continuous light, not a square of its own (a scale of its own is a jump at its
edges), and what a mean keeps from its value is within the patch's own noise; a sharp step of
light across a smooth joint has no
non-negative continuous answer, and keeps part of its step. Where light falls off faster than a
patch can follow, the continuous answer swings corners up and down row after row (bands): where
the iterations turn a patch's corners against the plain average's, it and its neighbours keep
the plain average, scaled, in every channel if in one (``_ringing``). Every step keeps values
non-negative (averages of non-negative values, a clip at 0, a non-negative scale); negative
values (a signed estimator's noise) count as 0, non-finite ones are refused.

Noise (``filter_noise``): ``noise_filter``.
"""
from dataclasses import dataclass

import numpy as np

from .creases import crease_pairs
from .noise_filter import NOISE_CUTOFF, NoiseFilter, checked_rows, sums_by
from .slack import beyond
from ..distributed.runners import each_on_threads
from ..mesh.welding import weld_points

CREASE_ANGLE = 30.0  # degrees, as Blender's auto smooth
WELD_FRACTION = 1e-4  # of the median patch's side
ITERATIONS = 10
# A patch rings where its corners' deviations from its value, after the iterations, correlate
# below -RINGING with the plain average's (turned against it, not a rounding's sign).
RINGING = 0.5
RINGING_BLOCK = 1 << 16  # corners compared at a time (a few hundred kB of temporaries)
SIGNIFICANT = 1e-3  # nor where the iterations moved its corners by less than this share of its value (RMS)
RELAXATION = 1.5  # over-relaxed corrections leave smaller jumps for the same iterations
# Channels (and parts) on the local threads up to this many corners, above one at a time: a channel
# holds a few (T*3,) float64 arrays, two at once passed the command line's memory bound a patch.
THREADED_CORNERS = 1 << 19

# A corner's value never falls below this share of the darkest patch meeting at it (a valley may
# dip below its patches, as a smooth surface through their means must; black it may not).
LOWEST_SHARE = 0.5
# A patch whose corners' mean came below this share of its value shows flat: scaled up, they would
# make a spike, and each source's corners (linear maps of the same steps) cancel past float32's digits.
FLAT_BELOW = 1e-3


@dataclass
class Surface(NoiseFilter):
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
    hidden: np.ndarray | None = None  # (P,) bool: patches no camera sees, which no neighbour's corners read
    # (T*3,) each corner's weight in its patch's mean over the part seen (covered.visible_corner_weights), and
    # (P,) that part's area; None: every patch seen whole (a third of each triangle's area a corner)
    visible: np.ndarray | None = None
    visible_area: np.ndarray | None = None
    covered: np.ndarray | None = None  # (P,) bool: patches under a cover, kept apart from the rest as at a crease

    @property
    def patch_count(self):
        return len(self.patch_area)

    @classmethod
    def of(cls, vertices, triangles, triangle_patch, patch_count=None, crease_angle=CREASE_ANGLE, weld=None, hidden=None,
           visible=None, covered=None):
        """``vertices`` (V,3) world positions, ``triangles`` (T,3) vertex indices, ``triangle_patch``
        (T,) patch of each triangle; ``weld`` a length (default WELD_FRACTION of the median
        patch's side, at least float32 rounding of the coordinates); ``hidden`` (P,) bool the
        patches no camera sees (``covered.hidden_patches``: under a box, behind a panel that
        touches them), whose light, nothing or little, joins no visible neighbour's corners;
        ``visible`` (T,3) each corner's weight in its patch's mean over the part seen (partly
        buried patches: ``covered.visible_corner_weights``), the mean every patch's corners keep; ``covered``
        (P,) bool the patches under a cover (``covered_parts.CoveredSplit``): a crease."""
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
        covered = None if covered is None or not np.any(covered) else np.asarray(covered, bool)
        smooth_point, pairs = crease_pairs(point, triangle_patch, patch_normal, cos_crease, covered)
        hidden = None if hidden is None or not np.any(hidden) else np.asarray(hidden, bool)
        if visible is not None:
            visible = np.asarray(visible, np.float64).reshape(-1)
            visible_area = np.bincount(np.repeat(triangle_patch, 3), weights=visible, minlength=P)
        return cls(point, triangle_patch, triangle_area, patch_area, patch_normal, centroid, cos_crease,
                   smooth_point, pairs, hidden, visible, None if visible is None else visible_area, covered)

    # -- corner values -------------------------------------------------------------------------
    def _averaging(self):
        """What step (a) needs, fixed for the surface: per corner weight, the reciprocal of the
        compatible weight around it (0 where it is zero), the crease corners and their pairs
        renumbered among them."""
        point = self.point.ravel()
        w = np.repeat(self.triangle_area if self.hidden is None else self.triangle_area * ~self.hidden[self.triangle_patch], 3)
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
        out = np.bincount(point, weights=wx, minlength=len(self.smooth_point)).take(point, mode="wrap")  # (take: faster)
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

    def corner_means(self, x):
        """Area-weighted mean (P,) of the linear interpolation of corner values (T*3,) over each
        patch (over the part seen, where ``visible`` is given)."""
        seen = self.visible is not None
        y = x * self.visible if seen else x
        tri = y[0::3] + y[1::3]  # (a triangle's three corners added in order: as sum(axis=1) adds them, 8x faster)
        tri += y[2::3]
        if not seen:
            tri *= self.__dict__.setdefault("_third_area", self.triangle_area / 3.0)  # (made once)
        sums = sums_by(self.triangle_patch, tri, self.patch_count)
        area = self.visible_area if seen else self.patch_area
        return np.divide(sums, area, out=np.zeros_like(sums), where=area > 0)

    def interpolated(self, corners):
        """``corners`` (..., T,3,k) as this surface shows them: its own (a refined surface carries a
        coarse one's to its cells: ``refine.cell_meshes.RefinedSurface``)."""
        return corners

    def corner_values(self, patch_values, iterations=ITERATIONS, return_filter=False, dtype=np.float64, slack=None):
        """Per triangle corner values (T,3,k) of per-patch values (P,k): continuous across
        compatible corners, the area-weighted mean of each patch's linear interpolation equal to
        its value (negative values taken as 0), or with ``slack`` (P,k) (``slack.slack_of``; NaN:
        none), within that of it; non-negative. With ``return_filter``, also
        ``apply`` (``LinearCorners``): the same steps with these values' clips, floors and final
        scales held fixed, a linear map of (P,k) or (S,P,k) values to (T,3,k) or (S,T,3,k) corners
        whose value at ``patch_values`` is these corners (float error), so that parts of the
        values (each source's) give corners that add up to these. Made in float64 a channel at
        a time, given as ``dtype``."""
        # a signed estimator's slightly negative patches show as black: light is never negative
        checked = checked_rows(patch_values, self.patch_count, "patch values")
        values = np.maximum(checked, 0.0)
        if slack is not None:  # (what is not a finite standard error keeps the mean exact)
            slack = np.asarray(slack, np.float64).reshape(values.shape)
            slack = np.where(np.isfinite(slack) & (slack > 0), slack, 0.0)
        corner_patch = np.repeat(self.triangle_patch, 3)
        averaging = self._averaging()
        out = np.empty((len(self.triangle_patch), 3, values.shape[1]), dtype)
        made = [None] * values.shape[1]
        rings = np.zeros(self.patch_count, bool)

        def channel(k):  # (a colour channel a thread: a channel's memory each)
            record = {} if return_filter else None
            x, plain_scale, ringing = self._corner_channel(np.ascontiguousarray(values[:, k]), corner_patch, averaging,
                                                           iterations, record, None if slack is None else slack[:, k])
            out[:, :, k] = x.reshape(-1, 3)
            made[k] = record, plain_scale, ringing

        each_on_threads(values.shape[1], channel, 1 if corner_patch.size > THREADED_CORNERS else None)
        records, plain_scales = [m[0] for m in made], [m[1] for m in made]
        for _, _, ringing in made:
            rings |= ringing
        # patches that ring in any channel take the plain average in every one (no colour fringes);
        # it is made again here (one averaging pass) rather than kept from each channel's steps
        flat_out = out.reshape(-1, values.shape[1])
        for k, (record, plain_scale) in enumerate(zip(records, plain_scales)):
            if rings.any():
                plain = self._average_corners(np.ascontiguousarray(values[:, k])[corner_patch], averaging)
                _put_rings(flat_out[:, k], plain, plain_scale, rings, corner_patch)
            if record is not None:
                record["rings"], record["plain_scale"] = rings, plain_scale
        if not return_filter:
            return out
        return out, LinearCorners(self, checked > 0, corner_patch, averaging, int(iterations), records)

    def _corner_channel(self, values, corner_patch, averaging, iterations, record=None, slack=None):
        """One channel's corners (T*3,), the scales (P,) of its plain average (no iterations) and
        its ringing patches (P,) bool (``_ringing``); ``record`` (a dict), where given, keeps the
        floored corners of each step, the floors' patches, the final scales and the flat corners;
        ``slack`` (P,): how far each patch's mean may stay from its value (``_scale_to``)."""
        x = self._average_corners(values.take(corner_patch, mode="wrap"), averaging)
        floor = LOWEST_SHARE * self._corner_lowest(self._seen_values(values, corner_patch), averaging)
        floor[np.isinf(floor)] = 0.0  # (a point only hidden patches meet)
        if record is not None:
            record["lowest"] = self._corner_lowest_patch(values, corner_patch, averaging)
            record["floored"] = []
            if slack is not None:
                record["kept"] = []
        for _ in range(int(iterations)):
            # each patch's missing light, spread continuously over the corners around it (with a
            # slack, only what is missing beyond it: noise within it is not chased into swings)
            missing = values - self.corner_means(x)
            if slack is not None:  # (the shares as float16: a relight's map keeps one a patch a step)
                kept = beyond(missing, slack).astype(np.float16)
                missing *= kept
                if record is not None:
                    record["kept"].append(kept)
            x += RELAXATION * self._average_corners(missing.take(corner_patch, mode="wrap"), averaging)
            if record is not None:
                record["floored"].append(np.flatnonzero(x < floor))
            # a bright patch beside dim ones would push its neighbours' far corners down to black:
            # never below a share of the darkest patch meeting there (the last scale keeps means)
            np.maximum(x, floor, out=x)
        del floor  # (a (T*3,) array less while the plain average is made)
        x, scale, flat = self._scale_to(values, x, corner_patch, slack)
        # (no iterations, made again rather than kept through them: what ringing falls back to)
        plain, plain_scale, _ = self._scale_to(values, self._average_corners(values.take(corner_patch, mode="wrap"), averaging),
                                               corner_patch, slack)
        if record is not None:
            record["scale"], record["flat"] = scale, flat
        return x, plain_scale, self._ringing(values, x, plain, corner_patch)

    def _scale_to(self, values, x, corner_patch, slack=None):
        """Corners ``x`` (T*3,) scaled in place to each patch's value (exact at last; with
        ``slack`` (P,), only as far as to within it: a mean already that close keeps its corners;
        a patch whose corners all came to zero, or below FLAT_BELOW of its value, keeps its own
        value, flat): (x, scales (P,), flat corners)."""
        means = self.corner_means(x)
        low = means <= FLAT_BELOW * values
        target = values if slack is None else np.clip(means, values - slack, values + slack)
        scale = np.divide(target, means, out=np.ones_like(values), where=~low)
        x *= scale.take(corner_patch, mode="wrap")
        flat = np.flatnonzero(low[corner_patch])
        x[flat] = values[corner_patch[flat]]
        return x, scale, flat

    def _ringing(self, values, x, plain, corner_patch):
        """(P,) bool: the patches whose corners the iterations turned against the plain average's
        (their deviations from the patch's value correlated below -RINGING), and the patches
        around them: light falling off faster than a patch can follow, where keeping every mean
        swings corners up and down row after row (bands); they keep the plain average."""
        agree, own_size, plain_size = (np.zeros(self.patch_count) for _ in range(3))
        for start in range(0, len(x), RINGING_BLOCK):  # (a block of corners at a time: no (T*3,) temporaries)
            rows = slice(start, start + RINGING_BLOCK)
            patches = corner_patch[rows]
            own, other = x[rows] - values[patches], plain[rows] - values[patches]
            agree += sums_by(patches, own * other, self.patch_count)
            own_size += sums_by(patches, own * own, self.patch_count)
            plain_size += sums_by(patches, other * other, self.patch_count)
        # (where the iterations moved nothing that matters, the correlation is a rounding's sign)
        counts = np.bincount(corner_patch, minlength=self.patch_count)
        moved = own_size > counts * np.square(SIGNIFICANT * values)
        ringing = moved & (agree < -RINGING * np.sqrt(own_size * plain_size))
        # and the patches around them, so that the steep part is plain on both sides of each corner
        point = self.point.ravel()
        touched = np.zeros(len(self.smooth_point), bool)
        blocks = [slice(start, start + RINGING_BLOCK) for start in range(0, len(x), RINGING_BLOCK)]
        for rows in blocks:
            touched[point[rows][ringing[corner_patch[rows]]]] = True
        rings = np.zeros(self.patch_count, bool)
        for rows in blocks:
            rings[corner_patch[rows][touched[point[rows]]]] = True
        return rings

    def _seen_values(self, values, corner_patch):
        """(T*3,) each corner's patch value, inf at hidden patches' (no floor is a share of them)."""
        x = values[corner_patch]
        return x if self.hidden is None else np.where(self.hidden[corner_patch], np.inf, x)

    def _corner_lowest_patch(self, values, corner_patch, averaging):
        """(T*3,) the patch of the lowest of the compatible corners' values at each corner's
        point (``_corner_lowest``'s, as a patch: what the floor is a share of)."""
        point, _, _, crease, local, o = averaging
        x = self._seen_values(values, corner_patch)
        lowest = _first_lowest(point, x, len(self.smooth_point))[point]
        if len(crease):  # (a crease corner with no compatible pair, a patch of no normal, keeps its point's)
            first = _first_lowest(local, x[o], len(crease))
            lowest[crease[first < len(o)]] = o[first[first < len(o)]]
        return corner_patch[lowest]


def _first_lowest(index, x, n):
    """(n,) at each of n ``index`` values the first position of the least ``x`` there (a stable sort's)."""
    least = np.full(n, np.inf)
    np.minimum.at(least, index, x)
    at = np.flatnonzero(x == least[index])
    first = np.full(n, len(x), np.int64)
    np.minimum.at(first, index[at], at)
    return first


class LinearCorners:
    """``Surface.corner_values`` with the clips, floors and scales of one set of values held
    fixed: ``apply(x)``, x (P,k) or (S,P,k), gives (T,3,k) or (S,T,3,k) corners, linear in x."""

    def __init__(self, surface, positive, corner_patch, averaging, iterations, records):
        self.surface, self.positive, self.corner_patch = surface, positive, corner_patch
        self.averaging, self.iterations, self.records = averaging, iterations, records

    def __call__(self, x, dtype=np.float64):
        """The corners of ``x`` (P,k) or (S,P,k), made in float64, given as ``dtype``."""
        x = np.asarray(x, np.float64)
        if x.shape[-2:] != self.positive.shape:
            raise ValueError(f"the corners take values of shape (P, k) = {self.positive.shape} (or (S, P, k)); got {x.shape}")
        if x.ndim == 3:
            out = np.empty((len(x), len(self.surface.triangle_patch), 3, x.shape[2]), dtype)
            each_on_threads(len(x), lambda s: out.__setitem__(s, self(x[s], dtype)),  # (a part a thread)
                            1 if self.corner_patch.size > THREADED_CORNERS else None)
            return out
        surface, cp = self.surface, self.corner_patch
        values = np.where(self.positive, x, 0.0)  # (the whole's negative patches count as 0)
        out = np.empty((len(surface.triangle_patch), 3, values.shape[1]), dtype)

        def channel(k):  # (a colour channel a thread)
            record, v = self.records[k], np.ascontiguousarray(values[:, k])
            corner = surface._average_corners(v.take(cp, mode="wrap"), self.averaging)
            plain = corner.copy()
            for step, floored in enumerate(record["floored"]):
                missing = v - surface.corner_means(corner)
                if "kept" in record:  # (the whole's shares beyond its slack, held fixed)
                    missing *= record["kept"][step]
                corner += RELAXATION * surface._average_corners(missing.take(cp, mode="wrap"), self.averaging)
                corner[floored] = LOWEST_SHARE * v[record["lowest"][floored]]
            corner *= record["scale"].take(cp, mode="wrap")
            corner[record["flat"]] = v[cp[record["flat"]]]
            _put_rings(corner, plain, record["plain_scale"], record["rings"], cp)
            out[:, :, k] = corner.reshape(-1, 3)

        each_on_threads(len(self.records), channel, 1 if cp.size > THREADED_CORNERS else None)
        return out


def _put_rings(out, plain, scale, rings, corner_patch, block=RINGING_BLOCK):
    """``out`` (T*3,) = the plain average ``plain`` x its ``scale`` (P,) at the corners of the
    patches ``rings`` (P,) bool: a block of corners at a time (no (T*3,) index)."""
    for start in range(0, len(plain), block):
        at = np.flatnonzero(rings[corner_patch[start:start + block]]) + start
        out[at] = plain[at] * scale[corner_patch[at]]


def corner_values(vertices, triangles, triangle_patch, patch_values, crease_angle=CREASE_ANGLE, iterations=ITERATIONS,
                  slack=None):
    """Smooth per-corner values (T,3,k) of per-patch values (P,k) (``Surface.corner_values``)."""
    surface = Surface.of(vertices, triangles, triangle_patch, len(patch_values), crease_angle)
    return surface.corner_values(patch_values, iterations, slack=slack)


def filter_noise(vertices, triangles, triangle_patch, patch_values, patch_variances, crease_angle=CREASE_ANGLE,
                 cutoff=NOISE_CUTOFF):
    """Noise-filtered per-patch values (P,k) (``Surface.filter_noise``)."""
    surface = Surface.of(vertices, triangles, triangle_patch, len(patch_values), crease_angle)
    return surface.filter_noise(patch_values, patch_variances, cutoff)
