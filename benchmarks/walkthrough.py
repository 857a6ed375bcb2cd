"""The walkthrough: one solve, then ten views of an interior in every display the product offers,
each against a Cycles reference of that view.

    nice -n 10 .venv/bin/python -m benchmarks.walkthrough                       # the two new interiors -> results/walkthrough*.md
    nice -n 10 .venv/bin/python -m benchmarks.walkthrough --interior loft       # any of interior_scene's rooms too
    .venv/bin/python -m benchmarks.walkthrough --quick                          # smoke run into out/walkthrough_quick/

Per interior, in one process: (1) each view's reference (Cycles, 64 bounces, no clamping, two
independent halves of ``--reference-samples``, cached in out/picture_cache/ by the scene's
content); (2) the product: the panel's operator at its defaults (5% target, Live lamps), timed
(its wall time is "the solve's time"), then every view shown from the same results in (a) EEVEE
(Material Preview's engine; the scene's lamps and world), (b) the baked display: the result
materials' view-independent part (the stored light times the surface, as emission: what they show
with no lamps), (c) the 'Radiosity' attribute alone as emission (Solid view, exporters), (d) the
product's own Cycles preview (``addon/cli/preview.py``); (b) and (c) are Cycles renders without
bounces at ``BAKED_SAMPLES`` (anti-aliasing alone). Then (e) the same baked display of a second
run with Live lamps off (``--no-unlive``: not made). (3) Cycles on the original scene with
OpenImageDenoise, the ten views sharing the solve's time (samples from a timing line, then tracked
view by view). Numbers and the contact sheet: ``walkthrough_measures``, ``walkthrough_report``.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
QUICK = ROOT / "out" / "walkthrough_quick"

from benchmarks import picture as pic  # noqa: E402
from benchmarks import picture_metrics as pm  # noqa: E402
from benchmarks import walkthrough_displays as shown  # noqa: E402
from benchmarks import walkthrough_measures as wm  # noqa: E402
from benchmarks import walkthrough_report as report  # noqa: E402
from benchmarks import walkthrough_scenes as scenes  # noqa: E402

SIZE = (240, 180)  # pixels of every view (the references' time goes with it)
DEFAULT_INTERIORS = ("skylight_hall", "studio_flat")


# --------------------------------------------------------------------------- views and what they see

def set_view(walk, view):
    """The scene's camera moved to ``view``, at SIZE."""
    import bpy
    from mathutils import Vector

    scene = bpy.context.scene
    camera = bpy.data.objects[walk.info.camera]
    camera.location = view.location
    camera.rotation_euler = (Vector(view.target) - Vector(view.location)).to_track_quat("-Z", "Y").to_euler()
    camera.data.lens = view.lens
    scene.camera = camera
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()


def view_pixels(walk, triangles):
    """(object id (H, W): index into info.meshes, -1 background; lamp in front (H, W)) at the
    pixel centres of the current view (``picture``'s ray casts)."""
    import bpy

    corners, owner = triangles
    width, height = SIZE
    origins, directions = pic.camera_rays(bpy.data.objects[walk.info.camera], width, height)
    hit, t = pic.first_hits(corners, origins, directions)
    object_id = np.where(hit >= 0, owner[np.maximum(hit, 0)], -1).reshape(height, width)
    lamps = [bpy.data.objects[n] for n in walk.info.lamps]
    lamp = (pic.lamp_distances(lamps, origins, directions) < t).reshape(height, width)
    return object_id, lamp


def references(walk, samples, log=print):
    """Each view's reference halves, seconds and pixel map: a list of dicts."""
    import bpy

    triangles = pic.mesh_triangles([bpy.data.objects[n] for n in walk.info.meshes])[:2]
    out = []
    for k, view in enumerate(walk.views):
        set_view(walk, view)
        name = f"walk_{walk.info.name}_{k}_{SIZE[0]}x{SIZE[1]}"
        first, second, seconds = pic.reference(name, samples, log)
        object_id, lamp = view_pixels(walk, triangles)
        out.append({"first": first, "second": second, "seconds": seconds, "object_id": object_id, "lamp": lamp})
        log(f"{walk.info.name}: view {k + 1} reference ready ({seconds:.0f} s)")
    return out


# --------------------------------------------------------------------------- the product

def solve(seed=0, before_writing=None, **overrides):
    """The panel's operator at its defaults (the error target ``pic.TARGET_ERROR``, textured output,
    Live lamps) as the command line runs it, over every source mesh: (wall seconds, statistics);
    ``before_writing(output)`` is given the solve's output (``solve_job.run``'s)."""
    import bpy

    from addon.blender_write import solve_job
    from addon.bpy_free import options
    from addon.cli.run import release_solve_memory

    scene = bpy.context.scene
    pic.source_objects()
    settings = pic.prepare_product(scene, options.OUTPUT.default, seed)
    for name, value in overrides.items():
        setattr(settings, name, value)
    noise = {}

    def kept(output):
        noise.update(solve_noise(output))
        if before_writing is not None:
            before_writing(output)

    wall = time.perf_counter()
    finished = solve_job.run(bpy.context, before_writing=kept)  # what the operator runs
    release_solve_memory()
    wall = time.perf_counter() - wall
    if finished.status != "FINISHED":
        raise RuntimeError(f"the solve failed: {finished.error or finished.messages}")
    return wall, {"patches": settings.last_patches, "patch_size": settings.last_patch_size,
                  "error": settings.last_relative_error, "method": settings.last_estimator,
                  "solver_seconds": settings.last_seconds, "live_lamps": bool(settings.live_lamps), "object_noise": noise}


def solve_noise(output):
    """Each receiving object's own noise in a solve's output (``walkthrough_measures.object_noise``)."""
    patches, result = output.patches, output.result
    objects = []
    for k, o in enumerate(patches.objects):
        if o.receives:
            rows = patches.combined.patch_slice(k)
            objects.append((o.name, patches.meshes[k].patch_area, result.radiosity[rows], result.reflected_variance[rows]))
    return wm.object_noise(objects)


# --------------------------------------------------------------------------- one interior

#: The pictures of the results, by kind: what makes each of the current view.
SHOWN = {"eevee": shown.eevee_image, "baked": lambda: shown.emission_image(shown.baked_material),
         "attribute": lambda: shown.emission_image(shown.attribute_material), "preview": lambda: shown.preview_image(SIZE[0])}


def cycles_views(walk, budget, log=print, most=1 << 16):
    """Cycles on the original scene with OpenImageDenoise (the reference's light paths), the views
    sharing ``budget`` seconds: a list of (image, seconds, samples) per view."""
    set_view(walk, walk.views[0])
    pic.cycles_image(1)  # (the first render loads the kernels)
    walls = [pic.cycles_image(n, True, 7)[1] for n in (1, 4)]
    line = (walls[0], max((walls[1] - walls[0]) / 3, 1e-3))
    log(f"{walk.info.name}: Cycles denoised, 1 sample {walls[0]:.2f} s, 4 samples {walls[1]:.2f} s; "
        f"{budget:.1f} s for {len(walk.views)} views")
    out, spent, last = [], 0.0, None
    for k, view in enumerate(walk.views):
        samples = wm.next_samples(budget, spent, len(walk.views) - k, line, last, most)
        set_view(walk, view)
        image, wall = pic.cycles_image(samples, True, k)
        out.append((image, wall, samples))
        spent, last = spent + wall, (samples, wall)
    return out


def shown_views(walk, kinds, log=print):
    """Each kind's picture of each view, from the results in the scene now: kind -> [(image, seconds)]."""
    out = {kind: [] for kind in kinds}
    for k, view in enumerate(walk.views):
        set_view(walk, view)
        for kind in kinds:
            out[kind].append(SHOWN[kind]())
        log(f"{walk.info.name}: view {k + 1}: " + ", ".join(f"{kind} {out[kind][-1][1]:.1f} s" for kind in kinds))
    return out


def measure(name, reference_samples, views, eevee=True, unlive=True, warm_up=True, seed=0, log=print, overrides=None,
            diffuse=False):
    """One interior: references, the product's solve and its pictures of every view, Cycles at the
    solve's time; a dict of images per kind and view, times and statistics. ``overrides``: panel
    settings of the product's solves, as NAME=VALUE; ``diffuse``: every material Lambertian
    (``interior_scene.make_diffuse``: what the specular layer accounts for)."""
    walk = scenes.build(name, views)
    if diffuse:
        from benchmarks import interior_scene

        interior_scene.make_diffuse()
    overrides = settings_of(overrides or [])
    clock = time.perf_counter()
    refs = references(walk, reference_samples, log)
    timing = {"references": time.perf_counter() - clock}
    if warm_up:
        log(f"{name}: warming up (a solve not counted)")
        solve(seed=99, **overrides)
    solve_seconds, stats = solve(seed=seed, **overrides)
    log(f"{name}: the solve took {solve_seconds:.1f} s ({stats['patches']:,} patches, {stats['method']})")
    kinds = [k for k in SHOWN if eevee or k != "eevee"]
    clock = time.perf_counter()
    images = shown_views(walk, kinds, log)
    timing["shown"] = time.perf_counter() - clock
    clock = time.perf_counter()
    cycles = cycles_views(walk, solve_seconds, log)
    timing["cycles"] = time.perf_counter() - clock
    images["cycles"] = [(image, wall) for image, wall, _ in cycles]
    unlive_stats = None
    if unlive:
        _, unlive_stats = solve(seed=seed, **{**overrides, "live_lamps": False})
        images["baked_unlive"] = [(set_view(walk, v), SHOWN["baked"]())[1] for v in walk.views]
    return {"walk": walk, "refs": refs, "images": images, "solve": solve_seconds, "stats": stats,
            "unlive_stats": unlive_stats, "samples": [s for _, _, s in cycles], "timing": timing}


def analyse(m, masks=None):
    """The numbers of one interior (``measure``'s dict; its surface ``masks`` if known), JSON-ready."""
    walk, refs = m["walk"], m["refs"]
    names = walk.info.meshes
    emitters = [names.index(n) for n in walk.info.emitters]
    masks = masks or [pm.surface_mask(r["object_id"], emitters, r["lamp"]) for r in refs]
    kinds = {}
    for kind, shots in m["images"].items():
        sums = [wm.view_sums(image, r["first"], r["second"], r["object_id"], mask, len(names))
                for (image, _), r, mask in zip(shots, refs, masks)]
        kinds[kind] = {**wm.walk_numbers(sums, names), "seconds": [wall for _, wall in shots]}
    own = wm.reference_error([wm.reference_sums(r["first"], r["second"], mask) for r, mask in zip(refs, masks)])
    views = [{"location": list(v.location), "target": list(v.target), "lens": v.lens, "label": v.label,
              "surface_pixels": int(mask.sum())} for v, mask in zip(walk.views, masks)]
    return {"interior": walk.info.name, "views": views, "kinds": kinds, "reference_error": own,
            "reference_seconds": [r["seconds"] for r in refs], "solve": m["solve"], "stats": m["stats"],
            "unlive_stats": m["unlive_stats"], "samples": m["samples"], "timing": m["timing"]}, masks


# --------------------------------------------------------------------------- the command

def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--interior", action="append", choices=scenes.NAMES, help="an interior to walk through "
                        f"(repeatable; default: {', '.join(DEFAULT_INTERIORS)})")
    parser.add_argument("--views", type=int, default=10, help="views of each interior (at most 10)")
    parser.add_argument("--reference-samples", type=int, default=1024, help="the references' samples (two halves)")
    parser.add_argument("--eevee", action=argparse.BooleanOptionalAction, default=True, help="EEVEE's pictures "
                        "(software OpenGL here: its first render compiles shaders for a minute)")
    parser.add_argument("--unlive", action=argparse.BooleanOptionalAction, default=True, help="a second solve with "
                        "Live lamps off, its baked display")
    parser.add_argument("--seed", type=int, default=0, help="the product's seed (its solves')")
    parser.add_argument("--diffuse", action="store_true", help="Specular IOR Level 0 on every material (Lambertian: "
                        "what the specular layer accounts for)")
    parser.add_argument("--warm-up", action=argparse.BooleanOptionalAction, default=True, help="a solve before the timed one")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a panel setting of the "
                        "product's solves (repeatable), e.g. detail=HIGH")
    parser.add_argument("--quick", action="store_true", help=f"smoke run: 16 reference samples, 2 views, into {QUICK.relative_to(ROOT)}/")
    parser.add_argument("--out", type=Path, default=RESULTS, help="folder of the reports and sheets")
    parser.add_argument("--replot", action="store_true", help="rewrite the reports from their .json")
    parser.add_argument("--reanalyse", action="store_true", help="the numbers and sheets again from the pictures kept in "
                        "out/walkthrough_images/ (and the .json's times): after a change to the measures")
    args = parser.parse_args(argv)
    names = args.interior or list(DEFAULT_INTERIORS)
    if not 1 <= args.views <= 10:
        parser.error(f"--views must be between 1 and 10; got {args.views}")
    if args.reference_samples < 2:
        parser.error(f"--reference-samples must be at least 2 (two halves); got {args.reference_samples}")
    for item in args.set:
        if not item.partition("=")[2]:
            parser.error(f"--set takes NAME=VALUE; got '{item}'")
    if args.quick:
        args.reference_samples, args.views, args.out = 16, 2, QUICK
    args.out.mkdir(parents=True, exist_ok=True)
    command = "python -m benchmarks.walkthrough " + " ".join(argv if argv is not None else sys.argv[1:])
    if args.replot:
        done = {n: json.loads((args.out / f"walkthrough_{n}.json").read_text()) for n in names}
    elif args.reanalyse:
        done = {n: reanalyse(n, args) for n in names}
    else:
        done = {n: walk_one(n, args, command.strip()) for n in names}
    for name, a in done.items():
        (args.out / f"walkthrough_{name}.md").write_text(report.interior_page(a))
    (args.out / "walkthrough.md").write_text(report.summary_page(done))
    print((args.out / "walkthrough.md").read_text())


def walk_one(name, args, command):
    """Measure, analyse and save one interior: its numbers (.json) and contact sheet (.png)."""
    start, load = time.perf_counter(), os.getloadavg()[0]
    m = measure(name, args.reference_samples, args.views, args.eevee, args.unlive, args.warm_up, args.seed,
                overrides=args.set, diffuse=args.diffuse)
    a, masks = analyse(m)
    keep_images(m, masks, ROOT / "out" / "walkthrough_images" / f"{name}{image_tag(args)}.npz")
    sheet = args.out / f"walkthrough_{name}.png"
    report.contact_sheet(m, masks, sheet)
    a["run"] = {"command": command, "seconds": time.perf_counter() - start, "loads": [load, os.getloadavg()[0]],
                "reference_samples": args.reference_samples, "size": list(SIZE), "eevee_samples": shown.EEVEE_SAMPLES,
                "baked_samples": shown.BAKED_SAMPLES, "seed": args.seed, "preview_samples": pic.PREVIEW_SAMPLES, "target": pic.TARGET_ERROR,
                "sheet": sheet.name}
    (args.out / f"walkthrough_{name}.json").write_text(json.dumps(a, indent=1))
    return a


def settings_of(items):
    """{name: value} of ``--set NAME=VALUE`` items, each value as its panel setting's type (a bool
    from 1/true/yes)."""
    import bpy

    settings, out = bpy.context.scene.radiosity, {}
    for item in items:
        name, _, value = item.partition("=")
        kind = type(getattr(settings, name))
        out[name] = value.lower() in ("1", "true", "yes") if kind is bool else kind(value)
    return out


def reanalyse(name, args):
    """``walk_one`` again from the kept pictures and the .json's run, times and statistics."""
    saved = json.loads((args.out / f"walkthrough_{name}.json").read_text())
    kept = np.load(ROOT / "out" / "walkthrough_images" / f"{name}{image_tag(args)}.npz")
    count = len(saved["views"])
    walk = scenes.build(name, count)

    def image(key):
        return kept[key].astype(np.float32)

    refs = [{"first": image(f"first_{k}"), "second": image(f"second_{k}"), "object_id": kept[f"object_id_{k}"],
             "seconds": saved["reference_seconds"][k]} for k in range(count)]
    images = {kind: [(image(f"{kind}_{k}"), saved["kinds"][kind]["seconds"][k]) for k in range(count)] for kind in saved["kinds"]}
    m = {"walk": walk, "refs": refs, "images": images, **{key: saved[key] for key in ("solve", "stats", "unlive_stats", "samples", "timing")}}
    a, masks = analyse(m, [kept[f"mask_{k}"] for k in range(count)])
    report.contact_sheet(m, masks, args.out / saved["run"]["sheet"])
    a["run"] = saved["run"]
    (args.out / f"walkthrough_{name}.json").write_text(json.dumps(a, indent=1))
    return a


def image_tag(args):
    """What tells a run's kept pictures from the default run's: quick, another seed."""
    return ("_quick" if args.quick else "") + ("_diffuse" if getattr(args, "diffuse", False) else "") + (
        f"_seed{args.seed}" if args.seed else "") + "".join(
        "_" + item.replace("=", "-") for item in getattr(args, "set", []))


def keep_images(m, masks, path):
    """Every picture, the references' halves and the pixel maps as float16 (for a look afterwards)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = {f"{kind}_{k}": image.astype(np.float16) for kind, shots in m["images"].items()
              for k, (image, _) in enumerate(shots)}
    for k, (r, mask) in enumerate(zip(m["refs"], masks)):
        arrays.update({f"first_{k}": r["first"].astype(np.float16), f"second_{k}": r["second"].astype(np.float16),
                       f"object_id_{k}": r["object_id"], f"mask_{k}": mask})
    np.savez_compressed(path, names=np.array(m["walk"].info.meshes), **arrays)


if __name__ == "__main__":
    main()
