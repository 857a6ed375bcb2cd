"""Every way the core carries the light, on the suite's scenes, in the core alone.

    python -m benchmarks.methods            # into benchmarks/results/methods.md
    python -m benchmarks.methods --quick    # fewer paths, into out/

For each scene of ``benchmarks.suite`` that has no lamps (the core builds it from the suite's
own arrays, no Blender) and each method: the per-patch relative RMS error (lit patches, the
suite's measure) and the RMS over patches / mean radiosity, from the solve's batch means, and
what reaching 1% would take at the measured error: rays (error^2 x rays, the noise per ray
traced) and seconds (error^2 x seconds, 2 threads). The paper's walk is the unit: a gain is
its rays (seconds) to 1% over the method's. Each solve is run twice with different seeds
(medians of the two). Exit point hit throughout (the suite's: results as continuous as Cycles').
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from addon.core import PatchScene, solve  # noqa: E402
from benchmarks import suite  # noqa: E402

SCENES = ("empty_room", "cornell", "fig4_room")
METHODS = {
    "paper walk": {},
    "walk, gathered first bounce": {"direct_light": "gathered"},
    "shooting Jacobi": {"method": "jacobi"},
    "shooting Jacobi, gathered first bounce": {"method": "jacobi", "direct_light": "gathered"},
    "two-way iteration": {"method": "two_way"},
}


def core_scene(spec):
    """The suite scene's quads as a PatchScene (two triangles a quad)."""
    P = len(spec.corners)
    base = 4 * np.arange(P)[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return PatchScene(spec.corners.reshape(-1, 3), triangles, np.repeat(np.arange(P), 2), spec.reflectivity, spec.emission)


def errors(result, measured):
    v = result.reflected_variance.mean(axis=1)[measured]
    m = result.radiosity.mean(axis=1)[measured]
    lit = m > suite.LIT * m.max()
    return math.sqrt(np.mean(v[lit] / m[lit] ** 2)), math.sqrt(v.mean()) / m.mean()


def measure(name, paths):
    spec = suite.SCENES[name]()
    scene = core_scene(spec)
    measured = ~(spec.emission > 0).any(axis=1)
    paths = round(paths * spec.paths_scale)
    rows = []
    for label, kw in METHODS.items():
        solve(scene, paths=max(paths // 32, 4096), threads=2, exit_point="hit", **kw)  # (tables, caches, Halton)
        runs = []
        for seed in (1, 2):
            r = solve(scene, paths=paths, seed=seed, threads=2, exit_point="hit", **kw)
            per_patch, over_mean = errors(r, measured)
            runs.append((per_patch, over_mean, r.rays, r.seconds))
        per_patch, over_mean, rays, seconds = np.median(np.array(runs), axis=0)
        rows.append({"method": label, "paths": paths, "rays": rays, "seconds": seconds, "per_patch": per_patch,
                     "over_mean": over_mean, "rays_to_1": rays * (per_patch / 0.01) ** 2,
                     "seconds_to_1": seconds * (per_patch / 0.01) ** 2,
                     "seconds_to_1_mean": seconds * (over_mean / 0.01) ** 2})
        print(f"{name} {label}: {rows[-1]['rays_to_1'] / 1e6:.1f} M rays, {rows[-1]['seconds_to_1']:.2f} s to 1% per patch",
              flush=True)
    return {"scene": name, "patches": scene.patch_count, "rows": rows}


def report(results, command, out):
    lines = ["# Every method of the core on the suite's scenes", "", f"`{command}`", "",
             __doc__.split("\n\n", 1)[1].strip(), ""]
    for res in results:
        base = res["rows"][0]
        lines += [f"## {res['scene']} ({res['patches']:,} patches, {base['paths']:,} paths a run)", "",
                  "| method | rays a path | per-patch error | RMS / mean | M rays to 1% | gain in rays | s to 1% | gain in s | s to 1% (RMS / mean) |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in res["rows"]:
            lines.append(f"| {r['method']} | {r['rays'] / r['paths']:.2f} | {r['per_patch']:.4f} | {r['over_mean']:.4f} | "
                         f"{r['rays_to_1'] / 1e6:.1f} | {base['rays_to_1'] / r['rays_to_1']:.2f} | {r['seconds_to_1']:.2f} | "
                         f"{base['seconds_to_1'] / r['seconds_to_1']:.2f} | {r['seconds_to_1_mean']:.2f} |")
        lines.append("")
    out.write_text("\n".join(lines) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    args = p.parse_args(argv)
    paths = 100_000 if args.quick else 2_000_000
    started = time.perf_counter()
    results = [measure(name, paths) for name in args.scenes]
    out = (ROOT / "out" if args.quick else RESULTS) / "methods.md"
    out.parent.mkdir(exist_ok=True)
    report(results, "python -m benchmarks.methods" + (" --quick" if args.quick else ""), out)
    print(f"wrote {out} ({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
