"""What carrying three colour channels on one path costs in saturated scenes.

    .venv/bin/python -m benchmarks.colour_channels           # into benchmarks/results/colour_channels.md
    .venv/bin/python -m benchmarks.colour_channels --quick   # into out/

A colour walk chooses its paths by the grey (channel-mean) power and reflectivity and carries
each channel's weight, multiplied by R_c / R_bar at every survival (tables.survivor_weight).
Where colours are saturated those weights spread and a channel's error grows. The alternative
is one grey walk per channel (reflectivity R_c, emission E_c), each choosing its own paths.

Measured on the closed Cornell box (20 divisions, its red and green walls; the classic warm light)
and on the same box with the walls' colours pushed to one channel (red (0.8, 0.02, 0.02),
green (0.02, 0.8, 0.02)), finite estimator, random exit, 2 threads, the first shot shot. For
each channel: the area-weighted mean over patches of the batch-means variance of b_c, relative
to the channel's mean b_c squared, times the wall seconds (lower is better: the work to a given
error goes as variance x time). The ratio colour / per channel is the cost of the shared paths;
for the three channels together, the per-channel runs' seconds are added (the same solve needs
all three).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"


def scenes():
    import sample_scenes
    from sample_scenes import cornell_box

    base = sample_scenes.build("cornell_box", divisions=20, closed=True).scene
    yield "Cornell box", base
    R = base.reflectivity.copy()
    red = np.all(np.isclose(R, cornell_box.RED), axis=1)
    green = np.all(np.isclose(R, cornell_box.GREEN), axis=1)
    R[red], R[green] = (0.8, 0.02, 0.02), (0.02, 0.8, 0.02)
    yield "Cornell box, saturated walls", base.with_materials(R, base.emission)


def measure(scene, paths, seed):
    """{(run, channel): (relative variance x seconds, relative variance, seconds)}: the colour
    walk and one grey walk per channel."""
    from addon.core import solve

    weight = scene.patch_area / scene.patch_area.sum()
    out = {}
    colour = solve(scene, paths=paths, seed=seed, threads=2)
    for c in range(3):
        b = colour.reflected[:, c]
        relative = float(weight @ colour.reflected_variance[:, c]) / float(weight @ b) ** 2
        out[("colour", c)] = relative, colour.seconds
    for c in range(3):
        grey = scene.with_materials(scene.reflectivity[:, c], scene.emission[:, c])
        r = solve(grey, paths=paths, seed=seed, threads=2)
        b = r.reflected[:, 0]
        out[("channel", c)] = float(weight @ r.reflected_variance[:, 0]) / float(weight @ b) ** 2, r.seconds
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    paths, seeds = (300_000, 1) if args.quick else (3_000_000, 3)
    from addon.core import solve

    rows = []
    for name, scene in scenes():
        solve(scene, paths=paths // 10, threads=2)  # warm: the BVH, the tables
        runs = [measure(scene, paths, seed) for seed in range(seeds)]
        med = {key: (float(np.median([r[key][0] for r in runs])), float(np.median([r[key][1] for r in runs])))
               for key in runs[0]}
        separate_seconds = sum(med[("channel", c)][1] for c in range(3))
        for c, channel in enumerate("RGB"):
            colour_cost = med[("colour", c)][0] * med[("colour", c)][1]
            own_cost = med[("channel", c)][0] * separate_seconds
            rows.append((name, channel, med[("colour", c)][0], med[("colour", c)][1], med[("channel", c)][0],
                         med[("channel", c)][1], colour_cost / own_cost))
            print(f"{name:30s} {channel}: colour walk var {med[('colour', c)][0]:.3g} in {med[('colour', c)][1]:.2f} s, "
                  f"own walk var {med[('channel', c)][0]:.3g} in {med[('channel', c)][1]:.2f} s; "
                  f"cost colour / three walks {colour_cost / own_cost:.2f}", flush=True)
    out = (ROOT / "out" if args.quick else RESULTS) / "colour_channels.md"
    out.parent.mkdir(exist_ok=True)
    L = ["# Three channels on one path, or one walk per channel", "",
         f"`python -m benchmarks.colour_channels{' --quick' if args.quick else ''}`: {paths:,} paths a run, medians of "
         f"{seeds} seeds, 2 threads; the scenes and the measure in the module's docstring. Relative variance: "
         "area-weighted batch-means variance of b_c over (mean b_c)^2. Cost = relative variance x seconds; the "
         "last column is the colour walk's cost over three grey walks' (their seconds added): above 1, the shared "
         "paths cost that much more work to the same error in that channel.", "",
         "| scene | channel | colour walk rel. variance | s | own walk rel. variance | s | cost colour / three walks |",
         "|---|---|---:|---:|---:|---:|---:|"]
    for name, channel, v, s, vo, so, ratio in rows:
        L.append(f"| {name} | {channel} | {v:.3g} | {s:.2f} | {vo:.3g} | {so:.2f} | {ratio:.2f} |")
    out.write_text("\n".join(L) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
