"""Patches of the selected objects: faces cleaned, meshed (cached per geometry) and given materials.

No bpy: reading the scene (``blender_read``) gives :class:`ObjectArrays`; :func:`make_patches` makes the
:class:`Patches` the pipeline solves, and :func:`scene_and_notes` their core scene.
"""
from __future__ import annotations

import hashlib
import threading
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from ..core import RELATIVE_DEGENERATE_AREA, PatchScene, meshing
from ..core.diagnostics import back_light, escaping_light, light_fates
from ..core.textures import patch_attribute_average, patch_texture_average
from ..options import AUTOMATIC_PATCH_DIVISIONS

#: A patch size that would make more patches than this is refused before meshing (memory and
#: time grow with the patch count: a tiny patch size could otherwise exhaust the memory).
MAX_PATCHES = 2_000_000

#: An object whose emitting faces send at least this share of their light out of the scene
#: (none of it reaching the other objects) gets a warning.
ESCAPING_WARNING = 0.9

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

    def patch_scene(self):
        """The core scene; geometry, sampling tables and the Embree scene are built once per
        geometry and reused when only materials (or estimator, target, seed) change."""
        return _GEOMETRY_CACHE.scene(self)


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
                return base.with_materials(patches.reflectivity, patches.emission, lights=patches.lights)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                scene = PatchScene(
                    patches.combined.vertices,
                    patches.combined.triangles,
                    patches.combined.triangle_patch,
                    patches.reflectivity,
                    patches.emission,
                    lights=patches.lights,
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


_GEOMETRY_CACHE = _GeometryCache()


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
        ))
    if lost:
        raise ValueError(f"{', '.join(repr(name) for name in lost)}: every face is too small to trace beside "
                         f"{_too_small(objects, threshold)}; move far objects nearer, or hide them from render")
    return kept, notes


def _too_small(objects, threshold):
    diagonal = (threshold / RELATIVE_DEGENERATE_AREA) ** 0.5
    return (f"the scene's extent (a diagonal of {diagonal:.3g}, {_extent_ends(objects)}; a face needs an area "
            f"above {RELATIVE_DEGENERATE_AREA:g} of its square, {threshold:.3g})")


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


def automatic_patch_size(objects) -> float:
    """Patch size 0's meaning: the largest extent of the selected objects' geometry over
    AUTOMATIC_PATCH_DIVISIONS (1.0 where there is no extent)."""
    used = [o.vertices[np.unique(o.triangles)] for o in objects if len(o.triangles) and o.receives]
    if not used:
        return 1.0
    used = np.vstack(used)
    extent = float(np.max(used.max(axis=0) - used.min(axis=0)))
    return extent / AUTOMATIC_PATCH_DIVISIONS if extent > 0 else 1.0


def make_patches(objects, patch_size) -> Patches:
    """Mesh every object into patches and gather per-patch materials (the meshing of an
    unchanged geometry comes from the cache). Faces of zero area are left out first, and a
    patch size that would make more than MAX_PATCHES patches is refused before any meshing.
    A patch size of 0 is automatic (:func:`automatic_patch_size`)."""
    lights = tuple(getattr(objects, "lights", ()))  # (a blender_read.selection.Selection carries them)
    check_finite_vertices(objects)
    objects, notes = drop_zero_area_faces(objects)
    if not objects:
        raise ValueError("the selected objects have no faces of non-zero area")
    if not patch_size:
        patch_size = automatic_patch_size(objects)
    count = check_patch_count(objects, patch_size)
    patches = _make_patches(objects, patch_size, count)
    patches.lights = lights
    patches.notes = notes
    patches.patch_size = float(patch_size)
    return patches


def _make_patches(objects, patch_size, count) -> Patches:
    key = _GeometryCache.key(objects, patch_size)
    cached = _GEOMETRY_CACHE.meshes(key)
    if cached is not None:
        meshes, combined = cached
        return _with_materials(objects, meshes, combined, key)
    _GEOMETRY_CACHE.make_room(count)
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
    _GEOMETRY_CACHE.store(key, meshes, combined)
    return _with_materials(objects, meshes, combined, key)


def _with_materials(objects, meshes, combined, key) -> Patches:
    materials = [patch_materials(o, m) for o, m in zip(objects, meshes)]
    reflectivity = np.concatenate([r for r, _ in materials]).reshape(-1, 3)
    emission = np.concatenate([e for _, e in materials]).reshape(-1, 3)
    return Patches([ObjectInfo.of(o) for o in objects], meshes, combined, reflectivity, emission, key)


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


def objects_of_patches(patches: Patches, indices) -> str:
    """' (objects 'A', 'B')' for the source objects of the given patch indices, or ''."""
    if indices is None or len(indices) == 0:
        return ""
    owners = np.unique(patches.combined.patch_object[np.asarray(indices, dtype=np.int64)])
    names = ", ".join(f"'{patches.objects[k].name}'" for k in owners)
    return f" (in {names})"


def scene_and_notes(patches: Patches):
    """(PatchScene, notes): the core's errors and warnings name the objects of their patches."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            scene = patches.patch_scene()
        except ValueError as exc:
            where = objects_of_patches(patches, getattr(exc, "patches", None))
            raise ValueError(f"{exc}{where}") from exc
    notes = list(patches.notes) + [
        f"{w.message}{objects_of_patches(patches, getattr(w.message, 'patches', None))}"
        for w in caught
        if issubclass(w.category, UserWarning)
    ]
    return scene, notes + escaping_sources(patches, scene) + light_notes(scene)


def light_notes(scene) -> list:
    """A note for each light none of whose light reaches the front of a face (inside a closed
    object, or a sun or sky outside a closed room), and for each that casts no shadow."""
    gathered = dict(scene.lights.gathered_only())
    notes = [f"light '{name}' {why} (as Cycles draws it): the direct light of every source is gathered by "
             "shadow rays from each patch, not shot" for name, why in gathered.items()]
    for light, (missed, back) in zip(scene.lights.lights, light_fates(scene)):
        if gathered.get(light.name) == "casts no shadow":  # its light passes through objects
            continue
        if missed + back < 0.999:  # some of it reaches the front of a face
            continue
        if type(light).__name__ in ("SunLight", "WorldLight"):
            if back > 0:
                notes.append(f"light '{light.name}': no light entered; it meets only the outside (the back) of "
                             "the faces, as a sun or sky outside a closed room: the result is dark")
            else:
                notes.append(f"light '{light.name}': none of its light reaches the selection")
        elif back >= ESCAPING_WARNING:
            notes.append(f"light '{light.name}': {back:.0%} of its light meets the back of faces; it sits inside "
                         "a closed object or behind faces")
        else:
            notes.append(f"light '{light.name}': none of its light reaches the front of a face")
    return notes


def escaping_sources(patches: Patches, scene) -> list:
    """A note for each object whose emitting faces send (almost) all their light out of the
    scene: they face away from everything else."""
    emitting, missed = escaping_light(scene)
    if not emitting.size:
        return []
    owner = patches.combined.patch_object[emitting]
    power = scene.patch_power[emitting]
    notes = []
    for k in np.unique(owner):
        share = float(np.average(missed[owner == k], weights=power[owner == k]))
        if share >= ESCAPING_WARNING:
            notes.append(f"'{patches.objects[k].name}' sends {share:.0%} of its light out of the scene: its "
                         "emitting faces point away from everything else (a new plane faces up: flip its normals "
                         "or turn it; see Overlays > Face Orientation)")
    return notes


#: Light absorbed on back sides in view of the selection above this share of the power gets a warning.
BLOCKED_WARNING = 0.05
#: The warning names this many (faces' object, source) pairs, the most light first.
BLOCKED_NAMED = 3


def source_label(patches: Patches, scene, row) -> str:
    """What emits source row ``row`` of ``scene.source_power``: "emissive faces of 'Lamp'",
    "sun 'Sun'", "world 'World'", "point light 'Bulb'"..."""
    if row < scene.patch_count:
        return f"emissive faces of '{patches.objects[patches.combined.patch_object[row]].name}'"
    light = scene.lights.lights[scene.lights.light_of[row - scene.patch_count]]
    return f"{light_kind(light)} '{light.name}'"


def light_kind(light) -> str:
    """"point light", "spot light", "area light", "sun" or "world"."""
    if type(light).__name__ == "PointLight":
        return "point light" if getattr(light, "spot", None) is None else "spot light"
    return {"AreaLight": "area light", "SunLight": "sun", "WorldLight": "world"}.get(type(light).__name__, "light")


def back_light_warning(patches: Patches, scene, blocked, seed=0):
    """The warning for light absorbed on back sides (``blocked``: the solve's measured share of
    the power), or None. core.diagnostics.back_light splits it by where it landed: only the share
    that met back sides in view of the selection counts, named by the faces' objects and the
    sources it came from; light that met back sides from outside every receiver (a sky under a
    room's floor) is no concern."""
    if blocked <= BLOCKED_WARNING:
        return None
    receives = np.array([o.receives for o in patches.objects])[patches.combined.patch_object]
    source, patch, weight, in_view = back_light(scene, receives, seed)
    advice = ("one-sided faces seen from behind, or flipped normals (see Overlays > Face Orientation; give thin "
              "walls thickness with a Solidify modifier)")
    if not weight.size:  # the check's rays found none of it: said as measured, without names
        return f"{blocked:.1%} of the light reached the back of faces and was absorbed there: {advice}"
    share = blocked * float(weight[in_view].sum() / weight.sum())
    if share <= BLOCKED_WARNING:
        return None
    owner = patches.combined.patch_object[patch[in_view]]
    # summed per (object, source row) at once; the few distinct pairs then named
    pair_rows, which = np.unique(np.stack([owner, source[in_view]]), axis=1, return_inverse=True)
    pair_weights = np.bincount(which.ravel(), weights=weight[in_view], minlength=pair_rows.shape[1])
    pairs = {}
    for (k, row), w in zip(pair_rows.T.tolist(), pair_weights.tolist()):
        key = (int(k), source_label(patches, scene, int(row)))
        pairs[key] = pairs.get(key, 0.0) + w
    total = sum(pairs.values())
    ranked = sorted(pairs.items(), key=lambda item: -item[1])
    named = [f"faces of '{patches.objects[k].name}' lit by {label} ({share * w / total:.1%})"
             for (k, label), w in ranked[:BLOCKED_NAMED]]
    more = f" and {len(ranked) - BLOCKED_NAMED} more" if len(ranked) > BLOCKED_NAMED else ""
    return (f"{share:.1%} of the light reached the back of faces in view of the selection and was absorbed there: "
            f"{', '.join(named)}{more}; {advice}")
