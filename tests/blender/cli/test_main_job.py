"""The main job (the README's first command): its preview and target are what the README says,
and the file it saves keeps them (F12 renders the same)."""

import os
import re

from .test_run import ROOT, run


def _readme_promise():
    """(resolution, samples, target %) from the README's main-job paragraph."""
    with open(os.path.join(ROOT, "README.md")) as f:
        text = f.read()
    found = re.search(r"solves it to a ([\d.]+)% error.*?\((\d+) x \d+ pixels, (\d+) samples of Cycles, denoised\)",
                      text, flags=re.S)
    assert found, "the README's main-job paragraph names its target, picture size and samples"
    return int(found.group(2)), int(found.group(3)), float(found.group(1))


def test_the_main_jobs_preview_and_target_are_what_the_readme_says(tmp_path):
    """Fixed samples (no adaptive sampling: the count the README gives, on every pixel),
    OpenImageDenoise with the albedo and normal passes, one bounce; the Cornell sample's own target."""
    import bpy

    from addon.cli.arguments import LIVE_SAMPLES, RESOLUTION, checked, parser
    from sample_scenes import cornell_box

    width, samples, target = _readme_promise()
    assert (RESOLUTION.default, LIVE_SAMPLES) == (width, samples)
    assert checked(parser().parse_args(["--scene", "cornell"])).samples == samples
    assert cornell_box.build(divisions=10).metadata["settings"]["target_error"] == target
    blend = tmp_path / "box.blend"
    out = run(["--scene", "cornell", "--patch-size", "0.4", "--threads", "1", "--resolution", "24", "-q",
               "-o", str(blend)], cwd=str(tmp_path))
    assert f"of a {target:g}% target" in out, out[-2000:]
    bpy.ops.wm.open_mainfile(filepath=str(blend))
    cycles = bpy.context.scene.cycles
    try:
        assert (cycles.samples, cycles.use_adaptive_sampling) == (samples, False)
        assert (cycles.use_denoising, cycles.denoiser, cycles.denoising_input_passes) == (
            True, "OPENIMAGEDENOISE", "RGB_ALBEDO_NORMAL")
        assert (cycles.max_bounces, cycles.diffuse_bounces) == (1, 1)
    finally:
        bpy.ops.wm.read_factory_settings(use_empty=True)
