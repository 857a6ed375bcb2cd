"""A solve of the selection, from reading it to its results written: what the panel's operator
(``radiosity.solve``), the command line and scripts run (bpy).

``start`` reads the selection and makes the job (``bpy_free.worker.SolveJob``), which runs on a
thread (the panel) or here (``run``); ``finish`` checks what changed meanwhile, writes the results
and says what happened as (kind, text) messages, which the operator reports and the command line
prints. Nothing here reports or prints.
"""

from __future__ import annotations

import traceback
from dataclasses import dataclass, field

import bpy

from ..blender_read import images
from ..blender_read.selection import read_selection
from ..bpy_free import pipeline, worker
from . import relight_keep
from .results import write_results


class JobError(Exception):
    """The job cannot start: the message for the user."""


@dataclass
class Started:
    """A job made from the selection, with what its end checks against: the scene solved, the
    sources' strengths and the objects' placements when it started."""

    job: worker.SolveJob
    notes: list
    scene_uid: int
    sources: dict
    placements: dict


@dataclass
class Finished:
    """A job's end: "FINISHED" (results written) or "CANCELLED", the error that ended it (None),
    the messages to show as (kind, text), kind "INFO", "WARNING" or "ERROR"."""

    status: str
    error: str | None = None
    messages: list = field(default_factory=list)
    output: object = None


def start(context, progress_listener=None):
    """The Started job of the context's selection and its scene's settings; JobError in one line
    where the selection cannot be read (the scene unchanged)."""
    try:
        objects, notes = read_selection(context, later=True)  # (the rest on the job's thread: ``_resolve``)
    except ValueError as exc:
        raise JobError(str(exc)) from None
    except Exception as exc:  # noqa: BLE001 - an unforeseen scene: a message, never a traceback
        print(traceback.format_exc())
        raise JobError(f"Reading the selection failed ({type(exc).__name__}: {exc}); the scene is unchanged") from None
    scene = context.scene
    placements = _placements({o.uid for o in objects if o.uid is not None})
    job = worker.SolveJob(objects, scene.radiosity.solve_settings(), progress_listener=progress_listener,
                          prepare=lambda: _resolve(objects, notes))
    return Started(job, notes, scene.session_uid, relight_keep.snapshot(scene), placements)


def _resolve(objects, notes):
    """The job's first step (its thread, no bpy): the read of the selection finished (its images
    converted, its materials checked), its notes kept in ``notes``."""
    notes[:] = objects.resolve(notes)
    images.release()  # (the run's arrays hold its images' pixels: the copies kept for a next read go)


def run(context, progress_listener=None, before_writing=None):
    """A synchronous solve of the selection (scripts, the command line): the Finished job. The
    running job while it runs (``worker.running_job``: ``radiosity.cancel`` and Ctrl-C stop it);
    ``before_writing(output)`` is called once its results are known, before they are written."""
    try:
        started = start(context, progress_listener)
    except JobError as exc:
        return Finished("CANCELLED", str(exc), [("ERROR", str(exc))])
    worker.set_running_job(started.job)
    try:
        started.job.run()
    finally:
        worker.set_running_job(None)
    return finish(context, started, before_writing)


def finish(context, started, before_writing=None):
    """The Finished end of a job whose run is over: its results written to the scene it solved,
    unless it failed, was cancelled, or the file, the scene or a source object went meanwhile."""
    job = started.job
    job.join(timeout=10)  # (done is set: the thread is ending)
    output = job.output
    refused = _refused(job, output, started)
    if refused is not None:
        return refused
    scene = next((sc for sc in bpy.data.scenes if sc.session_uid == started.scene_uid), None)
    if scene is None:
        return _cancelled("Radiosity: the scene was deleted while solving; the result was discarded")
    try:
        stats = run_stats(output)
        if before_writing is not None:
            before_writing(output)
        created = write_results(context, output, job.settings.output, scene=scene)
        relight_keep.keep(scene, created, output, started.sources, job.settings)
    except Exception as exc:  # noqa: BLE001 - a message, never a traceback
        print(traceback.format_exc())
        return _cancelled(f"Writing the result failed, the scene is unchanged: {exc}")
    # The results are written: from here on nothing may raise (the operator's undo step).
    try:
        messages = after_writing(scene.radiosity, started, output, stats)
    except Exception as exc:  # noqa: BLE001
        print(traceback.format_exc())
        messages = [("WARNING", f"Radiosity: the result was written, but reporting on the run failed ({exc})")]
    return Finished("FINISHED", None, messages, output)


def _refused(job, output, started):
    """The Finished of a job whose results must not be written, or None."""
    if job.refusal is not None:
        return _cancelled(job.refusal)
    if job.error is not None:
        if job.traceback:
            print(job.traceback)
        return _cancelled(f"Radiosity failed: {job.error}")
    if output is None or output.result.stopped == "cancelled":
        return _cancelled("Radiosity cancelled: the scene is unchanged", kind="INFO")
    if job.file_generation != worker.file_generation():
        return _cancelled("Radiosity: the file changed while solving; the result was discarded", kind="WARNING")
    missing = _missing_sources(output)
    if missing:
        return _cancelled(f"Radiosity: {', '.join(repr(n) for n in missing)} was deleted while solving; the "
                          "result was discarded and the scene is unchanged")
    if output.result.paths == 0:
        return _cancelled(f"Radiosity: the time limit ({job.settings.max_seconds:g} s) ended the run before the "
                          "first batch of paths; nothing was written. Raise the time limit")
    return None


def _cancelled(text, kind="ERROR"):
    return Finished("CANCELLED", text, [(kind, text)])


def run_stats(output):
    """The statistics to keep, as plain Python values (computed before anything is written).

    Path and ray counts go beyond 2^31 in long runs: they are kept as exact integers (stored
    as text, see ``ui.properties``), never through a 32-bit property."""
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
        "last_estimator": method_text(r),
        "last_relative_error": 100.0 * r.relative_error if r.relative_error == r.relative_error else -1.0,
        "last_target_error": float(output.settings_relative_rms * 100.0) if output.settings_relative_rms else 0.0,
    }


def method_text(result):
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


def after_writing(settings, started, output, stats):
    """The statistics stored, and the messages of a run whose results are written."""
    messages = []
    failed = _store_stats(settings, stats)
    if failed:
        messages.append(("WARNING", f"Radiosity: could not store the run's {', '.join(failed)}"))
    messages += [("WARNING", note) for note in [*started.notes, *output.notes]]
    if output.back_warning:
        messages.append(("WARNING", output.back_warning))
    missed = pipeline.target_missed_text(stats["last_stopped"], stats["last_relative_error"], stats["last_target_error"])
    if missed:
        messages.append(("WARNING", missed))
    if stats["last_stopped"] == "time_limit":
        messages.append(("WARNING", f"Time limit reached after {stats['last_paths']:,} paths; the result is "
                                    "noisier than asked"))
    moved = _moved_sources(started.placements)
    if moved:
        messages.append(("WARNING", f"Radiosity: {', '.join(repr(n) for n in moved)} moved while solving; the "
                                    "result shows the scene as it was when Solve was pressed (solve again to update it)"))
    messages.append(("INFO", f"Radiosity: {stats['last_patches']:,} patches, {stats['last_paths']:,} paths, "
                             f"{stats['last_rays']:,} rays in {stats['last_seconds']:.1f} s"
                             + (f"; {stats['last_light_account']}" if stats["last_light_account"] else "")))
    return messages


def _placements(uids):
    """World matrix of each source object (by session_uid), to notice objects moved during a run."""
    return {o.session_uid: _matrix_values(o) for o in bpy.data.objects if o.session_uid in uids}


def _matrix_values(obj):
    return tuple(value for row in obj.matrix_world for value in row)


def _moved_sources(placements):
    """Names of the source objects whose world matrix changed since the run started."""
    return sorted(o.name for o in bpy.data.objects
                  if o.session_uid in placements and _matrix_values(o) != placements[o.session_uid])


def _missing_sources(output):
    """Names of the source objects that no longer exist (deleted while the worker ran)."""
    present = {o.session_uid for o in bpy.data.objects}
    return [o.name for o in output.patches.objects if o.uid is not None and o.uid not in present]
