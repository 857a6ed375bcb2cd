"""Triangles in unit space, block by block: their corners on demand, crosses, normals and leaving frames.

Unit space is (world - centre) / diagonal of the scene's bounding box (or a region's frame of it,
:mod:`.regions`). Arrays over every triangle are made a block of whole patches at a time, so that
the float64 temporaries are a block's, not the scene's.
"""
from __future__ import annotations

import numpy as np

from .frames import RELATIVE_EDGE_INSET, inset_triangles

# Per-patch arrays are computed in blocks of this many patches (every value patch by patch).
BLOCK_PATCHES = 1 << 16

# Per-triangle arrays are computed in blocks of about this many triangles (whole patches), so
# that the float64 temporaries are a block's, not the scene's: every value is computed
# triangle by triangle (and every per-patch sum within one block), so the bits are the same.
BLOCK_TRIANGLES = 1 << 16


class UnitCorners:
    """The (T,3,3) float64 unit-space corners (world - centre) / diagonal of the triangles
    ``triangles[rows]`` (all of them without ``rows``), computed on demand for the rows asked
    for: the same numbers as indexing the whole array, without holding it (rounded to
    ``dtype`` where given)."""

    def __init__(self, vertices, triangles, centre, diagonal, rows=None, dtype=None, frames=None):
        self.vertices, self.triangles, self.rows = vertices, triangles, rows
        self.centre, self.diagonal, self.dtype = centre, diagonal, dtype
        # (region centres (K,3), region of each of ``triangles`` (T,)): corners in their
        # regions' frames (.regions), or None
        self.frames = frames

    def float32(self):
        """These corners rounded to float32 (the rows of Geometry.triangle_corners)."""
        return UnitCorners(self.vertices, self.triangles, self.centre, self.diagonal, self.rows, np.float32, self.frames)

    def __len__(self):
        return len(self.triangles if self.rows is None else self.rows)

    def __getitem__(self, index):
        index = index if self.rows is None else self.rows[index]
        triangles = self.triangles[index]
        corners = (self.vertices[triangles] - self.centre) / self.diagonal
        if self.frames is not None:
            region_centre, region = self.frames
            corners -= region_centre[region[index]][..., None, :]
        return corners if self.dtype is None else corners.astype(self.dtype)


def triangle_blocks(count, size=None):
    """(start, stop) ranges of about ``size`` (BLOCK_TRIANGLES) of the triangles sorted by patch,
    cut only between patches (``count``: (P,) triangles of each patch)."""
    size = size or BLOCK_TRIANGLES
    end = np.cumsum(count)
    total = int(end[-1]) if end.size else 0
    cuts = end[np.maximum(np.searchsorted(end, np.arange(size, total, size), side="right") - 1, 0)]
    cuts = np.unique(np.concatenate([[0], cuts, [total]]))
    return list(zip(cuts[:-1].tolist(), cuts[1:].tolist()))


def triangle_cross(corners):
    """(n,3) float64 (corner1 - corner0) x (corner2 - corner0) of (n,3,3) corners."""
    return np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])


def triangle_normals(corners):
    """(n,3) float64 unit normals of (n,3,3) corners."""
    cross = triangle_cross(corners)
    return cross / np.linalg.norm(cross, axis=1)[:, None]


def leaving_frames(corners, ray_offset, inset=RELATIVE_EDGE_INSET):
    """(9,n) float32 leaving frames of (n,3,3) corners: the inset triangle's first corner pushed
    off along the normal, and its two edges from it (``ray_offset`` a number or (n,1),
    ``inset`` a number or (n,))."""
    leave_corners = inset_triangles(corners, inset)
    return np.ascontiguousarray(
        np.hstack(
            [
                leave_corners[:, 0] + ray_offset * triangle_normals(corners),
                leave_corners[:, 1] - leave_corners[:, 0],
                leave_corners[:, 2] - leave_corners[:, 0],
            ]
        ).T,
        dtype=np.float32,
    )
