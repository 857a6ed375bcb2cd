"""What per-source results cost a solve, and what relighting costs.

    .venv/bin/python -m benchmarks.relight           # into benchmarks/results/relight.md
    .venv/bin/python -m benchmarks.relight --quick   # into out/

1. A solve with per-source results (``solve(..., per_source=True)``) against one without, at the
   same paths, seed and threads, the two run alternately in one process: wall seconds, the
   measured MSE of the total, and the time ratio at the same error of the total,
   (t_on mse_on) / (t_off mse_off) (the paths to an error go as its MSE: the ratio of the times
   each needs to reach the same error). Peak memory of each solve (tracemalloc: numpy's and
   Python's allocations during the solve) in separate runs. Scenes: the closed Cornell box lit by
   its ceiling and a point, a spot and an area lamp (4 sources), and the same box with 16 small
   point lamps beside its ceiling (17 sources).
2. ``relight`` against patch count (10^3 to 10^6) and sources (1 to 32), on stored results (no
   ray is traced): the median of 5 calls, with and without the irradiance. Patches x sources
   over grouping.PER_SOURCE_MAX are refused by the solve and left out.
"""
from __future__ import annotations

import argparse
import gc
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

METHODS = [("walk, shot", dict()), ("walk, gathered", dict(direct_light="gathered")),
           ("Jacobi", dict(method="jacobi")), ("two-way", dict(method="two_way")),
           ("two-way, hit exit", dict(method="two_way", exit_point="hit"))]


def scenes(divisions):
    import sample_scenes
    from addon.core.lights.lights import AreaLight, PointLight, Spot

    base = sample_scenes.build("cornell_box", divisions=divisions, closed=True).scene
    lo, hi = base.vertices.min(axis=0), base.vertices.max(axis=0)
    centre, size = (lo + hi) / 2, hi - lo
    scale = float(size.max())
    down = np.array([0.0, 0.0, -1.0])
    four = [PointLight(centre + size * [0.2, 0.1, 0.1], np.array([0.4, 0.3, 0.2]) * scale**2, name="point"),
            AreaLight(centre + size * [-0.2, -0.2, 0.3], np.array([0.1, 0, 0]) * scale, np.array([0, 0.1, 0]) * scale, down,
                      np.full(3, 3.0), name="area"),
            PointLight(centre + size * [-0.2, 0.2, 0.2], np.full(3, 0.6) * scale**2, spot=Spot(down, 0.8, 0.9), name="spot")]
    yield f"Cornell box, {base.patch_count:,} patches, 4 sources", base.with_materials(base.reflectivity, base.emission, four)
    grid = [(x, y) for x in np.linspace(-0.35, 0.35, 4) for y in np.linspace(-0.35, 0.35, 4)]
    many = [PointLight(centre + size * [x, y, 0.0], np.full(3, 0.05) * scale**2, name=f"lamp {k}") for k, (x, y) in enumerate(grid)]
    yield f"Cornell box, {base.patch_count:,} patches, 17 sources", base.with_materials(base.reflectivity, base.emission, many)


def solve_pair(scene, paths, kw, reps):
    """[(seconds, mse) without, (seconds, mse) with per-source results], each the sum/mean of
    ``reps`` alternate runs (seeds 0..reps-1)."""
    from addon.core import solve

    out = {False: [0.0, 0.0], True: [0.0, 0.0]}
    for seed in range(reps):
        for per_source in (False, True) if seed % 2 == 0 else (True, False):
            r = solve(scene, paths=paths, seed=seed, threads=2, per_source=per_source, **kw)
            out[per_source][0] += r.seconds
            out[per_source][1] += r.measured_mse / reps
    return out


def peak_memory(scene, paths, kw, per_source):
    """Peak bytes allocated during a solve (tracemalloc)."""
    from addon.core import solve

    gc.collect()
    tracemalloc.start()
    solve(scene, paths=paths, seed=0, threads=2, per_source=per_source, **kw)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak


def solve_table(divisions, paths, reps):
    lines = ["| scene | method | paths | s without | s with | MSE without | MSE with | time at the same error | "
             "peak MiB without | peak MiB with |", "|---|---|---|---|---|---|---|---|---|---|"]
    for name, scene in scenes(divisions):
        for label, kw in METHODS:
            pair = solve_pair(scene, paths, kw, reps)
            (t0, m0), (t1, m1) = pair[False], pair[True]
            memory = [peak_memory(scene, paths, kw, flag) / 2**20 for flag in (False, True)]
            lines.append(f"| {name} | {label} | {paths:,} | {t0:.2f} | {t1:.2f} | {m0:.3g} | {m1:.3g} | "
                         f"{t1 * m1 / (t0 * m0):.2f}x | {memory[0]:.0f} | {memory[1]:.0f} |")
            print(lines[-1], flush=True)
    return lines


def relight_table(patch_counts, source_counts):
    from addon.core import relight
    from addon.core.estimate.grouping import PER_SOURCE_MAX
    from addon.core.estimate.per_source import PerSource

    rng = np.random.default_rng(0)
    lines = ["| patches | sources | radiosity ms | radiosity and irradiance ms | radiosity ms, float32 results | "
             "stored MiB (float64, both) |", "|---|---|---|---|---|---|"]
    for P in patch_counts:
        for S in source_counts:
            if P * S > PER_SOURCE_MAX:
                lines.append(f"| {P:,} | {S} | over the cap | | | |")
                continue
            values = rng.random((S, P, 3))
            ps = PerSource(tuple(f"s{k}" for k in range(S)), values, values.copy(), rng.random((S, 3)),
                           np.eye(S)[None].repeat(3, axis=0) * 1e-6, 1.0, None)
            single = PerSource(ps.names, values.astype(np.float32), None, ps.power, ps.covariance, 1.0, None)
            weights = rng.random((S, 3))
            times = [_median_ms(lambda: relight(ps, weights)), _median_ms(lambda: relight(ps, weights, irradiance=True)),
                     _median_ms(lambda: relight(single, weights))]
            lines.append(f"| {P:,} | {S} | {times[0]:.1f} | {times[1]:.1f} | {times[2]:.1f} | {2 * values.nbytes / 2**20:.0f} |")
            print(lines[-1], flush=True)
            del values, ps, single
    return lines


def _median_ms(call, runs=5):
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        call()
        times.append(time.perf_counter() - start)
    return 1000 * float(np.median(times))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        solves = solve_table(10, 200_000, 2)
        relights = relight_table([1000, 100_000], [1, 8])
        out = ROOT / "out" / "relight.md"
    else:
        solves = solve_table(20, 1_000_000, 4)
        relights = relight_table([1000, 10_000, 100_000, 1_000_000], [1, 4, 8, 16, 32])
        out = RESULTS / "relight.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    text = ["# Per-source results and relighting", "", "Made by `python -m benchmarks.relight` "
            "(2 threads; the machine's 2 cores shared with other jobs: seconds are noisy, the two sides "
            "run alternately).", "", "## A solve with per-source results against one without", "", *solves, "",
            "## relight()", "", *relights, ""]
    out.write_text("\n".join(text))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
