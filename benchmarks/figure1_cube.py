"""The paper's figure 1 cube (a whole face emits): the two-way iteration against the paper's walk.

    python -m benchmarks.figure1_cube [--paths 2000000] [--seeds 3]

Where an emitter is large and near what it lights, the walk shoots the direct light about as
well as gathering does; this scene (27 small cubes in a unit enclosure whose top face emits,
546 patches) is where *Automatic* (which takes the two-way iteration here) was measured to lose.
Each method solves it at R_ave 0.2, 0.5 and 0.8 (exit point hit, 2 threads, the same paths),
for several seeds; its error is batch means' (per-patch relative variance over the non-emitting
patches, and the RMS over them over the mean, squared), its cost the wall seconds. Reported:
each method's MSE x seconds, medians over the seeds, and the walk's over the two-way
iteration's (above 1: the two-way iteration wins).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"
METHODS = {"two-way iteration": {"method": "two_way"}, "paper walk": {"method": "walk"}}


def measure(scene, paths, seed, arguments):
    from addon.core import solve

    start = time.perf_counter()
    r = solve(scene, estimator="finite", paths=paths, threads=2, seed=seed, exit_point="hit", **arguments)
    seconds = time.perf_counter() - start
    measured = ~scene.emission.any(axis=1)
    B, V = r.radiosity.mean(axis=1)[measured], r.reflected_variance.mean(axis=1)[measured]
    return seconds, np.mean(V / B**2), V.mean() / B.mean() ** 2


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=int, default=2_000_000)
    parser.add_argument("--seeds", type=int, default=3)
    args = parser.parse_args(argv)
    from sample_scenes import cube_enclosure

    rows = []
    for R in (0.2, 0.5, 0.8):
        scene = cube_enclosure.build(reflectivity=R).scene
        cost = {}
        for label, arguments in METHODS.items():
            runs = np.array([measure(scene, args.paths, seed, arguments) for seed in range(args.seeds)])
            cost[label] = (np.median(runs[:, 0]), np.median(runs[:, 0] * runs[:, 1]), np.median(runs[:, 0] * runs[:, 2]))
        rows.append((R, cost))
        print(R, cost, flush=True)
    lines = ["# The figure 1 cube: the two-way iteration against the paper's walk", "",
             f"`python -m benchmarks.figure1_cube --paths {args.paths} --seeds {args.seeds}`", "",
             __doc__.split("\n\n", 2)[2].strip(), "",
             "| R_ave | method | seconds | per-patch MSE x s | (RMS/mean)^2 x s |", "|---:|---|---:|---:|---:|"]
    for R, cost in rows:
        for label, (seconds, per_patch, rms) in cost.items():
            lines.append(f"| {R} | {label} | {seconds:.2f} | {per_patch:.3g} | {rms:.3g} |")
        w, t = cost["paper walk"], cost["two-way iteration"]
        lines.append(f"| {R} | walk / two-way | | **{w[1] / t[1]:.2f}** | **{w[2] / t[2]:.2f}** |")
    (RESULTS / "figure1_cube.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
