"""The measured stop rule against exact references: delivered MSE over the target, per method;
and its price: the paths and time to the same target on the sample scenes.

    python -m benchmarks.stop_rule            # writes benchmarks/results/stop_rule.md

Closed boxes of rectangular patches with exact form factors (tests/core/boxes.py), solved by the
direct linear solve (core.reference), then by the solver with stop_rule="measured" at the
panel's relative targets, 12 seeds, one thread. "old" is the rule before the confidence margin
(stop once the measured MSE alone meets the target, from MIN_MEASURED_CHUNKS chunks); "new" the
solver's (plus MEASURED_STOP_Z standard errors of the estimate, MEASURED_STOP_CHUNKS chunks at least).
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
from addon.core.estimate import plan  # noqa: E402
from addon.core.estimate.reference import area_weighted_mse, solve_radiosity_system  # noqa: E402

SEEDS = range(12)
NEW = (plan.MEASURED_STOP_Z, plan.MEASURED_STOP_CHUNKS)
OLD = (0.0, plan.MIN_MEASURED_CHUNKS)
PRICE_SEEDS = range(3)


def use(rule):
    plan.MEASURED_STOP_Z, plan.MEASURED_STOP_CHUNKS = rule


EVERY = ("auto", "walk", "two_way", "jacobi")
CASES = [  # (name, scene maker, methods, relative targets)
    ("small source, middle (384 patches, R 0.8)", small_source_box, EVERY, (0.05,)),
    ("small source, middle (384 patches, R 0.8)", small_source_box, ("auto", "walk"), (0.02,)),
    ("small source, corner (96 patches, R 0.8)", lambda: small_source_box(n=4, corner=True), EVERY, (0.05, 0.02)),
    ("small source, corner (384 patches, R 0.8)", lambda: small_source_box(corner=True), EVERY, (0.05,)),
    ("small source, corner (384 patches, R 0.8)", lambda: small_source_box(corner=True), ("walk", "two_way"), (0.02,)),
    ("bright box (216 patches, R 0.95)", bright_box, EVERY, (0.10, 0.05)),
    ("colour box (96 patches)", colour_box, EVERY, (0.05, 0.02)),
    ("grey room (384 patches, R 0.5)", grey_room, EVERY, (0.05, 0.02)),
]


def run(scene, exact, method, relative, rule):
    use(rule)
    target = relative_rms_to_mse(predict(scene), relative)
    ratios, paths, seconds, ran = [], [], [], set()
    for seed in SEEDS:
        start = time.perf_counter()
        r = solve(scene, target_mse=target, seed=seed, stop_rule="measured", threads=1, method=method)
        seconds.append(time.perf_counter() - start)
        paths.append(r.paths)
        ran.add(f"{r.method}/{r.stopped}")
        ratios.append(area_weighted_mse(r.reflected, exact - scene.emission, scene.patch_area) / target)
    use(NEW)
    return np.array(ratios), np.mean(paths), np.sum(seconds), ",".join(sorted(ran))


def price():
    """The paths and seconds to the same target, old and new rule, on sample scenes (no exact
    reference: what the margin costs), 3 seeds, 2 threads."""
    import sample_scenes

    lines = ["", "## The price on the sample scenes", "",
             f"Mean paths a run and the {len(PRICE_SEEDS)} runs' seconds (2 threads, a shared 2-core machine: "
             "the paths are the measure), old and new rule, at the same target.", "",
             "| scene | method (ran/stopped/chunks) | target | paths old | paths new | new/old | s old | s new |",
             "|---|---|---|---|---|---|---|---|"]
    for name, kwargs in (("cornell_box", {"closed": True}), ("cornell_box", {}), ("fig1_r0.5", {})):
        scene = sample_scenes.build(name, **kwargs).scene
        label = f"{name}{' closed' if kwargs else ''} ({scene.patch_count:,} patches)"
        for relative in (0.05, 0.02):
            target = relative_rms_to_mse(predict(scene), relative)
            for method in ("auto", "walk"):
                out = []
                for rule in (OLD, NEW):
                    use(rule)
                    paths, seconds, ran = [], 0.0, set()
                    for seed in PRICE_SEEDS:
                        start = time.perf_counter()
                        r = solve(scene, target_mse=target, seed=seed, stop_rule="measured", threads=2, method=method)
                        seconds += time.perf_counter() - start
                        paths.append(r.paths)
                        ran.add(f"{r.method}/{r.stopped}/{r.chunks}")
                    out.append((np.mean(paths), seconds, ran))
                use(NEW)
                row = (f"| {label} | {method} ({', '.join(sorted(out[1][2]))}) | {relative:.0%} | {out[0][0]:,.0f} | "
                       f"{out[1][0]:,.0f} | {out[1][0] / out[0][0]:.2f} | {out[0][1]:.1f} | {out[1][1]:.1f} |")
                print(row, flush=True)
                lines.append(row)
    return lines


def main():
    lines = ["# The measured stop rule against exact references", "",
             f"Delivered MSE (against the direct solve) over the target MSE, {len(SEEDS)} seeds, one thread; "
             f"old: the measured MSE alone, from {OLD[1]} chunks; new: plus {NEW[0]:g} of its standard errors, "
             f"from {NEW[1]} chunks. Paths: the mean a run; time: the 12 runs'. `python -m benchmarks.stop_rule`.", "",
             "| scene | method (ran/stopped) | target | rule | mean | median | worst | over 1 | paths | time (s) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, make, methods, targets in CASES:
        scene, F = make()
        exact = solve_radiosity_system(F, scene.reflectivity, scene.emission)
        for relative in targets:
            for method in methods:
                for label, rule in (("old", OLD), ("new", NEW)):
                    ratios, paths, seconds, ran = run(scene, exact, method, relative, rule)
                    row = (f"| {name} | {method} ({ran}) | {relative:.0%} | {label} | {ratios.mean():.2f} | "
                           f"{np.median(ratios):.2f} | {ratios.max():.2f} | {np.sum(ratios > 1)}/{len(ratios)} | "
                           f"{paths:,.0f} | {seconds:.1f} |")
                    print(row, flush=True)
                    lines.append(row)
    lines += price()
    out = ROOT / "benchmarks" / "results" / "stop_rule.md"
    out.write_text("\n".join(lines) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
