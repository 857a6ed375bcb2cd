"""The polygons of split cells: a cell's corners and the midpoints its neighbours put on its edges.

A cell of ``refine.adaptive`` (a quad or a triangle) whose edges carry its finer neighbours'
midpoints is written as one polygon, every midpoint a corner (collinear with the two beside it),
so that the mesh has no T-junction. :func:`pattern` gives, for each kind of cell (its corner count
and which edges carry a midpoint), the polygon's corners and the core's own triangles of it (no
triangle of zero area), and starts the polygon where Blender's own triangulation of it, which the
viewport draws, has none either (BLENDER_START).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

# The corner each split polygon (corner count, bits of the edges with a midpoint) starts at, so
# that Blender's own triangulation of it, which the viewport draws, has no triangle of zero area
# along a collinear edge (a GPU draws such a sliver with wild interpolated colours: specks in
# EEVEE). Blender splits a 4-corner polygon on its 0-2 diagonal and ear-clips larger ones in an
# order its start decides; these starts were found by search over Blender's triangulation of
# thousands of shapes of random size and orientation (tests/blender/test_adaptive.py checks them).
# A quad with midpoints on two opposite edges (bits 5 and 10) has none: every start leaves a
# sliver on about 45% of rotated shapes.
BLENDER_START = {(3, 1): 1, (3, 2): 2, (3, 4): 3, (3, 6): 1, (4, 2): 1, (4, 4): 2, (4, 6): 1, (4, 7): 2,
                 (4, 9): 2, (4, 12): 2, (4, 13): 5, (4, 14): 1, (4, 15): 2}


@lru_cache(maxsize=None)
def pattern(corner_count, mask):
    """(polygon, triangles) of a cell of ``corner_count`` corners whose edges numbered in the
    bits of ``mask`` carry a midpoint: the polygon's corners as local indices (2k: corner k,
    2k+1: the midpoint of edge k), and its triangles (t,3) as positions in the polygon, made by
    clipping corners whose triangle has an area (greedy, largest smallest angle first)."""
    if corner_count == 4:
        ideal = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    else:
        ideal = np.array([[0, 0], [1, 0], [0.5, 0.8660254037844386]], float)
    polygon, xy = [], []
    for k in range(corner_count):
        polygon.append(2 * k)
        xy.append(ideal[k])
        if mask >> k & 1:
            polygon.append(2 * k + 1)
            xy.append(0.5 * (ideal[k] + ideal[(k + 1) % corner_count]))
    xy = np.array(xy)
    alive, triangles = list(range(len(polygon))), []
    if mask == 0:  # the meshing's own fan
        return tuple(polygon), np.array([(0, k + 1, k + 2) for k in range(corner_count - 2)], np.int64)
    while len(alive) > 3:
        best, best_angle = None, -1.0
        for i in range(len(alive)):
            p, v, n = alive[i - 1], alive[i], alive[(i + 1) % len(alive)]
            e1, e2 = xy[p] - xy[v], xy[n] - xy[v]
            area = e1[0] * e2[1] - e1[1] * e2[0]
            if abs(area) < 1e-9:
                continue
            rest = [xy[j] for j in alive if j != v]
            if _collinear(rest):
                continue
            angle = _smallest_angle(xy[p], xy[v], xy[n])
            if angle > best_angle + 1e-12:
                best, best_angle = i, angle
        v = alive[best]
        triangles.append((alive[best - 1], v, alive[(best + 1) % len(alive)]))
        alive.pop(best)
    triangles.append(tuple(alive))
    # the polygon written from where Blender's triangles all have area; its own triangles the same
    start = BLENDER_START.get((corner_count, mask), 0)
    return tuple(polygon[start:] + polygon[:start]), (np.array(triangles, np.int64) - start) % len(polygon)


def _collinear(points):
    a = points[0]
    return all(abs((p[0] - a[0]) * (q[1] - a[1]) - (p[1] - a[1]) * (q[0] - a[0])) < 1e-9
               for p in points[1:] for q in points[1:])


def _smallest_angle(a, b, c):
    def angle(p, q, r):
        u, v = q - p, r - p
        return np.arccos(np.clip(u @ v / (np.linalg.norm(u) * np.linalg.norm(v)), -1, 1))
    return min(angle(a, b, c), angle(b, c, a), angle(c, a, b))
