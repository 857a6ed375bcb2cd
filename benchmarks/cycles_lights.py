"""Lights and the world against Cycles: one small scene per source kind, Cycles' COMBINED bake as
the referee (issue 23).

    python -m benchmarks.cycles_lights            # about 10 minutes on 2 cores
    python -m benchmarks.cycles_lights --quick    # fewer samples and paths, to out/

The scene: an open floor of 2 x 2 m in 8 x 8 patches (albedo 0.5), a red back wall of 2 x 1 m
in 8 x 4 patches (albedo 0.6, 0.2, 0.2) and a grey block of 0.4 m (albedo 0.5, 2 x 2 patches a
face), every patch a quad of its own, all Lambertian (Diffuse BSDF). Lit by one source kind at a
time: a point light, a sphere light (radius 0.15 m, soft falloff off), a spot, a square and a
disk area light, a sun and a uniform world. Ours reads the lights through the extension
(``scene_io.read_selection``: ``lights_io``) and solves the same patches (exit point "hit":
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

KINDS = {
    "point": ("POINT", {"energy": 200.0, "shadow_soft_size": 0.0}, (0.3, 0.2, 1.2), (0, 0, 0)),
    "sphere": ("POINT", {"energy": 200.0, "shadow_soft_size": 0.15, "use_soft_falloff": False}, (0.3, 0.2, 1.2), (0, 0, 0)),
    "spot": ("SPOT", {"energy": 300.0, "spot_size": math.radians(70), "spot_blend": 0.3, "shadow_soft_size": 0.0},
             (0.0, -0.3, 1.5), (math.radians(15), 0, 0)),
    "area_square": ("AREA", {"energy": 150.0, "shape": "SQUARE", "size": 0.6}, (0.2, 0.0, 1.4), (0, 0, 0)),
    "area_disk": ("AREA", {"energy": 150.0, "shape": "DISK", "size": 0.6}, (-0.2, 0.1, 1.3), (math.radians(20), 0, 0)),
    "sun": ("SUN", {"energy": 3.0, "angle": math.radians(8)}, (0, 0, 3), (math.radians(35), 0, math.radians(20))),
    "world": ("WORLD", {"color": (0.3, 0.35, 0.4), "strength": 1.0}, None, None),
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
    kind_type, settings, location, rotation = KINDS[kind]
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


def cycles(image, rows, patches, samples, seed=0):
    import bpy

    scene = bpy.context.scene
    scene.cycles.samples, scene.cycles.seed = samples, seed
    wall = time.perf_counter()
    assert bpy.ops.object.bake(type="COMBINED") == {"FINISHED"}
    wall = time.perf_counter() - wall
    pixels = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(rows * BLOCK, COLUMNS * BLOCK, 4)[..., :3].astype(np.float64)
    B = rgb.reshape(rows, BLOCK, COLUMNS, BLOCK, 3).mean(axis=(1, 3)).reshape(-1, 3)[:patches]
    return B, wall


def ours(paths, seed=0):
    import bpy

    from addon import patches as patch_making
    from addon import pipeline, scene_io

    objects, notes = scene_io.read_selection(bpy.context)
    settings = pipeline.SolveSettings(paths=paths, patch_size=1e6, exit_point="hit", seed=seed, threads=2)
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
    obj, image, rows = build(kind)
    P = len(obj.data.polygons)
    reference, cycles_seconds = cycles(image, rows, P, samples)
    mine, variance, our_seconds, sources, notes = ours(paths)
    grey_ref, grey = reference.mean(axis=1), mine.mean(axis=1)
    lit = grey_ref > 0.02 * grey_ref.max()
    ratio = grey[lit] / grey_ref[lit]
    return {
        "kind": kind, "patches": P, "lit": int(lit.sum()), "sources": sources, "notes": notes,
        "mean_ratio": float(ratio.mean()), "ratio_se": float(ratio.std(ddof=1) / math.sqrt(ratio.size)),
        "relative_rms": float(np.sqrt(np.mean((grey[lit] / grey_ref[lit] - 1) ** 2))),
        "our_noise": float(np.sqrt(np.mean(variance.mean(axis=1)[lit] / grey_ref[lit] ** 2))),
        "cycles_seconds": cycles_seconds, "our_seconds": our_seconds,
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--kinds", nargs="+", default=list(KINDS))
    args = p.parse_args(argv)
    samples, paths = (64, 200_000) if args.quick else (1024, 3_000_000)
    rows = []
    for kind in args.kinds:
        row = compare(kind, samples, paths)
        rows.append(row)
        print(f"{kind:12s} ours/Cycles {row['mean_ratio']:.4f} +- {row['ratio_se']:.4f}  rel. RMS {row['relative_rms']:.3f} "
              f"(our noise {row['our_noise']:.3f})  {row['sources']}", flush=True)
    out = (ROOT / "out" if args.quick else RESULTS) / "cycles_lights.md"
    out.parent.mkdir(exist_ok=True)
    lines = [
        "# Lights and the world against Cycles' COMBINED bake",
        "",
        f"`python -m benchmarks.cycles_lights{' --quick' if args.quick else ''}`: Cycles {samples} samples a pixel, "
        f"{BLOCK}x{BLOCK} pixels a patch; ours {paths:,} paths, exit point hit. Scenes in the module's docstring. "
        "Ratio: mean over the lit patches of ours / Cycles (grey), with its standard error over the patches; "
        "relative RMS of the per-patch difference, beside our own noise (batch means) of the same measure.",
        "",
        "| source | patches lit | ours / Cycles | rel. RMS | our noise | ours s | Cycles s | sources |",
        "|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        lines.append(f"| {r['kind']} | {r['lit']} | {r['mean_ratio']:.4f} ± {r['ratio_se']:.4f} | {r['relative_rms']:.3f} | "
                     f"{r['our_noise']:.3f} | {r['our_seconds']:.2f} | {r['cycles_seconds']:.2f} | {r['sources']} |")
    notes = sorted({n for r in rows for n in r["notes"]})
    if notes:
        lines += ["", "Notes from reading the scenes:", ""] + [f"- {n}" for n in notes]
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
