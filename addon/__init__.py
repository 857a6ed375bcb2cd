"""Random Walk Radiosity: a Blender extension.

Shooting random walk radiosity (Sbert & Brusi) for diffuse global
illumination, baked into colour attributes.

This module must import without bpy: the numerical core (``addon.core``) is
used and tested on its own.  The Blender glue (properties, operators, panel)
lives in submodules that are imported only inside :func:`register`.
"""

bl_info = {  # for Blender versions that load it as a legacy add-on
    "name": "Random Walk Radiosity",
    "author": "Random Walk Radiosity developers",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "View3D > Sidebar > Radiosity",
    "description": "Diffuse global illumination by shooting random walk radiosity, baked to colour attributes",
    "category": "Lighting",
}

_registered_modules = []


def _glue_modules():
    from .ui import estimate
    from .ui import operators, panel, properties, relight, relight_update, world_watch

    return [properties, operators, panel, estimate, relight, relight_update, world_watch]


def register():
    """Register every class, property and handler of the extension."""
    if _registered_modules:
        return
    for module in _glue_modules():
        module.register()
        _registered_modules.append(module)


def unregister():
    """Undo :func:`register` completely (classes, properties, handlers, timers)."""
    from .bpy_free import worker

    worker.cancel_running_job()
    while _registered_modules:
        _registered_modules.pop().unregister()
