"""The multilayer EXR reader gives the passes Cycles wrote (bpy): its Combined pass is the
float EXR of the same render, and the diffuse and glossy passes rebuild it."""
import os

import bpy
import numpy as np

from benchmarks import exr_layers, interior_scene, picture


def test_a_multilayer_render_reads_back_as_its_combined_image_and_its_passes(tmp_path):
    interior_scene.build("window_room")
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 40, 30
    picture.configure_cycles(scene, 2, seed=4)
    scene.render.threads = 1
    single, _ = picture.render_exr(scene)
    layer = scene.view_layers[0]
    names = ("diffuse_direct", "diffuse_indirect", "diffuse_color", "glossy_direct", "glossy_indirect", "glossy_color",
             "emit", "environment")
    for name in names:
        setattr(layer, "use_pass_" + name, True)
    image = scene.render.image_settings
    image.media_type = "MULTI_LAYER_IMAGE"
    image.file_format, image.color_depth, image.exr_codec = "OPEN_EXR_MULTILAYER", "32", "NONE"
    scene.render.filepath = str(tmp_path / "passes.exr")
    bpy.ops.render.render(write_still=True)
    channels = exr_layers.read_channels(str(tmp_path / "passes.exr"))
    os.remove(tmp_path / "passes.exr")

    def rgb(name):
        return np.stack([channels[f"ViewLayer.{name}.{c}"] for c in "RGB"], axis=-1)

    combined = rgb("Combined")
    assert combined.shape == (30, 40, 3)
    assert np.allclose(combined, single, rtol=1e-6, atol=1e-7)  # the same seed, the same pixels
    rebuilt = (rgb("Diffuse Color") * (rgb("Diffuse Direct") + rgb("Diffuse Indirect"))
               + rgb("Glossy Color") * (rgb("Glossy Direct") + rgb("Glossy Indirect")) + rgb("Emission") + rgb("Environment"))
    assert np.abs(rebuilt - combined).max() <= 1e-3 * combined.max()
    assert rgb("Glossy Color").max() > 0.01  # default Principled: a specular layer the camera sees
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_cycles_sample_counts_track_the_products_time_round_by_round():
    """The picture benchmark's next round gives Cycles the samples that take the product's time
    at the last round's rate (render time about proportional to samples), within its bounds."""
    assert picture.tracked(70, 24.0, 28.0, 1 << 16) == 60
    assert picture.tracked(70, 28.0, 24.0, 1 << 16) == 82
    assert picture.tracked(3, 1.0, 30.0, 1 << 16) == 1
    assert picture.tracked(70, 100.0, 1.0, 1000) == 1000
