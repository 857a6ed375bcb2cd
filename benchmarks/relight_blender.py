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

    from addon.blender_write.results import SOURCE_PROPERTY, result_collection

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
    from addon.core.relighting import PerSource

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
    times = []
    for _ in range(repeat):
        started = time.perf_counter()
        call()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


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


def main(argv=None):
    p = argparse.ArgumentParser()
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    import addon

    addon.register()
    sides = (32, 100) if args.quick else (32, 100, 317)
    counts = (1, 4) if args.quick else (1, 4, 8, 16, 32)
    rng = np.random.default_rng(0)
    lines = ["# Relighting through Blender", "",
             "Made by `python -m benchmarks.relight_blender` (bpy 5.0.1 module, headless; the machine's 2 cores "
             "shared with other jobs). The operator `radiosity.relight` after one lamp's strength changed: "
             "median of 7 with the stored arrays in memory (warm: the live relight and the button), the first "
             "call after the in-memory copy is dropped (cold: a reopened file), and the live handler's relight.",
             "", "| patches | corners | sources | outputs | one lamp turned ms | every lamp turned ms | cold ms | live ms |",
             "|---|---|---|---|---|---|---|---|"]
    for side in sides:
        for sources in counts:
            for label, targets in (("textured (3 outputs)", TEXTURED), ("flat (1 output)", FLAT)):
                P, cold, warm, every, live = measure(side, sources, targets, rng)
                line = (f"| {P:,} | {4 * P:,} | {sources} | {label} | {warm * 1e3:.1f} | {every * 1e3:.1f} | "
                        f"{cold * 1e3:.1f} | {live * 1e3:.1f} |")
                print(line, flush=True)
                lines.append(line)
    target = (ROOT / "out" if args.quick else RESULTS) / "relight_blender.md"
    target.parent.mkdir(exist_ok=True)
    target.write_text("\n".join(lines) + "\n")
    print(f"written: {target}")


if __name__ == "__main__":
    main()
