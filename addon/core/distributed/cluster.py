"""Chunks on a Dask cluster: the runner ``solve(..., cluster=...)`` uses instead of threads.

The scene travels once to each worker (scattered); a worker builds its walk tables (and the
Embree scene) and its method's state once per scene and solve parameters and keeps them for
later tasks and solves. A task is "chunks k, k+1, ... of sizes n_k" with the solve's seed: it
draws from its own streams, so its tallies are bitwise those a thread would make, on whatever
worker, however many times it runs (a lost worker's tasks run again elsewhere). Connecting, and
what the cluster is trusted with, is ``cluster_connect``'s.
"""
from __future__ import annotations

import hashlib
import pickle
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, replace

import numpy as np

from .. import methods
from .cluster_connect import CONNECT_SECONDS, ClusterError, connect
from .runners import run_chunks
from ..scene.scene import PatchScene
from ..methods.tables import WalkTables

# Tasks queued per worker thread beyond the running ones (the solver reads results in order).
QUEUE_PER_WORKER = 2
# How often a wait for a task's result looks again (seconds).
WAIT_STEP = 0.002
# Methods' states (and their walk tables) a worker keeps: one per scene and solve parameters.
WORKER_TABLES = 4


@dataclass(frozen=True)
class WalkParameters:
    """What a worker needs besides the scene to build the state a solve's chunks read."""

    estimator: str
    threshold: float
    exit_point: str
    sampling: str
    speedups: object  # Speedups, as the solver resolved them
    method: str       # names.METHODS
    direct_light: str
    # What the method's state is rebuilt from (methods.base.Integrator.spec; None: the tables
    # alone). A gathering's split of what it finds on no front is a solve's own, no part of the
    # key: solves of other seeds reuse the state.
    spec: object = None
    groups: object = None  # the SourceGroups of a per-source solve (None: none)
    direct_apart: bool = False  # gathered direct light kept apart in the tallies (WalkTables.direct_apart)


@dataclass(frozen=True, eq=False)
class ScenePayload:
    """A PatchScene as it travels: its arrays, and fingerprints of its geometry and of the whole
    (a worker rebuilds the scene once, and its geometry, with the Embree scene, once per geometry)."""

    arrays: tuple          # vertices, triangles, triangle_patch, reflectivity, emission
    lights: tuple
    aim: tuple
    geometry_key: str
    key: str
    glossy: object = None  # the scene's GlossyLobe (None: none)

    @classmethod
    def of(cls, scene):
        arrays = (scene.vertices, scene.triangles, scene.triangle_patch, scene.reflectivity, scene.emission)
        geometry = _digest(arrays[:3])
        whole = _digest(arrays[3:], geometry, pickle.dumps((scene.lights.lights, scene.lights.aim, scene.glossy)))
        return cls(arrays, scene.lights.lights, scene.lights.aim, geometry, whole, scene.glossy)


def _digest(arrays, *extra):
    digest = hashlib.blake2b(digest_size=16)
    for a in arrays:
        a = np.ascontiguousarray(a)
        digest.update(f"{a.dtype}{a.shape}".encode())
        digest.update(a.tobytes())
    for e in extra:
        digest.update(e if isinstance(e, bytes) else str(e).encode())
    return digest.hexdigest()


_worker_geometries = OrderedDict()  # geometry key -> Geometry (with its Embree scene)
_worker_states = OrderedDict()      # (scene key, parameters) -> the method's state (with its WalkTables)
_worker_lock = threading.Lock()


def _tune_allocator():
    """Undo Dask's MALLOC_TRIM_THRESHOLD_=65536 on its workers (glibc): the walks make and drop
    many arrays, and giving memory back to the system at every drop (and mapping every array
    above 128 kB afresh) made them 25% slower."""
    global _allocator_tuned
    if _allocator_tuned:
        return
    _allocator_tuned = True
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD)
        libc.mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)  # (the env var also froze this one at 128 kB)
    except (OSError, AttributeError):  # not glibc: nothing to undo
        pass


_allocator_tuned = False
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc's mallopt parameters
TRIM_THRESHOLD, MMAP_THRESHOLD = 1 << 27, 1 << 25  # (32 MiB: glibc's own largest dynamic threshold)


def _state(payload, parameters):
    """This worker's state of the solve's method for the scene and parameters, built once and
    kept (the geometry, and its Embree scene, once per geometry, across solves), with the
    solve's own spec."""
    _tune_allocator()
    with _worker_lock:
        state = _cached_state(payload, parameters)
    return state if parameters.spec is None else state.with_spec(parameters.spec)


def _cached_state(payload, parameters):
    """The state for the scene and parameters (under _worker_lock), built once and kept."""
    key = (payload.key, parameters)
    state = _worker_states.get(key)
    if state is not None:
        _worker_states.move_to_end(key)
        return state
    geometry = _worker_geometries.get(payload.geometry_key)
    scene = PatchScene(*payload.arrays, lights=payload.lights, aim=payload.aim, glossy=payload.glossy, _geometry=geometry)
    _worker_geometries[payload.geometry_key] = scene.geometry
    p = parameters
    tables = WalkTables(scene, p.estimator, p.threshold, p.exit_point, p.sampling, p.speedups, groups=p.groups,
                        direct_apart=p.direct_apart)
    state = _worker_states[key] = methods.create(p.method, p.direct_light).rebuild(scene, tables, p.spec)
    for cache in (_worker_states, _worker_geometries):
        while len(cache) > WORKER_TABLES:
            cache.popitem(last=False)
    return state


def cluster_chunks(payload, parameters, seed, first_chunk, sizes):
    """A task: the tallies of chunks ``first_chunk``... of ``sizes`` paths, on a worker."""
    return run_chunks(_state(payload, parameters), seed, first_chunk, sizes)


class _Result:
    """A Dask future with the calls the solver makes of a thread's: result(timeout), cancel()."""

    def __init__(self, future):
        self.future = future

    def result(self, timeout=None):
        # Waits on done() rather than result(timeout): distributed's own timeout path can fail
        # with an UnboundLocalError under load.
        if timeout is not None:
            deadline = time.monotonic() + timeout
            while not self.future.done():
                if time.monotonic() >= deadline:
                    raise TimeoutError
                time.sleep(WAIT_STEP)
        try:
            return self.future.result()
        except Exception as exc:
            if getattr(self.future.client, "status", "running") in ("closing", "closed"):
                raise ClusterError("the Dask cluster went away during the solve") from exc
            raise

    def cancel(self):
        self.future.cancel()


class ClusterRunner:
    """Chunks as tasks on a Dask cluster: the calls of runners.ThreadRunner (slots, start,
    submit, stop)."""

    def __init__(self, cluster, scene, parameters):
        self.client, self._made = connect(cluster)
        self.scene, self.parameters = scene, parameters
        threads = sum(self.client.nthreads().values())
        self.slots = threads * QUEUE_PER_WORKER + 1
        self.threads = threads

    def start(self, state, seed):
        self.seed = int(seed)
        # The scene goes to every worker once; tasks refer to it.
        self._scene = self.client.scatter(ScenePayload.of(self.scene), broadcast=True, hash=False)

    def submit(self, first_chunk, sizes):
        future = self.client.submit(cluster_chunks, self._scene, self.parameters, self.seed, first_chunk,
                                    list(sizes), pure=False, key=f"radiosity-chunks-{first_chunk}-{id(self)}")
        return _Result(future)

    def restate(self, state):
        """The state the tasks submitted from now on rebuild (its spec: their size changed)."""
        self.parameters = replace(self.parameters, spec=state.spec)

    def stop(self, pending):
        """Cancel the tasks still queued or running; their partial tallies are dropped."""
        futures = [p.future for p in pending]
        if futures:
            self.client.cancel(futures)
        self._scene = None
        if self._made:  # (a client made for this solve from an address; one given stays open)
            self.client.close(timeout=CONNECT_SECONDS)
