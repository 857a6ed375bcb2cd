"""The command line entry: python -m addon (bpy module, headless)."""

import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


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
    # the one Cornell box (sample_scenes/cornell_box.py): one object per part
    sources = sorted(o["radiosity_source"] for o in results)
    assert len(sources) >= 7 and any("light" in name for name in sources) and any("red" in name for name in sources)
    for o in results:
        attr = o.data.color_attributes["Radiosity"]
        c = np.empty(len(attr.data) * 4, dtype=np.float32)
        attr.data.foreach_get("color", c)
        assert np.all(np.isfinite(c)) and c.reshape(-1, 4)[:, :3].max() > 0
    # a scene built here is saved to render the preview on F12: the sources hidden from render
    assert all(bpy.data.objects[n].hide_render for n in sources)
    # the preview shows something: not a black image
    image = bpy.data.images.load(str(png))
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    assert pixels.reshape(-1, 4)[:, :3].mean() > 0.02
    # F12 in the saved file renders the preview (README): the same image, to Cycles' noise
    f12 = tmp_path / "f12.png"
    bpy.context.scene.render.filepath = str(f12)
    bpy.ops.render.render(write_still=True)
    again = bpy.data.images.load(str(f12))
    other = np.empty(len(again.pixels), dtype=np.float32)
    again.pixels.foreach_get(other)
    assert other.shape == pixels.shape
    assert np.abs(other - pixels).mean() < 0.01 * max(pixels.mean(), 1e-3) + 2 / 255
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


# ---------------------------------------------------------------------------------------------
# Bad input on the command line: one line on stderr, a non-zero status, no traceback
# ---------------------------------------------------------------------------------------------

def _run_failing(args, cwd):
    proc = subprocess.run([sys.executable, "-m", "addon", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode != 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Traceback" not in proc.stdout + proc.stderr, proc.stdout[-3000:] + proc.stderr[-3000:]
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1, proc.stderr
    return proc.returncode, errors[0]


def _save_scene(path, build):
    """Build a scene in a fresh file with ``build()`` and save it; back to an empty file after."""
    import bpy

    import addon

    addon.unregister()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    try:
        build()
        bpy.ops.wm.save_as_mainfile(filepath=str(path))
    finally:
        addon.unregister()
        bpy.ops.wm.read_factory_settings(use_empty=True)


def test_cli_failures_are_one_line_and_a_non_zero_status(tmp_path):
    import bpy

    from ..conftest import box_arrays, build_test_scene, make_object, principled

    def no_emitter():
        build_test_scene()
        bpy.data.objects["Lamp"].select_set(False)
        bpy.data.objects["Lamp"].hide_render = True  # not in the render: it takes no part

    def nothing_selected():
        build_test_scene()
        for o in bpy.data.objects:
            o.select_set(False)

    def slow_batches():  # albedo 0.99999: the first batch takes far longer than the time limit
        v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
        make_object("Room", v, f, [principled("Glow", (0.99999,) * 3, (1, 1, 1), 1.0)]).select_set(True)

    for name, build in (("no_emitter", no_emitter), ("nothing", nothing_selected), ("slow", slow_batches)):
        _save_scene(tmp_path / f"{name}.blend", build)
    common = ["--no-preview", "--patch-size", "0.5", "--threads", "1"]
    status, line = _run_failing(["--open", str(tmp_path / "no_emitter.blend"), "-o", str(tmp_path / "a.blend"),
                                 *common], str(tmp_path))
    assert status == 1 and line.startswith("error: No emitter among the selected objects")
    status, line = _run_failing(["--open", str(tmp_path / "nothing.blend"), "-o", str(tmp_path / "b.blend"),
                                 *common], str(tmp_path))
    assert status == 2 and "no mesh object selected" in line
    status, line = _run_failing(["--open", str(tmp_path / "slow.blend"), "-o", str(tmp_path / "c.blend"),
                                 "--time-limit", "0.01", *common], str(tmp_path))
    assert status == 1 and "before the first batch" in line and "nothing was written" in line
    status, line = _run_failing(["--open", str(tmp_path / "missing.blend"), *common], str(tmp_path))
    assert status == 2 and "no such file" in line
    assert not any((tmp_path / n).exists() for n in ("a.blend", "b.blend", "c.blend"))


@pytest.mark.parametrize("args, expected", [
    (["--error", "-1"], "--error must be between 0.05 and 100 %; got -1"),
    (["--error", "0"], "--error must be between 0.05 and 100 %; got 0"),
    (["--error", "500"], "--error must be between 0.05 and 100 %; got 500"),
    (["--threshold", "2"], "--threshold must be between 1e-06 and 0.5; got 2"),
    (["--threshold", "0"], "--threshold must be between 1e-06 and 0.5; got 0"),
    (["--patch-size", "-1"], "--patch-size must be 0 (automatic) or at least 0.0001; got -1"),
    (["--seed", "-5"], "--seed must be between 0 and 2147483647; got -5"),
    (["--threads", "-1"], "--threads must be between 0 and 64; got -1"),
    (["--resolution", "0"], "--resolution must be between 16 and 16384 pixels; got 0"),
    (["--colours", "stripes"], "--colours must be one of TEXTURED, FACE, VERTEX, BOTH; got 'stripes'"),
    (["--no-such-option"], "unrecognized arguments: --no-such-option"),
    (["--error", "lots"], "argument --error: invalid float value: 'lots'"),
])
def test_cli_refuses_values_out_of_range_in_one_line(tmp_path, args, expected):
    """Values the panel's properties would clamp are refused, naming the option, its range and
    the value: exit status 2, one line on stderr (no usage dump), nothing run or written."""
    proc = subprocess.run([sys.executable, "-m", "addon", *args, "-o", str(tmp_path / "x.blend")], cwd=str(tmp_path),
                          capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and expected in lines[0], proc.stderr
    assert "usage:" not in proc.stderr and not (tmp_path / "x.blend").exists()


def test_help_lists_every_option(tmp_path):
    out = run(["--help"], cwd=str(tmp_path))
    from addon.bpy_free import options

    for option in options.SETTINGS:
        assert option.flag in out
    assert "between 0.05 and 100 %" in " ".join(out.split())  # a description's own % sign, printed as it is


def test_cli_names_and_defaults_are_the_panels():
    """One set of defaults and names (addon/bpy_free/options.py): the parser's defaults are the
    properties' defaults, and choices are taken in any case."""
    import bpy

    import addon
    from addon.bpy_free import options
    from addon.cli.arguments import checked, parser

    args = checked(parser().parse_args(["--colours", "vertex", "--sampling", "STRATIFIED"]))
    assert args.output == "VERTEX" and args.sampling == "stratified"
    defaults = parser().parse_args([])
    addon.register()
    try:
        from addon.ui.properties import RadiositySettings

        props = RadiositySettings.bl_rna.properties
        for option in options.SETTINGS:
            default = props[option.name].default
            if isinstance(option, options.Number):
                assert getattr(defaults, option.name) == pytest.approx(default), option.name
            else:
                assert getattr(defaults, option.name) == default, option.name
            if isinstance(option, options.Choice):
                assert [i.identifier for i in props[option.name].enum_items] == [i for i, _, _ in option.items]
    finally:
        addon.unregister()


def test_an_operator_error_prints_once(tmp_path):
    """The operator's error reaches the command line once, not as Blender's report and again."""
    import bpy

    from ..conftest import build_test_scene

    def no_emitter():
        build_test_scene()
        bpy.data.objects["Lamp"].select_set(False)
        bpy.data.objects["Lamp"].hide_render = True  # not in the render: it takes no part

    _save_scene(tmp_path / "dark.blend", no_emitter)
    proc = subprocess.run([sys.executable, "-m", "addon", "--open", str(tmp_path / "dark.blend"), "--no-preview",
                           "-o", str(tmp_path / "y.blend")], cwd=str(tmp_path), capture_output=True, text=True,
                          timeout=300, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 1
    assert (proc.stdout + proc.stderr).count("No emitter among the selected objects") == 1, proc.stdout + proc.stderr


def test_cli_warns_before_a_slow_run(tmp_path):
    """A setting that makes the predicted time pass a minute is said before the run, naming the
    patch size and the target (a time limit keeps the test short: under it, Automatic's chunks
    keep the usual size, and the first ones end within it)."""
    proc = subprocess.run([sys.executable, "-m", "addon", "--scene", "cornell", "--patch-size", "0.01", "--error", "0.3",
                           "--time-limit", "1", "--no-preview", "-q", "-o", str(tmp_path / "slow.blend")],
                          cwd=str(tmp_path), capture_output=True, text=True, timeout=600,
                          env={**os.environ, "PYTHONPATH": ROOT})
    # the warning is said before the run, whatever the run then does in its second: ends with
    # the chunks done, or (on a loaded machine) before its first chunk, said in one line
    first_batch = "the time limit (1 s) ended the run before the first batch"
    assert proc.returncode == 0 or (proc.returncode == 1 and first_batch in proc.stderr), proc.stderr[-2000:]
    warning = next(line for line in proc.stderr.splitlines() if line.startswith("warning: Predicted"))
    assert "patch size 0.01" in warning and "0.3% error target" in warning


def test_an_unreachable_cluster_is_one_line_and_nothing_is_written(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "addon", "--scene", "cornell", "--cluster", "tcp://127.0.0.1:9",
                           "--no-preview", "-q", "-o", str(tmp_path / "c.blend")], cwd=str(tmp_path),
                          capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 1
    errors = [line for line in proc.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and "cannot reach the Dask scheduler at 'tcp://127.0.0.1:9'" in errors[0], proc.stderr
    assert not (tmp_path / "c.blend").exists()


def test_a_malformed_cluster_address_is_refused_before_the_scene_is_read(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "addon", "--scene", "cornell", "--cluster", "http://127.0.0.1:8786",
                           "--no-preview", "-q", "-o", str(tmp_path / "c.blend")], cwd=str(tmp_path),
                          capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": ROOT})
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines() == ["error: the cluster address must be tcp://HOST:PORT, or "
                                                "tls://HOST:PORT with the cluster's certificates; got 'http://127.0.0.1:8786'"]
    assert not (tmp_path / "c.blend").exists()


def test_a_service_that_is_not_dask_is_one_line_and_nothing_is_written(tmp_path):
    """An HTTP server's reply where a Dask scheduler's handshake was expected: one line, no
    traceback (Dask read its first 8 bytes as a frame of 3.07 EiB), nothing written."""
    import socket
    import threading

    server = socket.create_server(("127.0.0.1", 0))
    connections = []

    def serve():
        while True:
            try:
                connection, _ = server.accept()
            except OSError:
                return
            connections.append(connection)
            connection.sendall(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n")

    threading.Thread(target=serve, daemon=True).start()
    address = f"tcp://127.0.0.1:{server.getsockname()[1]}"
    try:
        proc = subprocess.run([sys.executable, "-m", "addon", "--scene", "cornell", "--cluster", address,
                               "--error", "10", "--no-preview", "-q", "-o", str(tmp_path / "c.blend")], cwd=str(tmp_path),
                              capture_output=True, text=True, timeout=300, env={**os.environ, "PYTHONPATH": ROOT})
    finally:
        server.close()
        for connection in connections:
            connection.close()
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert lines[0].endswith(f"{address!r} does not answer as a Dask scheduler (another service there?)")
    assert not (tmp_path / "c.blend").exists()


def test_run_sh_takes_paths_from_the_callers_directory(tmp_path):
    """tools/run.sh from another directory: -o and --open are the caller's paths."""
    elsewhere = tmp_path / "work"
    elsewhere.mkdir()
    env = {**os.environ}
    proc = subprocess.run(["bash", os.path.join(ROOT, "tools", "run.sh"), "--scene", "cornell", "--error", "30",
                           "--no-preview", "-q", "-o", "mine.blend"], cwd=str(elsewhere), capture_output=True,
                          text=True, timeout=600, env=env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (elsewhere / "mine.blend").exists() and not os.path.exists(os.path.join(ROOT, "mine.blend"))
    assert "\r" not in proc.stderr  # no progress line when not on a terminal


def test_progress_line_and_summary_speak_of_the_target():
    """The progress line (on a terminal) says paths of those the run is expected to end at, the
    rate, the error against the target and the time left (the solve's, from its measured error);
    the summary the error reached as a share of the target."""
    from types import SimpleNamespace

    from addon.bpy_free.worker import SolveJob
    from addon.cli.progress import progress_text
    from addon.cli.run import summary

    class Job:
        prediction = SimpleNamespace(paths=1_000_000, mean_reflected_radiosity=2.0)
        settings = SimpleNamespace(relative_rms=0.05, paths=None)

        def snapshot(self):
            return {"fraction": 0.25, "paths": 250_000, "seconds": 3.0, "rays_per_second": 2.5e6,
                    "measured_mse": (0.06 * 2.0) ** 2, "relative_error": 0.06, "expected_paths": 1_000_000.0,
                    "seconds_left": 9.0}

        relative_error = staticmethod(SolveJob.relative_error)

    text = progress_text(Job())
    assert "250,000 of 1,000,000 expected paths" in text and "2.50 Mray/s" in text
    assert "error 6.00% (target 5%)" in text and "0:09 left" in text
    settings = SimpleNamespace(last_relative_error=4.5, last_target_error=5.0, last_patches=10, last_paths=100,
                               last_rays=300, last_seconds=1.0, last_mean_path_length=3.0, last_stopped="target",
                               last_estimator="two-way iteration, direct light gathered")
    line = summary("box", settings)
    assert "error 4.50% of a 5% target (90% of it; " in line and "(two-way iteration, direct light gathered)" in line
    # what the error covers, said where it is read
    assert "the patch values' noise, not the flat patches' discretization" in line


# ---------------------------------------------------------------------------------------------
# Curves, text, surfaces, metaballs and modifiers on the command line
# ---------------------------------------------------------------------------------------------

def _curvy_scene():
    """Text, a bevelled curve, a metaball and a NURBS surface patch, a plane arrayed by a modifier and
    an emitter above them, all selected. Returns the expected world bounds."""
    import bpy

    from ..conftest import make_object, principled

    bpy.ops.object.text_add(location=(0, 0, 0))
    bpy.context.active_object.data.extrude = 0.05
    bpy.ops.curve.primitive_bezier_circle_add(radius=0.5, location=(3, 0, 0))
    bpy.context.active_object.data.bevel_depth = 0.1  # tessellated: a tube around the circle
    bpy.ops.object.metaball_add(type="BALL", radius=0.4, location=(0, 3, 0))
    bpy.ops.surface.primitive_nurbs_surface_surface_add(radius=0.5, location=(3, 3, 0))
    floor = make_object("Floor", [(-0.5, -3.5, -1), (0.5, -3.5, -1), (0.5, -2.5, -1), (-0.5, -2.5, -1)],
                        [(0, 1, 2, 3)], [principled("Grey", (0.5, 0.5, 0.5))])
    array = floor.modifiers.new("Array", "ARRAY")
    array.count = 6  # the floor reaches x = 5.5 only through the modifier
    make_object("Sky", [(-1, -4, 2), (6, -4, 2), (6, 4, 2), (-1, 4, 2)], [(0, 3, 2, 1)],
                [principled("Light", (0.5, 0.5, 0.5), (1, 1, 1), 5.0)])
    for o in bpy.data.objects:
        o.select_set(True)
    assert {o.type for o in bpy.data.objects} == {"FONT", "CURVE", "META", "SURFACE", "MESH"}
    return np.array([-1.0, -4.0, -1.0]), np.array([6.0, 4.0, 2.0])


def test_cli_reads_curves_text_surfaces_metaballs_and_modifiers(blender, tmp_path):
    import bpy

    from addon.__main__ import main
    from addon.cli.preview import world_bounds

    lo, hi = _curvy_scene()
    sources = [o for o in bpy.data.objects if o.name not in ("Sky", "Floor")]
    b_lo, b_hi = world_bounds(sources)  # the tessellated geometry, in world space
    # the metaball's surface (x and z = -0.22), the bevelled circle's tube (y = -0.6, x = 3.6) and
    # the NURBS patch (y up to 3.25, bulging to z = 0.46); control points would give other numbers
    np.testing.assert_allclose(b_lo, [-0.223, -0.6, -0.223], atol=0.01)
    np.testing.assert_allclose(b_hi, [3.6, 3.25, 0.459], atol=0.01)
    np.testing.assert_allclose(world_bounds([bpy.data.objects["Floor"]]),
                               [[-0.5, -3.5, -1], [5.5, -2.5, -1]], atol=1e-6)  # with the array modifier
    np.testing.assert_allclose(world_bounds(list(bpy.data.objects)), [lo, hi], atol=1e-6)
    blend = tmp_path / "curvy.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "out.blend"
    assert main(["--current", "--no-preview", "--error", "30", "--threads", "1", "-o", str(out)]) == 0
    # patch size 0, automatic: 1/20 of the selection's largest extent (its evaluated geometry)
    assert blender.scene.radiosity.patch_size == 0
    assert blender.scene.radiosity.last_patch_size == pytest.approx(np.max(hi - lo) / 20, rel=1e-6)
    sources = {o["radiosity_source"] for o in bpy.data.objects if "radiosity_source" in o.keys()}
    assert sources == {o.name for o in bpy.data.objects if "radiosity_source" not in o.keys()}


# ---------------------------------------------------------------------------------------------
# The user's scene is saved as it was (plus the results): the preview's settings are temporary
# ---------------------------------------------------------------------------------------------

def _user_settings(with_camera):
    """A scene with render settings of its own (none of them the preview's)."""
    import bpy

    from ..conftest import build_test_scene

    build_test_scene()
    scene = bpy.context.scene
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.cycles.samples = 77
    scene.cycles.max_bounces = 5
    scene.cycles.use_denoising = True
    scene.cycles.device = "CPU"
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 320, 200, 50
    scene.render.image_settings.file_format = "JPEG"
    scene.render.filepath = "//renders/frame_"
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.look = "AgX - Punchy"
    scene.view_settings.exposure = 0.7
    world = bpy.data.worlds.new("Sky")
    world.color = (0.2, 0.3, 0.4)
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.2, 0.3, 0.4, 1.0)
    scene.world = world
    if with_camera:
        camera = bpy.data.objects.new("My Camera", bpy.data.cameras.new("My Camera"))
        scene.collection.objects.link(camera)
        camera.location = (0.5, -2.0, 0.5)
        camera.rotation_euler = (1.5708, 0.0, 0.0)
        scene.camera = camera


def _settings_of(scene):
    """What the preview must not leave behind in the user's scene."""
    import bpy

    render, cycles, view = scene.render, scene.cycles, scene.view_settings
    world = scene.world
    return {
        "render": (render.engine, render.resolution_x, render.resolution_y, render.resolution_percentage,
                   render.filepath, render.image_settings.file_format, render.image_settings.color_mode),
        "cycles": (cycles.samples, cycles.max_bounces, cycles.use_denoising, cycles.device),
        "view": (view.view_transform, view.look, round(view.exposure, 6)),
        "world": world and (world.name, tuple(round(c, 6) for c in world.color),
                            tuple(round(c, 6) for c in world.node_tree.nodes["Background"].inputs["Color"].default_value)),
        "camera": scene.camera and scene.camera.name,
        "objects": sorted(o.name for o in bpy.data.objects if "radiosity_source" not in o.keys()),
        "cameras": sorted(c.name for c in bpy.data.cameras),
        "worlds": sorted(w.name for w in bpy.data.worlds),
        "hidden": sorted(o.name for o in bpy.data.objects if o.hide_render),
    }


PREVIEW_ARGS = ["--error", "20", "--patch-size", "0.5", "--threads", "1", "--resolution", "32", "--samples", "1"]


def test_cli_open_saves_the_users_settings_unchanged(tmp_path):
    """--open: the saved .blend holds the user's render settings, world and camera as they were,
    plus the results; the preview's temporary camera (for a scene with none) is not kept."""
    import bpy

    from ..conftest import result_objects

    for with_camera in (True, False):
        source = tmp_path / f"user_{with_camera}.blend"
        _save_scene(source, lambda: _user_settings(with_camera))
        bpy.ops.wm.open_mainfile(filepath=str(source))
        expected = _settings_of(bpy.context.scene)
        assert (expected["camera"] is not None) == with_camera
        out, png = tmp_path / f"out_{with_camera}.blend", tmp_path / f"out_{with_camera}.png"
        run(["--open", str(source), "-o", str(out), "--preview", str(png), *PREVIEW_ARGS], cwd=str(tmp_path))
        assert png.exists()
        bpy.ops.wm.open_mainfile(filepath=str(out))
        assert _settings_of(bpy.context.scene) == expected
        assert sorted(o["radiosity_source"] for o in result_objects()) == ["Block", "Lamp", "Room"]
    bpy.ops.wm.read_factory_settings(use_empty=True)


# ---------------------------------------------------------------------------------------------
# The README's  blender --background file.blend --python-expr "...main(['--current'])"
# ---------------------------------------------------------------------------------------------

def test_cli_current_solves_the_loaded_file(blender, tmp_path):
    import bpy

    from addon.__main__ import main

    from ..conftest import read_colours, result_objects

    source = tmp_path / "room.blend"
    _save_scene(source, lambda: _user_settings(with_camera=True))
    # an unselected mesh takes no part
    bpy.ops.wm.open_mainfile(filepath=str(source))
    from ..conftest import make_object

    make_object("Bystander", [(0, 0, 2), (1, 0, 2), (1, 1, 2)], [(0, 1, 2)]).select_set(False)
    bpy.ops.wm.save_mainfile()
    bpy.ops.wm.open_mainfile(filepath=str(source))
    assert sorted(o.name for o in bpy.context.selected_objects) == ["Block", "Lamp", "Room"]
    before = _settings_of(bpy.context.scene)
    out, png = tmp_path / "out" / "room_solved.blend", tmp_path / "out" / "room_solved.png"
    assert main(["--current", "-o", str(out), "--preview", str(png), *PREVIEW_ARGS]) == 0
    # the loaded file: results added, everything else as it was, still the same file
    assert bpy.data.filepath == str(source)
    assert sorted(o["radiosity_source"] for o in result_objects()) == ["Block", "Lamp", "Room"]
    assert _settings_of(bpy.context.scene) == before
    assert bpy.context.scene.radiosity.last_paths > 0
    # the outputs: a preview that shows something, a .blend with the results and the user's settings
    image = bpy.data.images.load(str(png))
    pixels = np.empty(len(image.pixels), dtype=np.float32)
    image.pixels.foreach_get(pixels)
    assert (image.size[0], image.size[1]) == (32, 20)  # the scene's own frame shape, 320 x 200
    assert pixels.reshape(-1, 4)[:, :3].max() > 0.05
    colours = {o["radiosity_source"]: read_colours(o.data, "Radiosity")[1].copy() for o in result_objects()}
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert _settings_of(bpy.context.scene) == before
    saved = {o["radiosity_source"]: read_colours(o.data, "Radiosity")[1] for o in result_objects()}
    assert saved.keys() == colours.keys()
    for name in saved:
        np.testing.assert_array_equal(saved[name], colours[name])


def test_the_main_job_solves_the_box_at_its_own_target_unless_the_command_line_gives_one(tmp_path):
    """The Cornell sample brings a 2% target for its picture (the 5% default left tile mottling on
    the README's first image); --error, when given, still decides (in either spelling)."""
    from addon.cli.arguments import given_options

    assert given_options(["--scene", "cornell", "--error=5", "--no-preview"]) == {"target_error"}
    assert given_options(["--no-scene-objects", "--seed", "3"]) == {"use_scene_objects", "seed"}
    quick = ["--scene", "cornell", "--patch-size", "0.4", "--no-preview", "--threads", "1", "-q"]
    own = run([*quick, "-o", str(tmp_path / "own.blend")], cwd=str(tmp_path))
    given = run([*quick, "--error", "5", "-o", str(tmp_path / "given.blend")], cwd=str(tmp_path))
    assert "of a 2% target" in own, own[-2000:]
    assert "of a 5% target" in given, given[-2000:]
