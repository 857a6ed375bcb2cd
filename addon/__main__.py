"""Command line: build or open a scene, solve, save the .blend, render a preview.

    python -m addon                          # built-in Cornell box -> out/cornell.blend, out/cornell.png
    python -m addon --scene fig1_r0.5        # a scene of sample_scenes/ (see --list)
    python -m addon --open room.blend --select-all --error 3
    blender --background room.blend --python-expr \\
        "import sys; sys.path.insert(0, '/path/to/repo'); from addon.__main__ import main; main(['--current'])"

Runs with the ``bpy`` module (pip package) or inside Blender.  The solve runs
synchronously through the same operator the panel uses (``radiosity.solve``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np


def _parser():
    p = argparse.ArgumentParser(prog="python -m addon", description=__doc__.split("\n")[0])
    src = p.add_mutually_exclusive_group()
    src.add_argument("--scene", default=None,
                     help="built-in 'cornell' (default) or a sample_scenes name, e.g. fig1_r0.5, cornell_box")
    src.add_argument("--open", metavar="FILE.blend", help="open this .blend and solve its selected meshes")
    src.add_argument("--current", action="store_true", help="use the scene already loaded (inside Blender)")
    p.add_argument("--list", action="store_true", help="list the scene names and exit")
    p.add_argument("--select-all", action="store_true", help="solve all mesh objects, not just the selection")
    p.add_argument("--output", "-o", metavar="FILE.blend", help="where to save (default out/<scene>.blend)")
    p.add_argument("--preview", metavar="FILE.png", help="preview image (default: next to the .blend)")
    p.add_argument("--no-preview", action="store_true", help="skip the preview render")
    p.add_argument("--estimator", choices=["finite", "biased_infinite"], default="finite")
    p.add_argument("--threshold", type=float, default=1e-3, help="t of the biased infinite estimator")
    p.add_argument("--error", type=float, default=3.0, help="relative RMS error target in percent (default 3)")
    p.add_argument("--patch-size", type=float, default=None,
                   help="largest patch edge in scene units (default: 1/20 of the scene's size; "
                   "sample_scenes keep the paper's patches)")
    p.add_argument("--exit-point", choices=["random", "hit"], default="random")
    p.add_argument("--sampling", choices=["independent", "stratified"], default="independent",
                   help="independent (the paper's) or stratified sources and low-discrepancy first rays")
    p.add_argument("--stop-rule", choices=["predicted", "measured"], default="predicted",
                   help="run the predicted paths, or until the measured error meets the target")
    p.add_argument("--colours", choices=["FACE", "VERTEX", "BOTH"], default="BOTH",
                   help="face colours (CORNER), vertex colours (POINT) or both")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--time-limit", type=float, default=0.0, help="seconds, 0 = none")
    p.add_argument("--threads", type=int, default=0, help="0 = automatic")
    p.add_argument("--resolution", type=int, default=480, help="preview width in pixels")
    p.add_argument("--samples", type=int, default=16, help="Cycles samples for the preview")
    return p


def _sample_scene_names():
    try:
        import sample_scenes

        return sorted(sample_scenes.SCENES)
    except ImportError:
        return []


def _repo_root():
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _ensure_registered():
    import bpy

    if not hasattr(bpy.types.Scene, "radiosity") or not hasattr(bpy.ops.radiosity, "solve"):
        import addon

        addon.register()


def build_sample_scene(name):
    """Objects for a sample_scenes scene (one object per part, one quad per patch), selected."""
    import bpy
    import sample_scenes
    from sample_scenes.blender import to_blender

    objects = to_blender(sample_scenes.build(name))
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    return objects


def world_bounds(objects):
    """(lo, hi) corners of the objects' world-space bounding box, read with foreach_get."""
    points = []
    for o in objects:
        co = np.empty(3 * len(o.data.vertices), dtype=np.float64)
        o.data.vertices.foreach_get("co", co)
        m = np.array(o.matrix_world, dtype=np.float64)
        points.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
    points = np.concatenate(points)
    return points.min(axis=0), points.max(axis=0)


def _camera_for(objects):
    """A camera inside the bounding box's front, looking in (+y)."""
    import bpy

    lo, hi = world_bounds(objects)
    c = (lo + hi) / 2
    size = hi - lo
    data = bpy.data.cameras.new("Preview Camera")
    data.lens = 18
    cam = bpy.data.objects.new("Preview Camera", data)
    bpy.context.scene.collection.objects.link(cam)
    cam.location = (c[0], lo[1] + 0.02 * size[1], c[2])
    cam.rotation_euler = (math.pi / 2, 0.0, 0.0)
    bpy.context.scene.camera = cam
    return cam


def render_preview(path, sources, width=480, samples=16, exposure=0.0):
    """Render the result objects (their baked colours as emission) with Cycles.

    The source objects are hidden from the render only while it runs.
    """
    import bpy

    scene = bpy.context.scene
    hidden = [(o, o.hide_render) for o in sources]
    for o, _ in hidden:
        o.hide_render = True
    try:
        scene.render.engine = "CYCLES"
        scene.cycles.device = "CPU"
        scene.cycles.samples = samples
        scene.cycles.max_bounces = 0  # the light transport is baked in the colours
        scene.cycles.use_denoising = False
        scene.render.resolution_x = width
        scene.render.resolution_y = int(width * 3 / 4) if scene.camera.data.lens < 30 else width
        scene.render.resolution_percentage = 100
        scene.render.image_settings.file_format = "PNG"
        scene.view_settings.view_transform = "Standard"
        scene.view_settings.exposure = exposure
        if scene.world is None:
            scene.world = bpy.data.worlds.new("World")
        scene.world.color = (0.0, 0.0, 0.0)
        if scene.world.node_tree is not None:
            bg = scene.world.node_tree.nodes.get("Background")
            if bg is not None:
                bg.inputs["Color"].default_value = (0, 0, 0, 1)
        scene.render.filepath = os.path.abspath(path)
        bpy.ops.render.render(write_still=True)
    finally:
        for o, h in hidden:
            o.hide_render = h


def main(argv=None):
    args = _parser().parse_args(sys.argv[1:] if argv is None else argv)
    names = ["cornell"] + _sample_scene_names()
    if args.list:
        print("\n".join(names))
        return 0
    root = _repo_root()
    if root not in sys.path:
        sys.path.insert(0, root)
    import bpy

    from . import scene_io

    t0 = time.perf_counter()
    scene_name = args.scene or "cornell"
    if args.open:
        bpy.ops.wm.open_mainfile(filepath=os.path.abspath(args.open))
        scene_name = os.path.splitext(os.path.basename(args.open))[0]
    elif args.current:
        scene_name = os.path.splitext(os.path.basename(bpy.data.filepath))[0] or "scene"
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
    _ensure_registered()
    if not (args.open or args.current):
        if scene_name == "cornell":
            from .scenes import cornell_box

            cornell_box()
        elif scene_name in _sample_scene_names():
            build_sample_scene(scene_name)
        else:
            print(f"error: unknown scene {scene_name!r}; choose from: {', '.join(names)}", file=sys.stderr)
            return 2
    if args.select_all:
        for o in bpy.context.view_layer.objects:
            o.select_set(o.type == "MESH" and not scene_io.is_result_object(o))
    sources = scene_io.source_objects(bpy.context)
    if not sources:
        print("error: no mesh object selected (use --select-all)", file=sys.stderr)
        return 2

    settings = bpy.context.scene.radiosity
    settings.estimator = args.estimator
    settings.threshold = args.threshold
    settings.target_error = args.error
    if args.patch_size is None and scene_name in _sample_scene_names() and not (args.open or args.current):
        # sample scenes come meshed as in the paper: keep their patches
        args.patch_size = 1e6
    if args.patch_size is None:
        lo, hi = world_bounds(sources)
        args.patch_size = float(np.max(hi - lo)) / 20.0
    settings.patch_size = args.patch_size
    settings.exit_point = args.exit_point
    settings.sampling = args.sampling
    settings.stop_rule = args.stop_rule
    settings.output = args.colours
    settings.seed = args.seed
    settings.time_limit = args.time_limit
    settings.threads = args.threads

    result = bpy.ops.radiosity.solve()
    if "FINISHED" not in result:
        print("error: the solve did not finish", file=sys.stderr)
        return 1
    print(
        f"{scene_name}: {settings.last_patches} patches, {settings.last_paths} paths, "
        f"{int(settings.last_rays)} rays, {settings.last_seconds:.2f} s, "
        f"mean path length {settings.last_mean_path_length:.2f}, predicted MSE {settings.last_predicted_mse:.3g}"
    )
    out_blend = args.output or os.path.join("out", f"{scene_name}.blend")
    os.makedirs(os.path.dirname(os.path.abspath(out_blend)), exist_ok=True)

    if not args.no_preview:
        if bpy.context.scene.camera is None:
            _camera_for(sources)
        exposure = _auto_exposure(scene_io)
        png = args.preview or os.path.splitext(out_blend)[0] + ".png"
        render_preview(png, sources, args.resolution, args.samples, exposure)
        print(f"preview: {os.path.abspath(png)}")
    bpy.ops.wm.save_as_mainfile(filepath=os.path.abspath(out_blend))
    print(f"saved: {os.path.abspath(out_blend)}  ({time.perf_counter() - t0:.1f} s in all)")
    return 0


def _auto_exposure(scene_io):
    """Exposure (stops) that maps the median reflected radiosity to 0.35."""
    values = []
    for obj in scene_io.previous_results():
        attr = obj.data.color_attributes.get(scene_io.ATTRIBUTE_NAME)
        if attr is None:
            continue
        c = np.empty(len(attr.data) * 4, dtype=np.float32)
        attr.data.foreach_get("color", c)
        values.append(c.reshape(-1, 4)[:, :3].mean(axis=1))
    if not values:
        return 0.0
    v = np.concatenate(values)
    v = v[v > 0]
    if not len(v):
        return 0.0
    median = float(np.median(v))
    return float(np.clip(math.log2(0.35 / median), -10, 10)) if median > 0 else 0.0


if __name__ == "__main__":
    sys.exit(main())
