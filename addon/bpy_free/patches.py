"""Patches of the selected objects: faces cleaned (``cleaning``), meshed (cached per geometry)
and given materials.

No bpy: reading the scene (``blender_read``) gives :class:`ObjectArrays`; :func:`make_patches` makes the
:class:`Patches` the pipeline solves, and ``scene_notes.scene_and_notes`` their core scene.
"""
from __future__ import annotations

import hashlib
import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from ..core import PatchScene
from ..core.mesh import meshing
from ..core.materials.textures import patch_attribute_average, patch_texture_average
from .options import AUTOMATIC_PATCH_DIVISIONS
from .surface_layers import SourceLayers, result_layers
from .cleaning import check_finite_vertices, degenerate_area, drop_zero_area_faces

#: A patch size that would make more patches than this is refused before meshing (memory and
#: time grow with the patch count: a tiny patch size could otherwise exhaust the memory).
MAX_PATCHES = 2_000_000

#: The rest of the scene (objects that block and reflect but get no results) is meshed this
#: many times coarser than the selection.
OTHERS_COARSER = 4.0


def object_patch_size(o, patch_size) -> float:
    """The patch size an object is meshed at: the selection's, or coarser for the rest of the scene."""
    return patch_size if o.receives else patch_size * OTHERS_COARSER


@dataclass
class ObjectArrays:
    """One source object, read from Blender, world space, outward winding."""

    name: str
    vertices: np.ndarray  # (V,3) float64
    face_sizes: np.ndarray  # (F,) int32 or int64 (blender_read: int32, as Blender's)
    corner_verts: np.ndarray  # (C,) int32 or int64
    triangles: np.ndarray  # (T,3) int32 or int64, Blender's loop triangles (vertex indices)
    triangle_face: np.ndarray  # (T,) int32 or int64
    face_reflectivity: np.ndarray  # (F,3) float64 in [0, 1) (blender_read: a broadcast row for one material)
    face_emission: np.ndarray  # (F,3) float64 >= 0, emission colour x strength
    uid: int | None = None  # the source object's session_uid (to find it again)
    face_slot: np.ndarray | None = None  # (F,) material slot of each face
    slot_names: tuple = ()  # material name of each slot
    receives: bool = True  # selected: gets results; else an object of the rest of the scene (blocks, reflects)
    triangle_uv: np.ndarray | None = None  # (T,3,2) UVs of the loop triangles' corners (textured objects)
    slot_textures: tuple = ()  # per slot: (pixels (H,W,3) linear, affine (2,3), UV map) or None
    slot_colours: tuple = ()   # per slot: (T,3,3) colour attribute at the loop triangles' corners, or None
    slot_emission_textures: tuple = ()  # per slot: (pixels, affine, UV map, strength) or None
    layers: SourceLayers | None = None  # UV maps and colour attributes the result keeps (selected objects)
    lightgroup: str = ""  # the object's Blender light group ("": none)
    face_glossy: np.ndarray | None = None  # (F,4) the glossy lobe's share (3) and alpha (core.glossy); None: none
    later: object = None  # blender_read: what gives the material fields above their values (objects.with_materials)


@dataclass(frozen=True)
class ObjectInfo:
    """What the patches keep of a source object once meshed: its arrays are not needed again."""

    name: str
    uid: int | None
    receives: bool

    @classmethod
    def of(cls, o: ObjectArrays):
        return cls(o.name, o.uid, o.receives)


@dataclass
class Patches:
    """The patch meshes of the source objects and their PatchScene arrays."""

    objects: list  # ObjectInfo of each source object (name, uid, receives), in patch order
    meshes: list  # meshing.PatchMesh, one per object
    combined: meshing.CombinedPatches
    reflectivity: np.ndarray  # (P,3)
    emission: np.ndarray  # (P,3)
    geometry_key: str | None = None  # fingerprint of the meshed geometry (see _GeometryCache)
    notes: list = field(default_factory=list)  # what reading the geometry left out, for the user
    patch_size: float = 0.0  # the size meshed with (an automatic size resolved)
    lights: tuple = ()  # the core's light sources (blender_read.selection.Selection.lights)
    light_labels: tuple = ()  # each light's light group, or None (Selection.light_labels)
    # (P,) int32: each patch's face's material in ``material_names``; each object's light group ("": none)
    patch_material: np.ndarray | None = None
    material_names: tuple = ()
    object_lightgroups: tuple = ()
    # per object, ResultLayers of a receiving object (make_patches(..., layers=True)), else None
    layers: list = field(default_factory=list)
    refinement: list = field(default_factory=list)  # the Detail setting's steps (adaptive_patches), if any
    cells: list | None = None  # the Detail's core.adaptive Cells per object (further splits), if any
    glossy: tuple | None = None  # (share (P,3), alpha (P,)) of the glossy lobe (core.glossy), or None

    def patch_scene(self):
        """The core scene; geometry, sampling tables and the Embree scene are built once per
        geometry and reused when only materials (or estimator, target, seed) change."""
        return GEOMETRY_CACHE.scene(self)


class _GeometryCache:
    """The last few meshed geometries and their core scenes, keyed by a fingerprint of the
    objects' arrays and the patch size: the panel's estimate and a re-run neither re-mesh
    nor rebuild the ray tracer."""

    size = 2
    # Older geometries stay only while all the entries, a new one included, have at most this
    # many patches: a big scene's meshes, arrays and Embree scene are not kept beside another's.
    max_patches = 1 << 19

    def __init__(self):
        self._entries = OrderedDict()  # key -> {"meshes", "combined", "scene", "warnings"}
        self._lock = threading.Lock()

    @staticmethod
    def key(objects, patch_size):
        digest = hashlib.blake2b(digest_size=16)
        digest.update(np.float64(patch_size).tobytes())
        for o in objects:
            digest.update(b"r" if o.receives else b"o")
            for array in (o.vertices, o.face_sizes, o.corner_verts, o.triangles, o.triangle_face):
                array = np.ascontiguousarray(array)
                digest.update(f"{array.dtype}{array.shape}".encode())
                digest.update(array.tobytes())
        return digest.hexdigest()

    def meshes(self, key):
        with self._lock:
            entry = self._entries.get(key)
            if entry is not None:
                self._entries.move_to_end(key)
                return entry["meshes"], entry["combined"]
        return None

    def make_room(self, patch_count):
        """Forget the oldest geometries until ``patch_count`` more patches fit in max_patches
        (before meshing a new geometry, so that the old ones are not held while it is made)."""
        with self._lock:
            while self._entries and self._patches() + patch_count > self.max_patches:
                self._entries.popitem(last=False)

    def _patches(self):
        return sum(entry["combined"].patch_count for entry in self._entries.values())

    def store(self, key, meshes, combined):
        with self._lock:
            self._entries[key] = {"meshes": meshes, "combined": combined, "scene": None, "warnings": []}
            while len(self._entries) > self.size or (len(self._entries) > 1 and self._patches() > self.max_patches):
                self._entries.popitem(last=False)

    def scene(self, patches):
        with self._lock:
            entry = self._entries.get(patches.geometry_key)
            base = entry["scene"] if entry is not None else None
            if base is not None and base.patch_count == patches.combined.patch_count:
                for message in entry["warnings"]:  # what building it said, said again
                    warnings.warn(message, stacklevel=2)  # the Warning itself: keeps its .patches
                return base.with_materials(patches.reflectivity, patches.emission, lights=patches.lights,
                                           glossy=patches.glossy)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                scene = PatchScene(
                    patches.combined.vertices,
                    patches.combined.triangles,
                    patches.combined.triangle_patch,
                    patches.reflectivity,
                    patches.emission,
                    lights=patches.lights,
                    glossy=patches.glossy,
                    hidden=covered_flags(patches),
                )
            for w in caught:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            if entry is not None:
                entry["scene"] = scene
                entry["warnings"] = [w.message for w in caught if issubclass(w.category, UserWarning)]
            return scene

    def clear(self):
        with self._lock:
            self._entries.clear()


GEOMETRY_CACHE = _GeometryCache()


def covered_flags(patches: Patches):
    """(P,) bool the patches under a near surface (the outline split's ``covered`` on each mesh it
    made: ``adaptive_patches.covered``), or None where none is."""
    flags = [getattr(m, "covered", None) for m in patches.meshes]
    if not any(f is not None and np.any(f) for f in flags):
        return None
    return np.concatenate([np.zeros(m.patch_count, bool) if f is None else np.asarray(f, bool) for m, f in zip(patches.meshes, flags)])


def patch_count(objects, patch_size) -> float:
    """How many patches ``meshing.mesh_patches`` makes of these objects at this patch size,
    counted without meshing (``meshing.count_patches``; a float, so that absurd counts do not
    overflow)."""
    min_area = degenerate_area(objects)
    return sum(
        meshing.count_patches(
            o.vertices, o.face_sizes, o.corner_verts, object_patch_size(o, patch_size), o.triangles, o.triangle_face,
            min_area,
        )
        for o in objects
        if len(o.face_sizes)
    )


def check_patch_count(objects, patch_size, limit=None):
    """ValueError, suggesting a larger patch size, when the patch size would make more than
    ``limit`` (default MAX_PATCHES) patches; returns the count otherwise."""
    limit = MAX_PATCHES if limit is None else limit
    count = patch_count(objects, patch_size)
    if count <= limit:
        return count
    suggested = float(patch_size) * max(1.0, (count / limit) ** 0.5)
    for _ in range(64):  # the count falls as the size grows: a few steps up to a size that fits
        suggested = float(f"{suggested:.2g}")
        if patch_count(objects, suggested) <= limit:
            break
        suggested *= 1.25
    raise ValueError(
        f"A patch size of {float(patch_size):.3g} would make {count:,.0f} patches, more than the limit of "
        f"{limit:,} (memory and time grow with the patch count). Use a larger patch size "
        f"({suggested:.2g} or more)"
    )


class NothingToSolve(ValueError):
    """The selection has no face with an area: no light to compute, no result to write."""


def automatic_patch_size(objects) -> float:
    """Patch size 0's meaning: the largest extent of the selected objects' geometry over
    AUTOMATIC_PATCH_DIVISIONS (1.0 where there is no extent)."""
    used = [o.vertices[np.unique(o.triangles)] for o in objects if len(o.triangles) and o.receives]
    if not used:
        return 1.0
    used = np.vstack(used)
    extent = float(np.max(used.max(axis=0) - used.min(axis=0)))
    return extent / AUTOMATIC_PATCH_DIVISIONS if extent > 0 else 1.0


def make_patches(objects, patch_size, layers=False) -> Patches:
    """Mesh every object into patches and gather per-patch materials (the meshing of an
    unchanged geometry comes from the cache). Faces of zero area are left out first, and a
    patch size that would make more than MAX_PATCHES patches is refused before any meshing.
    A patch size of 0 is automatic (:func:`automatic_patch_size`). With ``layers``, also the
    receiving objects' UV maps and colour attributes at the patch corners (``result_layers``)."""
    lights = tuple(getattr(objects, "lights", ()))  # (a blender_read.selection.Selection carries them)
    light_labels = tuple(getattr(objects, "light_labels", None) or (None,) * len(lights))
    check_finite_vertices(objects)
    selected = [o.name for o in objects if o.receives]
    objects, notes = drop_zero_area_faces(objects)
    if not any(o.receives for o in objects):  # (the rest of the scene alone: no result to write)
        raise NothingToSolve(f"nothing to solve: the selected objects ({', '.join(map(repr, selected))}) "
                             "have no faces of non-zero area")
    if not patch_size:
        patch_size = automatic_patch_size(objects)
    count = check_patch_count(objects, patch_size)
    patches = _make_patches(objects, patch_size, count)
    if layers:
        patches.layers = [result_layers(o, m) if o.receives else None for o, m in zip(objects, patches.meshes)]
    patches.lights = lights
    patches.light_labels = light_labels
    patches.notes = notes
    patches.patch_size = float(patch_size)
    return patches


def _make_patches(objects, patch_size, count) -> Patches:
    key = _GeometryCache.key(objects, patch_size)
    cached = GEOMETRY_CACHE.meshes(key)
    if cached is not None:
        meshes, combined = cached
        return _with_materials(objects, meshes, combined, key)
    GEOMETRY_CACHE.make_room(count)
    min_area = degenerate_area(objects)  # the scene's: what the core drops, across all objects
    meshes = [
        meshing.mesh_patches(
            o.vertices,
            o.face_sizes,
            o.corner_verts,
            object_patch_size(o, patch_size),
            face_triangles=o.triangles,
            triangle_face=o.triangle_face,
            min_area=min_area,
        )
        for o in objects
    ]
    combined = meshing.concatenate(meshes)
    if combined.patch_count == 0:
        raise ValueError("the selected objects have no faces")
    GEOMETRY_CACHE.store(key, meshes, combined)
    return _with_materials(objects, meshes, combined, key)


def _with_materials(objects, meshes, combined, key) -> Patches:
    materials = [patch_materials(o, m) for o, m in zip(objects, meshes)]
    reflectivity = np.concatenate([r for r, _ in materials]).reshape(-1, 3)
    emission = np.concatenate([e for _, e in materials]).reshape(-1, 3)
    out = Patches([ObjectInfo.of(o) for o in objects], meshes, combined, reflectivity, emission, key)
    out.glossy = glossy_of_patches(objects, meshes)
    names = {}
    out.patch_material = np.concatenate([material_of_patches(o, m, names) for o, m in zip(objects, meshes)])
    out.material_names, out.object_lightgroups = tuple(names), tuple(o.lightgroup for o in objects)
    return out


def glossy_of_patches(objects, meshes):
    """(share (P,3), alpha (P,)) of every patch's glossy lobe, its face's; None where none has one."""
    if all(o.face_glossy is None for o in objects):
        return None
    none = np.array([0.0, 0.0, 0.0, 1.0])
    rows = np.concatenate([(np.broadcast_to(none, (m.patch_count, 4)) if o.face_glossy is None
                            else o.face_glossy[m.patch_face]) for o, m in zip(objects, meshes)])
    return (rows[:, :3], rows[:, 3]) if rows[:, :3].any() else None


def material_of_patches(o, mesh, names):
    """(P,) int32: the material of each patch of ``o`` (its object's name without one) as its
    place in ``names`` (a dict, added to)."""
    if o.face_slot is None or not len(o.slot_names):
        return np.full(mesh.patch_count, names.setdefault(o.name, len(names)), np.int32)
    ids = np.array([names.setdefault(n or o.name, len(names)) for n in o.slot_names], dtype=np.int32)
    return ids[np.asarray(o.face_slot)[mesh.patch_face]]


def patch_materials(o, mesh):
    """(reflectivity (P,3), emission (P,3)) of each patch of object ``o``: its face's, or where
    its material reads an image texture (through the UV map) or a colour attribute, their mean
    over the patch's own footprint (core.textures)."""
    reflectivity = o.face_reflectivity[mesh.patch_face]
    emission = o.face_emission[mesh.patch_face]
    if o.face_slot is None:
        return reflectivity, emission
    per_slot = [(reflectivity, o.slot_colours, lambda c, p: patch_attribute_average(mesh, p, corners(), c, o.triangle_face))]
    if o.triangle_uv is not None:
        per_slot += [(reflectivity, o.slot_textures, lambda t, p: image(t, p)),
                     (emission, o.slot_emission_textures, lambda t, p: t[3] * image(t, p))]
    if not any(source is not None for _, sources, _ in per_slot for source in sources):
        return reflectivity, emission  # one value a face: no (T,3,3) corners nor per-slot passes
    slot_of_patch = o.face_slot[mesh.patch_face]
    made = []

    def corners():
        if not made:
            made.append(o.vertices[o.triangles])
        return made[0]

    def image(texture, patches):
        return patch_texture_average(mesh, patches, corners(), o.triangle_uv, o.triangle_face, *texture[:2])

    for target, sources, average in per_slot:
        for slot, source in enumerate(sources):
            patches = np.flatnonzero(slot_of_patch == slot) if source is not None else ()
            if len(patches):
                target[patches] = average(source, patches)
    return reflectivity, emission
