"""predict() reproduces formulas (2), (3), (4) and the path counts, on hand-computed cases."""
import math

import pytest

from addon.core import predict, relative_rms_to_mse, mse_to_relative_rms
from boxes import box_scene


@pytest.fixture(scope="module")
def unit_cube():
    # Six unit faces, one patch each; the ceiling emits 1, every face reflects 0.5.
    # By hand: Phi_T = 1, A_T = 6, P = 6, A_ave = 1, R_ave = 0.5.
    scene, _, _ = box_scene([0.5] * 6, [0, 1, 0, 0, 0, 0])
    return scene


def test_paper_quantities(unit_cube):
    p = predict(unit_cube, "finite")
    assert p.Phi_T == pytest.approx(1.0, rel=1e-12)
    assert p.A_T == pytest.approx(6.0, rel=1e-12)
    assert p.A_ave == pytest.approx(1.0, rel=1e-12)
    assert p.R_ave == pytest.approx(0.5, rel=1e-12)


def test_formula_2_and_paths(unit_cube):
    # (2): 1^2 / (6 * 1) * 0.25 / 0.5 = 1/12; N for 1e-3 is ceil(83.33) = 84.
    p = predict(unit_cube, "finite", target_mse=1e-3)
    assert p.mse_per_path == pytest.approx(1 / 12, rel=1e-12)
    assert p.paths == 84
    assert p.expected_path_length == pytest.approx(2.0, rel=1e-12)
    assert p.expected_rays == pytest.approx(168.0, rel=1e-12)
    assert p.predicted_mse == pytest.approx((1 / 12) / 84, rel=1e-12)


def test_formula_3_and_paths(unit_cube):
    # (3): 1/6 * 0.25 / 0.75 = 1/18; N for 1e-3 is ceil(55.56) = 56.
    p = predict(unit_cube, "biased_infinite", target_mse=1e-3, threshold=1e-3)
    assert p.mse_per_path == pytest.approx(1 / 18, rel=1e-12)
    assert p.paths == 56
    # 1 + log(1e-3) / log(0.5) = 10.965784284662087
    assert p.expected_path_length == pytest.approx(10.965784284662087, rel=1e-12)


def test_formula_4(unit_cube):
    # (4): (1 - 0.5)(1 + log 1e-3 / log 0.5) / 1.5 = 3.6552614282206957; at t = 0.01: 0.5 * 7.643856 / 1.5
    assert predict(unit_cube, "finite", threshold=1e-3).relative_efficiency == pytest.approx(3.6552614282206957, rel=1e-12)
    assert predict(unit_cube, "finite", threshold=1e-2).relative_efficiency == pytest.approx(0.5 * (1 + math.log(0.01) / math.log(0.5)) / 1.5, rel=1e-12)


def test_relative_rms_round_trip(unit_cube):
    # b_ave = R_ave Phi_T / (A_T (1 - R_ave)) = 0.5 / 3; 2% of it, squared.
    mse = relative_rms_to_mse(unit_cube, 0.02)
    assert mse == pytest.approx((0.02 * 0.5 / 3) ** 2, rel=1e-12)
    assert mse_to_relative_rms(unit_cube, mse) == pytest.approx(0.02, rel=1e-12)


def test_area_weighting_of_R_ave():
    # Box 1 x 2 x 1: floor and ceiling 2, x-walls 2, y-walls 1; A_T = 10, P = 6.
    # R: floor .2, ceiling .4, x=0 .6, x=1 .8, y=0 .1, y=2 .3
    # R_ave = (2*.2 + 2*.4 + 2*.6 + 2*.8 + .1 + .3) / 10 = 0.44; Phi_T = 3 * 2 (ceiling emits 3)
    scene, _, _ = box_scene([0.2, 0.4, 0.6, 0.8, 0.1, 0.3], [0, 3, 0, 0, 0, 0], size=(1, 2, 1))
    p = predict(scene, "finite", target_mse=0.01)
    assert p.R_ave == pytest.approx(0.44, rel=1e-12)
    assert p.Phi_T == pytest.approx(6.0, rel=1e-12)
    expected = 36 / (10 * 10 / 6) * 0.44**2 / 0.56
    assert p.mse_per_path == pytest.approx(expected, rel=1e-12)
    assert p.paths == math.ceil(expected / 0.01)


def test_bad_arguments(unit_cube):
    with pytest.raises(ValueError, match="estimator"):
        predict(unit_cube, "infinite")
    with pytest.raises(ValueError, match="threshold"):
        predict(unit_cube, "biased_infinite", threshold=1.5)
    with pytest.raises(ValueError, match="target_mse"):
        predict(unit_cube, "finite", target_mse=-1)
