"""Closed boxes of axis-aligned rectangular patches, with exact form factors.

Used as analytic references: every patch of a closed box sees every non-coplanar patch whole,
so the contour-integral form factors are exact.
"""
import numpy as np

from addon.core import PatchScene
from addon.core.estimate.reference import rectangle_form_factors

# Six faces of the box [0,sx]x[0,sy]x[0,sz] as (origin, u, v) in units of the size, with
# u x v pointing into the box: floor, ceiling, x=0, x=sx, y=0, y=sy.
FACES = (
    ((0, 0, 0), (1, 0, 0), (0, 1, 0)),
    ((0, 0, 1), (0, 1, 0), (1, 0, 0)),
    ((0, 0, 0), (0, 1, 0), (0, 0, 1)),
    ((1, 0, 0), (0, 0, 1), (0, 1, 0)),
    ((0, 0, 0), (0, 0, 1), (1, 0, 0)),
    ((0, 1, 0), (1, 0, 0), (0, 0, 1)),
)
FLOOR, CEILING, LEFT, RIGHT, FRONT, BACK = range(6)


def box_rectangles(size=(1.0, 1.0, 1.0), n=1, offset=(0.0, 0.0, 0.0), scale=1.0):
    """Patch rectangles (origin, u, v) and face index of each: n x n patches on every face."""
    size = np.asarray(size, dtype=np.float64) * scale
    origins, us, vs, face_of = [], [], [], []
    for face, (o, u, v) in enumerate(FACES):
        o, u, v = (np.asarray(x, np.float64) * size for x in (o, u, v))
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        i, j = i.ravel(), j.ravel()
        origins.append(o + np.outer(i, u / n) + np.outer(j, v / n))
        us.append(np.tile(u / n, (n * n, 1)))
        vs.append(np.tile(v / n, (n * n, 1)))
        face_of.append(np.full(n * n, face))
    origin = np.concatenate(origins) + np.asarray(offset, np.float64)
    return origin, np.concatenate(us), np.concatenate(vs), np.concatenate(face_of)


def rectangles_to_mesh(origin, u, v):
    """Two triangles per rectangle, wound so the normal is u x v."""
    P = origin.shape[0]
    corners = np.stack([origin, origin + u, origin + u + v, origin + v], axis=1).reshape(-1, 3)
    base = 4 * np.arange(P)[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    triangle_patch = np.repeat(np.arange(P), 2)
    return corners, triangles, triangle_patch


def box_scene(reflectivity_by_face, emission_by_face, size=(1.0, 1.0, 1.0), n=1, offset=(0, 0, 0), scale=1.0):
    """PatchScene of a closed box and its exact form factors F (P,P)."""
    origin, u, v, face = box_rectangles(size, n, offset, scale)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    R = np.asarray(reflectivity_by_face, np.float64)[face]
    E = np.asarray(emission_by_face, np.float64)[face]
    scene = PatchScene(vertices, triangles, triangle_patch, R, E)
    return scene, rectangle_form_factors(origin, u, v), face


def small_source_box(n=8, reflectivity=0.8, corner=False):
    """A closed unit box of n x n patches a face, every patch of reflectivity R, lit by one
    ceiling patch of emittance 1 (1/n^2 of the ceiling), at its middle or in a corner.
    (PatchScene, F)."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    emission = np.zeros(origin.shape[0])
    ceiling = np.flatnonzero(face == CEILING).reshape(n, n)
    emission[ceiling[0, 0] if corner else ceiling[n // 2, n // 2]] = 1.0
    scene = PatchScene(vertices, triangles, triangle_patch, np.full(origin.shape[0], reflectivity), emission)
    return scene, rectangle_form_factors(origin, u, v)


def spot_box(degrees, n=16, reflectivity=0.6, soft_falloff=False, radius=0.1, size=(4.0, 3.0, 2.5)):
    """A closed 4 x 3 x 2.5 room of n x n patches a face lit only by a spot lamp of a cone of
    ``degrees`` (Blender's spot size; blend 0.15) and ``radius``, 5 cm under the middle of the
    ceiling (above a corner of four floor patches), aimed down. PatchScene."""
    import math

    from addon.core.lights.lights import PointLight, Spot

    origin, u, v, _ = box_rectangles(size, n)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    cos_outer = math.cos(math.radians(degrees) / 2)
    spot = Spot(np.array([0.0, 0.0, -1.0]), cos_outer, cos_outer + 0.15 * (1 - cos_outer))
    lamp = PointLight(np.array([size[0] / 2, size[1] / 2, size[2] - 0.05]), np.full(3, 100.0), radius=radius, spot=spot,
                      name="Spot", soft_falloff=soft_falloff)
    P = origin.shape[0]
    return PatchScene(vertices, triangles, triangle_patch, np.full(P, reflectivity), np.zeros(P), lights=[lamp])


def colour_box():
    """A closed box of 4 x 4 patches a face, each face its own colour, the ceiling emitting 1.
    (PatchScene, F)."""
    R = [(0.9,) * 3, (0.2,) * 3, (0.8, 0.3, 0.1), (0.1, 0.7, 0.3), (0.85,) * 3, (0.3, 0.3, 0.6)]
    E = [(0, 0, 0), (1, 1, 1)] + [(0, 0, 0)] * 4
    scene, F, _ = box_scene(R, E, n=4)
    return scene, F


def grey_room():
    """A closed 1 x 1.4 x 0.8 room of 8 x 8 patches a face, R 0.5, the ceiling emitting 1. (PatchScene, F)."""
    scene, F, _ = box_scene([(0.5,) * 3] * 6, [(0, 0, 0), (1, 1, 1)] + [(0, 0, 0)] * 4, (1.0, 1.4, 0.8), n=8)
    return scene, F


def bright_box():
    """Reflectivity 0.95 everywhere, the whole ceiling emitting: long paths, and at 10% short runs.
    (PatchScene, F)."""
    scene, F, _ = box_scene([(0.95,) * 3] * 6, [(0, 0, 0), (1, 1, 1)] + [(0, 0, 0)] * 4, n=6)
    return scene, F


def open_box_with_card(reflectivity=0.6):
    """A unit box open at the top (n = 2) with a card facing down at half height, which rays
    from above hit from behind; the first 4 patches (the floor) emit 1: rays escape and are
    blocked. PatchScene."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    keep = face != CEILING
    origin = np.vstack([origin[keep], [[0.3, 0.3, 0.5]]])
    u, v = np.vstack([u[keep], [[0, 0.4, 0]]]), np.vstack([v[keep], [[0.4, 0, 0]]])
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    emission = np.zeros(P)
    emission[:4] = 1.0
    return PatchScene(vertices, triangles, triangle_patch, np.full(P, reflectivity), emission)


def rays_to_triangle_points(g, rng, n, powers=(4, 13)):
    """n rays (unit space, float32 origins and directions) from near the origin to points of
    random triangles of Geometry ``g``, half of them on or next to an edge: one barycentric
    coordinate 0 (a fifth of those) or 10^-k, k in range(*powers). Returns (o, d, bary, target)."""
    triangle = rng.integers(0, g.triangle_count, n)
    bary = rng.dirichlet((1.0, 1.0, 1.0), n)
    m = n // 2
    tiny = np.where(rng.random(m) < 0.2, 0.0, 10.0 ** -rng.integers(*powers, m))
    side = rng.integers(0, 3, m)
    rest = bary[:m].copy()
    rest[np.arange(m), side] = 0
    rest *= ((1 - tiny) / rest.sum(axis=1))[:, None]
    rest[np.arange(m), side] = tiny
    bary[:m] = rest
    target = np.einsum("nk,nkj->nj", bary, g.triangle_corners[triangle].astype(np.float64))
    o = (0.05 * rng.uniform(-1, 1, (n, 3))).astype(np.float32)
    return o, (target - o).astype(np.float32), bary, target
