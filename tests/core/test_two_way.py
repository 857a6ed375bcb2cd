"""Two-way stochastic Jacobi iteration (method="two_way"): unbiased against the exact references,
its accounts balanced in expectation, bitwise reproducible, and less noisy than the paper's walk
for the rays it traces."""
import math

import numpy as np
import pytest
from boxes import CEILING, box_rectangles, box_scene, rectangles_to_mesh, small_source_box
from test_first_shot import R_FACES, _box_with_one_emitter, floor_lit_unevenly_and_a_wall

from addon.core.settings import Settings
from addon.core import PatchScene, predict, relative_rms_to_mse, solve
from addon.core.estimate import plan
from addon.core.methods import two_way
from addon.core.methods.first_shot import Gathering
from addon.core.methods.two_way import pilot_irradiance
from addon.core.methods import automatic
from addon.core.methods import two_way as tw
from addon.core.methods import two_way_sizes
from addon.core.lights.lights import AreaLight, PointLight, SunLight, WorldLight
from addon.core.estimate.reference import form_factors_raycast, rectangle_form_factors, solve_radiosity_system
from addon.core.methods.tables import WalkTables
from addon.core.methods.two_way import direct_samples

Z = 5.0


def _z(result, exact):
    return ((result.radiosity - exact) / np.sqrt(result.reflected_variance)).ravel()


def _t_beyond(dof, share):
    """The x that |t| of ``dof`` degrees of freedom passes with chance ``share`` (its density integrated)."""
    x = np.linspace(0.0, 80.0, 800_001)
    density = (1 + x * x / dof) ** (-(dof + 1) / 2) * math.exp(math.lgamma((dof + 1) / 2) - math.lgamma(dof / 2)) \
        / math.sqrt(dof * math.pi)
    # (summed from the far end, trapezoids: the tail itself, not one minus a sum whose rounding is larger)
    tail = 2.0 * np.concatenate([np.cumsum(((density[1:] + density[:-1]) / 2 * (x[1] - x[0]))[::-1])[::-1], [0.0]])
    return float(x[np.searchsorted(-tail, -share)])


def _z_ok(z, chunks=32):
    """No |z| above 5, or above what the largest of z.size draws of a t-distribution with K-1
    degrees of freedom passes once in a thousand where that is more (12 chunks, 1,152 values:
    9.8; a t of 11 degrees passes 5 once in 2,500 draws); and the mean square near (K-1)/(K-3),
    its variance (bound: 5 standard errors of a chi-square mean, widened by 1.2 for the t's
    heavier tail)."""
    k = chunks - 1
    bound = max(Z, _t_beyond(k, 1e-3 / z.size))
    return np.abs(z).max() < bound and abs(np.mean(z**2) - k / (k - 2)) < 5 * math.sqrt(2 / z.size) * 1.2


def _open_box(n=3):
    """A colour box without its ceiling, lit by one floor patch: every pair of patches sees the
    other whole (exact form factors), and what leaves through the top escapes."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=n)
    keep = face != CEILING
    origin, u, v, face = origin[keep], u[keep], v[keep], face[keep]
    R = np.asarray(R_FACES)[face]
    E = np.zeros_like(R)
    E[n + 1] = (10.0, 9.0, 8.0)
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), R, E)
    return scene, solve_radiosity_system(rectangle_form_factors(origin, u, v), R, E)


@pytest.mark.parametrize("box", ["closed", "open"])
def test_two_way_is_the_direct_solve(box):
    """Per patch and channel against the discrete exact solution (exit point random), in
    batch-means standard errors: a closed colour box lit by one ceiling patch, and an open one
    (rays that escape see 0 about the control variate, from their own patch only)."""
    scene, exact = _box_with_one_emitter() if box == "closed" else _open_box()
    r = solve(scene, paths=200_000, seed=1, method="two_way")
    assert r.chunks == tw.TWO_WAY_MIN_CHUNKS and r.method == "two_way" and r.direct_light == "gathered"
    assert r.path_ends["generations"] > r.chunks * 5
    assert _z_ok(_z(r, exact), r.chunks)


def test_samples_go_where_the_light_lands_and_every_patch_keeps_its_floor():
    """With a source in a corner of the ceiling, the pilot's allotment gives the two wall patches
    beside it many times their area's samples, takes from no patch more than RECEIVED_SHARE of
    its area share (none starved: each keeps an unbiased estimate of its own), and keeps the
    chunk's total."""
    scene, _ = small_source_box(corner=True)
    tables = WalkTables(scene, "finite", 1e-3, "random")
    with tables.numpy_turn:
        pilot = pilot_irradiance(tables, Gathering(scene, direct_samples(768, scene)), 0)
    area, allotted = direct_samples(768, scene), direct_samples(768, scene, pilot)
    assert (allotted >= (1 - two_way.RECEIVED_SHARE) * area * (1 - 1e-12)).all()
    assert math.isclose(allotted.sum(), area.sum())
    assert np.sort(allotted / area)[-2] > 10  # (the two wall patches: about 40% of the light)


def test_a_large_chunk_gives_the_patches_beside_a_small_source_all_their_samples():
    """In a large chunk the pilot's allotment gives the two wall patches beside the corner source
    thousands of samples, and the chunk keeps DIRECT_SAMPLES a path in all: no patch's share is
    clipped (at 256 a patch, the patches beside a small source had fewer than their share, and a
    two-way run's error was heavy-tailed: benchmarks/results/stop_rule.md)."""
    scene, _ = small_source_box(corner=True)
    tables = WalkTables(scene, "finite", 1e-3, "random")
    with tables.numpy_turn:
        pilot = pilot_irradiance(tables, Gathering(scene, direct_samples(768, scene)), 0)
    allotted = direct_samples(20_000, scene, pilot)
    assert np.sort(allotted)[-2] > 1_000
    assert math.isclose(allotted.sum(), two_way.DIRECT_SAMPLES * 20_000)


def test_a_patchs_samples_longer_than_a_block_are_a_block_of_their_own():
    """The gathering's blocks (``first_shot._blocks``) are whole runs of a patch's samples, about a
    block's size, a run longer than a block a block alone: every sample in one block, in order."""
    from addon.core.methods.first_shot import _blocks

    patch = np.repeat(np.arange(6), [3, 800, 2, 900, 4, 1])
    blocks = _blocks(patch, 500)
    assert [(b.start, b.stop) for b in blocks] == [(0, 3), (3, 803), (803, 805), (805, 1705), (1705, 1710)]
    patch = np.repeat(np.arange(50), 30)
    blocks = _blocks(patch, 500)
    assert blocks[0] == slice(0, 480) and blocks[-1].stop == patch.size
    assert all(patch[b.start - 1] != patch[b.start] for b in blocks[1:])


def test_allotted_by_the_light_the_corner_source_box_is_still_the_direct_solve():
    """Where the allotment is most uneven (a source in a corner of the ceiling: a few patches
    take most of the samples), each patch's direct light keeps its own unbiased estimate: per
    patch against the exact discrete solution, in batch-means standard errors, no |z| above Z.
    (Not their mean square: here the error is mostly one pattern, the whole room a little too
    bright or too dark, so the patches' z are far from independent.)"""
    scene, F = small_source_box(corner=True)
    exact = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    r = solve(scene, paths=400_000, seed=2, method="two_way")
    assert np.abs(_z(r, exact)).max() < Z


def test_leaving_from_hit_points_the_first_reflection_leaves_from_where_the_light_landed():
    """A one-patch floor (R 0.5) lit unevenly by a point light low beside it, and a one-patch
    wall (R 0.01) the light does not reach (test_first_shot). With exit_point="hit" the wall's
    first irradiance is the floor's uneven reflection (a Gauss-Legendre quadrature); the light
    then goes back and forth between the two patches uniformly from each (the two-way
    generations), a geometric series of ratio q = R_w F_wf R_f F_fw with the exact rectangle
    form factors. With exit_point="random" the first reflection is uniform too (15% less).
    Each within 5 batch-means standard errors of its own truth and beyond 5 of the other's."""
    R_floor, R_wall = 0.5, 0.01
    scene, exact, uniform, rectangles = floor_lit_unevenly_and_a_wall(R_floor, R_wall)
    F = rectangle_form_factors(*rectangles)
    series = 1.0 / (1.0 - R_wall * F[1, 0] * R_floor * F[0, 1])
    for exit_point, truth, other in (("hit", exact, uniform), ("random", uniform, exact)):
        result = solve(scene, paths=200_000, seed=1, method="two_way", exit_point=exit_point)
        H_wall, sd = result.irradiance[1, 0], np.sqrt(result.reflected_variance[1, 0]) / R_wall
        assert abs(H_wall - truth * series) < 5 * sd < abs(H_wall - other * series), exit_point



def _cove(n=3):
    """A closed unit box of n x n patches a face (R 0.6) with a cove light: a small emitting box
    (R 0.8, 3 x 60 x 2 cm) 4 cm from a wall and from the ceiling, a tenth of a
    patch wide (the lamp room's strip is a fifth of its 0.32 m patches). The strip hides parts of the box from
    one another, so the form factors are cast: A_i F_ij from the hits both ways, each pair's
    counts pooled (G_ij = (c_ij + c_ji) / (n (1/A_i + 1/A_j)), reciprocal by construction).
    (PatchScene, exact discrete solution, index of the strip's patches, of the cove's)."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n)
    strip, su, sv, _ = box_rectangles((0.03, 0.6, 0.02), 1, offset=(0.93, 0.2, 0.94))
    origin, u, v = np.vstack([origin, strip]), np.vstack([u, sv]), np.vstack([v, su])  # (its faces outwards)
    P = origin.shape[0]
    R, E = np.full((P, 3), 0.6), np.zeros((P, 3))
    R[-6:], E[-6:] = 0.8, (12.0, 9.6, 7.2)
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), R, E)
    rays = 300_000
    counts = form_factors_raycast(scene, rays, seed=0) * rays
    A = scene.patch_area
    F = (counts + counts.T) / (rays * (1 / A[:, None] + 1 / A[None, :])) / A[:, None]
    centre = (origin + 0.5 * (u + v))[:-6]
    cove = np.flatnonzero((centre[:, 0] > 0.6) & (centre[:, 2] > 0.6) & (np.abs(centre[:, 1] - 0.5) < 0.34))
    return scene, solve_radiosity_system(F, R, E), np.arange(P - 6, P), cove


def test_about_a_cove_light_the_two_way_iteration_is_the_direct_solve():
    """Where a small emitter sits close to two surfaces, the two-way iteration (random exit)
    loses no light: over 12 seeds, the reflected power on the strip, in the cove and in the whole
    box each averages to the exact discrete solution's within 4 standard errors of that mean
    (a t of 11 degrees of freedom passes 4 once in 500). What the walk with the hit exit finds
    there is not that answer: it carries the light on from where it landed, which in the cove
    is beside the strip, so the strip gets far more back than the patches' uniform reflection
    gives (the discretization, the same for every method on these patches)."""
    scene, exact, strip, cove = _cove()
    A = scene.patch_area
    b = (exact - scene.emission)[:, 0]
    power = lambda reflected, rows: float((reflected[rows, 0] * A[rows]).sum())  # noqa: E731
    parts = (strip, cove, slice(None))
    ratios = np.array([[power(r.reflected, rows) / power(b[:, None], rows) - 1 for rows in parts]
                       for r in (solve(scene, paths=100_000, seed=seed, method="two_way") for seed in range(12))])
    t = ratios.mean(axis=0) / (ratios.std(axis=0, ddof=1) / math.sqrt(len(ratios)))
    assert (np.abs(t) < 4).all(), t
    walk = solve(scene, paths=200_000, seed=1, method="walk", exit_point="hit")
    on_strip = walk.reflected[strip, 0] - b[strip]
    assert on_strip.sum() > 10 * math.sqrt(walk.reflected_variance[strip, 0].sum()) > 0

def _scene_with_every_light():
    from boxes import open_box_with_card

    base = open_box_with_card()
    lights = [
        PointLight(np.array([0.5, 0.5, 0.3]), np.array([1.0, 0.8, 0.6]), radius=0.05),
        AreaLight(np.array([0.7, 0.3, 0.9]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), np.array([0, 0, -1.0]), np.full(3, 2.0)),
        SunLight(np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]), np.full(3, 1.5), angle=0.1),
        WorldLight(irradiance=np.array([0.2, 0.3, 0.4])),
    ]
    return base.with_materials(base.reflectivity, base.emission, lights=lights)


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_two_way_is_bitwise_reproducible_across_threads(exit_point):
    """An open box with a card, an emissive patch and a light of every kind: one thread and
    two give the same bits; what the run emits is the scene's Phi_T."""
    scene = _scene_with_every_light()
    a = solve(scene, paths=50_000, seed=11, method="two_way", threads=1, exit_point=exit_point)
    b = solve(scene, paths=50_000, seed=11, method="two_way", threads=2, exit_point=exit_point)
    assert np.array_equal(a.radiosity, b.radiosity) and np.array_equal(a.reflected_variance, b.reflected_variance)
    assert a.rays == b.rays
    np.testing.assert_allclose(a.energy["emitted"].mean(), scene.total_power, rtol=1e-9)
    assert np.isnan(a.predicted_mse)  # the paper's formulas do not predict it


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_the_accounts_balance_in_expectation(exit_point):
    """Each chunk's accounts: what is emitted is absorbed, escapes or is blocked in expectation
    (the generations' escapes and back-side hits are estimated from their rays, the absorption
    from the irradiance): the mean imbalance of 64 chunks within 5 standard errors of 0, per
    channel, while the escaped and blocked power are far from 0."""
    scene = _scene_with_every_light()
    tables = WalkTables(scene, "finite", 1e-3, exit_point)
    chunks = tw.TwoWayChunks(tables, Gathering(scene, direct_samples(3000, scene)))
    tallies = chunks.run([3000] * 64, np.random.default_rng(5))
    emitted = np.array([t.emitted for t in tallies])
    imbalance = np.array([t.emitted - t.absorbed - t.escaped - t.blocked - t.undistributed for t in tallies])
    z = imbalance.mean(axis=0) / (imbalance.std(axis=0, ddof=1) / math.sqrt(len(tallies)))
    assert np.abs(z).max() < Z
    escaped = np.array([t.escaped for t in tallies]).mean(axis=0)
    blocked = np.array([t.blocked for t in tallies]).mean(axis=0)
    assert (escaped > 0.05 * emitted[0]).all() and (blocked > 0).all()


def test_less_noise_than_the_paper_walk_for_the_rays_it_traces():
    """In the closed colour box lit by one ceiling patch the measured MSE times the rays traced
    (the inverse of the efficiency per ray) is at least 2 times lower than the paper's walk's
    (measured 2.45 +- 0.07 over six seeds: small patches near one small emitter, where the
    direct light is most of the error)."""
    scene, _ = _box_with_one_emitter()
    walk = solve(scene, paths=400_000, seed=7)
    two_way = solve(scene, paths=100_000, seed=7, method="two_way")
    assert two_way.measured_mse * two_way.rays * 2 < walk.measured_mse * walk.rays


def test_two_way_gathers_its_direct_light_and_stops_on_the_measured_error():
    scene, _ = _box_with_one_emitter()
    with pytest.raises(ValueError, match="gathers its direct light"):
        solve(scene, paths=1000, method="two_way", direct_light="shot")
    target = 4e-6
    r = solve(scene, target_mse=target, seed=4, method="two_way")
    assert r.stopped == "target" and r.measured_mse <= target and r.direct_light == "gathered"


@pytest.mark.parametrize("kind", [{"method": "two_way"}, {"direct_light": "gathered"}])
def test_direct_light_landing_on_back_sides_is_reported_as_blocked(kind):
    """A closed box turned inside out (every normal out) with a point light inside: the gathering
    finds no light on any front side, and the rays from the light all meet back sides: what it
    found on no front is reported blocked (the panel's flipped-normals warning), not escaped."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, v, u)  # (winding reversed: normals out)
    scene = PatchScene(vertices, triangles, triangle_patch, np.full(len(origin), 0.5), np.zeros(len(origin)),
                       lights=[PointLight(np.array([0.4, 0.5, 0.6]), np.ones(3))])
    r = solve(scene, paths=20_000, seed=1, **kind)
    e = r.energy
    np.testing.assert_allclose(e["blocked"], e["emitted"], rtol=1e-9)
    assert (e["escaped"] == 0).all() and np.allclose(r.radiosity, 0)


def test_automatic_method_takes_the_two_way_iteration_only_where_each_patch_gets_enough_rays():
    """method="auto": the two-way iteration where a chunk's first generation can give every patch
    TWO_WAY_RAYS_PER_PATCH rays within the plan, else the walk; the result is bitwise the chosen
    method's own and names it."""
    scene, _ = _box_with_one_emitter()
    P = scene.patch_count
    few = 8 * plan.MIN_CHUNK_PATHS  # a plan of 8 minimal chunks: far under 4 rays a patch
    assert tw.first_generation_rays(P, tw.TwoWay().chunk_paths(P, 2.0, few)) < tw.TWO_WAY_RAYS_PER_PATCH
    assert automatic.choose(scene, Settings(paths=few)) == "walk"
    assert automatic.choose(scene, Settings(paths=200_000)) == "two_way"
    for paths, method in ((few, "walk"), (20_000, "two_way")):
        auto = solve(scene, paths=paths, seed=2, method="auto", threads=2)
        own = solve(scene, paths=paths, seed=2, method=method, threads=2)
        assert auto.method == method and np.array_equal(auto.radiosity, own.radiosity) and auto.rays == own.rays


def test_two_way_chunks_grow_to_enough_rays_a_patch_within_the_plan():
    """A big scene's two-way chunks give each patch TWO_WAY_CHUNK_RAYS_PER_PATCH (32)
    first-generation rays when the plan has room for TWO_WAY_MIN_CHUNKS of them, and at least
    TWO_WAY_RAYS_PER_PATCH (4) when it has room for MIN_MEASURED_CHUNKS of those, never more
    than the cap; a scene too big for that (or a plan too small) gets fewer, and "auto" takes
    the walk there."""
    rays = lambda P, planned: tw.first_generation_rays(P, tw.TwoWay().chunk_paths(P, 2.5, planned))  # noqa: E731
    assert rays(50_000, 10**9) >= tw.TWO_WAY_CHUNK_RAYS_PER_PATCH > tw.TWO_WAY_RAYS_PER_PATCH
    assert rays(50_000, 10**9) < tw.TWO_WAY_CHUNK_RAYS_PER_PATCH + 0.01  # (no bigger than it needs)
    enough = 50_000 * tw.TWO_WAY_RAYS_PER_PATCH // 2  # paths of a chunk of that many rays a patch
    assert tw.TwoWay().chunk_paths(50_000, 2.5, 8 * enough) == enough  # (8 chunks of them)
    assert rays(50_000, 8 * enough) >= tw.TWO_WAY_RAYS_PER_PATCH
    assert tw.TwoWay().chunk_paths(1_000_000, 2.5, 10**9) == tw.TWO_WAY_MAX_CHUNK_PATHS
    assert rays(1_000_000, 10**9) < tw.TWO_WAY_RAYS_PER_PATCH
    assert math.ceil(10**6 / tw.TwoWay().chunk_paths(50_000, 2.5, 10**6)) >= plan.MIN_MEASURED_CHUNKS


def test_a_guessed_plan_grows_the_two_way_chunks_to_the_balance_of_the_stop_rule():
    """A run that stops on its measured error plans on a guess (the walk's prediction); where
    the guess is small, chunks sized from it are small, and their variance per path
    (1 + G P / n, TWO_WAY_GROWTH) costs more paths than the fewest chunks the stop rule reads.
    A guessed plan's chunks grow to ``balanced_chunk`` (K n = N (1 + G P / n)), up to
    TWO_WAY_CHUNK_RAYS_PER_PATCH; a plan of given paths keeps its chunks (its batch estimate
    needs them), and so does a plan already at that size."""
    P, planned = 4_000, 64_000
    n = two_way_sizes.balanced_chunk(P, planned)
    K, G = plan.MEASURED_STOP_CHUNKS, two_way_sizes.TWO_WAY_GROWTH
    assert K * n == pytest.approx(planned * (1 + G * P / n), rel=1e-3)
    given, guessed = (tw.TwoWay().chunk_paths(P, 2.5, planned, guessed=g) for g in (False, True))
    assert given < n == guessed  # (given: 4 rays a patch, 2P paths)
    assert tw.first_generation_rays(P, given) == tw.TWO_WAY_RAYS_PER_PATCH
    big = 10**9
    assert tw.TwoWay().chunk_paths(P, 2.5, big, guessed=True) == tw.TwoWay().chunk_paths(P, 2.5, big)
    # a solve at a loose target runs such chunks, and the automatic choice reads them
    scene, _ = _box_with_one_emitter()
    target = 1e-4
    chosen = plan.chunk_plan(scene, tw.TwoWay(), Settings.for_mse(scene, target))
    assert chosen.chunk >= two_way_sizes.balanced_chunk(scene.patch_count, tw.TwoWay().planned_paths(chosen.prediction.paths_for(target)))
    r = solve(scene, target_mse=target, seed=1, method="auto")
    assert r.method == "two_way" and r.stopped == "target"
    sizes = r.chunk_sizes  # (the first chunks of the plan's size, the rest smaller: later_chunk, again_chunk)
    assert set(sizes[:plan.RESIZE_AFTER]) == {chosen.chunk} and max(sizes) == chosen.chunk and sum(sizes) == r.paths


def test_a_small_plan_runs_in_fewer_larger_chunks_than_the_walk_s():
    """A small plan's two-way chunks are TWO_WAY_MIN_CHUNKS (16), twice the walk's size: a
    chunk's variance per path falls as it grows. A solve of a million paths in the 600-patch
    box runs 16 of them, and its batch estimate is there."""
    assert tw.TWO_WAY_MIN_CHUNKS == 16 < plan.MIN_CHUNKS
    assert tw.TwoWay().chunk_paths(600, 2.0, 1_000_000) == 1_000_000 // 16
    assert plan.chunk_paths_for(2.0, 1_000_000) == 1_000_000 // 32
    scene = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], n=10)[0]
    r = solve(scene, paths=1_000_000, seed=1, method="two_way", threads=2)
    assert r.chunks == 16 and np.isfinite(r.reflected_variance).all()


def test_chunks_traced_in_blocks_are_still_exact(monkeypatch):
    """A large chunk gathers and casts a block at a time (first_shot.SAMPLE_BLOCK,
    generations.RAY_BLOCK: its memory is a block's). With blocks of a few hundred samples and rays
    every chunk here is tens of blocks, and the results still hold: the closed colour box is its
    discrete exact solution (z-scores as above), and with exit_point="hit" the unevenly lit
    floor's first reflection still leaves from where the light landed (the first reflection's
    rays in blocks too)."""
    from addon.core.methods import first_shot, generations

    monkeypatch.setattr(first_shot, "SAMPLE_BLOCK", 500)
    monkeypatch.setattr(generations, "RAY_BLOCK", 700)
    scene, exact = _box_with_one_emitter()
    r = solve(scene, paths=200_000, seed=1, method="two_way")
    assert _z_ok(_z(r, exact), r.chunks)
    R_floor, R_wall = 0.5, 0.01
    scene, lit, uniform, rectangles = floor_lit_unevenly_and_a_wall(R_floor, R_wall)
    F = rectangle_form_factors(*rectangles)
    series = 1.0 / (1.0 - R_wall * F[1, 0] * R_floor * F[0, 1])
    result = solve(scene, paths=200_000, seed=1, method="two_way", exit_point="hit")
    H_wall, sd = result.irradiance[1, 0], np.sqrt(result.reflected_variance[1, 0]) / R_wall
    assert abs(H_wall - lit * series) < 5 * sd < abs(H_wall - uniform * series)


def test_automatic_method_takes_the_walk_past_its_measured_scene_size(monkeypatch):
    """Past AUTO_MAX_PATCHES (the largest scene the rule was measured on, and memory: a million
    patches stay under 1 GiB with the walk) "auto" takes the walk, whatever the rays a patch."""
    scene, _ = _box_with_one_emitter()
    assert automatic.choose(scene, Settings(paths=200_000)) == "two_way"
    monkeypatch.setattr(automatic, "AUTO_MAX_PATCHES", scene.patch_count - 1)
    assert automatic.choose(scene, Settings(paths=200_000)) == "walk"


def test_under_a_time_limit_two_way_chunks_stay_the_usual_size(monkeypatch):
    """A chunk of a million paths can outlast a time limit, and a run stopped before its first
    chunk has nothing to give: under a time limit two-way chunks keep the usual size (about
    RAYS_PER_CHUNK rays), and "auto" decides on those chunks."""
    usual = plan.chunk_paths_for(two_way.rays_per_path(2.5), 10**9, tw.TWO_WAY_MIN_CHUNKS)
    assert tw.TwoWay().chunk_paths(50_000, 2.5, 10**9, time_limited=True) == usual
    assert usual < tw.TwoWay().chunk_paths(50_000, 2.5, 10**9)
    scene, _ = _box_with_one_emitter()
    monkeypatch.setattr(plan, "RAYS_PER_CHUNK", 1_000)  # usual chunks of under 4 rays a patch here
    assert automatic.choose(scene, Settings(paths=200_000)) == "two_way"
    assert automatic.choose(scene, Settings(paths=200_000, max_seconds=60)) == "walk"
    r = solve(scene, paths=200_000, seed=1, method="auto", max_seconds=60, threads=2)
    assert r.method == "walk"
    limited = solve(scene, paths=20_000, seed=1, method="two_way", max_seconds=60, threads=2)
    free = solve(scene, paths=20_000, seed=1, method="two_way", threads=2)
    assert limited.paths == free.paths == 20_000 and free.chunks == tw.TWO_WAY_MIN_CHUNKS and limited.chunks > 8 * free.chunks


def test_paired_ranks_count_each_patch_and_sign_in_order():
    """A correction ray's rank is the number of rays before it with its patch and its sign (the
    rays come in patch order): ray r of a patch's positive shares and ray r of its negative ones
    take one Sobol' point. Checked against that count written as a loop."""
    from addon.core.methods.generations import _paired_ranks

    rng = np.random.default_rng(3)
    for P, n in ((1, 0), (4, 1), (6, 200), (50, 5000)):
        ray_patch = np.sort(rng.integers(0, P, n)).astype(np.int32)
        negative = rng.random(n) < 0.3
        rank, shift = _paired_ranks(ray_patch, negative, P, np.random.default_rng(0))
        seen, expected = {}, []
        for key in zip(ray_patch.tolist(), negative.tolist()):
            expected.append(seen.get(key, 0))
            seen[key] = expected[-1] + 1
        assert rank.tolist() == expected
        assert shift.shape == (2, P) and shift.dtype == np.uint32


def test_the_roulette_that_ends_the_light_moves_every_patch_together_only_by_a_small_share():
    """The closed Cornell box (2,940 patches), eight seeds: the area-weighted total of the light
    after a bounce varies between runs by less than a tenth of one patch's error. Independent
    patch errors would give about 1/sqrt(P) of it (0.02); the roulette, all or nothing for every
    patch of a chunk at once, played where the light left would pay for LEAST_RAYS a patch moved
    the total by 0.2 of it. Bound: 0.1, twice what the sample deviation of eight runs (chi-square
    with 7 degrees of freedom, 99%: 1.56 sigma) leaves of the expected 0.04."""
    import sample_scenes

    scene = sample_scenes.build("cornell_box", divisions=20, closed=True).scene
    runs = []
    for seed in range(8):
        r = solve(scene, paths=300_000, seed=seed, method="two_way", exit_point="hit", direct_apart=True)
        runs.append((r.irradiance - r.direct_irradiance).mean(axis=1))
    runs, area = np.array(runs), scene.patch_area
    mean = runs.mean(axis=0) @ area / area.sum()
    per_patch = math.sqrt(runs.var(axis=0, ddof=1) @ area / area.sum()) / mean
    total = runs @ area
    assert total.std(ddof=1) / total.mean() < 0.1 * per_patch, (total.std(ddof=1) / total.mean(), per_patch)


@pytest.mark.parametrize("degrees", [10, 1])
def test_automatic_runs_the_walk_where_a_narrow_spot_lights_few_patches(degrees):
    """A room lit by one spot lamp of 10 (or 1) degrees: Automatic took the two-way iteration,
    whose rays go by area and whose gathered direct light finds a narrow cone's light rarely: at
    5% it ended at its path cap at 6.3% (10 degrees) or far off. The light lands on a few of the
    1,536 patches (concentration about 280 and 350, against 1.4-4 in ordinary rooms): the walk
    runs and meets the target in under a second; a 75-degree spot keeps the two-way iteration."""
    from boxes import spot_box

    scene = spot_box(degrees)
    assert automatic.concentration(scene) > 20 * automatic.MAX_CONCENTRATION
    r = solve(scene, target_mse=relative_rms_to_mse(predict(scene), 0.05), seed=0, stop_rule="measured", method="auto",
              exit_point="hit", error_scale="measured", threads=2)
    assert r.method == "walk" and r.stopped == "target" and r.relative_error <= 0.05
    wide = spot_box(75)
    assert 2 < automatic.concentration(wide) < automatic.MAX_CONCENTRATION
    assert automatic.choose(wide, Settings(target_error=0.05)) == "two_way"


def test_concentration_is_the_patch_count_over_the_patches_lit_and_near_one_where_light_is_even():
    """sum_j q_j^2 / w_j: about 1.4 in a box lit by its whole ceiling (rays allotted by sqrt(A) R
    on equal patches: the ceiling gets none of the first light); a quarter over a floor patch's
    share of the rays for a point spot whose cone lands evenly on the four floor patches around the
    point below it; a lamp whose light must be gathered (soft falloff), or a walk asked to gather,
    leaves the choice to the rays a patch (the walk would gather it too)."""
    from boxes import grey_room, spot_box

    assert 1.2 < automatic.concentration(grey_room()[0]) < 1.6
    pin = spot_box(0.5, radius=0.0)
    weight = two_way.allotment_weight(pin.patch_area, pin.reflectivity.max(axis=1))
    even = 0.25 / (weight[0] / weight.sum())  # (patch 0: a floor patch)
    assert 0.9 * even < automatic.concentration(pin) < 1.1 * even
    soft = spot_box(10, soft_falloff=True)
    assert automatic.choose(soft, Settings(target_error=0.05)) == "two_way"
    assert automatic.choose(pin, Settings(target_error=0.05, direct_light="gathered")) == "two_way"


def test_a_run_that_found_no_light_does_not_stop_on_its_target():
    """The two-way iteration in a room under a 1-degree spot: its gathering samples rarely land in
    the cone, and a run whose 12 chunks all found none (seed 0) measured no error about no light
    and stopped "on its target" with a black room. It goes on until it finds light (here to its
    path count, far from the target, which the run's error says)."""
    from boxes import spot_box

    scene = spot_box(1)
    r = solve(scene, target_mse=relative_rms_to_mse(predict(scene), 0.05), paths=200_000, seed=0, stop_rule="measured",
              method="two_way", exit_point="hit", error_scale="measured", threads=2)
    assert r.stopped == "paths" and r.mean_reflected > 0 and r.relative_error > 0.05


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_an_abandoned_chunk_stops_between_its_stages(exit_point):
    """A chunk asked to stop (a run that met its target abandons the chunks still running, and
    waits for them) stops at the next stage: the shadow rays, the cosine rays, the first
    reflection's rays and each generation ask, not only the generations."""
    from addon.core.methods.base import Aborted
    from addon.core.distributed.runners import chunk_generator

    scene = _scene_with_every_light()
    tables = WalkTables(scene, "finite", 1e-3, exit_point)
    state = two_way.TwoWay().create(scene, tables, 20_000, 0, None)
    calls = []

    def check():
        calls.append(len(calls))
        raise Aborted

    def must_not_run(*args, **kwargs):
        raise AssertionError("the chunk went on past a check")

    from addon.core.methods import first_shot

    original = (tw.reflect_first, tw.generation, first_shot._cosine_rays)
    tw.reflect_first = tw.generation = first_shot._cosine_rays = must_not_run
    try:
        with pytest.raises(Aborted), tables.numpy_turn:
            two_way.two_way_chunk(tables, state.gathering, 20_000, chunk_generator(0, 0), check)
    finally:
        tw.reflect_first, tw.generation, first_shot._cosine_rays = original
    assert calls == [0]


def test_a_panels_back_lighting_the_ceiling_over_it_leaves_the_two_way_iteration_to_automatic():
    """The sample Cornell box's panel hangs 1 cm under the ceiling, and its back emits: half its
    light lands on the few ceiling patches over it (counted by where it lands: concentration
    about 18 and 23 at 10 and 5 cm patches, and Automatic ran the walk, 2.3x the two-way
    iteration's time in the main job). That light goes back to the panel's back, where it is
    absorbed and adds no patch's noise: counted by the light that goes on from where it lands,
    the concentration is an ordinary room's, and Automatic runs the two-way iteration."""
    import sample_scenes

    for divisions in (10, 20):
        scene = sample_scenes.build("cornell_box", divisions=divisions).scene
        assert scene.back_emits.any()
        assert automatic.concentration(scene) < automatic.MAX_CONCENTRATION / 1.5
        assert automatic.choose(scene, Settings(target_error=0.02)) == "two_way"


def test_later_chunk_is_the_smallest_that_meets_the_target_on_the_fewest_chunks():
    """The later chunks' size: the smallest n from ``least`` to ``most`` whose expected batch
    estimate on MEASURED_STOP_CHUNKS chunks (``later_estimate``) meets the target; ``most`` where
    none does; ``least`` where it already does. (A run's ``most`` is its first chunks' size: the
    plan's.)"""
    P, first, m, least, most = 4_000, 30_000, plan.RESIZE_AFTER, 2_000, 60_000
    variance = 1.0
    at_first = two_way_sizes.later_estimate(P, first, m, variance, first)
    assert at_first == pytest.approx(variance / (plan.MEASURED_STOP_CHUNKS * first))  # (equal chunks: v / N)
    assert two_way_sizes.later_chunk(P, first, m, variance, 0.1 * at_first, least, most) == most
    for target in (0.8 * at_first, 2.0 * at_first):  # (larger chunks than the first, or smaller)
        n = two_way_sizes.later_chunk(P, first, m, variance, target, least, most)
        assert least < n < most and (n > first) == (target < at_first)
        assert two_way_sizes.later_estimate(P, first, m, variance, n) <= target < two_way_sizes.later_estimate(P, first, m, variance, n - 1)
    assert two_way_sizes.later_chunk(P, first, m, variance, 100 * at_first, least, most) == least


def test_later_chunks_may_grow_past_the_plans_up_to_their_rays_a_patch():
    """The two-way iteration sizes its later chunks past the plan's (``most``) where the plan's
    are too small for the fewest chunks the stop rule reads: up to TWO_WAY_LATER_RAYS_PER_PATCH
    first-generation rays a patch (at most TWO_WAY_MAX_CHUNK_PATHS), the largest where none
    meets the target; with nothing measured, the first chunks' size."""
    P, m, variance = 4_000, plan.RESIZE_AFTER, 1.0
    first = most = 30_000
    largest = math.ceil(tw.TWO_WAY_LATER_RAYS_PER_PATCH * P / tw.GENERATION_RAYS)
    at_first = two_way_sizes.later_estimate(P, first, m, variance, first)
    method = tw.TwoWay()
    n = method.later_chunk(P, first, m, variance, 0.7 * at_first, most)
    assert most < n < largest
    assert two_way_sizes.later_estimate(P, first, m, variance, n) <= 0.7 * at_first
    assert method.later_chunk(P, first, m, variance, 0.01 * at_first, most) == largest
    assert method.later_chunk(P, first, m, 0.0, 0.7 * at_first, most) == first
    assert method.later_chunk(10**6, first, m, variance, 1e-30, most) == tw.TWO_WAY_MAX_CHUNK_PATHS


def test_a_run_whose_plan_overshoots_goes_on_with_smaller_chunks_and_still_meets_its_target():
    """A grey room at a 2% target: the walk's guess plans chunks twelve of which reach about
    1%; after RESIZE_AFTER of them the run goes on with the smaller chunks its target needs
    (their gathering sized alike), stopping on its measured error at the target, on well under
    the plan's paths. Against the direct solve, each
    patch's error is within its batch standard error (z-scores, as above; chunks of two sizes
    in the estimate), and the run's true error meets the target."""
    from boxes import grey_room

    scene, F = grey_room()
    exact = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    settings = Settings.for_mse(scene, relative_rms_to_mse(predict(scene), 0.02), method="two_way")
    planned = plan.chunk_plan(scene, tw.TwoWay(), settings).chunk
    first = planned
    w = scene.patch_area / scene.total_area
    for seed in range(3):
        r = solve(scene, target_error=0.02, method="two_way", seed=seed, threads=2)
        sizes = r.chunk_sizes
        assert set(sizes[:plan.RESIZE_AFTER]) == {first} and max(sizes[plan.RESIZE_AFTER:]) < first, (sizes, first)
        assert r.stopped == "target" and r.paths < plan.MEASURED_STOP_CHUNKS * planned / 1.5, (r.paths, r.chunks, planned)
        z = _z(r, exact)
        assert _z_ok(z, r.chunks), (np.abs(z).max(), np.mean(z**2))
        true = float((w[:, None] * (r.radiosity - exact) ** 2).mean(axis=1).sum())
        assert math.sqrt(true) / float((w[:, None] * (exact - scene.emission)).mean(axis=1).sum()) <= 0.02


def test_the_growth_of_the_variance_a_path_is_read_from_two_chunk_sizes():
    """``measured_growth`` gives back the G of v (1 + G P / n) that made two sizes' variances; 0
    where the smaller chunks measured less (noise about no growth); TWO_WAY_MOST_GROWTH where they
    measured more than any G makes (the ratio of the sizes); None where the sizes are too near."""
    P, first, later = 4_000, 30_000, 10_000
    for G in (0.0, 0.8, 3.0, 12.0, 40.0):
        v = (1 + G * P / later) / (1 + G * P / first)
        assert two_way_sizes.measured_growth(P, first, later, 2.0, 2.0 * v) == pytest.approx(G, abs=1e-9)
        # (the chunks may have grown as well: the same G from the other side)
        assert two_way_sizes.measured_growth(P, later, first, 2.0 * v, 2.0) == pytest.approx(G, abs=1e-9)
    assert two_way_sizes.measured_growth(P, first, later, 1.0, 0.9) == 0.0
    assert two_way_sizes.measured_growth(P, first, later, 1.0, 1.01 * first / later) == two_way_sizes.TWO_WAY_MOST_GROWTH
    assert two_way_sizes.measured_growth(P, first, 29_500, 1.0, 1.5) is None
    assert two_way_sizes.measured_growth(P, first, later, 0.0, 1.0) is None


def _again_bound(P, sizes, increments, terms, running, n):
    """The stop rule's bound ``again_chunk`` expects at chunks of n after ``sizes`` and ``running``."""
    return two_way_sizes.again_bound(P, sizes, increments, terms, running)(n)


def test_chunks_sized_again_are_the_smallest_whose_expected_bound_meets_the_target(monkeypatch):
    """``again_chunk``: with the variances of a growth G = 2 measured (no noise in the increments,
    ``plan.expected_increments``), the smallest n whose expected bound meets the target; ``least``
    where that does, ``most`` where none does; where they shrink, smaller than a growth of 12
    would make them (a scene whose variance grows less than the suite's middle runs smaller chunks)."""
    P, n1, n2, least, most, terms = 4_000, 30_000, 10_000, 2_000, 60_000, 5_000.0
    model = lambda G, n: (1 + G * P / n) / (1 + G * P / n1)  # noqa: E731
    sizes, running = [n1, n1, n2], [n2, n2]
    increments = list(plan.expected_increments(sizes, [model(2.0, n) for n in sizes]))
    target = 0.6 * _again_bound(P, sizes, increments, terms, running, n2)
    n = two_way_sizes.again_chunk(P, sizes, increments, terms, target, running, least, most)
    assert least < n < most
    assert _again_bound(P, sizes, increments, terms, running, n) <= target < _again_bound(P, sizes, increments, terms, running, n - 1)
    assert two_way_sizes.again_chunk(P, sizes, increments, terms, 100 * target, running, least, most) == least
    assert two_way_sizes.again_chunk(P, sizes, increments, terms, 1e-3 * target, running, least, most) == most
    # where the chunks shrink, a growth of 12 read into the same variances keeps them larger
    loose = 1.3 * _again_bound(P, sizes, increments, terms, running, n2)
    small = two_way_sizes.again_chunk(P, sizes, increments, terms, loose, running, least, most)
    monkeypatch.setattr(two_way_sizes, "measured_growth", lambda *a: two_way_sizes.TWO_WAY_GROWTH)
    assert least < small < two_way_sizes.again_chunk(P, sizes, increments, terms, loose, running, least, most) < n2
    monkeypatch.undo()
    # nothing left to size, or an error held by too few terms to read a growth from: the last size
    assert two_way_sizes.again_chunk(P, sizes, increments, 0.9 * two_way_sizes.AGAIN_TERMS, target, running, least, most) == n2
    assert two_way_sizes.again_chunk(P, [n1] * 2 + [n2] * 8, increments + [increments[-1]] * 7, terms, target, [n2] * 2, least, most) == n2


def test_a_run_sized_twice_has_the_same_chunks_on_one_thread_and_on_two():
    """A run to a target whose plan overshoots sizes its chunks after RESIZE_AFTER and again from
    RESIZE_AGAIN_FROM on (three sizes); the chunks between run meanwhile, so that on one thread and
    on two every chunk's size, and the result, are the same, bit for bit."""
    R, E = np.full((6, 3), 0.5), np.zeros((6, 3))
    E[CEILING] = 1.0
    scene, _, _ = box_scene(R, E, n=24)  # (3,456 patches: an error held by more than AGAIN_TERMS terms)
    a = solve(scene, target_error=0.05, method="two_way", seed=1, threads=1)
    b = solve(scene, target_error=0.05, method="two_way", seed=1, threads=2)
    assert a.chunk_sizes == b.chunk_sizes and np.array_equal(a.radiosity, b.radiosity)
    sizes = a.chunk_sizes
    assert len(set(sizes[:plan.RESIZE_AFTER])) == len(set(sizes[plan.RESIZE_AFTER:plan.RESIZE_AGAIN_FROM])) == 1
    assert len(set(sizes)) == 3 and len(set(sizes[plan.RESIZE_AGAIN_FROM:])) == 1, sizes
