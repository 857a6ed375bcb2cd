"""Faces cleaned before meshing: faces of no area at the core's tolerance left out (and said
so), vertices that are not finite refused, naming the objects (no bpy)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..core import RELATIVE_DEGENERATE_AREA
from ..core.mesh import meshing


def degenerate_area(objects) -> float:
    """The core's degenerate-triangle area for the scene these objects make: triangles of this
    area or less are dropped by the core (RELATIVE_DEGENERATE_AREA x the squared diagonal of the
    vertices the triangles use). The meshing gets it too, so that the faces it cuts into
    triangles (non-planar ones) never make a patch of dropped triangles only."""
    used = [o.vertices[np.unique(o.triangles)] for o in objects if len(o.triangles)]
    if not used:
        return 0.0
    used = np.vstack(used)
    diagonal = float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
    return RELATIVE_DEGENERATE_AREA * diagonal**2


def check_finite_vertices(objects):
    """ValueError naming the first object whose faces use a vertex that is NaN or infinite
    (a script, a driver, a modifier): the scene's extent, and every area, would be NaN."""
    for o in objects:
        if np.isfinite(o.vertices).all():
            continue
        used = np.unique(o.triangles)
        bad = int(np.count_nonzero(~np.isfinite(o.vertices[used]).all(axis=1)))
        if bad:
            hint = " (its location, rotation or scale?)" if bad == used.size else ""
            raise ValueError(f"'{o.name}': {bad} of the {used.size} vertices its faces use "
                             f"{'is' if bad == 1 else 'are'} not a finite number (NaN or infinite){hint}")


def _extent_ends(objects):
    """'from 'A' to 'B'': the objects at both ends of the scene's widest side."""
    boxes = [(o.name, o.vertices[np.unique(o.triangles)]) for o in objects if len(o.triangles)]
    lo = np.array([v.min(axis=0) for _, v in boxes])
    hi = np.array([v.max(axis=0) for _, v in boxes])
    axis = int(np.argmax(hi.max(axis=0) - lo.min(axis=0)))
    return f"from '{boxes[int(np.argmin(lo[:, axis]))][0]}' to '{boxes[int(np.argmax(hi[:, axis]))][0]}'"


def drop_zero_area_faces(objects):
    """(objects, notes): faces with no area at the core's tolerance left out, objects left
    without faces skipped. Such faces (collinear or coincident corners, common in imported
    meshes) are invisible, and a patch made of them only would make the core refuse the scene.
    Faces with an area of their own that the scene's extent makes too small to trace are said
    so; a selected object left with none of its faces that way is a ValueError."""
    if not any(len(o.triangles) for o in objects):
        return [], [f"'{o.name}': every face has zero area; the object was skipped" for o in objects]
    threshold = degenerate_area(objects)
    kept, notes, lost = [], [], []
    for o in objects:
        F = len(o.face_sizes)
        area = meshing.triangle_areas(o.vertices, o.triangles) if len(o.triangles) else np.zeros(0)
        face_area = np.bincount(o.triangle_face, weights=np.where(area > threshold, area, 0.0), minlength=F)
        flat = face_area <= 0
        if not flat.any():
            kept.append(o)
            continue
        own = degenerate_area([o])  # the same tolerance with the object's own extent
        real = np.bincount(o.triangle_face, weights=np.where(area > own, area, 0.0), minlength=F) > 0
        small = int(np.count_nonzero(flat & real))
        if small:
            if flat.all() and o.receives:
                lost.append(o.name)
            notes.append(f"'{o.name}': {small} face{' is' if small == 1 else 's are'} too small to trace beside "
                         f"{_too_small(objects, threshold)}: {'the object was skipped' if flat.all() else 'left out'}")
        count = int(flat.sum()) - small
        if flat.all():
            if not small:
                notes.append(f"'{o.name}': every face has zero area; the object was skipped")
            continue
        if count:
            notes.append(f"'{o.name}': {count} face{'s' if count > 1 else ''} of zero area "
                         "(collinear or coincident corners) left out")
        keep = ~flat
        corner_face = np.repeat(np.arange(F), o.face_sizes)
        new_index = np.cumsum(keep) - 1
        keep_triangle = keep[o.triangle_face]
        kept.append(replace(
            o,
            face_sizes=o.face_sizes[keep],
            corner_verts=o.corner_verts[keep[corner_face]],
            triangles=o.triangles[keep_triangle],
            triangle_face=new_index[o.triangle_face[keep_triangle]],
            face_reflectivity=o.face_reflectivity[keep],
            face_emission=o.face_emission[keep],
            triangle_uv=None if o.triangle_uv is None else o.triangle_uv[keep_triangle],
            slot_colours=tuple(None if c is None else c[keep_triangle] for c in o.slot_colours),
            face_slot=None if o.face_slot is None else o.face_slot[keep],
            layers=None if o.layers is None else o.layers.taken(keep_triangle),
        ))
    if lost:
        raise ValueError(f"{', '.join(repr(name) for name in lost)}: every face is too small to trace beside "
                         f"{_too_small(objects, threshold)}; move far objects nearer, or hide them from render")
    return kept, notes


def _too_small(objects, threshold):
    diagonal = (threshold / RELATIVE_DEGENERATE_AREA) ** 0.5
    return (f"the scene's extent (a diagonal of {diagonal:.3g}, {_extent_ends(objects)}; a face needs an area "
            f"above {RELATIVE_DEGENERATE_AREA:g} of its square, {threshold:.3g})")

