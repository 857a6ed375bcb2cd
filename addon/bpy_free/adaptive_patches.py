"""The Detail setting: a solve's patches refined where the direct light changes (core.adaptive),
before any walk, with their materials and result layers made again for the refined meshes."""
from __future__ import annotations

import hashlib
import pickle
import threading
import time
from dataclasses import replace

import numpy as np

from ..core.mesh import meshing
from ..core.refine.adaptive import patch_mesh, shading_triangulation
from ..core.refine.adaptive_light import DETAILS, refine_by_direct_light
from ..core.refine.covered_parts import covered_split
from . import patches as patches_module
from .cleaning import drop_zero_area_faces
from .patches import MAX_PATCHES, Patches, GEOMETRY_CACHE, glossy_of_patches, material_of_patches, patch_materials
from .surface_layers import result_layers

# Solves that refine the mesh after the direct light's refinement, at most (0: none; solve_refinement);
# one measured best at equal time (docs/adaptive.md): a second cost its time and splits noise
ROUNDS = 1

OFF = "OFF"


class _Last:
    """The last refinement (the estimate's, reused by the run that follows it)."""

    def __init__(self):
        self.key = None
        self.value = None
        self.lock = threading.Lock()


_LAST = _Last()


def _key(patches, detail, seed):
    digest = hashlib.blake2b(digest_size=16)
    digest.update(f"{patches.geometry_key}|{detail}|{DETAILS.get(detail)}|{seed}".encode())
    digest.update(np.ascontiguousarray(patches.emission).tobytes())
    digest.update(pickle.dumps(tuple(patches.lights)))
    return digest.hexdigest()


def refined(objects, patches: Patches, detail: str, seed: int = 0, layers=False, should_stop=None) -> Patches:
    """``patches`` (make_patches' of ``objects``) with the receiving objects' patches split where
    their direct light changes, as far as ``detail`` (OFF, LOW, MEDIUM, HIGH) says; the same
    Patches where nothing splits. The steps taken are in ``.refinement``. At OFF only the
    patches a near surface partly covers split, along its outline (``covered``)."""
    if detail == OFF:
        return covered(objects, patches, layers)
    key = _key(patches, detail, seed)
    with _LAST.lock:
        cached = _LAST.value if _LAST.key == key else None
    if cached is None:
        started = time.perf_counter()
        result = refine_by_direct_light(patches.meshes, patches.patch_scene(), DETAILS[detail], int(seed),
                                        receives=[o.receives for o in patches.objects], should_stop=should_stop)
        cached = (result, time.perf_counter() - started)
        if not result.stopped:  # (a refinement cut short is not the one these settings make)
            with _LAST.lock:
                _LAST.key, _LAST.value = key, cached
    result, _ = cached
    first = patches.combined.patch_count
    steps = [dict(s, first=first, budget=int(DETAILS[detail].budget * first)) for s in result.steps]
    if sum(m.patch_count for m in result.meshes) == patches.combined.patch_count:
        return replace(patches, refinement=steps, cells=result.cells)
    return of_cells(objects, patches, result.cells, key + ":refined", steps, layers, detail)


def covered(objects, patches: Patches, layers=False) -> Patches:
    """``patches`` with the patches a near surface partly covers split along its outline (core
    refine.covered_parts: a light panel just under a ceiling), the same Patches where none is;
    the objects not split keep their meshes as they were (the display's own cells split them).
    Each mesh keeps its patches' side of the outline as ``covered`` (``patches.covered_flags``)."""
    key = f"{patches.geometry_key}:covered"  # (the geometry's alone: no seed, no light)
    with _LAST.lock:
        cached = _LAST.value if _LAST.key == key else None
    if cached is None:
        cached = (covered_split(patches.meshes, patches.combined, [o.receives for o in patches.objects]), 0.0)
        with _LAST.lock:
            _LAST.key, _LAST.value = key, cached
    split, _ = cached
    # (a refinement of the light's accuracy, not needed: never past the patch limit the meshing kept to)
    if split is None or sum(c.count for c in split.cells) > patches_module.MAX_PATCHES:
        return patches
    out = of_cells(objects, patches, split.cells, key, [], layers, "", keep_unsplit=True)
    for mesh, flags in zip(out.meshes, split.covered):
        mesh.covered = flags  # (one patch a cell, in cell order)
    return replace(out, cells=None)


def of_cells(objects, patches: Patches, cells, geometry_key, steps, layers=False, detail="", keep_unsplit=False) -> Patches:
    """``patches`` (make_patches' of ``objects``, or refined ones) on the conforming meshes of
    ``cells`` (core.adaptive, one per object), their materials and result layers made again;
    ``keep_unsplit``: an object none of whose cells split keeps its plain mesh (no shading
    triangulation of its own: the display's cells may split it)."""
    objects, _ = drop_zero_area_faces(objects)  # (as make_patches read them: the same faces)
    # The key names these cells: meshes made for it before are these (kept with their core scene,
    # which a re-run then reuses instead of building its arrays and Embree scenes again).
    cached = GEOMETRY_CACHE.meshes(geometry_key)
    if cached is not None:
        meshes, combined = cached
    else:
        meshes = [_copy(patch_mesh(c)[0], not (keep_unsplit and c.level.max(initial=0) == 0)) for c in cells]
        combined = meshing.concatenate(meshes)
    if combined.patch_count > MAX_PATCHES:
        raise ValueError(f"Detail {detail.lower()} would make {combined.patch_count:,} patches, more than the "
                         f"limit of {MAX_PATCHES:,}: use a larger patch size or a lower detail")
    if cached is None:
        GEOMETRY_CACHE.store(geometry_key, meshes, combined)
    materials = [_unsplit_materials(patches, k, c) or patch_materials(o, m) for k, (o, m, c) in enumerate(zip(objects, meshes, cells))]
    reflectivity = np.concatenate([r for r, _ in materials]).reshape(-1, 3)
    emission = np.concatenate([e for _, e in materials]).reshape(-1, 3)
    names = {n: i for i, n in enumerate(patches.material_names)}  # (per-light groups read each patch's)
    patch_material = np.concatenate([material_of_patches(o, m, names) for o, m in zip(objects, meshes)])
    out = replace(patches, meshes=meshes, combined=combined, reflectivity=reflectivity, emission=emission,
                  geometry_key=geometry_key, refinement=steps, patch_material=patch_material,
                  material_names=tuple(names), cells=list(cells), glossy=glossy_of_patches(objects, meshes))
    if layers:
        out.layers = [result_layers(o, m) if o.receives else None for o, m in zip(objects, meshes)]
    else:
        out.layers = []
    return out


def refinement_text(patches: Patches) -> str:
    """What refinement did and may do, for the estimate's patch line, e.g. "refined from 4,782 in
    2 steps (0.5 s), at most 11,955 after a refining solve" ("" without refinement)."""
    steps = getattr(patches, "refinement", None)
    if not steps:
        return ""
    seconds = sum(s["seconds"] for s in steps)
    text = (f"refined from {steps[0]['first']:,} in {len(steps)} step{'s' if len(steps) > 1 else ''} ({seconds:.1f} s), "
            f"at most {steps[0]['budget']:,}")
    solved = any(s.get("solve") for s in steps)
    if not ROUNDS or solved:
        return text
    return text + (" after a refining solve" if ROUNDS == 1 else f" after up to {ROUNDS} refining solves")


def _unsplit_materials(patches: Patches, k, cells):
    """(reflectivity, emission) of object ``k``'s patches where none of its ``cells`` split (the
    first patches, in order): the first patches' own, not read again (a texture's mean over each
    patch's footprint is most of a material's reading); else None."""
    first = patches.meshes[k].patch_count
    if len(cells.level) != first or cells.level.max(initial=0) > 0 or not np.array_equal(cells.origin, np.arange(first)):
        return None
    rows = patches.combined.patch_slice(k)
    return patches.reflectivity[rows].copy(), patches.emission[rows].copy()


def _copy(mesh, shading=True):
    """A PatchMesh of its own (concatenate makes a mesh share the combined arrays), ``shading`` kept."""
    out = meshing.PatchMesh(mesh.points, mesh.face_sizes, mesh.corner_verts, mesh.patch_face, mesh.triangles,
                            mesh.triangle_patch, mesh.patch_area)
    if shading:
        out.shading_triangles, out.shading_triangle_patch = shading_triangulation(mesh)
    return out


def shading_arrays(patches: Patches, scene):
    """(triangles, patch of each) of the scene's points the smooth colours are made on: refined
    meshes' polygons with every corner (their midpoints: no T-junction, no seam); None where no
    mesh is refined (the scene's own)."""
    if not any(getattr(m, "shading_triangles", None) is not None for m in patches.meshes):
        return None
    vertex = np.cumsum([0] + [len(m.points) for m in patches.meshes])
    patch = patches.combined.patch_offsets
    triangles, triangle_patch = [], []
    for k, m in enumerate(patches.meshes):
        t, tp = shading_triangulation(m)
        triangles.append(np.asarray(t, np.int64) + vertex[k])
        triangle_patch.append(np.asarray(tp, np.int64) + patch[k])
    return np.concatenate(triangles).astype(np.int32), np.concatenate(triangle_patch).astype(np.int32)
