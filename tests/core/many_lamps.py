"""A room lit by many lamps (point, sphere, spot and area lamps under its ceiling), as the
pipeline's object arrays (``room_objects``) or as a core scene (``room_scene``): the time limit's,
the prediction's and the corner pass's case of a lamp count that grows."""
from __future__ import annotations

import numpy as np

from addon.core import PatchScene
from addon.core.lights.lights import AreaLight, PointLight, Spot

ROOM = np.array([6.0, 5.0, 3.0])
# furniture: (low corner, high corner), boxes standing on the floor
FURNITURE = [((1.0, 1.0, 0.0), (2.6, 2.0, 0.8)), ((4.4, 3.6, 0.0), (5.6, 4.8, 2.2)), ((0.4, 3.8, 0.0), (1.4, 4.6, 1.0))]


class Selection(list):
    """Object arrays with the lights that go with them (as ``blender_read.selection.Selection``)."""

    lights = ()
    light_labels = None


def _box_quads(low, high, inward):
    """(8,3) corners and (6,4) quads of the box, wound to face in (a room) or out."""
    lo, hi = np.asarray(low, float), np.asarray(high, float)
    corners = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    # (outward winding: counter-clockwise seen from outside)
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])
    return corners, quads[:, ::-1] if inward else quads


def _object(name, boxes, inward, reflectivity):
    from addon.bpy_free.patches import ObjectArrays

    vertices, faces = [], []
    for low, high in boxes:
        corners, quads = _box_quads(low, high, inward)
        faces.append(quads + 8 * len(vertices))
        vertices.append(corners)
    vertices, faces = np.concatenate(vertices), np.concatenate(faces)
    F = len(faces)
    triangles = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
    return ObjectArrays(name=name, vertices=vertices, face_sizes=np.full(F, 4), corner_verts=faces.ravel(),
                        triangles=triangles, triangle_face=np.concatenate([np.arange(F), np.arange(F)]),
                        face_reflectivity=np.full((F, 3), reflectivity), face_emission=np.zeros((F, 3)))


KINDS = ("point", "sphere", "spot", "area")


def lamps(count, seed=0, power=2000.0, kinds=KINDS, grey=False):
    """``count`` lamps under the ceiling, of ``kinds`` in turn (a quarter each point, sphere,
    spot and area lamps), at random places, of random colours (``grey``: white), of ``power`` in
    all (radiosity units times area)."""
    rng = np.random.default_rng(seed)
    out = []
    each = power / max(count, 1)
    for k in range(count):
        at = rng.uniform([0.3, 0.3, 1.6], ROOM - [0.3, 0.3, 0.2])
        colour = np.ones(3) if grey else rng.uniform(0.6, 1.0, 3)
        kind = KINDS.index(kinds[k % len(kinds)])
        if kind == 0:
            out.append(PointLight(at, colour * each / (4 * np.pi), name=f"Point {k}"))
        elif kind == 1:
            out.append(PointLight(at, colour * each / (4 * np.pi), radius=0.05, name=f"Sphere {k}"))
        elif kind == 2:
            axis = np.array([rng.uniform(-0.3, 0.3), rng.uniform(-0.3, 0.3), -1.0])
            spot = Spot(axis / np.linalg.norm(axis), np.cos(np.radians(35.0)), np.cos(np.radians(28.0)))
            out.append(PointLight(at, colour * each / (4 * np.pi), spot=spot, name=f"Spot {k}"))
        else:
            half = rng.uniform(0.05, 0.2)
            out.append(AreaLight(at, np.array([half, 0.0, 0.0]), np.array([0.0, half, 0.0]), np.array([0.0, 0.0, -1.0]),
                                 colour * each / (4 * half * half), name=f"Area {k}"))
    return out


def room_objects(count, seed=0, furniture=True, **kinds):
    """The room (its inside faces) and its furniture (or none: nothing between a lamp and a
    face), selected, with ``count`` lamps (``kinds``: ``lamps``' keywords)."""
    objects = Selection([_object("Room", [((0.0, 0.0, 0.0), tuple(ROOM))], True, 0.6)])
    if furniture:
        objects.append(_object("Furniture", FURNITURE, False, 0.4))
    objects.lights = tuple(lamps(count, seed, **kinds))
    return objects


def room_scene(count, patch_size=0.5, seed=0, furniture=True, **kinds):
    """The room as a core PatchScene of ``patch_size`` patches, lit by ``count`` lamps."""
    from addon.bpy_free.patches import make_patches
    from addon.bpy_free.scene_notes import scene_and_notes

    return scene_and_notes(make_patches(room_objects(count, seed, furniture, **kinds), patch_size))[0]
