"""Furnace: a closed box where every patch emits E and reflects R has B = E / (1 - R) everywhere.

Bands come from the estimators' exact variances:
- finite, per patch: table 1, R b Phi_T / A (1 + 2 R xi) - b^2, with xi from exact form factors;
- finite, area-weighted mean: the number of hits of a path is geometric (mean 1/(1-R),
  variance R/(1-R)^2) whatever the geometry or the exit point;
- biased infinite: every path scores R + R^2 + ... + R^K in total (deterministic), so the
  area-weighted mean is exact; per patch the variance follows from powers of F.
"""
import numpy as np
import pytest

from addon.core import solve
from addon.core.estimate.reference import path_variances
from boxes import box_scene

E, R = 1.0, 0.5
Z_PATCH = 4.5   # P(max |z| > 4.5 over 54 patches) < 4e-4 for normal z
Z_TOTAL = 4.0


@pytest.fixture(scope="module")
def furnace():
    return box_scene([R] * 6, [E] * 6, size=(1.0, 1.3, 0.7), n=3)


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_finite_furnace(furnace, exit_point):
    scene, F, _ = furnace
    N = 200_000
    result = solve(scene, estimator="finite", paths=N, seed=11, exit_point=exit_point)
    B = result.radiosity[:, 0]
    assert np.array_equal(result.radiosity[:, 0], result.radiosity[:, 2])
    A = scene.patch_area
    # Area-weighted mean: exact variance from the geometric number of hits.
    mean_b = (A * result.reflected[:, 0]).sum() / A.sum()
    hits_sd = np.sqrt(R) / (1 - R)
    sd = R * scene.total_power / A.sum() * hits_sd / np.sqrt(N)
    assert abs(mean_b - E * R / (1 - R)) < Z_TOTAL * sd
    if exit_point == "random":
        # Per patch: table 1's exact variance (the random-exit walk is a Markov chain on patches).
        var_finite, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], A)
        z = (B - E / (1 - R)) / np.sqrt(var_finite / N)
        assert np.abs(z).max() < Z_PATCH, np.abs(z).max()
    assert result.stopped == "paths" and result.paths == N


def _biased_expectation_and_variance(F, area, R, t):
    """Per-patch mean and variance of one path's score in the grey furnace (random exit)."""
    P = F.shape[0]
    start = area / area.sum()   # sources in proportion to power = area here
    Phi_T = E * area.sum()
    K = 1
    while R**K >= t:
        K += 1
    c = R ** np.arange(1, K + 1)          # score factor at hit k
    p = np.empty((K, P))
    p[0] = start @ F
    for k in range(1, K):
        p[k] = p[k - 1] @ F
    powers = [np.eye(P)]
    for _ in range(K):
        powers.append(powers[-1] @ F)
    diag = np.array([np.diag(M) for M in powers])  # (K+1, P): (F^m)_ii
    mean = (c[:, None] * p).sum(axis=0)
    second = (c[:, None] ** 2 * p).sum(axis=0)
    for k in range(K):
        for l in range(k + 1, K):
            second += 2 * c[k] * c[l] * p[k] * diag[l - k]
    scale = Phi_T / area
    return scale * mean, scale**2 * second - (scale * mean) ** 2, c.sum()


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_biased_furnace(furnace, exit_point):
    scene, F, _ = furnace
    t = 1e-3
    N = 100_000
    result = solve(scene, estimator="biased_infinite", paths=N, threshold=t, seed=12, exit_point=exit_point)
    A = scene.patch_area
    b_mean, b_var, score_per_path = _biased_expectation_and_variance(F, A, R, t)
    # Every path scores the same total: the area-weighted mean is exact to rounding.
    mean_b = (A * result.reflected[:, 0]).sum() / A.sum()
    assert mean_b == pytest.approx(E * score_per_path, rel=1e-12)
    # The truncation bias is the tail R^(K+1) + ... : the expected B is below E / (1 - R).
    assert E * (1 + score_per_path) < E / (1 - R)
    if exit_point == "random":
        z = (result.reflected[:, 0] - b_mean) / np.sqrt(b_var / N)
        assert np.abs(z).max() < Z_PATCH, np.abs(z).max()


def test_biased_path_length_definition(furnace):
    """Rays per path = 1 + hits that continue: with R = 0.5, t = 1e-3 the path is cut at the
    hit where 0.5^k < 1e-3, k = 10, after 10 rays (the paper's formula gives 10.97)."""
    scene, _, _ = furnace
    result = solve(scene, estimator="biased_infinite", paths=1000, threshold=1e-3, seed=1)
    assert result.mean_path_length == 10.0
    assert result.path_ends["threshold"] == 1000


@pytest.mark.parametrize("exit_point", ["random", "hit"])
@pytest.mark.parametrize("sampling", ["independent", "stratified"])
def test_finite_furnace_of_triangle_patches(exit_point, sampling):
    """The furnace with every patch a single triangle (no parallelograms: rays leave from a
    triangle chosen by area and folded points, new paths of a hit-point exit included). The
    area-weighted mean has the exact geometric-hits variance; per patch, the run's own batch
    variances (>= 32 batches: t with >= 31 degrees of freedom, P(max |t| > 5) < 1e-3 over
    108 patches)."""
    from addon.core import PatchScene
    from boxes import box_rectangles, rectangles_to_mesh

    V, T, _ = rectangles_to_mesh(*box_rectangles((1.0, 1.3, 0.7), n=3)[:3])
    P = T.shape[0]
    scene = PatchScene(V, T, np.arange(P), np.full(P, R), np.full(P, E))
    assert not scene.geometry.any_parallelograms
    N = 200_000
    result = solve(scene, estimator="finite", paths=N, seed=12, exit_point=exit_point, sampling=sampling)
    A = scene.patch_area
    mean_b = (A * result.reflected[:, 0]).sum() / A.sum()
    sd = R * scene.total_power / A.sum() * (np.sqrt(R) / (1 - R)) / np.sqrt(N)
    # (Stratified sources can only lower the total's variance: the same band holds.)
    assert abs(mean_b - E * R / (1 - R)) < Z_TOTAL * sd
    assert result.chunks >= 32
    z = (result.reflected[:, 0] - E * R / (1 - R)) / np.sqrt(result.reflected_variance[:, 0])
    assert np.abs(z).max() < 5.0, np.abs(z).max()
