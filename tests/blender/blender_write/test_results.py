"""What the results write: the smooth light joins separate objects that meet in one plane and
stays apart where surfaces meet at a crease."""
import bpy
import numpy as np

from ..blender_read.test_lights import _lamp
from ..conftest import box_arrays, make_object, mesh_arrays, principled, read_colours, result_objects


def _corner_values(name):
    """{(x, y, z) rounded to 1e-5: [(normal of its polygon, smooth colour), ...]} of the result
    object of ``name``."""
    (obj,) = [o for o in result_objects() if o["radiosity_source"] == name]
    co, sizes, corners = mesh_arrays(obj.data)
    _, smooth = read_colours(obj.data, "Radiosity")
    normals = np.empty(len(obj.data.polygons) * 3, np.float32)
    obj.data.polygons.foreach_get("normal", normals)
    normal_of_corner = np.repeat(normals.reshape(-1, 3), sizes, axis=0)
    out = {}
    for position, normal, value in zip(np.round(co[corners], 5), normal_of_corner, smooth[:, :3]):
        out.setdefault(tuple(position), []).append((tuple(np.round(normal, 3)), value))
    return out


def test_wall_pieces_of_separate_objects_share_their_light_and_corners_keep_creases(blender):
    """A room whose floor is two objects side by side, lit by a lamp low beside their joint: at
    the joint the two floors' smooth colours agree within 0.5% (before, each object's vertex
    averages stopped at its own edge: a seam of the light's slope across a patch). At the room's floor-wall edge the floor and the wall keep
    their own light (before, a point averaged both: a dark line)."""
    room_v, room_f = box_arrays((0, 0, 0), (2, 1, 1), inward=True)
    floor = [f for f in room_f if all(room_v[i][2] == 0 for i in f)]
    walls = [f for f in room_f if f not in floor]
    white = principled("White", (0.7, 0.7, 0.7))
    make_object("Walls", room_v, walls, [white]).select_set(True)
    for name, x0 in (("Left floor", 0.0), ("Right floor", 1.0)):
        v = [(x0, 0, 0), (x0 + 1, 0, 0), (x0 + 1, 1, 0), (x0, 1, 0)]
        make_object(name, v, [[0, 1, 2, 3]], [white]).select_set(True)
    _lamp("POINT", "Bulb", location=(0.8, 0.5, 0.3), energy=30.0, shadow_soft_size=0.0)
    s = blender.scene.radiosity
    s.output, s.patch_size, s.target_error, s.threads = "VERTEX", 0.1, 3.0, 2
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    left, right = _corner_values("Left floor"), _corner_values("Right floor")
    joint = [p for p in left if abs(p[0] - 1.0) < 1e-6 and p in right]
    assert len(joint) >= 9
    for p in joint:
        a = np.mean([v for _, v in left[p]], axis=0)
        b = np.mean([v for _, v in right[p]], axis=0)
        # (the smoothing keeps each patch's mean exactly, which leaves steps of about 0.1%: far
        # below what the eye sees; a per-object average differs by the light's slope there)
        np.testing.assert_allclose(a, b, rtol=5e-3)
    walls = _corner_values("Walls")
    edge = [p for p in left if p in walls and 0.05 < p[0] < 0.95]  # the floor's edge along the y = 0 or 1 wall
    assert edge
    differ = 0
    for p in edge:
        floor_value = np.mean([v for _, v in left[p]], axis=0)
        wall_values = [v for n, v in walls[p] if abs(n[2]) < 0.5]  # the wall's own corners there
        assert wall_values
        differ += not np.allclose(floor_value, wall_values[0], rtol=1e-3)
    assert differ >= len(edge) // 2  # (the lamp lights the floor and the walls unlike)


def test_both_leaves_the_smooth_light_out_above_its_patch_bound_and_says_so(blender, monkeypatch):
    """Above SMOOTH_MAX_PATCHES (at a million patches smoothing doubled the run's time and memory)
    Both writes the flat colours alone, as 'Radiosity', and a note says why; below it, both."""
    from addon.bpy_free import options, pipeline

    room_v, room_f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", room_v, room_f, [principled("White", (0.7, 0.7, 0.7))]).select_set(True)
    _lamp("POINT", "Bulb", location=(0.5, 0.5, 0.8), energy=30.0, shadow_soft_size=0.0)
    s = blender.scene.radiosity
    s.output, s.patch_size, s.target_error, s.threads = "BOTH", 0.25, 5.0, 2
    notes = []
    real = pipeline._write_colours
    monkeypatch.setattr(pipeline, "_write_colours", lambda out, *a: (real(out, *a), notes.extend(out.notes))[0])
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    (room,) = result_objects()
    assert [a.name for a in room.data.color_attributes] == ["Radiosity", "Radiosity Patches"]
    assert not any("smooth colours left out" in n for n in notes)
    monkeypatch.setattr(options, "SMOOTH_MAX_PATCHES", 10)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    (room,) = result_objects()
    assert [a.name for a in room.data.color_attributes] == ["Radiosity"]
    _, colours = read_colours(room.data, "Radiosity")
    _, sizes, _ = mesh_arrays(room.data)
    starts = np.r_[0, np.cumsum(sizes)[:-1]]
    assert (colours == np.repeat(colours[starts], sizes, axis=0)).all()  # flat per patch
    assert any("smooth colours left out at 96 patches" in n for n in notes), notes
