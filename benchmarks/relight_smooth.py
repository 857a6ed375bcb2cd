"""What each source's smooth colours cost against the solve's own (relighting.smooth_sources).

    .venv/bin/python -m benchmarks.relight_smooth           # into benchmarks/results/relight_smooth.md
    .venv/bin/python -m benchmarks.relight_smooth --quick   # into out/

The closed Cornell box lit by its ceiling and S - 1 small point lamps under it, solved with
per-source results (the walk, 300,000 paths, 2 threads). For each size and source count, the
smooth colours the pipeline makes for the solve (the light arriving and the radiosity, each noise
filtered and smooth: ``smooth_colours.smooth_corners``) and every source's (``smooth_sources``, the
whole's filter weights, clips and corner scales held fixed), one after the other, alternately
first, twice: wall seconds (the sum of both rounds over 2), and the largest difference of the
sources' sum from the whole over the whole's largest value. Peak memory (tracemalloc) of each in
a run of its own. The surface (``smoothing.Surface.of``) is built once for both and not timed.
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


def scene_of(divisions, sources):
    import sample_scenes
    from addon.core.lights.lights import PointLight

    base = sample_scenes.build("cornell_box", divisions=divisions, closed=True).scene
    lo, hi = base.vertices.min(axis=0), base.vertices.max(axis=0)
    centre, size = (lo + hi) / 2, hi - lo
    grid = [(x, y) for x in np.linspace(-0.35, 0.35, 4) for y in np.linspace(-0.35, 0.35, 4)][:sources - 1]
    lamps = [PointLight(centre + size * [x, y, 0.0], np.full(3, 0.05) * float(size.max()) ** 2, name=f"lamp {k}")
             for k, (x, y) in enumerate(grid)]
    return base.with_materials(base.reflectivity, base.emission, lamps)


def made(kind, surface, scene, result):
    from addon.bpy_free import smooth_colours
    from addon.core.relight.relighting import smooth_sources

    if kind == "whole":
        return dict(smooth_colours.smooth_corners(scene, result, light=True))
    return dict(smooth_sources(surface, scene, result, light=True))


def peak(kind, surface, scene, result):
    gc.collect()
    tracemalloc.start()
    made(kind, surface, scene, result)
    top = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return top / 2**20


def row(divisions, sources):
    from addon.core.display import smoothing
    from addon.core import solve

    scene = scene_of(divisions, sources)
    result = solve(scene, paths=300_000, seed=0, threads=2, per_source=True)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    seconds = {"whole": 0.0, "sources": 0.0}
    for round_ in range(2):
        for kind in ("whole", "sources") if round_ == 0 else ("sources", "whole"):
            start = time.perf_counter()
            out = made(kind, surface, scene, result)
            seconds[kind] += (time.perf_counter() - start) / 2
            if kind == "whole":
                whole = out
            else:
                parts = out
    error = max(float(np.abs(parts[k].sum(axis=0) - whole[k]).max() / np.abs(whole[k]).max()) for k in whole)
    memory = {kind: peak(kind, surface, scene, result) for kind in ("whole", "sources")}
    return (f"| {scene.patch_count:,} | {result.per_source.count} | {seconds['whole']:.2f} | {seconds['sources']:.2f} | "
            f"{seconds['sources'] / seconds['whole']:.1f}x | {error:.1e} | {memory['whole']:.0f} | {memory['sources']:.0f} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    cases = [(10, 4)] if args.quick else [(40, 4), (40, 8), (40, 16), (110, 4), (110, 8)]
    out = ROOT / "out" / "relight_smooth.md" if args.quick else RESULTS / "relight_smooth.md"
    lines = ["| patches | sources | whole s | every source's s | ratio | sum - whole (of the largest) | "
             "peak MiB whole | peak MiB every source's |", "|---|---|---|---|---|---|---|---|"]
    for divisions, sources in cases:
        lines.append(row(divisions, sources))
        print(lines[-1], flush=True)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(["# Every source's smooth colours", "",
                              "Made by `python -m benchmarks.relight_smooth` (the machine's 2 cores shared with other "
                              "jobs: seconds are noisy; the two sides run alternately).", "", *lines, ""]))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
