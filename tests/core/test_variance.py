"""The measured MSE of the finite estimator matches the exact expected MSE of table 1.

E[MSE_N] = (1/A_T) sum_i A_i Var_i / N, Var_i = R_i b_i Phi_T / A_i (1 + 2 R_i xi_i) - b_i^2,
with b and xi from the same exact form factors. Over S seeds the mean of the measured MSE
has a standard error estimated from the seeds themselves; the band is 4 of those (t with
S-1 = 23 degrees of freedom: P(|t| > 4) < 6e-4).
"""
import numpy as np
import pytest

from addon.core import predict, solve
from addon.core.estimate.reference import area_weighted_mse, path_variances, solve_radiosity_system
from boxes import box_scene

SEEDS = range(24)
BAND = 4.0


@pytest.fixture(scope="module")
def runs():
    scene, F, _ = box_scene([0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0], (1.0, 1.4, 0.8), n=2)
    B = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    N = 20_000
    results = [solve(scene, estimator="finite", paths=N, seed=s, threads=1) for s in SEEDS]
    var, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    expected = float((scene.patch_area * var).sum() / scene.total_area / N)
    return scene, B, results, expected, N


def test_measured_mse_matches_table_1(runs):
    scene, B, results, expected, _ = runs
    mse = np.array([area_weighted_mse(r.radiosity, B, scene.patch_area) for r in results])
    standard_error = mse.std(ddof=1) / np.sqrt(mse.size)
    assert abs(mse.mean() - expected) < BAND * standard_error, (mse.mean(), expected, standard_error)


def test_batch_estimate_matches_table_1(runs):
    """The a-posteriori estimate (batch means over chunks) is unbiased for the same MSE."""
    _, _, results, expected, _ = runs
    estimates = np.array([r.measured_mse for r in results])
    standard_error = estimates.std(ddof=1) / np.sqrt(estimates.size)
    assert abs(estimates.mean() - expected) < BAND * standard_error, (estimates.mean(), expected, standard_error)


def test_heuristic_formula_is_the_right_order(runs):
    """Formula (2) is a heuristic (it drops the xi and b^2 terms and averages b); on this
    small scene it must still be within the paper's 'same order of magnitude'."""
    scene, _, results, expected, N = runs
    predicted = predict(scene, "finite", paths=N).predicted_mse
    assert results[0].predicted_mse == pytest.approx(predicted, rel=1e-12)
    assert 0.2 < predicted / expected < 5, predicted / expected
