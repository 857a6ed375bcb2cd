"""The Detail setting's patches (addon.bpy_free.adaptive_patches): refined meshes keep every
object's materials and power, Off changes nothing, and too many patches is one clear line."""
import numpy as np
import pytest

from addon.bpy_free import adaptive_patches, patches
from addon.core.lights.lights import PointLight

from test_patches import box_object


class Selection(list):
    lights = (PointLight(np.array([0.5, 0.5, 0.9]), np.full(3, 0.3)),)


def room():
    box = box_object(reflectivity=0.6)
    box.face_reflectivity = np.array([[0.6, 0.5, 0.4]] * 5 + [[0.2, 0.7, 0.3]])
    return Selection([box])


def test_refined_patches_keep_materials_areas_and_power():
    objects = room()
    first = patches.make_patches(objects, 0.25, layers=True)
    refined = adaptive_patches.refined(objects, first, "HIGH", seed=1, layers=True)
    assert refined.combined.patch_count > first.combined.patch_count and refined.refinement
    face = refined.meshes[0].patch_face
    np.testing.assert_array_equal(refined.reflectivity, objects[0].face_reflectivity[face])
    np.testing.assert_array_equal(refined.emission, objects[0].face_emission[face])
    assert refined.combined.patch_area.sum() == pytest.approx(first.combined.patch_area.sum(), rel=1e-12)
    assert refined.patch_scene().source_power.sum() == pytest.approx(first.patch_scene().source_power.sum(), rel=1e-12)
    assert len(refined.layers[0].patch_slot) == refined.combined.patch_count


def test_detail_off_is_the_patches_themselves():
    objects = room()
    first = patches.make_patches(objects, 0.25)
    assert adaptive_patches.refined(objects, first, "OFF") is first


def test_more_patches_than_the_limit_is_one_line(monkeypatch):
    objects = room()
    first = patches.make_patches(objects, 0.25)
    monkeypatch.setattr(adaptive_patches, "MAX_PATCHES", first.combined.patch_count + 1)
    adaptive_patches._LAST.key = None
    with pytest.raises(ValueError, match=r"^Detail high would make [\d,]+ patches, more than the limit of [\d,]+: use a "
                                         r"larger patch size or a lower detail$"):
        adaptive_patches.refined(objects, first, "HIGH", seed=1)


def box_arrays(name, lo, hi, inward, reflectivity, emission=0.0):
    """A box ``lo``-``hi`` of six quads (wound inwards: a room; else outwards), every face emitting
    ``emission``."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    vertices = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    faces = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])  # (outward)
    faces = faces[:, ::-1] if inward else faces
    return patches.ObjectArrays(name=name, vertices=vertices, face_sizes=np.full(6, 4), corner_verts=faces.ravel(),
                                triangles=np.concatenate([faces[:, [0, 1, 2]], faces[:, [0, 2, 3]]]),
                                triangle_face=np.tile(np.arange(6), 2), face_reflectivity=np.full((6, 3), reflectivity),
                                face_emission=np.full((6, 3), emission))


def slab_room():
    """A 2 x 2 x 1 m room, an emitting slab 0.7 x 0.7 x 0.04 m 2 cm under its ceiling."""
    return Selection([box_arrays("Room", (0, 0, 0), (2, 2, 1), True, 0.8),
                      box_arrays("Slab", (0.65, 0.65, 0.94), (1.35, 1.35, 0.98), False, 0.8, 5.0)])


def floor_light(p, seed):
    """(the floor's mean irradiance, its standard error) of a solve of ``p`` without its lamp."""
    from addon.core import solve

    scene = p.patch_scene()
    scene = type(scene)(scene.vertices, scene.triangles, scene.triangle_patch, scene.reflectivity, scene.emission,
                        _geometry=scene.geometry)
    centre = np.stack([np.bincount(scene.triangle_patch, weights=scene.vertices[scene.triangles].mean(axis=1)[:, k])
                       / np.bincount(scene.triangle_patch) for k in range(3)], axis=1)
    floor = np.flatnonzero((centre[:, 2] < 1e-9) & (np.arange(scene.patch_count) < p.combined.patch_offsets[1]))
    r = solve(scene, paths=400_000, seed=seed, exit_point="random", threads=1, method="walk", direct_light="shot")
    area = scene.patch_area[floor]
    return (np.sum(area * r.irradiance[floor, 0]) / area.sum(),
            np.sqrt(np.sum(area**2 * r.irradiance_variance[floor, 0])) / area.sum())


def test_detail_off_splits_the_patches_a_near_surface_partly_covers_and_the_room_gets_the_right_light():
    """Detail off, the ceiling's four 0.5 m patches the slab's outline crosses split along it (the
    slab, the walls and the floor keep their meshes, no shading triangulation of their own),
    materials, areas and power kept; the floor's light then within 3% of the solve on 0.05 m
    patches, which follow the outline (before: the patches themselves, 29% too bright; the 0.5 m
    patches' own discretization is 2.6%: tests/core/test_covered_parts.py)."""
    objects = slab_room()
    adaptive_patches._LAST.key = None
    first = patches.make_patches(objects, 0.5, layers=True)
    split = adaptive_patches.refined(objects, first, "OFF", layers=True)
    assert split.combined.patch_count > first.combined.patch_count and not split.refinement
    assert getattr(split.meshes[1], "shading_triangles", None) is None and split.meshes[1].patch_count == first.meshes[1].patch_count
    assert split.meshes[0].shading_triangles is not None
    face = split.meshes[0].patch_face
    np.testing.assert_array_equal(split.reflectivity[: split.combined.patch_offsets[1]], objects[0].face_reflectivity[face])
    assert split.combined.patch_area.sum() == pytest.approx(first.combined.patch_area.sum(), rel=1e-12)
    assert split.patch_scene().source_power.sum() == pytest.approx(first.patch_scene().source_power.sum(), rel=1e-12)
    assert len(split.layers[0].patch_slot) == split.meshes[0].patch_count
    # the gap's patches, under the slab, are the scene's hidden ones: the error measure leaves them out
    hidden = split.patch_scene().hidden
    np.testing.assert_array_equal(hidden, patches.covered_flags(split))
    assert hidden is not None and 0 < hidden.sum() and first.patch_scene().hidden is None
    assert adaptive_patches.refined(objects, patches.make_patches(objects, 0.5), "OFF").combined.patch_count == \
        split.combined.patch_count  # (the estimate's patches are the run's)
    ref, ref_se = floor_light(patches.make_patches(objects, 0.05), 13)
    straddling, straddling_se = floor_light(first, 11)
    light, se = floor_light(split, 12)
    assert straddling - ref > 0.2 * ref
    assert -4 * np.hypot(ref_se, se) < light - ref < 0.03 * ref, (light, ref, straddling)


def test_a_rerun_of_the_split_patches_with_other_materials_reuses_their_meshes_geometry_and_tracer():
    """The outline split's meshes are kept with their core scene, as the plain meshes are
    (test_patches): a second solve of the same objects, another reflectivity, neither splits nor
    builds the scene's arrays and Embree scenes again (before: each run stored fresh meshes
    under the split's key, dropping the scene the last run built); the new materials are read."""
    objects = slab_room()
    patches.GEOMETRY_CACHE.clear()
    adaptive_patches._LAST.key = None
    first = adaptive_patches.refined(objects, patches.make_patches(objects, 0.5, layers=True), "OFF", layers=True)
    scene = first.patch_scene()
    objects[0].face_reflectivity = objects[0].face_reflectivity * 0.5
    again = adaptive_patches.refined(objects, patches.make_patches(objects, 0.5, layers=True), "OFF", layers=True)
    assert again.meshes is first.meshes and again.combined is first.combined
    rescene = again.patch_scene()
    assert rescene.geometry is scene.geometry and rescene.tracer is scene.tracer
    np.testing.assert_array_equal(rescene.hidden, scene.hidden)
    np.testing.assert_allclose(rescene.reflectivity[: again.combined.patch_offsets[1]],
                               0.5 * scene.reflectivity[: first.combined.patch_offsets[1]])


def test_the_outline_split_reads_the_materials_of_the_objects_it_split_only(monkeypatch):
    """An object none of whose patches split keeps its first patches' materials (a texture's mean
    over each patch is most of a material's reading: read once, not again); the split ceiling's
    object is read for its new patches. Before, every object was read twice."""
    objects = slab_room()
    objects[1].face_emission = np.array([[5.0, 4.0, 3.0]] * 5 + [[1.0, 2.0, 3.0]])
    adaptive_patches._LAST.key = None
    first = patches.make_patches(objects, 0.5, layers=True)
    read = []
    real = adaptive_patches.patch_materials
    monkeypatch.setattr(adaptive_patches, "patch_materials", lambda o, m: read.append(o.name) or real(o, m))
    split = adaptive_patches.refined(objects, first, "OFF", layers=True)
    assert read == ["Room"]
    offset = split.combined.patch_offsets[1]
    np.testing.assert_array_equal(split.emission[offset:], first.emission[first.combined.patch_offsets[1]:])
    np.testing.assert_array_equal(split.emission[offset:], objects[1].face_emission[split.meshes[1].patch_face])
