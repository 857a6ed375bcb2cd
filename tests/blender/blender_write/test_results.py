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
    the joint the two floors' smooth colours differ no more than two patches' corners inside one
    floor do (before, each object's vertex averages stopped at its own edge: a seam of the
    light's slope across a patch). At the room's floor-wall edge the floor and the wall keep
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
    # (the smoothing keeps each patch's mean to within its standard error, which leaves small steps
    # between two patches' corners inside an object where it must move one further: at the joint
    # no larger than those, and under half a percent of the light; a per-object average differs
    # there by the light's slope across a patch)
    inside = [p for p in left if 0.05 < p[0] < 0.95 and 0.05 < p[1] < 0.95 and len(left[p]) > 1]
    assert len(inside) > 50
    steps = [np.ptp([v for _, v in left[p]], axis=0).max() / np.mean([v for _, v in left[p]]) for p in inside]
    gaps = []
    for p in joint:
        a = np.mean([v for _, v in left[p]], axis=0)
        b = np.mean([v for _, v in right[p]], axis=0)
        gaps.append(float(np.abs(a - b).max() / np.abs(b).max()))
    assert np.median(gaps) <= 0.005 and max(gaps) <= 2 * np.percentile(steps, 90), (gaps, np.percentile(steps, [50, 90]))
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
    real = pipeline.write_colours
    monkeypatch.setattr(pipeline, "write_colours", lambda out, *a: (real(out, *a), notes.extend(out.notes))[0])
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


def _world_corner_normals(obj):
    """(C,3) positions and normals of an object's corners in world space, the normals as the
    renderer shades with them (object-space corner normals by the inverse transpose)."""
    mesh = obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
    co, _, corners = mesh_arrays(mesh)
    normals = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", normals)
    M = np.array(obj.matrix_world)
    world = normals.reshape(-1, 3).astype(np.float64) @ np.linalg.inv(M[:3, :3])
    return co[corners] @ M[:3, :3].T + M[:3, 3], world / np.linalg.norm(world, axis=1, keepdims=True)


def test_results_are_shaded_as_their_sources_flat_smooth_and_creased(blender):
    """A result mesh is shaded as its source: a flat box flat; a smooth, mirrored, stretched ball
    with the source's normals where their corners meet (the renderer's normal matrix); a smooth
    post whose cap edges are sharp keeps them sharp. Before, every result was smooth across every
    edge: with live lamps the renderer lit a box's side near its top with the top's normal (the
    lamp room's bed 1.5-2x too bright there, dark below)."""
    room_v, room_f = box_arrays((-1, -1, 0), (1, 1, 2), inward=True)
    white = principled("White", (0.7, 0.7, 0.7))
    room = make_object("Room", room_v, room_f, [white])
    block_v, block_f = box_arrays((0.3, 0.3, 0), (0.7, 0.6, 0.4), inward=False)
    block = make_object("Block", block_v, block_f, [white])
    bpy.ops.mesh.primitive_uv_sphere_add(segments=12, ring_count=6, radius=0.3, location=(-0.5, 0.4, 0.8))
    ball = bpy.context.object
    ball.name, ball.scale = "Ball", (1.0, 1.5, -0.8)  # (stretched and mirrored)
    ball.data.shade_smooth()
    bpy.ops.mesh.primitive_cylinder_add(vertices=8, radius=0.15, depth=0.8, location=(0.4, -0.5, 0.4))
    post = bpy.context.object
    post.name = "Post"
    post.data.shade_smooth()
    edges = post.data.edges
    rim = [len({round(post.data.vertices[v].co.z, 6) for v in e.vertices}) == 1 for e in edges]  # (not the sides')
    for e, on_rim in zip(edges, rim):
        e.use_edge_sharp = on_rim  # (the caps' edges: a crease, the sides smooth)
    for o in (ball, post):
        o.data.materials.append(white)
    for o in (room, block, ball, post):  # (adding a primitive deselects the rest)
        o.select_set(True)
    _lamp("POINT", "Bulb", location=(0.0, 0.0, 1.6), energy=60.0, shadow_soft_size=0.0)
    s = blender.scene.radiosity
    s.patch_size, s.target_error, s.threads = 0.1, 5.0, 2
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    results = {o["radiosity_source"]: o for o in result_objects()}
    assert results["Block"].data.normals_domain == "FACE" and results["Room"].data.normals_domain == "FACE"
    for name in ("Ball", "Post"):
        assert results[name].data.normals_domain == "CORNER", (name, bpy.data.objects[name].data.normals_domain)
        source_at, source_n = _world_corner_normals(bpy.data.objects[name])
        result_at, result_n = _world_corner_normals(results[name])
        shared = 0
        for p, n in zip(result_at, result_n):
            same = np.linalg.norm(source_at - p, axis=1) < 1e-5
            if same.any():  # a corner of the source there: one of its normals, on the same side
                shared += 1
                assert np.max(source_n[same] @ n) > 0.9995, (name, p, n)
        assert shared >= 24
    at, n = _world_corner_normals(results["Post"])
    cap = np.abs(at[:, 2] - 0.8) < 1e-6
    up = n[:, 2] > 0.5
    assert cap.sum() >= 16 and np.allclose(n[cap & up], [0, 0, 1], atol=1e-3)  # the cap's corners flat
    assert np.all(np.abs(n[cap & ~up, 2]) < 1e-3)  # the side's corners at the rim horizontal
