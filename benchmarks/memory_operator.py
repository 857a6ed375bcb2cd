"""Peak memory of a solve of about a million patches through the operator (issue 26).

    .venv/bin/python -m benchmarks.memory_operator              # into benchmarks/results/memory_operator.md
    .venv/bin/python -m benchmarks.memory_operator --quick      # ~250k patches, into out/

The scene: a closed room of 4 x 3 x 2.5 m (six faces, inward, albedo 0.7) with a ceiling panel of
0.5 x 0.5 m emitting (5, 5, 5), meshed by the operator at a patch size that makes about a million
patches. Each measurement runs in a fresh process (its peak resident set is its own):

- ``operator``: ``bpy.ops.radiosity.solve()`` as a script runs it (background mode, synchronous),
  stopped by a time limit (the memory of a solve does not grow with its paths: benchmarks/memory.md);
- ``stages``: the same work called stage by stage (reading the selection, meshing, the core's
  scene, the solve, the colours, writing them), with the peak resident set after each, and a
  sampler of the current resident set every 10 ms, whose maximum within a stage is its own peak.

Issue 26's target: the peak under 1 GiB.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
MIB = 1 << 20
GIB = 1 << 30
ROOM = (4.0, 3.0, 2.5)


def peak_rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def current_rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class Sampler(threading.Thread):
    """The current resident set every 10 ms, its maximum per stage label."""

    def __init__(self):
        super().__init__(daemon=True)
        self.stage, self.peaks, self.stop = "start", {}, threading.Event()

    def run(self):
        while not self.stop.is_set():
            rss = current_rss()
            self.peaks[self.stage] = max(self.peaks.get(self.stage, 0), rss)
            time.sleep(0.01)

    def enter(self, stage):
        rss = current_rss()
        self.peaks[self.stage] = max(self.peaks.get(self.stage, 0), rss)
        self.stage = stage


def build_scene(patch_size):
    import bpy

    from tests.blender.conftest import box_arrays, make_object, principled

    bpy.ops.wm.read_factory_settings(use_empty=True)
    import addon

    addon.register()
    v, f = box_arrays((0, 0, 0), ROOM, inward=True)
    room = make_object("Room", v, f, [principled("wall", (0.7, 0.7, 0.7))])
    x, y, z = ROOM[0] / 2, ROOM[1] / 2, ROOM[2] - 1e-3
    panel = [(x - 0.25, y - 0.25, z), (x + 0.25, y - 0.25, z), (x + 0.25, y + 0.25, z), (x - 0.25, y + 0.25, z)]
    lamp = make_object("Panel", panel, [(3, 2, 1, 0)], [principled("light", (0, 0, 0), (1, 1, 1), 5.0)])
    for obj in (room, lamp):
        obj.select_set(True)
    bpy.context.view_layer.objects.active = room
    settings = bpy.context.scene.radiosity
    settings.patch_size = patch_size
    return settings


def child(mode, patch_size, seconds):
    sys.path.insert(0, str(ROOT))
    sampler = Sampler()
    sampler.start()
    out = {"mode": mode, "patch_size": patch_size}
    import bpy

    out["after_imports"] = peak_rss()
    sampler.enter("scene")
    settings = build_scene(patch_size)
    settings.time_limit = seconds
    settings.target_error = 0.05  # far below what the time allows: the time limit stops it
    out["after_scene"] = peak_rss()
    t = time.perf_counter()
    if mode == "operator":
        sampler.enter("operator")
        from addon import operators

        assert bpy.ops.radiosity.solve() == {"FINISHED"}, operators.LAST_ERROR
        out["after_operator"] = peak_rss()
    else:
        from addon import patches as patch_making
        from addon import pipeline, scene_io

        sampler.enter("read selection")
        objects, _ = scene_io.read_selection(bpy.context)
        out["after_read"] = peak_rss()
        sampler.enter("patches")
        # (the patch size as the property holds it, float32: the solve below then finds these
        # patches and their core scene in the geometry cache, as the operator's solve does)
        patches = patch_making.make_patches(objects, settings.solve_settings().patch_size)
        out["after_patches"] = peak_rss()
        sampler.enter("core scene")
        scene, _ = patch_making.scene_and_notes(patches)
        from addon.core.tables import WalkTables

        WalkTables(scene, "finite", 1e-3, "random").tracer  # the Embree scene (once per geometry)
        out["after_core_scene"] = peak_rss()
        out["patches_made"] = int(scene.patch_count)
        del scene, patches
        sampler.enter("solve")
        run = pipeline.run_solve(objects, settings.solve_settings())
        out["after_solve"] = peak_rss()
        out["paths"], out["rays"] = run.result.paths, run.result.rays
        sampler.enter("write")
        scene_io.write_results(bpy.context, run, settings.output)
        out["after_write"] = peak_rss()
    out["seconds"] = time.perf_counter() - t
    sampler.enter("end")
    sampler.stop.set()
    sampler.join()
    out["stage_peaks"] = sampler.peaks
    print(json.dumps(out))


def measure(mode, patch_size, seconds):
    cmd = [sys.executable, "-m", "benchmarks.memory_operator", "--child", mode, "--patch-size", str(patch_size),
           "--seconds", str(seconds)]
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(done.stdout[-3000:] + done.stderr[-3000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def patch_size_for(patches):
    """The patch edge that meshes the room into about ``patches`` square patches."""
    a, b, c = ROOM
    area = 2 * (a * b + a * c + b * c)
    return (area / patches) ** 0.5


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--patch-size", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--patches", type=int, default=1_000_000)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args(argv)
    if args.child:
        child(args.child, args.patch_size, args.seconds)
        return
    patches = 250_000 if args.quick else args.patches
    seconds = 10.0 if args.quick else args.seconds
    size = patch_size_for(patches)
    op = measure("operator", size, seconds)
    st = measure("stages", size, seconds)
    print(json.dumps(op), json.dumps(st), sep="\n")
    out = (ROOT / "out" if args.quick else RESULTS) / "memory_operator.md"
    out.parent.mkdir(exist_ok=True)
    L = [
        "# Peak memory of a solve through the operator (issue 26)",
        "",
        f"`python -m benchmarks.memory_operator{' --quick' if args.quick else ''}`: the room of the module's "
        f"docstring at patch size {size:.5f} m ({st['patches_made']:,} patches), stopped after "
        f"{seconds:.0f} s; each run in a fresh process. Target: peak under 1 GiB ({GIB // MIB} MiB).",
        "",
        f"**Operator** (`bpy.ops.radiosity.solve()`): peak resident set {op['after_operator'] / MIB:.0f} MiB "
        f"({'under' if op['after_operator'] < GIB else 'OVER'} 1 GiB; {op['after_scene'] / MIB:.0f} MiB before it: "
        f"bpy and the scene).",
        "",
        "**Stage by stage** (the same work called in turn): peak resident set after each stage, and the "
        "highest resident set sampled during it.",
        "",
        "| stage | peak after MiB | highest during MiB |",
        "|---|---:|---:|",
    ]
    for key, stage in (("after_imports", "start"), ("after_scene", "scene"), ("after_read", "read selection"),
                       ("after_patches", "patches"), ("after_core_scene", "core scene"), ("after_solve", "solve"),
                       ("after_write", "write")):
        L.append(f"| {stage} | {st[key] / MIB:.0f} | {st['stage_peaks'].get(stage, 0) / MIB:.0f} |")
    L += ["", f"The solve traced {st['rays']:,} rays ({st['paths']:,} paths)."]
    out.write_text("\n".join(L) + "\n")
    (out.with_suffix(".json")).write_text(json.dumps({"operator": op, "stages": st}, indent=1))
    print("\n".join(L))


if __name__ == "__main__":
    main()
