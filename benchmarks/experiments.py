"""Building blocks of the paper's experiments, shared by ``benchmarks.paper`` and the tests.

* :func:`cumulative_runs` runs a sequence of independent ``solve`` batches and returns the
  estimate after each cumulative path count. Both estimators are linear in the per-path scores,
  so the path-weighted mean of K independent runs of n_k paths is distributed exactly like one
  run of sum n_k paths: a curve of MSE against paths costs only its last point.
* :func:`fig1_reference` is the direct solve B = E + R F B with F from two independent ray-cast
  halves, and an estimate of its own MSE from the disagreement of the halves.
* :func:`long_run_reference` is the paper's reference for the rooms: one much longer finite run.
"""
from __future__ import annotations

import hashlib
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

CACHE = Path(os.environ.get("RWR_BENCH_CACHE", Path(__file__).resolve().parent.parent / "out" / "benchmarks_cache"))


def mse(estimate, reference, area):
    """Area-weighted mean over patches of the squared error of B, averaged over channels."""
    err = np.asarray(estimate, float) - np.asarray(reference, float)
    sq = (err**2).mean(axis=1) if err.ndim == 2 else err**2
    return float(np.sum(sq * area) / np.sum(area))


def percent_area_error(estimate, reference, area, tolerance=0.10):
    """%A: percentage of the surface area whose radiosity (channel mean) has a relative error of
    at least ``tolerance``. Patches whose reference radiosity is 0 (covered by furniture) count
    as wrong only if the estimate is not 0 there either."""
    b = np.asarray(estimate, float)
    r = np.asarray(reference, float)
    if b.ndim == 2:
        b, r = b.mean(axis=1), r.mean(axis=1)
    diff = np.abs(b - r)
    with np.errstate(divide="ignore", invalid="ignore"):
        wrong = np.where(r > 0, diff >= tolerance * r, diff > 0)
    return float(100.0 * np.sum(area[wrong]) / np.sum(area))


@dataclass
class CurvePoint:
    paths: int
    rays: int
    seconds: float      # wall time of the solves (the core's own seconds), summed
    cpu_seconds: float  # process CPU time (all threads) of the solves, summed: robust to other load
    radiosity: np.ndarray
    predicted_mse: float
    batch_mse: float  # the core's a-posteriori estimate for the cumulative run (combined batches)


def paper_sampling():
    """Keyword arguments that pin the paper's own estimator (independent sampling) if the core
    offers other samplings; empty if it does not."""
    import inspect

    from addon.core import solve

    return {"sampling": "independent"} if "sampling" in inspect.signature(solve).parameters else {}


def cumulative_runs(scene, estimator, batches, seed, threshold=1e-3, threads=None, exit_point="random", sampling=None):
    """Run independent batches of ``batches[k]`` paths; yield the combined estimate after each.

    ``sampling`` None runs the paper's estimator; "stratified" the core's option beyond it."""
    how = paper_sampling() if sampling is None else {"sampling": sampling}
    from addon.core import solve

    total_paths = 0
    total_rays = 0
    seconds = 0.0
    cpu = 0.0
    weighted = None
    batch_mse_weighted = 0.0
    out = []
    for k, n in enumerate(batches):
        c0 = time.process_time()
        r = solve(scene, estimator=estimator, paths=int(n), threshold=threshold, seed=int(seed) * 1000 + k,
                  threads=threads, exit_point=exit_point, **how)
        cpu += time.process_time() - c0
        total_paths += r.paths
        total_rays += r.rays
        seconds += r.seconds
        weighted = r.reflected * r.paths if weighted is None else weighted + r.reflected * r.paths
        # MSE of a path-weighted mean of independent runs: sum (n_k/N)^2 mse_k
        batch_mse_weighted += (r.paths**2) * r.measured_mse
        p = r.prediction
        out.append(CurvePoint(
            paths=total_paths, rays=total_rays, seconds=seconds, cpu_seconds=cpu,
            radiosity=scene.emission + weighted / total_paths,
            predicted_mse=p.mse_per_path / total_paths,
            batch_mse=batch_mse_weighted / total_paths**2,
        ))
    return out


def doubling_batches(first, count):
    """Batch sizes whose cumulative sums are first, 2 first, 4 first, ... (count points)."""
    return [first] + [first * 2**k for k in range(count - 1)]


def _cache_key(*parts):
    return hashlib.sha1(repr(parts).encode()).hexdigest()[:16]


def geometry_key(sample):
    h = hashlib.sha1()
    for a in (sample.vertices, sample.triangles, sample.triangle_patch):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


@dataclass
class Reference:
    radiosity: np.ndarray
    mse: float          # estimated MSE of the reference itself
    rays: int
    seconds: float
    method: str
    extra: dict = field(default_factory=dict)


def raycast_form_factors_halves(sample, rays_per_patch, seed=0, cache=True):
    """Two independent ray-cast estimates of F (each with rays_per_patch/2 rays per patch)."""
    from addon.core.estimate.reference import form_factors_raycast

    key = _cache_key("ff2", geometry_key(sample), rays_per_patch, seed)
    path = CACHE / f"ff_{key}.npz"
    if cache and path.exists():
        z = np.load(path)
        return z["F1"], z["F2"], float(z["seconds"])
    t = time.perf_counter()
    half = rays_per_patch // 2
    F1 = form_factors_raycast(sample.scene, rays_per_patch=half, seed=seed * 2 + 1)
    F2 = form_factors_raycast(sample.scene, rays_per_patch=half, seed=seed * 2 + 2)
    seconds = time.perf_counter() - t
    if cache:
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, F1=F1.astype(np.float32), F2=F2.astype(np.float32), seconds=seconds)
        # float32 storage: counts/half are exact in float32 up to 2^24 rays
    return F1, F2, seconds


def direct_reference(F1, F2, reflectivity, emission, area, rays, seconds):
    """B from F = (F1 + F2)/2, and its MSE estimated as MSE(B(F1), B(F2)) / 4.

    To first order the error of B(F) is linear in the error of F; F1 and F2 are independent
    with twice the variance of their mean, so B(F1) - B(F2) has four times the variance of
    the error of B((F1 + F2)/2).
    """
    from addon.core.estimate.reference import solve_radiosity_system

    F = 0.5 * (F1.astype(np.float64) + F2.astype(np.float64))
    B = solve_radiosity_system(F, reflectivity, emission)
    B1 = solve_radiosity_system(F1.astype(np.float64), reflectivity, emission)
    B2 = solve_radiosity_system(F2.astype(np.float64), reflectivity, emission)
    return Reference(radiosity=B, mse=mse(B1, B2, area) / 4, rays=rays, seconds=seconds,
                     method="direct solve, ray-cast form factors")


def long_run_reference(sample, paths, seed=987654, threads=None, cache=True, label=""):
    """The paper's reference: one long finite (Phi_T) run; its MSE from the core's batch estimate."""
    from addon.core import solve

    key = _cache_key("long", geometry_key(sample), sample.reflectivity.tobytes(), sample.emission.tobytes(),
                     paths, seed)
    path = CACHE / f"ref_{label}_{key}.npz"
    if cache and path.exists():
        z = np.load(path)
        return Reference(radiosity=z["B"], mse=float(z["mse"]), rays=int(z["rays"]), seconds=float(z["seconds"]),
                         method=f"finite run of {paths:,} paths")
    r = solve(sample.scene, estimator="finite", paths=int(paths), seed=seed, threads=threads, **paper_sampling())
    if cache:
        CACHE.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, B=r.radiosity, mse=r.measured_mse, rays=r.rays, seconds=r.seconds)
    return Reference(radiosity=r.radiosity, mse=r.measured_mse, rays=r.rays, seconds=r.seconds,
                     method=f"finite run of {paths:,} paths")


def relative_efficiency_measured(mse_biased, rays_biased, mse_finite, rays_finite):
    """(MSE x rays) of the biased estimator over that of the finite one."""
    return (mse_biased * rays_biased) / (mse_finite * rays_finite)


def geometric_mean(values):
    v = np.asarray(values, float)
    return float(np.exp(np.mean(np.log(v))))


def paper_path_length(R, t):
    return 1 + math.log(t) / math.log(R)


# --------------------------------------------------------------------------------------------
# Why the rooms' paths are shorter than the formulas say (grey scenes)
# --------------------------------------------------------------------------------------------

def first_hit_distribution(scene, paths=2_000_000, seed=31, threads=None):
    """Fraction of the emitted power whose first hit is each patch, (P,).

    A biased run in which every patch reflects 0.5 and t = 0.9 stops every path at its first
    hit (0.5 < 0.9), so its reflected radiosity is 0.5 x the directly incident power / area."""
    from addon.core import solve

    P = scene.patch_count
    probe = scene.with_materials(np.full(P, 0.5), scene.emission.mean(axis=1))
    r = solve(probe, estimator="biased_infinite", paths=int(paths), threshold=0.9, seed=seed, threads=threads,
              **paper_sampling())
    power = r.reflected.mean(axis=1) * scene.patch_area / 0.5
    return power / power.sum()


def biased_length_model(reflectivity, area, threshold, first_hit=None, walks=400_000, seed=5, max_hits=200):
    """Mean rays per biased path when the k-th hit's reflectivity is drawn independently:
    hit 1 from ``first_hit`` (or by area), later hits by area (the stationary distribution of
    the form-factor walk in a closed scene). A path ends at the first hit after which the product
    of reflectivities is below t (a reflectivity of 0 ends it at once)."""
    rng = np.random.default_rng(seed)
    R = np.asarray(reflectivity, float)
    p_area = np.asarray(area, float) / np.sum(area)
    p_first = p_area if first_hit is None else np.asarray(first_hit, float)
    log_t = math.log(threshold)
    with np.errstate(divide="ignore"):
        logR = np.log(R)
    acc = np.zeros(walks)
    alive = np.ones(walks, bool)
    hits = np.zeros(walks)
    for k in range(max_hits):
        n = int(alive.sum())
        if n == 0:
            break
        idx = rng.choice(R.size, size=n, p=p_first if k == 0 else p_area)
        hits[alive] += 1
        acc[alive] += logR[idx]
        alive[alive] = acc[alive] >= log_t
    return float(hits.mean())


def finite_length_model(reflectivity, area, first_hit):
    """1 + E[R_1] / (1 - R_ave): the first hit from ``first_hit``, the rest the formula's."""
    R = np.asarray(reflectivity, float)
    r_ave = float(np.sum(area * R) / np.sum(area))
    return 1.0 + float(np.sum(first_hit * R)) / (1.0 - r_ave)


def path_length_analysis(scene, threshold, threads=None, first_hit_paths=2_000_000):
    """Mean rays per path, from the formulas to what the rooms' walks see (grey scenes)."""
    R = scene.grey_reflectivity
    area = scene.patch_area
    r_ave = float(np.sum(area * R) / area.sum())
    positive = R > 0
    geo = math.exp(float(np.sum(area[positive] * np.log(R[positive])) / area[positive].sum()))
    first = first_hit_distribution(scene, first_hit_paths, threads=threads)
    return {
        "R_ave": r_ave,
        "geometric_mean_R": geo,               # area-weighted, reflecting patches only
        "absorbing_area_fraction": float(area[~positive].sum() / area.sum()),
        "first_hit_mean_R": float(np.sum(first * R)),
        "biased_formula": 1 + math.log(threshold) / math.log(r_ave),
        "biased_geometric": 1 + math.log(threshold) / math.log(geo),
        "biased_model_area_reflecting": biased_length_model(R[positive], area[positive], threshold),
        "biased_model_area": biased_length_model(R, area, threshold),
        "biased_model_first_hit": biased_length_model(R, area, threshold, first_hit=first),
        "finite_formula": 1 / (1 - r_ave),
        "finite_model_first_hit": finite_length_model(R, area, first),
    }


def formula1_infinite_per_path(scene, paths=4_000_000, seed=41, threads=None):
    """The infinite estimator's step before averaging: Phi_T / A_T * sum_i beta_i, with beta_i
    the reflected radiosity of the scene with every reflectivity squared (table 1), estimated by
    two independent finite runs of that scene (paths/2 each). Returns (value, the two halves'
    relative difference / 2, an estimate of the value's relative standard error)."""
    from addon.core import solve

    R = scene.grey_reflectivity
    squared = scene.with_materials(R**2, scene.emission.mean(axis=1))
    sums = [float(solve(squared, estimator="finite", paths=int(paths) // 2, seed=seed + k, threads=threads,
                        **paper_sampling()).reflected.mean(axis=1).sum()) for k in range(2)]
    total = 0.5 * (sums[0] + sums[1])
    return scene.total_power / scene.total_area * total, abs(sums[0] - sums[1]) / 2 / total
