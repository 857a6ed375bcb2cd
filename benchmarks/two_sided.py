"""The sample Cornell box's panel (1 cm under the ceiling, facing down) against Cycles: emitting
faces emit from both sides, so its back lights the ceiling above and around it.

    nice .venv/bin/python -m benchmarks.two_sided            # ~7 min on 2 cores -> results/two_sided.md
    .venv/bin/python -m benchmarks.two_sided --quick         # a smoke run (~1 min), to out/

Three solves of the box at 10 cm patches (``cornell_box``, divisions 10), each patch's mean:
Cycles' COMBINED bake of the scene as Cycles draws it (the panel's back emits and reflects, R
0.78), Cycles' bake with the panel's back emitting but reflecting nothing (a Backfacing mix: the
product's model, whose surfaces are one-sided), and the product's continuous walk (direct light
gathered, hit exit). Per part of the box, the ratio of the area-weighted light (B A) to each
bake, on the patches not covered by the panel (those above it are hidden in the 1 cm gap).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

import sample_scenes  # noqa: E402
from benchmarks.cycles_comparison import block_mesh, configure_bake, selected_object  # noqa: E402

BLOCK, COLUMNS = 8, 32


def quads(scene):
    """(P,4,3) each patch's corners: its triangles (a, b, c) and (a, c, d), as sample_scenes makes them."""
    corners = scene.vertices[scene.triangles].reshape(scene.patch_count, 2, 3, 3)
    return np.concatenate([corners[:, 0], corners[:, 1, 2:3]], axis=1)


def cycles_bake(scene, samples, back_reflects):
    """(P,3) the patches' means of Cycles' COMBINED bake; ``back_reflects`` False: the emitting
    patches' backs emit but reflect nothing (a Backfacing mix to their emission alone)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    mesh, image, rows = block_mesh("Box", quads(scene), BLOCK, COLUMNS)
    keys, kind = np.unique(np.hstack([scene.reflectivity, scene.emission]), axis=0, return_inverse=True)
    for k, row in enumerate(keys):
        mesh.materials.append(_material(f"M{k}", row[:3], row[3:], image, back_reflects))
    mesh.polygons.foreach_set("material_index", kind.ravel().astype(np.int32))
    mesh.update()
    selected_object(mesh)
    c = configure_bake(bpy.context.scene, threads=2)
    c.samples = samples
    if bpy.ops.object.bake(type="COMBINED") != {"FINISHED"}:
        raise RuntimeError("Cycles' bake failed")
    pixels = np.empty(image.size[0] * image.size[1] * 4, np.float32)
    image.pixels.foreach_get(pixels)
    image = pixels.reshape(image.size[1], image.size[0], 4)[..., :3].astype(np.float64)
    return image.reshape(rows, BLOCK, COLUMNS, BLOCK, 3).mean(axis=(1, 3)).reshape(-1, 3)[:scene.patch_count]


def _material(name, reflectivity, emission, image, back_reflects):
    import bpy

    m = bpy.data.materials.new(name)
    tree = m.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*reflectivity, 1.0)
    shader = diffuse.outputs[0]
    if emission.any():
        glow = tree.nodes.new("ShaderNodeEmission")
        glow.inputs["Color"].default_value = (*emission, 1.0)
        add = tree.nodes.new("ShaderNodeAddShader")
        tree.links.new(shader, add.inputs[0])
        tree.links.new(glow.outputs[0], add.inputs[1])
        shader = add.outputs[0]
        if not back_reflects:
            side, mix = tree.nodes.new("ShaderNodeNewGeometry"), tree.nodes.new("ShaderNodeMixShader")
            tree.links.new(side.outputs["Backfacing"], mix.inputs[0])
            tree.links.new(shader, mix.inputs[1])
            tree.links.new(glow.outputs[0], mix.inputs[2])
            shader = mix.outputs[0]
    tree.links.new(shader, tree.nodes.new("ShaderNodeOutputMaterial").inputs["Surface"])
    texture = tree.nodes.new("ShaderNodeTexImage")  # (the bake target: the active image node)
    texture.image = image
    tree.nodes.active = texture
    return m


def parts(sample):
    """[(name, rows)] the box's parts off the emitters, without the ceiling's patches the panel
    covers (wholly or partly: hidden in the gap), and those covered patches apart."""
    scene = sample.scene
    centre, emitting = sample.patch_centroid, scene.emission.any(axis=1)
    names = np.array(sample.part_names)[sample.patch_part]
    covered = (np.abs(centre[:, 2] - 1) < 1e-9) & (np.abs(centre - 0.5)[:, :2] < 0.2).all(axis=1)
    out = [(name, (names == name) & ~emitting & ~covered) for name in sorted(set(names[~emitting]))]
    return out + [("ceiling over the panel (hidden)", covered)]


def run(samples, paths, divisions):
    from addon.core import solve

    sample = sample_scenes.build("cornell_box", divisions=divisions)
    scene = sample.scene
    started = time.time()
    drawn = cycles_bake(scene, samples, back_reflects=True)
    one_sided = cycles_bake(scene, samples, back_reflects=False)
    baked = time.time() - started
    ours = solve(scene, paths=paths, seed=1, method="walk", direct_light="gathered", exit_point="hit", threads=2)
    area = scene.patch_area[:, None]
    rows = []
    for name, part in parts(sample):
        light = lambda B: float((B[part] * area[part]).sum())  # noqa: E731
        rows.append((name, int(part.sum()), light(ours.radiosity) / light(drawn), light(ours.radiosity) / light(one_sided)))
    return rows, dict(samples=samples, paths=paths, divisions=divisions, bake_seconds=baked, solve_seconds=ours.seconds,
                      relative_error=ours.relative_error)


def report(rows, settings):
    lines = ["# The Cornell box's panel: both sides emit", "",
             "Written by `benchmarks/two_sided.py` (its docstring says what it measures). "
             f"Cycles {settings['samples']} samples a pixel, {BLOCK} x {BLOCK} pixels a patch "
             f"({settings['bake_seconds']:.0f} s for both bakes); ours {settings['paths']:,} paths "
             f"({settings['solve_seconds']:.1f} s, error {settings['relative_error']:.2%}); patches of "
             f"{1 / settings['divisions']:.2f} m.", "",
             "| Part | Patches | Ours / Cycles | Ours / Cycles, the panel's back reflecting nothing |", "|---|---|---|---|"]
    lines += [f"| {name} | {n} | {drawn:.4f} | {one_sided:.4f} |" for name, n, drawn, one_sided in rows]
    lines += ["", "Against Cycles with the panel's back reflecting nothing (the product's model) every part",
              "agrees; what is left against Cycles as it draws the box is the light between the ceiling and",
              "the panel's back, which Cycles reflects (R 0.78) and the product absorbs: surfaces here are",
              "one-sided (docs/lights.md)."]
    return "\n".join(lines) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="a smoke run (16 samples, 400,000 paths) into out/")
    args = ap.parse_args(argv)
    samples, paths = (16, 400_000) if args.quick else (256, 4_000_000)
    rows, settings = run(samples, paths, 10)
    out = (ROOT / "out" / "two_sided.md") if args.quick else (RESULTS / "two_sided.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(report(rows, settings))
    print(out.read_text())


if __name__ == "__main__":
    main()
