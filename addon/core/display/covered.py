"""Patches no camera sees: buried whole inside another object, or covered by a surface lying
against them.

The smooth colours join, at each corner, the patches that meet there. A patch that gets no light
because something lies against it (the ceiling behind a light panel hung 1 cm under it, the floor
under a box or a rug) would pull its visible neighbours' corners towards black: a dark rim around
the panel and, as each neighbour keeps its mean, ripples beyond it. Such patches are left out of
their neighbours' corners (``smoothing.Surface``'s ``hidden``); their own values stay as solved.

A patch is covered when the ray from its middle along its normal meets the back of a surface
within COVER_SHARE of the patch's side (a panel facing away from it, a rug's underside; a table
top a patch's width above the floor is not). A patch whose ray meets a back side farther off is
hidden when the near-grazing probes of ``visibility`` meet back sides first too (the floor under
a box with no bottom, whose patches nothing crosses; under a one-sided table top they escape),
or buried whole as ``visibility`` found it.

A patch partly buried shows its visible part only, and its light is its mean over that part: the
smooth colours hold that mean (``smoothing.Surface``'s ``visible``, from ``visible_corner_weights``),
not the mean over the whole patch, which would hand the buried part its share of a slope and leave
the part seen too dark where the light climbs toward the buried edge (a cove beside a lamp).
"""
from __future__ import annotations

import numpy as np

from ..scene.rays import meets_front
from ..mesh.faces import triangle_areas
from ..lights.sampling import patch_point_rows
from ..materials.textures import locate
from ..scene.visibility import PROBES, tangents

COVER_SHARE = 1.0  # of the patch's side
BLOCK = 1 << 17  # visible cells located at a time (visible_corner_weights)


def seen_parts(scene, triangles, triangle_patch):
    """``smoothing.Surface.of``'s ``hidden`` and ``visible`` for ``triangles`` (T,3) of the scene's
    vertices and their patches (the module's docstring)."""
    g = scene.geometry
    return dict(hidden=hidden_patches(g), visible=visible_corner_weights(g, scene.vertices, triangles, triangle_patch))


def visible_corner_weights(geometry, vertices, triangles, triangle_patch):
    """(T,3) what each corner weighs in its patch's mean over the visible part: the integral, over
    the part of its triangle seen, of the corner's barycentric coordinate (a third of the area on
    patches wholly seen); None where no patch is partly buried. On a partly buried patch, each
    visible cell's centre (``visibility.Buried``) carries its share of the visible area to the
    corners of the triangle it lies in, by its barycentric coordinates."""
    b = geometry.buried
    if b is None or not b.patch.size:
        return None
    vertices, triangles, triangle_patch = np.asarray(vertices, np.float64), np.asarray(triangles), np.asarray(triangle_patch)
    area = triangle_areas(vertices, triangles)
    weight = np.repeat(area[:, None] / 3.0, 3, axis=1)
    partly = np.flatnonzero(b.slot[triangle_patch] >= 0)
    weight[partly] = 0.0
    rows = partly[np.argsort(triangle_patch[partly], kind="stable")]
    share = np.bincount(triangle_patch, weights=area, minlength=len(b.slot))[b.patch] * b.fraction / np.diff(b.first)
    ends = np.searchsorted(b.first, np.arange(BLOCK, b.first[-1], BLOCK))  # (the cells a block of patches at a time)
    for block in np.split(np.arange(b.patch.size), np.unique(ends)):
        count = np.diff(b.first)[block]
        patch = np.repeat(b.patch[block], count).astype(np.int64)
        rank = np.arange(patch.size) - np.repeat(np.cumsum(count) - count, count)
        u0 = ((rank + 0.5) / np.repeat(count, count)).astype(np.float32)  # (the remap's k-th visible cell, its middle)
        half = np.full(patch.size, 0.5, np.float32)
        points = geometry.to_world(patch_point_rows(geometry, patch, half.copy(), u0, half.copy()).T, patch)
        # (the triangle of its patch each lies in, as a texture's points are found in their face's)
        triangle, bary = locate(points, patch, vertices[triangles[rows]], triangle_patch[rows])
        for k in range(3):
            weight[:, k] += np.bincount(rows[triangle], weights=np.repeat(share[block], count) * bary[:, k],
                                        minlength=len(weight))
    return weight


def hidden_patches(geometry):
    """(P,) bool: the patches buried whole or covered (the module's docstring)."""
    g = geometry
    P = len(g.patch_area)
    hidden = np.zeros(P, bool)
    if g.buried is not None:
        hidden[g.buried.whole] = True
    patch = np.arange(P, dtype=np.int64)
    half = np.full(P, 0.5, np.float32)
    origins = patch_point_rows(g, patch, half.astype(np.float64), half, half.copy())  # (pushed off its patch)
    normal = g.patch_normal_rows.astype(np.float64)
    back, t = _meets_back(g, origins, normal, patch)
    near = COVER_SHARE * np.sqrt(g.patch_area) / g.diagonal  # (unit space)
    hidden |= back & (t < near)
    rows = np.flatnonzero(back & ~hidden)
    tangent, bitangent = tangents(normal[:, rows])
    for theta, phi in PROBES[1:]:
        if not rows.size:
            break
        s, c = np.sin(np.radians(theta)), np.cos(np.radians(theta))
        d = c * normal[:, rows] + s * (np.cos(np.radians(phi)) * tangent + np.sin(np.radians(phi)) * bitangent)
        keep = _meets_back(g, origins[:, rows], d, rows)[0]
        rows, tangent, bitangent = rows[keep], tangent[:, keep], bitangent[:, keep]
    hidden[rows] = True
    return hidden


def _meets_back(g, origins, directions, patch):
    """((n,) bool: the first surface met is seen from behind, (n,) its distance, unit space) for
    rays (3,n) from points of ``patch``."""
    d = np.ascontiguousarray(directions.T, np.float32)
    hit, _, _, t, hit_normal = g.surface_tracer.first_hit_barycentric(np.ascontiguousarray(origins.T, np.float32), d,
                                                                      g.region_of(patch))
    return (hit >= 0) & ~meets_front(d.T, hit_normal), t
