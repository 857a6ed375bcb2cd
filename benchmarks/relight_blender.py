"""Relighting through Blender: ``bpy.ops.radiosity.relight()`` against patch count and sources.

    .venv/bin/python -m benchmarks.relight_blender           # into benchmarks/results/relight_blender.md
    .venv/bin/python -m benchmarks.relight_blender --quick   # into out/

A result object of P quad patches (a grid: 4P polygon corners) holding per-source values for S
point lamps as a solve with per-light results leaves them (``blender_write.relight_store``), for
the outputs the textured colours write (the smooth radiosity and the smooth light arriving on
every corner, the flat radiosity on every corner) and for the flat colours alone. Stored values
are random (relighting's cost does not depend on them; no solve is run: the solve's cost is in
relight.md). Timed: the operator after one lamp's strength changed, the median of 7 calls with
the arrays in memory (what the live relight and the panel's button take: the changed source's
values alone are added), the same after every lamp changed (a full recombination), the first
call after the in-memory copy is dropped ("cold", a reopened file: the arrays read from the
attributes, a full recombination); and the live handler's relight (``relight.live_tick``, one
lamp turned), median of 7.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

TEXTURED = [("Radiosity", "smooth", "CORNER"), ("Radiosity Patches", "flat", "FACE_CORNERS"),
            ("Radiosity Light", "light", "CORNER")]
FLAT = [("Radiosity", "flat", "FACE_CORNERS")]


def grid(n):
    """A mesh of n x n quads (each a patch) as a result object; returns it."""
    import bpy

    from addon.blender_read.objects import SOURCE_PROPERTY
    from addon.blender_write.results import result_collection

    bpy.ops.wm.read_factory_settings(use_empty=True)
    xs = np.linspace(0, 1, n + 1, dtype=np.float32)
    x, y = np.meshgrid(xs, xs, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size, np.float32)], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    corners = np.stack([a, a + n + 1, a + n + 2, a + 1], axis=1).ravel().astype(np.int32)
    mesh = bpy.data.meshes.new("Grid Radiosity")
    mesh.vertices.add(len(points))
    mesh.vertices.foreach_set("co", points.ravel())
    mesh.loops.add(len(corners))
    mesh.loops.foreach_set("vertex_index", corners)
    mesh.polygons.add(n * n)
    mesh.polygons.foreach_set("loop_start", np.arange(0, len(corners), 4, dtype=np.int32))
    mesh.update()
    obj = bpy.data.objects.new("Grid Radiosity", mesh)
    obj[SOURCE_PROPERTY] = "Grid"
    result_collection(bpy.context.scene).objects.link(obj)
    return obj


def stored(obj, sources, targets, rng):
    """S lamps, and per-source values of the ``targets`` kept on ``obj`` as a solve keeps them."""
    import bpy

    from addon.blender_read import sources as reading
    from addon.blender_write import relight_store
    from addon.bpy_free.relit import SourceResults
    from addon.core.estimate.per_source import PerSource

    for s in range(sources):
        data = bpy.data.lights.new(f"Lamp {s}", "POINT")
        data.energy = 10.0
        lamp = bpy.data.objects.new(f"Lamp {s}", data)
        lamp.location = (rng.random(), rng.random(), 1.0)
        bpy.context.scene.collection.objects.link(lamp)
    bpy.context.view_layer.update()
    P, C = len(obj.data.polygons), len(obj.data.loops)
    names = tuple(f"Lamp {s}" for s in range(sources))
    empty = np.zeros((sources, 0, 3))
    ps = PerSource(names, empty, empty, np.ones((sources, 3)), np.zeros((3, sources, sources)), 1.0, None)
    members = [[("light", name, np.ones(3))] for name in names]
    values = {kind: rng.random((sources, C if domain == "CORNER" else P, 3), dtype=np.float32)
              for _, kind, domain in targets}
    results = SourceResults(ps, None, members, arrays=[values], targets=targets)
    snapshot = reading.snapshot(bpy.context.scene)
    for name, kind, domain in targets:
        if name not in obj.data.attributes:
            obj.data.color_attributes.new(name, "FLOAT_COLOR", "CORNER")
    relight_store.store(bpy.context.scene, [obj], results, snapshot, ([], [], reading.geometry_signature(
        bpy.context.scene, [])))


def timed(call, repeat):
    """(median wall seconds, median CPU seconds of this process) of ``repeat`` calls: on a shared
    machine the wall time holds other jobs' turns, the CPU time this work alone (the relight is
    one thread)."""
    wall, cpu = [], []
    for _ in range(repeat):
        started, started_cpu = time.perf_counter(), time.process_time()
        call()
        wall.append(time.perf_counter() - started)
        cpu.append(time.process_time() - started_cpu)
    return statistics.median(wall), statistics.median(cpu)


def measure(n, sources, targets, rng):
    import bpy

    from addon.blender_write import relight_store
    from addon.ui import relight

    obj = grid(n)
    stored(obj, sources, targets, rng)
    lamp = bpy.data.objects["Lamp 0"].data
    counter = iter(range(10**6))

    def turn():
        lamp.energy = 10.0 + next(counter) % 7
        assert bpy.ops.radiosity.relight() == {"FINISHED"}

    def turn_all():
        step = next(counter) % 7
        for s in range(sources):
            bpy.data.objects[f"Lamp {s}"].data.energy = 10.0 + step + 0.5 * s
        assert bpy.ops.radiosity.relight() == {"FINISHED"}

    relight_store.forget()
    cold = timed(turn, 1)
    warm = timed(turn, 7)
    every = timed(turn_all, 7)

    def live():
        lamp.energy = 10.0 + next(counter) % 7
        relight.live_tick()

    live_seconds = timed(live, 7)
    return len(obj.data.polygons), cold, warm, every, live_seconds


def solve_pair(side, rounds):
    """The textured solve through the operator with per-light results Off and On, alternately:
    a room of side x side patches a wall (patch size 1 / side) lit by a point lamp, an area lamp,
    the sun and the sky; (patches, [off seconds], [on seconds], the on run's stored MiB)."""
    import bpy

    from addon.blender_write import relight_store

    sys.path.insert(0, str(ROOT / "tests" / "blender"))
    from tests.blender.ui import relight_scene

    times = {"OFF": [], "ON": []}
    stored = 0.0
    for _ in range(rounds):
        for choice in ("OFF", "ON"):
            bpy.ops.wm.read_factory_settings(use_empty=True)
            settings = relight_scene.build(bpy.context, "TEXTURED")
            bpy.data.materials["Glow"].node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 0
            settings.patch_size, settings.per_source, settings.threads = 1.0 / side, choice, 2
            settings.target_error, settings.method = 5.0, "auto"
            started = time.perf_counter()
            assert bpy.ops.radiosity.solve() == {"FINISHED"}
            times[choice].append(time.perf_counter() - started)
            if choice == "ON":
                meta = relight_store.meta_of(bpy.context.scene)
                arrays = relight_store.load(bpy.context.scene, meta)[0].arrays
                stored = sum(a.nbytes for values in arrays.values() for a in values.values()) / 2**20
            patches = bpy.context.scene.radiosity.last_patches
    return patches, times["OFF"], times["ON"], stored


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    import addon

    addon.register()
    sides = (32, 100) if args.quick else (32, 100, 317)
    counts = (1, 4) if args.quick else (1, 4, 8, 16, 32)
    rng = np.random.default_rng(0)
    load = os.getloadavg()
    lines = ["# Relighting through Blender", "",
             "Made by `python -m benchmarks.relight_blender` (bpy 5.0.1 module, headless; the machine's 2 cores "
             "shared with other jobs). The operator `radiosity.relight` after one lamp's strength changed: "
             "median of 7 with the stored arrays in memory (the live relight and the button: the changed lamp's "
             "values added to the last recombination), the same after every lamp changed (a full recombination), "
             "the first call after the in-memory copy is dropped (cold: a reopened file, the arrays read from the "
             "attributes), and the live handler's relight.", "",
             "Each cell: wall ms (CPU ms of this process, what the work itself takes where other jobs share the "
             "cores).", "",
             "| patches | corners | sources | outputs | one lamp turned ms | every lamp turned ms | cold ms | live ms |",
             "|---|---|---|---|---|---|---|---|"]
    for side in sides:
        for sources in counts:
            for label, targets in (("textured (3 outputs)", TEXTURED), ("flat (1 output)", FLAT)):
                P, cold, warm, every, live = measure(side, sources, targets, rng)
                line = (f"| {P:,} | {4 * P:,} | {sources} | {label} | " + " | ".join(
                    f"{w * 1e3:.1f} ({c * 1e3:.1f})" for w, c in (warm, every, cold, live)) + " |")
                print(line, flush=True)
                lines.append(line)
    lines += ["", "## The solve through the operator, per-light results Off and On", "",
              "Textured colours, Method Automatic, 5% target, 2 threads, the two run alternately (3 rounds, "
              "median seconds): a room open to the sun and the sky with a point and an area lamp inside "
              "(tests/blender/ui/relight_scene.py, its emissive strip off: 4 sources). The time includes "
              "meshing, the solve, the smoothing (each source's, On) and writing; stored MiB: the per-source "
              "values the .blend and the relight's memory each keep.", "",
              "| patches | Off s | On s | ratio | stored MiB |", "|---|---|---|---|---|"]
    for side in ((8, 24) if args.quick else (8, 24, 48)):
        P, off, on, stored_mib = solve_pair(side, 1 if args.quick else 3)
        line = (f"| {P:,} | {statistics.median(off):.2f} | {statistics.median(on):.2f} | "
                f"{statistics.median(on) / statistics.median(off):.2f}x | {stored_mib:.1f} |")
        print(line, flush=True)
        lines.append(line)
    lines += ["", f"Load average (1 min) at the start {load[0]:.1f}, at the end {os.getloadavg()[0]:.1f}, on 2 cores."]
    target = (ROOT / "out" if args.quick else RESULTS) / "relight_blender.md"
    target.parent.mkdir(exist_ok=True)
    target.write_text("\n".join(lines) + "\n")
    print(f"written: {target}")


if __name__ == "__main__":
    main()
