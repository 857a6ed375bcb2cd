"""The solve, as numpy arrays in and numpy arrays out, and the thread that runs it.

Nothing here imports bpy: the main thread reads the Blender scene into
:class:`ObjectArrays` (see ``scene_io``), a :class:`SolveJob` meshes, solves
and averages in a worker thread, and the main thread writes the result.
"""

from __future__ import annotations

import atexit
import hashlib
import threading
import time
import warnings
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from .core import meshing

#: With "Clamp bright colours" on, reflectivity above this is lowered to it (the random walks
#: need R < 1; without the setting, a base colour of 1 or more is refused).
MAX_REFLECTIVITY = 0.99

#: A patch size that would make more patches than this is refused before meshing (memory and
#: time grow with the patch count: a tiny patch size could otherwise exhaust the memory).
MAX_PATCHES = 2_000_000


@dataclass
class ObjectArrays:
    """One source object, read from Blender, world space, outward winding."""

    name: str
    vertices: np.ndarray  # (V,3) float64
    face_sizes: np.ndarray  # (F,) int64
    corner_verts: np.ndarray  # (C,) int64
    triangles: np.ndarray  # (T,3) int64, Blender's loop triangles (vertex indices)
    triangle_face: np.ndarray  # (T,) int64
    face_reflectivity: np.ndarray  # (F,3) float64 in [0, 1)
    face_emission: np.ndarray  # (F,3) float64 >= 0, emission colour x strength
    uid: int | None = None  # the source object's session_uid (to find it again)
    face_slot: np.ndarray | None = None  # (F,) material slot of each face
    slot_names: tuple = ()  # material name of each slot


@dataclass
class SolveSettings:
    estimator: str = "finite"  # "finite" | "biased_infinite"
    threshold: float = 1e-3
    relative_rms: float = 0.05  # error target as a fraction of the mean reflected radiosity
    paths: int | None = None  # fixed path count instead of the error target
    patch_size: float = 0.5
    exit_point: str = "random"  # "random" | "hit"
    sampling: str = "independent"  # "independent" (the paper's) | "stratified"
    stop_rule: str = "predicted"  # "predicted" (formula paths) | "measured" (batch error estimate)
    seed: int = 0
    max_seconds: float | None = None
    threads: int | None = None
    output: str = "FACE"  # "FACE" | "VERTEX" | "BOTH"


@dataclass
class Patches:
    """The patch meshes of the source objects and their PatchScene arrays."""

    objects: list  # ObjectArrays
    meshes: list  # meshing.PatchMesh, one per object
    combined: meshing.CombinedPatches
    reflectivity: np.ndarray  # (P,3)
    emission: np.ndarray  # (P,3)
    geometry_key: str | None = None  # fingerprint of the meshed geometry (see _GeometryCache)
    notes: list = field(default_factory=list)  # what reading the geometry left out, for the user

    def patch_scene(self):
        """The core scene; geometry, sampling tables and the Embree scene are built once per
        geometry and reused when only materials (or estimator, target, seed) change."""
        return _GEOMETRY_CACHE.scene(self)


class _GeometryCache:
    """The last few meshed geometries and their core scenes, keyed by a fingerprint of the
    objects' arrays and the patch size: the panel's estimate and a re-run neither re-mesh
    nor rebuild the ray tracer."""

    size = 2

    def __init__(self):
        self._entries = OrderedDict()  # key -> {"meshes", "combined", "scene", "warnings"}
        self._lock = threading.Lock()

    @staticmethod
    def key(objects, patch_size):
        digest = hashlib.blake2b(digest_size=16)
        digest.update(np.float64(patch_size).tobytes())
        for o in objects:
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

    def store(self, key, meshes, combined):
        with self._lock:
            self._entries[key] = {"meshes": meshes, "combined": combined, "scene": None, "warnings": []}
            while len(self._entries) > self.size:
                self._entries.popitem(last=False)

    def scene(self, patches):
        from .core import PatchScene

        with self._lock:
            entry = self._entries.get(patches.geometry_key)
            base = entry["scene"] if entry is not None else None
            if base is not None and base.patch_count == patches.combined.patch_count:
                for message in entry["warnings"]:  # what building it said, said again
                    warnings.warn(message, stacklevel=2)  # the Warning itself: keeps its .patches
                return base.with_materials(patches.reflectivity, patches.emission)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                scene = PatchScene(
                    patches.combined.vertices,
                    patches.combined.triangles,
                    patches.combined.triangle_patch,
                    patches.reflectivity,
                    patches.emission,
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


@dataclass
class SolveOutput:
    patches: Patches
    result: object  # core SolveResult
    prediction: object  # core Prediction for the run's settings
    target_mse: float | None
    face_colours: list = field(default_factory=list)  # (P_k,3) per object
    point_colours: list = field(default_factory=list)  # (N_k,3) per object, or None
    notes: list = field(default_factory=list)  # the core's warnings, for the user

    def blocked_fraction(self):
        """Share of the emitted power absorbed on the back side of faces."""
        energy = self.result.energy
        if not energy:
            return 0.0
        emitted = float(np.sum(energy["emitted"]))
        return float(np.sum(energy["blocked"])) / emitted if emitted > 0 else 0.0


def degenerate_area(objects) -> float:
    """The core's degenerate-triangle area for the scene these objects make: triangles of this
    area or less are dropped by the core (RELATIVE_DEGENERATE_AREA x the squared diagonal of the
    vertices the triangles use). The meshing gets it too, so that the faces it cuts into
    triangles (non-planar ones) never make a patch of dropped triangles only."""
    from .core import RELATIVE_DEGENERATE_AREA

    used = [o.vertices[np.unique(o.triangles)] for o in objects if len(o.triangles)]
    if not used:
        return 0.0
    used = np.vstack(used)
    diagonal = float(np.linalg.norm(used.max(axis=0) - used.min(axis=0)))
    return RELATIVE_DEGENERATE_AREA * diagonal**2


def drop_zero_area_faces(objects):
    """(objects, notes): faces with no area at the core's tolerance left out, objects left
    without faces skipped. Such faces (collinear or coincident corners, common in imported
    meshes) are invisible, and a patch made of them only would make the core refuse the scene."""
    if not any(len(o.triangles) for o in objects):
        return [], [f"'{o.name}': every face has zero area; the object was skipped" for o in objects]
    threshold = degenerate_area(objects)
    kept, notes = [], []
    for o in objects:
        F = len(o.face_sizes)
        area = meshing.triangle_areas(o.vertices, o.triangles) if len(o.triangles) else np.zeros(0)
        face_area = np.bincount(o.triangle_face, weights=np.where(area > threshold, area, 0.0), minlength=F)
        flat = face_area <= 0
        if not flat.any():
            kept.append(o)
            continue
        if flat.all():
            notes.append(f"'{o.name}': every face has zero area; the object was skipped")
            continue
        count = int(flat.sum())
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
            face_slot=None if o.face_slot is None else o.face_slot[keep],
        ))
    return kept, notes


def patch_count(objects, patch_size) -> float:
    """How many patches ``meshing.mesh_patches`` makes of these objects at this patch size,
    counted without meshing (``meshing.count_patches``; a float, so that absurd counts do not
    overflow)."""
    min_area = degenerate_area(objects)
    return sum(
        meshing.count_patches(
            o.vertices, o.face_sizes, o.corner_verts, patch_size, o.triangles, o.triangle_face, min_area
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


def make_patches(objects, patch_size) -> Patches:
    """Mesh every object into patches and gather per-patch materials (the meshing of an
    unchanged geometry comes from the cache). Faces of zero area are left out first, and a
    patch size that would make more than MAX_PATCHES patches is refused before any meshing."""
    objects, notes = drop_zero_area_faces(objects)
    if not objects:
        raise ValueError("the selected objects have no faces of non-zero area")
    check_patch_count(objects, patch_size)
    patches = _make_patches(objects, patch_size)
    patches.notes = notes
    return patches


def _make_patches(objects, patch_size) -> Patches:
    key = _GeometryCache.key(objects, patch_size)
    cached = _GEOMETRY_CACHE.meshes(key)
    if cached is not None:
        meshes, combined = cached
        return _with_materials(objects, meshes, combined, key)
    min_area = degenerate_area(objects)  # the scene's: what the core drops, across all objects
    meshes = [
        meshing.mesh_patches(
            o.vertices,
            o.face_sizes,
            o.corner_verts,
            patch_size,
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
    reflectivity = np.concatenate(
        [o.face_reflectivity[m.patch_face] for o, m in zip(objects, meshes)]
    ).reshape(-1, 3)
    emission = np.concatenate(
        [o.face_emission[m.patch_face] for o, m in zip(objects, meshes)]
    ).reshape(-1, 3)
    return Patches(list(objects), meshes, combined, reflectivity, emission, key)


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
    return scene, notes


def prediction_for(scene, settings: SolveSettings):
    """(prediction, target_mse) of the core for these settings, no tracing."""
    from .core import predict, relative_rms_to_mse

    base = predict(scene, settings.estimator, threshold=settings.threshold)
    if settings.paths:
        return predict(scene, settings.estimator, threshold=settings.threshold, paths=int(settings.paths)), None
    target = relative_rms_to_mse(base, settings.relative_rms)
    return predict(scene, settings.estimator, threshold=settings.threshold, target_mse=target), target


def estimate(objects, settings: SolveSettings) -> dict:
    """What the panel shows before a run: sizes and the paper's predictions."""
    from .core import predict

    patches = make_patches(objects, settings.patch_size)
    scene, _ = scene_and_notes(patches)
    p, target = prediction_for(scene, settings)
    other = "biased_infinite" if settings.estimator == "finite" else "finite"
    return {
        "objects": len(objects),
        "patches": int(scene.patch_count),
        "paths": int(p.paths),
        "rays": float(p.expected_rays),
        "path_length": float(p.expected_path_length),
        "R_ave": float(p.R_ave),
        "relative_efficiency": float(predict(scene, "biased_infinite", threshold=settings.threshold).relative_efficiency),
        "target_mse": target,
        "predicted_mse": float(p.predicted_mse),
        "other_estimator": other,
    }


def run_solve(objects, settings: SolveSettings, progress=None, should_stop=None, on_prediction=None) -> SolveOutput:
    """Mesh, solve and compute the colours to write, for the given objects.

    ``on_prediction(prediction, patch_count)`` is called once the patches
    are known, before the first path.
    """
    from .core import solve

    patches = make_patches(objects, settings.patch_size)
    scene, notes = scene_and_notes(patches)
    prediction, target = prediction_for(scene, settings)
    if on_prediction is not None:
        on_prediction(prediction, int(scene.patch_count))
    result = solve(
        scene,
        settings.estimator,
        paths=int(settings.paths) if settings.paths else None,
        target_mse=target,
        threshold=settings.threshold,
        seed=int(settings.seed),
        exit_point=settings.exit_point,
        sampling=settings.sampling,
        stop_rule=settings.stop_rule if target is not None else "predicted",
        progress=progress,
        should_stop=should_stop,
        max_seconds=settings.max_seconds or None,
        threads=settings.threads or None,
    )
    out = SolveOutput(patches, result, prediction, target, notes=notes)
    radiosity = np.asarray(result.radiosity, dtype=np.float64)
    for k, mesh in enumerate(patches.meshes):
        B = radiosity[patches.combined.patch_slice(k)]
        out.face_colours.append(B)
        out.point_colours.append(
            meshing.point_average(mesh, B) if settings.output in ("VERTEX", "BOTH") else None
        )
    return out


class SolveJob:
    """Runs :func:`run_solve` in a thread; the main thread polls it.

    ``progress`` is a dict (fraction, paths, rays, seconds, rays_per_second,
    measured_mse) updated between batches; ``cancel()`` stops the solve at the
    next batch.  When ``done`` is set, either ``output`` or ``error`` holds the
    outcome (``error`` is a message for the user, ``traceback`` for developers).
    """

    def __init__(self, objects, settings: SolveSettings):
        self.objects = objects
        self.settings = settings
        self._lock = threading.Lock()
        self._cancel = threading.Event()
        self.done = threading.Event()
        self.progress = {"fraction": 0.0, "paths": 0, "rays": 0, "seconds": 0.0,
                         "rays_per_second": 0.0, "measured_mse": None}
        self.output: SolveOutput | None = None
        self.prediction = None  # core Prediction, once the patches are known
        self.patch_count = None
        self.error: str | None = None
        self.traceback: str | None = None
        self.started = time.perf_counter()
        self.file_generation = _file_generation  # the open file when the job was made
        self._thread = threading.Thread(target=self._run, name="radiosity-solve", daemon=True)

    def start(self):
        self._thread.start()
        return self

    def cancel(self):
        self._cancel.set()

    @property
    def cancelled(self) -> bool:
        return self._cancel.is_set()

    def join(self, timeout=None):
        if self._thread.is_alive():
            self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        """The worker thread is still running."""
        return self._thread.is_alive()

    def snapshot(self) -> dict:
        with self._lock:
            return dict(self.progress)

    def _on_progress(self, fraction, stats):
        with self._lock:
            self.progress = {"fraction": float(fraction), **dict(stats)}

    def _on_prediction(self, prediction, patch_count):
        self.prediction = prediction
        self.patch_count = patch_count

    def relative_error(self, mse):
        """An MSE as the relative RMS error the settings speak of (None if unknown)."""
        p = self.prediction
        if p is None or mse is None or not mse == mse or p.mean_reflected_radiosity <= 0:
            return None
        return mse ** 0.5 / p.mean_reflected_radiosity

    def _run(self):
        try:
            self.output = run_solve(
                self.objects, self.settings, self._on_progress, self._cancel.is_set, self._on_prediction
            )
        except ValueError as exc:  # bad input: a message for the user
            self.error = str(exc)
        except Exception as exc:  # noqa: BLE001 - reported, never raised into Blender
            import traceback

            self.error = f"{type(exc).__name__}: {exc}"
            self.traceback = traceback.format_exc()
        finally:
            self.done.set()


# The job of the running modal solve, if any (one at a time).
_running: SolveJob | None = None


def running_job() -> SolveJob | None:
    return _running if _running is not None and not _running.done.is_set() else None


def set_running_job(job: SolveJob | None):
    global _running
    _running = job


def cancel_running_job():
    job = _running
    if job is not None:
        job.cancel()
        job.join(timeout=10)
    set_running_job(None)


# Bumped when another file is loaded (or the file is closed): a job made for the old file
# must not write into the new one.
_file_generation = 0


def file_generation() -> int:
    return _file_generation


def file_changed():
    """Another file is being loaded: stop the running job and remember that the file changed."""
    global _file_generation
    _file_generation += 1
    cancel_running_job()


def _stop_at_exit():
    job = _running
    if job is not None:
        job.cancel()


# Blender quitting (or the Python process ending) with a solve running: stop the worker before
# the interpreter waits for threads. The solver's chunks run in a ThreadPoolExecutor, whose
# threads Python joins at shutdown *before* ``atexit`` runs -- a chunk of long paths could hold
# the exit for minutes -- so the cancel is registered with threading's own exit hooks (run
# last-registered first, before those joins), and with atexit as a fallback.
try:
    import concurrent.futures.thread  # noqa: F401 - registers its exit hook first

    threading._register_atexit(_stop_at_exit)
except (AttributeError, RuntimeError):  # pragma: no cover - other Pythons, or already exiting
    pass
atexit.register(cancel_running_job)
