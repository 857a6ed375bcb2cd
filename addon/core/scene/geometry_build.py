"""build_geometry: the Geometry of a mesh, checked, in stages.

Degenerate triangles dropped (with a warning), patch areas and normals (patches of no area,
folded or crooked are a PatchError naming them), each triangle's share of its patch's area, the
rays' offsets (each patch's own where it is small beside the scene, with regions of their own
where parts lie far apart: :mod:`.regions`), and the patches' leaving frames.
"""
from __future__ import annotations

import warnings

import numpy as np

from ..mesh.frames import RELATIVE_EDGE_INSET, RELATIVE_RAY_OFFSET, local_offsets, parallelogram_frames, set_by_rounding
from .geometry import Geometry
from .regions import split_regions
from ..mesh.triangles import BLOCK_TRIANGLES, UnitCorners, triangle_blocks, triangle_cross, triangle_normals
from .visibility import with_visible_parts
from ..mesh.validation import (
    MIN_PATCH_NORMAL_COSINE,
    RELATIVE_DEGENERATE_AREA,
    PatchError,
    indices_of,
    indices_text,
    validate_mesh,
    warn_coincident,
)

# Patches whose ray offset, set by the float32 spacing of the scene's coordinates, exceeds this
# share of their side are reported: their form factors drift with it.
COARSE_OFFSET_SHARE = 0.02


def warn_coarse(offset, side, diagonal):
    """Warns (naming how many patches and how far) where float32 positions of a scene this large
    are coarse beside some patches: their rays leave more than COARSE_OFFSET_SHARE of their
    side off them (unit-space ``offset`` and ``side``, (P,) each)."""
    coarse = offset > COARSE_OFFSET_SHARE * side
    if coarse.any():
        share = float((offset / side)[coarse].max())
        warnings.warn(
            f"{int(coarse.sum())} patches are small beside the scene's extent ({diagonal:.3g} across): float32 "
            f"positions put their rays up to {float(offset[coarse].max()) * diagonal:.3g} off them ({share:.1%} of "
            "their size), which shifts their light; keep far objects out of the scene or solve them apart",
            stacklevel=4,
        )


def build_geometry(vertices, triangles, triangle_patch, patch_count, visible_parts=True):
    """The :class:`Geometry` of a mesh whose triangles make ``patch_count`` patches (checked: ValueError naming
    what is wrong); ``visible_parts``: patches partly inside other objects keep their visible part (.visibility)."""
    V, T, tp, centre, diagonal = validate_mesh(vertices, triangles, triangle_patch, patch_count)
    area, keep = _kept_triangles(UnitCorners(V, T, centre, diagonal))
    kept_patch = tp[keep]
    warn_coincident(UnitCorners(V, T, centre, diagonal, keep), kept_patch)
    patch_area = np.bincount(kept_patch, weights=area[keep], minlength=patch_count)
    empty = patch_area <= 0
    if empty.any():
        raise PatchError(f"patches {indices_text(empty)} have no area (no triangles, or only degenerate ones)", indices_of(empty))
    order = keep[np.argsort(kept_patch, kind="stable")].astype(np.int32)  # (T < 2^31: checked)
    del keep, kept_patch
    tp_sorted = tp[order]
    count = np.bincount(tp_sorted, minlength=patch_count).astype(np.int64)
    sorted_corners = UnitCorners(V, T, centre, diagonal, order)
    blocks = triangle_blocks(count)
    patch_normal = _patch_normals(sorted_corners, tp_sorted, blocks, patch_area)
    first = np.concatenate(([0], np.cumsum(count)[:-1]))
    fraction = _area_fractions(area[order], tp_sorted, first, count, patch_area)
    del area
    largest = np.abs((V[np.unique(T)] - centre) / diagonal).max()
    side = np.sqrt(patch_area)
    patch_ray_offset, patch_edge_inset, regions = *local_offsets(side, largest), None
    if (patch_ray_offset == RELATIVE_RAY_OFFSET).all() and (patch_edge_inset == RELATIVE_EDGE_INSET).all():
        ray_offset, patch_ray_offset, patch_edge_inset = RELATIVE_RAY_OFFSET, None, None
        inset, offset = RELATIVE_EDGE_INSET, RELATIVE_RAY_OFFSET
    else:
        # Parts far apart take frames of their own, where float32 would set some patch's offsets (regions.py).
        if set_by_rounding(side, largest).any():
            regions = split_regions(*patch_bounds(sorted_corners, tp_sorted, first, blocks, patch_count), side)
        if regions is not None:
            sorted_corners = UnitCorners(V, T, centre, diagonal, order, frames=(regions.centre, regions.patch_region[tp]))
            patch_ray_offset, patch_edge_inset = local_offsets(side, regions.largest_coordinate()[regions.patch_region])
        ray_offset = float(patch_ray_offset.min())  # (the lights', at least)
        inset, offset = patch_edge_inset, patch_ray_offset
        warn_coarse(patch_ray_offset, side, diagonal)
    leave_table = np.empty((12, patch_count), np.float32)
    is_parallelogram = parallelogram_frames(sorted_corners, first, count, inset, offset, patch_normal, leave_table[0:9])
    leave_table[9:12] = patch_normal.T
    geometry = Geometry(
        centre=centre,
        diagonal=diagonal,
        ray_offset=ray_offset,
        triangle_index=order,
        triangle_patch=tp_sorted.astype(np.int32, copy=False),
        corners=sorted_corners,
        patch_area=patch_area * diagonal**2,
        patch_normal=leave_table[9:12].T,  # (the same float32 numbers: one copy)
        patch_first_triangle=first.astype(np.int32),
        patch_triangle_count=count.astype(np.int32),
        triangle_key=tp_sorted + fraction if count.max() > 2 else None,
        patch_first_fraction=np.ascontiguousarray(fraction[first], dtype=np.float32),
        patch_parallelogram=is_parallelogram,
        leave_table=leave_table,
        patch_ray_offset=patch_ray_offset,
        patch_edge_inset=patch_edge_inset,
        regions=regions,
    )
    return with_visible_parts(geometry) if visible_parts else geometry


def _kept_triangles(corners):
    """((T,) unit-space area of each triangle, the indices of those that are not degenerate),
    warning how many are dropped."""
    area = np.empty(len(corners))
    for start in range(0, len(corners), BLOCK_TRIANGLES):
        area[start:start + BLOCK_TRIANGLES] = 0.5 * np.linalg.norm(triangle_cross(corners[start:start + BLOCK_TRIANGLES]), axis=1)
    degenerate = area <= RELATIVE_DEGENERATE_AREA
    if degenerate.any():
        warnings.warn(
            f"dropped {int(degenerate.sum())} degenerate (zero-area) triangles: {indices_text(degenerate)}",
            stacklevel=4,
        )
    return area, np.flatnonzero(~degenerate)


def _patch_normals(sorted_corners, tp_sorted, blocks, patch_area):
    """(P,3) float64 each patch's area-weighted unit normal, block by block of whole patches;
    PatchError for patches whose triangles cancel (opposite windings) or lean off it."""
    weighted = np.zeros((patch_area.size, 3))  # area-weighted normal sum (x2)
    for start, stop in blocks:
        cross = triangle_cross(sorted_corners[start:stop])
        patches = tp_sorted[start:stop]
        first_patch = patches[0]
        for k in range(3):
            weighted[first_patch:patches[-1] + 1, k] = np.bincount(patches - first_patch, weights=cross[:, k])
    norm = np.linalg.norm(weighted, axis=1)
    folded = norm <= 1e-12 * patch_area * 2
    if folded.any():
        raise PatchError(
            f"patches {indices_text(folded)} have triangles of opposite winding that cancel: "
            "a patch must be coplanar triangles facing one way",
            indices_of(folded),
        )
    patch_normal = weighted / norm[:, None]
    del weighted, norm
    # Every triangle within MIN_PATCH_NORMAL_COSINE of its patch's normal, block by block.
    crooked = np.zeros(tp_sorted.size, bool)
    for start, stop in blocks:
        cosine = np.einsum("ij,ij->i", triangle_normals(sorted_corners[start:stop]), patch_normal[tp_sorted[start:stop]])
        crooked[start:stop] = cosine < MIN_PATCH_NORMAL_COSINE
    if crooked.any():
        crooked_patches = np.unique(tp_sorted[crooked])
        raise PatchError(
            f"patches {indices_text(crooked_patches)} mix triangles of different "
            "orientation: a patch must be coplanar triangles with the same winding",
            crooked_patches,
        )
    return patch_normal


def _area_fractions(sorted_area, tp_sorted, first, count, patch_area):
    """(T,) each sorted triangle's cumulative share of its patch's area (1 exactly at a patch's
    last triangle, whatever the rounding)."""
    cumulative = np.cumsum(sorted_area)
    before_patch = np.concatenate(([0.0], cumulative))[first]
    fraction = (cumulative - before_patch[tp_sorted]) / patch_area[tp_sorted]
    fraction[first + count - 1] = 1.0
    return fraction


def patch_bounds(sorted_corners, triangle_patch, first, blocks, patch_count):
    """((P,3), (P,3)) float64 unit-space bounding box of each patch, block by block of whole
    patches of the triangles sorted by patch."""
    lower, upper = np.empty((patch_count, 3)), np.empty((patch_count, 3))
    for start, stop in blocks:
        corners = sorted_corners[start:stop]
        patches = slice(int(triangle_patch[start]), int(triangle_patch[stop - 1]) + 1)
        runs = first[patches] - start  # (each patch's triangles a run of the block)
        lower[patches] = np.minimum.reduceat(corners.min(axis=1), runs, axis=0)
        upper[patches] = np.maximum.reduceat(corners.max(axis=1), runs, axis=0)
    return lower, upper
