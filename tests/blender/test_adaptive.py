"""The Detail setting (adaptive patches) through the operator: every output on the refined mesh,
a written mesh without cracks, cancel leaving the scene as it was."""
from collections import Counter

import bpy
import numpy as np
import pytest

from .conftest import build_test_scene, mesh_arrays, read_colours, result_objects
from .test_extension import _drive, _modal_operator, _snapshot, configure


def edge_uses(obj):
    """How many polygons of the object's mesh use each edge (by vertex pair)."""
    _, sizes, corners = mesh_arrays(obj.data)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    uses = Counter()
    for start, size in zip(starts, sizes):
        face = corners[start:start + size]
        for a, b in zip(face, np.roll(face, -1)):
            uses[(min(a, b), max(a, b))] += 1
    return uses


def polygons(name):
    return len(bpy.data.objects[f"{name} Radiosity"].data.polygons)


@pytest.mark.parametrize("output, light", [("FACE", True), ("VERTEX", False), ("BOTH", False), ("TEXTURED", False)])
def test_every_output_on_refined_patches(blender, output, light):
    """Detail high splits patches where the lamp's light changes (more polygons than Detail off);
    every output is written on the refined mesh: its colours finite, one a polygon corner, and
    the closed room and block stay closed (every edge in exactly two polygons: no T-junction)."""
    build_test_scene()
    s = configure(blender, output=output)
    s.light_output = light
    s.detail = "OFF"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    uniform = {name: polygons(name) for name in ("Room", "Block")}
    s.detail = "HIGH"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert polygons("Room") > uniform["Room"]
    assert s.last_patches == sum(len(o.data.polygons) for o in result_objects())
    for obj in result_objects():
        assert obj.data.color_attributes, obj.name
        for attribute in obj.data.color_attributes:
            domain, colours = read_colours(obj.data, attribute.name)
            assert domain == "CORNER" and len(colours) == len(obj.data.loops)
            assert np.isfinite(colours).all() and (colours[:, :3] >= 0).all()
        if obj["radiosity_source"] in ("Room", "Block"):
            assert set(edge_uses(obj).values()) == {2}, obj.name
    if light:
        assert "Radiosity Light" in bpy.data.objects["Room Radiosity"].data.color_attributes


def test_the_estimate_counts_the_refined_patches(blender):
    from addon.ui import estimate

    build_test_scene()
    s = configure(blender)
    s.detail = "HIGH"
    value = estimate.compute(blender)
    assert value["refinement"]
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert value["patches"] == s.last_patches


def test_cancel_with_detail_leaves_the_scene_as_before(blender):
    build_test_scene()
    s = configure(blender)
    s.detail = "HIGH"
    s.target_error = 0.05  # millions of paths: still running when Esc comes
    before = _snapshot()
    op = _modal_operator()
    assert op._start_job(blender, threaded=True) is None
    assert _drive(op, blender, cancel=True) == {"CANCELLED"}
    assert not result_objects() and "Radiosity" not in bpy.data.collections
    assert _snapshot() == before and s.last_paths == 0
