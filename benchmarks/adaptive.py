"""Adaptive patches (the Detail setting) against uniform ones: the preview's image error against the
picture benchmark's Cycles reference (``picture.py``: same rooms, same preview, same metric), at
several error targets, so that error can be read against wall time; and uniform patches at the
adaptive run's patch count.

    nice -n 10 .venv/bin/python -m benchmarks.adaptive --scenes window_room --targets --time-limits 3 6 12

Per room, in one process: the cached reference, then for each error target (or time limit: the
solve stopped at that time, its paths kept) rounds of the configurations one after
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
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from benchmarks import interior_scene, picture  # noqa: E402
from benchmarks import picture_metrics as pm  # noqa: E402


# The refinement steps of the last run (solve_refinement.refined's, recorded by :func:`run`).
LAST_STEPS = []


def detail_and_rounds(spec):
    """("MEDIUM", None) of "MEDIUM" (the product's refining solves), ("MEDIUM", 0) of "MEDIUM/0"
    (the direct light's refinement alone)."""
    name, _, rounds = spec.partition("/")
    return name, (int(rounds) if rounds else None)


def label_of(spec):
    from addon.bpy_free.solve_refinement import ROUNDS

    name, rounds = detail_and_rounds(spec)
    rounds = ROUNDS if rounds is None else rounds
    return f"adaptive {name.lower()}" + (f" (+{rounds} refining solve{'s' if rounds > 1 else ''})" if rounds else
                                         " (direct light only)")


def run(detail, target, patch_size=0.0, seed=0, colours="TEXTURED", limit=0.0):
    """The product with these settings (the picture benchmark's otherwise: picture.product), then
    its preview: (image, solve seconds, preview seconds, patches, patch size). ``detail`` "MEDIUM/0":
    Medium without the refining solves."""
    from addon.bpy_free import solve_refinement

    name, rounds = detail_and_rounds(detail)
    original, kept = solve_refinement.refined, solve_refinement.ROUNDS

    def recording(*args, **kwargs):
        patches, settings = original(*args, **kwargs)
        LAST_STEPS[:] = [dict(s) for s in patches.refinement]
        return patches, settings

    LAST_STEPS.clear()
    solve_refinement.refined = recording
    solve_refinement.ROUNDS = kept if rounds is None else rounds
    try:
        image, solve, shown, stats = picture.product(colours, seed, target_error=target, detail=name,
                                                     patch_size=patch_size, time_limit=limit)
    finally:
        solve_refinement.refined, solve_refinement.ROUNDS = original, kept
    return image, solve, shown, int(stats["patches"]), float(stats["patch_size"])


def budget_text(target, limit):
    return f"{limit:g} s" if limit else f"{target:g}%"


def measure(name, budgets, details, reference_samples, scales=(), rounds=1, log=print):
    """One room: per target, rounds of every configuration one after another (alternating);
    rows of the errors (each round's) and wall times (each round's), the images of round 0."""
    from addon.blender_write.results import previous_results

    info = interior_scene.build(name)
    first, second, _ = picture.reference(name, reference_samples, log)
    ref = 0.5 * (first + second)
    rows, images, mask = [], {}, None
    log(f"{name}: warming up (a solve of each kind, not counted)")
    for detail in ["OFF"] + list(details):
        run(detail, max(t for t, _ in budgets), seed=99, limit=min(l for _, l in budgets))
    steps = refinement_steps(details)
    for target, limit in budgets:
        budget = budget_text(target, limit)
        configs = [("uniform", "OFF", 0.0)] + [(label_of(d), d, 0.0) for d in details]
        configs += [(f"uniform {scale:g}x size", "OFF", scale) for scale in scales]
        found = {}
        for k in range(rounds):
            for label, detail, scale in list(configs):
                size = scale * found["uniform"]["patch_size"] if scale else 0.0
                try:
                    image, solve, shown, patches, used = run(detail, target, patch_size=size, seed=k, limit=limit)
                except RuntimeError as exc:  # (a time limit below the first batch: no result, said in the log)
                    log(f"{name} {budget} round {k} {label}: {exc}")
                    continue
                if mask is None:
                    px = picture.pixel_map(info, previous_results())
                    emitters = [info.meshes.index(n) for n in info.emitters]
                    mask = pm.surface_mask(px["object_id"], emitters, px["lamp"])
                row = found.setdefault(label, {"config": label, "target": target, "limit": limit, "budget": budget,
                                               "patches": patches, "patch_size": used, "steps": [],
                                               "errors": [], "seconds": [], "solve": [], "preview": []})
                row.setdefault("steps", []).append([dict(st) for st in LAST_STEPS])
                row["errors"].append(pm.relative_mae(image, ref, mask))
                row["seconds"].append(solve + shown)
                row["solve"].append(solve)
                row["preview"].append(shown)
                if k == 0:
                    images[(label, budget)] = image
                log(f"{name} {budget} round {k} {label}: {patches:,} patches, {solve:.1f} + {shown:.1f} s, "
                    f"error {row['errors'][-1]:.4f}")
            if k == 0:  # then uniform at each adaptive run's patch count, in every later round too
                base = found["uniform"]
                added = [(f"uniform at {label_of(d)}'s count", "OFF",
                          math.sqrt(base["patches"] / found[label_of(d)]["patches"]))
                         for d in details if label_of(d) in found]
                configs += added
                for label, detail, scale in added:
                    try:
                        image, solve, shown, patches, used = run(detail, target, limit=limit,
                                                               patch_size=scale * found["uniform"]["patch_size"])
                    except RuntimeError as exc:
                        log(f"{name} {budget} round 0 {label}: {exc}")
                        continue
                    found[label] = {"config": label, "target": target, "limit": limit, "budget": budget,
                                    "patches": patches, "patch_size": used,
                                    "errors": [pm.relative_mae(image, ref, mask)], "seconds": [solve + shown],
                                    "solve": [solve], "preview": [shown]}
                    images[(label, budget)] = image
                    log(f"{name} {budget} round 0 {label}: {patches:,} patches, {solve:.1f} + {shown:.1f} s, "
                        f"error {found[label]['errors'][-1]:.4f}")
        for row in found.values():
            row["error"] = float(np.mean(row["errors"]))
            row["time"] = float(np.median(row["seconds"]))
            rows.append(row)
    return {"rows": rows, "images": images, "ref": ref, "mask": mask, "first": first, "second": second, "steps": steps}


def refinement_steps(details, seed=0):
    """Per detail, the refinement's steps on the selection (patches and seconds of each), timed
    alone: the pipeline's patches, then core.adaptive.refine_by_direct_light."""
    import bpy

    from addon.blender_read.selection import read_selection
    from addon.bpy_free.patches import make_patches
    from addon.core.refine.adaptive_light import DETAILS, refine_by_direct_light

    objects, _ = read_selection(bpy.context)
    patches = make_patches(objects, 0.0)
    scene = patches.patch_scene()
    out = {"first": patches.combined.patch_count}
    for d in dict.fromkeys(detail_and_rounds(spec)[0] for spec in details):
        result = refine_by_direct_light(patches.meshes, scene, DETAILS[d], seed, receives=[o.receives for o in patches.objects])
        out[d] = result.steps
    return out


def plot(rooms, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(rooms), figsize=(6 * len(rooms), 4.5), squeeze=False)
    for ax, (name, m) in zip(axes[0], rooms.items()):
        configs = sorted({r["config"] for r in m["rows"]}, key=lambda c: (not c.startswith("uniform"), c))
        for c in configs:
            rs = sorted((r for r in m["rows"] if r["config"] == c), key=lambda r: r["time"])
            style = "s--" if c.startswith("uniform") else "o-"
            ax.plot([r["time"] for r in rs], [100 * r["error"] for r in rs], style, label=c)
            for r in rs:
                ax.annotate(r["budget"], (r["time"], 100 * r["error"]), fontsize=7)
        ax.set_xscale("log")
        ax.set_xlabel("wall time, solve + preview (s, median of the rounds)")
        ax.set_ylabel("preview's mean abs. luminance error vs Cycles (%)")
        ax.set_title(name)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def side_by_side(m, labels, budget, path):
    from PIL import Image, ImageDraw, ImageFont

    ref, mask = m["ref"], m["mask"]
    exposure = pm.exposure_for(ref, mask)
    images = [ref] + [m["images"][(label, budget)] for label in labels]
    names = ["reference (Cycles)"] + [f"{label}, {budget}" for label in labels]
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
        lines += [f"## {name}", "", "| configuration | error target or time limit | patches | patch size | wall s (median; rounds) | "
                  "error (mean; rounds) |", "|---|---|---|---|---|---|"]
        for r in sorted(m["rows"], key=lambda r: (r["limit"], -r["target"], r["time"])):
            lines.append(f"| {r['config']} | {r['budget']} | {r['patches']:,} | {r['patch_size']:.3g} | "
                         f"{r['time']:.1f} ({', '.join(f'{x:.1f}' for x in r['seconds'])}) | {100 * r['error']:.2f}% "
                         f"({', '.join(f'{100 * x:.2f}' for x in r['errors'])}) |")
        steps = m.get("steps") or {}
        if steps:
            lines += ["", f"Refinement steps, timed alone (first patches {steps['first']:,}):", "",
                      "| detail | step | candidates | split | patches after | seconds |", "|---|---|---|---|---|---|"]
            for d, taken in steps.items():
                if d == "first":
                    continue
                for st in taken:
                    lines.append(f"| {d.lower()} | {st['level'] + 1} | {st['candidates']:,} | {st['split']:,} | "
                                 f"{st['patches']:,} | {st['seconds']:.2f} |")
        runs = [r for r in m["rows"] if any(r.get("steps") or [])]
        if runs:
            lines += ["", "Refinement steps in the runs (round 0; a refining solve's seconds include its solve):", "",
                      "| configuration | budget | step | kind | split | patches after | seconds | refining solve: paths, s |",
                      "|---|---|---|---|---|---|---|---|"]
            for r in runs:
                for k, st in enumerate(r["steps"][0]):
                    kind = "solve" if st.get("solve") else "direct light"
                    solved = f"{st['paths']:,}, {st['solve_seconds']:.2f}" if st.get("solve") else "-"
                    lines.append(f"| {r['config']} | {r['budget']} | {k + 1} | {kind} | {st['split']:,} | "
                                 f"{st['patches']:,} | {st['seconds']:.2f} | {solved} |")
        lines.append("")
    out.write_text("\n".join(lines))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["window_room"], choices=list(interior_scene.SCENES))
    parser.add_argument("--targets", nargs="*", type=float, default=[4.0, 2.0])
    parser.add_argument("--time-limits", nargs="*", type=float, default=[],
                        help="also runs stopped at these solve times (Time limit), with a 0.5%% target none reaches")
    parser.add_argument("--details", nargs="+", default=["MEDIUM"])
    parser.add_argument("--uniform-scales", nargs="*", type=float, default=[0.7, 0.5],
                        help="uniform patches also at these fractions of the automatic size (the time axis)")
    parser.add_argument("--reference-samples", type=int, default=256)
    parser.add_argument("--rounds", type=int, default=2, help="rounds of every configuration (seeds 0, 1, ...)")
    parser.add_argument("--out", type=Path, default=RESULTS / "adaptive.md")
    args = parser.parse_args(argv)
    command = "python -m benchmarks.adaptive " + " ".join(argv if argv is not None else sys.argv[1:])
    loads = [os.getloadavg()[0]]
    rooms = {}
    for name in args.scenes:
        budgets = [(t, 0.0) for t in args.targets] + [(0.5, limit) for limit in args.time_limits]
        rooms[name] = measure(name, budgets, args.details, args.reference_samples, args.uniform_scales, args.rounds)
        middle = budget_text(*budgets[len(budgets) // 2])
        labels = [label for label in ["uniform"] + [label_of(d) for d in args.details]
                  if (label, middle) in rooms[name]["images"]]
        side_by_side(rooms[name], labels, middle, args.out.parent / f"{args.out.stem}_{name}.png")
        saved = {n: {"rows": m["rows"], "steps": m["steps"]} for n, m in rooms.items()}
        (args.out.parent / f"{args.out.stem}.json").write_text(json.dumps({"command": command, **saved}, indent=1))
        plot(rooms, args.out.parent / f"{args.out.stem}_error_time.png")
        report(rooms, command.strip(), [loads[0], os.getloadavg()[0]], args.out)
    print(args.out.read_text())


if __name__ == "__main__":
    main()
