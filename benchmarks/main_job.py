"""The main job (``python -m addon --scene cornell``, the README's first command): its time by stage,
and its preview against a high-sample Cycles render of the original scene.

    .venv/bin/python -m benchmarks.main_job --runs 2                 # stages of two runs + the pictures -> results/main_job.md
    .venv/bin/python -m benchmarks.main_job --runs 1 --no-pictures   # the stages alone (printed)

Stages: one run of the main job in a child process, each step timed by wall and by the process's CPU
seconds (every thread): on a shared 2-core machine the wall time follows the load, the CPU time much
less (the load average is noted). Pictures: the main job's solve saved without a preview, then each
preview variant (``addon/cli/preview.py``'s settings, changed as named) rendered to a float EXR at the
main job's 480 x 480 and compared on surface pixels (the light panel and the background excluded,
``picture_metrics``) with a Cycles render of the original scene (64 bounces, no clamping, two halves of
``--reference-samples`` with different seeds: the RMS error is given with the reference's own variance
taken out, the mean absolute error as it is).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
WIDTH = 480  # the command line's --resolution default; the box's camera frame is square

#: preview variants: label -> (samples, {"cycles.NAME": value}); "before" is the preview as it was
VARIANTS = {
    "before: 64 samples, adaptive sampling": (64, {"cycles.use_adaptive_sampling": True}),
    "now: 16 samples, no adaptive sampling": (16, {}),
    "16 samples, adaptive sampling": (16, {"cycles.use_adaptive_sampling": True}),
    "32 samples, no adaptive sampling": (32, {}),
    "8 samples, no adaptive sampling": (8, {}),
}


def cpu_seconds():
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


# --------------------------------------------------------------------------- stages

def _timed(owner, name, label):
    """Replace ``owner.name`` by a wrapper printing its wall and CPU seconds as a STAGE line."""
    original = getattr(owner, name)

    def wrapper(*args, **kwargs):
        wall, cpu = time.perf_counter(), cpu_seconds()
        try:
            return original(*args, **kwargs)
        finally:
            print(f"STAGE {json.dumps([label, time.perf_counter() - wall, cpu_seconds() - cpu])}", flush=True)

    setattr(owner, name, wrapper)


def child(argv):
    """The main job in this process, its steps timed (the run's own functions wrapped)."""
    start, cpu = time.perf_counter(), cpu_seconds()
    import bpy  # noqa: F401 - timed on its own

    print(f"STAGE {json.dumps(['import bpy', time.perf_counter() - start, cpu_seconds() - cpu])}", flush=True)
    from addon.blender_write import solve_job
    from addon.cli import preview, run

    _timed(run, "_open_scene", "build the scene")
    _timed(run, "_warn_before", "estimate before the run")
    _timed(solve_job, "run", "solve and write the results")
    _timed(preview, "render_preview", "preview: settings, render, PNG")
    _timed(run, "save_blend", "save the .blend")
    _timed(run.Outputs, "check", "check the files written")
    status = run.main(argv)
    print(f"STAGE {json.dumps(['the whole run', time.perf_counter() - start, cpu_seconds() - cpu])}", flush=True)
    return status


def stages(folder, code=ROOT):
    """One main job in a child process, the extension's code from the checkout ``code``:
    ([(stage, wall s, CPU s)], load averages before and after, summary line)."""
    load = os.getloadavg()[0]
    command = [sys.executable, str(Path(__file__).resolve()), "--child", "--scene", "cornell", "-q",
               "-o", str(Path(folder) / "cornell.blend")]
    done = subprocess.run(command, cwd=folder, env={**os.environ, "PYTHONPATH": str(ROOT), "MAIN_JOB_CODE": str(code)},
                          capture_output=True, text=True, check=True)
    rows = [json.loads(line[6:]) for line in done.stdout.splitlines() if line.startswith("STAGE ")]
    summary = next((line for line in done.stdout.splitlines() if line.startswith("cornell:")), "")
    return rows, (load, os.getloadavg()[0]), summary


# --------------------------------------------------------------------------- pictures

def solved_box(folder):
    """The main job's solve saved without a preview: the .blend's path."""
    blend = Path(folder) / "solved.blend"
    subprocess.run([sys.executable, "-m", "addon", "--scene", "cornell", "--no-preview", "-q", "-o", str(blend)],
                   cwd=folder, env={**os.environ, "PYTHONPATH": str(ROOT)}, capture_output=True, check=True)
    return blend


def surface(scene, sources):
    """(H, W) surface pixels of the main job's camera: a source seen, not the light panel, one pixel in."""
    from benchmarks import picture as P
    from benchmarks import picture_metrics as pm

    corners, owner, _ = P.mesh_triangles(sources)
    origins, directions = P.camera_rays(scene.camera, WIDTH, WIDTH)
    hit, _ = P.first_hits(corners, origins, directions)
    ids = np.where(hit >= 0, owner[np.maximum(hit, 0)], -1).reshape(WIDTH, WIDTH)
    emitters = [k for k, o in enumerate(sources) if o.name.endswith(" light")]
    return pm.surface_mask(ids, emitters, margin=1)


def preview_image(scene, sources, samples, overrides):
    """The preview as the command line sets it up (``overrides`` on top), to a float EXR:
    (image, wall s, CPU s)."""
    from addon.blender_write.results import previous_results
    from addon.cli import preview
    from benchmarks import picture as P

    for obj in previous_results(scene):
        obj.hide_render = False
    changes = preview.preview_settings(scene, sources, WIDTH, samples, 0.0)
    hidden = [(o, o.hide_render) for o in sources]
    try:
        for o, _ in hidden:
            o.hide_render = True
        for key, value in overrides.items():
            owner, name = key.split(".")
            changes.set({"cycles": scene.cycles, "render": scene.render}[owner], name, value)
        cpu = cpu_seconds()
        image, wall = P.render_exr(scene)
        return image, wall, cpu_seconds() - cpu
    finally:
        for o, h in hidden:
            o.hide_render = h
        changes.restore()


def pictures(blend, reference_samples, variants, log=print):
    """Each variant's errors against the reference: {label: {...}}, and the reference's own."""
    import bpy

    from addon.blender_read.objects import is_result_object
    from addon.cli import scenes
    from benchmarks import picture as P
    from benchmarks import picture_metrics as pm

    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scenes.ensure_registered()
    scene = bpy.context.scene
    sources = [o for o in scene.objects if o.type == "MESH" and not is_result_object(o)]
    scene.render.resolution_x = scene.render.resolution_y = WIDTH
    scene.render.resolution_percentage = 100
    first, second, seconds = P.reference("main_job_cornell", reference_samples, log=log)
    reference = 0.5 * (first + second)
    mask = surface(scene, sources)
    variance = pm.reference_variance(first, second)
    own = {"mae": pm.halves_error(first, second, mask), "seconds": seconds,
           "rms": float(np.sqrt(variance[mask].mean()) / pm.luminance(reference)[mask].mean())}
    out, images = {}, {}
    for label, (samples, overrides) in variants.items():
        image, wall, cpu = preview_image(scene, sources, samples, overrides)
        images[label] = image
        out[label] = {"samples": samples, "mae": pm.relative_mae(image, reference, mask),
                      "rms": pm.relative_rms(image, reference, mask, variance), "wall": wall, "cpu": cpu,
                      "brightness": float(pm.luminance(image)[mask].mean() / pm.luminance(reference)[mask].mean())}
        log(f"{label}: {json.dumps(out[label])}")
    first_label = next(iter(variants))
    for label in variants:  # how far each is from the first (the preview as it was)
        out[label]["from_first"] = pm.relative_mae(images[label], images[first_label], mask)
    return out, own


# --------------------------------------------------------------------------- report

def stage_table(runs):
    names = list(dict.fromkeys(row[0] for _, rows, _, _ in runs for row in rows))
    lines = ["| stage | " + " | ".join(f"{label}: wall / CPU s" for label, _, _, _ in runs) + " |",
             "|---|" + "---|" * len(runs)]
    for name in names:
        cells = []
        for _, rows, _, _ in runs:
            hits = [r for r in rows if r[0] == name]
            cells.append(f"{sum(r[1] for r in hits):.1f} / {sum(r[2] for r in hits):.1f}" if hits else "-")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    lines.append("| load average (1 min) before / after | "
                 + " | ".join(f"{a:.1f} / {b:.1f}" for _, _, (a, b), _ in runs) + " |")
    return lines


def report(runs, picture, own, reference_samples, command):
    lines = ["# The main job: its time by stage and its picture", "", f"`{command}` (`benchmarks/main_job.py`).", "",
             "## Time by stage", "",
             "`python -m addon --scene cornell` in a child process, each step's wall and CPU seconds (every thread). "
             "The render is part of the preview's row; the solve's row includes writing the results.", ""]
    lines += stage_table(runs)
    for label, _, _, summary in runs[-2:]:
        lines += ["", f"{label}, the run's summary: `{summary}`"]
    if picture:
        lines += ["", "## The picture", "",
                  f"Against Cycles on the original scene at {WIDTH} x {WIDTH}, {reference_samples} samples in two halves "
                  f"(seeds 101, 202), 64 bounces, no clamping ({own['seconds'] / 60:.0f} min); its own error from "
                  f"its halves: {100 * own['mae']:.1f}% mean absolute, {100 * own['rms']:.1f}% RMS. Luminance over "
                  "the surface pixels, relative to the reference's mean there. Render seconds in this process "
                  "(after the first render: no kernel loading).", "",
                  "| preview | mean abs. error | RMS error, the reference's noise out | brightness / reference | "
                  "mean abs. difference from the first row | render wall / CPU s |", "|---|---|---|---|---|---|"]
        for label, m in picture.items():
            lines.append(f"| {label} | {100 * m['mae']:.2f}% | {100 * m['rms']:.2f}% | {m['brightness']:.4f} | "
                         f"{100 * m['from_first']:.2f}% | {m['wall']:.1f} / {m['cpu']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["--child"]:
        sys.path.insert(0, os.environ.get("MAIN_JOB_CODE", str(ROOT)))  # (the checkout whose main job is timed)
        return child(argv[1:])
    parser = argparse.ArgumentParser(prog="python -m benchmarks.main_job")
    parser.add_argument("--runs", type=int, default=2, help="timed runs of the main job")
    parser.add_argument("--before", metavar="DIR", help="a checkout of earlier code: its main job timed too, "
                        "run by run alternating with this one")
    parser.add_argument("--no-pictures", action="store_true")
    parser.add_argument("--reference-samples", type=int, default=256)
    parser.add_argument("--out", default=str(RESULTS / "main_job.md"))
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="main_job_") as folder:
        runs = []
        for k in range(args.runs):
            for label, code in ([("before", Path(args.before).resolve())] if args.before else []) + [("now", ROOT)]:
                runs.append((f"{label}, run {k + 1}", *stages(folder, code)))
                for name, wall, cpu in runs[-1][1]:
                    print(f"{runs[-1][0]}: {name}: {wall:.1f} s wall, {cpu:.1f} s CPU", flush=True)
        picture, own = (None, None) if args.no_pictures else pictures(solved_box(folder), args.reference_samples,
                                                                     VARIANTS)
    if not args.no_pictures:
        text = report(runs, picture, own, args.reference_samples, "python -m benchmarks.main_job " + " ".join(argv))
        Path(args.out).write_text(text)
        print(f"-> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
