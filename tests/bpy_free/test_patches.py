"""The extension's patch making reuses meshing, geometry tables and the Embree scene when only the
materials (or estimator, target, seed) change: the panel's estimate and a re-run neither
re-mesh nor rebuild. (addon.bpy_free.patches imports no bpy.)"""
import numpy as np

from addon.bpy_free import patches
from addon.bpy_free.scene_notes import scene_and_notes


def box_object(name="Box", size=1.0, reflectivity=0.5):
    """A closed cube of 6 quads wound inwards, the top one emitting."""
    s = size
    vertices = np.array([[0, 0, 0], [s, 0, 0], [s, s, 0], [0, s, 0], [0, 0, s], [s, 0, s], [s, s, s], [0, s, s]], float)
    faces = np.array([[0, 1, 2, 3], [4, 7, 6, 5], [0, 3, 7, 4], [1, 5, 6, 2], [0, 4, 5, 1], [3, 2, 6, 7]])
    triangles = np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]])
    triangle_face = np.concatenate([np.arange(6), np.arange(6)])
    emission = np.zeros((6, 3))
    emission[1] = 1.0
    return patches.ObjectArrays(
        name=name,
        vertices=vertices,
        face_sizes=np.full(6, 4),
        corner_verts=faces.ravel(),
        triangles=triangles,
        triangle_face=triangle_face,
        face_reflectivity=np.full((6, 3), reflectivity),
        face_emission=emission,
    )


def test_materials_change_reuses_meshes_geometry_and_tracer():
    patches.GEOMETRY_CACHE.clear()
    first = patches.make_patches([box_object(reflectivity=0.5)], patch_size=0.25)
    scene_a = first.patch_scene()
    tracer = scene_a.tracer
    second = patches.make_patches([box_object(reflectivity=0.3)], patch_size=0.25)
    scene_b = second.patch_scene()
    assert second.meshes is first.meshes and second.combined is first.combined
    assert scene_b.geometry is scene_a.geometry and scene_b.tracer is tracer
    np.testing.assert_allclose(scene_b.reflectivity, 0.3)
    np.testing.assert_allclose(scene_a.reflectivity, 0.5)


def test_geometry_or_patch_size_change_rebuilds_and_the_last_two_are_kept():
    patches.GEOMETRY_CACHE.clear()
    make = lambda size=1.0, patch=0.25: patches.make_patches([box_object(size=size)], patch_size=patch).patch_scene()  # noqa: E731
    base = make()
    finer = make(patch=0.2)
    assert finer.geometry is not base.geometry and finer.patch_count > base.patch_count
    assert make().geometry is base.geometry          # the two most recent are kept
    bigger = make(size=2.0)                          # evicts the least recent (finer)
    assert bigger.geometry is not base.geometry
    assert make(patch=0.2).geometry is not finer.geometry


def _plane_over_box(normal_up, z=1.5):
    """A closed box (its top face not emitting) and a small emitting plane above it at height
    ``z``, facing up (away from everything) or down."""
    box = box_object(name="Room", reflectivity=0.5)
    box.face_emission = np.zeros((6, 3))
    corners = [[0.3, 0.3, z], [0.7, 0.3, z], [0.7, 0.7, z], [0.3, 0.7, z]]
    order = [0, 1, 2, 3] if normal_up else [0, 3, 2, 1]
    lamp = patches.ObjectArrays(
        name="Lamp", vertices=np.array(corners, float), face_sizes=np.array([4]), corner_verts=np.array(order),
        triangles=np.array([[order[0], order[1], order[2]], [order[0], order[2], order[3]]]),
        triangle_face=np.array([0, 0]), face_reflectivity=np.full((1, 3), 0.5), face_emission=np.ones((1, 3)))
    # the box's outside faces the lamp: wind the box outwards
    box.corner_verts = box.corner_verts.reshape(6, 4)[:, ::-1].ravel()
    box.triangles = box.triangles[:, ::-1]
    return [box, lamp]


def test_an_emitter_that_sees_nothing_is_named():
    """An emissive plane far above the other objects sends nearly all its light out of the
    scene, from either side: a note names it. Just above them, facing up or down, one side
    lights them (emitting faces emit from both sides, as in Cycles): no note."""
    far = patches.make_patches(_plane_over_box(normal_up=True, z=40.0), patch_size=0.25)
    _, notes = scene_and_notes(far)
    assert any(n.startswith("'Lamp' sends 100% of its light out of the scene") for n in notes), notes
    for normal_up in (True, False):
        near = patches.make_patches(_plane_over_box(normal_up=normal_up), patch_size=0.25)
        _, notes = scene_and_notes(near)
        assert not any("out of the scene" in n for n in notes), notes
