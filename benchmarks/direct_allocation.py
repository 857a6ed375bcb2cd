"""The two-way iteration's direct-light samples allotted by area alone or half by a pilot's
light (two_way.RECEIVED_SHARE, two_way.pilot_irradiance), against exact references.

    python -m benchmarks.direct_allocation [fixed|stop|stop2|sample]   # all: writes
                                                                 # benchmarks/results/direct_allocation.md

fixed: each share's delivered MSE at a fixed path count (12 seeds, one thread) and its
MSE x seconds (the variance per path times seconds a path: lower is better); stop: delivered
MSE over the target with the measured stop rule at 5% (12 seeds); stop2: at 2%; sample: MSE x seconds on the
Cornell boxes against long runs (no exact reference).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "core"))

from boxes import bright_box, colour_box, grey_room, small_source_box  # noqa: E402

from addon.core import predict, relative_rms_to_mse, solve  # noqa: E402
from addon.core.methods import two_way
from addon.core.estimate.reference import area_weighted_mse, solve_radiosity_system  # noqa: E402

SEEDS = range(12)
SHARES = (0.0, 0.5)


CASES = [  # (name, maker, paths for the fixed runs)
    ("small source, corner (384 patches, R 0.8)", lambda: small_source_box(corner=True), 40_000),
    ("small source, middle (384 patches, R 0.8)", small_source_box, 20_000),
    ("colour box (96 patches)", colour_box, 10_000),
    ("grey room (384 patches, R 0.5)", grey_room, 20_000),
    ("bright box (216 patches, R 0.95)", bright_box, 20_000),
]


def exact_of(scene, F):
    return solve_radiosity_system(F, scene.reflectivity, scene.emission) - scene.emission


def fixed():
    """Delivered MSE over the 5% target's at a fixed path count (two_way, 12 seeds, one thread),
    and MSE x seconds a run relative to the area allotment's (the seconds are a busy 2-core
    machine's: the MSE at equal paths is the measure)."""
    lines = ["| scene | share | paths | mean MSE / target(5%) | worst | MSE x s (rel. to area) |", "|---|---|---|---|---|---|"]
    for name, make, paths in CASES:
        scene, F = make()
        exact = exact_of(scene, F)
        target = relative_rms_to_mse(predict(scene), 0.05)
        base = None
        for share in SHARES:
            two_way.RECEIVED_SHARE = share
            mse, seconds = [], []
            for seed in SEEDS:
                start = time.perf_counter()
                r = solve(scene, paths=paths, seed=seed, threads=1, method="two_way")
                seconds.append(time.perf_counter() - start)
                mse.append(area_weighted_mse(r.reflected, exact, scene.patch_area))
            cost = np.mean(mse) * np.mean(seconds)
            base = base or cost
            row = (f"| {name} | {share:g} | {paths:,} | {np.mean(mse) / target:.3f} | {np.max(mse) / target:.3f} | "
                   f"{cost / base:.2f} ({np.mean(seconds):.2f} s) |")
            print(row, flush=True)
            lines.append(row)
    return lines


STOP_HEADER = ["| scene | share | mean | median | worst | over 1 | paths | time (s) | stopped |", "|---|---|---|---|---|---|---|---|---|"]


def _stop_rows(name, make, relative, shares):
    """Automatic with the measured stop rule at ``relative``, each allotment share of ``shares``:
    delivered MSE over the target (12 seeds, one thread), mean, median, worst, runs over; mean
    paths; the 12 runs' seconds; how they ran. The table's rows."""
    scene, F = make()
    exact = exact_of(scene, F)
    target = relative_rms_to_mse(predict(scene), relative)
    rows = []
    for share in shares:
        two_way.RECEIVED_SHARE = share
        ratios, paths, seconds, ran = [], [], 0.0, set()
        for seed in SEEDS:
            start = time.perf_counter()
            r = solve(scene, target_mse=target, seed=seed, stop_rule="measured", threads=1, method="auto")
            seconds += time.perf_counter() - start
            paths.append(r.paths)
            ran.add(f"{r.method}/{r.stopped}")
            ratios.append(area_weighted_mse(r.reflected, exact, scene.patch_area) / target)
        ratios = np.array(ratios)
        row = (f"| {name} | {share:g} | {ratios.mean():.2f} | {np.median(ratios):.2f} | {ratios.max():.2f} | "
               f"{np.sum(ratios > 1)}/{len(ratios)} | {np.mean(paths):,.0f} | {seconds:.1f} | {','.join(sorted(ran))} |")
        print(row, flush=True)
        rows.append(row)
    return rows


def stop():
    """Every case at 5% (``_stop_rows``)."""
    return STOP_HEADER + [row for name, make, _ in CASES for row in _stop_rows(name, make, 0.05, SHARES[:2])]


def stop2():
    """The small-source boxes at 2%, as ``stop`` (the corner with the pilot's allotment only:
    by area it runs to its cap)."""
    return STOP_HEADER + [row for name, make, _ in CASES[:2]
                          for row in _stop_rows(name, make, 0.02, SHARES[1:] if "corner" in name else SHARES)]


def sample():
    """The Cornell boxes: MSE at 100k paths (16 seeds, 2 threads) against the mean of two
    8M-path runs (one of each allotment), and the seconds a run (median of the 16)."""
    import sample_scenes

    lines = ["| scene | share | paths | MSE (+- its standard error) | MSE x s (rel. to area) | rays a run |",
             "|---|---|---|---|---|---|"]
    for name, kwargs, paths in (("cornell_box", {"closed": True}, 100_000), ("cornell_box", {}, 100_000)):
        scene = sample_scenes.build(name, **kwargs).scene
        references = []
        for share, seed in ((0.0, 5000), (0.5, 5001)):
            two_way.RECEIVED_SHARE = share
            references.append(solve(scene, paths=80 * paths, seed=seed, threads=2, method="two_way").reflected)
        reference = (references[0] + references[1]) / 2
        base = None
        for share in SHARES[:2]:
            two_way.RECEIVED_SHARE = share
            mse, seconds, rays = [], [], []
            for seed in range(16):
                start = time.perf_counter()
                r = solve(scene, paths=paths, seed=seed, threads=2, method="two_way")
                seconds.append(time.perf_counter() - start)
                rays.append(r.rays)
                mse.append(area_weighted_mse(r.reflected, reference, scene.patch_area))
            cost = np.mean(mse) * np.median(seconds)
            base = base or cost
            row = (f"| {name}{' closed' if kwargs else ''} ({scene.patch_count:,} patches) | {share:g} | {paths:,} | "
                   f"{np.mean(mse):.3e} (+- {np.std(mse, ddof=1) / 4:.1e}) | {cost / base:.2f} ({np.median(seconds):.2f} s) | "
                   f"{np.mean(rays):,.0f} |")
            print(row, flush=True)
            lines.append(row)
    return lines


if __name__ == "__main__":
    which = sys.argv[1:] or ["fixed", "stop", "stop2", "sample"]
    out = [f"# The two-way iteration's direct-light samples: by area, or half by a pilot's light", "",
           f"`python -m benchmarks.direct_allocation {' '.join(which)}`; share 0: the allotment by sqrt(A) R alone; "
           f"0.5: two_way.RECEIVED_SHARE (the solver's).", ""]
    for w in which:
        out += ["", f"## {w}", "", " ".join(globals()[w].__doc__.split()) if globals()[w].__doc__ else "", ""] + globals()[w]()
    print("\n".join(out))
    if which == ["fixed", "stop", "stop2", "sample"]:
        (ROOT / "benchmarks" / "results" / "direct_allocation.md").write_text("\n".join(out) + "\n")
