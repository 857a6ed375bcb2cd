"""The solve without threads: object arrays -> patches -> prediction -> solve -> colours.

:func:`run_solve` is the public synchronous way to run a job (scripts, the command line, the
operator's synchronous mode); ``worker`` runs the same on a thread. No bpy.
"""
from __future__ import annotations

import math
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..core import predict, solve
from ..core.display import direct_means, final_gather, live_sources
from ..core.scene.diagnostics import MAX_BOUNCES, check_bounces
from ..core.distributed.runners import local_threads, machine_threads
from ..core.methods.first_shot import direct_irradiance
from ..core.forecast import forecast
from ..core.names import AUTO
from . import adaptive_patches, options, reach, relit, run_budget, shown_mesh, smooth_colours, solve_refinement, trim
from .settings import SolveSettings, direct_light_for, method_for, prediction_for
from .patches import Patches, make_patches
from .scene_notes import back_light_warning, light_kind, scene_and_notes

@dataclass
class SolveOutput:
    patches: Patches
    result: object  # core SolveResult
    prediction: object  # core Prediction for the run's settings
    target_mse: float | None
    face_colours: list = field(default_factory=list)  # (P_k,3) per object (per polygon of its written mesh)
    # (C_k,3) per object, one a polygon corner: the smooth light (core smoothing), or None
    smooth_colours: list = field(default_factory=list)
    # the textured output's light arriving (H, without the surface's colour) per object: (C_k,3)
    # smooth, a polygon corner each (light_domain "CORNER"), or (P_k,3) a patch each ("FACE"); or None
    light_colours: list = field(default_factory=list)
    light_domain: str = "CORNER"
    # live lamps: the light arriving less what the renderer draws live (what Cycles' output adds), as light_colours
    bounced_colours: list = field(default_factory=list)
    # live lamps in a scene with lamps: the light arriving less the lamps' and suns' (EEVEE draws their highlights), as
    # light_colours
    lampless_colours: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)  # attribute name -> [(P_k,3) per object], light and indirect
    notes: list = field(default_factory=list)  # the core's warnings, for the user
    settings_relative_rms: float | None = None  # the error target asked for (None: a path count)
    sources: str = ""  # the sources that took part (sources_text)
    back_warning: str | None = None  # light absorbed on back sides in view of the selection (back_light_warning)
    sources_out: object = None  # relit.SourceResults of a per-source solve, else None
    live_lamps: bool = False  # Cycles' output leaves the lamps' direct light to the renderer (bounced_colours)
    seconds: float = 0.0  # the whole run's (meshing, solve, colours)
    # core refine.cell_meshes.Shown: the meshes written where the display split cells (None: the patches'),
    # and the source layers on them (the patches' layers where None)
    shown: object = None
    layers: list | None = None
    corner_rows: list | None = None  # per object, the triangle corner each written polygon corner reads (shown_mesh)

    def blocked_fraction(self):
        """Share of the emitted power absorbed on the back side of faces."""
        energy = self.result.energy
        if not energy:
            return 0.0
        emitted = float(np.sum(energy["emitted"]))
        return float(np.sum(energy["blocked"])) / emitted if emitted > 0 else 0.0


LIGHT_ATTRIBUTE = "Radiosity Light"
INDIRECT_ATTRIBUTE = "Radiosity Indirect"
INDIRECT_SAMPLES = 64  # gathering samples a patch for the direct light the indirect output leaves out

#: Above this predicted time the estimate warns and says which settings drive it.
SLOW_SECONDS = 60.0
#: Above this many expected bounces a path the warning says the reflectivity drives the time.
LONG_BOUNCES = 1000.0


def efficiency_sentence(relative_efficiency) -> str:
    """Formula (4) for an artist: which of the paper's estimators needs less time for this error."""
    if relative_efficiency >= 1:
        return f"Finite needs {relative_efficiency:.1f}x less time than biased infinite for this error"
    return f"Biased infinite needs {1 / relative_efficiency:.1f}x less time than finite for this error"


def slow_warning(seconds, patches, settings: SolveSettings, bounces=1.0) -> str | None:
    """A warning when the predicted time passes SLOW_SECONDS, naming what drives it: the light's
    bounces where they are many (base colours near 1), else the patches and the target."""
    if not seconds > SLOW_SECONDS:
        return None
    if bounces > LONG_BOUNCES:
        return (f"Predicted {duration_text(seconds)}: the light bounces about {bounces:,.0f} times before it is "
                "absorbed (base colours near 1 in a closed scene), and every bounce is a ray. Lower the base colours "
                f"(0.99 gives about 100 bounces); above {MAX_BOUNCES:,.0f} bounces a solve is refused")
    target = f"the {settings.relative_rms * 100:g}% error target" if not settings.paths else f"{settings.paths:,} paths"
    return (f"Predicted {duration_text(seconds)}: {patches.combined.patch_count:,} patches (patch size "
            f"{patches.patch_size:.3g}) and {target} drive it. Paths grow with the patch count: twice the "
            "patch size needs about 4x fewer; twice the error target, 4x fewer")


def duration_text(seconds) -> str:
    if not math.isfinite(seconds):
        return "unknown"
    if seconds < 60:
        return f"{seconds:.0f} s" if seconds >= 1 else f"{seconds:.1f} s"
    if seconds < 3600:
        return f"{int(seconds // 60)} min {int(seconds % 60)} s"
    return f"{seconds / 3600:.1f} h"


def sources_text(scene) -> str:
    """The sources that take part and each kind's share of the power, e.g. "1 point light 92%,
    world 3%, emissive faces 5%"."""
    total = scene.total_power
    parts = []
    kinds = {}
    for light, power in zip(scene.lights.lights, scene.lights.light_power().mean(axis=1)):
        kind = light_kind(light)
        count, share = kinds.get(kind, (0, 0.0))
        kinds[kind] = (count + 1, share + power / total)
    for kind, (count, share) in kinds.items():
        name = kind if kind == "world" else f"{count} {kind}{'s' if count > 1 else ''}"
        parts.append(f"{name} {share:.0%}")
    emissive = float(scene.patch_power.sum()) / total
    if emissive > 0:
        parts.append(f"emissive faces {emissive:.0%}")
    return ", ".join(parts)


def target_missed_text(stopped, relative_error, target) -> str:
    """A warning where a run with an error target ended at its path cap with its measured error
    (relative RMS, percent) above the target: the target was not kept, and the user must know."""
    if stopped != "paths" or not target or target <= 0 or not relative_error >= 0 or relative_error <= target:
        return ""
    return (f"The {target:g}% error target was not reached: the run stopped at its path cap with a measured "
            f"error of {relative_error:.2f}% ({relative_error / target:.1f}x the target). Solve again with a "
            "larger patch size or a looser target, or try Method: Random walks (paper)")


def light_account_text(energy) -> str:
    """Where the emitted light went, as shares of it, e.g. "light: 71.8% absorbed by surfaces
    (0.9% on the back of faces), 28.2% left the scene": every run says how much it lost."""
    emitted = float(np.sum(energy["emitted"])) if energy else 0.0
    if not emitted > 0:
        return ""
    # the two-way iteration's accounts are estimates, a little below 0 or above 1 by noise
    share = {k: min(max(float(np.sum(energy[k])) / emitted, 0.0), 1.0)
             for k in ("absorbed", "escaped", "blocked", "undistributed")}
    text = f"light: {share['absorbed']:.1%} absorbed by surfaces"
    if share["blocked"] >= 5e-4:
        text += f" ({share['blocked']:.1%} on the back of faces)"
    text += f", {share['escaped']:.1%} left the scene"
    if share["undistributed"] >= 5e-4:
        text += f", {share['undistributed']:.1%} left undistributed (paths cut at t)"
    return text


def estimate(objects, settings: SolveSettings, should_stop=None) -> dict:
    """What the panel and the command line show before a run: the predicted time, paths and
    rays of the run these settings make, from a pilot of it on this machine (core forecast), the
    paper's predictions beside them; a ValueError where the solve would refuse the scene.
    ``should_stop()`` cuts the pilot short (the panel's, when a run starts)."""
    started = time.perf_counter()
    patches = adaptive_patches.refined(objects, make_patches(objects, settings.patch_size), settings.detail,
                                       settings.seed, should_stop=should_stop)
    with trim.roomy(patches.combined.patch_count), local_threads(settings.threads):  # (as the run builds it: its time the run's)
        scene, notes = scene_and_notes(patches)
    building = time.perf_counter() - started  # (a run meshes again)
    automatic = settings.method == AUTO
    p, target = prediction_for(scene, settings)
    settings = method_for(scene, settings)
    bounces = check_bounces(scene, settings.estimator, settings.threshold)
    other = "biased_infinite" if settings.estimator == "finite" else "finite"
    relative_efficiency = float(predict(scene, "biased_infinite", threshold=settings.threshold).relative_efficiency)
    groups = relit.groups_for(scene, patches, settings.per_source, [])
    with trim.roomy(scene.patch_count):  # (the pilots' memory as the run's, so their pace is the run's)
        f = forecast(scene, run_core(scene, settings, groups), bounces=bounces, should_stop=should_stop)  # (as the run)
        display = run_budget.display_forecast(scene, patches, settings, groups)  # (the colours' time: their direct light)
    # (what the settings need, the Detail's refining solves included; a time limit ends the whole run first)
    needed = building + solve_refinement.predicted_seconds(patches, f.seconds) + display.seconds
    limited = bool(settings.max_seconds) and needed > settings.max_seconds
    seconds = max(settings.max_seconds, building + display.least) if limited else needed
    return {
        "objects": sum(o.receives for o in patches.objects),
        "others": sum(not o.receives for o in patches.objects),
        "patches": int(scene.patch_count),
        "patch_size": float(patches.patch_size),
        "refinement": adaptive_patches.refinement_text(patches),
        "paths": int(math.ceil(f.paths)),
        "rays": float(f.rays),
        "paper_paths": int(p.paths),  # formula (2)/(3) for the target or the paths given
        "paper_rays": float(p.expected_rays),
        "direct_light": direct_light_for(scene, settings),
        "method": settings.method,
        "automatic": automatic,  # the method chosen by "auto"
        "planned": bool(target is not None),  # the paths where the measured error is expected to meet the target
        "measured": f.measured,  # from the pilot's chunks (else from the bounces and Embree's raw rate)
        "rays_per_second": float(f.rays_per_second),
        "seconds": seconds,
        "seconds_needed": needed,
        "time_limited": limited,
        "display_seconds": display.seconds,
        "pilot_seconds": f.pilot_seconds,
        "bounces": float(bounces),
        "path_length": float(p.expected_path_length),
        "R_ave": float(p.R_ave),
        "relative_efficiency": relative_efficiency,
        "efficiency": efficiency_sentence(relative_efficiency),
        "target_mse": target,
        "predicted_mse": float(p.predicted_mse),
        "other_estimator": other,
        "warning": reach.out_of_reach(f.short_of_target, scene, settings) or slow_warning(needed, patches, settings, bounces),
        "sources": sources_text(scene),
        "notes": notes,
    }


def run_core(scene, settings: SolveSettings, groups, **changes):
    """The core's Settings of a run of ``settings`` with per-source ``groups`` (or None): each
    group's direct light apart, the lamps' left out of the error, which the display's replace
    after the solve (core direct_means)."""
    return settings.core(scene, per_source=groups is not None, groups=groups, direct_apart=True,
                         replaced_direct=direct_means.replaced(scene, groups), **changes)


def run_solve(objects, settings: SolveSettings, progress=None, should_stop=None, on_prediction=None) -> SolveOutput:
    """Mesh, solve and compute the colours to write, for the given objects.

    ``on_prediction(prediction, patch_count, patches)`` is called once the patches
    are known, before the first path.
    """
    started, limit = time.perf_counter(), settings.max_seconds  # (a time limit holds for the whole run: run_budget)
    trim.fix_mmap_threshold()
    patches = make_patches(objects, settings.patch_size, layers=True)
    patches, settings = solve_refinement.refined(objects, patches, settings, progress, should_stop, on_prediction)
    del objects  # the source arrays are meshed: the caller's references are the only ones left
    trim.give_back()  # (between stages: what meshing freed, then what building the scene freed)
    with trim.roomy(patches.combined.patch_count), local_threads(settings.threads):  # (its probes on the threads)
        scene, notes = scene_and_notes(patches)
    prediction, target = prediction_for(scene, settings)
    groups = relit.groups_for(scene, patches, settings.per_source, notes)
    settings = method_for(scene, settings, relit.measured_choice_groups(groups))
    if on_prediction is not None:
        on_prediction(prediction, int(scene.patch_count), patches)
    budget = run_budget.Budget.of(started, limit, scene, patches, settings, groups)
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="radiosity-beside") as beside:
        first = _lamp_means_beside(beside, scene, groups, settings)
        with trim.roomy(scene.patch_count):  # (freed memory kept for the next chunk: no page faults)
            result = solve(scene, run_core(scene, settings, groups, max_seconds=budget.solve_seconds()),
                           progress=progress, should_stop=should_stop)
        first = None if first is None else first.result()
    # (the display's direct light in place of the solve's, whose weak lamps are heavy-tailed: core direct_means)
    with local_threads(settings.threads):  # (the display's work on the threads the solve had)
        result = direct_means.corrected(scene, result, None if settings.paths else settings.relative_rms, first)
    out = SolveOutput(patches, result, prediction, target, notes=notes,
                      settings_relative_rms=None if settings.paths else settings.relative_rms,
                      sources=sources_text(scene))
    out.back_warning = back_light_warning(patches, scene, out.blocked_fraction(), int(settings.seed))
    out.sources_out = relit.source_results(scene, patches, result, groups) if groups is not None else None
    with trim.roomy(scene.patch_count), local_threads(settings.threads):
        write_colours(out, scene, result, settings, budget.deadline())
    relit.add_object_values(out, settings)
    shown_mesh.let_go(out)
    out.seconds = time.perf_counter() - started
    return out


def _lamp_means_beside(beside, scene, groups, settings):
    """The future of the display's first lamp means (core ``direct_means.first_means``) on the
    ``beside`` executor's one thread, made while the solve runs (they need nothing of it, and the
    solve's threads leave a core idle part of the time); None where there are no groups of lamps
    alone, or the run has one thread (they are made after the solve, as the same numbers)."""
    if groups is None or machine_threads(settings.threads) < 2 \
            or direct_means.replaced(scene, groups) is None:
        return None

    def first():
        with local_threads(1):  # (its own thread alone: the solve has the others)
            return direct_means.first_means(scene, groups.light_group, groups.patch_group(scene.patch_count),
                                            groups.count, int(settings.seed))

    return beside.submit(first)


def write_colours(out, scene, result, settings, deadline=None):
    """The colours ``out`` carries to the objects: per patch and per point, the light arriving
    (textured output), and the extra outputs (light only, indirect), per object that receives;
    the direct light's retries within ``deadline``. The smooth colours show the bounced light
    gathered again (core final_gather); the per-patch ones, and ``result``, stay as solved."""
    patches = out.patches
    # Light is written as at least 0: an estimate below it is noise about a value near 0 (the two-way
    # iteration's control variate where a patch gets almost no light; a difference of two estimates).
    radiosity = np.maximum(result.radiosity, 0.0)
    textured = settings.output == "TEXTURED"
    out.live_lamps = textured and settings.live_lamps and live_sources.has_live(scene)
    extras = {}
    if settings.light_output and not textured:  # (the textured output writes the light smooth)
        extras[LIGHT_ATTRIBUTE] = np.maximum(result.irradiance, 0.0)
    if settings.indirect_output:
        # the light arriving minus a gathered estimate of the direct light alone (noise of both)
        extras[INDIRECT_ATTRIBUTE] = np.maximum(
            result.irradiance - direct_irradiance(scene, INDIRECT_SAMPLES, int(settings.seed)), 0.0)

    made = {}  # "smooth", "light", "bounced" -> per object (C_k,3) at its polygon corners (None: not receiving)
    both = settings.output in ("BOTH", "TEXTURED")
    if settings.output == "VERTEX" or (both and scene.patch_count <= options.SMOOTH_MAX_PATCHES):
        shading = adaptive_patches.shading_arrays(patches, scene)
        shown = final_gather.gathered(scene, result)  # (the blotches a dim wall's patches share through the chunks)
        # (the display's direct light and cells traced beside the filters and the live parts, which read neither)
        surface = shown_mesh.surface_of(scene, shading)
        display = shown_mesh.display_beside(out, scene, shown, shading, deadline, settings.display_cells, surface)
        smooth = smooth_colours.smooth_corners if out.sources_out is None else relit.SmoothSources(out, shown_mesh.polygon_corners).corners
        for name, corners in smooth(scene, shown, light=textured, shading=shading, live=out.live_lamps, deadline=deadline,
                                    surface=surface, display=display):
            made[name] = shown_mesh.polygon_corners(out, scene, corners, shading, least=0.0)
            del corners  # (let go of before the next is made)
        del surface, display, shown
        out.layers = shown_mesh.layers_on(out)
    elif both:
        shown = "the textures times each patch's own light are shown" if textured else "the flat colours are shown"
        label = options.OUTPUT.item_label(settings.output)
        out.notes.append(f"smooth colours left out at {scene.patch_count:,} patches ({label} makes them up to "
                         f"{options.SMOOTH_MAX_PATCHES:,}: at a million they double the time and memory of the run); "
                         f"{shown}: choose Smooth colours to make them")
    for name, values in extras.items():
        out.extra[name] = [None if not o.receives else shown_mesh.per_polygon(out, k, np.asarray(values[patches.combined.patch_slice(k)]))
                           for k, o in enumerate(patches.objects)]
    out.light_domain = "CORNER" if "light" in made else "FACE"
    flat = {} if not textured or "light" in made else {"light": np.maximum(result.irradiance, 0.0)}
    if flat and out.live_lamps:  # (lamps drawn live)
        drawn = relit.drawn_light(out, scene, result, deadline)
        flat["bounced"] = np.maximum(result.irradiance - drawn, 0.0)
        if live_sources.draws_highlights(scene):
            flat["lampless"] = np.maximum(result.irradiance - relit.lamp_light(out, scene, result, drawn, deadline), 0.0)
    for k, o in enumerate(patches.objects):
        rows = patches.combined.patch_slice(k)
        out.face_colours.append(shown_mesh.per_polygon(out, k, radiosity[rows]) if o.receives else None)
        out.smooth_colours.append(made["smooth"][k] if "smooth" in made else None)
        for name, colours in (("light", out.light_colours), ("bounced", out.bounced_colours),
                              ("lampless", out.lampless_colours)):
            if name in made:
                colours.append(made[name][k])
            else:
                colours.append(flat[name][rows] if name in flat and o.receives else None)
