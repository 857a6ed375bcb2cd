"""Operators: ``radiosity.solve`` (modal with a worker thread, or synchronous) and
``radiosity.cancel``; the job itself is ``blender_write.solve_job``'s."""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from ..blender_write import solve_job
from ..bpy_free import worker
from . import live_view

TIMER_SECONDS = 0.1


def _redraw(context):
    screen = getattr(context, "screen", None)
    if screen is None:
        return
    for area in screen.areas:
        if area.type == "VIEW_3D":
            area.tag_redraw()


class RADIOSITY_OT_solve(bpy.types.Operator):
    """Compute diffuse global illumination of the selected meshes by shooting random walks and bake it into colour attributes"""

    bl_idname = "radiosity.solve"
    bl_label = "Solve Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    _started = None
    _timer = None
    _live = None

    @classmethod
    def poll(cls, context):
        return context.scene is not None and worker.running_job() is None

    # -- synchronous: background mode, scripts, EXEC_DEFAULT ------------------
    def execute(self, context):
        return self._reported(solve_job.run(context))

    # -- interactive: worker thread + modal timer -----------------------------
    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        failed = self._start(context)
        if failed is not None:
            return failed
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        _redraw(context)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._started.job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
            return {"RUNNING_MODAL"}  # consumed; finishes on the next timer tick
        if job.done.is_set():
            self._cleanup(context)
            return self._reported(solve_job.finish(context, self._started))
        if event.type == "TIMER":
            _redraw(context)
        return {"PASS_THROUGH"}

    def cancel(self, context):  # Blender cancels the modal (e.g. file closed)
        if self._started is not None:
            self._started.job.cancel()
            self._started.job.join(timeout=10)
        self._cleanup(context)

    def _start(self, context):
        """The job started on its thread, drawn live; the result set of a failure, else None."""
        try:
            self._started = solve_job.start(context)
        except solve_job.JobError as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        job = self._started.job
        worker.set_running_job(job)
        job.live_view = True
        self._live = _live_view(job)
        job.start()
        return None

    def _reported(self, finished):
        """The operator's result of a job's end, its messages reported."""
        for kind, text in finished.messages:
            self.report({kind}, text)
        return {finished.status}

    def _cleanup(self, context):
        if self._live is not None:
            self._live.remove()
            self._live = None
        job = self._started.job if self._started is not None else None
        if job is not None:  # nothing draws the result so far any more: let it go
            job.live = (job.live[0], None)
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        worker.set_running_job(None)
        _redraw(context)


def _live_view(job):
    """The 3D view's live result of ``job`` (live_view.LiveView), or None where it cannot draw."""
    try:
        return live_view.LiveView(job)
    except Exception:  # noqa: BLE001 - no drawing (e.g. no GPU): the solve goes on without it
        return None


@persistent
def _on_load_pre(*_args):
    """Another file is about to load (or a new one): stop the solve, discard its result."""
    worker.file_changed()


class RADIOSITY_OT_cancel(bpy.types.Operator):
    """Stop the running radiosity solve; the scene stays as it was"""

    bl_idname = "radiosity.cancel"
    bl_label = "Cancel Radiosity"

    @classmethod
    def poll(cls, context):
        return worker.running_job() is not None

    def execute(self, context):
        job = worker.running_job()
        if job is not None:
            job.cancel()
        return {"FINISHED"}


# The tooltips of the panel's estimate: the paper's terms for an artist.
EXPLANATIONS = {
    "time": "Measured before the run: a pilot of a few of its chunks on this machine gives the error per path, "
            "the rays per path and the seconds per path, and the run's own plan and stop rule give the paths "
            "it will end at; meshing included. During the run the time left follows its measured error",
    "paths": "The paths (and the rays they trace) the run is expected to end at: with 'Stop at: Measured error', "
             "where its error estimate meets the target (in whole batches, at least 8); else the paper's formula "
             "(2) (finite) or (3) (biased infinite) for the target, or the paths given. The paper derives the "
             "formulas for its discrete method (exit point Random); with the hit point the same paths give about "
             "the same noise (benchmarks/results/exits.md)",
    "method": "How the light is carried: the paper's random walks, or the two-way iteration (beyond the paper). "
              "Automatic takes the two-way iteration where each patch gets enough of its rays to pay, else the walks",
    "patches": "Selected objects get results; the other visible objects (Rest of the scene) block and "
               "reflect light as in a render, meshed coarser, and get none. Smaller patches show more "
               "detail and need more paths for the same error",
    "efficiency": "The paper's relative efficiency, formula (4): the time one estimator needs for an error "
                  "over the other's, from the scene's average reflectivity and threshold t",
    "reflectivity": "R_ave, the area-weighted mean reflectivity: paths last 1 / (1 - R_ave) bounces on "
                    "average (the finite estimator) and the error grows with it",
    "size": "The selection meshed into patches no larger than the patch size (the rest of the scene 4x "
            "coarser): each patch gets one colour",
    "sources": "The light sources that take part and each one's share of the emitted power (Phi_T): "
               "emissive faces of the selection, lights that render (selected or not) and the world",
    "target": "The error target as the paper's mean square error: the relative RMS error times the "
              "scene's mean reflected radiosity, squared. It is the noise of the patch values; how a flat patch "
              "differs from the continuous light across it (and, with exit point Random, the discrete method's "
              "own error) is not in it",
}


class RADIOSITY_OT_explain(bpy.types.Operator):
    """Explain this value"""

    bl_idname = "radiosity.explain"
    bl_label = "Explain"
    bl_options = {"INTERNAL"}

    term: bpy.props.StringProperty(options={"HIDDEN", "SKIP_SAVE"})

    @classmethod
    def description(cls, context, properties):
        return EXPLANATIONS.get(properties.term, "")

    def execute(self, context):
        return {"FINISHED"}


classes = (RADIOSITY_OT_solve, RADIOSITY_OT_cancel, RADIOSITY_OT_explain)


def register():
    for cls in classes:
        bpy.utils.register_class(cls)
    if _on_load_pre not in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.append(_on_load_pre)


def unregister():
    if _on_load_pre in bpy.app.handlers.load_pre:
        bpy.app.handlers.load_pre.remove(_on_load_pre)
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
