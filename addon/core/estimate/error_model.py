"""The paper's heuristic error model: formulas (2), (3) and (4) of Sbert & Brusi.

For one path,
    finite (Phi_T):       E(MSE) ~ Phi_T^2 / (A_T A_ave) * R_ave^2 / (1 - R_ave)      (2)
    biased infinite:      E(MSE) ~ Phi_T^2 / (A_T A_ave) * R_ave^2 / (1 - R_ave^2)    (3)
and for N paths the MSE is divided by N, so N = mse_per_path / target.
Expected rays per path: 1 / (1 - R_ave) (finite) and 1 + log t / log R_ave (biased), and the
relative efficiency (MSE x cost of the biased estimator over that of the finite one) is
    re = (1 - R_ave) (1 + log t / log R_ave) / (1 + R_ave)                              (4)

In colour the grey quantities are channel means (Phi_T the mean over channels of the total
power, R_ave the area-weighted mean of the patches' mean reflectivity); MSE is the
area-weighted mean over patches of the squared error of B, averaged over channels.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from ..names import BIASED_INFINITE, ESTIMATORS, FINITE

# No run plans more paths than this (2^50, about 1.1e15): years of tracing on any machine or
# cluster, and counts stay exact integers in float64.
MAX_PATHS = 1 << 50

def mse_scale(Phi_T, A_T, A_ave):
    """Phi_T^2 / (A_T A_ave), the factor common to formulas (2) and (3)."""
    return Phi_T**2 / (A_T * A_ave)


def finite_mse_per_path(Phi_T, A_T, A_ave, R_ave):
    """Formula (2)."""
    return mse_scale(Phi_T, A_T, A_ave) * R_ave**2 / (1 - R_ave)


def infinite_mse_per_path(Phi_T, A_T, A_ave, R_ave):
    """Formula (3)."""
    return mse_scale(Phi_T, A_T, A_ave) * R_ave**2 / (1 - R_ave**2)


def finite_path_length(R_ave):
    """Expected rays per path of the finite estimator, 1 / (1 - R_ave)."""
    return 1.0 / (1.0 - R_ave)


def biased_path_length(R_ave, t):
    """Expected rays per path of the biased estimator as the paper writes it, 1 + log t / log R_ave."""
    if R_ave <= 0:
        return 1.0
    return 1.0 + math.log(t) / math.log(R_ave)


def relative_efficiency(R_ave, t):
    """Formula (4): (MSE x cost) of the biased infinite estimator over that of the finite one.

    Above 1 the finite estimator is the more efficient.
    """
    return (1.0 - R_ave) * biased_path_length(R_ave, t) / (1.0 + R_ave)


def mean_reflected_radiosity(Phi_T, A_T, R_ave):
    """The paper's average reflected radiosity, b_ave = R_ave Phi_T / (A_T (1 - R_ave))."""
    return R_ave * Phi_T / (A_T * (1.0 - R_ave))


@dataclass(frozen=True)
class Prediction:
    estimator: str
    threshold: float | None
    R_ave: float
    A_T: float
    A_ave: float
    Phi_T: float
    patch_count: int
    mse_per_path: float
    expected_path_length: float
    relative_efficiency: float
    mean_reflected_radiosity: float
    target_mse: float | None = None
    paths: int | None = None            # N needed for target_mse
    expected_rays: float | None = None  # N times the expected path length
    predicted_mse: float | None = None  # for the N given or needed

    def mse_for(self, paths):
        """Predicted MSE after ``paths`` paths."""
        return self.mse_per_path / paths if paths > 0 else math.inf

    def paths_for(self, target_mse):
        """Paths needed for ``target_mse`` (at least 1); ValueError, in one line, where that is
        more than MAX_PATHS (an absolute target far below the scene's light)."""
        needed = self.mse_per_path / target_mse
        if not needed <= MAX_PATHS:
            raise ValueError(
                f"target_mse {target_mse:.3g} would take about {needed:.3g} paths by the paper's formulas for sources of power "
                f"{self.Phi_T:.3g}, more than any run can trace ({MAX_PATHS:.3g}): give a larger target_mse, or one "
                "relative to the scene's light (relative_rms_to_mse)")
        return max(1, math.ceil(needed))


def _is_whole(value):
    """A Python or numpy integer (not a bool)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _is_number(value):
    """A Python or numpy real number (not a bool)."""
    return _is_whole(value) or isinstance(value, (float, np.floating))


def check_estimator(estimator, threshold):
    if estimator not in ESTIMATORS:
        raise ValueError(f"estimator must be one of {', '.join(ESTIMATORS)}; got {estimator!r}")
    if estimator == BIASED_INFINITE:
        if not (_is_number(threshold) and math.isfinite(threshold) and 0 < threshold < 1):
            raise ValueError(f"threshold t must be a number in (0, 1) for the biased infinite estimator; got {threshold!r}")


def check_positive(name, value, integer=False):
    if value is None:
        return
    kind = _is_whole if integer else _is_number
    if not kind(value) or not math.isfinite(value) or value <= 0:
        what = "a positive whole number" if integer else "a positive number"
        raise ValueError(f"{name} must be {what}; got {value!r}")


def predict(scene, estimator=FINITE, *, target_mse=None, threshold=1e-3, paths=None):
    """The paper's predictions for ``scene``, without tracing a ray.

    Gives R_ave, A_T, A_ave, Phi_T, the MSE of one path (formula (2) or (3)), the paths N
    needed for ``target_mse``, the expected path length and the relative efficiency (4).
    """
    check_estimator(estimator, threshold)
    check_positive("target_mse", target_mse)
    check_positive("paths", paths, integer=True)
    R_ave = scene.average_reflectivity
    A_T = scene.total_area
    P = scene.patch_count
    A_ave = A_T / P
    Phi_T = scene.total_power
    if estimator == FINITE:
        mse_per_path = finite_mse_per_path(Phi_T, A_T, A_ave, R_ave)
        length = finite_path_length(R_ave)
    else:
        mse_per_path = infinite_mse_per_path(Phi_T, A_T, A_ave, R_ave)
        length = biased_path_length(R_ave, threshold)
    prediction = Prediction(
        estimator=estimator,
        threshold=threshold if estimator == BIASED_INFINITE else None,
        R_ave=R_ave,
        A_T=A_T,
        A_ave=A_ave,
        Phi_T=Phi_T,
        patch_count=P,
        mse_per_path=mse_per_path,
        expected_path_length=length,
        relative_efficiency=relative_efficiency(R_ave, threshold) if threshold is not None and 0 < threshold < 1 else math.nan,
        mean_reflected_radiosity=mean_reflected_radiosity(Phi_T, A_T, R_ave),
        target_mse=target_mse,
    )
    n = paths if paths is not None else (prediction.paths_for(target_mse) if target_mse is not None else None)
    if n is None:
        return prediction
    return replace(prediction, paths=n, expected_rays=n * length, predicted_mse=prediction.mse_for(n))


def relative_rms_to_mse(prediction_or_scene, relative_rms):
    """The MSE of a relative RMS error of the reflected radiosity, relative to b_ave.

    ``relative_rms = 0.02`` means an RMS error of 2% of the scene's average reflected radiosity
    b_ave = R_ave Phi_T / (A_T (1 - R_ave)).
    """
    check_positive("relative RMS error", relative_rms)
    p = prediction_or_scene if isinstance(prediction_or_scene, Prediction) else predict(prediction_or_scene)
    if p.mean_reflected_radiosity <= 0:
        raise ValueError("the scene reflects nothing (every reflectivity is zero): a relative error has no scale")
    return (relative_rms * p.mean_reflected_radiosity) ** 2


def mse_to_relative_rms(prediction_or_scene, mse):
    """Inverse of :func:`relative_rms_to_mse`."""
    p = prediction_or_scene if isinstance(prediction_or_scene, Prediction) else predict(prediction_or_scene)
    if p.mean_reflected_radiosity <= 0:
        return 0.0 if mse == 0 else math.inf
    return math.sqrt(mse) / p.mean_reflected_radiosity
