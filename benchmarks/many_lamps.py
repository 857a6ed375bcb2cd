"""Many lamps and a time limit: the display's corner pass, the whole run under a limit, and the
estimate against the real time.

    python -m benchmarks.many_lamps                  # -> benchmarks/results/many_lamps.{md,json}
    python -m benchmarks.many_lamps --interior       # the three rooms of benchmarks.interior_scene at
                                                     # ~11,000 patches through the operator (bpy)

The room of tests/core/many_lamps.py (6 x 5 x 3 m, three boxes of furniture) lit by 1, 10, 100 and
500 lamps (a quarter each point, sphere, spot and area lamps, 2,000 units of power in all), at
the automatic patch size (1,768 patches), the panel's defaults, 2 threads. Per lamp count: the
corner pass alone (``point_direct.corner_direct`` on the scene's triangles: seconds and shadow
rays a corner); a run with a 2 s time limit (``pipeline.run_solve``: wall time, paths); the
estimate (``pipeline.estimate``) against a run's wall time, with the limit and without it at a
20% error target (a short solve: the colours most of the run). Run in a checkout of an earlier
commit (``--tag before``) for the "before" rows: it uses nothing that commit lacks.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "core"))
RESULTS = ROOT / "benchmarks" / "results"
COUNTS = (1, 10, 100, 500)


def corner_pass(count):
    """(seconds, rays a corner) of the corner pass in the room of ``count`` lamps."""
    import numpy as np
    from many_lamps import room_scene

    from addon.core.display import point_direct, smoothing
    from addon.core.methods.tables import WalkTables

    scene = room_scene(count, patch_size=0.0)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    rays, traced = [], WalkTables.outside_turn
    WalkTables.outside_turn = lambda tables, trace, origins, *rest: rays.append(len(origins)) or traced(
        tables, trace, origins, *rest)
    try:
        started = time.perf_counter()
        point_direct.corner_direct(surface, scene, scene.triangles, seed=0)
        seconds = time.perf_counter() - started
    finally:
        WalkTables.outside_turn = traced
    corners = len(np.unique(surface.point.ravel().astype(np.int64) * scene.patch_count + np.repeat(surface.triangle_patch, 3)))
    return seconds, sum(rays) / corners


def run(count, **settings):
    """(estimate seconds, wall seconds, paths, solve seconds) of the room of ``count`` lamps."""
    from many_lamps import room_objects

    from addon.bpy_free import pipeline

    objects, chosen = room_objects(count), pipeline.SolveSettings(threads=2, **settings)
    estimate = pipeline.estimate(objects, chosen)["seconds"]
    started = time.perf_counter()
    out = pipeline.run_solve(objects, chosen)
    return estimate, time.perf_counter() - started, int(out.result.paths), float(out.result.seconds)


INTERIORS = (("window_room", 0.16), ("lamp_room", 0.17), ("loft", 0.2))  # (about 11,000 patches each)


def interior(name, patch_size):
    """An interior of benchmarks.interior_scene through the operator: (patches, operator
    seconds, corner pass seconds, solve seconds)."""
    import bpy

    from benchmarks import interior_scene
    from benchmarks.picture import source_objects
    from addon.core.display import point_direct

    import addon

    addon.register()
    interior_scene.build(name)
    source_objects()
    settings = bpy.context.scene.radiosity
    settings.patch_size, settings.threads = patch_size, 2
    spent, direct = [], point_direct.corner_direct

    def timed(*args, **kwargs):
        started = time.perf_counter()
        try:
            return direct(*args, **kwargs)
        finally:
            spent.append(time.perf_counter() - started)

    point_direct.corner_direct = timed
    started = time.perf_counter()
    assert bpy.ops.radiosity.solve() == {"FINISHED"}
    seconds = time.perf_counter() - started
    point_direct.corner_direct = direct
    return settings.last_patches, seconds, sum(spent), None


def main(argv=None):
    parser = argparse.ArgumentParser()
    parser.add_argument("--tag", default="after")
    parser.add_argument("--interior", action="store_true")
    args = parser.parse_args(argv)
    rows = []
    if args.interior:
        for name, size in INTERIORS:
            patches, seconds, corners, _ = interior(name, size)
            rows.append({"case": name, "patches": patches, "operator": seconds, "corner_pass": corners})
            print(args.tag, rows[-1], flush=True)
    else:
        for count in COUNTS:
            seconds, rays = corner_pass(count)
            limited = run(count, max_seconds=2.0)
            loose = run(count, relative_rms=0.2)
            rows.append({"lamps": count, "corner_pass": seconds, "rays_a_corner": rays, "limit_2s_wall": limited[1],
                         "limit_2s_paths": limited[2], "limit_2s_estimate": limited[0], "loose_estimate": loose[0],
                         "loose_wall": loose[1], "loose_solve": loose[3]})
            print(args.tag, rows[-1], flush=True)
    RESULTS.mkdir(parents=True, exist_ok=True)
    name = f"many_lamps_{'interior_' if args.interior else ''}{args.tag}.json"
    (RESULTS / name).write_text(json.dumps(rows, indent=1))
    print(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
