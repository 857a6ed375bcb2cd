"""Blender's application handlers the panel's modules hang functions on (bpy): each added once
by its module's ``register``, taken off again by its ``unregister``."""
from __future__ import annotations

import bpy


def attach(*pairs):
    """Adds each function to its handler list, ``(name in bpy.app.handlers, function)``, once."""
    for name, function in pairs:
        handlers = getattr(bpy.app.handlers, name)
        if function not in handlers:
            handlers.append(function)


def detach(*pairs):
    """Takes each function off its handler list, where it is on it."""
    for name, function in pairs:
        handlers = getattr(bpy.app.handlers, name)
        if function in handlers:
            handlers.remove(function)
