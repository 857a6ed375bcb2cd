"""The world's EEVEE output follows the results (bpy): where the results that need it
(``blender_write.eevee_world``) are deleted by hand, the user's world is put back as it was.

A depsgraph update costs a dictionary look-up while the world has no such output; while it has
one and objects or collections changed, the results' collections are looked at (a few objects),
and every object of the scenes only where none there shows the highlights."""
from __future__ import annotations

import bpy
from bpy.app.handlers import persistent

from ..blender_write import eevee_world
from ..blender_write.results import previous_results
from . import handlers


def check(world):
    """``eevee_world.restore_unless_shown`` for ``world`` and the scenes it lights; True where it
    put the world back."""
    scenes = [s for s in bpy.data.scenes if s.world == world]
    return eevee_world.restore_unless_shown(world, scenes, (o for s in scenes for o in previous_results(s)))


@persistent
def on_depsgraph_update(scene, depsgraph):
    world = getattr(scene, "world", None)
    if not eevee_world.has_output(world):
        return
    if depsgraph.id_type_updated("OBJECT") or depsgraph.id_type_updated("COLLECTION"):
        check(world)


@persistent
def on_load(_):
    """A file saved with the output but without the results that need it (deleted before this
    watch existed, or with the add-on off)."""
    for world in bpy.data.worlds:
        check(world)


HANDLERS = (("depsgraph_update_post", on_depsgraph_update), ("load_post", on_load))


def register():
    handlers.attach(*HANDLERS)


def unregister():
    handlers.detach(*HANDLERS)
