"""The display cells' meshes: the polygons written, and values carried inside a patch's triangles.

``refine.display_cells`` decides where cells split; here the split cells become the meshes the
results are written on (a patch none of whose cells split stays its own polygon), the coarse
surface is read at the cells' corners (linear inside each of its patch's triangles, which no cell
crosses), and the source's layers kept per polygon corner are carried to the new corners.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..display.smoothing import ITERATIONS, Surface
from ..mesh.faces import ranks_in_runs, starts_of, triangle_areas
from ..mesh.meshing import PatchMesh


@dataclass
class Shown:
    """The meshes the display is written on: per object ``meshes`` (the solve's PatchMesh, or its
    cells split), ``origin`` (each polygon's patch in the solve's mesh, or None: the solve's own);
    ``vertices`` (V',3) all objects' points, ``triangles`` (T',3) and ``triangle_patch`` (T',) (the
    solve's patches) the shading triangles, ``point_starts`` each object's first point in them."""

    meshes: list
    origin: list
    vertices: np.ndarray
    triangles: np.ndarray
    triangle_patch: np.ndarray
    point_starts: np.ndarray

    def corner_patch(self, k, patch_offset):
        """(C_k,) the solve's patch (its number in the scene) of each polygon corner of object ``k``."""
        local = self.meshes[k].corner_patch if self.origin[k] is None else self.origin[k][self.meshes[k].corner_patch]
        return np.asarray(local, np.int64) + patch_offset

    def per_polygon(self, k, values):
        """Object ``k``'s per-patch ``values`` ([S,]P_k,3) per polygon of its shown mesh."""
        return values if self.origin[k] is None else np.asarray(values)[..., self.origin[k], :]


class RefinedSurface:
    """``coarse`` (``smoothing.Surface`` of the solve's triangles) as the finer cells show it: its
    per-patch filters as they are, corner values its own interpolated at the fine corners, corner
    means the fine triangles'."""

    def __init__(self, coarse, fine, shown, slots, weights):
        self.coarse, self.fine, self.shown = coarse, fine, shown
        self.slots, self.weights = slots, weights  # (T'*3,) coarse corner slots; the new points' (``_slots``)

    def __getattr__(self, name):
        return getattr(self.coarse, name)

    @property
    def triangle_patch(self):
        return self.fine.triangle_patch

    def corner_means(self, x):
        return self.fine.corner_means(x)

    def corner_values(self, patch_values, iterations=ITERATIONS, return_filter=False, dtype=np.float64, slack=None):
        """``smoothing.Surface.corner_values`` of the coarse surface at the fine corners (with
        ``return_filter``, its ``apply`` too): the same means, continuous as the coarse ones."""
        if not return_filter:
            return self.interpolated(self.coarse.corner_values(patch_values, iterations, dtype=dtype, slack=slack))
        corners, apply = self.coarse.corner_values(patch_values, iterations, return_filter=True, dtype=dtype, slack=slack)
        return self.interpolated(corners), lambda parts, dtype=np.float64: self.interpolated(apply(parts, dtype))

    def interpolated(self, corners):
        """(..., T',3,k) the fine corners of coarse ``corners`` (..., T,3,k): linear within each patch."""
        corners = np.asarray(corners)
        flat = corners.reshape(corners.shape[:-3] + (-1, corners.shape[-1]))
        out = flat[..., self.slots, :]  # (a new point's row is filled below)
        rows, slots, weights = self.weights
        mixed = flat[..., slots[:, 0], :] * weights[:, 0, None]
        for j in (1, 2):
            mixed += flat[..., slots[:, j], :] * weights[:, j, None]
        out[..., rows, :] = mixed
        return out.reshape(corners.shape[:-3] + (-1, 3, corners.shape[-1]))


class Means:
    """The fine triangles as ``Surface.corner_means`` reads them: areas, patches, the part seen."""

    corner_means = Surface.corner_means

    def __init__(self, shown, patch_count, visible=None):
        self.triangle_patch = shown.triangle_patch
        self.triangle_area = triangle_areas(shown.vertices, shown.triangles)
        self.patch_area = np.bincount(self.triangle_patch, weights=self.triangle_area, minlength=patch_count)
        self.visible = None if visible is None else np.asarray(visible, np.float64).reshape(-1)
        self.visible_area = None if visible is None else np.bincount(np.repeat(self.triangle_patch, 3), weights=self.visible,
                                                                     minlength=patch_count)

    @property
    def patch_count(self):
        return len(self.patch_area)


def merged(coarse, fine, origin):
    """(the cells' PatchMesh ``fine`` with every patch whose triangles none split nor took a point (or
    that no cell covers) written as the ``coarse`` patch's own polygon, each polygon's coarse patch): the written mesh's
    polygons a patch each where nothing changed (a quad, not its two triangles)."""
    sizes = np.asarray(fine.face_sizes, np.int64)
    P = coarse.patch_count
    count = np.bincount(origin, minlength=P)
    whole = (count == 0) | (count == np.bincount(np.asarray(coarse.triangle_patch, np.int64), minlength=P)) & (
        np.bincount(origin, weights=sizes != 3, minlength=P) == 0)
    keep = ~whole[origin]  # (the fine polygons written)
    polygon_patch = np.concatenate([np.flatnonzero(whole), origin[keep]])
    order = np.argsort(polygon_patch, kind="stable")
    polygon_patch = polygon_patch[order]
    coarse_sizes = np.asarray(coarse.face_sizes, np.int64)
    coarse_starts, fine_starts = starts_of(coarse_sizes), starts_of(sizes)
    source = np.concatenate([np.flatnonzero(whole), np.flatnonzero(keep)])[order]  # coarse patch, or fine polygon
    is_coarse = np.concatenate([np.ones(whole.sum(), bool), np.zeros(keep.sum(), bool)])[order]
    new_sizes = np.where(is_coarse, coarse_sizes[np.where(is_coarse, source, 0)], sizes[np.where(is_coarse, 0, source)])
    first = np.where(is_coarse, coarse_starts[np.where(is_coarse, source, 0)], fine_starts[np.where(is_coarse, 0, source)])
    rank = ranks_in_runs(new_sizes)
    at = np.repeat(first, new_sizes) + rank
    corner_verts = np.where(np.repeat(is_coarse, new_sizes), np.asarray(coarse.corner_verts, np.int64)[np.minimum(at, len(coarse.corner_verts) - 1)],
                            np.asarray(fine.corner_verts, np.int64)[np.minimum(at, len(fine.corner_verts) - 1)])
    # the shading triangles: a whole patch's own, a split one's cells'
    renumber = np.full(len(sizes), -1, np.int64)
    renumber[source[~is_coarse]] = np.flatnonzero(~is_coarse)
    whole_number = np.full(P, -1, np.int64)
    whole_number[source[is_coarse]] = np.flatnonzero(is_coarse)
    ctp = np.asarray(coarse.triangle_patch, np.int64)
    from_coarse = np.flatnonzero(whole[ctp])
    ftp = np.asarray(fine.shading_triangle_patch, np.int64)
    from_fine = np.flatnonzero(renumber[ftp] >= 0)
    tris = np.concatenate([np.asarray(coarse.triangles, np.int64)[from_coarse], np.asarray(fine.shading_triangles, np.int64)[from_fine]])
    tri_polygon = np.concatenate([whole_number[ctp[from_coarse]], renumber[ftp[from_fine]]])
    tri_order = np.argsort(tri_polygon, kind="stable")
    tris, tri_polygon = tris[tri_order], tri_polygon[tri_order]
    area = np.bincount(tri_polygon, weights=triangle_areas(fine.points, tris), minlength=len(source))
    mesh = PatchMesh(fine.points, new_sizes.astype(np.int32), corner_verts.astype(np.int32),
                     np.asarray(coarse.patch_face)[polygon_patch].astype(np.int32), tris.astype(np.int32),
                     tri_polygon.astype(np.int32), area)
    mesh.shading_triangles, mesh.shading_triangle_patch = mesh.triangles, mesh.triangle_patch
    return mesh, polygon_patch


def containing(x, patch, vertices, triangles, tp):
    """((n,) the triangle of its ``patch`` each point ``x`` (n,3) lies in, (n,3) its barycentric
    coordinates there, clipped to the triangle): the nearest where it lies in none (float error)."""
    order = np.argsort(tp, kind="stable")
    count = np.bincount(tp, minlength=int(patch.max(initial=-1)) + 1)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    best = np.full(len(x), -np.inf)
    tri = np.zeros(len(x), np.int64)
    bary = np.zeros((len(x), 3))
    for j in range(int(count[patch].max(initial=0))):
        has = np.flatnonzero(count[patch] > j)
        t = order[first[patch[has]] + j]
        b = barycentric(x[has], *(vertices[triangles[t, c]] for c in range(3)))
        better = b.min(axis=1) > best[has]
        rows = has[better]
        best[rows], tri[rows], bary[rows] = b[better].min(axis=1), t[better], b[better]
    bary = np.clip(bary, 0.0, None)
    bary /= np.maximum(bary.sum(axis=1, keepdims=True), 1e-300)
    return tri, bary


def barycentric(x, a, b, c):
    """(n,3) the barycentric coordinates of points ``x`` (n,3) in triangles (a, b, c), each (n,3),
    of their projection onto its plane."""
    v0, v1, v2 = b - a, c - a, x - a
    d00, d01, d11 = (v0 * v0).sum(1), (v0 * v1).sum(1), (v1 * v1).sum(1)
    d20, d21 = (v2 * v0).sum(1), (v2 * v1).sum(1)
    denominator = d00 * d11 - d01 * d01
    denominator = np.where(denominator != 0, denominator, 1.0)
    v = (d11 * d20 - d01 * d21) / denominator
    w = (d00 * d21 - d01 * d20) / denominator
    return np.stack([1.0 - v - w, v, w], axis=1)


def corner_weights(coarse, fine, origin):
    """((C',3) corners of the ``coarse`` PatchMesh, (C',3) weights): each polygon corner of its
    ``fine`` cells (``origin`` (polygons,) the coarse patch of each) as the linear interpolation of
    its coarse patch's polygon corners (a coarse point: its own corner), for values kept per polygon
    corner (the source's UV maps, colours, normals)."""
    points = len(coarse.points)
    key = np.asarray(coarse.corner_patch, np.int64) * points + np.asarray(coarse.corner_verts, np.int64)
    order = np.argsort(key, kind="stable")
    vertex = np.asarray(fine.corner_verts, np.int64)
    patch = np.asarray(origin, np.int64)[fine.corner_patch]
    corner_vertex = np.repeat(vertex[:, None], 3, axis=1)
    weights = np.zeros((len(vertex), 3))
    weights[:, 0] = 1.0
    new = np.flatnonzero(vertex >= points)
    triangles = np.asarray(coarse.triangles, np.int64)
    tri, bary = containing(np.asarray(fine.points, np.float64)[vertex[new]], patch[new], np.asarray(coarse.points, np.float64),
                           triangles, np.asarray(coarse.triangle_patch, np.int64))
    corner_vertex[new], weights[new] = triangles[tri], bary
    wanted = patch[:, None] * points + corner_vertex
    return order[found(key[order], wanted.ravel())].reshape(-1, 3), weights


def shown_of(meshes, made, triangles, tp, starts, offsets):
    """The Shown of the objects' meshes, ``made`` {object: (PatchMesh, origin)} in place of theirs."""
    out_meshes, origin, vertices, tris, patches = [], [], [], [], []
    fine_start = 0
    point_starts = []
    for k, mesh in enumerate(meshes):
        point_starts.append(fine_start)
        if k in made:
            fine, where = made[k]
            out_meshes.append(fine)
            origin.append(np.asarray(where, np.int64))
            vertices.append(fine.points)
            tris.append(np.asarray(fine.shading_triangles, np.int64) + fine_start)
            patches.append(offsets[k] + origin[-1][np.asarray(fine.shading_triangle_patch, np.int64)])
        else:
            out_meshes.append(mesh)
            origin.append(None)
            vertices.append(mesh.points)
            rows = (tp >= offsets[k]) & (tp < offsets[k + 1])
            tris.append(triangles[rows] - starts[k] + fine_start)
            patches.append(tp[rows])
        fine_start += len(vertices[-1])
    index = np.int32 if sum(len(v) for v in vertices) < 2**31 else np.int64  # (as the scene's: half the memory)
    return Shown(out_meshes, origin, np.concatenate(vertices).astype(np.float64), np.concatenate(tris).astype(index),
                 np.concatenate(patches).astype(np.int32), np.asarray(point_starts, np.int64))


def found(sorted_keys, keys):
    """(n,) where each of ``keys`` is in ``sorted_keys``; ValueError where one is not."""
    at = np.searchsorted(sorted_keys, keys)
    if len(keys) and (at.max() >= len(sorted_keys) or not np.array_equal(sorted_keys[at], keys)):
        raise ValueError("a corner of the display's cells has no direct light")
    return at
