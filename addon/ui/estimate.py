"""The panel's estimate before a run: patch count, predicted paths and rays,
path length and relative efficiency, for the current selection and settings.

The panel only reads a cache.  When the selection, the settings or the scene
change, a timer reads the selection (main thread, arrays only: an image's raw
pixels, not converted) and a thread converts the images, checks the materials,
meshes and predicts (no ray tracing), so the interface never waits for it.
The thread touches no bpy (not thread-safe): it only sets the cache, and a
timer registered on the main thread polls it and redraws when it is done.
"""

from __future__ import annotations

import threading

import bpy

from ..bpy_free import pipeline
from ..blender_read.objects import skipped_objects, source_objects
from ..blender_read.selection import read_selection
from ..bpy_free import worker
from . import handlers

DELAY_SECONDS = 0.3
POLL_SECONDS = 0.1


class _State:
    def __init__(self):
        self.key = None  # key of the estimate in ``value``
        self.pending_key = None  # key being computed or scheduled
        self.value = None  # dict from pipeline.estimate, or {"error": message}
        self.thread = None
        self.generation = 0  # bumped by scene changes and settings
        self.lock = threading.Lock()


STATE = _State()


def invalidate(*_args):
    STATE.generation += 1


def _key(context):
    settings = context.scene.radiosity
    names = tuple(o.name for o in (*source_objects(context), *skipped_objects(context)))
    return (
        context.scene.name, names, settings.estimator, round(settings.threshold, 9),
        round(settings.target_error, 6), round(settings.patch_size, 9), STATE.generation,
        getattr(settings, "detail", "OFF"),
    )


def compute(context) -> dict:
    """The estimate for the current selection, synchronously (tests, scripts)."""
    try:
        objects, _notes = read_selection(context)
        return pipeline.estimate(objects, context.scene.radiosity.solve_settings())
    except ValueError as exc:
        return {"error": str(exc)}


def current(context):
    """(estimate or None, up_to_date) for the panel; schedules an update if stale."""
    try:
        key = _key(context)
    except Exception:  # noqa: BLE001 - during registration / odd contexts
        return STATE.value, False
    if key != STATE.key and key != STATE.pending_key:
        STATE.pending_key = key
        if not bpy.app.timers.is_registered(_start):
            bpy.app.timers.register(_start, first_interval=DELAY_SECONDS)
    return STATE.value, key == STATE.key


def _start():
    """Timer: read the selection on the main thread, estimate in a thread."""
    context = bpy.context
    if context.scene is None or not hasattr(context.scene, "radiosity"):
        return None
    if STATE.thread is not None and STATE.thread.is_alive():
        return 0.2  # one estimate at a time
    try:
        key = _key(context)
        objects, _notes = read_selection(context, later=True)
        settings = context.scene.radiosity.solve_settings()
    except ValueError as exc:
        STATE.value, STATE.key = {"error": str(exc)}, _key(context)
        STATE.pending_key = None
        _redraw_all()
        return None
    except Exception as exc:  # noqa: BLE001 - shown in the panel, never raised
        STATE.value = {"error": f"{type(exc).__name__}: {exc}"}
        STATE.key = STATE.pending_key
        STATE.pending_key = None
        _redraw_all()
        return None

    def run():
        try:
            objects.resolve()  # (the images converted here, not on the main thread)
            # (its pilot stops when a run starts: the panel then shows the run, not the estimate)
            value = pipeline.estimate(objects, settings, should_stop=lambda: worker.running_job() is not None)
        except ValueError as exc:
            value = {"error": str(exc)}
        except Exception as exc:  # noqa: BLE001
            value = {"error": f"{type(exc).__name__}: {exc}"}
        # plain Python state only: bpy is not thread-safe (the main thread's _poll redraws)
        with STATE.lock:
            STATE.value, STATE.key = value, key
            if STATE.pending_key == key:
                STATE.pending_key = None

    STATE.thread = threading.Thread(target=run, name="radiosity-estimate", daemon=True)
    STATE.thread.start()
    if not bpy.app.timers.is_registered(_poll):  # registered here, on the main thread
        bpy.app.timers.register(_poll, first_interval=POLL_SECONDS)
    return None


def _poll():
    """Timer (main thread): wait for the estimate thread, then redraw the panels."""
    thread = STATE.thread
    if thread is not None and thread.is_alive():
        return POLL_SECONDS
    _redraw_all()
    return None


def _redraw_all():
    wm = getattr(bpy.context, "window_manager", None)
    if wm is not None:
        for window in wm.windows:
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()
    return None


def _on_depsgraph_update(scene, depsgraph):
    for update in depsgraph.updates:
        if update.is_updated_geometry or update.is_updated_transform or isinstance(
            update.id, (bpy.types.Material, bpy.types.ShaderNodeTree)
        ):
            invalidate()
            return


def register():
    handlers.attach(("depsgraph_update_post", _on_depsgraph_update))


def unregister():
    handlers.detach(("depsgraph_update_post", _on_depsgraph_update))
    for fn in (_start, _poll, _redraw_all):
        if bpy.app.timers.is_registered(fn):
            bpy.app.timers.unregister(fn)
    STATE.key = STATE.pending_key = STATE.value = None
