"""What a solve keeps for relighting (bpy): the sources as they were when it started, and its
per-source results on the result objects (``blender_write.relight_store``)."""

from __future__ import annotations

from ..blender_read import sources
from . import relight_store


def snapshot(scene):
    """Every source's strength, colour and signature now (a solve's start)."""
    return sources.snapshot(scene)


# The last solve's result, settings and patch size (by its results' token), for Update.
LAST = {}


def keep(scene, created, output, snapshot, settings):
    """Stores ``output``'s per-source results (or forgets earlier ones where it has none)."""
    results = getattr(output, "sources_out", None)
    objects = output.patches.objects
    selected = [o.name for o in objects if o.receives]
    solved = [o.name for o in objects]
    geometry = sources.geometry_signature(scene, solved) if results is not None else None
    meta = relight_store.store(scene, created, results, snapshot, (selected, solved, geometry))
    LAST.clear()
    if results is not None:
        scene.radiosity.last_relit = ""
        LAST[meta["token"]] = (output.result, settings, output.patches.patch_size)
