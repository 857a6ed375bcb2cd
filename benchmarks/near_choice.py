"""Shadow rays choosing emitting patches by nearness (core near_choice) against by power alone.

    python -m benchmarks.near_choice      # writes benchmarks/results/near_choice.md

Per scene and method: the measured (batch-means) MSE of a fixed path count, its mean over four
seeds, and the rays traced: the speed-up to a given error is the MSE ratio over the rays ratio
(rays, not seconds: on a shared machine seconds were noisier than the effect; their median
ratio is the last column). The two choices alternate in one process run. "By power" sets
near_choice.MAX_TABLE to 0 (fewer than two clusters: the choice and cosine share of before).
The rooms are built with bpy (benchmarks/interior_scene.py) at a 0.32 m patch size.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "core"))

from addon.core.lights import near_choice  # noqa: E402
from addon.core import solve

OUT = ROOT / "benchmarks" / "results" / "near_choice.md"
ROUNDS = 4
METHODS = (("two-way", dict(method="two_way")), ("walk, gathered", dict(direct_light="gathered")))


def room(name):
    import bpy

    from addon.blender_read.selection import read_selection
    from addon.bpy_free.patches import make_patches
    from addon.bpy_free.scene_notes import scene_and_notes
    from benchmarks import interior_scene

    interior_scene.build(name)
    bpy.context.view_layer.update()
    for o in bpy.context.view_layer.objects:
        o.select_set(o.type == "MESH")
    objects, _ = read_selection(bpy.context)
    return scene_and_notes(make_patches(objects, 0.32))[0]


def scenes():
    from pinned_cases import sample

    return [("Cornell box (sample)", lambda: sample("cornell_box"), 200_000),
            ("figure 4 room (sample)", lambda: sample("fig4_room"), 200_000),
            ("lamp room: a strip 4-8 cm from a wall and the ceiling, a spot", lambda: room("lamp_room"), 1_000_000),
            ("window room: sun, sky, point and area lamps", lambda: room("window_room"), 300_000)]


def measure(scene, paths, seed, options):
    t = time.perf_counter()
    r = solve(scene, estimator="finite", paths=paths, seed=seed, exit_point="hit", **options)
    return r.measured_mse, r.rays + r.gather_rays, time.perf_counter() - t


def main():
    table = near_choice.MAX_TABLE
    rows = []
    for name, make, paths in scenes():
        scene = make()
        for label, options in METHODS:
            found = {"near": [], "power": []}
            for k in range(ROUNDS):
                for choice in ("power", "near"):
                    near_choice.MAX_TABLE = table if choice == "near" else 0
                    found[choice].append(measure(scene, paths, k, options))
            near_choice.MAX_TABLE = table
            near, power = (np.mean([m[0] for m in found[c]]) for c in ("near", "power"))
            rays = np.mean([m[1] for m in found["near"]]) / np.mean([m[1] for m in found["power"]])
            seconds = np.median([m[2] for m in found["near"]]) / np.median([m[2] for m in found["power"]])
            rows.append(f"| {name} | {scene.patch_count:,} | {label} | {paths:,} | {power:.3g} | {near:.3g} | "
                        f"{rays:.2f} | {power / near / rays:.2f}x | {seconds:.2f} |")
            print(rows[-1], flush=True)
    OUT.write_text(
        "# Emitting patches chosen by nearness\n\n" + (__doc__.split("\n\n", 2)[2]).strip() + "\n\n"
        "| scene | patches | method | paths | MSE, by power | MSE, by nearness | rays, nearness / power | speed-up to equal error | seconds, nearness / power |\n"
        "|---|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n")


if __name__ == "__main__":
    main()
