"""The patch scene: validated arrays of geometry and materials, and everything the
random walks precompute from them once (patch frames, sampling tables, the ray tracer).

Notation follows Sbert & Brusi: a patch i has area A_i, reflectivity R_i and emittance
(emitted power per unit area) E_i; its power is Phi_i = E_i A_i and Phi_T = sum_i Phi_i.
Colours are carried as three channels; the grey quantities the paper's formulas use are
channel means (R_bar_i, E_bar_i), so that a grey scene is exactly the paper's.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass
from functools import cached_property

import numpy as np

CHANNELS = 3

# The ray tracer works in unit space: positions (world - centre) / diagonal, where centre and
# diagonal are the bounding box's, so that float32 precision and Embree's internal tolerances
# (its barycentrics fail below a scene size of ~1e-8) see the same scene at any scale or
# distance from the origin. Rays leave a patch from a point pushed this far along its normal
# (~170 float32 ulps at the scene's extent).
RELATIVE_RAY_OFFSET = 1e-5

# Points where rays leave a patch keep this distance (relative to the diagonal, ~17 float32
# ulps at the scene's extent) from the patch's edges, so that float32 rounding never puts an
# origin on the far side of an adjacent wall, where its ray would hit that wall's back.
RELATIVE_EDGE_INSET = 1e-6

# A ray leaving from where the previous one hit starts at that hit point (origin + t direction,
# pushed off along the normal) if the point lies at least this far (relative to the diagonal)
# from every edge of its triangle: four times the edge inset, which leaves room for float32's
# error in the point (~2e-7 in unit space). Closer to an edge, the hit's barycentric
# coordinates are mapped onto the triangle's inset leaving frame instead.
RELATIVE_HIT_EDGE_CLEARANCE = 4 * RELATIVE_EDGE_INSET

# At most this many distinct leaving-frame shapes (edges and normal) are kept as a table of
# their own (Geometry.leave_shapes; 2^12 shapes take 144 kB): more, and the table is no
# smaller than the patches' own rows.
LEAVE_SHAPES_MAX = 1 << 12

# Odd multipliers (of the golden ratio's 64-bit constant) that hash a leaving frame's 9 float32
# bit patterns to one uint64 (Geometry.leave_shapes).
_SHAPE_HASH = np.array([((2 * k + 1) * 0x9E3779B97F4A7C15) % 2**64 for k in range(9)], dtype=np.uint64)

# Scenes whose bounding-box diagonal lies outside this range are refused: float32 ray tracing
# and float64 areas stay far from overflow and underflow inside it.
MIN_DIAGONAL, MAX_DIAGONAL = 1e-12, 1e12

# Above this mean reflectivity a finite path takes on average more than 2^24 (16.7 million)
# bounces on the patch's neighbourhood: such a run would never end in practice, so it is refused.
MAX_MEAN_REFLECTIVITY = 1.0 - 2.0**-24

# A triangle whose area is below this fraction of diagonal**2 is degenerate.
RELATIVE_DEGENERATE_AREA = 1e-14

# Triangles of one patch must share its orientation: a triangle whose normal is further than
# this (cosine) from the patch's mean normal has the wrong winding or is not coplanar.
MIN_PATCH_NORMAL_COSINE = 0.5


class PatchError(ValueError):
    """A ValueError about particular patches; ``patches`` holds their indices, so that a caller
    that knows where patches came from (the Blender layer) can name the objects instead."""

    def __init__(self, message, patches):
        super().__init__(message)
        self.patches = np.asarray(patches, dtype=np.int64)


def _indices(mask_or_indices):
    a = np.asarray(mask_or_indices)
    return np.flatnonzero(a) if a.dtype == bool else a


class CoincidentFacesWarning(UserWarning):
    """Triangles lying exactly on top of others; ``patches`` holds the patches involved."""

    def __init__(self, message, patches):
        super().__init__(message)
        self.patches = patches


def _warn_coincident(corners, triangle_patch):
    """Warn about triangles with exactly the same corners as another (in any order or winding):
    a ray hits one of them at random, so each shows only part of the light it gets."""
    # A key that does not depend on the corners' order: each corner's projection, sorted, then
    # projected again. Equal triangles get equal keys; neighbours with equal keys are then
    # compared exactly (corners in lexicographic order). O(T log T), no false positives.
    projected = corners @ np.array([1.0, 1.37, 1.73])  # (T,3)
    a, b, c = projected[:, 0], projected[:, 1], projected[:, 2]
    low, high = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
    middle = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))  # exact, order-free
    key = low + 2.3 * middle + 3.1 * high
    by_key = np.argsort(key, kind="stable")
    candidates = np.flatnonzero(key[by_key[1:]] == key[by_key[:-1]])
    if candidates.size == 0:
        return
    first, second = by_key[candidates], by_key[candidates + 1]

    def canonical(c):
        order = np.lexsort((c[:, :, 2], c[:, :, 1], c[:, :, 0]), axis=-1)
        return np.take_along_axis(c, order[:, :, None], axis=1)

    same = (canonical(corners[first]) == canonical(corners[second])).all(axis=(1, 2))
    if not same.any():
        return
    flagged = np.zeros(len(corners), dtype=bool)
    flagged[first[same]] = True
    flagged[second[same]] = True
    patches = np.unique(triangle_patch[flagged])
    warnings.warn(
        CoincidentFacesWarning(
            f"{int(flagged.sum())} triangles lie exactly on top of others (duplicated faces), on patches "
            f"{_indices_text(patches)}: a ray hits one of each pair at random, so each shows only part "
            "of the light (and where they face opposite ways, the one seen from behind absorbs it); "
            "delete the duplicates, or give a two-sided wall some thickness",
            patches,
        ),
        stacklevel=4,
    )


def _indices_text(mask_or_indices, limit=10):
    idx = np.flatnonzero(mask_or_indices) if np.asarray(mask_or_indices).dtype == bool else np.asarray(mask_or_indices)
    shown = ", ".join(str(int(i)) for i in idx[:limit])
    more = f" and {idx.size - limit} more" if idx.size > limit else ""
    return f"{shown}{more}"


def _as_channels(values, patch_count, name):
    """(P,) grey or (P,3) RGB -> (P,3) float64, with shape errors that say what was expected."""
    array = np.asarray(values, dtype=np.float64)
    if array.ndim == 1:
        if array.shape[0] != patch_count:
            raise ValueError(f"{name} has {array.shape[0]} values but the scene has {patch_count} patches")
        return np.repeat(array[:, None], CHANNELS, axis=1)
    if array.ndim == 2 and array.shape[1] == CHANNELS:
        if array.shape[0] != patch_count:
            raise ValueError(f"{name} has {array.shape[0]} rows but the scene has {patch_count} patches")
        return np.ascontiguousarray(array)
    raise ValueError(f"{name} must have shape (P,) or (P, 3); got {array.shape}")


def validate_materials(reflectivity, emission, patch_count):
    """Check reflectivity and emission arrays; return them as (P,3) float64.

    Raises ValueError naming the problem and the offending patch indices.
    """
    R = _as_channels(reflectivity, patch_count, "reflectivity")
    E = _as_channels(emission, patch_count, "emission")
    for name, values in (("reflectivity", R), ("emission", E)):
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            raise PatchError(f"{name} is NaN or infinite on patches {_indices_text(bad)}", _indices(bad))
    negative = (E < 0).any(axis=1)
    if negative.any():
        raise PatchError(f"emission is negative on patches {_indices_text(negative)}", _indices(negative))
    outside = ((R < 0) | (R >= 1)).any(axis=1)
    if outside.any():
        raise PatchError(
            f"reflectivity must lie in [0, 1) but does not on patches {_indices_text(outside)} "
            "(a reflectivity of 1 or more creates energy or never lets a path end)",
            _indices(outside),
        )
    unresolved = R.mean(axis=1) > MAX_MEAN_REFLECTIVITY
    if unresolved.any():
        raise PatchError(
            f"reflectivity is within 2^-24 of 1 (mean over channels above {MAX_MEAN_REFLECTIVITY:.9f}) on patches "
            f"{_indices_text(unresolved)}: a path would take more than 16 million bounces there and would never end "
            "in practice",
            _indices(unresolved),
        )
    if not (E > 0).any():
        raise ValueError("the scene has no emitting patch: every emission is zero")
    return R, E


@dataclass(frozen=True)
class Geometry:
    """Geometry arrays derived once and shared by every material set on the same patches.

    Triangles are stored sorted by patch (the ray tracer's primitive ids index this order).
    Positions are in unit space, (world - centre) / diagonal, in float32; areas are in the
    scene's units.
    """

    centre: np.ndarray            # (3,) float64
    diagonal: float               # bounding-box diagonal, scene units
    ray_offset: float             # distance a ray origin is pushed along the normal (unit space)
    triangle_index: np.ndarray    # (T,) original index of each sorted triangle
    triangle_patch: np.ndarray    # (T,) int32 patch of each sorted triangle
    triangle_area: np.ndarray     # (T,) float64
    triangle_normal: np.ndarray   # (T,3) float32 unit normals
    triangle_corners: np.ndarray  # (T,3,3) float32 unit-space corners, the ray tracer's input
    patch_area: np.ndarray        # (P,) float64
    patch_normal: np.ndarray      # (P,3) float32
    patch_first_triangle: np.ndarray  # (P,) int64 first sorted triangle of each patch
    patch_triangle_count: np.ndarray  # (P,) int64
    triangle_key: np.ndarray      # (T,) float64: patch + cumulative area fraction in the patch
    triangle_frame: np.ndarray    # (9,T) float32: origin (pushed off), edge1, edge2, one row per coordinate
    patch_first_fraction: np.ndarray  # (P,) float32: area fraction of each patch's first triangle
    patch_parallelogram: np.ndarray   # (P,) bool: the patch is two triangles forming a parallelogram
    parallelogram_frame: np.ndarray   # (9,P) float32: corner (pushed off), edge a, edge b (zeros if not)

    @property
    def patch_count(self):
        return self.patch_area.shape[0]

    @property
    def triangle_count(self):
        return self.triangle_patch.shape[0]

    @cached_property
    def max_triangles_per_patch(self):
        return int(self.patch_triangle_count.max())

    def to_world(self, points):
        """Unit-space points (n,3) back in the scene's coordinates, float64."""
        return np.asarray(points, dtype=np.float64) * self.diagonal + self.centre

    @cached_property
    def patch_normal_rows(self):
        """(3,P) float32: the patch normals one coordinate per row, for column gathers."""
        return np.ascontiguousarray(self.patch_normal.T)

    @cached_property
    def leave_table(self):
        """(12,P) float32: each parallelogram patch's corner (pushed off), edge a, edge b, then
        its normal, one coordinate per row: one gather gives a random exit's origin frame and
        the normal its direction is built on."""
        return np.ascontiguousarray(np.vstack([self.parallelogram_frame, self.patch_normal_rows]))

    @cached_property
    def leave_shapes(self):
        """The distinct shapes of the parallelogram patches' leaving frames: ((9,K) float32
        rows edge a, edge b, normal, one column per distinct shape; (P,) uint16 the shape of
        each patch), bit for bit equal, or None where there are more than LEAVE_SHAPES_MAX.
        A patch's frame is its corner and its shape: patches meshed from one face share one
        (a wall of a room, a box's side). Compared as bits: a shared shape is the same
        float32 numbers, and -0.0 stays apart from 0.0."""
        bits = np.ascontiguousarray(self.leave_table[3:12].T).view(np.uint32)  # (P,9)
        # Rows are told apart by a hash first (a sort of P numbers, not of P rows: 1M patches
        # of distinct shapes are refused in 15 ms, not 1.3 s); equal hashes are then checked to
        # be equal rows, and where two shapes share one, the rows themselves are sorted.
        hashed = bits.astype(np.uint64) @ _SHAPE_HASH
        if np.unique(hashed).size > LEAVE_SHAPES_MAX:  # (shared hashes only lower the count)
            return None
        _, first, shape_of_patch = np.unique(hashed, return_index=True, return_inverse=True)
        shapes = bits[first]
        if not np.array_equal(shapes[shape_of_patch.reshape(-1)], bits):
            shapes, shape_of_patch = np.unique(bits, axis=0, return_inverse=True)
            if shapes.shape[0] > LEAVE_SHAPES_MAX:
                return None
        return (
            np.ascontiguousarray(shapes.view(np.float32).T),
            shape_of_patch.reshape(-1).astype(np.uint16),
        )

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
        return edge_barycentric(self.triangle_corners)

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
        from .patch_grids import patch_grids

        return patch_grids(self)

    @cached_property
    def tracer(self):
        """The Embree scene over these triangles, built on first use and then reused."""
        from .raytrace import RayTracer

        return RayTracer(self.triangle_corners)


def build_geometry(vertices, triangles, triangle_patch, patch_count):
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3); got {V.shape}")
    if V.shape[0] == 0:
        raise ValueError("the scene has no vertices")
    bad_vertex = ~np.isfinite(V).all(axis=1)
    if bad_vertex.any():
        raise ValueError(f"vertices are NaN or infinite at vertex indices {_indices_text(bad_vertex)}")
    T_raw = np.asarray(triangles)
    if T_raw.ndim != 2 or T_raw.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3); got {T_raw.shape}")
    if T_raw.shape[0] == 0:
        raise ValueError("the scene has no triangles")
    if not np.issubdtype(T_raw.dtype, np.integer):
        raise ValueError(f"triangles must hold integer vertex indices; got dtype {T_raw.dtype}")
    T = T_raw.astype(np.int64)
    out_of_range = ((T < 0) | (T >= V.shape[0])).any(axis=1)
    if out_of_range.any():
        raise ValueError(
            f"triangles {_indices_text(out_of_range)} use vertex indices outside [0, {V.shape[0]})"
        )
    tp_raw = np.asarray(triangle_patch)
    if tp_raw.shape != (T.shape[0],):
        raise ValueError(f"triangle_patch must have shape ({T.shape[0]},) to match triangles; got {tp_raw.shape}")
    if not np.issubdtype(tp_raw.dtype, np.integer):
        raise ValueError(f"triangle_patch must hold integer patch indices; got dtype {tp_raw.dtype}")
    tp = tp_raw.astype(np.int64)
    bad_patch = (tp < 0) | (tp >= patch_count)
    if bad_patch.any():
        raise ValueError(
            f"triangles {_indices_text(bad_patch)} name patches outside [0, {patch_count}) "
            f"(the scene has {patch_count} patches, one per row of reflectivity and emission)"
        )

    is_used = np.zeros(V.shape[0], dtype=bool)
    is_used[T.ravel()] = True
    used = V[is_used]
    lo, hi = used.min(axis=0), used.max(axis=0)
    centre = 0.5 * (lo + hi)
    with np.errstate(over="ignore", invalid="ignore"):
        diagonal = float(np.linalg.norm(hi - lo))
    if not diagonal > 0:
        raise ValueError("the scene has no extent: all vertices coincide")
    if not MIN_DIAGONAL <= diagonal <= MAX_DIAGONAL:
        raise ValueError(
            f"the scene's size (bounding-box diagonal {diagonal:.3g}) is outside [{MIN_DIAGONAL:g}, {MAX_DIAGONAL:g}] "
            "scene units: rescale it (radiosity does not depend on the unit of length)"
        )

    corners = (V[T] - centre) / diagonal          # (T,3,3) float64, unit space
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    cross = np.cross(e1, e2)
    double_area = np.linalg.norm(cross, axis=1)
    area = 0.5 * double_area                      # unit space
    degenerate = area <= RELATIVE_DEGENERATE_AREA
    if degenerate.any():
        warnings.warn(
            f"dropped {int(degenerate.sum())} degenerate (zero-area) triangles: {_indices_text(degenerate)}",
            stacklevel=3,
        )
    keep = np.flatnonzero(~degenerate)
    _warn_coincident(corners[keep], tp[keep])
    patch_area = np.bincount(tp[keep], weights=area[keep], minlength=patch_count)
    empty = patch_area <= 0
    if empty.any():
        raise PatchError(f"patches {_indices_text(empty)} have no area (no triangles, or only degenerate ones)", _indices(empty))

    order = keep[np.argsort(tp[keep], kind="stable")]
    tp_sorted = tp[order]
    normal = cross[order] / double_area[order, None]
    weighted = np.stack(  # area-weighted normal sum (x2)
        [np.bincount(tp_sorted, weights=cross[order, k], minlength=patch_count) for k in range(3)], axis=1
    )
    norm = np.linalg.norm(weighted, axis=1)
    folded = norm <= 1e-12 * patch_area * 2
    if folded.any():
        raise PatchError(
            f"patches {_indices_text(folded)} have triangles of opposite winding that cancel: "
            "a patch must be coplanar triangles facing one way",
            _indices(folded),
        )
    patch_normal = weighted / norm[:, None]
    cosine = np.einsum("ij,ij->i", normal, patch_normal[tp_sorted])
    crooked = cosine < MIN_PATCH_NORMAL_COSINE
    if crooked.any():
        crooked_patches = np.unique(tp_sorted[crooked])
        raise PatchError(
            f"patches {_indices_text(crooked_patches)} mix triangles of different "
            "orientation: a patch must be coplanar triangles with the same winding",
            crooked_patches,
        )

    count = np.bincount(tp_sorted, minlength=patch_count).astype(np.int64)
    first = np.concatenate(([0], np.cumsum(count)[:-1]))
    sorted_area = area[order]
    cumulative = np.cumsum(sorted_area)
    before_patch = np.concatenate(([0.0], cumulative))[first]
    fraction = (cumulative - before_patch[tp_sorted]) / patch_area[tp_sorted]
    last = first + count - 1
    fraction[last] = 1.0  # exact upper end, whatever the rounding
    ray_offset = RELATIVE_RAY_OFFSET
    sorted_corners = corners[order]
    inset = RELATIVE_EDGE_INSET
    is_parallelogram, parallelogram = _parallelograms(sorted_corners, first, count, inset)
    parallelogram[:, :3] += ray_offset * patch_normal
    leave_corners = _inset_triangles(sorted_corners, inset)

    f32 = lambda a: np.ascontiguousarray(a, dtype=np.float32)  # noqa: E731
    return Geometry(
        centre=centre,
        diagonal=diagonal,
        ray_offset=ray_offset,
        triangle_index=order,
        triangle_patch=tp_sorted.astype(np.int32),
        triangle_area=sorted_area * diagonal**2,
        triangle_normal=f32(normal),
        triangle_corners=f32(sorted_corners),
        patch_area=patch_area * diagonal**2,
        patch_normal=f32(patch_normal),
        patch_first_triangle=first,
        patch_triangle_count=count,
        triangle_key=tp_sorted + fraction,
        triangle_frame=f32(
            np.hstack(
                [
                    leave_corners[:, 0] + ray_offset * normal,
                    leave_corners[:, 1] - leave_corners[:, 0],
                    leave_corners[:, 2] - leave_corners[:, 0],
                ]
            ).T
        ),
        patch_first_fraction=f32(fraction[first]),
        patch_parallelogram=is_parallelogram,
        parallelogram_frame=f32(np.where(is_parallelogram[:, None], parallelogram, 0.0).T),
    )


def edge_barycentric(corners):
    """(T,) float32: for (T,3,3) unit-space triangles, the barycentric coordinate below which a
    point may lie closer than RELATIVE_HIT_EDGE_CLEARANCE to one of the triangle's edges (the
    clearance over its smallest altitude, 2 area / longest edge; 1 for triangles too small to
    have such points)."""
    corners = np.asarray(corners, dtype=np.float64)
    edges = corners[:, [1, 2, 0]] - corners
    longest = np.linalg.norm(edges, axis=2).max(axis=1)
    twice_area = np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        threshold = RELATIVE_HIT_EDGE_CLEARANCE * longest / twice_area
    return np.where(np.isfinite(threshold), np.minimum(threshold, 1.0), 1.0).astype(np.float32)


def _inset_triangles(corners, inset):
    """Each triangle shrunk about its incentre so that every edge moves in by ``inset``
    (by at most half the inradius for tiny triangles). (T,3,3)."""
    a = np.linalg.norm(corners[:, 2] - corners[:, 1], axis=1)  # side opposite corner 0
    b = np.linalg.norm(corners[:, 0] - corners[:, 2], axis=1)
    c = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    perimeter = a + b + c
    incentre = (a[:, None] * corners[:, 0] + b[:, None] * corners[:, 1] + c[:, None] * corners[:, 2]) / perimeter[:, None]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    inradius = 2 * area / perimeter
    shrink = np.minimum(inset / inradius, 0.5)
    return incentre[:, None, :] + (1 - shrink)[:, None, None] * (corners - incentre[:, None, :])


def _parallelograms(sorted_corners, first, count, inset=0.0):
    """Which patches are two triangles forming a parallelogram, and its (corner, a, b).

    Such a patch (any quad with parallel sides: the grids meshing makes) is sampled as
    corner + u a + v b, without choosing a triangle or folding.
    """
    P = first.shape[0]
    frame = np.zeros((P, 9))
    two, ok, (p, s1, s2, _) = parallelogram_corners(sorted_corners, first, count)
    if two.size == 0:
        return np.zeros(P, bool), frame
    edge_a, edge_b = s1 - p, s2 - p
    # Inset every side by ``inset`` (at most a quarter of the patch): corner + d_a a + d_b b.
    d_a = np.minimum(inset / np.linalg.norm(edge_a, axis=1), 0.25)[:, None]
    d_b = np.minimum(inset / np.linalg.norm(edge_b, axis=1), 0.25)[:, None]
    frame[two] = np.hstack([p + d_a * edge_a + d_b * edge_b, (1 - 2 * d_a) * edge_a, (1 - 2 * d_b) * edge_b])
    flags = np.zeros(P, bool)
    flags[two[ok]] = True
    return flags, frame


def parallelogram_corners(sorted_corners, first, count):
    """The corners of the patches made of two triangles: (patches with two triangles (n,),
    whether each is a parallelogram (n,), and its corners (p, s1, s2, q), each (n,3) float64).
    p is the first triangle's own corner, s1 and s2 the two corners the triangles share (the
    edges are a = s1 - p and b = s2 - p), q the second triangle's own corner (p + a + b to
    within rounding)."""
    two = np.flatnonzero(count == 2)
    t0 = np.asarray(sorted_corners[first[two]], dtype=np.float64)  # (n,3,3)
    t1 = np.asarray(sorted_corners[first[two] + 1], dtype=np.float64)
    tolerance = 1e-7  # unit space
    between = t0[:, :, None, :] - t1[:, None, :, :]  # (n,3,3,3): every corner of t0 to every corner of t1
    shared = np.einsum("...k,...k->...", between, between) < tolerance**2  # (n,3,3)
    shared_in_t0 = shared.any(axis=2)        # (n,3)
    shared_in_t1 = shared.any(axis=1)
    ok = (shared_in_t0.sum(axis=1) == 2) & (shared_in_t1.sum(axis=1) == 2) & (shared.sum(axis=(1, 2)) == 2)
    rows = np.arange(two.size)
    p = t0[rows, np.argmin(shared_in_t0, axis=1)]      # t0's own corner
    q = t1[rows, np.argmin(shared_in_t1, axis=1)]      # t1's own corner
    order = np.argsort(~shared_in_t0, axis=1, kind="stable")[:, :2]
    s1 = t0[rows, order[:, 0]]
    s2 = t0[rows, order[:, 1]]
    ok &= np.linalg.norm(p + q - s1 - s2, axis=1) < tolerance  # the diagonals bisect each other
    return two, ok, (p, s1, s2, q)


class PatchScene:
    """Patches (groups of coplanar triangles) with their reflectivity and emittance.

    Parameters
    ----------
    vertices : (V,3) float
    triangles : (T,3) int, indices into ``vertices``; the normal follows the right-hand rule
        and radiosity leaves the front side.
    triangle_patch : (T,) int in [0, P): the patch each triangle belongs to.
    reflectivity : (P,3) RGB or (P,) grey, each in [0, 1).
    emission : (P,3) or (P,), the emittance E (power per unit area), >= 0.

    Degenerate triangles are dropped with a warning; everything else that is wrong raises
    ``ValueError`` naming the problem and the offending indices.
    """

    def __init__(self, vertices, triangles, triangle_patch, reflectivity, emission, *, _geometry=None):
        reflectivity_arr = np.asarray(reflectivity)
        if reflectivity_arr.ndim not in (1, 2) or reflectivity_arr.shape[0] == 0:
            raise ValueError(f"reflectivity must have shape (P,) or (P, 3) with P > 0; got {reflectivity_arr.shape}")
        patch_count = reflectivity_arr.shape[0]
        self.reflectivity, self.emission = validate_materials(reflectivity, emission, patch_count)
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.triangles = np.asarray(triangles)
        self.triangle_patch = np.asarray(triangle_patch)
        self.geometry = _geometry if _geometry is not None else build_geometry(
            vertices, triangles, triangle_patch, patch_count
        )
        with np.errstate(over="ignore", invalid="ignore"):
            power = self.patch_area[:, None] * self.emission
        if not np.isfinite(power.sum()):
            raise PatchError(
                "emission times area overflows: the emitted power is not a finite number "
                f"(largest emission {self.emission.max():.3g}); use smaller units of power",
                np.flatnonzero(~np.isfinite(power).all(axis=1) | (power.max(axis=1) > 1e300)),
            )

    # --- materials -------------------------------------------------------------------------
    def with_materials(self, reflectivity, emission):
        """A scene on the same patches with other materials, sharing geometry and ray tracer."""
        return PatchScene(
            self.vertices, self.triangles, self.triangle_patch, reflectivity, emission, _geometry=self.geometry
        )

    # --- sizes -----------------------------------------------------------------------------
    @property
    def patch_count(self):
        return self.geometry.patch_count

    @property
    def triangle_count(self):
        return self.geometry.triangle_count

    @property
    def patch_area(self):
        return self.geometry.patch_area

    @property
    def patch_normal(self):
        return self.geometry.patch_normal.astype(np.float64)

    @cached_property
    def total_area(self):
        """A_T."""
        return float(self.patch_area.sum())

    # --- grey quantities of the paper ------------------------------------------------------
    @cached_property
    def mean_reflectivity(self):
        """R_bar_i: the channel mean of each patch's reflectivity (the survival probability);
        exactly R_i where the three channels are equal (a float mean of three equal numbers
        may differ from them in the last bit)."""
        R = self.reflectivity
        mean = R.mean(axis=1)
        grey = (R == R[:, :1]).all(axis=1)
        mean[grey] = R[grey, 0]
        return mean

    @cached_property
    def is_grey(self):
        return bool((self.reflectivity == self.reflectivity[:, :1]).all() and (self.emission == self.emission[:, :1]).all())

    @cached_property
    def patch_power(self):
        """Phi_i = A_i E_bar_i, the channel-mean power of each patch."""
        return self.patch_area * self.emission.mean(axis=1)

    @cached_property
    def total_power(self):
        """Phi_T."""
        return float(self.patch_power.sum())

    @cached_property
    def average_reflectivity(self):
        """R_ave: the area-weighted average reflectivity (channel mean)."""
        return float((self.patch_area * self.mean_reflectivity).sum() / self.total_area)

    @property
    def tracer(self):
        """The ray tracer over this geometry (shared with scenes made by with_materials)."""
        return self.geometry.tracer

    def __repr__(self):
        return (
            f"PatchScene({self.patch_count} patches, {self.triangle_count} triangles, "
            f"A_T={self.total_area:.6g}, Phi_T={self.total_power:.6g}, R_ave={self.average_reflectivity:.4g})"
        )
