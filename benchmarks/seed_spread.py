"""How far each object's light moves from seed to seed, against what the error estimate says:
the picture benchmark's window room (``interior_scene.py``), solved by the paper's walk and the
two-way iteration at the panel's defaults and a 2% target, several seeds each.

    python benchmarks/seed_spread.py                   # every source
    python benchmarks/seed_spread.py --only Sun        # the sun alone (lamps removed, no sky)

Per object, the area-weighted mean of the light arriving ('Radiosity Light', flat) over its
faces inside the room (facing its middle), over the walk's mean over the seeds: each seed's, and
half the range. Each run's own error estimate (the scene-wide relative RMS) and solve seconds.
Appends a section to benchmarks/results/seed_spread.md.
"""
import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from benchmarks import interior_scene, picture as pic  # noqa: E402


def inside_light(info):
    """{object: (3,) its inside faces' area-weighted mean light}."""
    from addon.blender_write.results import previous_results

    lo, hi = np.array(info.room[0]) - 0.01, np.array(info.room[1]) + 0.01
    out = {}
    for obj in previous_results(__import__("bpy").context.scene):
        mesh, n = obj.data, len(obj.data.polygons)
        read = lambda name, width, dtype=np.float32: _read(mesh.polygons, name, n * width, dtype).reshape(n, -1)  # noqa: E731
        area, centre, normal = read("area", 1)[:, 0], read("center", 3), read("normal", 3)
        area = area * (((centre > lo) & (centre < hi)).all(1) & ((normal * ((lo + hi) / 2 - centre)).sum(1) > 0))
        attr = mesh.attributes["Radiosity Light"]
        light = _read(attr.data, "color", len(attr.data) * 4).reshape(-1, 4)[:, :3]
        if len(light) != n:  # (at the corners: each its polygon's share)
            loops = read("loop_total", 1, np.int32)[:, 0]
            area = np.repeat(area / loops, loops)
        out[obj["radiosity_source"]] = (light * area[:, None]).sum(0) / area.sum()
    return out


def _read(collection, name, size, dtype=np.float32):
    values = np.empty(size, dtype)
    collection.foreach_get(name, values)
    return values


def main():
    import bpy

    from addon.blender_write import solve_job

    ap = argparse.ArgumentParser()
    ap.add_argument("--only", default="", help="keep this lamp alone (no sky, no other lamp)")
    ap.add_argument("--seeds", type=int, default=4)
    ap.add_argument("--methods", default="walk,two_way")
    args = ap.parse_args()
    info = interior_scene.build("window_room")
    scene = bpy.context.scene
    if args.only:
        for name in [n for n in info.lamps if n != args.only]:
            bpy.data.objects.remove(bpy.data.objects[name])
        scene.world = None
    runs = {}
    for method in args.methods.split(","):
        for seed in range(args.seeds):
            pic.source_objects()
            settings = pic.prepare_product(scene, "FACE", seed)
            settings.method, settings.light_output = method, True
            assert solve_job.run(bpy.context).status == "FINISHED"
            runs[method, seed] = (inside_light(info), settings.last_relative_error, settings.last_seconds)
            print(method, seed, settings.last_estimator, settings.last_relative_error, settings.last_seconds, flush=True)
    methods = args.methods.split(",")
    unit = {name: np.mean([runs[methods[0], s][0][name] for s in range(args.seeds)], axis=0).mean()
            for name in runs[methods[0], 0][0]}
    lines = [f"## {'every source' if not args.only else args.only + ' alone'}", "",
             f"`python benchmarks/seed_spread.py{' --only ' + args.only if args.only else ''}`; light (channels' mean) "
             f"over the {methods[0]}'s mean over seeds 0-{args.seeds - 1}: each seed's, and half the range.", "",
             "| object | " + " | ".join(f"{m} (seeds), ± half range" for m in methods) + " |",
             "|---|" + "---|" * len(methods)]
    for name in sorted(unit):
        cells = []
        for m in methods:
            values = np.array([runs[m, s][0][name].mean() / unit[name] for s in range(args.seeds)])
            cells.append(" ".join(f"{v:.3f}" for v in values) + f", ±{np.ptp(values) / 2:.3f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines += ["", "| method | error estimate (each seed) | solve seconds (each seed) |", "|---|---|---|"]
    for m in methods:
        lines.append(f"| {m} | " + ", ".join(f"{runs[m, s][1]:.2f}%" for s in range(args.seeds)) + " | "
                     + ", ".join(f"{runs[m, s][2]:.1f}" for s in range(args.seeds)) + " |")
    out = ROOT / "benchmarks" / "results" / "seed_spread.md"
    head = "" if out.exists() else ("# The window room's light per object from seed to seed\n\n"
                                    + __doc__.split("\n\n")[0].replace("\n", " ") + "\n\n")
    with out.open("a") as f:
        f.write(head + "\n".join(lines) + "\n\n")


if __name__ == "__main__":
    main()
