"""Meshing of polygon meshes into radiosity patches (pure numpy, no bpy).

A source mesh is given the way Blender stores it: vertex positions, the
number of corners of each face (``face_sizes``) and the vertex of each corner
(``corner_verts``, faces one after the other).  Faces whose longest edge is
larger than the patch size are subdivided:

* quads into a regular ``n x m`` grid (bilinear, ``n`` and ``m`` from the
  longest of each pair of opposite edges),
* triangles regularly into ``n**2`` triangles (``n`` from the longest edge),
* n-gons are triangulated first (with the triangulation given by the caller,
  e.g. Blender's loop triangles, or a fan) and each triangle is then
  subdivided as a triangle.

Faces that are small enough are kept as they are: one face, one patch.

A patch must be coplanar triangles (the core refuses a patch whose triangles
face different ways).  A quad or n-gon that is not planar (a twisted quad, a
sculpted or deformed mesh, a NURBS surface's tessellation) is therefore never
one patch nor a grid of bilinear cells: it is split into the triangles of its
triangulation, each of which is a patch of its own (subdivided as a triangle
when larger than the patch size).  A face is planar when every triangle of its
triangulation is within PLANAR_ANGLE_DEGREES of the face's area-weighted
normal; triangles of no area at the core's tolerance do not count (their normal
is rounding noise) and, in split faces, are left out.  Every
face of the resulting *patch mesh* is one patch; points generated on the same
source edge at the same fraction are welded, so neighbouring patches share
vertices wherever their subdivisions agree.

The steps: plan each face (``faces``), subdivide (``subdivision``: vectorised
over faces of one subdivision shape), weld and assemble (here).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .faces import (  # noqa: F401 - the meshing's public names
    PLANAR_ANGLE_DEGREES,
    PLANAR_COSINE,
    count_patches,
    default_min_area,
    fan_triangulation,
    nonplanar_faces,
    plan_faces,
    prepare,
    reverse_faces,
    ranks_in_runs,
    starts_of,
    triangle_areas,
)
from .subdivision import Builder, add_grids, add_kept_faces, add_triangles, weld

__all__ = [
    "PatchMesh",
    "mesh_patches",
    "nonplanar_faces",
    "default_min_area",
    "PLANAR_ANGLE_DEGREES",
    "concatenate",
    "reverse_faces",
    "fan_triangulation",
    "triangle_areas",
    "point_average",
    "corner_values",
    "count_patches",
]


class PatchMesh:
    """A patch mesh: every face is one patch.

    points        (N, 3) float64  positions of the patch mesh's vertices
    face_sizes    (P,)   int32    corners of each patch face (3, 4, or the
                                  source face's size for kept faces)
    corner_verts  (C,)   int32    point index of each corner, faces in order
    patch_face    (P,)   int32    source face each patch comes from
    triangles     (T, 3) int32    triangulation of the patches (into points)
    triangle_patch(T,)   int32    patch of each triangle
    patch_area    (P,)   float64  area of each patch (sum of its triangles)

    Once the mesh is one of several :func:`concatenate` combines, its points and areas are views
    of the combined arrays and its triangulation is the combined one's rows, made on each use
    (less the mesh's offsets): one copy of each.
    """

    def __init__(self, points, face_sizes, corner_verts, patch_face, triangles, triangle_patch, patch_area):
        self.points = points
        self.face_sizes = face_sizes
        self.corner_verts = corner_verts
        self.patch_face = patch_face
        self._triangles = triangles
        self._triangle_patch = triangle_patch
        self.patch_area = patch_area
        self._combined = None  # (CombinedPatches, its triangle rows, vertex offset, patch offset)

    def __repr__(self):
        return f"PatchMesh({self.patch_count} patches, {len(self.points)} points, {self.triangle_count} triangles)"

    @property
    def triangles(self) -> np.ndarray:
        if self._combined is None:
            return self._triangles
        combined, rows, vertex_offset, _ = self._combined
        return combined.triangles[rows] - combined.triangles.dtype.type(vertex_offset)

    @property
    def triangle_patch(self) -> np.ndarray:
        if self._combined is None:
            return self._triangle_patch
        combined, rows, _, patch_offset = self._combined
        return combined.triangle_patch[rows] - combined.triangle_patch.dtype.type(patch_offset)

    @property
    def triangle_count(self) -> int:
        return self._combined[1].stop - self._combined[1].start if self._combined else len(self._triangles)

    def _share(self, combined, rows, vertex_offset, patch_offset):
        """Points, areas and triangulation from now on from ``combined`` (see :func:`concatenate`)."""
        self.points = combined.vertices[vertex_offset : vertex_offset + len(self.points)]
        self.patch_area = combined.patch_area[patch_offset : patch_offset + self.patch_count]
        self._triangles = self._triangle_patch = None
        self._combined = (combined, rows, vertex_offset, patch_offset)

    @property
    def patch_count(self) -> int:
        return int(len(self.face_sizes))

    @property
    def face_starts(self) -> np.ndarray:
        """First corner of each patch face (Blender's ``loop_start``)."""
        return starts_of(self.face_sizes)

    @property
    def corner_patch(self) -> np.ndarray:
        """Patch of each corner (for writing flat colours on corners)."""
        return np.repeat(np.arange(self.patch_count, dtype=np.int32), self.face_sizes)


@dataclass
class CombinedPatches:
    """Several patch meshes concatenated into the arrays PatchScene takes."""

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_patch: np.ndarray
    patch_object: np.ndarray  # (P,) index of the mesh each patch comes from
    patch_offsets: np.ndarray  # (M+1,) patches of mesh k: offsets[k]:offsets[k+1]
    patch_area: np.ndarray
    meshes: list = field(default_factory=list)

    @property
    def patch_count(self) -> int:
        return int(self.patch_offsets[-1])

    def patch_slice(self, k: int) -> slice:
        return slice(int(self.patch_offsets[k]), int(self.patch_offsets[k + 1]))


def mesh_patches(
    vertices,
    face_sizes,
    corner_verts,
    patch_size: float,
    face_triangles=None,
    triangle_face=None,
    min_area=None,
) -> PatchMesh:
    """Subdivide the faces of one mesh into patches no larger than ``patch_size``.

    vertices      (V, 3) positions (world space)
    face_sizes    (F,)   corners per face (>= 3)
    corner_verts  (C,)   vertex of each corner, faces one after the other
    patch_size    largest patch edge, > 0
    face_triangles, triangle_face   optional triangulation of the source faces
                  (vertex indices, (T,3), and the face of each triangle), used
                  to triangulate n-gons, non-planar faces and kept faces; fan
                  triangulation if not given.
    min_area      triangles of this area or less are degenerate (see
                  :func:`nonplanar_faces`): they do not make a face non-planar,
                  and faces cut into triangles leave them out (the core would
                  drop them, leaving empty patches).  Default: the core's
                  tolerance for a scene of this mesh alone; pass
                  RELATIVE_DEGENERATE_AREA x (scene diagonal)**2 when several
                  meshes make one scene.

    Returns a :class:`PatchMesh` whose patches appear in source-face order
    (all patches of face 0 first, then face 1, ...).
    """
    args = prepare(vertices, face_sizes, corner_verts, patch_size, face_triangles, triangle_face)
    points, face_sizes, corner_verts, patch_size, face_triangles, triangle_face = args
    plan = plan_faces(*args, min_area)
    b = Builder()
    add_kept_faces(b, plan, points, face_sizes, corner_verts)
    add_grids(b, plan, points)
    add_triangles(b, plan, points, face_triangles, triangle_face)
    return _assemble(b, points, plan.kept_face, face_triangles, triangle_face)


def _assemble(b, points, kept_face, face_triangles, triangle_face):
    """The patch mesh of the built faces: points welded, patches in source-face order, and
    the patches' triangulation."""
    if b.count == 0:
        empty_i = np.zeros(0, dtype=np.int32)
        return PatchMesh(
            np.zeros((0, 3)), empty_i, empty_i, empty_i,
            np.zeros((0, 3), dtype=np.int32), empty_i, np.zeros(0),
        )
    uniq, out_points, inverse = _welded_points(b, points)
    sizes, corners, patch_face = _patches_in_face_order(b, inverse)
    del inverse
    tris, tri_patch = _triangulated(sizes, corners, patch_face, kept_face, uniq, len(points), face_triangles, triangle_face)
    area = np.bincount(tri_patch, weights=triangle_areas(out_points, tris), minlength=len(sizes))
    return PatchMesh(
        points=out_points,
        face_sizes=sizes.astype(np.int32),
        corner_verts=corners.astype(np.int32),
        patch_face=patch_face.astype(np.int32),
        triangles=tris,
        triangle_patch=tri_patch,
        patch_area=area,
    )


def _welded_points(b, points):
    """(welded keys, their points, each generated point's welded index): canonical positions,
    source vertices exactly, edge points from the lower-indexed vertex, so both neighbouring
    faces agree bit for bit."""
    # (the builder's parts go once joined: one copy of the generated points and their keys)
    keys, positions = _joined(b.keys), _joined(b.positions)
    uniq, first_index, inverse = weld(keys, len(points))
    del keys
    out_points = positions[first_index]
    del positions
    kind0 = uniq[:, 0] == 0
    out_points[kind0] = points[uniq[kind0, 1]]
    kind1 = uniq[:, 0] == 1
    if np.any(kind1):
        a = points[uniq[kind1, 1]]
        c = points[uniq[kind1, 2]]
        frac = (uniq[kind1, 3] / uniq[kind1, 4])[:, None]
        out_points[kind1] = a + frac * (c - a)
    return uniq, out_points, inverse


def _patches_in_face_order(b, inverse):
    """(corner count of each patch, their corners (welded indices), the source face of each),
    patches in source-face order (the builder's faces are let go of)."""
    sizes = np.concatenate([f[0] for f in b.faces])
    corners = inverse[np.concatenate([f[1] for f in b.faces])]
    patch_face = np.concatenate([f[2] for f in b.faces])
    order = np.concatenate([f[3] for f in b.faces])
    b.faces.clear()
    perm = np.lexsort((order, patch_face))
    fstarts = starts_of(sizes)
    sizes_sorted = sizes[perm]
    corner_index = np.repeat(fstarts[perm], sizes_sorted) + ranks_in_runs(sizes_sorted)
    return sizes_sorted, corners[corner_index], patch_face[perm]


def _triangulated(sizes, corners, patch_face, kept_face, uniq, point_count, face_triangles, triangle_face):
    """(triangles (T,3) int32, patch of each (T,) int32), sorted by patch: triangles and grid
    cells as fans (exact for a planar cell); kept quads and kept n-gons with the source
    triangulation (Blender's, when given) mapped onto the patch points."""
    F = len(kept_face)
    pstarts = starts_of(sizes)
    tri_patch = np.zeros(0, dtype=np.int64)
    tris = np.zeros((0, 3), dtype=np.int64)
    kept_patch = kept_face[patch_face]
    small = (sizes == 3) | ((sizes == 4) & ~kept_patch)
    if np.any(small):
        sp = np.nonzero(small)[0]
        cnt = sizes[sp] - 2
        tp = np.repeat(sp, cnt)
        k = ranks_in_runs(cnt)
        f0 = pstarts[tp]
        tris = np.stack([corners[f0], corners[f0 + k + 1], corners[f0 + k + 2]], axis=1)
        tri_patch = tp
    if np.any(~small):
        ng = np.nonzero(~small)[0]
        src_face = patch_face[ng]
        # map source vertex -> output point for the n-gon corners
        kind0 = uniq[:, 0] == 0
        vkey_point = -np.ones(point_count, dtype=np.int64)
        vkey_point[uniq[kind0, 1]] = np.nonzero(kind0)[0]
        patch_of_face = -np.ones(F, dtype=np.int64)
        patch_of_face[src_face] = ng
        tsel = np.nonzero(patch_of_face[triangle_face] >= 0)[0]
        tsel = tsel[kept_face[triangle_face[tsel]]]
        tris = np.concatenate([tris, vkey_point[face_triangles[tsel]]])
        tri_patch = np.concatenate([tri_patch, patch_of_face[triangle_face[tsel]]])
    order_t = np.argsort(tri_patch, kind="stable")
    return tris[order_t].astype(np.int32), tri_patch[order_t].astype(np.int32)


def _joined(parts):
    """The arrays of list ``parts`` as one (the list emptied: the parts go as soon as joined)."""
    joined = parts[0] if len(parts) == 1 else np.concatenate(parts)
    parts.clear()
    return joined


def concatenate(meshes) -> CombinedPatches:
    """Concatenate patch meshes (one per object) into PatchScene arrays: int32 indices (the
    meshing refuses more than 2^31 of anything long before), float64 positions and areas.
    The meshes then read their points, areas and triangulation from the combined arrays
    (PatchMesh._share): one copy of each."""
    meshes = list(meshes)
    vertex_offsets = starts_of(np.array([len(m.points) for m in meshes], dtype=np.int64))
    counts = np.array([m.patch_count for m in meshes], dtype=np.int64)
    patch_offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    triangle_offsets = starts_of(np.array([m.triangle_count for m in meshes] + [0], dtype=np.int64))
    if meshes:
        vertices = np.concatenate([m.points for m in meshes]).reshape(-1, 3)
        patch_area = np.concatenate([m.patch_area for m in meshes])
        triangles = np.empty((int(triangle_offsets[-1]), 3), dtype=np.int32)
        triangle_patch = np.empty(int(triangle_offsets[-1]), dtype=np.int32)
        for k, m in enumerate(meshes):
            rows = slice(int(triangle_offsets[k]), int(triangle_offsets[k + 1]))
            np.add(m.triangles, vertex_offsets[k], out=triangles[rows], casting="unsafe")
            np.add(m.triangle_patch, patch_offsets[k], out=triangle_patch[rows], casting="unsafe")
    else:
        vertices = np.zeros((0, 3))
        triangles = np.zeros((0, 3), dtype=np.int32)
        triangle_patch = np.zeros(0, dtype=np.int32)
        patch_area = np.zeros(0)
    patch_object = np.repeat(np.arange(len(meshes), dtype=np.int32), counts)
    combined = CombinedPatches(
        vertices=vertices,
        triangles=triangles,
        triangle_patch=triangle_patch,
        patch_object=patch_object,
        patch_offsets=patch_offsets,
        patch_area=patch_area,
        meshes=meshes,
    )
    for k, m in enumerate(meshes):
        rows = slice(int(triangle_offsets[k]), int(triangle_offsets[k + 1]))
        m._share(combined, rows, int(vertex_offsets[k]), int(patch_offsets[k]))
    return combined


def corner_values(mesh: PatchMesh, patch_values) -> np.ndarray:
    """Per-corner copy of per-patch values (flat colours), (C, ...)."""
    return np.asarray(patch_values)[mesh.corner_patch]


def point_average(mesh: PatchMesh, patch_values) -> np.ndarray:
    """Area-weighted average of the patch values around each point, (N, k).

    Every patch touching a point contributes once, weighted by its area.
    Points used by no patch get 0.
    """
    values = np.asarray(patch_values, dtype=np.float64)
    flat = values.reshape(len(values), -1)
    cp = mesh.corner_patch
    # each patch counted once per point even if it had a repeated corner
    P = max(mesh.patch_count, 1)
    code = np.unique(mesh.corner_verts.astype(np.int64) * P + cp)
    pairs = np.stack([code // P, code % P], axis=1)
    w = mesh.patch_area[pairs[:, 1]]
    N = len(mesh.points)
    total_w = np.bincount(pairs[:, 0], weights=w, minlength=N)
    out = np.empty((N, flat.shape[1]))
    for k in range(flat.shape[1]):  # over colour channels, not elements
        out[:, k] = np.bincount(pairs[:, 0], weights=w * flat[pairs[:, 1], k], minlength=N)
    with np.errstate(invalid="ignore", divide="ignore"):
        out = np.where(total_w[:, None] > 0, out / total_w[:, None], 0.0)
    return out.reshape((N,) + values.shape[1:])
