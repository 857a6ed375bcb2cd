"""Bad input and bad timing in Blender: each case ends with a clear report, the scene
is either unchanged or holds the complete new result, and the worker thread is gone."""

import math
import os
import subprocess
import sys
import time

import bpy
import numpy as np
import pytest

import addon
from addon.ui import estimate
from addon.bpy_free import pipeline
from addon.blender_read import SceneError, images, objects as object_reading
from addon.blender_read.materials import material_colours
from addon.blender_read.selection import MAX_REFLECTIVITY, read_selection
from addon.bpy_free import patches, worker

from ..conftest import ROOT, box_arrays, build_test_scene, make_object, principled, read_colours, result_objects
from ..test_extension import _drive, _modal_operator, _snapshot, configure


def _unchanged_after_error(context, match):
    """Run the solve synchronously; it must fail with ``match`` and change nothing."""
    before = _snapshot()
    results = {o.name: read_colours(o.data, "Radiosity")[1].tobytes() for o in result_objects()}
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.radiosity.solve()
    assert _snapshot() == before
    assert {o.name: read_colours(o.data, "Radiosity")[1].tobytes() for o in result_objects()} == results


def _run_sync(context):
    """The operator's synchronous path (blender_write.solve_job.run) with its reports captured:
    (state, reports)."""
    from addon.blender_write import solve_job

    finished = solve_job.run(context)
    return {finished.status}, finished.messages


def _select(*names):
    for o in bpy.data.objects:
        o.select_set(o.name in names)


# ---------------------------------------------------------------------------------------------
# Selection
# ---------------------------------------------------------------------------------------------

def test_nothing_selected_and_no_mesh_selected(blender):
    build_test_scene()
    configure(blender)
    _select()
    _unchanged_after_error(blender, "Select one or more mesh objects")
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    lamp = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    holder = bpy.data.collections.new("Props")
    instancer = bpy.data.objects.new("Instancer", None)
    instancer.instance_type = "COLLECTION"
    instancer.instance_collection = holder
    for o in (camera, lamp, instancer):
        blender.scene.collection.objects.link(o)
    _select("Camera", "Sun", "Instancer")
    _unchanged_after_error(
        blender, r"No mesh among the selected objects: 'Camera' is a camera; 'Instancer' instances collection "
        r"'Props', which holds no mesh; 'Sun' is a light")
    # With meshes too, the others are skipped with a note.
    _select("Camera", "Instancer", "Room", "Lamp", "Block")
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}
    assert ("WARNING", "'Camera' is a camera: skipped") in reports
    assert any(kind == "WARNING" and "'Instancer' instances collection 'Props'" in text for kind, text in reports)


def test_no_emitter_and_zero_strength(blender):
    build_test_scene()
    configure(blender)
    _select("Room", "Block")
    # the lamp, not selected, still lights the room (the rest of the scene, as in a render)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    assert sorted(o["radiosity_source"] for o in result_objects()) == ["Block", "Room"]
    bpy.data.objects["Lamp"].hide_render = True  # hidden from render: it takes no part
    _unchanged_after_error(blender, "No emitter among the selected objects")
    bpy.data.objects["Lamp"].hide_render = False
    _select("Room", "Block", "Lamp")
    bpy.data.materials["Emitter"].node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 0.0
    _unchanged_after_error(blender, "No emitter among the selected objects")


@pytest.mark.parametrize("where", ["Base Color", "Emission Strength", "Emission Color"])
def test_nan_in_a_material_is_named(blender, where):
    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}  # a previous result that must survive
    node = bpy.data.materials["Emitter"].node_tree.nodes["Principled BSDF"]
    socket = node.inputs[where]
    socket.default_value = math.nan if where == "Emission Strength" else (math.nan, 0.5, 0.5, 1.0)
    what = "base colour" if where == "Base Color" else "emission"
    _unchanged_after_error(blender, rf"'Lamp': the {what} of material 'Emitter' is not a finite number")


# ---------------------------------------------------------------------------------------------
# Reflectivity of 1 or more: refused with the reason, or clamped on request
# ---------------------------------------------------------------------------------------------

def test_white_base_colour_is_refused_with_the_reason_or_clamped_on_request(blender):
    build_test_scene()
    configure(blender)
    white = bpy.data.materials["White"].node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    white.default_value = (1.0, 1.0, 1.0, 1.0)
    _unchanged_after_error(
        blender, r"'Room': material 'White' has a reflectivity \(base colour, .*\) of 1\. .*reflectivity below 1: .*never lets a "
        r"random walk end in a closed room.*'Clamp bright colours'")
    # Opt in: clamped to 0.99, solved, and said so.
    blender.scene.radiosity.clamp_reflectivity = True
    objects, notes = read_selection(blender)
    room = next(o for o in objects if o.name == "Room")
    assert room.face_reflectivity.max() == MAX_REFLECTIVITY
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}
    assert any(kind == "WARNING" and "'White' above 0.99 were clamped to 0.99" in text for kind, text in reports)
    # Below 1 nothing is changed, clamp or not: 0.995 stays 0.995 (slow, but what was asked).
    blender.scene.radiosity.clamp_reflectivity = False
    white.default_value = (0.995, 0.995, 0.995, 1.0)
    objects, notes = read_selection(blender)
    room = next(o for o in objects if o.name == "Room")
    np.testing.assert_allclose(room.face_reflectivity.max(), 0.995, rtol=1e-6)
    assert not any("clamp" in n for n in notes)


# ---------------------------------------------------------------------------------------------
# Textures
# ---------------------------------------------------------------------------------------------

def test_image_texture_uses_the_average_linear_colour_and_says_so(blender):
    m = principled("Painted", (0.1, 0.1, 0.1))
    tree = m.node_tree
    image = bpy.data.images.new("Paint", 4, 2)  # 8-bit sRGB
    pixels = np.zeros((8, 4), np.float32)
    pixels[:, 3] = 1
    pixels[:4, :3] = [0.2, 0.6, 1.0]
    pixels[4:, :3] = [0.8, 0.4, 0.0]
    image.pixels.foreach_set(pixels.ravel())
    stored = np.empty(32, np.float32)
    image.pixels.foreach_get(stored)  # 8-bit quantised
    # (the mean of the linear pixels as kept for the patches' texture lookups, float32)
    expected = images.srgb_to_linear(stored.reshape(8, 4)[:, :3].astype(float)).astype(np.float32).mean(axis=0, dtype=float)
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    R, E, notes = material_colours(m)
    np.testing.assert_allclose(R, expected, rtol=1e-9)
    assert 0.2 < R[0] < 0.4  # linear, not the sRGB mean 0.5
    assert any("image 'Paint'" in n and "average colour" in n for n in notes)
    # A procedural texture has no known average: the socket's own colour, and a note saying so.
    noise = tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(noise.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    R, E, notes = material_colours(m)
    np.testing.assert_allclose(R, 0.1, rtol=1e-6)
    assert any("driven by 'Noise Texture'" in n and "socket's own colour" in n for n in notes)
    # An image without pixels (missing file): the socket's colour, said so.
    missing = bpy.data.images.new("Gone", 4, 4)
    missing.source = "FILE"
    missing.filepath = os.path.join(ROOT, "no_such_file.png")
    missing.reload()
    tex.image = missing
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    R, E, notes = material_colours(m)
    np.testing.assert_allclose(R, 0.1, rtol=1e-6)
    assert any("no pixels" in n for n in notes)
    # The same image driving the emission colour: the light is unknown, refused by name (a
    # white emitter of the socket's colour was solved). At strength 0 it gives no light: no error.
    tree.links.new(tex.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Emission Color"])
    tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 0.0
    material_colours(m)
    tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 5.0
    with pytest.raises(SceneError, match=r"^material 'Painted': its 'Emission Color' comes from image 'Gone', "
                                                  r"which has no pixels \(file not found: .*no_such_file.png\)"):
        material_colours(m)
    glow = bpy.data.materials.new("Glow")
    glow.node_tree.nodes.clear()
    emission = glow.node_tree.nodes.new("ShaderNodeEmission")
    glow.node_tree.links.new(emission.outputs["Emission"],
                             glow.node_tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    glow_image = glow.node_tree.nodes.new("ShaderNodeTexImage")
    glow_image.image = missing
    glow.node_tree.links.new(glow_image.outputs["Color"], emission.inputs["Color"])
    with pytest.raises(SceneError, match=r"^material 'Glow': its 'Color' comes from image 'Gone'"):
        material_colours(glow)


# ---------------------------------------------------------------------------------------------
# Time limits
# ---------------------------------------------------------------------------------------------

def test_time_limit_before_the_first_batch_writes_nothing(blender):
    """A closed glowing room of albedo 0.99999: every path bounces ~1e5 times, so one batch takes
    seconds, far beyond the limit. No path is finished, and an emission-only 'result' must not
    be written."""
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", v, f, [principled("Glow", (0.99999,) * 3, (1, 1, 1), 1.0)]).select_set(True)
    configure(blender)
    blender.scene.radiosity.time_limit = 0.01
    before = _snapshot()
    state, reports = _run_sync(blender)
    assert state == {"CANCELLED"}
    assert any(kind == "ERROR" and "before the first batch" in text for kind, text in reports)
    assert not result_objects() and _snapshot() == before and blender.scene.radiosity.last_paths == 0


def test_time_limit_keeps_the_paths_done_and_says_so(blender):
    build_test_scene()
    configure(blender)
    s = blender.scene.radiosity
    s.target_error = 0.05  # millions of paths
    s.time_limit = 1.5  # several batches of ~0.05 s each, even on a loaded machine
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}
    assert any(kind == "WARNING" and text.startswith("Time limit reached") for kind, text in reports)
    assert s.last_stopped == "time_limit" and s.last_paths > 0
    assert len(result_objects()) == 3
    for o in result_objects():
        colours = read_colours(o.data, "Radiosity")[1]
        assert np.isfinite(colours).all() and (colours >= 0).all()


def test_a_target_not_reached_at_the_path_cap_is_said(blender):
    """A run whose measured error is still above the target when it reaches its path cap says so
    in a warning with the error it reached (the operator's reports after writing, from the
    run's statistics); a run that met its target does not."""
    from addon.blender_write import solve_job

    build_test_scene()
    configure(blender)
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    s = blender.scene.radiosity
    stats = {name: getattr(s, name) for name in ("last_paths", "last_rays", "last_seconds", "last_patches",
                                                  "last_relative_error", "last_target_error", "last_stopped",
                                                  "last_light_account")}

    class Output:
        notes, back_warning = [], None

    def warnings_for(**changes):
        started = solve_job.Started(None, [], 0, {}, {})
        return [text for kind, text in solve_job.after_writing(s, started, Output(), {**stats, **changes})
                if kind == "WARNING"]

    assert s.last_stopped == "target" and not any("not reached" in w for w in warnings_for())
    missed = warnings_for(last_stopped="paths", last_relative_error=2.5 * s.last_target_error)
    assert any(w.startswith(f"The {s.last_target_error:g}% error target was not reached") and "2.5x" in w
               for w in missed), missed


# ---------------------------------------------------------------------------------------------
# While the worker runs: an object deleted, another file loaded
# ---------------------------------------------------------------------------------------------

def _start_long_job(context):
    configure(context)
    context.scene.radiosity.target_error = 0.05  # millions of paths: still running when we act
    op = _modal_operator()
    assert op._start(context) is None
    t0 = time.perf_counter()
    while op._started.job.snapshot()["paths"] == 0 and time.perf_counter() - t0 < 60:
        time.sleep(0.01)
    return op


def test_object_deleted_while_solving_a_completed_run_is_not_written(blender):
    build_test_scene()
    configure(blender)
    s = blender.scene.radiosity
    s.target_error = 0.05
    s.time_limit = 1.5  # the run completes by itself (time limit) after the deletion
    op = _modal_operator()
    assert op._start(blender) is None
    bpy.data.objects.remove(bpy.data.objects["Block"], do_unlink=True)
    state = _drive(op, blender)
    assert state == {"CANCELLED"}
    assert op._started.job.output is not None and op._started.job.output.result.paths > 0  # a complete run...
    assert any(kind == "ERROR" and "'Block' was deleted while solving" in text for kind, text in op.reports)
    assert not result_objects()  # ...that is not written for a scene that no longer exists
    assert not op._started.job.alive and worker.running_job() is None


@pytest.mark.parametrize("blender_cancels_the_modal", [True, False])
def test_new_file_while_solving_stops_the_worker_and_writes_nothing(blender, blender_cancels_the_modal):
    build_test_scene()
    op = _start_long_job(blender)
    job = op._started.job
    bpy.ops.wm.read_homefile(use_empty=True)  # load_pre: the worker is stopped
    assert not job.alive and job.cancelled and worker.running_job() is None
    if blender_cancels_the_modal:  # what Blender does to running modal operators on a load
        from addon.ui.operators import RADIOSITY_OT_solve

        RADIOSITY_OT_solve.cancel(op, bpy.context)
    else:  # a last timer tick reaches the operator: it must not write into the new file
        assert _drive(op, bpy.context) == {"CANCELLED"}
    assert not result_objects() and "Radiosity" not in bpy.data.collections
    assert worker.running_job() is None


def test_a_finished_job_from_the_previous_file_is_not_written(blender):
    """Even a job that completed just before the load must not write into the new file."""
    build_test_scene()
    configure(blender)
    op = _modal_operator()
    assert op._start(blender) is None
    op._started.job.join(timeout=60)
    assert op._started.job.output is not None and op._started.job.output.result.stopped == "target"
    worker.set_running_job(None)
    bpy.ops.wm.read_homefile(use_empty=True)
    build_test_scene()  # same names in the new file
    assert _drive(op, bpy.context) == {"CANCELLED"}
    assert any("the file changed while solving" in text for _, text in op.reports)
    assert not result_objects()


@pytest.mark.parametrize("hook", [True, False])
def test_quitting_while_solving_stops_the_worker(tmp_path, hook):
    """The Python process (Blender) ending with a solve running whose batches take minutes
    (walls of 0.99999): the exit hooks cancel the worker, the process exits within seconds, and
    the worker thread is gone. Without the hook (the control case) the exit waits for the batch."""
    script = tmp_path / "quit.py"
    script.write_text(
        "import atexit, sys, time\n"
        f"sys.path.insert(0, {ROOT!r})\n"
        "job = None\n"
        "def report():\n"
        "    print('worker alive after the hooks:', job.alive, flush=True)\n"
        "atexit.register(report)  # registered first: runs last\n"
        "import bpy, addon, threading\n"
        "from addon.bpy_free import pipeline\n"
        "from addon.blender_read.selection import read_selection\n"
        "from addon.bpy_free import patches, worker\n"
        f"if not {hook}:\n"
        "    threading._threading_atexits[:] = [f for f in threading._threading_atexits\n"
        "                                       if getattr(f, 'func', f) is not worker._stop_at_exit]\n"
        "from tests.blender.conftest import box_arrays, make_object, principled\n"
        "bpy.ops.wm.read_factory_settings(use_empty=True)\n"
        "addon.register()\n"
        "v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)\n"
        "room = make_object('Room', v, f, [principled('Glow', (0.99999,) * 3, (1, 1, 1), 1.0)])\n"
        "room.select_set(True)\n"
        "objects, _ = read_selection(bpy.context)\n"
        "settings = bpy.context.scene.radiosity.solve_settings().but(paths=10**6, threads=2)\n"
        "job = worker.SolveJob(objects, settings).start()\n"
        "worker.set_running_job(job)\n"
        "time.sleep(1.0)\n"
        "assert job.alive and job.snapshot()['paths'] == 0\n"
        "print('quitting', flush=True)\n"
        "t0 = time.perf_counter()\n"
        "sys.exit(0)\n"
    )
    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                              timeout=20 if hook else 5)
    except subprocess.TimeoutExpired:
        assert not hook, "the process did not exit within 20 s with the hook"
        return  # the control case: still stuck in the batch when killed after 5 s
    elapsed = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "quitting" in proc.stdout
    if hook:
        assert "worker alive after the hooks: False" in proc.stdout, proc.stdout
        assert elapsed < 15
    else:
        raise AssertionError(f"without the hook the process exited in {elapsed:.1f} s: the control case "
                             "no longer shows the problem, so the test proves nothing")


# ---------------------------------------------------------------------------------------------
# Geometry through Blender: n-gons, modifiers, negative scale, linked duplicates
# ---------------------------------------------------------------------------------------------

def _prism(name, sides, radius, height, material, inward=True, location=(0, 0, 0), scale=(1, 1, 1)):
    angles = 2 * np.pi * np.arange(sides) / sides
    ring = np.c_[radius * np.cos(angles), radius * np.sin(angles)]
    vertices = np.vstack([np.c_[ring, np.zeros(sides)], np.c_[ring, np.full(sides, height)]])
    bottom = tuple(range(sides - 1, -1, -1))
    top = tuple(range(sides, 2 * sides))
    sides_faces = [(k, (k + 1) % sides, sides + (k + 1) % sides, sides + k) for k in range(sides)]
    faces = [bottom, top, *sides_faces]  # outward
    if inward:
        faces = [tuple(reversed(f)) for f in faces]
    return make_object(name, vertices, faces, [material], location=location, scale=scale)


def _t_critical(alpha, dof):
    """c with P(|t_dof| > c) = alpha, by integrating Student's density (no scipy here)."""
    x = np.linspace(0, 200, 2_000_001)
    log_norm = math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2) - 0.5 * math.log(dof * math.pi)
    density = np.exp(log_norm - (dof + 1) / 2 * np.log1p(x * x / dof))
    tail = 2 * (np.trapz(density, x) - np.concatenate([[0], np.cumsum((density[1:] + density[:-1]) / 2 * np.diff(x))]))
    return float(x[np.searchsorted(-tail, -alpha)])


def test_furnace_through_blender_with_ngons_modifiers_mirror_and_linked_duplicates(blender):
    """A closed room made of an n-gon prism (octagon floor and ceiling), mirrored (negative
    scale), with a bevel and a subdivision modifier, and every face emitting S with albedo R:
    B = S / (1 - R) on every patch, exactly in expectation, whatever the geometry. The batch
    variance of each patch gives the band. Emitting faces emit from their back too, and the
    rounded room is not convex: the backs of most of its faces see room vertices behind them and
    emit out of it, where their light escapes or meets the room's outside (its faces' backs).
    Every other path stays in: the paths that end so are a binomial count of the backs' share."""
    S, R = 1.0, 0.5
    glow = principled("Glow", (R, R, R), (1, 1, 1), S)
    room = _prism("Room", 8, 2.0, 1.5, glow, inward=True, scale=(-1, 1, 1))
    room.modifiers.new("Bevel", "BEVEL").width = 0.1
    room.modifiers.new("Subdivision", "SUBSURF").levels = 1
    # Two linked duplicates (one mesh) of an outward box inside the room, also glowing.
    v, f = box_arrays((-0.2, -0.2, 0.0), (0.2, 0.2, 0.4), inward=False)
    block = make_object("Block", v, f, [glow], location=(-0.6, 0, 0.5))
    twin = bpy.data.objects.new("Block Twin", block.data)
    twin.location = (0.6, 0.3, 0.6)
    blender.scene.collection.objects.link(twin)
    _select("Room", "Block", "Block Twin")
    configure(blender)
    blender.scene.radiosity.patch_size = 0.5
    objects, notes = read_selection(blender)
    # (the walk: the band below is the walk's, its hits per path)
    settings = blender.scene.radiosity.solve_settings().but(paths=200_000, threads=2, method="walk")
    output = pipeline.run_solve(objects, settings)
    r = output.result
    scene = output.patches.patch_scene()
    A = scene.patch_area
    back = float((A * scene.back_emits).sum() / (A * scene.emitting_sides).sum())  # the backs' share of the paths
    lost = r.path_ends["escaped"] + r.path_ends["blocked"]
    assert 0 < back and abs(lost - r.paths * back) < 4.5 * math.sqrt(r.paths * back * (1 - back)), (lost, r.paths * back)
    # Area-weighted mean: a front path's hits are geometric (mean 1/(1-R), variance R/(1-R)^2),
    # a back path's none, each path Phi_T / N = S A_T / (q N) of power (q = 1 - back).
    mean_b = (A * r.reflected[:, 0]).sum() / A.sum()
    q = 1 - back
    sd = R * S * math.sqrt((1 + R) / q - 1) / (1 - R) / math.sqrt(r.paths)
    assert abs(mean_b - S * R / (1 - R)) < 4.5 * sd
    # Per patch: the batch estimate of the variance has chunks - 1 degrees of freedom, so z is
    # Student-t; the bound keeps P(any patch out) below 1e-3 (Bonferroni over the patches).
    z = (r.radiosity[:, 0] - S / (1 - R)) / np.sqrt(r.reflected_variance[:, 0])
    assert np.abs(z).max() < _t_critical(1e-3 / len(z), r.chunks - 1), (np.abs(z).max(), len(z), r.chunks)
    # And through the operator: one result per object, the twins apart.
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    names = sorted(o["radiosity_source"] for o in result_objects())
    assert names == ["Block", "Block Twin", "Room"]


# ---------------------------------------------------------------------------------------------
# Geometry the user should hear about: flipped normals, duplicated faces
# ---------------------------------------------------------------------------------------------

def test_flipped_normals_are_reported(blender):
    """A room whose faces point out: the lamp's light lands on back sides and is absorbed. The
    run finishes (the numbers are right for the geometry given) and says what happened."""
    build_test_scene()
    room = bpy.data.objects["Room"]
    room.data.flip_normals()
    configure(blender)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}
    warning = [text for kind, text in reports if kind == "WARNING" and "back of faces" in text]
    assert warning, reports
    share = float(warning[0].split("%")[0])
    assert share > 50  # most of the light: the room is inside out
    # The normal scene stays below the warning threshold (its lamp's back, which emits, takes what
    # the ceiling sends back: an emitter's back is no face to flip).
    room.data.flip_normals()
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"} and not any(kind == "WARNING" and "back of faces" in text for kind, text in reports)


def test_duplicated_faces_are_reported_with_their_objects(blender):
    """A block duplicated in place (Shift+D, then cancelling the move): every face lies on top
    of another. The solve runs and says which objects hold the duplicates."""
    build_test_scene()
    block = bpy.data.objects["Block"]
    copy = block.copy()
    copy.data = block.data.copy()
    copy.name = "Block Copy"
    blender.scene.collection.objects.link(copy)
    copy.select_set(True)
    configure(blender)
    for run in range(2):  # the second run reuses the cached geometry: still said, still named
        state, reports = _run_sync(blender)
        assert state == {"FINISHED"}
        assert any(kind == "WARNING" and "duplicated faces" in text and "'Block'" in text
                   and "'Block Copy'" in text for kind, text in reports), (run, reports)


def test_zero_area_faces_are_left_out_with_a_note(blender):
    """Imported meshes often hold faces with collinear or coincident corners. They are left out
    (they are invisible) instead of making the whole scene fail; an object of nothing but such
    faces is skipped. Both said."""
    build_test_scene()
    v = [(0.1, 0.1, 0.5), (0.2, 0.1, 0.5), (0.3, 0.1, 0.5), (0.5, 0.5, 0.5), (0.5, 0.5, 0.5), (0.5, 0.5, 0.5),
         (0.6, 0.6, 0.2), (0.7, 0.6, 0.2), (0.7, 0.7, 0.2), (0.6, 0.7, 0.2)]
    make_object("Junk", v, [(0, 1, 2), (3, 4, 5), (6, 7, 8, 9)]).select_set(True)
    make_object("Dust", [(0.4, 0.4, 0.4), (0.45, 0.4, 0.4), (0.5, 0.4, 0.4)], [(0, 1, 2)]).select_set(True)
    configure(blender)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports
    assert ("WARNING", "'Junk': 2 faces of zero area (collinear or coincident corners) left out") in reports
    assert ("WARNING", "'Dust': every face has zero area; the object was skipped") in reports
    names = sorted(o["radiosity_source"] for o in result_objects())
    assert names == ["Block", "Junk", "Lamp", "Room"]
    junk = bpy.data.objects["Junk Radiosity"].data
    assert len(junk.polygons) >= 1
    colours = read_colours(junk, "Radiosity")[1]
    assert np.isfinite(colours).all() and (colours[:, :3] > 0).all()  # the good quad is lit


def test_switching_scene_while_solving_writes_into_the_scene_solved(blender):
    build_test_scene()
    configure(blender)
    solved = blender.scene
    op = _modal_operator()
    assert op._start(blender) is None
    other = bpy.data.scenes.new("Other")
    blender.window.scene = other  # the user switches scene while it runs
    assert bpy.context.scene == other
    assert _drive(op, bpy.context) == {"FINISHED"}
    assert len(result_objects()) == 3
    radiosity = bpy.data.collections["Radiosity"]
    assert radiosity.name in solved.collection.children and radiosity.name not in other.collection.children
    assert solved.radiosity.last_paths > 0 and other.radiosity.last_paths == 0


def test_the_load_handler_comes_and_goes_with_the_extension():
    import addon
    from addon.ui.operators import _on_load_pre

    addon.register()
    assert _on_load_pre in bpy.app.handlers.load_pre
    addon.unregister()
    assert _on_load_pre not in bpy.app.handlers.load_pre


def test_escape_stops_a_batch_of_endless_paths_promptly(blender):
    """Albedo 0.99999: a batch takes seconds and no path ends in the first 0.3 s; Esc still
    ends the run within a few seconds, the scene unchanged and the worker gone."""
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
    make_object("Room", v, f, [principled("Glow", (0.99999,) * 3, (1, 1, 1), 1.0)]).select_set(True)
    configure(blender)
    before = _snapshot()
    op = _modal_operator()
    assert op._start(blender) is None
    time.sleep(0.3)
    assert op._started.job.snapshot()["paths"] == 0 and op._started.job.alive
    t0 = time.perf_counter()
    from ..test_extension import FakeEvent

    assert op.modal(blender, FakeEvent("ESC", "PRESS")) == {"RUNNING_MODAL"}
    assert _drive(op, blender, seconds=10) == {"CANCELLED"}
    assert time.perf_counter() - t0 < 3.0
    assert not op._started.job.alive and worker.running_job() is None
    assert not result_objects() and _snapshot() == before


def test_an_unforeseen_error_while_reading_is_a_report(blender, monkeypatch):
    build_test_scene()
    configure(blender)

    def broken(*args, **kwargs):
        raise AttributeError("'NoneType' object has no attribute 'vertices'")

    monkeypatch.setattr(object_reading, "read_object", broken)
    _unchanged_after_error(blender, r"Reading the selection failed \(AttributeError: .*\); the scene is unchanged")



def test_collection_and_geometry_node_instances_are_realised(blender):
    """Instances are part of the scene the artist sees: a collection instance (an empty) and a
    geometry-nodes scatter (Instance on Points) are each solved as objects of their own, placed
    where the instances are, and get result objects 'Parent [k] Radiosity'."""
    build_test_scene()
    props = bpy.data.collections.new("Props")  # not linked to the scene: only instanced
    v, f = box_arrays((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), inward=False)
    crate = make_object("Crate", v, f)
    blender.scene.collection.objects.unlink(crate)
    props.objects.link(crate)
    instancer = bpy.data.objects.new("Instancer", None)
    instancer.instance_type = "COLLECTION"
    instancer.instance_collection = props
    instancer.location = (0.6, 0.6, 0.0)
    blender.scene.collection.objects.link(instancer)
    # A plane scattering a small cube on its 4 corners with geometry nodes.
    scatter = make_object("Scatter", [(0.2, 0.6, 0.3), (0.4, 0.6, 0.3), (0.4, 0.8, 0.3), (0.2, 0.8, 0.3)],
                          [(0, 1, 2, 3)])
    tree = bpy.data.node_groups.new("Scatter cubes", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    group_in, group_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    cube = tree.nodes.new("GeometryNodeMeshCube")
    cube.inputs["Size"].default_value = (0.05, 0.05, 0.05)
    on_points = tree.nodes.new("GeometryNodeInstanceOnPoints")
    tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
    tree.links.new(cube.outputs["Mesh"], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], group_out.inputs[0])
    scatter.modifiers.new("Scatter", "NODES").node_group = tree
    _select("Room", "Lamp", "Block", "Instancer", "Scatter")
    configure(blender)
    objects, notes = read_selection(blender)
    names = sorted(o.name for o in objects)
    assert names == ["Block", "Instancer [0]", "Lamp", "Room", "Scatter [0]", "Scatter [1]", "Scatter [2]",
                     "Scatter [3]"], names
    crate_arrays = next(o for o in objects if o.name == "Instancer [0]")
    np.testing.assert_allclose(crate_arrays.vertices.min(axis=0), [0.6, 0.6, 0.0], atol=1e-6)
    np.testing.assert_allclose(crate_arrays.vertices.max(axis=0), [0.7, 0.7, 0.1], atol=1e-6)
    corners = sorted(tuple(np.round(o.vertices.mean(axis=0), 6)) for o in objects if o.name.startswith("Scatter"))
    assert corners == [(0.2, 0.6, 0.3), (0.2, 0.8, 0.3), (0.4, 0.6, 0.3), (0.4, 0.8, 0.3)]
    assert not any("skipped" in n for n in notes)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports
    results = sorted(o["radiosity_source"] for o in result_objects())
    assert results == names
    for o in result_objects():
        colours = read_colours(o.data, "Radiosity")[1]
        assert np.isfinite(colours).all() and (colours[:, :3] > 0).any()


def test_text_and_curves_are_tessellated_like_meshes(blender):
    """A glowing text object (a sign) lights the room: text, curves, surfaces and metaballs are
    read through their evaluated mesh, as Blender renders them. A flat curve without faces is
    skipped with a note."""
    build_test_scene()
    text_data = bpy.data.curves.new("Sign", "FONT")
    text_data.body = "EXIT"
    text_data.size = 0.15
    sign = bpy.data.objects.new("Sign", text_data)
    sign.location = (0.3, 0.5, 0.6)
    sign.data.materials.append(principled("Neon", (0.5, 0.5, 0.5), (0.2, 1.0, 0.2), 5.0))
    blender.scene.collection.objects.link(sign)
    wire = bpy.data.curves.new("Wire", "CURVE")
    spline = wire.splines.new("POLY")
    spline.points.add(1)
    wire_object = bpy.data.objects.new("Wire", wire)
    blender.scene.collection.objects.link(wire_object)
    _select("Room", "Block", "Sign", "Wire")
    bpy.data.objects["Lamp"].hide_render = True  # the lamp is off: the sign is the only emitter
    configure(blender)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports
    assert ("WARNING", "'Wire' has no faces and was skipped") in reports
    assert sorted(o["radiosity_source"] for o in result_objects()) == ["Block", "Room", "Sign"]
    room = read_colours(bpy.data.objects["Room Radiosity"].data, "Radiosity")[1]
    assert (room[:, 1] > room[:, 0]).mean() > 0.6  # lit green by the sign (5 of 6 walls are white)


def test_object_moved_while_solving_is_reported(blender):
    build_test_scene()
    configure(blender)
    s = blender.scene.radiosity
    s.target_error = 0.05
    s.time_limit = 1.0
    op = _modal_operator()
    assert op._start(blender) is None
    block = bpy.data.objects["Block"]
    block.location = (0.1, 0.0, 0.0)  # the user moves it while the worker runs
    bpy.context.view_layer.update()  # matrix_world follows the location
    assert _drive(op, blender) == {"FINISHED"}
    warnings = [text for kind, text in op.reports if kind == "WARNING"]
    assert any("'Block' moved while solving" in text for text in warnings)
    assert not any("'Room'" in text and "moved" in text for text in warnings)
    assert len(result_objects()) == 3  # the complete result of the scene as it was is written
    assert not op._started.job.alive and worker.running_job() is None


def test_unmoved_objects_give_no_moved_warning(blender):
    build_test_scene()
    configure(blender)
    op = _modal_operator()
    assert op._start(blender) is None
    assert _drive(op, blender) == {"FINISHED"}
    assert not any("moved while solving" in text for _, text in op.reports)


# ---------------------------------------------------------------------------------------------
# Statistics of long runs, and nothing after the results are written may lose the undo step
# ---------------------------------------------------------------------------------------------

def _with_huge_counts(monkeypatch, paths=3_000_000_017, rays=9_876_543_210_123):
    """Make the worker report path and ray counts beyond 2^31 (a long run, without running it)."""
    import dataclasses

    real = pipeline.run_solve

    def run_solve(*args, **kwargs):
        out = real(*args, **kwargs)
        out.result = dataclasses.replace(out.result, paths=paths, rays=rays)
        return out

    monkeypatch.setattr(worker, "run_solve", run_solve)
    return paths, rays


def test_path_and_ray_counts_beyond_32_bits_are_stored_exactly(blender, monkeypatch):
    from ..test_extension import draw_panel

    build_test_scene()
    configure(blender)
    paths, rays = _with_huge_counts(monkeypatch)
    bpy.ops.ed.undo_push(message="scene built")
    assert bpy.ops.radiosity.solve("EXEC_DEFAULT", True) == {"FINISHED"}
    s = blender.scene.radiosity
    assert s.last_paths == paths and s.last_rays == rays  # exact, as Python ints
    assert len(result_objects()) == 3
    labels = " ".join(t for k, t in draw_panel(blender) if k == "label")
    assert "Paths: 3.00 G" in labels and "Rays: 9876.54 G" in labels
    # the solve kept its undo step: Ctrl+Z removes results and statistics
    assert bpy.ops.ed.undo() == {"FINISHED"}
    assert not result_objects() and bpy.context.scene.radiosity.last_paths == 0


def test_a_failure_after_writing_keeps_the_results_and_finishes(blender, monkeypatch):
    """Whatever goes wrong once the results are written (statistics, reports), the operator
    finishes -- with its undo step -- and says so, instead of raising over a changed scene."""
    from addon.blender_write import solve_job

    build_test_scene()
    configure(blender)

    def broken(_placements):
        raise RuntimeError("broken on purpose")

    monkeypatch.setattr(solve_job, "_moved_sources", broken)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}
    assert len(result_objects()) == 3 and blender.scene.radiosity.last_paths > 0
    assert any(kind == "WARNING" and "broken on purpose" in text for kind, text in reports)


# ---------------------------------------------------------------------------------------------
# Patch count limit
# ---------------------------------------------------------------------------------------------

def _mixed_objects(context):
    """Quads, triangles and n-gons (a cylinder's caps, concave too), scaled unevenly."""
    build_test_scene()
    bpy.ops.mesh.primitive_cylinder_add(vertices=7, radius=0.4, depth=0.7, location=(2, 0, 0))
    bpy.context.active_object.scale = (1.0, 2.5, 1.0)
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=2, radius=0.3, location=(0, 2, 0))
    concave = make_object("Concave", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0.5, 0.3, 0), (0, 1, 0), (0.2, 0.5, 0)],
                          [(0, 1, 2, 3, 4, 5)], location=(-2, 0, 0))
    for o in bpy.data.objects:
        o.select_set(True)
    assert concave.select_get()
    objects, _ = read_selection(context)
    assert {len(o.face_sizes) for o in objects} >= {1, 9}
    return objects


def test_patch_count_is_the_meshings_count_without_meshing(blender):
    from addon.core.mesh import meshing

    objects = _mixed_objects(blender)
    for size in (10.0, 1.0, 0.5, 0.31, 0.25, 0.1, 0.037):
        meshed = sum(
            meshing.mesh_patches(o.vertices, o.face_sizes, o.corner_verts, size, face_triangles=o.triangles,
                                 triangle_face=o.triangle_face).patch_count
            for o in objects
        )
        assert patches.patch_count(objects, size) == meshed, size


def test_a_patch_size_that_makes_too_many_patches_is_refused_before_meshing(blender, monkeypatch):
    objects = _mixed_objects(blender)
    assert patches.MAX_PATCHES == 2_000_000
    # the smallest patch size the setting allows: ~10^9 patches; refused at once, never meshed
    blender.scene.radiosity.patch_size = 1e-4
    meshed = []
    real_mesh = patches.meshing.mesh_patches
    monkeypatch.setattr(patches.meshing, "mesh_patches", lambda *a, **k: meshed.append(1) or real_mesh(*a, **k))
    t0 = time.perf_counter()
    value = estimate.compute(blender)  # what the panel's estimate shows
    assert time.perf_counter() - t0 < 5
    assert not meshed
    message = value["error"]
    assert "more than the limit of 2,000,000" in message and "Use a larger patch size" in message
    count = patches.patch_count(objects, blender.scene.radiosity.patch_size)  # 1e-4 as a float32
    assert f"{count:,.0f} patches" in message
    # the size suggested fits under the limit
    suggested = float(message.rsplit("(", 1)[1].split()[0])
    assert patches.patch_count(objects, suggested) <= patches.MAX_PATCHES < count
    # a lower limit, to check the boundary exactly (and that a solve refuses the same way)
    blender.scene.radiosity.patch_size = 0.1
    at = patches.patch_count(objects, blender.scene.radiosity.patch_size)
    monkeypatch.setattr(patches, "MAX_PATCHES", int(at))
    assert estimate.compute(blender)["patches"] == at
    monkeypatch.setattr(patches, "MAX_PATCHES", int(at) - 1)
    assert "more than the limit" in estimate.compute(blender)["error"]
    before = _snapshot()
    with pytest.raises(RuntimeError, match="Use a larger patch size"):
        bpy.ops.radiosity.solve()
    assert _snapshot() == before and not result_objects()


def test_a_nan_vertex_is_named_with_its_object(blender):
    """One vertex set to NaN (by a script or a driver) made the scene's extent NaN, so that
    every face of every object looked like it had no area: the error names the object and
    how many of its vertices are not numbers. The scene is unchanged."""
    build_test_scene()
    configure(blender)
    block = bpy.data.objects["Block"]
    block.data.vertices[3].co = (float("nan"), 0.2, 0.0)
    _unchanged_after_error(blender, r"Radiosity failed: 'Block': 1 of the 8 vertices its faces use is not a finite "
                                    r"number \(NaN or infinite\)\n")
    block.data.vertices[3].co = (0.2, 0.5, 0.0)
    block.location = (float("nan"), 0.0, 0.0)
    before = sorted(o.name for o in bpy.data.objects), sorted(m.name for m in bpy.data.meshes)
    with pytest.raises(RuntimeError, match=r"'Block': 8 of the 8 vertices its faces use are not a finite number "
                                           r"\(NaN or infinite\) \(its location, rotation or scale\?\)"):
        bpy.ops.radiosity.solve()
    assert (sorted(o.name for o in bpy.data.objects), sorted(m.name for m in bpy.data.meshes)) == before
    assert not result_objects()


def test_an_object_ten_thousand_km_away_is_named_as_the_cause_of_faces_too_small(blender):
    """A 1 m cube 10,000 km from a 1 m room: the room's faces are below what the scene's extent
    lets the ray tracer resolve. The message says so, with the extent and the objects at both
    of its ends, instead of saying the selection has no faces of non-zero area."""
    build_test_scene()
    configure(blender)
    v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=False)
    make_object("Far", v, f, location=(1e7, 0, 0))  # not selected: the rest of the scene
    blender.scene.radiosity.use_scene_objects = True
    blender.view_layer.update()  # (its matrix_world, for the snapshot of the unchanged scene)
    _unchanged_after_error(
        blender, r"'Block', 'Lamp', 'Room': every face is too small to trace beside the scene's extent \(a diagonal "
                 r"of 1e\+07, from 'Room' to 'Far'; a face needs an area above 1e-14 of its square, 1\); move far "
                 r"objects nearer, or hide them from render")
    # Nearer (10 km), it solves, the far cube taking part as the rest of the scene.
    bpy.data.objects["Far"].location = (1e4, 0, 0)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports


def _sky_room(blender, flipped_floor=False):
    """A 4 x 4 m room 0.5 m high, open at the top under a grey sky (world colour 0.05), its floor
    an object of its own ('Floor'), built facing down with ``flipped_floor``."""
    room_v, room_f = box_arrays((0, 0, 0), (4, 4, 0.5), inward=True)
    walls = [f for k, f in enumerate(room_f) if k >= 2]  # no ceiling (the sky comes in), no floor
    make_object("Room", room_v, walls, [principled("White", (0.6, 0.6, 0.6))]).select_set(True)
    floor = [tuple(reversed(room_f[0]))] if flipped_floor else [room_f[0]]
    make_object("Floor", room_v, floor, [principled("Boards", (0.5, 0.4, 0.3))]).select_set(True)
    world = bpy.data.worlds.new("Sky")
    blender.scene.world = world
    background = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    background.inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    background.inputs["Strength"].default_value = 1.0
    configure(blender)
    blender.scene.radiosity.patch_size = 1.0


def test_sky_on_the_outside_of_a_room_gives_no_back_face_warning(blender):
    """The sky lights the walls and the floor of an open room from outside, on their back sides
    (most of the light that meets the room): that light met them from outside every receiver,
    as in any render of the room, and the run says nothing about thin walls."""
    _sky_room(blender)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports
    assert not any(kind == "WARNING" and "back of faces" in text for kind, text in reports), reports


def test_back_face_warnings_name_the_faces_and_the_sources(blender):
    """A floor built facing down in the open room: the sky that comes in meets its back side,
    which the walls see. The warning names the floor and the sky (and not the walls, lit from
    behind only from outside). The test room built inside out around its lamps: the lamp quad's
    and a bulb's light meet the room's back sides, which the block sees; both are named."""
    _sky_room(blender, flipped_floor=True)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports
    warning = [text for kind, text in reports if kind == "WARNING" and "back of faces" in text]
    assert len(warning) == 1, reports
    assert "of the light reached the back of faces in view of the selection" in warning[0]
    assert "faces of 'Floor' lit by world 'Sky'" in warning[0] and "'Room'" not in warning[0], warning

    addon.unregister()  # (as the blender fixture starts a test)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    build_test_scene()
    bpy.data.objects["Room"].data.flip_normals()
    bulb = bpy.data.objects.new("Bulb", bpy.data.lights.new("Bulb", "POINT"))
    bulb.data.energy, bulb.location = 2.0, (0.7, 0.7, 0.5)
    blender.scene.collection.objects.link(bulb)
    configure(blender)
    state, reports = _run_sync(blender)
    assert state == {"FINISHED"}, reports
    warning = [text for kind, text in reports if kind == "WARNING" and "back of faces" in text]
    assert len(warning) == 1, reports
    assert "faces of 'Room' lit by emissive faces of 'Lamp'" in warning[0], warning
    assert "faces of 'Room' lit by point light 'Bulb'" in warning[0], warning
