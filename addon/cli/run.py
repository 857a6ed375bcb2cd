"""The command line's run: open or build the scene, check where the files go, solve through the
panel's operator (``radiosity.solve``, synchronous), then save the .blend and render the preview
(numpy and bpy are imported where used: Ctrl-C is handled from the start)."""

from __future__ import annotations

import os
import sys
import time

from ..bpy_free import options
from . import preview, scenes
from .arguments import checked, default_samples, given_options, parser
from .interrupt import Interrupt, Interrupted, exit_now
from .messages import fail, for_command_line, one_line
from .progress import ProgressLine
from .saving import Outputs, check_blend, check_png, output_problem, save_blend


class Refused(Exception):
    """The run cannot go on: the message for the user and the exit status."""

    def __init__(self, message, status=2):
        super().__init__(message)
        self.status = status


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser().parse_args(argv)
    args.given = given_options(argv)
    try:
        args = checked(args)
    except ValueError as exc:
        return fail(str(exc), 2)
    names = ["cornell"] + scenes.sample_scene_names()
    if args.list:
        print("\n".join(names))
        return 0
    with Interrupt() as interrupt:
        try:
            return _run(args, names, interrupt)
        except Interrupted:
            status = interrupt.stopped()
        except Refused as exc:
            return fail(str(exc), exc.status)
    if status != Interrupt.STATUS:  # SIGTERM, SIGHUP: the process ends, as their default would end it (a host's too)
        exit_now(status)
    return status


def _run(args, names, interrupt):
    root = scenes.repo_root()
    if root not in sys.path:
        sys.path.insert(0, root)
    import bpy  # noqa: F401 - loaded here, before the first check for Ctrl-C

    interrupt.check()
    t0 = time.perf_counter()
    scene_name, own_scene = _open_scene(args, names)
    out_blend = os.path.abspath(args.blend_path or os.path.join("out", f"{scene_name}.blend"))
    png = None if args.no_preview else os.path.abspath(args.preview or os.path.splitext(out_blend)[0] + ".png")
    if png and os.path.realpath(png) == os.path.realpath(out_blend):  # (the render would be saved over)
        raise Refused(f"--preview and --output both name {png}: give the preview a file of its own")
    for target in (out_blend, png):  # said before the run, not after it
        problem = target and output_problem(target)
        if problem:
            raise Refused(problem)
    if args.relight:
        return _relight(args, interrupt, (out_blend, png))
    sources = _sources(args)
    settings = _settings(args, scene_name, own_scene)
    exposure = []
    status = _solve(args, settings, interrupt, exposure)
    if status is not None:
        return status
    print(summary(scene_name, settings))
    print(f"sources: {settings.last_sources}")
    status = _save(args, interrupt, (out_blend, png), sources, own_scene, exposure)
    if status is not None:
        return status
    if png:
        print(f"preview: {png}")
    print(f"saved: {out_blend}  ({time.perf_counter() - t0:.1f} s in all)")
    return 0


def _relight(args, interrupt, targets):
    """--relight: the opened file's per-light results recombined, no solve, then saved."""
    from . import relight

    if not (args.open or args.current):
        raise Refused("--relight needs a saved file with per-light results: --open FILE.blend")
    try:
        print(relight.run(args))
    except ValueError as exc:
        raise Refused(str(exc)) from None
    status = _save(args, interrupt, targets, relight.solved_objects(), False, [])
    if status is None:
        print(f"saved: {targets[0]}")
    return status or 0


def _open_scene(args, names):
    """(scene name, built here): the .blend opened, the scene already loaded, or a scene built
    in an empty file; Refused for a file that cannot be opened or an unknown scene."""
    import bpy

    scene_name = args.scene or "cornell"
    if args.open:
        path = os.path.abspath(args.open)
        if not os.path.isfile(path):
            raise Refused(f"no such file: {path}")
        try:
            bpy.ops.wm.open_mainfile(filepath=path)
        except RuntimeError as exc:
            raise Refused(f"cannot open {path}: {one_line(exc)}") from None
        scene_name = os.path.splitext(os.path.basename(args.open))[0]
    elif args.current:
        scene_name = os.path.splitext(os.path.basename(bpy.data.filepath))[0] or "scene"
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    scenes.ensure_registered()
    own_scene = not (args.open or args.current)  # built here, not the user's
    if own_scene:
        if scene_name == "cornell":  # the one Cornell box: sample_scenes/cornell_box.py
            _, args.scene_settings = scenes.build_sample_scene("cornell_box")
        elif scene_name in scenes.sample_scene_names():
            _, args.scene_settings = scenes.build_sample_scene(scene_name)
        else:
            raise Refused(f"unknown scene {scene_name!r}; choose from: {', '.join(names)}")
    return scene_name, own_scene


def _sources(args):
    """The objects to solve (all meshes with --select-all); Refused when there are none."""
    import bpy

    from ..blender_read.objects import source_objects
    from ..blender_read.objects import is_result_object

    if args.select_all:
        for o in bpy.context.view_layer.objects:
            o.select_set(o.type == "MESH" and not is_result_object(o))
    sources = source_objects(bpy.context)
    if not sources:
        raise Refused("no mesh object selected (use --select-all)")
    return sources


def _settings(args, scene_name, own_scene):
    """The scene's settings (``scene.radiosity``), set from the arguments; with --current, the
    panel's own where the command line gives none."""
    import bpy

    settings = bpy.context.scene.radiosity
    if own_scene and scene_name in scenes.sample_scene_names() and not args.patch_size:
        args.patch_size = 1e6  # sample scenes come meshed as in the paper: keep their patches
    scene_settings = getattr(args, "scene_settings", {})  # a sample's own, where no option says otherwise
    if args.current:
        scene_settings = {option.name: getattr(settings, option.name) for option in options.SETTINGS}
    for name, value in scene_settings.items():
        if name not in args.given:
            setattr(args, name, value)
    if not args.samples_given:  # (live lamps and the colours may have come from the panel)
        args.samples = default_samples(args)
    for option in options.SETTINGS:
        setattr(settings, option.name, getattr(args, option.name))
    return settings


def _solve(args, settings, interrupt, exposure):
    """Solve the selection (``blender_write.solve_job``, as the panel's operator does), with a
    warning first for a costly setting and the progress line on a terminal; the status of a
    failure, else None (the preview's exposure appended to ``exposure`` from the arrays written)."""
    import bpy

    from ..blender_write import solve_job

    _warn_before(settings, interrupt)
    progress = ProgressLine(sys.stderr) if (not args.quiet and sys.stderr.isatty()) else None
    interrupt.progress = progress

    def before_writing(output):
        if not args.no_preview:  # from the arrays written: reading Blender's back would copy them
            exposure.append(preview.preview_exposure(output))
        release_solve_memory()  # writing the colours needs the patches, not the core's scene

    try:
        finished = solve_job.run(bpy.context, progress_listener=progress, before_writing=before_writing)
    finally:
        if progress is not None:
            progress.end()
        interrupt.check()
    release_solve_memory()
    if finished.status != "FINISHED":
        return fail(finished.error or "the solve did not finish")
    for kind, text in finished.messages:  # (the operator's reports, as Blender prints them)
        print(f"{kind.capitalize()}: {for_command_line(text)}")
    return None


def _warn_before(settings, interrupt):
    """A costly setting is said before the run, as the panel says it."""
    import bpy

    from ..bpy_free import pipeline
    from ..bpy_free.patches import NothingToSolve
    from ..blender_read import selection

    try:
        warning = pipeline.estimate(selection.read_selection(bpy.context)[0], settings.solve_settings())["warning"]
    except NothingToSolve as exc:  # as nothing selected is
        raise Refused(str(exc)) from None
    except ValueError:
        warning = None  # bad input: the solve says what is wrong
    interrupt.check()
    if warning:
        print(f"warning: {for_command_line(warning)}", file=sys.stderr)


def _save(args, interrupt, targets, sources, own_scene, exposure):
    """Write the .blend and the preview, all in place or none; the status of a failure, else None."""
    out_blend, png = targets
    outputs = interrupt.outputs = Outputs()
    try:
        for target in (out_blend, png):
            if target:
                os.makedirs(os.path.dirname(target), exist_ok=True)
        outputs.add(out_blend, check_blend)
        if png:
            outputs.add(png, check_png)
        if png and own_scene:
            # a scene built here: saved with the preview's settings, so F12 renders the same
            preview.render_preview(png, sources, args.resolution, args.samples,
                                   exposure[-1] if exposure else preview.auto_exposure(),
                                   keep_settings=True, write_to=outputs.writing(png))
            interrupt.check()
        # the user's scene is saved as it is, plus the results (a copy: the open file stays the same)
        save_blend(outputs.writing(out_blend))
        interrupt.check()
        if png and not own_scene:
            # then the preview, with temporary settings undone afterwards
            preview.render_preview(png, sources, args.resolution, args.samples,
                                   exposure[-1] if exposure else preview.auto_exposure(), write_to=outputs.writing(png))
        outputs.check()
        with interrupt.lock:  # all files in place, or none
            interrupt.check()
            outputs.commit()
            interrupt.committed = True
    except (RuntimeError, OSError) as exc:
        outputs.discard()
        return fail(outputs.failure(exc))
    return None


def release_solve_memory():
    """Let go of what the solve kept for the panel (the meshed geometry and the core's scene with
    its ray tracer, kept for a re-run) and give it back to the system: the command line saves and
    renders next, and Cycles' copy of the results needs the room."""
    import gc

    from ..bpy_free import patches, trim

    patches.GEOMETRY_CACHE.clear()
    gc.collect()
    trim.give_back()


# What the error reached and the target are: the noise of the patch values, not their discretization.
ERROR_COVERS = "the patch values' noise, not the flat patches' discretization"


def summary(scene_name, settings) -> str:
    """The run in one line, with the error reached against the target (both relative RMS)."""
    error = settings.last_relative_error
    target = settings.last_target_error
    reached = "error unknown" if error < 0 else f"error {error:.2f}%"
    if target > 0 and error >= 0:
        reached += f" of a {target:g}% target ({error / target * 100:.0f}% of it; {ERROR_COVERS})"
    return (f"{scene_name}: {settings.last_patches:,} patches, {settings.last_paths:,} paths, "
            f"{settings.last_rays:,} rays, {settings.last_seconds:.2f} s ({settings.last_estimator}), mean path length "
            f"{settings.last_mean_path_length:.2f}, {reached}, stopped by {settings.last_stopped}")
