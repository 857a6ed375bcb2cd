"""What a result mesh keeps of its source's surface: every UV map and colour attribute, and
its shading normals, read at the source's loop triangles' corners (``SourceLayers``) and
interpolated at every patch corner of its result (``result_layers``), as Blender interpolates
them (numpy; ``core.textures`` locates the corners)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..core.materials.textures import corner_layers


@dataclass
class SourceLayers:
    """What a result mesh keeps of its source's surface: every UV map and colour attribute, at
    the source's loop triangles' corners (world-independent: UVs and linear colours)."""

    uv: tuple = ()       # (name, (T,3,2) float32) per UV map, in the source's order
    colours: tuple = ()  # (name, (T,3,4) float32) per colour attribute, scene linear RGBA
    active_uv: str = ""  # the UV map shown for editing
    render_uv: str = ""  # the UV map a texture without a UV Map node reads
    render_colour: str = ""  # the colour attribute a Color Attribute node without a name reads
    # (T,3,3) float32 shading normals at the corners (world space once ``placed``); None: every face flat
    normals: np.ndarray | None = None

    def taken(self, rows):
        """The layers of the loop triangles ``rows`` (a mask or indices) only."""
        return replace(self, uv=tuple((n, a[rows]) for n, a in self.uv),
                       colours=tuple((n, a[rows]) for n, a in self.colours),
                       normals=None if self.normals is None else self.normals[rows])

    def reversed(self):
        """The layers of the triangles with their corners reversed (a mirrored object)."""
        return replace(self, uv=tuple((n, a[:, ::-1].copy()) for n, a in self.uv),
                       colours=tuple((n, a[:, ::-1].copy()) for n, a in self.colours),
                       normals=None if self.normals is None else self.normals[:, ::-1].copy())

    def placed(self, linear):
        """The layers of the object placed by the (3,3) ``linear`` part of its matrix: normals
        transform by its inverse transpose (outward under a negative scale too)."""
        if self.normals is None:
            return self
        if not abs(np.linalg.det(linear)) > 0:  # (flattened to a plane or less: its faces are flat)
            return replace(self, normals=None)
        normals = self.normals.reshape(-1, 3) @ np.linalg.inv(linear).astype(np.float32)  # (rows: n M^-1 = M^-T n)
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
        return replace(self, normals=normals.reshape(self.normals.shape))


@dataclass
class ResultLayers:
    """A result mesh's share of its source's surface: its UV maps and colour attributes at
    every polygon corner (float32 (C,k)), and each patch's material slot."""

    uv: tuple              # (name, (C,2) float32)
    colours: tuple         # (name, (C,4) float32)
    active_uv: str
    render_uv: str
    render_colour: str
    patch_slot: np.ndarray  # (P,) int32
    slot_names: tuple       # the source's material of each slot
    normals: np.ndarray | None = None  # (C,3) float32 the source's shading normals; None: flat faces


def result_layers(o, mesh) -> ResultLayers:
    """The ResultLayers of object ``o`` meshed as ``mesh``: its UV maps, colour attributes and
    shading normals interpolated at every patch corner from the source face the patch lies on
    (core.textures)."""
    slot = (np.zeros(mesh.patch_count, np.int32) if o.face_slot is None
            else np.asarray(o.face_slot, np.int32)[mesh.patch_face])
    source = o.layers or SourceLayers()
    named = [*source.uv, *source.colours]
    layers = [layer for _, layer in named]
    if source.normals is not None:  # (the shading the source has: smooth faces, sharp edges, custom normals)
        layers.append(source.normals)
    values = []
    if layers:
        corner_face = np.repeat(mesh.patch_face, mesh.face_sizes)
        values = corner_layers(mesh.points, mesh.corner_verts, corner_face, o.vertices[o.triangles], o.triangle_face,
                               layers)
    normals = None
    if source.normals is not None:
        normals = values.pop()
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    pairs = [(name, value) for (name, _), value in zip(named, values, strict=True)]
    return ResultLayers(tuple(pairs[: len(source.uv)]), tuple(pairs[len(source.uv):]), source.active_uv,
                        source.render_uv, source.render_colour, slot, tuple(o.slot_names) or ("(no material)",),
                        normals)
