"""Non-planar faces in Blender: a NURBS sphere's tessellation (pole quads whose corners differ by
float32 rounding, slightly bent quads) and a randomly displaced grid (twisted quads) solve, and
their results are written patch by patch onto the right source faces."""

import bpy
import numpy as np

from addon.bpy_free import pipeline
from addon.blender_read.selection import read_selection
from addon.blender_write.results import written_mesh
from addon.bpy_free import patches, worker
from addon.bpy_free.cleaning import degenerate_area
from addon.core.mesh import meshing

from ..conftest import make_object, mesh_arrays, read_colours, result_objects
from ..test_extension import configure


def _nonplanar_scene(context):
    """The closed test room with its lamp, a NURBS sphere and a displaced grid inside."""
    from ..conftest import build_test_scene

    build_test_scene()
    bpy.ops.surface.primitive_nurbs_surface_sphere_add(radius=0.15, location=(0.72, 0.7, 0.3))
    sphere = context.active_object
    sphere.name = "Nurbs"
    n = 12
    x, y = np.meshgrid(np.linspace(0.1, 0.9, n + 1), np.linspace(0.1, 0.9, n + 1), indexing="ij")
    z = 0.6 + np.random.default_rng(7).uniform(-0.03, 0.03, x.shape)
    v = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    make_object("Bumpy", v, quads)  # facing up, towards the lamp
    for o in bpy.data.objects:
        o.select_set(True)
    objects, _ = read_selection(context)
    return {o.name: o for o in objects}


def test_nurbs_sphere_and_displaced_grid_solve_and_write_results(blender):
    objects = _nonplanar_scene(blender)
    settings = configure(blender, output="BOTH")
    # they are not planar: before, the core refused the whole scene
    for name in ("Nurbs", "Bumpy"):
        o = objects[name]
        nonplanar, _ = meshing.nonplanar_faces(o.vertices, len(o.face_sizes), o.triangles, o.triangle_face)
        assert nonplanar.sum() >= 8, name

    output = pipeline.run_solve(list(objects.values()), settings.solve_settings())  # the same run, for checking
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    results = {o["radiosity_source"]: o for o in result_objects()}
    assert set(results) == {"Block", "Lamp", "Room", "Nurbs", "Bumpy"}
    for k, obj in enumerate(output.patches.objects):
        # the result object is the written mesh (the patches, split where the display split them), its colours those
        # of its patches
        mesh = written_mesh(output, k)
        co, sizes, corners = mesh_arrays(results[obj.name].data)
        np.testing.assert_array_equal(sizes, mesh.face_sizes)
        np.testing.assert_array_equal(corners, mesh.corner_verts)
        np.testing.assert_allclose(co, mesh.points, atol=1e-6)
        domain, flat = read_colours(results[obj.name].data, "Radiosity Patches")
        assert domain == "CORNER"
        np.testing.assert_array_equal(flat[:, :3], np.repeat(output.face_colours[k], sizes, axis=0).astype(np.float32))
        domain, smooth = read_colours(results[obj.name].data, "Radiosity")
        assert domain == "CORNER"
        np.testing.assert_allclose(smooth[:, :3], output.smooth_colours[k], rtol=1e-6, atol=1e-7)
        assert np.isfinite(flat).all() and (flat[:, :3] >= 0).all()
        # every patch lies on its source face (patch_face maps results back to the right face):
        # its centroid is over one of the face's triangles, and near its plane (grid cells of
        # a face that is planar within 1 degree are bilinear: near, not on)
        source = objects[obj.name]  # (the patches keep only the objects' names, not their arrays)
        tri = source.vertices[source.triangles]
        centroid = np.add.reduceat(mesh.points[mesh.corner_verts], mesh.face_starts) / sizes[:, None]
        for p in range(mesh.patch_count):
            t = tri[source.triangle_face == mesh.patch_face[p]]
            a, b = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
            n = np.cross(a, b)
            keep = np.linalg.norm(n, axis=1) > 1e-12
            a, b, n, t = a[keep], b[keep], n[keep], t[keep]
            d = centroid[p] - t[:, 0]
            # barycentrics of the centroid's projection: d = u a + v b + h n
            uvh = np.linalg.solve(np.stack([a, b, n], axis=2), d[:, :, None])[:, :, 0]
            inside = (uvh[:, 0] >= -1e-6) & (uvh[:, 1] >= -1e-6) & (uvh[:, 0] + uvh[:, 1] <= 1 + 1e-6)
            height = np.abs(uvh[:, 2]) * np.linalg.norm(n, axis=1)
            size = np.linalg.norm(t - np.roll(t, 1, axis=1), axis=2).max()
            assert np.any(inside & (height <= np.tan(np.radians(2)) * size)), (obj.name, p)
    # the split objects are lit: their patches got light from the lamp
    for name in ("Nurbs", "Bumpy"):
        k = [o.name for o in output.patches.objects].index(name)
        mesh = written_mesh(output, k)  # (the display's cells where it split them)
        assert 3 in mesh.face_sizes  # non-planar faces were cut into triangles
        assert np.average(output.face_colours[k].mean(axis=1), weights=mesh.patch_area) > 0
    assert not any("mix triangles" in note for note in output.notes)


def test_patch_count_follows_the_non_planar_rule(blender):
    objects = list(_nonplanar_scene(blender).values())
    min_area = degenerate_area(objects)
    for size in (10.0, 0.2, 0.05):
        meshed = sum(
            meshing.mesh_patches(o.vertices, o.face_sizes, o.corner_verts, size, face_triangles=o.triangles,
                                 triangle_face=o.triangle_face, min_area=min_area).patch_count
            for o in objects
        )
        assert patches.patch_count(objects, size) == meshed, size
