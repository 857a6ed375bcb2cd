"""Geometry arrays derived once from a scene's mesh and shared by every material set on it
(made by :func:`.geometry_build.build_geometry`).

Triangles are sorted by patch; positions are in unit space, (world - centre) / diagonal, in
float32; areas are in the scene's units.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..mesh.frames import LIGHT_OFFSET_SPACINGS, RELATIVE_EDGE_INSET, RELATIVE_HIT_EDGE_CLEARANCE, edge_barycentric
from .patch_grids import patch_grids
from .raytrace import RayTracer, RegionTracer
from .regions import Regions
from .visibility import Buried
from ..mesh.triangles import (
    BLOCK_PATCHES,
    BLOCK_TRIANGLES,
    UnitCorners,
    leaving_frames,
    triangle_cross,
    triangle_normals,
)

# At most this many distinct leaving-frame shapes (edges and normal) are kept as a table of
# their own (Geometry.leave_shapes; 2^12 shapes take 144 kB): more, and the table is no
# smaller than the patches' own rows.
LEAVE_SHAPES_MAX = 1 << 12

# Odd multipliers (of the golden ratio's 64-bit constant) that hash a leaving frame's 9 float32
# bit patterns to one uint64 (Geometry.leave_shapes).
_SHAPE_HASH = np.array([((2 * k + 1) * 0x9E3779B97F4A7C15) % 2**64 for k in range(9)], dtype=np.uint64)


@dataclass(frozen=True)
class Geometry:
    """Geometry arrays derived once and shared by every material set on the same patches.

    Triangles are stored sorted by patch (the ray tracer's primitive ids index this order).
    Positions are in unit space, (world - centre) / diagonal, in float32; areas are in the
    scene's units. The per-triangle float32 arrays (corners, normals, leaving frames) are made
    on first use from ``corners``: walks over parallelograms traced as grids never need them.
    """

    centre: np.ndarray            # (3,) float64
    diagonal: float               # bounding-box diagonal, scene units
    ray_offset: float             # distance a ray origin is pushed along the normal (unit space)
    triangle_index: np.ndarray    # (T,) int32 original index of each sorted triangle
    triangle_patch: np.ndarray    # (T,) int32 patch of each sorted triangle
    corners: UnitCorners          # (T,3,3) float64 unit-space corners of the sorted triangles, on demand
    patch_area: np.ndarray        # (P,) float64
    patch_normal: np.ndarray      # (P,3) float32, a view of leave_table's rows 9-11
    patch_first_triangle: np.ndarray  # (P,) int32 first sorted triangle of each patch
    patch_triangle_count: np.ndarray  # (P,) int32
    # (T,) float64: patch + cumulative area fraction in the patch, where a patch has more than
    # two triangles (sampling.choose_triangles searches it); None where none has
    triangle_key: np.ndarray | None
    patch_first_fraction: np.ndarray  # (P,) float32: area fraction of each patch's first triangle
    patch_parallelogram: np.ndarray   # (P,) bool: the patch is two triangles forming a parallelogram
    # (12,P) float32: each parallelogram patch's corner (pushed off), edge a, edge b (zeros if
    # not), then its normal, one coordinate per row: one gather gives a random exit's origin
    # frame and the normal its direction is built on
    leave_table: np.ndarray
    # (P,) float64 each patch's ray offset and edge inset (frames.local_offsets), where a patch
    # small beside the scene takes less than ``ray_offset`` and RELATIVE_EDGE_INSET; None where
    # every patch takes those (ordinary scenes: then ``ray_offset`` is every patch's)
    patch_ray_offset: np.ndarray | None = None
    patch_edge_inset: np.ndarray | None = None
    # Parts of the scene far apart, each with positions in a frame of its own (.regions): then
    # every position above is in its patch's region frame; None where the scene is one frame
    regions: Regions | None = None
    # Patches partly inside other objects, and the visible cells their points are drawn from
    # (.visibility); ``patch_area`` is then each patch's visible area. None where none is.
    buried: Buried | None = None

    @property
    def patch_count(self):
        return self.patch_area.shape[0]

    @property
    def triangle_count(self):
        return self.triangle_patch.shape[0]

    @cached_property
    def max_triangles_per_patch(self):
        return int(self.patch_triangle_count.max())

    def _per_triangle(self, make, axis=0):
        """``make(corners)`` of every sorted triangle, block by block, into one array whose
        ``axis`` runs over the triangles."""
        T = self.triangle_count
        first = make(self.corners[0:BLOCK_TRIANGLES])
        shape = list(first.shape)
        shape[axis] = T
        out = np.empty(shape, first.dtype)
        for start in range(0, T, BLOCK_TRIANGLES):
            block = first if start == 0 else make(self.corners[start:start + BLOCK_TRIANGLES])
            out[(slice(None),) * axis + (slice(start, start + BLOCK_TRIANGLES),)] = block
        return out

    @cached_property
    def triangle_corners(self):
        """(T,3,3) float32 unit-space corners, the ray tracer's input."""
        return self._per_triangle(lambda c: c.astype(np.float32))

    @property
    def float32_corners(self):
        """``float32_corners[rows]``: rows of :attr:`triangle_corners`, without making it whole."""
        return self.__dict__.get("triangle_corners", self.corners.float32())

    @cached_property
    def triangle_normal(self):
        """(T,3) float32 unit normals."""
        return self._per_triangle(lambda c: triangle_normals(c).astype(np.float32))

    @cached_property
    def triangle_area(self):
        """(T,) float64 areas, scene units."""
        return self._per_triangle(lambda c: 0.5 * np.linalg.norm(triangle_cross(c), axis=1)) * self.diagonal**2

    @cached_property
    def triangle_frame(self):
        """(9,T) float32: origin (pushed off), edge1, edge2 of each triangle's leaving frame, one
        row per coordinate (:meth:`frames_of`)."""
        if self.patch_ray_offset is None:
            return self._per_triangle(lambda c: leaving_frames(c, self.ray_offset), axis=1)
        out = np.empty((9, self.triangle_count), np.float32)
        for start in range(0, self.triangle_count, BLOCK_TRIANGLES):
            rows = np.arange(start, min(start + BLOCK_TRIANGLES, self.triangle_count))
            out[:, rows] = self.frames_of(rows)
        return out

    def frames_of(self, rows):
        """Columns ``rows`` of :attr:`triangle_frame`, without making it whole."""
        if self.patch_ray_offset is None:
            return leaving_frames(self.corners[rows], self.ray_offset)
        patch = self.triangle_patch[rows]
        return leaving_frames(self.corners[rows], self.patch_ray_offset[patch][:, None], self.patch_edge_inset[patch])

    def ray_offsets(self, patch, dtype=np.float32):
        """The ray offset of each of the given patches: ``ray_offset`` where every patch takes
        it (a Python number, which numpy rounds to the array's dtype), else (n,) ``dtype``."""
        if self.patch_ray_offset is None:
            return self.ray_offset
        table = self.patch_ray_offset if dtype == np.float64 else self.patch_offset32
        return table.take(patch, mode="wrap")

    @cached_property
    def patch_offset32(self):
        return self.patch_ray_offset.astype(np.float32)

    def light_offsets(self, unit_origins):
        """How far a light's rays from ``unit_origins`` (3,n) start along their direction: the
        scene's ray offset, or where patches take less (small beside the scene), a few float32
        spacings of each origin's coordinates, which is all its rounding needs (a number, or
        (n,))."""
        if self.patch_ray_offset is None:
            return self.ray_offset
        largest = np.abs(unit_origins).max(axis=0).astype(np.float32)
        return LIGHT_OFFSET_SPACINGS * np.spacing(largest).astype(np.float64)

    def to_world(self, points, patch=None):
        """Unit-space points (n,3) back in the scene's coordinates, float64 (points of the
        given ``patch`` (n,) each, in its region's frame, where the scene has regions)."""
        points = np.asarray(points, dtype=np.float64)
        if self.regions is not None:
            points = points + self.regions.centre[self.regions.of(patch)]
        return points * self.diagonal + self.centre

    def region_of(self, patch):
        """(n,) int32 the region frame of each of the given patches' positions, or None where
        the scene is one frame."""
        return None if self.regions is None else self.regions.of(patch)

    @property
    def parallelogram_frame(self):
        """(9,P) float32: the parallelogram patches' corner (pushed off), edge a, edge b (zeros if
        not), one coordinate per row (rows of :attr:`leave_table`)."""
        return self.leave_table[0:9]

    @property
    def patch_normal_rows(self):
        """(3,P) float32: the patch normals one coordinate per row, for column gathers (rows of
        :attr:`leave_table`)."""
        return self.leave_table[9:12]

    @cached_property
    def leave_shapes(self):
        """The distinct shapes of the patches' leaving frames (:func:`leave_shapes`)."""
        return leave_shapes(self.leave_table)

    @cached_property
    def exit_table(self):
        """(12,T+P) float32: the leaving frames of triangles and patches. Columns 0..T-1 are the
        triangles' leaving frames (corner, edge1, edge2) with their patch's normal (random
        points of patches that are not parallelograms; a hit-point exit's hits near an edge),
        columns T..T+P-1 the rows of :attr:`leave_table` (parallelogram patches)."""
        triangle_columns = np.vstack([self.triangle_frame, self.patch_normal_rows[:, self.triangle_patch]])
        return np.ascontiguousarray(np.hstack([triangle_columns, self.leave_table]))

    @cached_property
    def edge_barycentric(self):
        """(T,) float32: the barycentric coordinate below which a point of each triangle may lie
        closer than RELATIVE_HIT_EDGE_CLEARANCE to one of its edges (the clearance over the
        triangle's smallest altitude, 2 area / longest edge; 1 for triangles too small to
        have such points). Where patches have leaving-frame shapes (:attr:`leave_shapes`), every
        triangle of a shape's patches takes the largest of their thresholds
        (:attr:`shape_edge_barycentric`), which a walk reads per patch class: a larger
        threshold only sends a few more hit points through the exact remap onto the frame."""
        if self.shape_edge_barycentric is not None:
            _, shape_of_patch = self.leave_shapes
            return self.shape_edge_barycentric[shape_of_patch[self.triangle_patch]]
        return self._own_edge_barycentric()

    @cached_property
    def shape_edge_barycentric(self):
        """(K,) float32: the largest :attr:`edge_barycentric` of the triangles of each shape of
        :attr:`leave_shapes`, or None where the patches are not all parallelograms or have no
        shape table."""
        if not self.all_parallelograms or self.leave_shapes is None:
            return None
        _, shape_of_patch = self.leave_shapes
        largest = np.zeros(shape_of_patch.max() + 1, dtype=np.float32)
        np.maximum.at(largest, shape_of_patch[self.triangle_patch], self._own_edge_barycentric())
        return largest

    def _own_edge_barycentric(self):
        if self.patch_edge_inset is None:
            return edge_barycentric(self.triangle_corners)
        clearance = RELATIVE_HIT_EDGE_CLEARANCE / RELATIVE_EDGE_INSET * self.patch_edge_inset[self.triangle_patch]
        return edge_barycentric(self.triangle_corners, clearance)

    @cached_property
    def triangle_normal_rows(self):
        """(3,T) float32: the triangle normals one coordinate per row, for column gathers."""
        return np.ascontiguousarray(self.triangle_normal.T)

    @cached_property
    def all_parallelograms(self):
        return bool(self.patch_parallelogram.all())

    @cached_property
    def any_parallelograms(self):
        return bool(self.patch_parallelogram.any())

    @cached_property
    def patch_grids(self):
        """The parallelogram patches merged into the grids they tile, with the other patches'
        own triangles (:mod:`.patch_grids`), which walks trace instead of the triangles; None
        where that would save too few triangles."""
        return patch_grids(self)

    @cached_property
    def tracer(self):
        """The Embree scene over these triangles, built on first use and then reused (one a
        region, where the scene has regions)."""
        if self.regions is not None:
            return RegionTracer(self.triangle_corners, self.regions.of(self.triangle_patch), self.regions)
        return RayTracer(self.triangle_corners)

    @property
    def surface_tracer(self):
        """An Embree scene of the patches' surfaces for checks that ask only whether a ray meets
        one and which side (its hit ids are not triangles of this geometry): the grids' where
        there are grids (what the walks trace), else :attr:`tracer`. The grids' is a few
        triangles where :attr:`tracer` holds every triangle's, which a walk may never build."""
        return self.tracer if self.patch_grids is None else self.patch_grids.tracer



def leave_shapes(leave_table, max_shapes=LEAVE_SHAPES_MAX, shape_hash=_SHAPE_HASH):
    """The distinct shapes of parallelogram patches' leaving frames ((12,P) ``leave_table``):
    ((9,K) float32 rows edge a, edge b, normal, one column per distinct shape; (P,) uint16 the
    shape of each patch), bit for bit equal, or None where there are more than ``max_shapes``.
    A patch's frame is its corner and its shape: patches meshed from one face share one (a wall
    of a room, a box's side). Compared as bits: a shared shape is the same float32 numbers, and
    -0.0 stays apart from 0.0."""
    P = leave_table.shape[1]

    def bits(rows):  # (n,9) uint32: the frames' bit patterns of patches ``rows`` (a slice)
        return np.ascontiguousarray(leave_table[3:12, rows].T).view(np.uint32)

    # A hash of each row first (a sort of P numbers, not of P rows), a block of patches at a
    # time (uint64 arithmetic wraps: the same hashes); rows of equal hashes are then checked to
    # be equal, and where two shapes share a hash the rows themselves are sorted.
    hashed = np.empty(P, np.uint64)
    for start in range(0, P, BLOCK_PATCHES):
        rows = slice(start, start + BLOCK_PATCHES)
        hashed[rows] = bits(rows).astype(np.uint64) @ shape_hash
    if np.unique(hashed).size > max_shapes:  # (shared hashes only lower the count)
        return None
    _, first, shape_of_patch = np.unique(hashed, return_index=True, return_inverse=True)
    del hashed
    shape_of_patch = shape_of_patch.reshape(-1)
    shapes = np.ascontiguousarray(leave_table[3:12, first].T).view(np.uint32)
    same = all(
        np.array_equal(shapes[shape_of_patch[start:start + BLOCK_PATCHES]], bits(slice(start, start + BLOCK_PATCHES)))
        for start in range(0, P, BLOCK_PATCHES)
    )
    if not same:
        shapes, shape_of_patch = np.unique(bits(slice(None)), axis=0, return_inverse=True)
        if shapes.shape[0] > max_shapes:
            return None
    return np.ascontiguousarray(shapes.view(np.float32).T), shape_of_patch.reshape(-1).astype(np.uint16)
