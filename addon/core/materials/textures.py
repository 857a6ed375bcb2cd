"""Image textures and colour attributes averaged over each patch's own footprint (supersampled, linear colour).

A patch is a piece of one source face; its texture colour is the mean of the image over the
part of UV space the patch covers: points spread evenly over each of the patch's triangles
(area-weighted) take the UV of the source face's loop triangle they lie in (linear inside it,
as Blender interpolates UVs), pass through the texture's affine mapping, and read the image
bilinearly with repeat, as an Image Texture node with Linear interpolation does.
"""
from __future__ import annotations

import numpy as np

# Barycentric points spread evenly over a triangle: the centres of the 16 sub-triangles of its
# 4 x 4 subdivision (equal areas), so that the mean over them integrates linear functions exactly.
_N = 4


def _subtriangle_centres(n=_N):
    points = []
    for i in range(n):
        for j in range(n - i):
            points.append(((i + 1 / 3) / n, (j + 1 / 3) / n))  # upright sub-triangle
            if i + j < n - 1:
                points.append(((i + 2 / 3) / n, (j + 2 / 3) / n))  # inverted one
    return np.array(points)


SAMPLES = _subtriangle_centres()  # (16, 2) barycentric (b1, b2) of corners 1 and 2


def patch_texture_average(patch_mesh, patches, source_corners, source_uv, triangle_face, image, affine):
    """(len(patches), 3) mean colour of ``image`` over each of the given (sorted) patches of
    ``patch_mesh``: ``source_corners`` (T,3,3) and ``source_uv`` (T,3,2) are the source
    object's loop triangles and their corners' UVs, ``triangle_face`` (T,) their faces (in face
    order); ``image`` (H,W,3) linear, row 0 at the bottom; ``affine`` (2,3) maps UV to image
    coordinates (u, v) before the lookup (the Mapping node)."""
    def colour(points, face):
        uv = _interpolated(points, face, source_corners, source_uv, triangle_face)
        return sample_bilinear(image, uv @ affine[:, :2].T + affine[:, 2])

    return _patch_means(patch_mesh, np.asarray(patches), colour)


def patch_attribute_average(patch_mesh, patches, source_corners, corner_colours, triangle_face):
    """(len(patches), 3) mean over each patch of a colour attribute given at the corners of
    the source's loop triangles (T,3,3), interpolated linearly inside them as Blender does."""
    return _patch_means(patch_mesh, np.asarray(patches),
                        lambda points, face: _interpolated(points, face, source_corners, corner_colours, triangle_face))


def _patch_means(patch_mesh, patches, colour):
    """(len(patches), 3) the area-weighted mean of ``colour(points, face)`` over SAMPLES points
    of every triangle of each patch."""
    in_patch = np.isin(patch_mesh.triangle_patch, patches)
    tri = patch_mesh.triangles[in_patch]
    owner = patch_mesh.triangle_patch[in_patch]
    corners = patch_mesh.points[tri]  # (k,3,3)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    s = SAMPLES
    points = a[:, None] + s[None, :, :1] * (b - a)[:, None] + s[None, :, 1:] * (c - a)[:, None]  # (k,S,3)
    face = np.repeat(patch_mesh.patch_face[owner], len(s))
    colour = colour(points.reshape(-1, 3), face).reshape(len(tri), len(s), 3).mean(axis=1)
    index = np.searchsorted(patches, owner)  # (patches come sorted: np.flatnonzero)
    total = np.zeros((len(patches), 3))
    np.add.at(total, index, colour * area[:, None])
    weight = np.bincount(index, weights=area, minlength=len(patches))
    return total / np.maximum(weight, 1e-300)[:, None]


def _interpolated(points, face, source_corners, corner_values, triangle_face):
    """Values (n,k) at each point (n,3) of face ``face`` (n,) of a quantity given at the loop
    triangles' corners (T,3,k), linear inside the triangle the point lies in (``locate``)."""
    return interpolate(*locate(points, face, source_corners, triangle_face), corner_values)


def locate(points, face, source_corners, triangle_face):
    """(triangle (n,), barycentric weights (n,3)) of each point (n,3) of face ``face`` (n,) among
    that face's loop triangles (``source_corners`` (T,3,3), ``triangle_face`` (T,) in face order):
    the one it lies in most (the largest smallest barycentric), so that a point on an edge
    between two of them takes either, which agree there."""
    first = np.searchsorted(triangle_face, face, side="left")
    count = np.searchsorted(triangle_face, face, side="right") - first
    best = np.full(len(points), -np.inf)
    triangle = np.minimum(first, max(len(triangle_face) - 1, 0))
    weights = np.zeros((len(points), 3))
    weights[:, 0] = 1.0
    for j in range(int(count.max()) if len(count) else 0):
        rows = np.flatnonzero(count > j)  # only the points whose face has a j-th triangle
        t = first[rows] + j
        w = _barycentric(points[rows], source_corners[t])
        inside = np.minimum(np.minimum(w[:, 0], w[:, 1]), w[:, 2])
        better = inside > best[rows]
        rows, t, w = rows[better], t[better], w[better]
        best[rows] = inside[better]
        triangle[rows] = t
        weights[rows] = w
    return triangle, weights


def interpolate(triangle, weights, corner_values):
    """(n,k) values at points located by ``locate``: linear in their triangle's corner values
    (T,3,k), as Blender interpolates UVs and colour attributes."""
    return np.einsum("ni,nij->nj", weights, corner_values[triangle])


def corner_layers(points, corner_verts, corner_face, source_corners, triangle_face, layers, block=1 << 18):
    """Each layer (T,3,k) of the source's loop-triangle corner values (UV maps, colour
    attributes) at every corner of a patch mesh, as float32 (C,k): ``points`` (N,3) and
    ``corner_verts`` (C,) the patch mesh's, ``corner_face`` (C,) the source face each corner's
    patch lies on. A block of corners at a time: temporaries stay a few MB whatever the mesh."""
    out = [np.empty((len(corner_verts), layer.shape[2]), np.float32) for layer in layers]
    for start in range(0, len(corner_verts), block):
        rows = slice(start, start + block)
        located = locate(points[corner_verts[rows]], corner_face[rows], source_corners, triangle_face)
        for target, layer in zip(out, layers):
            target[rows] = interpolate(*located, layer)
    return out


def _barycentric(p, triangle):
    """(n,3) barycentric coordinates of points p (n,3) in triangles (n,3,3), projected onto
    each triangle's plane."""
    a = triangle[:, 0]
    v0, v1, v2 = triangle[:, 1] - a, triangle[:, 2] - a, p - a
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731 - (a sum over 3 columns: sum(axis=1) is slow)
    d00, d01, d11, d20, d21 = dot(v0, v0), dot(v0, v1), dot(v1, v1), dot(v2, v0), dot(v2, v1)
    denominator = d00 * d11 - d01 * d01
    denominator = np.where(np.abs(denominator) > 0, denominator, 1.0)
    w1 = (d11 * d20 - d01 * d21) / denominator
    w2 = (d00 * d21 - d01 * d20) / denominator
    return np.column_stack([1.0 - w1 - w2, w1, w2])


def sample_bilinear(image, uv):
    """(n,3) the image (H,W,3, row 0 at the bottom) at UV points (n,2), bilinear with repeat
    (Blender's Linear interpolation, Repeat extension: texel centres at (i + 1/2) / W)."""
    H, W = image.shape[:2]
    x = uv[:, 0] * W - 0.5
    y = uv[:, 1] * H - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    i0, j0 = x0.astype(np.int64) % W, y0.astype(np.int64) % H
    i1, j1 = (i0 + 1) % W, (j0 + 1) % H
    return ((image[j0, i0] * (1 - fx) + image[j0, i1] * fx) * (1 - fy)
            + (image[j1, i0] * (1 - fx) + image[j1, i1] * fx) * fy)
