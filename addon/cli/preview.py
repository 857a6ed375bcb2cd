"""The preview: the result objects' baked colours rendered with Cycles (no bounces: the light
transport is in the colours; live results, one bounce through them), at an exposure from the results, with every setting it changed
put back afterwards (bpy and numpy, imported where used)."""

from __future__ import annotations

import math
import os
import sys


def world_bounds(objects):
    """(lo, hi) corners of the objects' world-space bounding box as Blender evaluates them:
    modifiers applied, and curves, text, surfaces and metaballs as tessellated -- the evaluated
    geometry's vertices (``to_mesh``, read with foreach_get; an evaluated curve's bound box
    holds its control points, not its bevel or extrusion). (0, 0) when there is no geometry."""
    import bpy
    import numpy as np

    depsgraph = bpy.context.evaluated_depsgraph_get()
    lows, highs = [], []
    for o in objects:
        evaluated = o.evaluated_get(depsgraph)
        mesh = evaluated.to_mesh()
        try:
            co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
            mesh.vertices.foreach_get("co", co)
        finally:
            evaluated.to_mesh_clear()
        if not len(co):
            continue
        m = np.array(evaluated.matrix_world, dtype=np.float64)
        points = co.reshape(-1, 3).astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        lows.append(points.min(axis=0))
        highs.append(points.max(axis=0))
    if not lows:
        return np.zeros(3), np.zeros(3)
    return np.min(lows, axis=0), np.max(highs, axis=0)


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


class SceneChanges:
    """Settings changed for the preview, and how to undo them: ``restore()`` sets every value
    back (in the order recorded: a view transform before its look) and then removes what was
    made for the preview (a camera, a world). Restoring never raises."""

    def __init__(self):
        self._values = []  # (owner, name, original value), each setting once
        self._seen = set()
        self._made = []  # callables removing what was created

    def keep(self, *names, owner):
        """Remember the original values of settings that setting others may change (a view
        transform's look, a file format's colour depth), before changing anything."""
        for name in names:
            key = (owner.as_pointer(), name)
            if hasattr(owner, name) and key not in self._seen:
                self._seen.add(key)
                self._values.append((owner, name, getattr(owner, name)))

    def set(self, owner, name, value):
        if hasattr(owner, name):
            self.keep(name, owner=owner)
            setattr(owner, name, value)

    def made(self, remove):
        self._made.append(remove)

    def restore(self):
        failed = []
        for owner, name, value in self._values:
            try:
                if getattr(owner, name) != value:
                    setattr(owner, name, value)
            except Exception:  # noqa: BLE001 - the rest is still restored
                failed.append(name)
        for remove in reversed(self._made):
            try:
                remove()
            except Exception:  # noqa: BLE001
                failed.append(getattr(remove, "__name__", "cleanup"))
        self._values, self._made = [], []
        if failed:
            print(f"warning: could not restore {', '.join(failed)} after the preview", file=sys.stderr)


def preview_settings(scene, sources, width=480, samples=16, exposure=0.0) -> SceneChanges:
    """Set the scene up to render the result objects' baked colours: Cycles without bounces
    (the light transport is in the colours; live lamps light their materials directly, and one
    bounce gathers the results' light at each camera hit, then denoised with the albedo and
    normal passes), otherwise no denoising; fixed samples; Standard view, the given exposure,
    a black world of its own (live results: the scene's, where it gives light, which the renderer
    draws on them), PNG output, and a camera if the scene has none. Returns the changes, for
    ``restore()``."""
    import bpy

    from ..blender_read.lights import world_gives_light

    changes = SceneChanges()
    render = scene.render
    if scene.camera is None:
        changes.set(scene, "camera", None)
        camera = _camera_for(sources)

        def remove_camera(camera=camera):
            data = camera.data
            bpy.data.objects.remove(camera, do_unlink=True)
            if data is not None and data.users == 0:
                bpy.data.cameras.remove(data)

        changes.made(remove_camera)
        height = int(width * 3 / 4)
    else:  # the scene's own camera and frame shape
        height = max(1, round(width * render.resolution_y / max(render.resolution_x, 1)))
    changes.set(render, "engine", "CYCLES")
    changes.set(scene.cycles, "device", "CPU")
    changes.set(scene.cycles, "samples", samples)
    changes.set(scene.cycles, "use_adaptive_sampling", False)  # the samples asked for, every pixel (at 16 it stops none early)
    changes.set(scene.cycles, "max_bounces", 0)  # the light transport is baked in the colours
    changes.set(scene.cycles, "use_denoising", False)
    changes.set(render, "resolution_x", width)
    changes.set(render, "resolution_y", height)
    changes.set(render, "resolution_percentage", 100)
    image = render.image_settings
    changes.keep("media_type", "file_format", "color_mode", "color_depth", owner=image)
    changes.set(image, "media_type", "IMAGE")
    changes.set(image, "file_format", "PNG")
    changes.set(image, "color_management", "FOLLOW_SCENE")
    view = scene.view_settings
    changes.keep("view_transform", "look", owner=view)
    changes.set(view, "view_transform", "Standard")
    changes.set(view, "look", "None")
    changes.set(view, "exposure", exposure)
    if _results_seen(scene, changes) and world_gives_light(scene):
        changes.keep("filepath", owner=render)
        return changes  # (live results: the renderer draws the world's light on them as the solve read it)
    world = bpy.data.worlds.new("Radiosity Preview World")
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        background = world.node_tree.nodes.get("Background")
        if background is not None:
            background.inputs["Color"].default_value = (0, 0, 0, 1)
    changes.set(scene, "world", world)
    changes.made(lambda world=world: bpy.data.worlds.remove(world))
    changes.keep("filepath", owner=render)
    return changes


def _results_seen(scene, changes):
    """The results' materials only seen: as lights, Cycles would build a light tree over every
    emitting triangle, which at a million patches took more memory than the scene. Live lamps
    (``LIVE_PROPERTY``): their light drawn at the preview's samples, denoised; the emitting
    materials among them (``LIVE_EMITS_PROPERTY``) sampled as lights, as their sources are.
    Whether any result is live."""
    from ..blender_write.materials import LIVE_EMITS_PROPERTY, LIVE_PROPERTY

    materials = _result_materials(scene)
    for material in materials:
        if not material.get(LIVE_EMITS_PROPERTY):
            changes.set(material.cycles, "emission_sampling", "NONE")
    live = any(material.get(LIVE_PROPERTY) for material in materials)
    if live:
        # (the denoiser itself is left as the scene has it, OpenImageDenoise by default: setting it makes
        # Cycles look for GPUs, which prints a warning on a machine without CUDA)
        for name, value in (("use_denoising", True), ("denoising_input_passes", "RGB_ALBEDO_NORMAL"),
                            ("denoising_prefilter", "ACCURATE")):
            changes.set(scene.cycles, name, value)
        # one bounce: the camera's hits gather the light of the results their rays meet, lit by the
        # lamps and showing their solved light after a bounce (materials._lit_by_lamps)
        for name, value in (("max_bounces", 1), ("glossy_bounces", 1), ("diffuse_bounces", 1),
                            ("transmission_bounces", 0), ("volume_bounces", 0)):
            changes.set(scene.cycles, name, value)
    return live


def _result_materials(scene):
    """The materials of the scene's result objects (ours, and any the user gave them)."""
    from ..blender_write.results import previous_results

    materials = {}
    for obj in previous_results(scene):
        for slot in obj.material_slots:
            if slot.material is not None:
                materials[slot.material.name] = slot.material
    return list(materials.values())


def render_preview(path, sources, width=480, samples=16, exposure=0.0, keep_settings=False, write_to=None):
    """Render the result objects (their baked colours as emission) with Cycles to ``path``
    (the scene's output path), written to ``write_to`` if given (a temporary file).

    The source objects are hidden from the render while it runs; they and the preview's
    settings (``preview_settings``) are restored afterwards unless ``keep_settings`` (a scene
    built here is saved so that F12 renders what the preview shows).
    """
    import bpy

    scene = bpy.context.scene
    changes = preview_settings(scene, sources, width, samples, exposure)
    hidden = [(o, o.hide_render) for o in sources if o.type != "LIGHT"]  # (lamps light live results)
    try:
        for o, _ in hidden:
            o.hide_render = True
        scene.render.filepath = os.path.abspath(path)
        bpy.ops.render.render()
        result = next(i for i in bpy.data.images if i.type == "RENDER_RESULT")
        result.save_render(filepath=os.path.abspath(write_to or path), scene=scene)
    finally:
        if not keep_settings:
            for o, h in hidden:
                o.hide_render = h
            changes.restore()



def auto_exposure():
    """Exposure (stops) that maps the median reflected radiosity to 0.35, from the result
    objects' colours as written in Blender (reading them back makes Blender copy them)."""
    import numpy as np

    from ..blender_write.results import ATTRIBUTE_NAME, previous_results

    values = []
    for obj in previous_results():
        attr = obj.data.color_attributes.get(ATTRIBUTE_NAME)
        if attr is None:
            continue
        c = np.empty(len(attr.data) * 4, dtype=np.float32)
        attr.data.foreach_get("color", c)
        values.append(c.reshape(-1, 4)[:, :3].mean(axis=1, dtype=np.float64))  # (float32 sums overflow near 3e38)
    return _exposure_of(values)


def preview_exposure(output) -> float:
    """``auto_exposure`` of the results a solve's ``output`` (pipeline.SolveOutput) writes, from
    its arrays: the 'Radiosity' attribute's values (the smooth light per polygon corner where it
    was made, else each patch's on every corner), as the float32 colours written."""
    import numpy as np

    from ..blender_write.results import rgba, written_mesh

    values = []
    meshes = [written_mesh(output, k) for k in range(len(output.patches.meshes))]
    for mesh, faces, smooth in zip(meshes, output.face_colours, output.smooth_colours):
        if faces is None:  # the rest of the scene: no results
            continue
        smooth_shown = smooth is not None  # (written: it is 'Radiosity')
        grey = rgba(smooth if smooth_shown else faces).reshape(-1, 4)[:, :3].mean(axis=1, dtype=np.float64)
        values.append(grey if smooth_shown else np.repeat(grey, mesh.face_sizes))
    return _exposure_of(values)


def _exposure_of(values):
    """Exposure (stops) that maps the median of the positive values (arrays) to 0.35."""
    import numpy as np

    if not values:
        return 0.0
    v = np.concatenate(values)
    v = v[v > 0]
    if not len(v):
        return 0.0
    median = float(np.median(v))
    return float(np.clip(math.log2(0.35 / median), -10, 10)) if median > 0 else 0.0

