"""Regions: parts of a scene far apart, each with positions of its own origin.

Unit space, (world - centre) / diagonal, keeps a whole scene in float32's range, but float32
places a point only to about 6e-8 of its distance from the origin: a 1 m room beside an object
100 km away sits 0.5 from the unit-space origin, where positions are 6 mm apart. Split at the
empty gaps between them into regions, each part keeps its positions relative to its own centre
(a *region frame*), where float32 is as fine as the part is small: the ray tracer holds one
Embree scene per region and carries a ray into another region's frame in float64
(:class:`.raytrace.RegionTracer`). Regions exist only where float32's spacing of the scene's
coordinates would set some patch's offsets (frames.set_by_rounding): a frame elsewhere changes no
offset, and each region costs every ray that may reach it a box test and a trace (a room with a
finely divided vase, its patches a thousandth of the room's size: benchmarks/results/flat_speed.md);
an ordinary scene is one frame, as before.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A part is split off into regions while it is more than this many times its smallest patch's
# side across: beyond about 1e4, float32 spacings of its own coordinates would set its patches'
# ray offsets (frames.local_offsets); splitting earlier keeps the offsets the patches' own size.
SPLIT_RATIO = 1e3
# At most this many regions: each is one more Embree scene a ray may have to be traced in.
MAX_REGIONS = 64
# A region's box is padded by this share of its diagonal, beyond float32 rounding of its corners.
BOX_PAD = 1e-5


@dataclass(frozen=True)
class Regions:
    """The regions of a scene's patches, in unit space (float64): region k's positions are
    stored as unit-space position - ``centre[k]``."""

    centre: np.ndarray        # (K,3) each region's bounding-box centre
    lower: np.ndarray         # (K,3) each region's bounding box
    upper: np.ndarray
    patch_region: np.ndarray  # (P,) int32 the region of each patch

    @property
    def count(self):
        return self.centre.shape[0]

    def of(self, patch):
        """(n,) int32 the region of each of the given patches."""
        return self.patch_region.take(patch, mode="wrap")

    def largest_coordinate(self):
        """(K,) the largest coordinate of a position in each region's own frame."""
        return np.maximum(np.abs(self.lower - self.centre), np.abs(self.upper - self.centre)).max(axis=1)

    def nearest(self, points):
        """(n,) the region whose bounding box is nearest each unit-space point (3,n)."""
        points = np.asarray(points, np.float64).T[:, None, :]
        outside = np.maximum(self.lower - points, 0.0) + np.maximum(points - self.upper, 0.0)  # (n,K,3)
        return np.argmin(np.einsum("nki,nki->nk", outside, outside), axis=1).astype(np.int32)

    def shift(self, region):
        """(3,n) the unit-space centre of each region: what takes its frame to unit space."""
        return self.centre.take(region, axis=0).T

    def entry(self, region, origins, directions):
        """(n,) how far along each unit-space ray (origins (n,3) float64, directions (n,3)) it
        enters region ``region``'s bounding box (0 inside it, inf where it misses it)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            inverse = 1.0 / directions
            a = (self.lower[region] - origins) * inverse
            b = (self.upper[region] - origins) * inverse
        # A direction 0 along an axis: inside the slab (a, b = -inf, +inf or NaN) or never in it.
        near = np.where(np.isnan(a), -np.inf, np.minimum(a, b)).max(axis=1)
        far = np.where(np.isnan(b), np.inf, np.maximum(a, b)).min(axis=1)
        return np.where((near <= far) & (far >= 0), np.maximum(near, 0.0), np.inf)


def split_regions(lower, upper, side, ratio=SPLIT_RATIO, max_regions=MAX_REGIONS):
    """The :class:`Regions` of patches with unit-space bounding boxes ``lower``, ``upper`` (P,3)
    and sides ``side`` (P,): a part is cut at its widest empty gap (along any axis, between the
    patches' boxes), or where it has none its patches more than 1 / ``ratio`` of its size go
    apart from the others, while it is more than ``ratio`` times its smallest side across, up
    to ``max_regions`` parts; None where that leaves one region."""
    done, todo = [], [np.arange(lower.shape[0])]
    while todo:
        part = todo.pop()
        size = np.linalg.norm(upper[part].max(axis=0) - lower[part].min(axis=0))
        below = None
        if size > ratio * side[part].min() and len(done) + len(todo) + 2 <= max_regions:
            cut = widest_gap(lower[part], upper[part])
            if cut is not None:
                below = lower[part, cut[0]] < cut[1]
            else:
                # No gap (a house on a terrain): the patches large enough for a frame of the
                # whole part's size go apart from the small ones (their boxes may overlap).
                below = side[part] > size / ratio
                if below.all() or not below.any():
                    below = None
        if below is None:
            done.append(part)
            continue
        todo += [part[below], part[~below]]
    if len(done) == 1:
        return None
    patch_region = np.empty(lower.shape[0], np.int32)
    for k, part in enumerate(done):
        patch_region[part] = k
    low = np.array([lower[part].min(axis=0) for part in done])
    high = np.array([upper[part].max(axis=0) for part in done])
    pad = BOX_PAD * np.linalg.norm(high - low, axis=1)[:, None]  # (float32 rounding of the corners)
    low, high = low - pad, high + pad
    return Regions(centre=0.5 * (low + high), lower=low, upper=high, patch_region=patch_region)


def widest_gap(lower, upper):
    """(axis, position) of the widest empty gap between boxes (n,3) along any axis (its middle),
    or None where the boxes overlap along every axis."""
    best = None
    for axis in range(3):
        order = np.argsort(lower[:, axis], kind="stable")
        reach = np.maximum.accumulate(upper[order, axis])  # the farthest any box before reaches
        gaps = lower[order[1:], axis] - reach[:-1]
        if gaps.size == 0:
            continue
        k = int(np.argmax(gaps))
        if gaps[k] > 0 and (best is None or gaps[k] > best[0]):
            best = (gaps[k], axis, 0.5 * (lower[order[k + 1], axis] + reach[k]))
    return None if best is None else best[1:]
