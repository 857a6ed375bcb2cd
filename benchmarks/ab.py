"""This tree's solve() against another commit's, in one process, on the same rays.

    python -m benchmarks.ab --base 4187daa [--scene small_room room_fig4] [--threads 1 2] [--rounds 9] [--methods]

The base commit's ``addon/core`` is unpacked (``git archive``) as the package ``addon_base.core``
beside this tree's ``addon.core``. Each case solves the same scene with the same seed in both,
alternating which goes first, so that both trace the same rays where the walk is meant to be the
same (the radiosity is checked bit for bit) and both meet the same load on this shared machine.
Reported: process CPU time and wall time per ray, medians over the rounds, and the ratio
new / base with its range over the rounds (a ratio below 1: this tree is faster). With
``--methods``, the gathered walk, Jacobi iteration and the two-way iteration (finite, random and
hit exit) are compared too.
"""
from __future__ import annotations

import argparse
import importlib
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.throughput import build_scene

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
# (estimator, exit point): the walks of the throughput benchmark.
WALKS = (("finite", "random"), ("finite", "hit"), ("biased_infinite", "random"), ("biased_infinite", "hit"))
PATHS = {"small_room": 400_000, "cornell": 400_000, "room_fig4": 400_000, "room_fig4_sphere": 300_000}
# (label, solve arguments, share of PATHS): the methods beyond the paper's walk (--methods).
METHODS = (("gathered walk", {"direct_light": "gathered"}, 1 / 2), ("Jacobi", {"method": "jacobi"}, 1 / 2),
           ("two-way", {"method": "two_way"}, 1 / 4))


def base_core(rev, into):
    """``addon_base.core``: the core of commit ``rev``, unpacked under ``into``."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", rev, "addon/core"], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(into)], input=archive, check=True)
    package = Path(into) / "addon_base"
    (Path(into) / "addon").rename(package)
    (package / "__init__.py").write_text("")
    sys.path.insert(0, str(into))
    return importlib.import_module("addon_base.core")


def same_scene(core, scene):
    """``scene`` built again with ``core``'s PatchScene (the same arrays)."""
    return core.PatchScene(scene.vertices, scene.triangles, scene.triangle_patch, scene.reflectivity, scene.emission)


def timed(core, scene, estimator, exit_point, threads, paths, seed, **arguments):
    cpu, wall = time.process_time(), time.perf_counter()
    r = core.solve(scene, estimator=estimator, paths=paths, threads=threads, seed=seed, exit_point=exit_point, **arguments)
    return time.process_time() - cpu, time.perf_counter() - wall, r


def compare(new, base, scene_name, threads, rounds, methods=False):
    scene_new = build_scene(scene_name)
    scene_base = same_scene(base, scene_new)
    rows = []
    cases = [(f"{e} / {x}", e, x, {}, PATHS[scene_name] // (4 if e != "finite" else 1)) for e, x in WALKS]
    if methods:
        cases += [(f"{label} / {x}", "finite", x, arguments, int(PATHS[scene_name] * share))
                  for label, arguments, share in METHODS for x in ("random", "hit")]
    for label, estimator, exit_point, arguments, paths in cases:
        for core, scene in ((new, scene_new), (base, scene_base)):  # warm up: tables, grids, Embree scene
            core.solve(scene, estimator=estimator, paths=paths // 10, threads=threads, exit_point=exit_point, **arguments)
        ratios_cpu, ratios_wall, times = [], [], {"new": [], "base": []}
        for k in range(rounds):
            order = (("new", new, scene_new), ("base", base, scene_base))
            order = order if k % 2 == 0 else order[::-1]
            out = {name: timed(core, scene, estimator, exit_point, threads, paths, k, **arguments)
                   for name, core, scene in order}
            if not np.array_equal(out["new"][2].radiosity, out["base"][2].radiosity):
                raise SystemExit(f"{scene_name} {label}: the two cores' results differ")
            rays = out["new"][2].rays
            for name in out:
                times[name].append((out[name][0] / rays, out[name][1] / rays))
            ratios_cpu.append(out["new"][0] / out["base"][0])
            ratios_wall.append(out["new"][1] / out["base"][1])
        med = {name: np.median(np.array(v), axis=0) * 1e9 for name, v in times.items()}
        rows.append((scene_name, threads, label, med["base"], med["new"],
                     np.median(ratios_cpu), min(ratios_cpu), max(ratios_cpu), np.median(ratios_wall)))
        print(f"{scene_name} {threads}t {label}: cpu ratio {np.median(ratios_cpu):.3f} "
              f"[{min(ratios_cpu):.3f}, {max(ratios_cpu):.3f}] wall {np.median(ratios_wall):.3f}", flush=True)
    return rows


def write(rows, base_rev, out):
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    lines = [
        f"# A/B: this tree ({head}) against {base_rev}, same rays",
        "",
        "Both cores solve the same scene with the same seed, alternating which goes first; results",
        "are checked bit for bit. Times are per ray (process CPU time, all threads; wall time), medians",
        "over the rounds; ratio = new / base (below 1: faster now), with its range over the rounds.",
        "",
        "| scene | threads | walk | base CPU ns/ray | new CPU ns/ray | CPU ratio | range | wall ratio |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for scene, threads, walk, base, new, ratio, lo, hi, wall in rows:
        lines.append(f"| {scene} | {threads} | {walk} | {base[0]:.1f} | {new[0]:.1f} | {ratio:.3f} | {lo:.3f}-{hi:.3f} | {wall:.3f} |")
    Path(out).write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="the commit to compare with")
    ap.add_argument("--scene", nargs="+", default=["small_room", "room_fig4"])
    ap.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--out", default=str(RESULTS / "ab.md"))
    ap.add_argument("--methods", action="store_true", help="also the gathered walk, Jacobi and the two-way iteration")
    args = ap.parse_args(argv)
    import addon.core as new

    with tempfile.TemporaryDirectory() as tmp:
        base = base_core(args.base, tmp)
        rows = [row for scene in args.scene for threads in args.threads
                for row in compare(new, base, scene, threads, args.rounds, args.methods)]
    write(rows, args.base, args.out)


if __name__ == "__main__":
    main()
