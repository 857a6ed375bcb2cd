"""sample_scenes.blender.to_blender: parts, patches, winding and materials survive into Blender."""
import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from sample_scenes import cornell_box, cube_enclosure  # noqa: E402
from sample_scenes.blender import to_blender  # noqa: E402


@pytest.fixture
def empty_scene():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy.context.scene
    bpy.ops.wm.read_factory_settings(use_empty=True)


@pytest.mark.parametrize("sample", [cube_enclosure.build(reflectivity=0.3, enclosure_divisions=4),
                                    cornell_box.build(divisions=10)], ids=["fig1", "cornell"])
def test_to_blender_round_trip(empty_scene, sample):
    objects = to_blender(sample)
    assert [o.name.split(" ", 1)[1] for o in objects] == sample.part_names
    normals, areas, refl, emis = [], [], [], []
    for obj in objects:
        mesh = obj.data
        n = len(mesh.polygons)
        nrm = np.empty(3 * n, np.float32)
        mesh.polygons.foreach_get("normal", nrm)
        area = np.empty(n, np.float32)
        mesh.polygons.foreach_get("area", area)
        mi = np.empty(n, np.int32)
        mesh.polygons.foreach_get("material_index", mi)
        normals.append(nrm.reshape(-1, 3))
        areas.append(area)
        for k in mi:
            node = mesh.materials[k].node_tree.nodes["Principled BSDF"]
            refl.append(node.inputs["Base Color"].default_value[:3])
            emis.append(np.array(node.inputs["Emission Color"].default_value[:3])
                        * node.inputs["Emission Strength"].default_value)
    order = np.concatenate([sample.part_patches(p) for p in sample.part_names])
    assert sum(len(a) for a in areas) == sample.patch_count
    np.testing.assert_allclose(np.concatenate(normals), sample.patch_normal[order], atol=1e-6)
    np.testing.assert_allclose(np.concatenate(areas), sample.patch_area[order], rtol=1e-5)
    np.testing.assert_allclose(np.array(refl), sample.reflectivity[order], atol=1e-6)
    np.testing.assert_allclose(np.array(emis), sample.emission[order], rtol=1e-6, atol=1e-6)


def test_extension_reads_back_the_same_scene(empty_scene):
    """Through the extension's own reader and patch meshing: same patches, areas and materials."""
    read_selection = pytest.importorskip("addon.blender_read.selection").read_selection
    patch_making = pytest.importorskip("addon.bpy_free.patches")
    sample = cornell_box.build(divisions=10)
    for obj in to_blender(sample):
        obj.select_set(True)
    objects, notes = read_selection(bpy.context)
    patches = patch_making.make_patches(objects, patch_size=10.0)  # larger than any face: no subdivision
    scene = patches.patch_scene()
    assert scene.patch_count == sample.patch_count
    assert scene.total_area == pytest.approx(sample.total_area, rel=1e-6)
    assert scene.average_reflectivity == pytest.approx(sample.r_ave, rel=1e-6)
    assert scene.total_power == pytest.approx(sample.scene.total_power, rel=1e-6)  # (the panel's back counted)
    assert float((scene.patch_area * scene.emission.mean(axis=1)).sum()) == pytest.approx(sample.total_power, rel=1e-6)
    # same normals, as a multiset (the extension may order patches its own way)
    key = lambda n: np.lexsort(np.round(n, 6).T)  # noqa: E731
    np.testing.assert_allclose(scene.patch_normal[key(scene.patch_normal)],
                               sample.patch_normal[key(sample.patch_normal)], atol=1e-5)
