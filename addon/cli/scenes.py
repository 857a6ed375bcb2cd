"""The scenes the command line builds: the Cornell box and the sample scenes (sample_scenes/),
and the extension registered in the ``bpy`` module (bpy, imported where used)."""

from __future__ import annotations

import os


def sample_scene_names():
    try:
        import sample_scenes

        return sorted(sample_scenes.SCENES)
    except ImportError:
        return []


def repo_root():
    return os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def ensure_registered():
    import bpy

    if not hasattr(bpy.types.Scene, "radiosity") or not hasattr(bpy.ops.radiosity, "solve"):
        import addon

        addon.register()


def build_sample_scene(name):
    """Objects for a sample_scenes scene (one object per part, one quad per patch), selected, and
    the settings the scene brings for its own picture ({option name: value})."""
    import bpy
    import sample_scenes
    from sample_scenes.blender import to_blender

    sample = sample_scenes.build(name)
    objects = to_blender(sample)
    view = sample.metadata.get("camera")
    if view is not None:  # the scene's own view, which the preview renders from
        data = bpy.data.cameras.new(f"{name} camera")
        data.lens = view["lens"]
        camera = bpy.data.objects.new(f"{name} camera", data)
        camera.location, camera.rotation_euler = view["location"], view["rotation"]
        bpy.context.scene.collection.objects.link(camera)
        bpy.context.scene.camera = camera
        bpy.context.scene.render.resolution_x, bpy.context.scene.render.resolution_y = view["resolution"]
    for obj in bpy.context.view_layer.objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0]
    return objects, dict(sample.metadata.get("settings") or {})

