"""The live view: the 3D view draws the solution refining while a solve runs, writing nothing.

The running job keeps its result so far (``SolveJob.live``); a draw handler of the 3D view draws
the patches in those colours over the scene. Nothing is written into Blender data, so cancel,
undo and saving are untouched: the handler goes when the solve ends.
"""
from __future__ import annotations

import numpy as np

# The median radiosity is drawn at this grey (before the display's gamma), as the preview does.
MEDIAN_GREY = 0.35


def triangles(patches, radiosity):
    """What the view draws for (P,3) ``radiosity`` on ``patches``: (3T,3) float32 corner
    positions (world space, every triangle of every patch) and (3T,4) float32 colours (each
    patch's, exposed so that the median radiosity is MEDIAN_GREY, gamma 2.2, clipped)."""
    c = patches.combined
    positions = np.asarray(c.vertices, dtype=np.float32)[np.asarray(c.triangles).reshape(-1)]
    rgba = np.ones((len(radiosity), 4), np.float32)
    rgba[:, :3] = display_colours(radiosity)
    # per patch, then per triangle, then per corner: no per-corner index or RGB arrays
    return positions, np.repeat(rgba[c.triangle_patch], 3, axis=0)


def display_colours(radiosity):
    """(P,3) float32 display colours of (P,3) radiosity."""
    b = np.asarray(radiosity, dtype=np.float64)
    grey = b.mean(axis=1)
    lit = grey[grey > 0]
    scale = MEDIAN_GREY / float(np.median(lit)) if lit.size else 1.0
    return np.clip(b * scale, 0.0, 1.0).astype(np.float32) ** np.float32(1 / 2.2)


class LiveView:
    """A 3D-view draw handler showing a job's live result; ``remove()`` when the solve ends."""

    def __init__(self, job):
        import bpy

        self.job = job
        self._drawn = None  # (version, batch) of the live result drawn
        self._handle = bpy.types.SpaceView3D.draw_handler_add(self.draw, (), "WINDOW", "POST_VIEW")

    def draw(self):
        version, radiosity = self.job.live
        patches = self.job.patches
        if radiosity is None or patches is None:
            return
        import gpu
        from gpu_extras.batch import batch_for_shader

        shader = gpu.shader.from_builtin("FLAT_COLOR")
        if self._drawn is None or self._drawn[0] != version:
            positions, colours = triangles(patches, radiosity)
            self._drawn = (version, batch_for_shader(shader, "TRIS", {"pos": positions, "color": colours}))
        gpu.state.depth_test_set("LESS_EQUAL")
        self._drawn[1].draw(shader)
        gpu.state.depth_test_set("NONE")

    def remove(self):
        import bpy

        if self._handle is not None:
            bpy.types.SpaceView3D.draw_handler_remove(self._handle, "WINDOW")
            self._handle = None
