"""The meshes the display is written on: the solve's patches, or their cells split where the direct
light changes (core refine.display_cells), with what each output needs made for them: the direct light at
their corners, the source's layers at their polygon corners, per-patch values per polygon."""
from __future__ import annotations

import time
from dataclasses import replace
from functools import partial

import numpy as np

from ..core.display import direct_means, point_direct, smoothing
from ..core.refine import cell_meshes, display_cells
from ..core.display.covered import seen_parts
from ..core.mesh.faces import polygon_corner_rows
from ..core.relight.relighting import group_direct
from ..core.distributed.runners import in_background, local_thread_count

TIME_SHARE = 0.5  # of the time left before a deadline the new points may take (the rest: the smoothing, the writing)
NEW_POINT_RETRIES = 1  # a new point's noisy light sampled again once (8x the samples), a corner's twice
SEED_STEP = 7919  # the seed of each level's new points, apart from the corners' and each other's


def surface_of(scene, shading=None):
    """The smoothing surface of the solve's shading triangles (``shading``: (triangles, patch of each),
    else the scene's)."""
    triangles, triangle_patch = shading if shading is not None else (scene.triangles, scene.triangle_patch)
    # (the patches under a cover kept apart from the rest, as at a crease: the gap's light stays in the gap)
    return smoothing.Surface.of(scene.vertices, triangles, triangle_patch, scene.patch_count,
                                covered=scene.hidden, **seen_parts(scene, triangles, triangle_patch))


def display_beside(out, scene, result, shading=None, deadline=None, refine=True, surface=None):
    """A callable giving ``display``'s (surface, direct light at its corners) and setting ``out.shown``:
    traced from now on a thread of its own where the local threads are two or more
    (``threads.in_background``; the caller makes what reads neither meanwhile on the other,
    ``threads.beside``), else when called."""
    def traced():
        return display(out, scene, result, shading, deadline, refine, surface)

    # (a scene without direct light has no shadow rays to trace beside)
    future = in_background(traced) if local_thread_count() > 1 and point_direct.has_direct(scene) else None

    def made():
        surface_made, direct, out.shown = traced() if future is None else future.result()
        return surface_made, direct

    made.beside = future is not None  # (the caller's work meanwhile on one thread: threads.beside)
    return made


def display(out, scene, result, shading=None, deadline=None, refine=True, surface=None):
    """(the smoothing surface, the direct light at its corners (``point_direct.CornerDirect``, each
    source group's for a per-source run), Shown or None) the colours are made on: the solve's
    shading triangles (``surface``: their ``surface_of``, made here if not given), their cells split
    where ``refine`` and the direct light say so (``out.shown``)."""
    triangles, triangle_patch = shading if shading is not None else (scene.triangles, scene.triangle_patch)
    surface = surface_of(scene, shading) if surface is None else surface
    grouped = out.sources_out is not None
    started = time.perf_counter()
    direct = (group_direct(surface, scene, result, triangles, deadline) if grouped else
              point_direct.corner_direct(surface, scene, triangles, seed=result.seed, deadline=deadline,
                                         light=result.irradiance))
    if direct is None or not refine:
        return surface, direct, None
    each = (time.perf_counter() - started) / max(2 * len(triangles), 1)  # (a corner's time: about 2 a triangle)
    most = None
    if deadline is not None:  # (new points as many as half the time left takes, at the corners' rate)
        most = int(TIME_SHARE * max(deadline - time.perf_counter(), 0.0) / max(each, 1e-9))
    ps = result.per_source if grouped else None

    def at_points(position, patch, level):
        groups = dict(light_group=ps.light_group, patch_group=ps.patch_group, groups=ps.count) if grouped else {}
        # (one retry, not two: new points are where the light changes, beside emitters too, where every point
        # would take them all; a count, not a time: the same seed, the same colours)
        return point_direct.points_direct(surface, scene, position, patch, seed=int(result.seed) + SEED_STEP * (level + 1),
                                          deadline=deadline, light=result.irradiance, retries=NEW_POINT_RETRIES, **groups)

    made = display_cells.refine(surface, direct, scene, triangles, out.patches.meshes, [o.receives for o in out.patches.objects],
                                result.irradiance, at_points, most, surface.covered,
                                direct_means.corner_sources_means(scene, result))
    return (surface, direct, None) if made is None else made


def mesh_of(out, k):
    """The PatchMesh object ``k``'s result is written on."""
    shown = getattr(out, "shown", None)
    return out.patches.meshes[k] if shown is None else shown.meshes[k]


def per_polygon(out, k, values):
    """Object ``k``'s per-patch ``values`` ([S,]P_k,3) per polygon of the mesh it is written on."""
    shown = getattr(out, "shown", None)
    return values if shown is None or values is None else shown.per_polygon(k, values)


def polygon_corners(out, scene, corners, shading=None, least=None):
    """Per object (None: not receiving), the values (C_k,3) at its written mesh's polygon corners, read from
    the triangle corners (T,3,3) of the Shown, else of ``shading`` (triangles, patch of each) or the scene's,
    as float32 clipped to at least ``least``; which corner each reads found once a run (``out.corner_rows``)."""
    if out.corner_rows is None:
        out.corner_rows = _corner_rows(out, scene, shading)
    flat = np.asarray(corners).reshape(-1, np.asarray(corners).shape[-1])
    return [None if rows is None else flat[rows].astype(np.float32).clip(least, np.inf) for rows in out.corner_rows]


def _corner_rows(out, scene, shading):
    """Per object (None: not receiving), the triangle corner each polygon corner of its written mesh reads."""
    patches, shown = out.patches, getattr(out, "shown", None)
    if shown is not None:
        triangles, triangle_patch, starts = shown.triangles, shown.triangle_patch, shown.point_starts
    else:
        triangles, triangle_patch = shading if shading is not None else (scene.triangles, scene.triangle_patch)
        starts = np.cumsum([0] + [len(mesh.points) for mesh in patches.meshes])
    rows = []
    for k, o in enumerate(patches.objects):
        if not o.receives:  # the rest of the scene: no results
            rows.append(None)
            continue
        offset = patches.combined.patch_offsets[k]
        mesh = mesh_of(out, k)
        corner_patch = shown.corner_patch(k, offset) if shown is not None else mesh.corner_patch + offset
        rows.append(polygon_corner_rows(triangles, triangle_patch, corner_patch, mesh.corner_verts + starts[k]))
    return rows


def layers_on(out):
    """The source layers of each object (``patches.layers``) at its written mesh's polygon corners."""
    layers, shown = out.patches.layers, getattr(out, "shown", None)
    if shown is None or not layers:
        return layers
    made = []
    for k, kept in enumerate(layers):
        if kept is None or shown.origin[k] is None:
            made.append(kept)
            continue
        corners, weights = cell_meshes.corner_weights(out.patches.meshes[k], shown.meshes[k], shown.origin[k])
        mixed = partial(_mixed, corners=corners, weights=weights)
        normals = None if kept.normals is None else mixed(kept.normals)
        if normals is not None:
            normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
        made.append(replace(kept, uv=tuple((name, mixed(v)) for name, v in kept.uv),
                            colours=tuple((name, mixed(v)) for name, v in kept.colours), normals=normals,
                            patch_slot=np.asarray(kept.patch_slot)[shown.origin[k]]))
    return made


def _mixed(values, corners, weights):
    """(C',k) per fine polygon corner, of per coarse polygon corner ``values`` (C,k)."""
    values = np.asarray(values)
    out = values[corners[:, 0]] * weights[:, 0, None]
    for j in (1, 2):
        out += values[corners[:, j]] * weights[:, j, None]
    return out.astype(values.dtype)


def let_go(out):
    """Drops what only the colours needed (the shown triangles, the polygon corners' rows) once they are
    made: the meshes written and each polygon's patch stay (a preview renders beside them)."""
    out.corner_rows = None
    if getattr(out, "shown", None) is not None:
        out.shown = replace(out.shown, vertices=None, triangles=None, triangle_patch=None)
