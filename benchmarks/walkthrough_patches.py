"""An interior's objects patch by patch: the product's solve over several seeds against Cycles'
bake of the same patches, and the display against the solve.

    nice -n 10 .venv/bin/python -m benchmarks.walkthrough_patches                    # the hall's Bench, Pedestal, Console, 9 seeds
    .venv/bin/python -m benchmarks.walkthrough_patches --set method=walk --seeds 4   # another method of the panel's
    .venv/bin/python -m benchmarks.walkthrough_patches --quick                       # smoke run into out/

The product: the panel's operator at its defaults (``walkthrough.solve``'s, the seeds 0, 1, ...);
per patch of each object its light arriving H (the solve's), its corner mean as written ('Radiosity
Light': the display) and its variance. Cycles: the DIFFUSE pass (direct and indirect, no colour: the
light arriving, the quantity the product solves) baked into BLOCK x BLOCK pixels a patch, two seeds,
each patch's mean taken over its pixels that get light: the part outside other objects, which the
solve's patches keep too (``docs/buried.md``). Reported per object and face group (top, underside,
sides, legs: the sides below the object's lowest lit underside): the solve over Cycles at the first
seed and over the seeds (mean, its standard error), one seed's spread against what one solve's
variances say of it (``walkthrough_measures.object_noise``), and the display over the solve.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from benchmarks import walkthrough as wt  # noqa: E402
from benchmarks import walkthrough_measures as wm  # noqa: E402
from benchmarks import walkthrough_scenes as scenes  # noqa: E402
from benchmarks.cycles_comparison import block_mesh, configure_bake  # noqa: E402

BLOCK, COLUMNS = 8, 16
DEFAULT_OBJECTS = ("Bench", "Pedestal", "Console")


# --------------------------------------------------------------------------- the product

def object_patches(output, names):
    """Per object named: its patches' quads (P,4,3), area, light arriving H, its corner mean as
    written ('Radiosity Light'), and the radiosity's and its variance (P,3), from a solve's output."""
    patches, result = output.patches, output.result
    out = {}
    for k, o in enumerate(patches.objects):
        if o.name not in names:
            continue
        mesh, rows = patches.meshes[k], patches.combined.patch_slice(k)
        if (mesh.face_sizes != 4).any():
            raise ValueError(f"'{o.name}': patches of {sorted(set(mesh.face_sizes.tolist()))} corners; quads only")
        quads = mesh.points[mesh.corner_verts.reshape(-1, 4)]
        out[o.name] = {"quads": quads, "area": np.asarray(mesh.patch_area), "H": result.irradiance[rows],
                       "shown": shown_means(output, k), "B": result.radiosity[rows], "variance": result.reflected_variance[rows]}
    return out


def shown_means(output, k):
    """(P_k,3) each patch's light as written ('Radiosity Light'): the area-weighted mean of its
    polygons' corner means, on the mesh the display is written on (the patches, or their display cells)."""
    from addon.bpy_free.shown_mesh import mesh_of

    mesh, shown = mesh_of(output, k), getattr(output, "shown", None)
    origin = None if shown is None else shown.origin[k]
    polygons = len(mesh.face_sizes)
    origin = np.arange(polygons) if origin is None else np.asarray(origin)
    light = np.asarray(output.light_colours[k], np.float64)
    corner_polygon = np.repeat(np.arange(polygons), mesh.face_sizes)
    area = np.asarray(mesh.patch_area, np.float64)
    weight = area / np.asarray(mesh.face_sizes, np.float64)
    patches = int(origin.max()) + 1
    total = np.bincount(origin, area, minlength=patches)
    return np.stack([np.bincount(origin, np.bincount(corner_polygon, light[:, c], minlength=polygons) * weight,
                                 minlength=patches) / total for c in range(3)], axis=1)


def solves(names, seeds, overrides, log=print):
    """``object_patches`` of the product's solve at each seed: a list, seed by seed."""
    import bpy

    settings = bpy.context.scene.radiosity
    overrides = {k: (v.lower() in ("1", "true", "yes") if isinstance(getattr(settings, k), bool) else type(getattr(settings, k))(v))
                 for k, v in overrides.items()}
    out = []
    for seed in range(seeds):
        kept = {}
        wall, stats = wt.solve(seed=seed, before_writing=lambda output: kept.update(object_patches(output, names)),
                               **overrides)
        out.append(kept)
        log(f"seed {seed}: {wall:.1f} s, error estimate {stats['error']:.2f}%, {stats['method']}")
    return out


# --------------------------------------------------------------------------- Cycles

def bake(quads_by_name, samples, seed):
    """Cycles' DIFFUSE light (direct and indirect, no colour) of every patch, in place of the
    objects (hidden from the render, as the results are; each patch's block keeps the object's
    material): per object (P,3) the mean over the pixels that get light, and (P,) their share."""
    import bpy

    from addon.blender_write.results import previous_results

    for o in previous_results():
        o.hide_render = True
    names = list(quads_by_name)
    quads = np.concatenate([quads_by_name[n] for n in names])
    mesh, image, rows = block_mesh("Patch Bake", quads, BLOCK, COLUMNS)
    for n in names:
        bpy.data.objects[n].hide_render = True
        material = bpy.data.objects[n].material_slots[0].material.copy()
        texture = material.node_tree.nodes.new("ShaderNodeTexImage")
        texture.image, material.node_tree.nodes.active = image, texture
        mesh.materials.append(material)
    counts = [len(quads_by_name[n]) for n in names]
    mesh.polygons.foreach_set("material_index", np.repeat(np.arange(len(names)), counts).astype(np.int32))
    mesh.update()
    obj = bpy.data.objects.new("Patch Bake", mesh)
    bpy.context.scene.collection.objects.link(obj)
    try:
        bpy.context.view_layer.update()
        for other in bpy.context.scene.objects:
            other.select_set(False)
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
        scene = bpy.context.scene
        configure_bake(scene, wt.pic.THREADS)
        scene.cycles.samples, scene.cycles.seed = samples, seed
        scene.render.bake.use_pass_direct = scene.render.bake.use_pass_indirect = True
        scene.render.bake.use_pass_color = False
        assert bpy.ops.object.bake(type="DIFFUSE") == {"FINISHED"}
        pixels = np.empty(len(image.pixels), np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.objects.remove(obj)
        for n in names:
            bpy.data.objects[n].hide_render = False
    blocks = pixels.reshape(rows, BLOCK, COLUMNS, BLOCK, 4)[..., :3].astype(np.float64)
    lit = blocks.sum(axis=4) > 1e-7  # (a pixel inside another object gets none)
    seen = lit.sum(axis=(1, 3)).reshape(-1)[: len(quads)]
    mean = (blocks * lit[..., None]).sum(axis=(1, 3)).reshape(-1, 3)[: len(quads)] / np.maximum(seen, 1)[:, None]
    starts = np.cumsum([0] + counts)
    return {n: (mean[starts[k]:starts[k + 1]], seen[starts[k]:starts[k + 1]] / BLOCK**2) for k, n in enumerate(names)}


# --------------------------------------------------------------------------- the numbers

def face_groups(quads, lit):
    """Each patch's group by its normal: top, underside, sides, and legs: the sides below the lowest
    underside that gets light (``lit``: (P,) bool; a table top's, a bench's seat's)."""
    normal = np.cross(quads[:, 1] - quads[:, 0], quads[:, 3] - quads[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    height = quads[:, :, 2].mean(axis=1)
    under = normal[:, 2] < -0.9
    below = height < height[under & lit].min() if (under & lit).any() else np.zeros(len(quads), bool)
    return np.where(normal[:, 2] > 0.9, "top", np.where(under, "underside", np.where(below, "legs", "sides")))


def object_rows(name, seeds, cycles):
    """The rows of one object: for the whole object and each face group, the numbers of the page."""
    first = seeds[0][name]
    reference, share = cycles
    area = first["area"] * share  # the part that gets light, as Cycles' mean is taken over it
    lit = reference.mean(axis=1) > 1e-6
    groups = face_groups(first["quads"], lit)
    rows = []
    for group in ["all", *sorted(set(groups[lit]))]:
        pick = lit & ((groups == group) if group != "all" else True)
        total = np.sum(area[pick] * reference[pick].mean(axis=1))
        ratio = np.array([np.sum(area[pick] * s[name]["H"][pick].mean(axis=1)) / total for s in seeds])
        said = [wm.object_noise([(name, area[pick], s[name]["B"][pick], s[name]["variance"][pick])])[name] for s in seeds]
        shown = np.sum(area[pick] * first["shown"][pick].mean(axis=1)) / np.sum(area[pick] * first["H"][pick].mean(axis=1))
        rows.append({"object": name, "group": group, "patches": int(pick.sum()), "first": float(ratio[0]),
                     "mean": float(ratio.mean()), "se": float(ratio.std(ddof=1) / np.sqrt(len(ratio))) if len(ratio) > 1 else None,
                     "spread": float(ratio.std(ddof=1) / ratio.mean()) if len(ratio) > 1 else None,
                     "said": float(np.median(said)), "shown": float(shown), "by_seed": ratio.tolist()})
    return rows


def page(a):
    """The markdown page of a run (``run``'s dict)."""
    head = ("| object | faces | patches | seed 0, solve / Cycles | over the seeds | one seed's spread | its own noise, "
            "from one solve | display / solve (seed 0) |")
    lines = [f"# The walkthrough's objects patch by patch: {a['interior']}", "",
             "Made by `benchmarks/walkthrough_patches.py` (what is compared: its docstring); numbers in "
             f"`walkthrough_patches_{a['interior']}{a['tag']}.json`.", "",
             f"`{a['command']}`; {a['seeds']} seeds of the product{a['overrides']}; Cycles {a['samples']} samples, "
             f"two seeds (their objects' light differs by at most {100 * a['cycles_halves']:.1f}%); the whole run "
             f"{a['seconds'] / 60:.0f} min.", "", head, "|---|---|---|---|---|---|---|---|"]
    for r in a["rows"]:
        over = f"{r['mean']:.3f} ± {r['se']:.3f}" if r["se"] is not None else "-"
        spread = f"{100 * r['spread']:.1f}%" if r["spread"] is not None else "-"
        lines.append(f"| {r['object']} | {r['group']} | {r['patches']} | {r['first']:.3f} | {over} | {spread} | "
                     f"{100 * r['said']:.1f}% | {r['shown']:.3f} |")
    return "\n".join(lines) + "\n"


def run(interior, names, seeds, samples, overrides, log=print):
    """The interior built, solved at ``seeds`` seeds, its objects ``names`` baked twice: the page's numbers."""
    scenes.build(interior)
    solved = solves(names, seeds, overrides, log)
    quads = {n: solved[0][n]["quads"] for n in names}
    bakes = [bake(quads, samples, seed) for seed in (1, 2)]
    cycles = {n: ((bakes[0][n][0] + bakes[1][n][0]) / 2, np.minimum(bakes[0][n][1], bakes[1][n][1])) for n in names}
    halves = []
    for n in names:
        area = solved[0][n]["area"] * cycles[n][1]
        one, two = (np.sum(area * b[n][0].mean(axis=1)) for b in bakes)
        halves.append(abs(one - two) / (one + two) * 2)
    rows = [row for n in names for row in object_rows(n, solved, cycles[n])]
    return {"interior": interior, "seeds": seeds, "samples": samples, "rows": rows, "cycles_halves": float(max(halves))}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--interior", default="skylight_hall", choices=scenes.NAMES)
    parser.add_argument("--objects", default=",".join(DEFAULT_OBJECTS), help="the objects to compare, by name, comma-separated")
    parser.add_argument("--seeds", type=int, default=9, help="the product's seeds (0, 1, ...)")
    parser.add_argument("--samples", type=int, default=512, help="Cycles' samples of each of its two bakes")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE", help="a panel setting of the product's")
    parser.add_argument("--quick", action="store_true", help="2 seeds, 32 samples, into out/")
    args = parser.parse_args(argv)
    overrides = {}
    for item in args.set:
        name, _, value = item.partition("=")
        if not value:
            parser.error(f"--set takes NAME=VALUE; got '{item}'")
        overrides[name] = value
    if args.quick:
        args.seeds, args.samples = 2, 32
    out = ROOT / "out" if args.quick else RESULTS
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    a = run(args.interior, args.objects.split(","), args.seeds, args.samples, overrides)
    tag = "".join(f"_{v}" for v in overrides.values())
    a.update(command="python -m benchmarks.walkthrough_patches " + " ".join(argv if argv is not None else sys.argv[1:]),
             seconds=time.perf_counter() - start, tag=tag,
             overrides="".join(f", {k} {v}" for k, v in overrides.items()) or " at the panel's defaults")
    (out / f"walkthrough_patches_{args.interior}{tag}.json").write_text(json.dumps(a, indent=1))
    (out / f"walkthrough_patches_{args.interior}{tag}.md").write_text(page(a))
    print(page(a))


if __name__ == "__main__":
    main()
