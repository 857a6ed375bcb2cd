"""``--relight`` on the command line: a saved file's per-light results recombined with new
strengths and colours, no ray traced, saved as a solve's results are; bad input in one line,
nothing written."""
import os
import subprocess
import sys

import bpy
import numpy as np
import pytest

from addon.cli import run as cli_run

from ..ui import relight_scene as rs
from ..ui.test_relight import _attributes

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
CHANGES = ["--strength", "Bulb=0", "--strength", "Sun=3", "--colour", "Sun=1,0.7,0.4", "--strength", "World=0.7",
           "--colour", "World=0.2,0.3,0.9", "--strength", "Glow=5", "--colour", "Glow=1,0.3,0.2"]


def _solved_file(blender, tmp_path):
    rs.build(blender, "TEXTURED")
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    path = str(tmp_path / "room.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    return path


def test_relight_on_a_saved_file_saves_what_the_operator_gives(blender, tmp_path):
    path = _solved_file(blender, tmp_path)
    out = tmp_path / "relit.blend"
    proc = subprocess.run([sys.executable, "-m", "addon", "--open", path, "--relight", *CHANGES, "-o", str(out),
                           "--no-preview"], cwd=str(tmp_path), capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 0, proc.stderr
    assert "\nrelit: error " in proc.stdout and f"saved: {out}" in proc.stdout
    # the same changes through the operator in this process
    bpy.ops.wm.open_mainfile(filepath=path)
    rs.change(blender)
    bpy.data.objects["Panel"].hide_render = False  # (the command line left the panel as it was)
    assert bpy.ops.radiosity.relight() == {"FINISHED"}
    expected = _attributes()
    bpy.ops.wm.open_mainfile(filepath=str(out))
    got = _attributes()
    assert set(got) == set(expected)
    for key in got:
        np.testing.assert_allclose(got[key], expected[key], rtol=1e-6, atol=1e-7, err_msg=str(key))


def test_relight_traces_no_ray_from_the_command_line(blender, tmp_path, monkeypatch):
    from addon.core.scene import raytrace

    _solved_file(blender, tmp_path)

    def no_rays(*args, **kwargs):
        raise AssertionError("traced a ray")

    for name in ("first_hit", "first_hit_barycentric"):
        monkeypatch.setattr(raytrace.RayTracer, name, no_rays)
    out = tmp_path / "current.blend"
    assert cli_run.main(["--current", "--relight", *CHANGES, "-o", str(out), "--no-preview"]) == 0
    assert out.exists()


@pytest.mark.parametrize("args,message", [
    (["--strength", "Nobody=3"], "error: no lamp, world or emissive material named 'Nobody' in the scene; the "
                                 "solve's sources: 'Bulb', 'Glow', 'Panel', 'Sun', 'World'"),
    (["--strength", "Bulb=-1"], "error: --strength takes NAME=VALUE with finite values of at least 0; got 'Bulb=-1'"),
    (["--colour", "Bulb=1,2"], "error: --colour takes NAME=R,G,B with finite values of at least 0; got 'Bulb=1,2'"),
])
def test_bad_relight_input_is_one_line_and_writes_nothing(blender, tmp_path, args, message):
    path = _solved_file(blender, tmp_path)
    out = tmp_path / "never.blend"
    proc = subprocess.run([sys.executable, "-m", "addon", "--open", path, "--relight", *args, "-o", str(out),
                           "--no-preview"], cwd=str(tmp_path), capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 2 and proc.stderr.strip() == message, proc.stderr
    assert not out.exists()


def test_relight_of_a_file_without_per_light_results_is_refused(blender, tmp_path):
    rs.build(blender)
    bpy.context.scene.radiosity.per_source = "OFF"
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    path = str(tmp_path / "plain.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    out = tmp_path / "never.blend"
    proc = subprocess.run([sys.executable, "-m", "addon", "--open", path, "--relight", "--strength", "Bulb=3", "-o",
                           str(out), "--no-preview"], cwd=str(tmp_path), capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 2 and proc.stderr.strip() == (
        "error: no per-light results to relight: solve with Per-light results On or Automatic first")
    assert not out.exists()
    assert cli_run.main(["--relight", "--strength", "Bulb=3", "--no-preview"]) == 2
