"""Every run says where its light went, and whether it kept its error target: the shares of the emitted power absorbed by surfaces
(on the back of faces among them), left the scene and left undistributed, from the run's own
power accounts (pipeline.light_account_text, shown after a run by the panel and the command line)."""
import re
from types import SimpleNamespace

import numpy as np
from boxes import box_scene, open_box_with_card

from addon.core import PatchScene, solve
from addon.core.lights.lights import WorldLight
from addon.bpy_free.pipeline import light_account_text
from addon.bpy_free.smooth_colours import smooth_light
from addon.core.display import smoothing
from addon.core.display.slack import SLACK_ERRORS
from addon.core.mesh.meshing import mesh_patches
from addon.core.materials.textures import patch_texture_average, sample_bilinear


def _shares(text):
    return {name: float(value) / 100 for value, name in re.findall(r"([\d.]+)% (absorbed|on the back|left the scene)", text)}


def test_an_open_box_says_how_much_light_left_it_and_met_back_faces():
    result = solve(open_box_with_card(), method="walk", paths=20_000, seed=0)
    energy = result.energy
    emitted = float(np.sum(energy["emitted"]))
    shares = _shares(light_account_text(energy))
    # the text rounds to 0.1%: each share within half of that of the accounts
    assert abs(shares["left the scene"] - float(np.sum(energy["escaped"])) / emitted) <= 5e-4
    assert abs(shares["on the back"] - float(np.sum(energy["blocked"])) / emitted) <= 5e-4
    assert abs(shares["absorbed"] - float(np.sum(energy["absorbed"])) / emitted) <= 5e-4
    assert shares["left the scene"] > 0.1  # an open box: a good part of its light leaves it


def test_a_closed_box_loses_nothing_and_says_so():
    scene, _, _ = box_scene([0.5] * 6, [1.0, 0, 0, 0, 0, 0], n=2)
    text = light_account_text(solve(scene, method="walk", paths=8_000, seed=1).energy)
    assert text == "light: 100.0% absorbed by surfaces, 0.0% left the scene", text
    # the two-way iteration's accounts are estimates: its escaped share is 0 within its seeds' spread
    escaped = []
    for seed in range(8):
        energy = solve(scene, method="two_way", paths=8_000, seed=seed).energy
        escaped.append(float(np.sum(energy["escaped"]) / np.sum(energy["emitted"])))
    mean, error = np.mean(escaped), np.std(escaped, ddof=1) / np.sqrt(len(escaped))
    assert abs(mean) <= 4.0 * error, (mean, error)
    text = light_account_text(energy)
    assert re.fullmatch(r"light: \d+\.\d% absorbed by surfaces, \d+\.\d% left the scene", text), text


def test_no_account_without_light():
    assert light_account_text({}) == ""
    assert light_account_text({"emitted": np.zeros(3)}) == ""


def test_a_target_missed_at_the_path_cap_is_said():
    from addon.bpy_free.pipeline import target_missed_text

    text = target_missed_text("paths", 9.5, 5.0)
    assert "5% error target was not reached" in text and "9.50%" in text and "1.9x" in text, text
    # kept, or ended for another reason, or no target (a path count), or no measured error: quiet
    assert target_missed_text("paths", 4.9, 5.0) == ""
    assert target_missed_text("target", 9.5, 5.0) == ""
    assert target_missed_text("time_limit", 9.5, 5.0) == ""  # (the time limit has its own warning)
    assert target_missed_text("paths", 9.5, 0.0) == ""
    assert target_missed_text("paths", -1.0, 5.0) == ""


# The textured output's light: what the result materials multiply the surface's own colour by
# (smooth_light(..., light=True), arriving_light), fed known arrays (no Monte Carlo).

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
SQUARE_TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])


def _plane(patch_size=0.25):
    """A 1 x 1 m quad meshed into patches, as the pipeline's scene and the patch mesh."""
    mesh = mesh_patches(SQUARE, np.array([4]), np.array([0, 1, 2, 3]), patch_size,
                        face_triangles=SQUARE_TRIANGLES, triangle_face=np.zeros(2, int))
    lit = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(mesh.patch_count, 0.5),
                     np.zeros(mesh.patch_count), lights=[WorldLight(np.ones(3))])  # (the sky alone: no point_direct)
    scene = SimpleNamespace(vertices=mesh.points, triangles=mesh.triangles, triangle_patch=mesh.triangle_patch,
                            patch_count=mesh.patch_count, emission=np.zeros((mesh.patch_count, 3)),
                            geometry=lit.geometry, lights=lit.lights)
    return mesh, scene


def _centres(mesh):
    corners = mesh.points[mesh.triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    centre = np.stack([np.bincount(mesh.triangle_patch, weights=corners[:, :, k].mean(axis=1) * area)
                       for k in range(3)], axis=1)
    return centre / np.bincount(mesh.triangle_patch, weights=area)[:, None]


def _result(H, variance, reflectivity):
    return SimpleNamespace(reflected=reflectivity * H, reflected_variance=reflectivity ** 2 * variance,
                           irradiance=H, irradiance_variance=variance, seed=0, direct_irradiance=None)


def _fine_samples(n=32):
    """Barycentric centres of the n x n sub-triangles of a triangle (equal areas)."""
    points = []
    for i in range(n):
        for j in range(n - i):
            points.append(((i + 1 / 3) / n, (j + 1 / 3) / n))
            if i + j < n - 1:
                points.append(((i + 2 / 3) / n, (j + 2 / 3) / n))
    b = np.array(points)
    return np.column_stack([1 - b.sum(axis=1), b])


def test_texture_times_light_averages_to_each_patch_s_reflected_radiosity():
    """A checker image (8 squares a metre, two a patch's side) on a floor of 0.25 m patches, the
    light arriving a gradient with a bump: each patch's reflectivity is the texture's mean over
    it (core.textures), its reflected radiosity b = rho H. The picture shows texture(x) x
    light(x); over each patch its area mean is b within the texture-averaging error: the light's
    mean over the patch is H within its slack (the smoothing moves no light beyond the solve's
    noise, here a few 1e-6), so what is left is
    the covariance of texture and light inside the patch, at most std(texture) x std(light)
    (Cauchy-Schwarz), plus the 16-sample texture average's own error."""
    mesh, scene = _plane()
    c = _centres(mesh)
    H = (1.0 + c[:, 0] + 0.5 * c[:, 1] + 2.0 * np.exp(-((c[:, 0] - 0.6) ** 2 + (c[:, 1] - 0.4) ** 2) / 0.05))[:, None]
    H = H * np.array([1.0, 0.9, 0.8])
    squares = (np.arange(64)[:, None] // 8 + np.arange(64)[None, :] // 8) % 2
    image = np.where(squares[..., None] == 1, [0.8, 0.7, 0.6], [0.1, 0.1, 0.2])
    corners = SQUARE[SQUARE_TRIANGLES]
    uv = corners[:, :, :2]
    identity = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    rho = patch_texture_average(mesh, np.arange(mesh.patch_count), corners, uv, np.zeros(2, int), image, identity)
    variance = np.full_like(H, 1e-12)  # (known exactly: the noise filter keeps every patch's value)
    scene.reflectivity = rho
    _, light = smooth_light(scene, _result(H, variance, rho), light=True)
    w = _fine_samples()
    points = np.einsum("si,tij->tsj", w, mesh.points[mesh.triangles])  # (T,S,3)
    light_at = np.einsum("si,tic->tsc", w, light)
    texture_at = sample_bilinear(image, points[..., :2].reshape(-1, 2)).reshape(light_at.shape)
    area = 0.5 * np.linalg.norm(np.cross(*(mesh.points[mesh.triangles][:, k] - mesh.points[mesh.triangles][:, 0]
                                           for k in (1, 2))), axis=1)
    P = mesh.patch_count

    def patch_mean(values):  # (T,S,3) -> (P,3), area-weighted
        per_triangle = values.mean(axis=1) * area[:, None]
        return np.stack([np.bincount(mesh.triangle_patch, weights=per_triangle[:, k], minlength=P)
                         for k in range(3)], axis=1) / np.bincount(mesh.triangle_patch, weights=area)[:, None]

    mean_light, mean_texture = patch_mean(light_at), patch_mean(texture_at)
    shown = patch_mean(texture_at * light_at)
    # the smoothing moves no light beyond each patch's slack (SLACK_ERRORS standard errors of 1e-6)
    np.testing.assert_allclose(mean_light, H * np.ones(3), rtol=1e-9, atol=1.001e-6 * SLACK_ERRORS)
    spread = np.sqrt(patch_mean(texture_at ** 2) - mean_texture ** 2) * np.sqrt(
        np.maximum(patch_mean(light_at ** 2) - mean_light ** 2, 0))
    b = rho * H
    error = np.abs(shown - b)
    assert (error <= spread + np.abs(mean_texture - rho) * H + 1e-12).all()
    # the light is not flat: the smooth light carries the gradient inside the patches
    assert (np.ptp(light.reshape(-1, 3), axis=0) > 0.5).all()


def test_black_patches_take_their_neighbours_light_and_leave_no_dark_rim():
    """A white floor with a black stripe (rho = 0) across it, lit evenly (H = 1): the stripe's own
    light estimate is 0 with a small variance (as where the two-way iteration's gathering gave a
    black patch no sample of its direct light). The light shows nowhere on black, but its
    corners are shared with the white patches beside it: it takes the neighbours' light, so the
    white patches keep their even light up to the stripe (taken as it came, their corners there
    fell to half the light)."""
    mesh, scene = _plane()
    c = _centres(mesh)
    black = (c[:, 0] > 0.5) & (c[:, 0] < 0.75)
    rho = np.where(black[:, None], 0.0, 0.7) * np.ones(3)
    H = np.where(black[:, None], 0.0, 1.0) * np.ones(3)
    variance = np.where(black[:, None], 1e-8, 1e-6) * np.ones(3)
    scene.reflectivity = rho
    _, light = smooth_light(scene, _result(H, variance, rho), light=True)
    white_triangles = ~black[mesh.triangle_patch]
    np.testing.assert_allclose(light[white_triangles], 1.0, rtol=1e-6)
    np.testing.assert_allclose(light[~white_triangles], 1.0, rtol=1e-6)


def test_the_noise_filter_leaves_the_direct_light_the_solve_kept_apart_alone():
    """A floor whose light is all direct (a bump: H = D, the solve's direct part kept apart), with
    the large measured variances of a heavy-tailed gathering (a weak lamp's few shadow rays): the
    noise filter works on the indirect part alone (0 here), so every patch's shown light keeps
    its mean H and its reflected light rho H to float error. (Filtered whole, each patch moved by
    up to 3 of those standard errors towards its neighbours: the hall's painting under its spot,
    0.51 of Cycles.)"""
    mesh, scene = _plane()
    c = _centres(mesh)
    H = (0.05 + np.exp(-((c[:, 0] - 0.5) ** 2 + (c[:, 1] - 0.5) ** 2) / 0.02))[:, None] * np.array([1.0, 0.9, 0.8])
    rho = np.full_like(H, 0.6)
    scene.reflectivity = rho
    result = _result(H, (0.5 * H) ** 2, rho)
    result.direct_irradiance = H.copy()
    smooth, light = smooth_light(scene, result, light=True)
    surface = smoothing.Surface.of(mesh.points, mesh.triangles, mesh.triangle_patch, mesh.patch_count)

    def means(corners):
        return np.stack([surface.corner_means(np.ascontiguousarray(corners[:, :, k]).ravel()) for k in range(3)], axis=1)
    np.testing.assert_allclose(means(light), H, rtol=1e-9)
    np.testing.assert_allclose(means(smooth), rho * H, rtol=1e-9)


def test_a_target_out_of_reach_is_said_before_the_run():
    """A 2 m room lit by one 3-degree spot with soft falloff: every method gathers its direct light
    from each patch and rarely finds the cone, and the run ended at its path cap at 19% against
    5% (1 degree: 137%) with nothing said before it. The estimate (the panel's, and the command line's before a run) says
    the target is out of reach and names the lamp and what lets the walk shoot it; a wide spot,
    and the same narrow spot without soft falloff (Automatic runs the walk), say nothing."""
    from addon.blender_read.selection import Selection
    from addon.bpy_free import pipeline
    from addon.core.lights.lights import PointLight, Spot
    from test_patches import box_object

    def room(degrees, soft):
        box = box_object(size=2.0, reflectivity=0.6)
        box.face_emission = np.zeros_like(box.face_emission)
        cos_outer = np.cos(np.radians(degrees) / 2)
        spot = Spot(np.array([0.0, 0.0, -1.0]), cos_outer, cos_outer + 0.15 * (1 - cos_outer))
        return Selection([box], [PointLight(np.array([1.0, 1.0, 1.95]), np.full(3, 50.0), radius=0.1, spot=spot,
                                            name="Spot", soft_falloff=soft)])

    warning = pipeline.estimate(room(3, True), pipeline.SolveSettings(patch_size=0.1, seed=1))["warning"]
    assert warning.startswith("The 5% error target is out of reach: a pilot says the run ends at its path cap"), warning
    assert "'Spot' has soft falloff" in warning and "Soft Falloff off" in warning, warning
    for degrees, soft in ((75, True), (3, False)):
        assert pipeline.estimate(room(degrees, soft), pipeline.SolveSettings(patch_size=0.1, seed=1))["warning"] is None


def test_the_threads_setting_holds_for_the_displays_colours_too(monkeypatch):
    """The room with two lamps: the display's direct light at the corners runs on the threads the
    setting gives (``runners.local_threads``): at 1 on the caller's thread; at 2 on a thread of its
    own, beside the filters and the live parts made meanwhile on the caller's, one thread each
    (``threads.in_background``, ``threads.beside``: two numpy streams on two threads each waited on
    the GIL; one each, the 11k room's display and live parts 0.88 -> 0.73-0.78 s), and the same
    colours. (Before, the display took one thread whatever the setting: 1.6 of the 11k room's 4.3 s.)"""
    import threading

    from many_lamps import room_objects

    from addon.bpy_free import pipeline
    from addon.core.display import point_direct, smoothing
    from addon.core.distributed import runners

    seen, corner_direct, filter_light = [], point_direct.corner_direct, smoothing.Surface.filter_light
    monkeypatch.setattr(point_direct, "corner_direct", lambda *args, **kwargs: seen.append(
        ("corners", threading.get_ident(), runners.local_thread_count())) or corner_direct(*args, **kwargs))
    monkeypatch.setattr(smoothing.Surface, "filter_light", lambda *args, **kwargs: seen.append(
        ("filter", threading.get_ident(), runners.local_thread_count())) or filter_light(*args, **kwargs))
    colours = []
    for threads in (1, 2):
        out = pipeline.run_solve(room_objects(2), pipeline.SolveSettings(threads=threads, relative_rms=0.3, patch_size=0.5))
        assert out.light_colours and any(c is not None for c in out.light_colours)
        colours.append(out.smooth_colours)
    caller = threading.get_ident()
    runs = [sorted((kind, ident == caller, count) for kind, ident, count in run) for run in (seen[:2], seen[2:])]
    assert runs == [[("corners", True, 1), ("filter", True, 1)], [("corners", False, 1), ("filter", True, 1)]], seen
    for one, two in zip(*colours):
        assert (one is None) == (two is None) and (one is None or np.array_equal(one, two))


def test_the_lamps_first_means_are_made_beside_the_solve_with_the_same_numbers(monkeypatch):
    """The room with two lamps on two threads: the display's first lamp means (core
    direct_means.first_means) are made on a thread of their own while the solve runs, and the
    run writes the same colours, bit for bit, as one that makes them after the solve. On one
    thread they are made after it."""
    import threading

    from many_lamps import room_objects

    from addon.bpy_free import pipeline
    from addon.core.display import direct_means

    events, first_means, solve = [], direct_means.first_means, pipeline.solve
    begun, waits = threading.Event(), [True]

    def recorded_first(*args, **kwargs):
        events.append(("first", threading.current_thread().name))
        begun.set()
        return first_means(*args, **kwargs)

    def recorded_solve(*args, **kwargs):
        events.append(("solve starts", threading.current_thread().name))
        if waits[0]:  # (a solve as long as the means' start: they begin during it, or it times out)
            assert begun.wait(60)
        result = solve(*args, **kwargs)
        events.append(("solve ends", threading.current_thread().name))
        return result

    monkeypatch.setattr(direct_means, "first_means", recorded_first)
    monkeypatch.setattr(pipeline, "solve", recorded_solve)
    settings = lambda threads: pipeline.SolveSettings(threads=threads, relative_rms=0.3, patch_size=0.5, seed=3)  # noqa: E731
    beside = pipeline.run_solve(room_objects(2), settings(2))
    kinds = [kind for kind, _ in events]
    assert kinds.index("first") < kinds.index("solve ends"), events
    assert dict(events)["first"].startswith("radiosity-beside"), events
    events.clear()
    waits[0] = False
    monkeypatch.setattr(pipeline, "_lamp_means_beside", lambda *args: None)
    after = pipeline.run_solve(room_objects(2), settings(2))
    assert "first" not in [kind for kind, _ in events]
    np.testing.assert_array_equal(after.result.irradiance, beside.result.irradiance)
    assert after.result.measured_mse == beside.result.measured_mse
    for a, b in zip(after.light_colours + after.smooth_colours, beside.light_colours + beside.smooth_colours):
        np.testing.assert_array_equal(a, b)
    events.clear()
    monkeypatch.undo()
    monkeypatch.setattr(pipeline, "solve", recorded_solve)
    monkeypatch.setattr(direct_means, "first_means", recorded_first)
    pipeline.run_solve(room_objects(2), settings(1))
    assert [kind for kind, _ in events] == ["solve starts", "solve ends"]
