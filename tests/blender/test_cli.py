"""The command line entry: python -m addon (bpy module, headless)."""

import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def run(args, cwd, timeout=300):
    proc = subprocess.run([sys.executable, "-m", "addon", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def test_cli_builds_solves_saves_and_renders(tmp_path):
    blend = tmp_path / "box.blend"
    png = tmp_path / "box.png"
    out = run(["--scene", "cornell", "--error", "10", "--patch-size", "0.4", "-o", str(blend),
               "--preview", str(png), "--resolution", "64", "--samples", "2", "--threads", "1"], cwd=str(tmp_path))
    assert "patches" in out and "saved:" in out
    assert blend.exists() and png.exists()
    import bpy

    bpy.ops.wm.open_mainfile(filepath=str(blend))
    results = [o for o in bpy.data.objects if "radiosity_source" in o.keys()]
    assert sorted(o["radiosity_source"] for o in results) == ["Light", "Room", "Short Box", "Tall Box"]
    for o in results:
        attr = o.data.color_attributes["Radiosity"]
        c = np.empty(len(attr.data) * 4, dtype=np.float32)
        attr.data.foreach_get("color", c)
        assert np.all(np.isfinite(c)) and c.reshape(-1, 4)[:, :3].max() > 0
    # the sources are visible again after the preview render
    assert all(not bpy.data.objects[n].hide_render for n in ("Light", "Room", "Short Box", "Tall Box"))
    # the preview shows something: not a black image
    image = bpy.data.images.load(str(png))
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    assert pixels.reshape(-1, 4)[:, :3].mean() > 0.02
    bpy.ops.wm.read_factory_settings(use_empty=True)


def test_cli_reopens_a_file_and_reports_unknown_scenes(tmp_path):
    blend = tmp_path / "first.blend"
    run(["--scene", "cornell", "--error", "20", "--patch-size", "0.5", "-o", str(blend), "--no-preview"],
        cwd=str(tmp_path))
    again = tmp_path / "again.blend"
    out = run(["--open", str(blend), "--select-all", "--error", "20", "--patch-size", "1.0", "-o", str(again),
               "--no-preview"], cwd=str(tmp_path))
    assert again.exists() and "first:" in out
    # a scene of sample_scenes/, keeping the paper's patches
    out = run(["--scene", "fig1_r0.5", "--error", "20", "-o", str(tmp_path / "fig1.blend"), "--no-preview"],
              cwd=str(tmp_path))
    assert "fig1_r0.5: 546 patches" in out
    proc = subprocess.run([sys.executable, "-m", "addon", "--scene", "nope", "--no-preview"], cwd=str(tmp_path),
                          capture_output=True, text=True, env={**os.environ, "PYTHONPATH": ROOT}, timeout=120)
    assert proc.returncode == 2 and "unknown scene" in proc.stderr and "cornell" in proc.stderr
