"""The two-way iteration's chunks at loose error targets: sized from the plan (the walk's
prediction, a guess) or grown to the balance of the measured stop rule (``balanced_chunk``).

    nice -n 10 .venv/bin/python -m benchmarks.loose_targets      # writes benchmarks/results/loose_targets.md

The panel's defaults (Automatic method) but the error target, through the operator, on the
README's Cornell box and the picture benchmark's two interiors (interior_scene.py), seeds 0-1.
"plan" is the rule before (chunks from the plan alone: at a small plan, 4 first-generation rays
a patch, and Automatic takes the walk below that); "balanced" the solver's. Rays traced are the
machine-independent cost; seconds are the solver's own, on a shared machine.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks import interior_scene, picture  # noqa: E402

SCENES = ("cornell", "window_room", "lamp_room")
TARGETS = (8.0, 5.0, 2.0)
SEEDS = (0, 1)


def build(name):
    """The scene built in an empty file."""
    import bpy

    bpy.ops.wm.read_homefile(use_empty=True)
    if name == "cornell":
        from addon.cli import scenes

        scenes.build_sample_scene("cornell_box")
    else:
        interior_scene.build(name)


def solve(target, seed, rule):
    """One run through the operator: (method, paths, rays, seconds, error %)."""
    import bpy

    from addon.bpy_free import options
    from addon.core.methods import two_way
    from addon.blender_write import solve_job

    settings = bpy.context.scene.radiosity
    for option in options.SETTINGS:
        setattr(settings, option.name, option.default)
    settings.target_error, settings.seed = target, seed
    picture.source_objects()  # (selected)
    chunk_paths = two_way.TwoWay.chunk_paths
    if rule == "plan":  # (the chunks the plan alone gives, as before)
        two_way.TwoWay.chunk_paths = lambda self, *a, guessed=False, **k: chunk_paths(self, *a, **k)
    try:
        finished = solve_job.run(bpy.context)
        if finished.status != "FINISHED":
            raise RuntimeError(finished.error)
    finally:
        two_way.TwoWay.chunk_paths = chunk_paths
    return settings.last_estimator, settings.last_paths, settings.last_rays, settings.last_seconds, settings.last_relative_error


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "loose_targets.md"))
    args = ap.parse_args(argv)
    from addon.cli import scenes

    scenes.ensure_registered()
    rows = []
    for name in SCENES:
        build(name)
        for target in TARGETS:
            for rule in ("plan", "balanced"):
                runs = [solve(target, seed, rule) for seed in SEEDS]
                print(name, target, rule, runs, flush=True)
                rows.append((name, target, rule, runs))
    lines = [__doc__.split("\n\n")[0].replace("\n", " "), "",
             f"`python -m benchmarks.loose_targets`: {len(SEEDS)} seeds a row (each seed's value, separated by /).", "",
             "| scene | target | chunks from | method | paths | rays | solver seconds | error reached |",
             "|---|---|---|---|---|---|---|---|"]
    for name, target, rule, runs in rows:
        join = lambda f, k: " / ".join(f.format(r[k]) for r in runs)  # noqa: E731
        lines.append(f"| {name} | {target:g}% | {rule} | {runs[0][0]} | {join('{:,}', 1)} | {join('{:,}', 2)} | "
                     f"{join('{:.1f}', 3)} | {join('{:.2f}%', 4)} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
