"""Odd scenes on the command line: a selection with nothing to solve, light beyond float32's
square root, a white material, and the loaded scene's own panel settings (--current)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from ..conftest import build_test_scene, make_object, principled, read_colours, result_objects

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
FAST = ["--patch-size", "0.5", "--threads", "1"]


def _cli(args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "addon", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "PYTHONPATH": ROOT})


def _saved(path, build):
    """A file of the test scene changed by ``build()``; back to an empty file after."""
    import bpy

    import addon

    addon.unregister()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    try:
        build_test_scene()
        build()
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        addon.unregister()
        bpy.ops.wm.read_factory_settings(use_empty=True)
    return path


def _emission(strength):
    import bpy

    for material in bpy.data.materials:
        node = material.node_tree.nodes["Principled BSDF"]
        if node.inputs["Emission Strength"].default_value > 0:
            node.inputs["Emission Strength"].default_value = strength


def test_a_selection_of_only_zero_area_faces_is_nothing_to_solve(tmp_path):
    """The selection's faces have no area, the rest of the scene has: that ran and saved an
    empty result with status 0. Now one line, status 2 (as nothing selected), nothing written."""
    import bpy

    def flat_selection():
        for o in bpy.data.objects:
            o.select_set(False)
        make_object("Flat", [(0, 0, 0.5), (1, 0, 0.5), (0.5, 0, 0.5), (0, 1, 0.5), (0, 0.5, 0.5)],
                    [(0, 1, 2), (0, 3, 4)], [principled("Grey", (0.5, 0.5, 0.5))]).select_set(True)

    source = _saved(tmp_path / "flat.blend", flat_selection)
    proc = _cli(["--open", str(source), "-o", str(tmp_path / "out" / "x.blend"), "--no-preview", *FAST], str(tmp_path))
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    errors = [line for line in proc.stderr.splitlines() if line.strip()]
    assert errors == ["error: nothing to solve: the selected objects ('Flat') have no faces of non-zero area"], errors
    assert "patches" not in proc.stdout and not (tmp_path / "out").exists()


def _light(path):
    """'Radiosity Light' of each result object in the saved file ``path``."""
    import bpy

    bpy.ops.wm.open_mainfile(filepath=str(path))
    light = {o["radiosity_source"]: read_colours(o.data, "Radiosity Light")[1][:, :3].astype(np.float64)
             for o in result_objects()}
    bpy.ops.wm.read_factory_settings(use_empty=True)
    return light


def test_light_beyond_float32s_square_root_gives_the_same_picture_and_no_numpy_warning(tmp_path):
    """Emission of 1e30: the run's variance of the light arriving overflowed float32 (numpy's
    "overflow encountered in cast" on the terminal) and the noise filter then smoothed 'Radiosity
    Light' 5-8% away from the same scene at strength 1. Light is linear in the emission and the
    paths do not depend on it: the same seed gives the same picture scaled, to float32 rounding."""
    scale = 1e30
    runs = {}
    for strength in (1.0, scale):
        source = _saved(tmp_path / f"e{strength:g}.blend", lambda s=strength: _emission(s))
        out = tmp_path / f"out{strength:g}.blend"
        proc = _cli(["--open", str(source), "-o", str(out), "--resolution", "32", "--samples", "1", "-q", *FAST],
                    str(tmp_path))
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert "Warning" not in proc.stderr and "warning" not in proc.stderr, proc.stderr  # numpy's, or any
        runs[strength] = _light(out)
    for name, unit in runs[1.0].items():
        np.testing.assert_allclose(runs[scale][name] / scale, unit, rtol=1e-5, atol=1e-6 * unit.max(), err_msg=name)


def test_light_the_results_colours_cannot_hold_is_refused_in_one_line_before_the_solve(tmp_path):
    """Emission near float32's largest (3.4e38): a numpy overflow warning, a traceback and
    "the result for 'Lamp' is not finite" after the whole solve. Now one line naming the
    emitting object and what to do, before any ray; nothing written."""
    source = _saved(tmp_path / "max.blend", lambda: _emission(3.4e38))
    proc = _cli(["--open", str(source), "-o", str(tmp_path / "x.blend"), "--no-preview", "-q", *FAST], str(tmp_path))
    assert proc.returncode == 1, proc.stderr[-3000:]
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip() and "Read blend" not in line]
    assert len(lines) == 1 and lines[0].startswith("error: Radiosity failed: the emission (in 'Lamp') is 3.4e+38: "), lines
    assert "use smaller units of power" in lines[0] and not (tmp_path / "x.blend").exists()


def test_the_previews_exposure_of_colours_near_float32s_largest_is_computed_without_overflow():
    """The mean of a corner's three float32 channels overflowed near 3.4e38 (numpy's "overflow
    encountered in reduce" on the terminal): it is taken in float64."""
    import warnings
    from types import SimpleNamespace

    from addon.cli.preview import preview_exposure

    output = SimpleNamespace(patches=SimpleNamespace(meshes=[SimpleNamespace(face_sizes=np.array([4, 4]))]),
                             face_colours=[np.full((2, 3), 3e38)], smooth_colours=[None])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert preview_exposure(output) == -10.0  # (the darkest exposure)


def test_a_white_material_names_the_command_lines_flag_and_the_flag_clamps_it(tmp_path):
    """The hint for a reflectivity of 1 named the panel's 'Clamp bright colours', which the
    command line had no flag for: it names --clamp-bright-colours, which clamps to 0.99."""
    import bpy

    def white():
        node = bpy.data.materials["White"].node_tree.nodes["Principled BSDF"]
        node.inputs["Base Color"].default_value = (1, 1, 1, 1)

    source = _saved(tmp_path / "white.blend", white)
    common = ["--open", str(source), "--no-preview", "--error", "20", *FAST]
    proc = _cli([*common, "-o", str(tmp_path / "a.blend")], str(tmp_path))
    assert proc.returncode == 1, proc.stderr[-2000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "add --clamp-bright-colours to use 0.99" in errors[0], proc.stderr
    assert "Clamp bright colours" not in proc.stdout + proc.stderr
    proc = _cli([*common, "--clamp-bright-colours", "-o", str(tmp_path / "b.blend")], str(tmp_path))
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "clamped to 0.99 (--clamp-bright-colours is on)" in proc.stdout, proc.stdout
    assert (tmp_path / "b.blend").exists() and not (tmp_path / "a.blend").exists()


def test_current_takes_the_panels_settings_where_the_command_line_gives_none(blender, tmp_path):
    """main(['--current']) inside Blender solved with the command line's defaults, whatever the
    loaded scene's panel said; now the panel's settings hold, and an option given still decides."""
    import bpy

    from addon.__main__ import main

    build_test_scene()
    panel = blender.scene.radiosity
    panel.target_error, panel.patch_size, panel.output, panel.seed, panel.threads = 20.0, 0.5, "FACE", 7, 1
    out = tmp_path / "out.blend"
    assert main(["--current", "--no-preview", "-q", "-o", str(out)]) == 0
    assert panel.last_target_error == pytest.approx(20.0) and panel.last_patch_size == pytest.approx(0.5)
    assert (panel.output, panel.seed, panel.threads) == ("FACE", 7, 1)  # (the panel's, kept)
    assert main(["--current", "--no-preview", "-q", "--error", "30", "-o", str(out)]) == 0
    assert panel.last_target_error == pytest.approx(30.0) and panel.last_patch_size == pytest.approx(0.5)
    bpy.ops.wm.read_factory_settings(use_empty=True)
