"""The 3D View sidebar panel (tab "Radiosity")."""

from __future__ import annotations

import math

import bpy

from . import estimate
from ..bpy_free import worker
from ..bpy_free.pipeline import duration_text

from ..bpy_free.options import METHOD

METHOD_LABELS = {identifier: label for identifier, label, _ in METHOD.items}


def _number(x):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if abs(x) >= 1e9:
        return f"{x / 1e9:.2f} G"
    if abs(x) >= 1e6:
        return f"{x / 1e6:.2f} M"
    if abs(x) >= 1e4:
        return f"{x / 1e3:.1f} k"
    return f"{x:,.0f}" if float(x).is_integer() else f"{x:.3g}"


def draw_settings(layout, settings):
    layout.prop(settings, "method")
    walk = settings.method in ("walk", "auto")  # (the estimator, sampling and direct light are the walks')
    col = layout.column(align=True)
    col.active = walk
    col.prop(settings, "estimator", text="")
    row = col.row()
    row.active = walk and settings.estimator == "biased_infinite"
    row.prop(settings, "threshold")
    col = layout.column(align=True)
    col.prop(settings, "target_error")
    col.prop(settings, "patch_size")
    col.prop(settings, "detail")
    col = layout.column(align=True)
    col.prop(settings, "exit_point")
    row = col.row()
    row.active = walk
    row.prop(settings, "sampling")
    row = col.row()
    row.active = walk
    row.prop(settings, "direct_light")
    col.prop(settings, "stop_rule")
    layout.prop(settings, "output")
    row = layout.row()
    row.active = settings.output == "TEXTURED"
    row.prop(settings, "live_lamps")
    layout.prop(settings, "display_cells")
    layout.prop(settings, "per_source")
    layout.prop(settings, "show_patches")
    row = layout.row(align=True)
    row.prop(settings, "light_output", toggle=True)
    row.prop(settings, "indirect_output", toggle=True)
    layout.prop(settings, "clamp_reflectivity")
    layout.prop(settings, "use_scene_objects")
    col = layout.column(align=True)
    col.prop(settings, "seed")
    col.prop(settings, "time_limit")
    col.prop(settings, "threads")
    layout.prop(settings, "cluster")


def draw_estimate(layout, context, value, fresh):
    box = layout.box()
    title = "Estimate" if fresh else "Estimate (updating...)"
    box.label(text=title, icon="INFO")
    if value is None:
        box.label(text="Computing...")
        return
    if "error" in value:
        for line in _wrap(value["error"], 40):
            box.label(text=line)
        return
    col = box.column(align=True)
    for term, text in estimate_lines(value):
        _explained(col, term, text)
    if value.get("warning"):
        for k, line in enumerate(_wrap(value["warning"], 40)):
            col.label(text=line, icon="ERROR" if k == 0 else "NONE")


def estimate_lines(value):
    """(term, text) of each line of the estimate, what the artist decides on first; each term
    has a tooltip with the paper's meaning (operators.EXPLANATIONS)."""
    size = f"{value['patch_size']:.3g}" if value.get("patch_size") else "-"
    lines = [
        ("time", _time_text(value)),
        ("paths", f"Paths: {_number(value['paths'])}   Rays: {_number(value['rays'])}"
         + (" (expected)" if value.get("planned") else "")),
        ("method", f"Method: {METHOD_LABELS.get(value.get('method'), value.get('method'))}"
         + (" (automatic)" if value.get("automatic") else "")),
        ("patches", f"Objects: {value['objects']} get results, {value.get('others', 0)} more block and reflect"),
        ("size", f"Patches: {_number(value['patches'])} (size {size}"
         + (f", {value['refinement']})" if value.get("refinement") else ")")),
        ("sources", f"Sources: {value.get('sources') or '-'}"),
        ("efficiency", value["efficiency"]),
        ("reflectivity", f"Average reflectivity {value['R_ave']:.2f}, path length {value['path_length']:.2f}"),
    ]
    if value.get("target_mse") is not None:
        lines.append(("target", f"Target MSE (the paper's measure): {value['target_mse']:.3g}"))
    return lines


def _time_text(value):
    if value.get("seconds") != value.get("seconds"):  # (NaN)
        return "Predicted time: -"
    if value.get("time_limited"):
        return (f"Predicted time: {duration_text(value['seconds'])} (time limit; the target needs "
                f"{duration_text(value['seconds_needed'])})")
    return f"Predicted time: {duration_text(value['seconds'])}"


def _explained(layout, term, text):
    """A line whose tooltip explains the paper's term (an operator that does nothing)."""
    op = layout.operator("radiosity.explain", text=text, emboss=False)
    op.term = term


def draw_progress(layout, job):
    stats = job.snapshot()
    box = layout.box()
    fraction = float(stats.get("fraction", 0.0) or 0.0)
    text = f"{fraction * 100:.0f}%  {_number(stats.get('paths', 0))} paths"
    if hasattr(box, "progress"):
        box.progress(factor=fraction, type="BAR", text=text)
    else:
        box.label(text=text)
    col = box.column(align=True)
    col.label(text=f"Rays/s: {_number(stats.get('rays_per_second'))}")
    left = stats.get("seconds_left")
    col.label(text=f"Time left: {duration_text(left)}" if left is not None and left == left else "Time left: -")
    if job.patch_count is not None:
        expected = stats.get("expected_paths")
        expected = expected if expected is not None and expected == expected else job.prediction.paths
        col.label(text=f"Patches: {_number(job.patch_count)}   Paths to do: {_number(expected)}")
    mse = stats.get("measured_mse")
    relative = job.relative_error(stats)
    target = job.settings.relative_rms * 100
    if relative is not None:
        col.label(text=f"Error now: {relative * 100:.2f}% (target {target:.2f}%)")
        col.label(text=f"MSE: {mse:.3g}")
    else:
        col.label(text=f"Error now: - (target {target:.2f}%)")
    if job.cancelled:
        col.label(text="Cancelling...")
    box.operator("radiosity.cancel", icon="CANCEL")


def draw_last_run(layout, settings):
    if not settings.last_paths:
        return
    box = layout.box()
    box.label(text="Last run", icon="CHECKMARK")
    col = box.column(align=True)
    col.label(text=f"{settings.last_estimator}: {_number(settings.last_patches)} patches")
    col.label(text=f"Paths: {_number(settings.last_paths)}   Rays: {_number(settings.last_rays)}")
    col.label(text=f"Time: {settings.last_seconds:.2f} s   Path length: {settings.last_mean_path_length:.2f}")
    col.label(text=f"MSE predicted: {settings.last_predicted_mse:.3g}")
    if settings.last_measured_mse >= 0:
        col.label(text=f"MSE measured: {settings.last_measured_mse:.3g}")
    col.label(text=f"Stopped by: {settings.last_stopped}")
    if settings.last_sources:
        col.label(text=f"Sources: {settings.last_sources}")
    if settings.last_light_account:
        col.label(text=settings.last_light_account[:1].upper() + settings.last_light_account[1:])


def _wrap(text, width):
    words, line, lines = text.split(), "", []
    for w in words:
        if len(line) + len(w) + 1 > width and line:
            lines.append(line)
            line = w
        else:
            line = f"{line} {w}".strip()
    if line:
        lines.append(line)
    return lines


class VIEW3D_PT_radiosity(bpy.types.Panel):
    bl_label = "Random Walk Radiosity"
    bl_idname = "VIEW3D_PT_radiosity"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Radiosity"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.radiosity
        job = worker.running_job()
        layout.enabled = True
        col = layout.column()
        col.enabled = job is None
        draw_settings(col, settings)
        if job is not None:
            draw_progress(layout, job)
        else:
            value, fresh = estimate.current(context)
            draw_estimate(layout, context, value, fresh)
            layout.operator("radiosity.solve", icon="LIGHT_SUN")
        draw_last_run(layout, settings)


classes = (VIEW3D_PT_radiosity,)


register, unregister = bpy.utils.register_classes_factory(classes)
