"""Buried parts of patches: where a patch runs into another object, the part inside it.

Artists model with overlapping boxes: a wall box runs into the ceiling box, and the ceiling's
edge patches lie partly inside the wall. Those parts can neither receive light (every ray from
the room meets the wall first) nor send it (rays from inside the wall meet its back faces).
A patch's radiosity is then its light over its *visible* area, and the points it emits,
reflects or gathers from must be drawn from its visible part only.

Each patch's square of point uniforms (u0, u1; and, for patches that are not parallelograms,
the triangle uniform) is cut into cells, a cell being visible or buried as its centre is.
A point is buried when, along three of four probe rays from it (its normal, and three directions
85 degrees off it, 120 degrees apart), it lies inside more closed surfaces than it enters: the
surfaces met from behind minus those met in front, all the way out (:func:`windings`). A point
inside a closed solid counts 1 or more along every probe but one that leaves through two
coincident faces (flush boxes), of which only one is met; a point on an open surface, in a room
of inward faces, beside a thin wall or under a one-sided table top counts 0 along the
near-grazing probes, which leave under the top. The first face met is not enough: inside two
overlapping boxes, the other box's faces are met from the front. The points of a patch are then
drawn uniformly over its visible cells (:meth:`Buried.remap`, which maps uniforms onto
uniforms), its area becomes the visible cells' share of it, and every method, reading areas and
drawing points through the same two functions, solves the scene of the visible surfaces: the
paper's estimators and formulas hold for it unchanged, with A_i the visible area.

Only patches that some other surface crosses can be partly buried, and such a crossing meets one
of the patch's diagonals away from its sides (any line across a parallelogram separates the ends
of one of them) or, for other patches, an edge of one of its triangles: in-plane rays just
above the patches (one per diagonal line of each grid of patches, :mod:`.patch_grids`) pick the
patches worth probing, and surfaces that only touch a patch along its sides are not crossings.
A patch buried whole (every cell; the sample scenes' floor under a box
with no bottom) keeps its area: it has no visible part to give its light to, receives nothing,
and stays as it was, except that the two-way iteration sends no rays from it (``Buried.whole``:
found, where some patch is partly buried, by probing every other patch's centre).
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .coincident import contacts_of
from .crossings import crossed_patches
from .rays import meets_front
from .threads import each_on_threads, local_thread_count
from ..lights.sampling import FLOAT32_BELOW_ONE, patch_point_rows

# Cells per side of a patch's (u0, u1) square, and bins of the triangle uniform for patches that
# are not parallelograms: a buried part's border is placed to within half a cell.
CELLS = 16
TRIANGLE_BINS = 4
# Probe directions (angle from the normal, azimuth), in degrees: the normal first (most points
# see the room straight ahead), the near-grazing ones last, which escape under a one-sided plane.
PROBES = ((0.0, 0.0),) + tuple((85.0, 23.0 + 120.0 * k) for k in range(3))
# A point is buried when this many probes find it inside: one probe may cross two coincident faces
# (flush boxes: a wall's bottom on the floor slab's) where only one of them is counted.
VOTES = len(PROBES) - 1
# Surfaces a probe is traced through at most.
MAX_CROSSINGS = 64
# Points probed a block at a time, the blocks shared among the local threads (``threads.each_on_threads``):
# a point's answer is its own rays', so the bits are the same on any number of threads.
PROBE_BLOCK = 1 << 13


@dataclass(frozen=True)
class Buried:
    """The patches partly buried, and which cells of each are visible.

    slot: (P,) int32, each patch's row here, -1 for patches wholly visible (or wholly buried)
    patch: (B,) int32 the partly buried patches, ascending
    bins: (B,) int32 triangle-uniform bins of each (1 for parallelograms)
    first: (B+1,) int64 where each patch's visible cells start in ``cells``
    cells: int32 visible cells of each patch, ascending: bin K^2 + i K + j for u0 in cell i, u1 in j
    fraction: (B,) float64 visible share f_j of each
    whole: (W,) int32 the patches buried whole (every cell, or the centre of a patch nothing
    crosses): they keep their area, and the two-way iteration sends no rays from them
    """

    slot: np.ndarray
    patch: np.ndarray
    bins: np.ndarray
    first: np.ndarray
    cells: np.ndarray
    fraction: np.ndarray
    whole: np.ndarray

    def visible_fraction(self, patch_count):
        """(P,) f_j: 1 for every patch but the partly buried ones."""
        f = np.ones(patch_count)
        f[self.patch] = self.fraction
        return f

    def remap(self, patch, u_triangle, u0, u1):
        """Moves the point uniforms of paths on partly buried patches onto those patches' visible
        cells, in place: u0 picks a visible cell (its fraction, still uniform, places the point
        along the cell), u1 and the triangle uniform are scaled into it. Uniform in, uniform
        over the visible cells out."""
        slot = self.slot.take(patch, mode="wrap")
        rows = np.flatnonzero(slot >= 0)
        if rows.size == 0:
            return
        b = slot.take(rows)
        count = self.first.take(b + 1) - self.first.take(b)
        x = u0.take(rows).astype(np.float64) * count
        k = np.minimum(np.floor(x), count - 1)
        r = x - k
        cell = self.cells.take(self.first.take(b) + k.astype(np.int64))
        per_bin = CELLS * CELLS
        t, rest = np.divmod(cell, per_bin)
        i, j = np.divmod(rest, CELLS)
        a, c = (i + r) / CELLS, (j + u1.take(rows)) / CELLS
        if u_triangle is not None:
            bins = self.bins.take(b)
            # A triangle's square folds along a + c = 1, which would send the upper half of a cell
            # across it onto its mirror cell's lower half: reflected within the cell instead.
            over = np.flatnonzero((bins > 1) & (i + j == CELLS - 1) & (a + c > 1))
            a[over], c[over] = 1 - c[over], 1 - a[over]
        u0[rows] = np.minimum(a.astype(np.float32), FLOAT32_BELOW_ONE)
        u1[rows] = np.minimum(c.astype(np.float32), FLOAT32_BELOW_ONE)
        if u_triangle is not None:
            u_triangle[rows] = np.minimum(((t + u_triangle.take(rows)) / bins).astype(u_triangle.dtype),
                                          np.nextafter(u_triangle.dtype.type(1), u_triangle.dtype.type(0)))


def with_visible_parts(geometry):
    """``geometry`` itself where no patch is partly buried; else a copy whose ``patch_area`` is
    each patch's visible area and whose ``buried`` says which cells are visible."""
    buried = find_buried(geometry)
    if buried is None:
        return geometry
    area = geometry.patch_area * buried.visible_fraction(geometry.patch_count)
    visible = dataclasses.replace(geometry, patch_area=area, buried=buried)
    for name, value in geometry.__dict__.items():  # (cached tracers and tables: the same geometry)
        if name not in visible.__dict__:
            visible.__dict__[name] = value
    return visible


def find_buried(geometry):
    """The :class:`Buried` patches of ``geometry``, or None where none is partly buried."""
    crossed = crossed_patches(geometry)
    if crossed.size == 0:
        return None
    bins = np.where(geometry.patch_parallelogram[crossed], 1, TRIANGLE_BINS).astype(np.int32)
    buried_cell, per_patch, cell = cell_states(geometry, crossed, bins)
    visible_count = np.bincount(np.repeat(np.arange(crossed.size), per_patch), weights=~buried_cell,
                                minlength=crossed.size).astype(np.int64)
    partly = (visible_count > 0) & (visible_count < per_patch)
    if not partly.any():
        return None
    keep = np.repeat(partly, per_patch) & ~buried_cell
    # Where some patch is partly buried, others may lie inside an object whole (nothing crosses
    # them): their centres, probed.
    rest = np.setdiff1d(np.arange(geometry.patch_count), crossed)
    half = np.full(rest.size, 0.5)
    whole = np.concatenate([crossed[visible_count == 0], rest[buried_points(geometry, rest, half, half, half)]])
    slot = np.full(geometry.patch_count, -1, np.int32)
    slot[crossed[partly]] = np.arange(int(partly.sum()), dtype=np.int32)
    counts = visible_count[partly]
    return Buried(slot=slot, patch=crossed[partly].astype(np.int32), bins=bins[partly],
                  first=np.concatenate(([0], np.cumsum(counts))).astype(np.int64), cells=cell[keep].astype(np.int32),
                  fraction=counts / per_patch[partly], whole=np.sort(whole).astype(np.int32))


def cell_states(geometry, patch, bins):
    """Which cells of each of the given patches are buried, coarse to fine: the centres of a
    grid half as fine first (CELLS / 2 per side); a patch whose coarse cells all agree is taken
    whole, and in the others only coarse cells beside one of the other kind (every coarse cell
    of a patch that is not a parallelogram) are split and their four cells probed, the rest
    passing their state on. Returns ((n,) bool buried, (m,) cells per patch, (n,) each one's
    cell: bin K^2 + i K + j), cells patch by patch."""
    K, K1 = CELLS, CELLS // 2
    m = patch.size
    per1 = bins * K1 * K1
    owner1 = np.repeat(np.arange(m), per1)
    cell1 = _ranks(per1)
    state1 = buried_points(geometry, patch[owner1], *cell_uniforms(cell1, bins[owner1], K1))
    count1 = np.bincount(owner1, weights=state1, minlength=m)
    mixed = (count1 > 0) & (count1 < per1)
    rest1 = cell1 % (K1 * K1)
    I, J = rest1 // K1, rest1 % K1
    beside = np.zeros(cell1.size, bool)
    for di, dj in ((-1, 0), (1, 0), (0, -1), (0, 1)):
        inside = (I + di >= 0) & (I + di < K1) & (J + dj >= 0) & (J + dj < K1)
        index = np.flatnonzero(inside)
        beside[index] |= state1[index] != state1[index + di * K1 + dj]
    split1 = mixed[owner1] & (beside | (bins[owner1] > 1))
    per = bins * K * K
    owner = np.repeat(np.arange(m), per)
    cell = _ranks(per)
    t, rest = np.divmod(cell, K * K)
    i, j = np.divmod(rest, K)
    coarse = (np.cumsum(per1) - per1)[owner] + t * K1 * K1 + (i // 2) * K1 + j // 2
    state = state1[coarse]
    rows = np.flatnonzero(split1[coarse])
    if rows.size:
        state[rows] = buried_points(geometry, patch[owner[rows]], *cell_uniforms(cell[rows], bins[owner[rows]], K))
    return state, per, cell


def _ranks(counts):
    """0..c-1 for each count c, concatenated."""
    start = np.repeat(np.cumsum(counts) - counts, counts)
    return np.arange(int(counts.sum()), dtype=np.int64) - start


def cell_uniforms(cell, bins, cells=CELLS):
    """The uniforms (triangle, u0, u1) of each cell's representative point: its centre, or on the
    fold of a triangle's square (cells across u0 + u1 = 1 fold onto their own lower half) that
    half's centroid. float64 (n,) each."""
    t, rest = np.divmod(cell, cells * cells)
    i, j = np.divmod(rest, cells)
    across = (bins > 1) & (i + j == cells - 1)
    at = np.where(across, 1.0 / 3.0, 0.5)
    return (t + 0.5) / bins, (i + at) / cells, (j + at) / cells


def buried_points(geometry, patch, u_triangle, u0, u1):
    """(n,) bool: whether each point of ``patch`` at the given uniforms is buried (``buried_at``)."""
    origins = patch_point_rows(geometry, patch, u_triangle.astype(np.float64), u0.astype(np.float32), u1.astype(np.float32))
    return buried_at(geometry, origins, patch)


def buried_at(g, origins, patch, side=1.0):
    """(n,) bool: whether each point (3,n) unit space, pushed off) of ``patch`` is buried: along
    VOTES of the probes it is inside more solids than it enters (:func:`windings` >= 1). Probes
    are cast only for points still undecided; ``side`` -1: about -n, for points behind it.
    PROBE_BLOCK points at a time, on the local threads."""
    blocks = [slice(start, start + PROBE_BLOCK) for start in range(0, patch.size, PROBE_BLOCK)]
    if len(blocks) < 2 or local_thread_count() == 1:
        return _buried_block(g, origins, patch, side)
    g.surface_tracer, contacts_of(g)  # (made once, here, before the threads read them)
    out = np.zeros(patch.size, bool)

    def block(k):
        out[blocks[k]] = _buried_block(g, origins[:, blocks[k]], patch[blocks[k]], side)

    each_on_threads(len(blocks), block)
    return out


def _buried_block(g, origins, patch, side):
    """``buried_at`` of a block of points, on the calling thread."""
    normal = g.patch_normal_rows.take(patch, axis=1).astype(np.float64) * side
    tangent, bitangent = tangents(normal)
    inside, outside = np.zeros(patch.size, np.int32), np.zeros(patch.size, np.int32)
    undecided = np.arange(patch.size)
    for theta, phi in PROBES:
        if undecided.size == 0:
            break
        s, c = np.sin(np.radians(theta)), np.cos(np.radians(theta))
        rows = (slice(None), undecided)
        d = c * normal[rows] + s * (np.cos(np.radians(phi)) * tangent[rows] + np.sin(np.radians(phi)) * bitangent[rows])
        says = windings(g, origins[rows].astype(np.float64), d, patch.take(undecided)) >= 1
        inside[undecided[says]] += 1
        outside[undecided[~says]] += 1
        undecided = undecided[(inside[undecided] < VOTES) & (outside[undecided] <= len(PROBES) - VOTES)]
    return inside >= VOTES


def windings(g, origins, directions, patch):
    """(n,) int: for rays (3,n) float64 from points of ``patch``, the surfaces met from behind
    minus those met in front, all the way out: the number of closed solids (outward normals) a
    point is inside; 0 or less on open surfaces, in rooms of inward faces, under one-sided
    planes. Each ray is traced on from just past every hit, at most MAX_CROSSINGS times."""
    n = origins.shape[1]
    count = np.zeros(n, np.int64)
    live = np.arange(n)
    o = np.ascontiguousarray(origins.T)  # (n,3) float64, the live rays' only
    d = np.ascontiguousarray((directions / np.linalg.norm(directions, axis=0)).T)
    d32 = d.astype(np.float32)
    region = g.region_of(patch)
    tracer = g.surface_tracer
    contacts = contacts_of(g)
    step = g.ray_offset
    for _ in range(MAX_CROSSINGS):
        if live.size == 0:
            break
        hit, _, _, t, normal = tracer.first_hit_barycentric(o.astype(np.float32), d32,
                                                            None if region is None else region.take(live))
        met = np.flatnonzero(hit >= 0)
        front = meets_front(d32.T, normal)
        sign = 1 - 2 * front.take(met).astype(np.int64)
        if contacts.any:  # (flush boxes: coincident faces, met as one, each counted: core coincident)
            sign *= contacts.faces_at(hit.take(met), o.take(met, axis=0) + d.take(met, axis=0) * t.take(met)[:, None])
        count[live[met]] += sign
        live, o, d, d32 = live.take(met), o.take(met, axis=0), d.take(met, axis=0), d32.take(met, axis=0)
        o += d * (t.take(met) + step)[:, None]
    return count


def tangents(normal):
    """Two unit tangents (3,n) of each normal (3,n) float64."""
    axis = np.zeros_like(normal)
    axis[np.argmin(np.abs(normal), axis=0), np.arange(normal.shape[1])] = 1.0
    t = np.cross(normal.T, axis.T).T
    t /= np.linalg.norm(t, axis=0)
    return t, np.cross(normal.T, t.T).T
