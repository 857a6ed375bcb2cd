"""The live view: the 3D view draws the solution refining while a solve runs, writing nothing.

The running job keeps its result so far (``SolveJob.live``); a draw handler of the 3D view draws
the patches in those colours over the scene. Nothing is written into Blender data, so cancel,
undo and saving are untouched: the handler goes when the solve ends.
"""
from __future__ import annotations

import numpy as np

# The median radiosity is drawn at this grey (before the display's gamma), as the preview does.
MEDIAN_GREY = 0.35


# Corner positions are gathered this many corners at a time (float64 to float32 per block).
BLOCK_CORNERS = 1 << 18


def triangles(patches, radiosity):
    """What the view draws for (P,3) ``radiosity`` on ``patches``: (3T,3) float32 corner
    positions (world space, every triangle of every patch) and (3T,4) uint8 colours (each
    patch's :func:`colour_bytes`), the vertex buffer's two attributes. The colours are made
    first, so that their temporaries are gone before the positions are made."""
    c = patches.combined
    # per patch, then per triangle, then per corner: no per-corner index or float arrays
    colours = np.repeat(colour_bytes(radiosity)[c.triangle_patch], 3, axis=0)
    corners = np.asarray(c.triangles).reshape(-1)
    positions = np.empty((len(corners), 3), np.float32)
    for start in range(0, len(corners), BLOCK_CORNERS):
        positions[start:start + BLOCK_CORNERS] = c.vertices[corners[start:start + BLOCK_CORNERS]]
    return positions, colours


def colour_bytes(radiosity):
    """(P,4) uint8 RGBA of (P,3) radiosity: :func:`display_colours` in steps of 1/255 (the
    vertex buffer holds 8-bit normalised colours, a quarter of float32's memory), opaque."""
    rgba = np.full((len(radiosity), 4), 255, np.uint8)
    rgb = display_colours(radiosity)
    rgb *= np.float32(255)
    rgba[:, :3] = np.rint(rgb, out=rgb)
    return rgba


def display_colours(radiosity):
    """(P,3) float32 display colours in [0, 1] of (P,3) radiosity: exposed so that the median
    radiosity is MEDIAN_GREY, clipped, gamma 2.2."""
    b = np.asarray(radiosity)
    grey = b.mean(axis=1, dtype=np.float32)
    lit = grey[grey > 0]
    del grey
    scale = MEDIAN_GREY / float(np.median(lit)) if lit.size else 1.0
    del lit
    out = np.multiply(b, scale, dtype=np.float32)
    np.clip(out, 0.0, 1.0, out=out)
    out **= np.float32(1 / 2.2)
    return out


def batch(positions, colours):
    """The GPU batch of :func:`triangles`' arrays: float32 positions and 8-bit normalised
    colours (which the FLAT_COLOR shader reads as floats in [0, 1])."""
    import gpu

    fmt = gpu.types.GPUVertFormat()
    fmt.attr_add(id="pos", comp_type="F32", len=3, fetch_mode="FLOAT")
    fmt.attr_add(id="color", comp_type="U8", len=4, fetch_mode="INT_TO_FLOAT_UNIT")
    vbo = gpu.types.GPUVertBuf(format=fmt, len=len(positions))
    vbo.attr_fill(id="pos", data=positions)
    vbo.attr_fill(id="color", data=colours)
    return gpu.types.GPUBatch(type="TRIS", buf=vbo)


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
        # (the Detail's refining solves change the patches: a result is drawn on its own mesh, the
        # last one drawn kept until the next mesh's first result)
        fresh = radiosity is not None and patches is not None and len(radiosity) == patches.combined.patch_count
        if not fresh and self._drawn is None:
            return
        import gpu

        shader = gpu.shader.from_builtin("FLAT_COLOR")
        if fresh and (self._drawn is None or self._drawn[0] != version):
            self._drawn = None  # the old batch goes before the new one is made
            self._drawn = (version, batch(*triangles(patches, radiosity)))
        gpu.state.depth_test_set("LESS_EQUAL")
        self._drawn[1].draw(shader)
        gpu.state.depth_test_set("NONE")

    def remove(self):
        import bpy

        if self._handle is not None:
            bpy.types.SpaceView3D.draw_handler_remove(self._handle, "WINDOW")
            self._handle = None
