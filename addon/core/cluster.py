"""Chunks on a Dask cluster: the runner ``solve(..., cluster=...)`` uses instead of threads.

The scene travels once to each worker (scattered); a worker builds its walk tables (and the
Embree scene) once per scene and solve parameters and keeps them for later tasks and solves.
A task is "chunks k, k+1, ... of sizes n_k" with the solve's seed: it draws from its own
streams, so its tallies are bitwise those a thread would make, on whatever worker, however many
times it runs (a lost worker's tasks run again elsewhere). Dask's ``distributed`` is optional:
imported only here, only when a cluster is asked for.
"""
from __future__ import annotations

import copy
import hashlib
import pickle
import threading
import time
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from .first_shot import Gathering
from .names import WALK
from .runners import run_chunks
from .scene import PatchScene
from .tables import WalkTables

INSTALL = "pip install 'dask[distributed]' (or pip install '.[distributed]' in the repository)"
CONNECT_SECONDS = 10
# Tasks queued per worker thread beyond the running ones (the solver reads results in order).
QUEUE_PER_WORKER = 2
# How often a wait for a task's result looks again (seconds).
WAIT_STEP = 0.002
# Walk tables a worker keeps (one per scene and solve parameters).
WORKER_TABLES = 4


class ClusterError(ValueError):
    """A cluster the solve cannot use (Dask missing, unreachable, workers without the core):
    said before any tracing, nothing run."""


def connect(cluster):
    """A ``distributed.Client`` for ``cluster`` (a Client, or a scheduler address): one clear
    error if Dask is missing or the scheduler cannot be reached, or its workers lack the core."""
    try:
        import distributed
    except ImportError as exc:
        raise ClusterError(f"solve(cluster=...) needs Dask's distributed package: {INSTALL}") from exc
    if isinstance(cluster, distributed.Client):
        client = cluster
    elif isinstance(cluster, str):
        try:
            client = distributed.Client(cluster, timeout=CONNECT_SECONDS, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {cluster!r} ({exc})") from exc
    else:
        raise ValueError(f"cluster must be a dask.distributed.Client or a scheduler address; got {cluster!r}")
    workers = client.run(_worker_check)
    if not workers:
        raise ClusterError(f"the Dask cluster at {client.scheduler.address} has no workers")
    missing = {address: problem for address, problem in workers.items() if problem}
    if missing:
        address, problem = next(iter(missing.items()))
        raise ClusterError(f"{len(missing)} of the cluster's {len(workers)} workers cannot run the walks "
                           f"(e.g. {address}: {problem}); they need numpy, embreex and addon.core importable")
    return client


def _worker_check():
    """'' if this worker can run walks, else what is missing."""
    try:
        import embreex  # noqa: F401

        from addon.core import solver  # noqa: F401
    except Exception as exc:  # noqa: BLE001 - reported to the client
        return f"{type(exc).__name__}: {exc}"
    return ""


@dataclass(frozen=True)
class WalkParameters:
    """What a worker needs besides the scene to build the walk tables a solve uses."""

    estimator: str
    threshold: float
    exit_point: str
    sampling: str
    speedups: object          # Speedups, as the solver resolved them
    gather_samples: tuple | None  # per patch, with the direct light gathered
    method: str = WALK            # how the light is carried (names.METHODS)
    # The gathering's (escaped, blocked) split, a solve's own (first_shot.fate_shares): not part
    # of the tables' key, so that solves of other seeds reuse the tables.
    fate_shares: tuple | None = field(default=None, compare=False)


@dataclass(frozen=True, eq=False)
class ScenePayload:
    """A PatchScene as it travels: its arrays, and fingerprints of its geometry and of the whole
    (a worker rebuilds the scene once, and its geometry, with the Embree scene, once per geometry)."""

    arrays: tuple          # vertices, triangles, triangle_patch, reflectivity, emission
    lights: tuple
    aim: tuple
    geometry_key: str
    key: str

    @classmethod
    def of(cls, scene):
        arrays = (scene.vertices, scene.triangles, scene.triangle_patch, scene.reflectivity, scene.emission)
        geometry = _digest(arrays[:3])
        whole = _digest(arrays[3:], geometry, pickle.dumps((scene.lights.lights, scene.lights.aim)))
        return cls(arrays, scene.lights.lights, scene.lights.aim, geometry, whole)


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
_worker_tables = OrderedDict()      # (scene key, parameters) -> WalkTables
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


def _tables(payload, parameters):
    """This worker's walk tables for the scene and parameters, built once and kept; the
    geometry (and its Embree scene) once per geometry, across solves."""
    _tune_allocator()
    with _worker_lock:
        tables = _cached_tables(payload, parameters)
    if parameters.fate_shares is None:
        return tables
    tables = copy.copy(tables)  # (the solve's own split, on shared tables)
    tables.gathering = copy.copy(tables.gathering)
    tables.gathering.fate_shares = parameters.fate_shares
    return tables


def _cached_tables(payload, parameters):
    """The tables for the scene and parameters (under _worker_lock), built once and kept."""
    key = (payload.key, parameters)
    tables = _worker_tables.get(key)
    if tables is not None:
        _worker_tables.move_to_end(key)
        return tables
    geometry = _worker_geometries.get(payload.geometry_key)
    scene = PatchScene(*payload.arrays, lights=payload.lights, aim=payload.aim, _geometry=geometry)
    _worker_geometries[payload.geometry_key] = scene.geometry
    p = parameters
    tables = WalkTables(scene, p.estimator, p.threshold, p.exit_point, p.sampling, p.speedups)
    tables.method = p.method
    if p.gather_samples is not None:
        tables.gathering = Gathering(scene, np.asarray(p.gather_samples))
    _worker_tables[key] = tables
    for cache in (_worker_tables, _worker_geometries):
        while len(cache) > WORKER_TABLES:
            cache.popitem(last=False)
    return tables


def cluster_chunks(payload, parameters, seed, first_chunk, sizes):
    """A task: the tallies of chunks ``first_chunk``... of ``sizes`` paths, on a worker."""
    return run_chunks(_tables(payload, parameters), seed, first_chunk, sizes)


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
        self.client = connect(cluster)
        self.scene, self.parameters = scene, parameters
        threads = sum(self.client.nthreads().values())
        self.slots = threads * QUEUE_PER_WORKER + 1
        self.threads = threads

    def start(self, tables, seed):
        self.seed = int(seed)
        # The scene goes to every worker once; tasks refer to it.
        self._scene = self.client.scatter(ScenePayload.of(self.scene), broadcast=True, hash=False)

    def submit(self, first_chunk, sizes):
        future = self.client.submit(cluster_chunks, self._scene, self.parameters, self.seed, first_chunk,
                                    list(sizes), pure=False, key=f"radiosity-chunks-{first_chunk}-{id(self)}")
        return _Result(future)

    def stop(self, pending):
        """Cancel the tasks still queued or running; their partial tallies are dropped."""
        futures = [p.future for p in pending]
        if futures:
            self.client.cancel(futures)
        self._scene = None
