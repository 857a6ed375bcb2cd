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
