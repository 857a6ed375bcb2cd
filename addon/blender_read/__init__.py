"""Reading the Blender scene into arrays: objects, materials, images, lights and the world (bpy).

What is read goes on as ``bpy_free.patches.ObjectArrays`` and the core's light sources; nothing here
writes into Blender."""


class SceneError(ValueError):
    """Bad input found while reading the scene: a message for the user."""
