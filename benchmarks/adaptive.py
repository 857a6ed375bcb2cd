"""Adaptive patches (the Detail setting) against uniform ones: the preview's image error against the
picture benchmark's Cycles reference (``picture.py``: same rooms, same preview, same metric), at
several error targets, so that error can be read against wall time; and uniform patches at the
adaptive run's patch count.

    nice -n 10 .venv/bin/python -m benchmarks.adaptive --scenes window_room --targets 4 2 1

Per room, in one process: the cached reference, then for each target the configurations one after
another (alternating, so a busy moment of the machine hits every side): uniform (Detail off, the
automatic patch size), adaptive (each detail asked), and uniform at the patch size that gives the
adaptive run's count. Results: benchmarks/results/adaptive.md, .json, an error-against-time PNG and
side-by-side images (reference | uniform | adaptive, with their error maps).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from benchmarks import interior_scene, picture  # noqa: E402
from benchmarks import picture_metrics as pm  # noqa: E402


def run(detail, target, patch_size=0.0, seed=0, colours="TEXTURED"):
    """The product with these settings (the panel's defaults otherwise), then its preview:
    (image, solve seconds, preview seconds, patches)."""
    import bpy

    from addon.bpy_free import options
    from addon.cli import preview
    from addon.cli.run import release_solve_memory
    from addon.ui import operators

    scene = bpy.context.scene
    sources = picture.source_objects()
    settings = scene.radiosity
    for option in options.SETTINGS:
        setattr(settings, option.name, option.default)
    settings.target_error, settings.output, settings.seed = target, colours, seed
    settings.detail, settings.patch_size = detail, patch_size
    operators.LAST_ERROR = ""
    wall = time.perf_counter()
    result = bpy.ops.radiosity.solve(quiet_errors=True)
    release_solve_memory()
    solve = time.perf_counter() - wall
    if "FINISHED" not in result:
        raise RuntimeError(f"the solve failed: {operators.LAST_ERROR}")
    picture.show_results(True)
    changes = preview.preview_settings(scene, sources, interior_scene.RESOLUTION[0], picture.PREVIEW_SAMPLES, 0.0)
    hidden = [(o, o.hide_render) for o in sources]
    try:
        for o, _ in hidden:
            o.hide_render = True
        scene.render.threads_mode, scene.render.threads = "FIXED", picture.THREADS
        image, shown = picture.render_exr(scene)
    finally:
        for o, h in hidden:
            o.hide_render = h
        changes.restore()
    return image, solve, shown, int(settings.last_patches), float(settings.last_patch_size)


def measure(name, targets, details, reference_samples, scales=(), log=print):
    from addon.blender_write.results import previous_results

    info = interior_scene.build(name)
    first, second, _ = picture.reference(name, reference_samples, log)
    ref = 0.5 * (first + second)
    rows, images, mask = [], {}, None
    log(f"{name}: warming up (a solve of each kind, not counted)")
    for detail in ["OFF"] + list(details):
        run(detail, max(targets), seed=99)
    for target in targets:
        configs = [("uniform", "OFF", 0.0)] + [(f"adaptive {d.lower()}", d, 0.0) for d in details]
        configs += [(f"uniform {scale:g}x size", "OFF", scale) for scale in scales]
        done = {}
        for label, detail, scale in configs:
            size = scale * done["uniform"][1] if scale else 0.0
            image, solve, shown, patches, used = run(detail, target, patch_size=size)
            if mask is None:
                px = picture.pixel_map(info, previous_results())
                emitters = [info.meshes.index(n) for n in info.emitters]
                mask = pm.surface_mask(px["object_id"], emitters, px["lamp"])
            done[label] = (patches, used)
            rows.append({"config": label, "target": target, "patches": patches, "patch_size": used,
                         "solve": solve, "preview": shown, "seconds": solve + shown,
                         "error": pm.relative_mae(image, ref, mask)})
            images[(label, target)] = image
            log(f"{name} {target}% {label}: {patches:,} patches, {solve:.1f} + {shown:.1f} s, error {rows[-1]['error']:.4f}")
        for d in details:  # uniform at the adaptive run's patch count
            label = f"adaptive {d.lower()}"
            base_count, base_size = done["uniform"]
            size = base_size * math.sqrt(base_count / done[label][0])
            image, solve, shown, patches, used = run("OFF", target, patch_size=size)
            rows.append({"config": f"uniform at {label}'s count", "target": target, "patches": patches, "patch_size": used,
                         "solve": solve, "preview": shown, "seconds": solve + shown,
                         "error": pm.relative_mae(image, ref, mask)})
            images[(rows[-1]["config"], target)] = image
            log(f"{name} {target}% {rows[-1]['config']}: {patches:,} patches, {solve:.1f} + {shown:.1f} s, "
                f"error {rows[-1]['error']:.4f}")
    return {"rows": rows, "images": images, "ref": ref, "mask": mask, "first": first, "second": second}


def plot(rooms, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(rooms), figsize=(6 * len(rooms), 4.5), squeeze=False)
    for ax, (name, m) in zip(axes[0], rooms.items()):
        configs = sorted({r["config"] for r in m["rows"]}, key=lambda c: (not c.startswith("uniform"), c))
        for c in configs:
            rs = sorted((r for r in m["rows"] if r["config"] == c), key=lambda r: r["seconds"])
            ax.plot([r["seconds"] for r in rs], [100 * r["error"] for r in rs], "o-", label=c)
            for r in rs:
                ax.annotate(f"{r['target']:g}%", (r["seconds"], 100 * r["error"]), fontsize=7)
        ax.set_xscale("log")
        ax.set_xlabel("wall time, solve + preview (s)")
        ax.set_ylabel("preview's mean abs. luminance error vs Cycles (%)")
        ax.set_title(name)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def side_by_side(m, labels, target, path):
    from PIL import Image, ImageDraw, ImageFont

    ref, mask = m["ref"], m["mask"]
    exposure = pm.exposure_for(ref, mask)
    images = [ref] + [m["images"][(label, target)] for label in labels]
    names = ["reference (Cycles)"] + [f"{label}, {target:g}% target" for label in labels]
    height, width = ref.shape[:2]
    band = 14
    canvas = Image.new("RGB", (len(images) * width, 2 * (height + band)), (255, 255, 255))
    draw = ImageDraw.Draw(canvas)
    font = ImageFont.load_default(size=11)
    noise = ref + 0.5 * (m["first"] - m["second"])
    for column, (image, name) in enumerate(zip(images, names)):
        canvas.paste(Image.fromarray(pm.to_display(image, exposure)), (column * width, band))
        lower = pm.error_display(noise if column == 0 else image, ref, mask)
        canvas.paste(Image.fromarray(lower), (column * width, 2 * band + height))
        draw.text((column * width + 4, 1), name, fill=(0, 0, 0), font=font)
        draw.text((column * width + 4, height + band + 1), "|error| (white: 50% of mean)" if column else
                  "reference's own error", fill=(0, 0, 0), font=font)
    canvas.save(path)


def report(rooms, command, loads, out):
    lines = [f"# Adaptive patches (Detail) against uniform patches", "",
             f"`{command}`; machine load {loads[0]:.1f} -> {loads[1]:.1f} (2 cores shared with other jobs). "
             "Error: the preview's relative mean absolute luminance error on surface pixels against the picture "
             "benchmark's 256-sample Cycles reference (picture.py's metric); time: the operator's wall time (meshing, "
             "refinement, solve, colours, writing) plus the preview render. Textured output, hit exit, the panel's "
             "defaults otherwise.", ""]
    for name, m in rooms.items():
        lines += [f"## {name}", "", "| configuration | target | patches | patch size | solve s | preview s | error |",
                  "|---|---|---|---|---|---|---|"]
        for r in m["rows"]:
            lines.append(f"| {r['config']} | {r['target']:g}% | {r['patches']:,} | {r['patch_size']:.3g} | "
                         f"{r['solve']:.1f} | {r['preview']:.1f} | {100 * r['error']:.2f}% |")
        lines.append("")
    out.write_text("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["window_room"], choices=list(interior_scene.SCENES))
    parser.add_argument("--targets", nargs="+", type=float, default=[4.0, 2.0, 1.0])
    parser.add_argument("--details", nargs="+", default=["MEDIUM"])
    parser.add_argument("--uniform-scales", nargs="*", type=float, default=[0.7, 0.5],
                        help="uniform patches also at these fractions of the automatic size (the time axis)")
    parser.add_argument("--reference-samples", type=int, default=256)
    parser.add_argument("--out", type=Path, default=RESULTS / "adaptive.md")
    args = parser.parse_args(argv)
    command = "python -m benchmarks.adaptive " + " ".join(argv if argv is not None else sys.argv[1:])
    loads = [os.getloadavg()[0]]
    rooms = {}
    for name in args.scenes:
        rooms[name] = measure(name, args.targets, args.details, args.reference_samples, args.uniform_scales)
        middle = sorted(args.targets)[len(args.targets) // 2]
        labels = ["uniform"] + [f"adaptive {d.lower()}" for d in args.details]
        side_by_side(rooms[name], labels, middle, args.out.parent / f"{args.out.stem}_{name}.png")
        saved = {n: m["rows"] for n, m in rooms.items()}
        (args.out.parent / f"{args.out.stem}.json").write_text(json.dumps({"command": command, **saved}, indent=1))
        plot(rooms, args.out.parent / f"{args.out.stem}_error_time.png")
        report(rooms, command.strip(), [loads[0], os.getloadavg()[0]], args.out)
    print(args.out.read_text())


if __name__ == "__main__":
    main()
