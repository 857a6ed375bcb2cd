"""The picture an artist sees: the product's preview against Cycles, pixel by pixel, in interiors
the product was not tuned for (``interior_scene.py``: a room with a window, sun and sky, a point
and an area lamp; a closed room with a spot lamp and an emissive strip; default Principled
materials, textured floors, furniture, a subdivided ball or stool).

    nice -n 10 .venv/bin/python -m benchmarks.picture                  # both rooms -> results/picture.md + PNGs
    nice -n 10 .venv/bin/python -m benchmarks.picture --colours VERTEX # the product's output mode (the panel's Colours)
    .venv/bin/python -m benchmarks.picture --quick                    # smoke run into out/picture_quick/

Per room, in one process: the reference (Cycles, 64 bounces, no clamping, two independent halves
of ``--reference-samples``, cached in out/picture_cache/ by the scene's content); then rounds
alternating the product (the panel's operator at its defaults, its error target ``--error``, as the
command line runs it, then its preview: ``addon/cli/preview.py``'s settings, live results with one
bounce and the denoiser, ``--preview-samples``, at 320 x 240) and Cycles on the original scene at
the product's wall time (the first round's sample counts from a timing fit in the same run, each
later round's tracked to the product's last time), with OpenImageDenoise and without.
Every image is rendered to a float EXR and compared on surface pixels (``picture_metrics``).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
CACHE = ROOT / "out" / "picture_cache"

from benchmarks import interior_scene  # noqa: E402
from benchmarks import picture_metrics as pm  # noqa: E402

from addon.bpy_free.options import TARGET_ERROR as _PANEL_TARGET  # noqa: E402
from addon.cli.arguments import LIVE_SAMPLES  # noqa: E402

TARGET_ERROR = _PANEL_TARGET.default  # percent, the panel's default (--error)
PREVIEW_SAMPLES = LIVE_SAMPLES  # the command line's preview default with live lamps, the default (--preview-samples)
THREADS = 2


# --------------------------------------------------------------------------- rendering

def render_exr(scene):
    """Render the scene's camera to a float EXR and read it back: ((H, W, 3) linear RGB top row
    first, wall seconds of the render and its file)."""
    import bpy

    image = scene.render.image_settings
    image.media_type = "IMAGE"
    image.file_format = "OPEN_EXR"
    image.color_depth = "32"
    image.color_mode = "RGB"
    folder = tempfile.mkdtemp(prefix="picture_")
    path = os.path.join(folder, "render.exr")
    scene.render.filepath = path
    wall = time.perf_counter()
    bpy.ops.render.render(write_still=True)
    wall = time.perf_counter() - wall
    loaded = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = loaded.size[:]
        pixels = np.empty(width * height * loaded.channels, np.float32)
        loaded.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(loaded)
        os.remove(path)
        os.rmdir(folder)
    return np.ascontiguousarray(pixels.reshape(height, width, -1)[::-1, :, :3]), wall


def linear_view(scene):
    """Standard view at exposure 0: the EXR holds the render's own linear values."""
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0


def configure_cycles(scene, samples, denoise=False, seed=0, unbiased=True):
    """Cycles on the CPU, 2 threads, fixed samples (no adaptive sampling). ``unbiased``: 64
    bounces of every kind, no clamping, no glossy blur (the reference's settings: it converges
    to the truth); else Cycles' default light paths (12 bounces, 4 diffuse, 4 glossy, indirect
    clamped at 10, caustics filtered)."""
    scene.render.engine = "CYCLES"
    scene.render.threads_mode = "FIXED"
    scene.render.threads = THREADS
    c = scene.cycles
    c.device = "CPU"
    c.samples = samples
    c.use_adaptive_sampling = False
    c.use_denoising = denoise
    c.denoiser = "OPENIMAGEDENOISE"
    c.seed = seed
    light_paths(scene, unbiased)
    scene.render.film_transparent = False
    linear_view(scene)


def light_paths(scene, unbiased=True):
    """Cycles' light paths: the reference's (``unbiased``: 64 bounces, no clamping, Filter Glossy
    0) or Cycles' defaults. Filter Glossy changes what a Principled surface passes on in the
    solve too (``blender_read.materials.transport_terms``)."""
    c = scene.cycles
    if unbiased:
        c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = 64
        c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
        c.blur_glossy = 0.0
    else:
        c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces = 12, 4, 4, 12
        c.sample_clamp_direct, c.sample_clamp_indirect, c.blur_glossy = 0.0, 10.0, 1.0


def show_results(visible):
    """Result objects rendered (the preview) or hidden (Cycles on the original scene)."""
    from addon.blender_write.results import previous_results

    for obj in previous_results():
        obj.hide_render = not visible


def cycles_image(samples, denoise=False, seed=0, unbiased=True):
    """Cycles' render of the original scene: (image, wall seconds)."""
    import bpy

    scene = bpy.context.scene
    show_results(False)
    configure_cycles(scene, samples, denoise, seed, unbiased)
    return render_exr(scene)


# --------------------------------------------------------------------------- the reference

LIGHT_SETTINGS = ("type", "energy", "color", "shadow_soft_size", "use_soft_falloff", "use_shadow", "normalize", "exposure",
                  "use_temperature", "temperature", "spot_size", "spot_blend", "shape", "size", "size_y", "spread", "angle")
CAMERA_SETTINGS = ("type", "lens", "sensor_width", "sensor_height", "sensor_fit", "shift_x", "shift_y", "clip_start", "clip_end")


def _plain(value):
    return tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value


def scene_fingerprint():
    """A hash of what the render sees: every object's evaluated vertices and transform, its
    materials' input values, lamps' and camera's settings, the world and the packed images."""
    import bpy

    h = hashlib.sha256()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for obj in sorted(bpy.context.scene.objects, key=lambda o: o.name):
        h.update(obj.name.encode())
        h.update(np.array(obj.matrix_world, np.float64).tobytes())
        if obj.type == "MESH":
            mesh = obj.evaluated_get(depsgraph).to_mesh()
            co = np.empty(3 * len(mesh.vertices), np.float32)
            mesh.vertices.foreach_get("co", co)
            obj.evaluated_get(depsgraph).to_mesh_clear()
            h.update(co.tobytes())
            for material in obj.data.materials:
                for node in material.node_tree.nodes:
                    for socket in node.inputs:
                        value = getattr(socket, "default_value", None)
                        h.update(repr(tuple(value) if hasattr(value, "__len__") else value).encode())
        elif obj.type in ("LIGHT", "CAMERA"):  # (settings by name: an ID's own numbers, session_uid, change per run)
            names = LIGHT_SETTINGS if obj.type == "LIGHT" else CAMERA_SETTINGS
            h.update(repr([_plain(getattr(obj.data, n, None)) for n in names]).encode())
    world = bpy.context.scene.world
    if world is not None:
        for node in world.node_tree.nodes:
            for socket in node.inputs:
                value = getattr(socket, "default_value", None)
                h.update(repr(tuple(value) if hasattr(value, "__len__") else value).encode())
    for image in sorted((i for i in bpy.data.images if i.packed_file is not None), key=lambda i: i.name):
        pixels = np.empty(len(image.pixels), np.float32)
        image.pixels.foreach_get(pixels)
        h.update(pixels.tobytes())
    h.update(bpy.app.version_string.encode())
    return h.hexdigest()[:16]


def reference(name, samples, log=print):
    """The reference of the scene built now: (first half, second half) images of samples / 2
    each with different seeds, and the wall seconds; cached by the scene's fingerprint."""
    import bpy

    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"{name}_{scene_fingerprint()}_{samples}.npz"
    if path.exists():
        data = np.load(path)
        return data["first"], data["second"], float(data["seconds"])
    halves, seconds = [], 0.0
    for seed in (101, 202):
        log(f"{name}: reference half of {samples // 2} samples (seed {seed}) ...")
        image, wall = cycles_image(samples // 2, seed=seed)
        halves.append(image)
        seconds += wall
    np.savez_compressed(path, first=halves[0], second=halves[1], seconds=seconds)
    bpy.context.scene.cycles.seed = 0
    return halves[0], halves[1], seconds


# --------------------------------------------------------------------------- the product

def source_objects():
    """Every mesh that is not a result, selected (the command line's --select-all)."""
    import bpy

    from addon.blender_read.objects import is_result_object

    bpy.context.view_layer.update()  # (a view layer lists its objects once updated)
    objects = []
    for obj in bpy.context.view_layer.objects:
        take = obj.type == "MESH" and not is_result_object(obj)
        obj.select_set(take)
        if take:
            objects.append(obj)
    bpy.context.view_layer.objects.active = objects[0]
    return sorted(objects, key=lambda o: o.name)


def prepare_product(scene, colours, seed=0):
    """The panel's settings at their defaults but the error target, ``colours`` and ``seed``, and
    the reference's light paths: the product solves the scene the reference renders (a Cycles
    render at default light paths before it leaves Filter Glossy 1, and the solve passes on less
    specular light). The scene's radiosity settings."""
    from addon.bpy_free import options

    settings = scene.radiosity
    for option in options.SETTINGS:
        setattr(settings, option.name, option.default)
    settings.target_error, settings.output, settings.seed = TARGET_ERROR, colours, seed
    light_paths(scene, unbiased=True)
    return settings


def product(colours, seed=0, width=interior_scene.RESOLUTION[0], **overrides):
    """The product as the command line runs it: the panel's settings at their defaults but the
    error target (TARGET_ERROR), the output mode ``colours`` and the seed (and ``overrides``, settings by
    name: a detail, a patch size, a time limit); the operator, then the preview (its settings,
    rendered to EXR). (image, solve seconds, preview seconds, statistics)."""
    import bpy

    from addon.cli import preview
    from addon.cli.run import release_solve_memory
    from addon.blender_write import solve_job

    scene = bpy.context.scene
    sources = source_objects()
    settings = prepare_product(scene, colours, seed)
    for name, value in overrides.items():  # (given as text on the command line: read as the setting's type)
        current = getattr(settings, name)
        setattr(settings, name, type(current)(value) if isinstance(value, str) and not isinstance(current, str) else value)
    wall = time.perf_counter()
    finished = solve_job.run(bpy.context)  # (what the panel's operator runs)
    release_solve_memory()
    solve = time.perf_counter() - wall
    if finished.status != "FINISHED":
        raise RuntimeError(f"the solve failed: {finished.error}")
    show_results(True)
    changes = preview.preview_settings(scene, sources, width, PREVIEW_SAMPLES, 0.0)
    hidden = [(o, o.hide_render) for o in sources]
    try:
        for o, _ in hidden:
            o.hide_render = True
        scene.render.threads_mode, scene.render.threads = "FIXED", THREADS
        image, shown = render_exr(scene)
    finally:
        for o, h in hidden:
            o.hide_render = h
        changes.restore()
    stats = {"patches": settings.last_patches, "patch_size": settings.last_patch_size, "error": settings.last_relative_error,
             "method": settings.last_estimator, "solver_seconds": settings.last_seconds}
    return image, solve, shown, stats


# --------------------------------------------------------------------------- what each pixel shows

def camera_rays(camera, width, height):
    """(origins (N,3), unit directions (N,3)) of the rays through the pixel centres, row 0 at
    the top (a perspective camera, sensor fit AUTO)."""
    data = camera.data
    m = np.array(camera.matrix_world, np.float64)
    half = 0.5 * data.sensor_width / data.lens  # AUTO: the sensor width spans the longer side
    half_x, half_y = (half, half * height / width) if width >= height else (half * width / height, half)
    u = ((np.arange(width) + 0.5) / width * 2 - 1) * half_x
    v = (1 - (np.arange(height) + 0.5) / height * 2) * half_y
    uu, vv = np.meshgrid(u, v)
    local = np.stack([uu, vv, -np.ones_like(uu)], axis=-1).reshape(-1, 3)
    directions = local @ m[:3, :3].T
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return np.broadcast_to(m[:3, 3], directions.shape).copy(), directions


def mesh_triangles(objects):
    """(corners (T,3,3) world space, object index (T,), polygon index (T,)) of the objects as
    evaluated (modifiers applied)."""
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    corners, owners, polygons = [], [], []
    for k, obj in enumerate(objects):
        evaluated = obj.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            mesh.calc_loop_triangles()
            co = np.empty(3 * len(mesh.vertices), np.float32)
            mesh.vertices.foreach_get("co", co)
            tri = np.empty(3 * len(mesh.loop_triangles), np.int32)
            mesh.loop_triangles.foreach_get("vertices", tri)
            poly = np.empty(len(mesh.loop_triangles), np.int32)
            mesh.loop_triangles.foreach_get("polygon_index", poly)
        finally:
            evaluated.to_mesh_clear()
        m = np.array(evaluated.matrix_world, np.float64)
        points = co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]
        corners.append(points[tri.reshape(-1, 3)])
        owners.append(np.full(len(poly), k, np.int32))
        polygons.append(poly)
    return np.concatenate(corners), np.concatenate(owners), np.concatenate(polygons)


def first_hits(corners, origins, directions):
    """(triangle index (-1 none), distance) of each ray's first hit (Embree)."""
    from addon.core.scene.raytrace import RayTracer

    tracer = RayTracer(corners)
    hit, _, _, t, _ = tracer.first_hit_barycentric(origins.astype(np.float32), directions.astype(np.float32))
    return hit, np.where(hit >= 0, t, np.inf)


def lamp_distances(lamps, origins, directions):
    """Distance along each ray to the nearest lamp it sees (inf where none): a point or spot
    lamp's sphere of its radius, an area lamp's rectangle or disc (both sides)."""
    best = np.full(len(origins), np.inf)
    for obj in lamps:
        data = obj.data
        m = np.array(obj.matrix_world, np.float64)
        if data.type in ("POINT", "SPOT") and data.shadow_soft_size > 0:
            c = m[:3, 3] - origins
            along = np.einsum("ij,ij->i", c, directions)
            miss2 = np.einsum("ij,ij->i", c, c) - along**2
            inside = miss2 <= data.shadow_soft_size**2
            t = along - np.sqrt(np.where(inside, data.shadow_soft_size**2 - miss2, 0.0))
            t = np.where(inside & (t > 0), t, np.inf)
        elif data.type == "AREA":
            normal = m[:3, 2] / np.linalg.norm(m[:3, 2])
            denominator = directions @ normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((m[:3, 3] - origins) @ normal) / denominator
            t = np.where(np.isfinite(t), t, -1.0)  # parallel to the lamp: never hits it
            p = origins + t[:, None] * directions - m[:3, 3]
            x = p @ (m[:3, 0] / np.linalg.norm(m[:3, 0])) / (0.5 * data.size * np.linalg.norm(m[:3, 0]))
            size_y = data.size_y if data.shape in ("RECTANGLE", "ELLIPSE") else data.size
            y = p @ (m[:3, 1] / np.linalg.norm(m[:3, 1])) / (0.5 * size_y * np.linalg.norm(m[:3, 1]))
            inside = (x * x + y * y <= 1) if data.shape in ("DISK", "ELLIPSE") else ((np.abs(x) <= 1) & (np.abs(y) <= 1))
            t = np.where(inside & (t > 0), t, np.inf)
        else:
            continue
        best = np.minimum(best, t)
    return best


def junctions(points, normals, owner, corners, triangle_owner, reach=0.1, directions=8):
    """Pixels whose surface point lies within ``reach`` of another object along the surface:
    probes in ``directions`` tangent directions from just above the point (edges where boxes
    meet: a wall and the ceiling, furniture on the floor)."""
    from addon.core.scene.raytrace import RayTracer

    tracer = RayTracer(corners)
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    helper = np.where(np.abs(n[:, 2:3]) < 0.9, np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, 0.0, 0.0]]))
    a = np.cross(n, helper)
    a /= np.linalg.norm(a, axis=1, keepdims=True)
    b = np.cross(n, a)
    start = (points + 2e-3 * n).astype(np.float32)
    near = np.zeros(len(points), bool)
    for k in range(directions):
        angle = 2 * math.pi * k / directions
        d = (math.cos(angle) * a + math.sin(angle) * b).astype(np.float32)
        hit, _, _, t, _ = tracer.first_hit_barycentric(start, d)
        near |= (hit >= 0) & (t <= reach) & (triangle_owner[np.maximum(hit, 0)] != owner)
    return near


def pixel_map(info, results):
    """What each pixel shows, at pixel centres: object id (index into ``info.meshes``, -1 for the
    background), lamp in front, patch id (the result objects' polygons, -1 where no result) and
    junction pixels. A dict of (H, W) arrays."""
    import bpy

    width, height = interior_scene.RESOLUTION
    camera = bpy.data.objects[info.camera]
    origins, directions = camera_rays(camera, width, height)
    objects = [bpy.data.objects[name] for name in info.meshes]
    corners, owner, _ = mesh_triangles(objects)
    hit, t = first_hits(corners, origins, directions)
    object_id = np.where(hit >= 0, owner[np.maximum(hit, 0)], -1)
    lamp = lamp_distances([bpy.data.objects[name] for name in info.lamps], origins, directions) < t
    points = origins + np.where(np.isfinite(t), t, 0.0)[:, None] * directions
    tri = corners[np.maximum(hit, 0)]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals *= -np.sign(np.einsum("ij,ij->i", normals, directions))[:, None]  # towards the camera
    seen = hit >= 0
    junction = np.zeros(len(hit), bool)
    junction[seen] = junctions(points[seen], normals[seen], object_id[seen], corners, owner)
    patch_id = np.full(len(hit), -1, np.int64)
    if results:
        r_corners, r_owner, r_poly = mesh_triangles(results)
        offsets = np.concatenate([[0], np.cumsum([len(o.data.polygons) for o in results])])
        r_hit, _ = first_hits(r_corners, origins, directions)
        patch_id = np.where(r_hit >= 0, offsets[r_owner[np.maximum(r_hit, 0)]] + r_poly[np.maximum(r_hit, 0)], -1)
    shape = (height, width)
    return {"object_id": object_id.reshape(shape), "lamp": lamp.reshape(shape), "patch_id": patch_id.reshape(shape),
            "junction": junction.reshape(shape)}


# --------------------------------------------------------------------------- the run

#: Cycles at the product's wall time: (denoise, unbiased light paths), by name.
CYCLES_KINDS = {"cycles_denoised": (True, True), "cycles_raw": (False, True), "cycles_default_denoised": (True, False)}
LABELS = {"product": "the product's preview", "cycles_denoised": "Cycles, same wall time, OpenImageDenoise",
          "cycles_raw": "Cycles, same wall time, no denoiser",
          "cycles_default_denoised": "Cycles' default light paths (4 diffuse bounces, clamp 10), same time, OpenImageDenoise"}


def time_lines(log=print):
    """Each Cycles kind's render time as a line through renders of 1 and 4 samples, timed now:
    kind -> (seconds of 1 sample, seconds a further sample)."""
    lines = {}
    for kind, (denoise, unbiased) in CYCLES_KINDS.items():
        walls = [cycles_image(n, denoise, 7, unbiased)[1] for n in (1, 4)]
        lines[kind] = (walls[0], max((walls[1] - walls[0]) / 3, 1e-3))
        log(f"  {kind}: 1 sample {walls[0]:.2f} s, 4 samples {walls[1]:.2f} s")
    return lines


def samples_for(seconds, line, most):
    """The sample count whose render takes ``seconds`` on a time line, at least 1, at most ``most``."""
    first, per_sample = line
    return int(min(max(1, round(1 + (seconds - first) / per_sample)), most))


def tracked(samples, seconds, wall, most):
    """The next round's sample count: ``samples`` took ``wall`` seconds where the product took
    ``seconds`` (render time is about proportional to samples; at least 1, at most ``most``)."""
    return int(min(max(1, round(samples * seconds / max(wall, 1e-3))), most))


def measure(name, colours, reference_samples, rounds, diffuse=False, warm_up=True, most=1 << 16, log=print, **overrides):
    """One room: the reference, then rounds alternating the product and Cycles at its wall time
    (the first round's sample counts from its product time on lines timed before, each later
    round's from the one before, ``tracked`` to the product's time; at most ``most``), and the
    pixel map; a dict of images, times and statistics. ``diffuse``: every
    material's Specular IOR Level set to 0 first (Lambertian surfaces, the product's own model);
    ``overrides`` the product's settings by name."""
    info = interior_scene.build(name)
    if diffuse:
        interior_scene.make_diffuse()
    first, second, reference_seconds = reference(name, reference_samples, log)
    if warm_up:
        log(f"{name}: warming up (a solve and a render, not counted)")
        product(colours, seed=99, **overrides)
    cycles_image(1)
    lines = time_lines(log)
    samples = {}
    runs = {"product": [], **{kind: [] for kind in CYCLES_KINDS}}
    for k in range(rounds):  # alternating, so that a busy moment of the machine hits every side
        image, solve, shown, stats = product(colours, seed=k, **overrides)
        runs["product"].append({"image": image, "seconds": solve + shown, "solve": solve, "preview": shown, "stats": stats})
        if not samples:
            samples = {kind: samples_for(solve + shown, line, most) for kind, line in lines.items()}
        else:
            samples = {kind: tracked(n, solve + shown, runs[kind][-1]["seconds"], most) for kind, n in samples.items()}
        for kind, (denoise, unbiased) in CYCLES_KINDS.items():
            image, wall = cycles_image(samples[kind], denoise, k, unbiased)
            runs[kind].append({"image": image, "seconds": wall, "samples": samples[kind]})
        log(f"{name}: round {k}: product {solve:.2f} + {shown:.2f} s, " + ", ".join(
            f"{kind} {samples[kind]} samples {runs[kind][-1]['seconds']:.2f} s" for kind in CYCLES_KINDS))
    from addon.blender_write.results import previous_results

    pixels = pixel_map(info, previous_results())  # the last round's patches (same patch layout every round)
    return {"info": info, "first": first, "second": second, "reference_seconds": reference_seconds,
            "reference_samples": reference_samples, "samples": samples, "runs": runs, "pixels": pixels}


def analyse(m):
    """The numbers of one room (``measure``'s dict): errors, times, per-object brightness, where
    the error lies."""
    info, px = m["info"], m["pixels"]
    ref = 0.5 * (m["first"] + m["second"])
    emitters = [info.meshes.index(name) for name in info.emitters]
    mask = pm.surface_mask(px["object_id"], emitters, px["lamp"])
    variance = pm.reference_variance(m["first"], m["second"])
    out = {"surface_pixels": int(mask.sum()), "reference_error": pm.halves_error(m["first"], m["second"], mask),
           "reference_rms": float(np.sqrt(variance[mask].mean()) / pm.luminance(ref)[mask].mean()),
           "reference_seconds": m["reference_seconds"], "reference_samples": m["reference_samples"],
           "samples": m["samples"], "kinds": {}}
    for kind, runs in m["runs"].items():
        errors = [pm.relative_mae(r["image"], ref, mask) for r in runs]
        rms = [pm.relative_rms(r["image"], ref, mask, variance) for r in runs]
        out["kinds"][kind] = {"errors": errors, "rms": rms, "seconds": [r["seconds"] for r in runs],
                              "samples": [r.get("samples") for r in runs]}
    runs = m["runs"]["product"]
    out["kinds"]["product"].update(solve=[r["solve"] for r in runs], preview=[r["preview"] for r in runs], stats=runs[0]["stats"])
    patched = mask & (px["patch_id"] >= 0)
    flat = pm.patch_means(ref, px["patch_id"], patched)
    out["flat_reference"] = pm.relative_mae(flat, ref, patched)
    out["flat_reference_rms"] = pm.relative_rms(flat, ref, patched, variance)
    out["product_vs_flat"] = pm.relative_mae(runs[0]["image"], flat, patched)
    count = len(info.meshes)
    means = {kind: pm.object_means(m["runs"][kind][0]["image"], px["object_id"], mask, count) for kind in m["runs"]}
    means["reference"] = pm.object_means(ref, px["object_id"], mask, count)
    halves = [pm.object_means(h, px["object_id"], mask, count) for h in (m["first"], m["second"])]
    means["reference_spread"] = 0.5 * np.abs(halves[0] - halves[1])
    pixels = pm.object_pixels(px["object_id"], mask, count)
    out["objects"] = [{"name": info.meshes[i], "pixels": int(pixels[i]),
                       **{kind: means[kind][i].tolist() for kind in means}} for i in range(count) if pixels[i] >= 20]
    exposure = pm.exposure_for(ref, mask)
    regions = {"hot spots (reference brighter than display white)": pm.luminance(ref) * 2.0**exposure > 1.0,
               "patch boundaries inside an object": pm.boundaries(px["patch_id"]) & ~pm.boundaries(px["object_id"]),
               "within 10 cm of another object (junctions)": px["junction"],
               f"the textured {info.textured.lower()}": px["object_id"] == info.meshes.index(info.textured)}
    out["where"] = {kind: pm.error_shares(m["runs"][kind][0]["image"], ref, mask, regions, variance)
                    for kind in ("product", "cycles_denoised")}
    out["exposure"] = exposure
    return out, ref, mask


# --------------------------------------------------------------------------- the report

def side_by_side(m, ref, mask, exposure, path):
    """reference | product | Cycles denoised | Cycles raw (round 0), over their false-colour
    luminance errors (the reference's own: half its halves' difference)."""
    from PIL import Image, ImageDraw, ImageFont

    kinds = ("product", "cycles_denoised", "cycles_raw")
    images = [ref] + [m["runs"][k][0]["image"] for k in kinds]
    top = [pm.to_display(i, exposure) for i in images]
    reference_noise = ref + 0.5 * (m["first"] - m["second"])  # as far from ref as ref is from the truth
    bottom = [pm.error_display(reference_noise, ref, mask)] + [pm.error_display(i, ref, mask) for i in images[1:]]
    height, width = ref.shape[:2]
    label = 14
    canvas = Image.new("RGB", (4 * width, 2 * (height + label)), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    font = ImageFont.load_default(size=11)
    names = ["reference", "product", "Cycles same time, denoised", "Cycles same time, raw"]
    for column, (upper, lower, name) in enumerate(zip(top, bottom, names)):
        canvas.paste(Image.fromarray(upper), (column * width, label))
        canvas.paste(Image.fromarray(lower), (column * width, 2 * label + height))
        draw.text((column * width + 4, 1), name, fill=(0, 0, 0), font=font)
        draw.text((column * width + 4, height + label + 1), "|error| (white: 50% of mean)" if column else
                  "reference's own error", fill=(0, 0, 0), font=font)
    canvas.save(path)


def _seconds(values):
    return statistics.median(values)


def room_section(name, a, colours, png):
    kinds = a["kinds"]
    p = kinds["product"]
    stats = p["stats"]
    lines = [f"## {name}", "",
             f"Reference: Cycles, {a['reference_samples']} samples (two halves of different seeds), 64 bounces, no "
             f"clamping ({a['reference_seconds'] / 60:.0f} min); its own error from its halves: "
             f"{100 * a['reference_error']:.1f}% mean absolute, {100 * a['reference_rms']:.1f}% RMS. "
             f"{a['surface_pixels']:,} surface pixels of 320 x 240. The product: {stats['patches']:,} patches of "
             f"{stats['patch_size']:.3g} m, {stats['method']}, its error estimate {stats['error']:.2f}% (target {TARGET_ERROR:g}%), "
             f"output `{colours}`. {len(p['errors'])} round(s), seeds 0-{len(p['errors']) - 1}.", "",
             "| image | mean abs. error (rounds: mean; range) | RMS error, the reference's noise taken out | wall time (median) | samples |",
             "|---|---|---|---|---|"]
    for kind, label in LABELS.items():
        k = kinds[kind]
        e, r = np.array(k["errors"]) * 100, np.array(k["rms"]) * 100
        if kind == "product":
            time_text = f"{_seconds(k['seconds']):.2f} s (solve {_seconds(p['solve']):.2f} + preview {_seconds(p['preview']):.2f})"
            samples = f"{PREVIEW_SAMPLES} (preview)"
        else:
            used = [n for n in k.get("samples", []) if n] or [a["samples"][kind]]
            ratio = np.array(k["seconds"]) / np.array(p["seconds"])  # (round by round: the same time, as tracked)
            time_text = f"{_seconds(k['seconds']):.2f} s ({ratio.min():.2f}-{ratio.max():.2f} of the product's)"
            samples = f"{min(used)}-{max(used)}" if min(used) != max(used) else str(used[0])
        lines.append(f"| {label} | {e.mean():.1f}% ({e.min():.1f}-{e.max():.1f}) | {r.mean():.1f}% ({r.min():.1f}-{r.max():.1f}) "
                     f"| {time_text} | {samples} |")
    lines += [f"| the reference made flat per patch (each patch's visible pixels averaged) | {100 * a['flat_reference']:.1f}% "
              f"| {100 * a['flat_reference_rms']:.1f}% | - | - |",
              f"| the product against that flat reference | {100 * a['product_vs_flat']:.1f}% | - | - | - |", "",
              f"![{name}]({png})", "",
              "Per-object brightness: the mean luminance of the object's surface pixels (round 0) over the reference's; "
              "± the reference's own uncertainty (half its halves' difference); the product's R, G, B the same per channel:", "",
              "| object | pixels | product | product R, G, B | Cycles denoised | Cycles raw |", "|---|---|---|---|---|---|"]
    for o in a["objects"]:
        ref = np.array(o["reference"])
        y = {k: float(pm.luminance(np.array(o[k])) / pm.luminance(ref)) for k in ("product", "cycles_denoised", "cycles_raw")}
        spread = float(pm.luminance(np.array(o["reference_spread"])) / pm.luminance(ref))
        rgb = ", ".join(f"{v:.2f}" for v in np.array(o["product"]) / np.maximum(ref, 1e-12))
        lines.append(f"| {o['name']} | {o['pixels']:,} | {y['product']:.3f} ± {spread:.3f} | {rgb} | {y['cycles_denoised']:.3f} "
                     f"| {y['cycles_raw']:.3f} |")
    lines += ["", "Where the error lies (round 0): each region's share of the surface pixels, of the absolute luminance "
              "error, and of the squared error with the reference's noise taken out:", "",
              "| region | pixels | product: abs. error | product: squared error | Cycles denoised: abs. | Cycles denoised: squared |",
              "|---|---|---|---|---|---|"]
    for region, (pixels, share, square) in a["where"]["product"].items():
        _, d_share, d_square = a["where"]["cycles_denoised"][region]
        lines.append(f"| {region} | {100 * pixels:.1f}% | {100 * share:.0f}% | {100 * square:.0f}% | {100 * d_share:.0f}% "
                     f"| {100 * d_square:.0f}% |")
    return lines + [""]


def report(rooms, colours, command, loads, out):
    lines = ["# The picture: the product's preview against Cycles, pixel by pixel", "",
             f"`{command}`: interiors built by `benchmarks/interior_scene.py` (default Principled materials, walls "
             "of overlapping boxes, packed image textures on the floors, furniture, a subdivided ball or stool), the "
             f"product at the panel's defaults and a {TARGET_ERROR:g}% target, output `{colours}`, its preview at 320 x 240 "
             f"({PREVIEW_SAMPLES} samples; live results with one bounce and the denoiser), against a Cycles reference. Errors on luminance over the "
             "surface pixels (emitters, lamps, background and the pixels next to them excluded), relative to the "
             "reference's mean luminance there: the mean absolute error against the reference as it is (its own noise "
             "included), and the RMS error with the reference's own variance (from its two halves) subtracted: an "
             "estimate of the error against the truth. Cycles at the product's wall time: sample counts from a timing "
             "line fitted in the same run for the first round (capped where the product takes minutes), each later round's "
             "tracked to the product's last time, rounds alternating with the product. "
             f"Cycles and the product on {THREADS} threads each, under `nice`, on a 2-core machine shared with other "
             f"work (load average {loads[0]:.1f} at the start, {loads[1]:.1f} at the end): times compare within a "
             "room's rounds, not across runs.", ""]
    for name, (a, png) in rooms.items():
        lines += room_section(name, a, colours, png)
    out.write_text("\n".join(lines))


def main(argv=None):
    global TARGET_ERROR, PREVIEW_SAMPLES
    from addon.bpy_free import options

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--colours", default=options.OUTPUT.default, help="the product's output mode (the panel's Colours)")
    parser.add_argument("--scenes", nargs="+", default=list(interior_scene.SCENES), choices=list(interior_scene.SCENES))
    parser.add_argument("--reference-samples", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", type=Path, default=RESULTS / "picture.md", help="the report; its PNGs beside it")
    parser.add_argument("--diffuse", action="store_true", help="Specular IOR Level 0 on every material (a Lambertian "
                        "control: what is left of the brightness gap is not the specular layer)")
    parser.add_argument("--quick", action="store_true", help="64 reference samples, one round, into out/picture_quick/")
    parser.add_argument("--no-warm-up", dest="warm_up", action="store_false", help="no solve before the measured ones "
                        "(where a solve takes minutes its start-up is noise)")
    parser.add_argument("--max-samples", type=int, default=1 << 16, help="cap on Cycles' samples at the product's time "
                        "(where the product takes minutes; the report gives the times measured)")
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="the product's settings by name "
                        "(e.g. detail=MEDIUM)")
    parser.add_argument("--error", type=float, default=TARGET_ERROR, help="the product's error target, percent")
    parser.add_argument("--preview-samples", type=int, default=PREVIEW_SAMPLES, help="the preview's samples")
    parser.add_argument("--replot", action="store_true", help="rewrite the report from its .json (rooms measured so far)")
    args = parser.parse_args(argv)
    TARGET_ERROR, PREVIEW_SAMPLES = args.error, args.preview_samples
    if args.replot:
        saved = json.loads((args.out.parent / f"{args.out.stem}.json").read_text())
        rooms = {name: (a, f"{args.out.stem}_{name}.png") for name, a in saved.items() if name != "run"}
        report(rooms, saved["run"]["colours"], saved["run"]["command"], saved["run"]["loads"], args.out)
        return
    try:
        colours = options.OUTPUT.check(args.colours)
    except ValueError as exc:
        parser.error(str(exc))
    if args.quick:
        args.reference_samples, args.rounds, args.out = 64, 1, ROOT / "out" / "picture_quick" / "picture.md"
    args.out.parent.mkdir(parents=True, exist_ok=True)
    command = "python -m benchmarks.picture " + " ".join(argv if argv is not None else sys.argv[1:])
    loads = [os.getloadavg()[0]]
    rooms = {}
    for name in args.scenes:
        overrides = dict(item.split("=", 1) for item in args.set)
        m = measure(name, colours, args.reference_samples, args.rounds, args.diffuse, args.warm_up, args.max_samples,
                    **overrides)
        a, ref, mask = analyse(m)
        png = f"{args.out.stem}_{name}.png"
        side_by_side(m, ref, mask, a["exposure"], args.out.parent / png)
        rooms[name] = (a, png)
        run = {"colours": colours, "command": command.strip(), "loads": [loads[0], os.getloadavg()[0]]}
        (args.out.parent / f"{args.out.stem}.json").write_text(json.dumps({"run": run, **{n: r[0] for n, r in rooms.items()}}, indent=1))
    loads.append(os.getloadavg()[0])
    report(rooms, colours, command.strip(), loads, args.out)
    print(args.out.read_text())


if __name__ == "__main__":
    main()
