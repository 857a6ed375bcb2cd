"""Rooms modelled as artists do: thick slabs that run into each other at every edge.

The room's inside is the unit cube. Each of its six walls is a closed box (a slab of
THICKNESS) whose inner face runs past the cube's edges into the neighbouring slabs. The reaches
differ by slab and direction (no two faces coplanar and overlapping), and are chosen so that
every part of an inner face outside the cube lies inside a neighbour (no notch open to the
outside). Each inner face is a grid of patches whose middle lines fall on the cube's edges: the
edge patches are half (corners a quarter) inside the neighbours, their border on a visibility
cell line, so the visible part of every inner patch is an exact rectangle, known in closed form.
"""
import numpy as np

from addon.core import PatchScene
from boxes import rectangles_to_mesh

THICKNESS = 0.3
# REACH[a][k]: how far the slab across axis a runs past the cube along axis k; a reach of 0.25
# takes 3 patches along that axis (0.5 each), 0.125 takes 5 (0.25 each): the cube's edges fall
# on the middle lines of the edge patches.
REACH = ({1: 0.25, 2: 0.125}, {0: 0.125, 2: 0.25}, {0: 0.25, 1: 0.125})
PATCHES = {0.25: 3, 0.125: 5}


def solid_box(lower, upper, divisions):
    """Rectangles (origin, u, v) of the six faces of the box [lower, upper], normals outward,
    ``divisions[k]`` patches along axis k, and (6*...,) the face index (axis*2 + (upper side))."""
    lower, upper = np.asarray(lower, np.float64), np.asarray(upper, np.float64)
    origins, us, vs, faces = [], [], [], []
    for axis in range(3):
        a, b = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, 1):
            first, second = (a, b) if side else (b, a)  # u x v along +axis on the upper side
            o = lower.copy()
            if side:
                o[axis] = upper[axis]
            n1, n2 = divisions[first], divisions[second]
            step1 = np.zeros(3)
            step1[first] = (upper[first] - lower[first]) / n1
            step2 = np.zeros(3)
            step2[second] = (upper[second] - lower[second]) / n2
            i, j = np.meshgrid(np.arange(n1), np.arange(n2), indexing="ij")
            origins.append(o + np.outer(i.ravel(), step1) + np.outer(j.ravel(), step2))
            us.append(np.tile(step1, (n1 * n2, 1)))
            vs.append(np.tile(step2, (n1 * n2, 1)))
            faces.append(np.full(n1 * n2, 2 * axis + side))
    return np.concatenate(origins), np.concatenate(us), np.concatenate(vs), np.concatenate(faces)


def slab_room(overlap=True):
    """The six slabs' patches: (origin, u, v) (P,3) each and (P,) bool whether a patch is on an
    inner face. ``overlap=False``: the same room with the slabs cut at the cube's edges (they meet
    without running into each other), the same patch grid inside."""
    origins, us, vs, inner = [], [], [], []
    t = THICKNESS
    for axis in range(3):
        for side in (0, 1):
            lower, upper, divisions = np.zeros(3), np.ones(3), [1, 1, 1]
            for k, reach in REACH[axis].items():
                if overlap:
                    lower[k], upper[k] = -reach, 1.0 + reach
                    divisions[k] = PATCHES[reach]
                else:
                    divisions[k] = PATCHES[reach] - 1
            lower[axis], upper[axis] = (-t, 0.0) if side == 0 else (1.0, 1.0 + t)
            o, u, v, face = solid_box(lower, upper, divisions)
            origins.append(o)
            us.append(u)
            vs.append(v)
            inner.append(face == 2 * axis + (1 - side))  # the face towards the cube
    return np.concatenate(origins), np.concatenate(us), np.concatenate(vs), np.concatenate(inner)


def visible_rectangles(origin, u, v):
    """The parts of rectangles inside the unit cube's faces (clipped to [0, 1] on each axis)."""
    lo = np.minimum(origin, origin + u + v).clip(0, 1)
    hi = np.maximum(origin, origin + u + v).clip(0, 1)
    vo = origin.copy()
    vu, vv = u.copy(), v.copy()
    for k in range(3):
        moving_u, moving_v = u[:, k] != 0, v[:, k] != 0
        vo[:, k] = np.where(moving_u | moving_v, lo[:, k], origin[:, k])
        vu[:, k] = np.where(moving_u, hi[:, k] - lo[:, k], 0.0)
        vv[:, k] = np.where(moving_v, hi[:, k] - lo[:, k], 0.0)
    return vo, vu, vv


def slab_scene(reflectivity, emission, overlap=True):
    """PatchScene of the slab room; reflectivity and emission are (P,) arrays or callables of
    the inner mask. Returns (scene, origin, u, v, inner)."""
    origin, u, v, inner = slab_room(overlap)
    R = reflectivity(inner) if callable(reflectivity) else np.full(origin.shape[0], reflectivity)
    E = emission(inner) if callable(emission) else np.full(origin.shape[0], emission)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    return PatchScene(vertices, triangles, triangle_patch, R, E), origin, u, v, inner
