"""Agreement with a direct solve of B = E + R F B, F in closed form (a closed box whose faces
are split into 2 x 2 rectangles: every patch sees every non-coplanar patch whole).

- exit_point="random" is the paper's discrete method: its expectation is exactly the discrete
  solution, and its per-patch variance is exactly table 1's (a Markov chain on patches).
- exit_point="hit" is particle tracing: its expectation is the *continuous* solution averaged
  over each patch. Its reference is the discrete solution on a 4x finer mesh, averaged back,
  with the remaining discretisation error bounded by half the change from a 2x finer mesh
  (the differences shrink by a factor of about 3 per halving here, measured, so the rest of
  the series is below half the last step).
"""
import numpy as np
import pytest

from addon.core import Speedups, solve
from addon.core.methods.tables import WalkTables
from addon.core.estimate.reference import path_variances, solve_radiosity_system
from boxes import box_scene

SIZE = (1.0, 1.4, 0.8)
R_FACES = [0.3, 0.6, 0.7, 0.5, 0.4, 0.65]
E_FACES = [0, 1.0, 0, 0, 0, 0]
Z = 4.0  # 24 patches: P(max |z| > 4) < 2e-3 for normal z
SEEDS = (101, 102, 103, 104)


@pytest.fixture(scope="module")
def coarse():
    scene, F, _ = box_scene(R_FACES, E_FACES, SIZE, n=2)
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    return scene, F, B


def _coarse_average(fine_values, fine_area, n_fine, n_coarse=2):
    """Area-average fine patches (face-major, i, j) onto the coarse ones."""
    m = n_fine // n_coarse
    idx = np.arange(fine_values.shape[0])
    face, rest = idx // (n_fine * n_fine), idx % (n_fine * n_fine)
    i, j = rest // n_fine, rest % n_fine
    target = face * n_coarse * n_coarse + (i // m) * n_coarse + (j // m)
    return np.bincount(target, weights=fine_area * fine_values) / np.bincount(target, weights=fine_area)


def _mean_over_seeds(scene, estimator, N, **kw):
    runs = [solve(scene, estimator=estimator, paths=N, seed=s, **kw) for s in SEEDS]
    return runs, np.mean([r.reflected for r in runs], axis=0)


def test_form_factors_are_exact(coarse):
    scene, F, _ = coarse
    A = scene.patch_area
    np.testing.assert_allclose(F.sum(axis=1), 1.0, atol=1e-12)          # closed box
    np.testing.assert_allclose(A[:, None] * F, (A[:, None] * F).T, atol=1e-12)  # reciprocity


def test_finite_random_exit_matches_direct_solve(coarse):
    scene, F, B = coarse
    N = 250_000
    _, b = _mean_over_seeds(scene, "finite", N)
    var, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    z = (b[:, 0] - (B[:, 0] - scene.emission[:, 0])) / np.sqrt(var / (N * len(SEEDS)))
    assert np.abs(z).max() < Z, z


def test_infinite_random_exit_matches_direct_solve(coarse):
    """With t = 1e-9 the truncation bias (< 1e-9 of the carried power) is far below the noise."""
    scene, F, B = coarse
    N = 60_000
    _, b = _mean_over_seeds(scene, "biased_infinite", N, threshold=1e-9)
    _, var = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    z = (b[:, 0] - (B[:, 0] - scene.emission[:, 0])) / np.sqrt(var / (N * len(SEEDS)))
    assert np.abs(z).max() < Z, z


@pytest.mark.parametrize("sorted_paths", [False, True])
def test_colour_random_exit_matches_direct_solve(sorted_paths):
    """Colour: one path serves three channels (survival by the mean, weights R_c / R_bar).
    With sorted_paths, the walk regroups its paths by patch at every step (what it does in big
    scenes), carrying their weights along, and reads frames by patch class: the same answer."""
    speedups = Speedups(sorted_paths=sorted_paths, patch_classes=sorted_paths)
    R = np.array([[0.7, 0.2, 0.2], [0.6, 0.6, 0.6], [0.2, 0.7, 0.2], [0.5, 0.5, 0.5], [0.3, 0.4, 0.8], [0.6, 0.5, 0.4]])
    E = np.array([[0, 0, 0], [1.0, 0.8, 0.5], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]])
    scene, F, _ = box_scene(R, E, SIZE, n=2)
    assert WalkTables(scene, "finite", 1e-3, "random", speedups=speedups).speedups.sorted_paths == sorted_paths
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    result = solve(scene, estimator="finite", paths=600_000, seed=5, speedups=speedups)
    z = (result.reflected - (B - scene.emission)) / np.sqrt(result.reflected_variance)
    # 72 channel-patches, variances estimated from >= 32 batches (t with >= 31 d.o.f.):
    # P(max |t| > 5) < 2e-3.
    assert result.chunks >= 32
    assert np.abs(z).max() < 5.0, np.abs(z).max()
    biased = solve(scene, estimator="biased_infinite", paths=150_000, threshold=1e-9, seed=6, speedups=speedups)
    z = (biased.reflected - (B - scene.emission)) / np.sqrt(biased.reflected_variance)
    assert np.abs(z).max() < 5.0, np.abs(z).max()


@pytest.mark.parametrize("sorted_paths", [False, True])
def test_hit_exit_matches_continuous_solution(coarse, sorted_paths):
    """(sorted_paths: the paths regrouped by patch at every step with their hit points, and
    patch classes, as in big scenes.)"""
    speedups = Speedups(sorted_paths=sorted_paths, patch_classes=sorted_paths)
    scene, _, B_discrete = coarse
    assert WalkTables(scene, "finite", 1e-3, "hit", speedups=speedups).speedups.sorted_paths == sorted_paths
    fine = {}
    for n in (4, 8):
        s, F, _ = box_scene(R_FACES, E_FACES, SIZE, n=n)
        Bf = solve_radiosity_system(F, s.reflectivity, s.emission)[:, 0]
        fine[n] = _coarse_average(Bf, s.patch_area, n)
    reference_error = np.abs(fine[8] - fine[4]) / 2
    reference = fine[8] - scene.emission[:, 0]
    N = 400_000
    runs, b = _mean_over_seeds(scene, "finite", N, exit_point="hit", speedups=speedups)
    var = np.mean([r.reflected_variance[:, 0] for r in runs], axis=0) / len(SEEDS)
    sd = np.sqrt(var + reference_error**2)
    z = (b[:, 0] - reference) / sd
    assert np.abs(z).max() < Z, z
    # The two exit points really have different targets here: the discrete solution, put in
    # place of the continuous one, fails the same test.
    z_discrete = (b[:, 0] - (B_discrete[:, 0] - scene.emission[:, 0])) / sd
    assert np.abs(z_discrete).max() > Z, np.abs(z_discrete).max()


@pytest.mark.parametrize("counted", [True, False])
def test_interchangeable_paths_match_direct_solve(coarse, counted):
    """A grey finite walk's paths are interchangeable: small scenes count each step's hits by
    patch and outcome and restart the survivors from the counts; big scenes sort the survivors
    by patch (coherent rays). Either way (the sorted one forced on for this small scene), the
    estimate agrees with the direct solve within table 1's variance, and every path ends
    exactly once."""
    speedups = Speedups(counted=counted, patch_classes=not counted)  # (classes, as in big scenes)
    scene, F, B = coarse
    tables = WalkTables(scene, "finite", 1e-3, "random", speedups=speedups)
    assert tables.speedups.interchangeable and tables.speedups.counted == counted
    assert (tables.patch_class is None) == counted
    N = 250_000
    runs, b = _mean_over_seeds(scene, "finite", N, speedups=speedups)
    assert all(sum(r.path_ends.values()) == N for r in runs)
    var, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    z = (b[:, 0] - (B[:, 0] - scene.emission[:, 0])) / np.sqrt(var / (N * len(SEEDS)))
    assert np.abs(z).max() < Z, z
