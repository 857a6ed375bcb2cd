"""Stress tests of the numerical core: extreme reflectivities and thresholds, scale and
position, long runs, awkward geometry, and the energy accounting of every run.

Every statistical band comes from a known variance:
- the area-weighted mean of the finite walk in a furnace (every patch emits E, reflects R): the
  number of hits of a path is geometric, mean 1/(1-R), variance R/(1-R)^2, whatever the geometry;
- per patch, table 1's exact variance (random exit point: a Markov chain on the patches, F exact
  for closed boxes of rectangles, ``reference.rectangle_form_factors``);
- binomial counts for the fraction of paths that end a given way;
- otherwise the run's own batch-means variance ``result.reflected_variance``.
Z = 4.5 over tens of patches keeps the chance of a false failure below about 1e-3 per test.
"""
import math
import threading
import time
import warnings

import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.estimate.reference import path_variances, rectangle_form_factors, solve_radiosity_system
from addon.core.estimate.plan import chunk_paths_for
from boxes import box_rectangles, box_scene, rectangles_to_mesh

Z = 4.5
SIZE = (1.0, 1.3, 0.7)
R_FACES, E_FACES = [0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0]


def _sane(result, scene):
    """Radiosity is finite, never negative, never below the emission."""
    assert np.isfinite(result.radiosity).all()
    assert (result.reflected >= 0).all()
    assert (result.radiosity >= scene.emission).all()


def _area_mean(scene, values):
    return float((scene.patch_area * values).sum() / scene.total_area)


# ---------------------------------------------------------------------------------------------
# Reflectivity near 1
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize(
    "R, N",
    [(0.99, 20_000), pytest.param(0.999, 2_000, marks=pytest.mark.slow)],
)
def test_finite_furnace_near_one(R, N):
    """B = E / (1 - R) everywhere; rays per path geometric with mean 1/(1-R)."""
    E = 1.0
    scene, F, _ = box_scene([R] * 6, [E] * 6, SIZE, n=2)
    fractions = []
    r = solve(scene, estimator="finite", paths=N, seed=61, threads=2, progress=lambda f, s: fractions.append(f))
    _sane(r, scene)
    assert r.stopped == "paths" and r.paths == N
    assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0 and r.path_ends["absorbed"] == N
    # Path length as predicted: rays per path ~ geometric(1 - R).
    length_sd = math.sqrt(R) / (1 - R) / math.sqrt(N)
    assert abs(r.mean_path_length - 1 / (1 - R)) < Z * length_sd
    assert r.prediction.expected_path_length == pytest.approx(1 / (1 - R))
    # Every ray hits a front face of the closed box and scores R Phi_T / A_T = R E on average.
    mean_b = _area_mean(scene, r.reflected[:, 0])
    assert mean_b == pytest.approx(R * E * r.mean_path_length, rel=1e-12)
    assert abs(mean_b - E * R / (1 - R)) < Z * R * E * length_sd
    # Per patch: table 1's variance.
    var, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    z = (r.radiosity[:, 0] - E / (1 - R)) / np.sqrt(var / N)
    assert np.abs(z).max() < Z, np.abs(z).max()
    # Progress kept moving: once per chunk, strictly increasing, ending at 1.
    assert len(fractions) == r.chunks >= 8
    assert all(b > a for a, b in zip(fractions, fractions[1:])) and fractions[-1] == 1.0


@pytest.mark.parametrize("how", ["cancel", "time_limit"])
def test_cancel_and_time_limit_interrupt_a_chunk_of_endless_paths(how):
    """R = 0.99999: a chunk of 128 paths is ~1.3e7 rays (tens of seconds); cancel and the time
    limit still return promptly, from inside the chunk, with nothing half-counted."""
    scene, _, _ = box_scene([0.99999] * 6, [1.0] * 6, SIZE, n=1)
    start = time.perf_counter()
    if how == "cancel":
        r = solve(scene, estimator="finite", paths=10_000, seed=1, threads=2,
                  should_stop=lambda: time.perf_counter() - start > 0.3)
        assert r.stopped == "cancelled"
    else:
        r = solve(scene, estimator="finite", paths=10_000, seed=1, threads=2, max_seconds=0.3)
        assert r.stopped == "time_limit"
    assert time.perf_counter() - start < 3.0
    # No chunk finished: the result says so (no paths) rather than inventing one.
    assert r.paths == 0 and r.rays == 0 and r.chunks == 0
    assert np.array_equal(r.radiosity, scene.emission) and r.energy == {}


@pytest.mark.parametrize("value", [1.0, 1.5, 1 + 1e-12])
def test_reflectivity_of_one_or_more_is_refused_with_the_reason(value):
    with pytest.raises(ValueError, match=r"must lie in \[0, 1\).*never lets a path end"):
        box_scene([0.5, 0.5, value, 0.5, 0.5, 0.5], [1.0] * 6, SIZE)


def test_reflectivity_closer_to_one_than_the_survival_test_resolves_is_refused():
    """A mean reflectivity above 1 - 2^-24 means more than 2^24 bounces per path: a run that
    never ends in practice. Refused; 1 - 2^-24 itself is the largest accepted."""
    with pytest.raises(ValueError, match=r"within 2\^-24 of 1 .* on patches 2: .*never end"):
        box_scene([0.5, 0.5, 1 - 2.0**-25, 0.5, 0.5, 0.5], [1.0] * 6, SIZE)
    scene, _, _ = box_scene([1 - 2.0**-24] * 6, [1.0] * 6, SIZE)
    assert scene.grey_reflectivity.max() == 1 - 2.0**-24


# ---------------------------------------------------------------------------------------------
# Biased infinite: tiny thresholds, thresholds close to 1
# ---------------------------------------------------------------------------------------------

def _cut_step(R, t):
    """The hit at which the product R^k (computed as the walk does) first falls below t."""
    k, product = 0, 1.0
    while True:
        k += 1
        product *= R
        if product < t:
            return k


@pytest.mark.parametrize(
    "R, t, N",
    [
        (0.5, 1e-9, 20_000),
        (0.5, 0.9, 20_000),
        (0.5, 1 - 1e-12, 20_000),
        (0.95, 0.9, 20_000),
        (0.9, 1e-9, 5_000),
        pytest.param(0.999, 1e-9, 256, marks=pytest.mark.slow),
    ],
)
def test_biased_furnace_extreme_thresholds(R, t, N):
    """In the furnace every biased path scores R + R^2 + ... + R^K and is cut at hit K: the
    area-weighted mean, the path length and the energy balance are exact."""
    E = 1.0
    scene, _, _ = box_scene([R] * 6, [E] * 6, SIZE, n=2)
    r = solve(scene, estimator="biased_infinite", paths=N, threshold=t, seed=62, threads=2)
    _sane(r, scene)
    K = _cut_step(R, t)
    assert r.mean_path_length == K and r.rays == K * N
    assert r.path_ends["threshold"] == N
    score = sum(R**k for k in range(1, K + 1))
    assert _area_mean(scene, r.reflected[:, 0]) == pytest.approx(E * score, rel=1e-9)
    e = r.energy
    np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)
    np.testing.assert_allclose(e["undistributed"], scene.total_power * R**K, rtol=1e-9)


def test_biased_tiny_threshold_matches_the_direct_solve():
    """t = 1e-9 leaves a bias of order R^K ~ 1e-9: the result is the exact solution within table
    1's infinite-estimator variance (with colour and unequal reflectivities)."""
    scene, F, _ = box_scene([0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0], SIZE, n=2)
    N = 100_000
    r = solve(scene, estimator="biased_infinite", paths=N, threshold=1e-9, seed=63, threads=2)
    _sane(r, scene)
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    _, var = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    z = (r.radiosity[:, 0] - B[:, 0]) / np.sqrt(var / N)
    assert np.abs(z).max() < Z, np.abs(z).max()


# ---------------------------------------------------------------------------------------------
# Scale and position
# ---------------------------------------------------------------------------------------------

def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))  # a proper rotation


@pytest.mark.parametrize("exit_point", ["random", "hit"])
@pytest.mark.parametrize(
    "scale, offset",
    [(1e-4, 0.0), (1e4, 0.0), (1.0, 1e5), (1e-4, 1e5), (1e4, -1e5), (1e-11, 0.0), (1e11, 0.0), (1e-7, 1e2)],
)
def test_scaled_rotated_and_moved_box_matches_the_exact_solution(scale, offset, exit_point):
    """A closed box, rotated off the axes (so float32 edges do not line up), scaled and moved far
    from the origin: no ray escapes through the seams, none is lost to self-intersection, and the
    result is the unscaled exact one within the noise."""
    R_faces, E_faces = [0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0]
    origin, u, v, face = box_rectangles(SIZE, n=2)
    F = rectangle_form_factors(origin, u, v)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    V = (V - 0.5) @ _rotation(5).T * scale + offset
    R, E = np.asarray(R_faces)[face], np.asarray(E_faces)[face]
    scene = PatchScene(V, T, TP, R, E)
    N = 100_000
    r = solve(scene, estimator="finite", paths=N, seed=64, threads=2, exit_point=exit_point)
    _sane(r, scene)
    assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0
    if exit_point == "random":
        b = solve_radiosity_system(F, R, E)[:, 0] - E
        var, _ = path_variances(F, R, E, scene.patch_area / scale**2)
        z = (r.reflected[:, 0] - b) / np.sqrt(var / N)
    else:
        # The same box at unit scale, with the same seed: compare within both runs' batch noise.
        unit = solve(PatchScene(*rectangles_to_mesh(origin, u, v), R, E), estimator="finite", paths=N, seed=65,
                     threads=2, exit_point="hit")
        z = (r.reflected[:, 0] - unit.reflected[:, 0]) / np.sqrt(
            r.reflected_variance[:, 0] + unit.reflected_variance[:, 0])
    assert np.abs(z).max() < Z, np.abs(z).max()


@pytest.mark.parametrize("scale", [1e-13, 1e13, 1e200])
def test_sizes_beyond_float32_tracing_are_refused_not_miscomputed(scale):
    """A diagonal of 1e13 or 1e-13 once made every ray escape (float32 tracing over/underflows):
    radiosity = emission, silently. Such scenes are refused with the reason and the remedy."""
    with pytest.raises(ValueError, match=r"the scene's size .* is outside .*rescale it"):
        box_scene(R_FACES, E_FACES, SIZE, n=1, scale=scale)


# ---------------------------------------------------------------------------------------------
# Long runs
# ---------------------------------------------------------------------------------------------

def _incident(result, scene):
    """Front-side hits per patch (exact integers in a grey finite run): b A N / (R Phi_T)."""
    return result.reflected[:, 0] * scene.patch_area * result.paths / (scene.grey_reflectivity * scene.total_power)


@pytest.mark.slow
def test_1e8_paths_equal_their_two_halves_and_the_exact_solution(monkeypatch):
    """1e8 paths: the run's float64 per-patch totals equal, to the last hit, the exact integer
    sums of its chunks' tallies taken in two halves (the first and second half of its chunks,
    recorded as the run makes them); the radiosity matches table 1 at a noise of ~1e-4, and the
    batch variance agrees with table 1's."""
    import addon.core.distributed.runners as runners

    R = 0.2
    scene, F, _ = box_scene([R] * 6, [0, 1.0, 0, 0, 0, 0], SIZE, n=1)
    N = 10**8
    chunk = chunk_paths_for(1 / (1 - R), N)
    chunk_count = math.ceil(N / chunk)
    assert chunk_count >= 100  # enough batches for the variance check below
    half_chunks = chunk_count // 2
    halves = np.zeros((2, scene.patch_count), dtype=np.int64)
    real_run = runners.run_chunks
    lock = threading.Lock()

    def locked_run(state, seed, first, sizes, abort=None):
        tallies = real_run(state, seed, first, sizes, abort)
        with lock:
            for k, tally in enumerate(tallies, start=first):
                halves[int(k >= half_chunks)] += tally.incident[0].astype(np.int64)
        return tallies

    monkeypatch.setattr(runners, "run_chunks", locked_run)
    full = solve(scene, estimator="finite", paths=N, seed=66, threads=2)
    assert full.paths == N and full.chunks == chunk_count
    hits = _incident(full, scene)
    np.testing.assert_allclose(hits, np.round(hits), rtol=0, atol=1e-3)  # no rounding crept in
    np.testing.assert_array_equal(np.round(hits).astype(np.int64), halves.sum(axis=0))
    assert halves.sum() == full.rays  # closed box: every ray hits a front face
    assert full.path_ends["escaped"] == 0 and full.path_ends["blocked"] == 0
    _sane(full, scene)
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)[:, 0]
    var, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    z = (full.radiosity[:, 0] - B) / np.sqrt(var / N)
    assert np.abs(z).max() < Z, np.abs(z).max()
    # The batch-means variance agrees with table 1's (K batches: ratio within 4 * sqrt(2/(K-1))).
    ratio = full.reflected_variance[:, 0] / (var / N)
    assert np.abs(ratio - 1).max() < 4 * math.sqrt(2 / (full.chunks - 1)), ratio


# ---------------------------------------------------------------------------------------------
# Geometry
# ---------------------------------------------------------------------------------------------

def _exact_box(n=2):
    origin, u, v, face = box_rectangles(SIZE, n=n)
    F = rectangle_form_factors(origin, u, v)
    R, E = np.asarray(R_FACES)[face], np.asarray(E_FACES)[face]
    A = np.linalg.norm(np.cross(u, v), axis=1)
    b = solve_radiosity_system(F, R, E)[:, 0] - E
    var, _ = path_variances(F, R, E, A)
    return origin, u, v, R, E, b, var


def _sliver_fan(origin, u, v, cuts):
    """Each rectangle as a fan from its first corner: slivers between the cut points of its far
    edges (o+u -> o+u+v, then o+u+v -> o+v)."""
    vertices, triangles, patch = [], [], []
    for p, (o, a, c) in enumerate(zip(origin, u, v)):
        far = [o + a + t * c for t in cuts] + [o + a + c - t * a for t in cuts[1:]]
        base = len(vertices)
        vertices += [o] + far
        for k in range(1, len(far)):
            triangles.append([base, base + k, base + k + 1])
            patch.append(p)
    return np.array(vertices), np.array(triangles), np.array(patch)


def test_sliver_triangles_sample_and_trace_correctly():
    """Every patch is a fan of triangles down to 1e-12 of the patch's area (needles with an
    altitude of 1e-12): the result is still the exact one, and no ray is lost."""
    origin, u, v, R, E, b, var = _exact_box()
    cuts = [0.0, 1e-12, 1e-6, 1e-3, 0.5, 1 - 1e-6, 1.0]
    V, T, TP = _sliver_fan(origin, u, v, cuts)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # none of them is degenerate: nothing is dropped
        scene = PatchScene(V, T, TP, R, E)
    np.testing.assert_allclose(scene.patch_area, np.linalg.norm(np.cross(u, v), axis=1), rtol=1e-12)
    assert scene.triangle_count == 12 * len(origin)
    N = 100_000
    r = solve(scene, estimator="finite", paths=N, seed=71, threads=2)
    _sane(r, scene)
    assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0
    z = (r.reflected[:, 0] - b) / np.sqrt(var / N)
    assert np.abs(z).max() < Z, np.abs(z).max()


def test_mirrored_box_with_reversed_winding_is_the_same_box():
    """A negative-scale (mirrored) object, with its winding reversed as the Blender layer does,
    gives the exact result of the original."""
    origin, u, v, R, E, b, var = _exact_box()
    V, T, TP = rectangles_to_mesh(origin, u, v)
    scene = PatchScene(V * [-1, 1, 1], T[:, ::-1], TP, R, E)
    N = 100_000
    r = solve(scene, estimator="finite", paths=N, seed=72, threads=2)
    assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0
    z = (r.reflected[:, 0] - b) / np.sqrt(var / N)
    assert np.abs(z).max() < Z, np.abs(z).max()


def test_duplicated_coincident_face_splits_its_light():
    """A face duplicated in place (same vertices, same winding) is two patches in one place: the
    ray tracer gives each hit to one of them, so together they receive exactly what the single
    face receives (the Markov chain is the same), but each alone shows part of it. PatchScene
    warns about it."""
    origin, u, v, R, E, b, var = _exact_box()
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = len(origin)
    floor = 0
    T2 = np.vstack([T, T[TP == floor]])
    TP2 = np.r_[TP, [P, P]]
    with pytest.warns(UserWarning, match=r"lie exactly on top of others \(duplicated faces\), on patches 0, 24"):
        scene = PatchScene(V, T2, TP2, np.r_[R, R[floor]], np.r_[E, E[floor]])
    N = 100_000
    r = solve(scene, estimator="finite", paths=N, seed=73, threads=2)
    _sane(r, scene)
    A = scene.patch_area
    pair = (A[floor] * r.reflected[floor, 0] + A[P] * r.reflected[P, 0]) / A[floor]
    z_pair = (pair - b[floor]) / np.sqrt(var[floor] / N)
    assert abs(z_pair) < Z, z_pair
    others = np.arange(P) != floor
    z = (r.reflected[:P][others, 0] - b[others]) / np.sqrt(var[others] / N)
    assert np.abs(z).max() < Z, np.abs(z).max()


def test_back_to_back_coincident_faces_are_reported_and_absorb():
    """A zero-thickness two-sided wall modelled as two coincident faces facing opposite ways:
    the tracer gives a ray one of the two (Embree, observed here: always the same one), so light
    arriving on the side that face turns away from lands on its back and is absorbed
    ("blocked"), and the other face stays dark. PatchScene says so; the blocked share is far
    above the Blender layer's 5 % warning."""
    origin, u, v, R, E, b, var = _exact_box()
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = len(origin)
    wall = np.array([[0.5, 0.0, 0.0], [0.5, 1.3, 0.0], [0.5, 1.3, 0.7], [0.5, 0.0, 0.7]])
    V2 = np.vstack([V, wall])
    k = len(V)
    T2 = np.vstack([T, [[k, k + 1, k + 2], [k, k + 2, k + 3]], [[k, k + 2, k + 1], [k, k + 3, k + 2]]])
    TP2 = np.r_[TP, P, P, P + 1, P + 1]
    with pytest.warns(UserWarning, match=r"duplicated faces.*on patches 24, 25.*seen from behind absorbs it"):
        scene = PatchScene(V2, T2, TP2, np.r_[R, 0.5, 0.5], np.r_[E, 0.0, 0.0])
    N = 50_000
    r = solve(scene, estimator="finite", paths=N, seed=79, threads=2)
    _sane(r, scene)
    assert r.path_ends["escaped"] == 0
    assert r.path_ends["blocked"] > 0.05 * N


def test_non_manifold_fin_inside_a_box():
    """A one-sided card standing on the floor along an interior edge of the floor's patches (three
    faces on one edge): nothing leaks under it, every path ends one way, and the finite and the
    biased infinite estimators (t = 1e-12, bias ~1e-12) agree within their batch noise."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    card = (np.array([[0.5, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 0.5]]))  # normal +x
    origin, u, v = (np.vstack([a, c]) for a, c in zip((origin, u, v), card))
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = len(origin)
    R = np.full(P, 0.6)
    E = np.where(np.r_[face, -1] == 1, 1.0, 0.0)
    scene = PatchScene(V, T, TP, R, E)
    N = 100_000
    a = solve(scene, estimator="finite", paths=N, seed=74, threads=2)
    c = solve(scene, estimator="biased_infinite", paths=N, threshold=1e-12, seed=75, threads=2)
    for r in (a, c):
        _sane(r, scene)
        assert r.path_ends["escaped"] == 0
    # Rays reach the card's back side from the -x half of the room: absorbed there.
    assert a.path_ends["blocked"] > 0 and a.path_ends["absorbed"] + a.path_ends["blocked"] == N
    z = (a.reflected[:, 0] - c.reflected[:, 0]) / np.sqrt(a.reflected_variance[:, 0] + c.reflected_variance[:, 0])
    assert np.abs(z).max() < Z, np.abs(z).max()


def test_open_scene_everything_escapes():
    """A single emitter facing the void: every path escapes on its first ray."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    scene = PatchScene(V, [[0, 1, 2], [0, 2, 3]], [0, 0], [0.5], [2.0])
    for estimator in ("finite", "biased_infinite"):
        r = solve(scene, estimator=estimator, paths=10_000, seed=76)
        assert r.path_ends["escaped"] == 10_000 and r.rays == 10_000
        assert np.array_equal(r.radiosity, scene.emission)
        np.testing.assert_allclose(r.energy["escaped"], r.energy["emitted"], rtol=1e-12)
        np.testing.assert_allclose(r.energy["emitted"], scene.total_power, rtol=1e-12)


def test_single_sided_plane_seen_from_behind_absorbs():
    """An emitting square under a parallel square card that faces away from it: the card's back
    takes the rays (absorbed, "blocked"), the card gets no light, and the blocked fraction is the
    exact form factor (binomial count)."""
    origin = np.array([[0.0, 0, 0], [0.0, 0, 0.5]])
    u = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    v = np.array([[0.0, 1, 0], [0.0, 1, 0]])  # both normals +z: the card's back faces the emitter
    V, T, TP = rectangles_to_mesh(origin, u, v)
    scene = PatchScene(V, T, TP, [0.5, 0.7], [1.0, 0.0])
    down = rectangle_form_factors(origin[[0, 1]], np.array([[1.0, 0, 0], [0.0, 1, 0]]),
                                  np.array([[0.0, 1, 0], [1.0, 0, 0]]))  # the card turned to face down
    F = down[0, 1]
    N = 100_000
    r = solve(scene, estimator="finite", paths=N, seed=77)
    assert np.array_equal(r.reflected, np.zeros((2, 3)))
    assert r.path_ends["blocked"] + r.path_ends["escaped"] == N
    assert abs(r.path_ends["blocked"] - N * F) < Z * math.sqrt(N * F * (1 - F))
    e = r.energy
    np.testing.assert_allclose(e["blocked"] + e["escaped"], e["emitted"], rtol=1e-12)
    np.testing.assert_allclose(e["absorbed"], e["blocked"], rtol=1e-12)


@pytest.mark.parametrize("emitter_inside", [False, True])
def test_flipped_normals_give_no_light_and_say_where_it_went(emitter_inside):
    """A closed box with every normal pointing out. Its own emitting ceiling then shines into the
    void (all escapes); an extra emitter inside, facing in, lights only back sides (all blocked).
    Either way nothing is reflected, and the accounting shows where the power went."""
    origin, u, v, face = box_rectangles(SIZE, n=1)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    T = T[:, ::-1]  # flipped: outward normals
    R = np.full(6, 0.5)
    E = np.where(face == 1, 1.0, 0.0)
    if emitter_inside:
        lamp = np.array([[0.4, 0.5, 0.3], [0.6, 0.5, 0.3], [0.6, 0.7, 0.3], [0.4, 0.7, 0.3]])
        T = np.vstack([T, len(V) + np.array([[0, 1, 2], [0, 2, 3]])])
        V = np.vstack([V, lamp])
        TP = np.r_[TP, 6, 6]
        R, E = np.r_[R, 0.0], np.r_[np.zeros(6), 1.0]
    scene = PatchScene(V, T, TP, R, E)
    r = solve(scene, estimator="finite", paths=20_000, seed=78)
    assert np.array_equal(r.reflected, np.zeros_like(r.reflected))
    where = "blocked" if emitter_inside else "escaped"
    assert r.path_ends[where] == 20_000
    np.testing.assert_allclose(r.energy[where], r.energy["emitted"], rtol=1e-12)


@pytest.mark.parametrize("exit_point", ["random", "hit"])
@pytest.mark.parametrize("sampling", ["independent", "stratified"])
def test_first_rays_leave_uniformly_from_sources_beside_triangle_patches(exit_point, sampling):
    """A 1 m square light under a 0.3 m square card near one of its corners, facing it, and a
    stray triangle patch far away (so the scene is not all parallelograms and new paths take
    the general exit, in a hit-point walk too). Nothing reflects but the card, which faces only
    the black light: the card is hit by first rays only, each with the exact form factor F,
    and a path's first point must be uniform on the light for that (a fixed point would give
    another F). The light's back emits too (the stray triangle lies behind it): half its paths
    leave its front."""
    from addon.core.methods.path_walk import WAVEFRONT_PATHS

    origin = np.array([[0.0, 0, 0], [0.05, 0.05, 0.4], [5.0, 5, -3]])
    u = np.array([[1.0, 0, 0], [0, 0.3, 0], [0.2, 0, 0]])
    v = np.array([[0.0, 1, 0], [0.3, 0, 0], [0, 0.2, 0]])  # the card's normal is -z
    V, T, TP = rectangles_to_mesh(origin, u, v)
    V = np.vstack([V[:8], V[8:11]])  # the third patch: one triangle only
    T, TP = T[:5], TP[:5]
    scene = PatchScene(V, T, TP, [0.0, 0.5, 0.5], [1.0, 0.0, 0.0])
    assert not scene.geometry.all_parallelograms
    F = rectangle_form_factors(origin[:2], u[:2], v[:2])[0, 1]
    N = 1_000_000  # chunks of more paths than a wavefront: most paths start in later steps
    r = solve(scene, estimator="finite", paths=N, seed=83, exit_point=exit_point, sampling=sampling)
    assert N / r.chunks > WAVEFRONT_PATHS
    hits = r.reflected[1, 0] * scene.patch_area[1] / 0.5 / (scene.total_power / N)
    assert scene.total_power == 2 * scene.patch_area[0]
    F /= 2  # (the front's share of the paths)
    # Binomial count of first rays reaching the card (stratified sampling can only do better).
    assert abs(hits - N * F) < Z * math.sqrt(N * F * (1 - F)), (hits, N * F)
