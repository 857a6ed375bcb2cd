"""Operators: ``radiosity.solve`` (modal with a worker thread, or synchronous)
and ``radiosity.cancel``."""

from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from . import live_view
from ..bpy_free import pipeline
from ..blender_read import images
from ..blender_read.selection import read_selection
from ..blender_write.results import write_results
from ..bpy_free import worker
from . import relight_keep

TIMER_SECONDS = 0.1
#: The last error of ``radiosity.solve`` (with quiet_errors, its only record).
LAST_ERROR = ""
#: Called with a finished solve's output (pipeline.SolveOutput) before its results are written
#: (the command line's preview exposure), or None.
OUTPUT_LISTENER = None


def _redraw(context):
    screen = getattr(context, "screen", None)
    if screen is None:
        return
    for area in screen.areas:
        if area.type == "VIEW_3D":
            area.tag_redraw()


def _run_stats(output):
    """The statistics to keep, as plain Python values (computed before anything is written).

    Path and ray counts go beyond 2^31 in long runs: they are kept as exact integers (stored
    as text, see ``properties``), never through a 32-bit property."""
    r = output.result
    measured = float(r.measured_mse)
    return {
        "last_paths": int(r.paths),
        "last_rays": int(r.rays),
        "last_seconds": float(output.seconds or r.seconds),  # (the whole run's: meshing, solve, colours)
        "last_mean_path_length": float(r.mean_path_length),
        "last_predicted_mse": float(r.predicted_mse),
        "last_measured_mse": measured if measured == measured else -1.0,  # NaN -> -1
        "last_patches": int(output.patches.combined.patch_count),
        "last_sources": output.sources,
        "last_light_account": pipeline.light_account_text(r.energy),
        "last_patch_size": float(output.patches.patch_size),
        "last_stopped": str(r.stopped),
        "last_estimator": _method_text(r),
        "last_relative_error": 100.0 * r.relative_error if r.relative_error == r.relative_error else -1.0,
        "last_target_error": float(output.settings_relative_rms * 100.0) if output.settings_relative_rms else 0.0,
    }


def _method_text(result):
    """How the last run carried the light, for the panel's statistics."""
    if result.method == "two_way":
        return "two-way iteration, direct light gathered"
    return str(result.estimator) + (", direct light gathered" if result.direct_light == "gathered" else "")


def _store_stats(settings, stats):
    """Store the statistics; returns the names that could not be stored (never raises: the
    results are already written and the undo step must not be lost)."""
    failed = []
    for name, value in stats.items():
        try:
            setattr(settings, name, value)
        except Exception:  # noqa: BLE001 - a statistic out of a property's range
            failed.append(name)
    return failed


class RADIOSITY_OT_solve(bpy.types.Operator):
    """Compute diffuse global illumination of the selected meshes by shooting random walks and bake it into colour attributes"""

    bl_idname = "radiosity.solve"
    bl_label = "Solve Radiosity"
    bl_options = {"REGISTER", "UNDO"}

    quiet_errors: bpy.props.BoolProperty(
        name="Quiet errors", options={"HIDDEN", "SKIP_SAVE"},
        description="Keep an error in LAST_ERROR instead of reporting it (the command line prints it once)")

    _job = None
    _timer = None
    _notes = ()
    _scene_uid = None

    def _error(self, text, kind="ERROR"):
        global LAST_ERROR
        LAST_ERROR = text
        if not self.quiet_errors:
            self.report({kind}, text)

    @classmethod
    def poll(cls, context):
        return context.scene is not None and worker.running_job() is None

    # -- synchronous: background mode, scripts, EXEC_DEFAULT ------------------
    def execute(self, context):
        started = self._start_job(context, threaded=False)
        if started is not None:
            return started
        return self._finish(context)

    # -- interactive: worker thread + modal timer -----------------------------
    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        started = self._start_job(context, threaded=True)
        if started is not None:
            return started
        wm = context.window_manager
        self._timer = wm.event_timer_add(TIMER_SECONDS, window=context.window)
        wm.modal_handler_add(self)
        _redraw(context)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS":
            job.cancel()
            return {"RUNNING_MODAL"}  # consumed; finishes on the next timer tick
        if job.done.is_set():
            return self._finish(context)
        if event.type == "TIMER":
            _redraw(context)
        return {"PASS_THROUGH"}

    def cancel(self, context):  # Blender cancels the modal (e.g. file closed)
        if self._job is not None:
            self._job.cancel()
            self._job.join(timeout=10)
        self._cleanup(context)

    # -- shared -----------------------------------------------------------------
    def _start_job(self, context, threaded):
        """Read the scene and start the job; returns a result set on failure."""
        try:
            objects, notes = read_selection(context)
        except ValueError as exc:
            self._error(str(exc))
            return {"CANCELLED"}
        except Exception as exc:  # noqa: BLE001 - an unforeseen scene: a report, never a traceback
            import traceback

            print(traceback.format_exc())
            self._error(f"Reading the selection failed ({type(exc).__name__}: {exc}); "
                        "the scene is unchanged")
            return {"CANCELLED"}
        images.release()  # (the run's arrays hold its images' pixels: the copies kept for a next read go)
        settings = context.scene.radiosity.solve_settings()
        self._notes = notes
        self._scene_uid = context.scene.session_uid  # results go to the scene solved
        self._sources = relight_keep.snapshot(context.scene)  # the strengths solved with
        self._placements = _placements({o.uid for o in objects if o.uid is not None})
        self._job = worker.SolveJob(objects, settings)
        del objects  # the job's now: it lets go of the arrays once they are meshed
        if threaded:
            worker.set_running_job(self._job)
            self._job.live_view = True
            self._live = _live_view(self._job)
            self._job.start()
        else:  # (the running job while it runs: radiosity.cancel and the command line's Ctrl-C stop it)
            worker.set_running_job(self._job)
            try:
                self._job.run()
            finally:
                worker.set_running_job(None)
        return None

    def _cleanup(self, context):
        if getattr(self, "_live", None) is not None:
            self._live.remove()
            self._live = None
        if self._job is not None:  # nothing draws the result so far any more: let it go
            self._job.live = (self._job.live[0], None)
        if self._timer is not None:
            context.window_manager.event_timer_remove(self._timer)
            self._timer = None
        worker.set_running_job(None)
        _redraw(context)

    def _finish(self, context):
        job = self._job
        self._cleanup(context)
        job.join(timeout=10)  # done is set: the thread is ending
        output = job.output
        if job.error is not None:
            if job.traceback:
                print(job.traceback)
            self._error(f"Radiosity failed: {job.error}")
            return {"CANCELLED"}
        if output is None or output.result.stopped == "cancelled":
            self._error("Radiosity cancelled: the scene is unchanged", kind="INFO")
            return {"CANCELLED"}
        if job.file_generation != worker.file_generation():
            self.report({"WARNING"}, "Radiosity: the file changed while solving; the result was discarded")
            return {"CANCELLED"}
        missing = _missing_sources(output)
        if missing:
            self._error(f"Radiosity: {', '.join(repr(n) for n in missing)} was deleted while "
                        "solving; the result was discarded and the scene is unchanged")
            return {"CANCELLED"}
        uid = getattr(self, "_scene_uid", None)
        scene = next((sc for sc in bpy.data.scenes if sc.session_uid == uid), None) if uid else context.scene
        if scene is None:
            self._error("Radiosity: the scene was deleted while solving; the result was discarded")
            return {"CANCELLED"}
        r = output.result
        if r.paths == 0:
            self._error(f"Radiosity: the time limit ({job.settings.max_seconds:g} s) ended the run "
                        "before the first batch of paths; nothing was written. Raise the time limit")
            return {"CANCELLED"}
        try:
            stats = _run_stats(output)
            if OUTPUT_LISTENER is not None:
                OUTPUT_LISTENER(output)
            relight_keep.keep(scene, write_results(context, output, job.settings.output, scene=scene), output,
                              getattr(self, "_sources", {}), job.settings)
        except Exception as exc:  # noqa: BLE001 - report, never a traceback
            import traceback

            print(traceback.format_exc())
            self._error(f"Writing the result failed, the scene is unchanged: {exc}")
            return {"CANCELLED"}
        # The results are written: from here on nothing may raise, or the operator would end
        # without its undo step (and with a traceback) over a scene that holds the new results.
        try:
            _after_writing(self, scene.radiosity, output, stats)
        except Exception as exc:  # noqa: BLE001
            import traceback

            print(traceback.format_exc())
            self.report({"WARNING"}, f"Radiosity: the result was written, but reporting on the run failed ({exc})")
        return {"FINISHED"}


def _after_writing(op, settings, output, stats):
    """Statistics and reports of operator ``op`` once the results are written."""
    failed = _store_stats(settings, stats)
    if failed:
        op.report({"WARNING"}, f"Radiosity: could not store the run's {', '.join(failed)}")
    for note in [*op._notes, *output.notes]:
        op.report({"WARNING"}, note)
    if output.back_warning:
        op.report({"WARNING"}, output.back_warning)
    missed = pipeline.target_missed_text(stats["last_stopped"], stats["last_relative_error"], stats["last_target_error"])
    if missed:
        op.report({"WARNING"}, missed)
    if stats["last_stopped"] == "time_limit":
        op.report({"WARNING"}, f"Time limit reached after {stats['last_paths']:,} paths; the result is "
                  "noisier than asked")
    moved = _moved_sources(getattr(op, "_placements", {}))
    if moved:
        op.report({"WARNING"}, f"Radiosity: {', '.join(repr(n) for n in moved)} moved while solving; the "
                  "result shows the scene as it was when Solve was pressed (solve again to update it)")
    op.report(
        {"INFO"},
        f"Radiosity: {stats['last_patches']:,} patches, {stats['last_paths']:,} paths, "
        f"{stats['last_rays']:,} rays in {stats['last_seconds']:.1f} s"
        + (f"; {stats['last_light_account']}" if stats["last_light_account"] else ""),
    )


def _live_view(job):
    """The 3D view's live result of ``job`` (live_view.LiveView), or None where it cannot draw."""
    try:
        return live_view.LiveView(job)
    except Exception:  # noqa: BLE001 - no drawing (e.g. no GPU): the solve goes on without it
        return None


def _placements(uids):
    """World matrix of each source object (by session_uid), to notice objects moved during a run."""
    return {o.session_uid: _matrix_values(o) for o in bpy.data.objects if o.session_uid in uids}


def _matrix_values(obj):
    return tuple(value for row in obj.matrix_world for value in row)


def _moved_sources(placements):
    """Names of the source objects whose world matrix changed since the run started."""
    return sorted(
        o.name for o in bpy.data.objects
        if o.session_uid in placements and _matrix_values(o) != placements[o.session_uid]
    )


def _missing_sources(output):
    """Names of the source objects that no longer exist (deleted while the worker ran)."""
    present = {o.session_uid for o in bpy.data.objects}
    return [o.name for o in output.patches.objects if o.uid is not None and o.uid not in present]


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
