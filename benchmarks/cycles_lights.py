"""Lights and the world against Cycles: one small scene per source kind, Cycles' COMBINED bake as
the referee.

    python -m benchmarks.cycles_lights            # about 10 minutes on 2 cores
    python -m benchmarks.cycles_lights --quick    # fewer samples and paths, to out/

The scene: an open floor of 2 x 2 m in 8 x 8 patches (albedo 0.5), a red back wall of 2 x 1 m
in 8 x 4 patches (albedo 0.6, 0.2, 0.2) and a grey block of 0.4 m (albedo 0.5, 2 x 2 patches a
face), every patch a quad of its own, all Lambertian (Diffuse BSDF). Lit by one source kind at a
time: a point light, a sphere light (radius 0.15 m, soft falloff off), a spot, a square and a
disk area light, a sun and a uniform world; then a spot scaled (1.8, 1, 1), a point light that
casts no shadow (above the block), the sphere light with soft falloff on (Blender's default; the
core's sphere is the same without it: the difference measured), and a sphere light with colour temperature, exposure and
Normalize off. Ours reads the lights through the extension
(``read_selection``: ``lights_io``) and solves the same patches (exit point "hit":
patch averages of the continuous solution, what a bake's pixel blocks average); Cycles bakes
COMBINED into pixel blocks, one per patch. Reported per scene: the mean of ours / Cycles over
the lit patches with its standard error, the relative RMS of the difference, and both times.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from benchmarks.cycles_comparison import block_mesh, configure_bake, selected_object  # noqa: E402
BLOCK = 12
COLUMNS = 16
METHODS = ("walk", "two_way")

KINDS = {
    "point": ("POINT", {"energy": 200.0, "shadow_soft_size": 0.0}, (0.3, 0.2, 1.2), (0, 0, 0)),
    "sphere": ("POINT", {"energy": 200.0, "shadow_soft_size": 0.15, "use_soft_falloff": False}, (0.3, 0.2, 1.2), (0, 0, 0)),
    "spot": ("SPOT", {"energy": 300.0, "spot_size": math.radians(70), "spot_blend": 0.3, "shadow_soft_size": 0.0},
             (0.0, -0.3, 1.5), (math.radians(15), 0, 0)),
    "area_square": ("AREA", {"energy": 150.0, "shape": "SQUARE", "size": 0.6}, (0.2, 0.0, 1.4), (0, 0, 0)),
    "area_disk": ("AREA", {"energy": 150.0, "shape": "DISK", "size": 0.6}, (-0.2, 0.1, 1.3), (math.radians(20), 0, 0)),
    "sun": ("SUN", {"energy": 3.0, "angle": math.radians(8)}, (0, 0, 3), (math.radians(35), 0, math.radians(20))),
    "world": ("WORLD", {"color": (0.3, 0.35, 0.4), "strength": 1.0}, None, None),
    # Cycles' readings beyond the plain kinds: a spot scaled unevenly (an elliptical cone), a lamp
    # that casts no shadow over the block, and colour temperature, exposure and Normalize off.
    "spot_oval": ("SPOT", {"energy": 300.0, "spot_size": math.radians(70), "spot_blend": 0.3, "shadow_soft_size": 0.0},
                  (0.0, -0.3, 1.5), (math.radians(15), 0, 0), (1.8, 1.0, 1.0)),
    "no_shadow": ("POINT", {"energy": 200.0, "shadow_soft_size": 0.0, "use_shadow": False}, (-0.3, 0.0, 1.2), (0, 0, 0)),
    "sphere_soft": ("POINT", {"energy": 200.0, "shadow_soft_size": 0.15, "use_soft_falloff": True}, (0.3, 0.2, 1.2), (0, 0, 0)),
    "point_raw": ("POINT", {"energy": 400.0, "shadow_soft_size": 0.1, "use_soft_falloff": False, "normalize": False,
                            "use_temperature": True, "temperature": 4000.0, "exposure": 1.0}, (0.3, 0.2, 1.2), (0, 0, 0)),
}


def quads():
    """(corners (P,4,3), reflectivity (P,3)) of the floor, the back wall and the block."""
    cells, colours = [], []

    def grid(origin, u, v, nu, nv, colour):
        for i in range(nu):
            for j in range(nv):
                o = np.asarray(origin, float) + np.asarray(u, float) * i / nu + np.asarray(v, float) * j / nv
                a, b = np.asarray(u, float) / nu, np.asarray(v, float) / nv
                cells.append([o, o + a, o + a + b, o + b])
                colours.append(colour)

    grid((-1, -1, 0), (2, 0, 0), (0, 2, 0), 8, 8, (0.5, 0.5, 0.5))      # floor, facing up
    grid((-1, 1, 0), (2, 0, 0), (0, 0, 1), 8, 4, (0.6, 0.2, 0.2))       # back wall at y = 1, facing -y
    lo, hi = np.array([-0.5, -0.2, 0.0]), np.array([-0.1, 0.2, 0.4])
    s = hi - lo
    for origin, u, v in (((lo[0], lo[1], hi[2]), (s[0], 0, 0), (0, s[1], 0)),   # top
                         ((lo[0], lo[1], lo[2]), (0, 0, s[2]), (0, s[1], 0)),   # -x side... faces -x
                         ((hi[0], lo[1], lo[2]), (0, s[1], 0), (0, 0, s[2])),   # +x
                         ((lo[0], lo[1], lo[2]), (s[0], 0, 0), (0, 0, s[2])),   # -y
                         ((lo[0], hi[1], lo[2]), (0, 0, s[2]), (s[0], 0, 0))):  # +y
        grid(origin, u, v, 2, 2, (0.5, 0.5, 0.5))
    return np.array(cells), np.array(colours)


def build(kind):
    """The scene in Blender, lit by ``kind``: (the mesh object, its bake image, rows)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    import addon

    addon.register()
    corners, colours = quads()
    P = len(corners)
    mesh, image, rows = block_mesh("Scene", corners, BLOCK, COLUMNS)
    palette = {}
    index = np.zeros(P, np.int32)
    for p, colour in enumerate(map(tuple, colours)):
        if colour not in palette:
            palette[colour] = len(palette)
            mesh.materials.append(_diffuse(f"M{len(palette)}", colour, image))
        index[p] = palette[colour]
    mesh.polygons.foreach_set("material_index", index)
    mesh.update()
    obj = selected_object(mesh)
    scene = bpy.context.scene
    kind_type, settings, location, rotation, *scale = KINDS[kind]
    if kind_type == "WORLD":
        world = bpy.data.worlds.new("Sky")
        scene.world = world
        world.use_nodes = True
        bg = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
        bg.inputs["Color"].default_value = (*settings["color"], 1.0)
        bg.inputs["Strength"].default_value = settings["strength"]
    else:
        data = bpy.data.lights.new(kind, kind_type)
        for key, value in settings.items():
            if hasattr(data, key):
                setattr(data, key, value)
        lamp = bpy.data.objects.new(kind, data)
        lamp.location, lamp.rotation_euler = location, rotation
        lamp.scale = scale[0] if scale else (1.0, 1.0, 1.0)
        scene.collection.objects.link(lamp)
    configure_bake(scene)
    return obj, image, rows


def _diffuse(name, colour, image):
    import bpy

    m = bpy.data.materials.new(name)
    tree = m.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*colour, 1.0)
    tree.links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.nodes.active = texture
    m.diffuse_color = (*colour, 1.0)
    return m


def bake(image, rows, columns, block, patches, samples, seed):
    """(B (P,3), wall seconds) of a COMBINED bake: each patch's block of pixels averaged."""
    import bpy

    scene = bpy.context.scene
    scene.cycles.samples, scene.cycles.seed = samples, seed
    wall = time.perf_counter()
    assert bpy.ops.object.bake(type="COMBINED") == {"FINISHED"}
    wall = time.perf_counter() - wall
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(rows * block, columns * block, 4)[..., :3].astype(np.float64)
    return rgb.reshape(rows, block, columns, block, 3).mean(axis=(1, 3)).reshape(-1, 3)[:patches], wall


def cycles(image, rows, patches, samples, seed=0):
    return bake(image, rows, COLUMNS, BLOCK, patches, samples, seed)


def ours(paths, seed=0, direct_light="shot", method="walk"):
    import bpy

    from addon.bpy_free import pipeline
    from addon.blender_read.selection import read_selection

    objects, notes = read_selection(bpy.context)
    settings = pipeline.SolveSettings(paths=paths, patch_size=1e6, exit_point="hit", method=method,
                                      seed=seed, threads=2, direct_light=direct_light)
    wall = time.perf_counter()
    out = pipeline.run_solve(objects, settings)
    wall = time.perf_counter() - wall
    face = out.patches.meshes[0].patch_face
    B = np.zeros_like(out.result.radiosity)
    B[face] = out.result.radiosity  # back to face order: the bake's blocks
    variance = np.zeros_like(B)
    variance[face] = out.result.reflected_variance
    return B, variance, wall, out.sources, notes


def compare(kind, samples, paths):
    """Ours against one bake, for the paper's walk and for the two-way iteration (which the
    panel's Automatic takes in these scenes)."""
    obj, image, rows = build(kind)
    P = len(obj.data.polygons)
    reference, cycles_seconds = cycles(image, rows, P, samples)
    grey_ref = reference.mean(axis=1)
    lit = grey_ref > 0.02 * grey_ref.max()
    row = {"kind": kind, "patches": P, "lit": int(lit.sum()), "cycles_seconds": cycles_seconds}
    for method in METHODS:
        mine, variance, seconds, sources, notes = ours(paths, method=method)
        ratio = mine.mean(axis=1)[lit] / grey_ref[lit]
        row[method] = {
            "mean_ratio": float(ratio.mean()), "ratio_se": float(ratio.std(ddof=1) / math.sqrt(ratio.size)),
            "relative_rms": float(np.sqrt(np.mean((ratio - 1) ** 2))),
            "our_noise": float(np.sqrt(np.mean(variance.mean(axis=1)[lit] / grey_ref[lit] ** 2))),
            "seconds": seconds,
        }
        row["sources"], row["notes"] = sources, notes
    return row


def time_to_error(kind, samples, paths, target=0.01):
    """Seconds each side needs for a per-patch relative RMS error of ``target`` over the lit
    patches, each from its own error estimate: Cycles' from two bakes with different seeds (the
    spread of their difference), ours from batch means. The error goes as 1 / sqrt(work)
    (samples, paths); time = fixed + work x rate, both fitted from a small and a large run."""
    obj, image, rows = build(kind)
    P = len(obj.data.polygons)
    _, small_seconds = cycles(image, rows, P, 1, seed=3)
    a, seconds_a = cycles(image, rows, P, samples, seed=1)
    b, seconds_b = cycles(image, rows, P, samples, seed=2)
    grey_a, grey_b = a.mean(axis=1), b.mean(axis=1)
    mean = 0.5 * (grey_a + grey_b)
    lit = mean > 0.02 * mean.max()
    row = {"kind": kind, "cycles_error": float(np.sqrt(np.mean(((grey_a - grey_b)[lit] / mean[lit]) ** 2 / 2)))}
    row["cycles_seconds"] = _extrapolate(small_seconds, 1, 0.5 * (seconds_a + seconds_b), samples, row["cycles_error"], target)
    for light in ("shot", "gathered"):
        _, _, small, _, _ = ours(paths // 64, direct_light=light)
        _, variance, seconds, _, _ = ours(paths, direct_light=light)
        error = float(np.sqrt(np.mean(variance.mean(axis=1)[lit] / mean[lit] ** 2)))
        row[f"{light}_error"] = error
        row[f"{light}_seconds"] = _extrapolate(small, paths // 64, seconds, paths, error, target)
    return row


def _extrapolate(small_seconds, small_work, seconds, work, error, target):
    """Time for ``target`` from a line through (small_work, small_seconds) and (work, seconds),
    the work needed scaling as (error / target)^2."""
    rate = max(seconds - small_seconds, 1e-9) / (work - small_work)
    fixed = max(small_seconds - rate * small_work, 0.0)
    return fixed + rate * work * (error / target) ** 2


def plot(rows, timed, path):
    """The agreement (ours / Cycles, with standard errors) and the times to 1%, one bar group a
    source kind."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    kinds = [r["kind"] for r in rows]
    x = np.arange(len(kinds))
    fig, axes = plt.subplots(1, 2 if timed else 1, figsize=(12 if timed else 6, 4), squeeze=False)
    ax = axes[0, 0]
    for k, method in enumerate(METHODS):
        ax.errorbar(x + (k - 0.5) * 0.2, [r[method]["mean_ratio"] for r in rows],
                    yerr=[2 * r[method]["ratio_se"] for r in rows], fmt="o", capsize=4, label=method.replace("_", "-"))
    ax.legend()
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.set_xticks(x, kinds, rotation=30)
    ax.set_ylabel("ours / Cycles (mean over lit patches, 2 s.e.)")
    ax.set_title("Radiosity against Cycles' COMBINED bake")
    if timed:
        ax = axes[0, 1]
        width = 0.27
        for k, (key, label) in enumerate((("cycles_seconds", "Cycles"), ("shot_seconds", "ours, shot (paper)"),
                                           ("gathered_seconds", "ours, first shot gathered"))):
            ax.bar(x + (k - 1) * width, [t[key] for t in timed], width, label=label)
        ax.set_yscale("log")
        ax.set_xticks(x, [t["kind"] for t in timed], rotation=30)
        ax.set_ylabel("seconds to 1% per-patch relative RMS")
        ax.set_title("Time to 1% (2 cores)")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def timing(args):
    samples, paths = (64, 200_000) if args.quick else (256, 2_000_000)
    lines = ["", f"## Time to 1% (per-patch relative RMS over the lit patches), {samples} samples / {paths:,} paths measured",
             "",
             "Each side's error from its own estimate (Cycles: two bakes of different seeds; ours: batch means), "
             "the work for 1% as (error / 0.01)^2 times the work measured, and the time from a line through a small "
             "and a large run (a 1-sample bake; 1/64 of the paths): fixed cost plus work times rate. Ours shot: the "
             "paper's walk (hit exit); gathered: the first bounce by shadow rays (direct_light='gathered').", "",
             "| source | Cycles error | Cycles s to 1% | ours (shot) error | s to 1% | / Cycles | ours (gathered) error | s to 1% | / Cycles |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    args.timed = []
    for kind in args.kinds:
        r = time_to_error(kind, samples, paths)
        args.timed.append(r)
        c = r["cycles_seconds"]
        print(f"{kind:12s} to 1%: Cycles {c:.2f} s, shot {r['shot_seconds']:.2f} s, gathered {r['gathered_seconds']:.2f} s",
              flush=True)
        lines.append(f"| {kind} | {r['cycles_error']:.4f} | {c:.2f} | {r['shot_error']:.4f} | {r['shot_seconds']:.2f} | "
                     f"{r['shot_seconds'] / c:.2f} | {r['gathered_error']:.4f} | {r['gathered_seconds']:.2f} | "
                     f"{r['gathered_seconds'] / c:.2f} |")
    return lines


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--kinds", nargs="+", default=list(KINDS))
    p.add_argument("--timing", action="store_true", help="also the time each side needs to 1%% (appended)")
    args = p.parse_args(argv)
    samples, paths = (64, 200_000) if args.quick else (1024, 3_000_000)
    rows = []
    for kind in args.kinds:
        row = compare(kind, samples, paths)
        rows.append(row)
        print(f"{kind:12s} " + "  ".join(
            f"{m}: ours/Cycles {row[m]['mean_ratio']:.4f} +- {row[m]['ratio_se']:.4f} rel. RMS {row[m]['relative_rms']:.3f} "
            f"(noise {row[m]['our_noise']:.3f})" for m in METHODS) + f"  {row['sources']}", flush=True)
    out = (ROOT / "out" if args.quick else RESULTS) / "cycles_lights.md"
    out.parent.mkdir(exist_ok=True)
    lines = [
        "# Lights and the world against Cycles' COMBINED bake",
        "",
        f"`python -m benchmarks.cycles_lights{' --quick' if args.quick else ''}`: Cycles {samples} samples a pixel, "
        f"{BLOCK}x{BLOCK} pixels a patch; ours {paths:,} paths, exit point hit, the paper's walk and the two-way "
        "iteration (which Automatic takes here). Scenes in the module's docstring. Ratio: mean over the lit patches "
        "of ours / Cycles (grey), with its standard error over the patches; relative RMS of the per-patch "
        "difference, beside our own noise (batch means) of the same measure.",
        "",
        "| source | patches lit | walk / Cycles | rel. RMS | our noise | two-way / Cycles | rel. RMS | our noise | "
        "walk s | two-way s | Cycles s | sources |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        w, t = r["walk"], r["two_way"]
        lines.append(f"| {r['kind']} | {r['lit']} | {w['mean_ratio']:.4f} ± {w['ratio_se']:.4f} | {w['relative_rms']:.3f} | "
                     f"{w['our_noise']:.3f} | {t['mean_ratio']:.4f} ± {t['ratio_se']:.4f} | {t['relative_rms']:.3f} | "
                     f"{t['our_noise']:.3f} | {w['seconds']:.2f} | {t['seconds']:.2f} | {r['cycles_seconds']:.2f} | "
                     f"{r['sources']} |")
    notes = sorted({n for r in rows for n in r["notes"]})
    if notes:
        lines += ["", "Notes from reading the scenes:", ""] + [f"- {n}" for n in notes]
    args.timed = []
    if args.timing:
        lines += timing(args)
    plot(rows, args.timed, out.with_suffix(".png"))
    lines += ["", f"![agreement and time to 1%]({out.with_suffix('.png').name})"]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
