"""The solve on a thread: a running job the main thread polls, cancel, and the exit hooks.

The main thread reads the Blender scene into arrays (``blender_read``), a :class:`SolveJob` runs
``pipeline.run_solve`` on a thread, and the main thread writes the result. No bpy here.
"""
from __future__ import annotations

import atexit
import threading
import time
import traceback

import numpy as np

from . import trim
from .pipeline import SolveOutput, SolveSettings, run_solve


class SolveJob:
    """Runs ``pipeline.run_solve`` in a thread (``start``), or in the caller's (``run``); the
    main thread polls it.

    ``progress`` is a dict (fraction, paths, rays, seconds, rays_per_second,
    measured_mse) updated between batches; ``cancel()`` stops the solve at the
    next batch.  When ``done`` is set, either ``output`` or ``error`` holds the
    outcome (``error`` is a message for the user, ``traceback`` for developers).
    ``progress_listener(job)`` is called after each batch (the command line's progress line).
    """

    def __init__(self, objects, settings: SolveSettings, progress_listener=None, prepare=None):
        self.objects = objects
        self.prepare = prepare  # what the job does first, on its thread (the rest of reading the scene)
        self.refusal: str | None = None  # the scene's bad input ``prepare`` found: the message as it is
        self.settings = settings
        self.progress_listener = progress_listener
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
        # The live view (with ``live_view``): (version, (P,3) float32 B so far), every LIVE_SECONDS.
        self.live_view = False
        self.live = (0, None)
        self.patches = None
        self._live_at = -LIVE_SECONDS
        self.file_generation = _file_generation  # the open file when the job was made
        self._thread = threading.Thread(target=self.run, name="radiosity-solve", daemon=True)

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
        stats = dict(stats)
        radiosity = stats.pop("radiosity", None)
        now = time.perf_counter()
        if self.live_view and radiosity is not None and now - self._live_at >= LIVE_SECONDS:
            # the live view's data: the result so far, as the draw handler reads it
            self.live = (self.live[0] + 1, radiosity(np.float32))
            self._live_at = now
            if (self.patch_count or 0) >= TRIM_PATCHES:
                # what the last drawing and this result's temporaries freed goes back to the
                # system (they are P-sized: in the heap, not mapped on their own)
                trim.give_back()
        with self._lock:
            self.progress = {"fraction": float(fraction), **stats}
        if self.progress_listener is not None:
            self.progress_listener(self)

    def _on_prediction(self, prediction, patch_count, patches=None):
        self.prediction = prediction
        self.patch_count = patch_count
        self.patches = patches

    @staticmethod
    def relative_error(stats):
        """The run's error now as the relative RMS the settings speak of, from its progress
        ``stats`` (None if unknown)."""
        error = stats.get("relative_error")
        return float(error) if error is not None and error == error else None

    def _hand_over_objects(self):
        """The objects' arrays, which the job then lets go of: run_solve drops them once meshed."""
        objects, self.objects = self.objects, None
        return objects

    def run(self):
        """The whole job in the calling thread (``start`` runs it on its own)."""
        try:
            if self.prepare is not None:
                try:
                    self.prepare()
                except ValueError as exc:  # bad input in the scene: its message as it is
                    self.refusal = str(exc)
                    raise
            self.output = run_solve(
                self._hand_over_objects(), self.settings, self._on_progress, self._cancel.is_set, self._on_prediction
            )
        except ValueError as exc:  # bad input: a message for the user
            self.error = str(exc)
        except Exception as exc:  # noqa: BLE001 - reported, never raised into Blender
            self.error = f"{type(exc).__name__}: {exc}"
            self.traceback = traceback.format_exc()
        finally:
            self.done.set()


# The live view's result is refreshed at most this often (a pass over the patches each time).
LIVE_SECONDS = 0.5
# From this many patches, the memory freed between two refreshes of the live view is given back
# to the system at each (trim.give_back, a few ms): at a million patches it was 100-300 MiB.
TRIM_PATCHES = 1 << 18

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
