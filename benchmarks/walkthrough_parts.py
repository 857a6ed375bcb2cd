"""Which light EEVEE draws otherwise: EEVEE's picture of the results taken apart light by light,
against Cycles' direct light of each on the original scene (the walkthrough's interiors and views).

    nice -n 10 .venv/bin/python -m benchmarks.walkthrough_parts --interior skylight_hall   # -> results/walkthrough_parts_<interior>.md

Per interior, in one process: the solve at the panel's defaults (Live lamps), then each view drawn
by EEVEE with one light on at a time (the world, each lamp, the emitting meshes) and with none (the
stored light after a bounce alone, which EEVEE shows as it is), and by Cycles on the original scene
with that light alone and no bounce (its direct light). EEVEE's part of a light is its picture with
that light less the one with none; the light after a bounce is, in Cycles, the reference less every
direct part, in EEVEE the picture with none. Each part is the luminance summed over the surface
pixels of every view, over the reference's (``walkthrough.references``, cached; every light on).
"""
from __future__ import annotations

import argparse
import contextlib
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks import picture as pic  # noqa: E402
from benchmarks import picture_metrics as pm  # noqa: E402
from benchmarks import walkthrough as walking  # noqa: E402
from benchmarks import walkthrough_displays as shown  # noqa: E402
from benchmarks import walkthrough_scenes as scenes  # noqa: E402

NONE = "the light after a bounce"
DIRECT_SAMPLES = 64  # Cycles' direct light alone: little noise, and the parts are sums over many pixels


def light_groups(walk):
    """The lights to take apart: the world where it gives light, each lamp, the emitting meshes."""
    import bpy

    from addon.blender_read.lights import world_gives_light

    groups = ["world"] if world_gives_light(bpy.context.scene) else []
    return groups + list(walk.info.lamps) + (["emitters"] if walk.info.emitters else [])


def emitting_nodes():
    """The Principled nodes that emit: the sources' emitters, and the live result materials' copies."""
    import bpy

    return [node for m in bpy.data.materials if m.node_tree is not None for node in m.node_tree.nodes
            if node.bl_idname == "ShaderNodeBsdfPrincipled" and node.inputs["Emission Strength"].default_value > 0]


@contextlib.contextmanager
def only(walk, group):
    """Every light off but ``group`` (NONE: all off): lamps hidden, the world taken away, the
    emitting materials' strength 0; put back after."""
    import bpy

    scene = bpy.context.scene
    lamps = [(bpy.data.objects[n], bpy.data.objects[n].hide_render) for n in walk.info.lamps]
    emitting = [(n, n.inputs["Emission Strength"].default_value) for n in emitting_nodes()]
    world = scene.world
    for obj, _ in lamps:
        obj.hide_render = obj.name != group
    if group != "world":
        scene.world = None
    if group != "emitters":
        for node, _ in emitting:
            node.inputs["Emission Strength"].default_value = 0.0
    try:
        yield
    finally:
        for obj, hidden in lamps:
            obj.hide_render = hidden
        scene.world = world
        for node, strength in emitting:
            node.inputs["Emission Strength"].default_value = strength


def direct_image(seed):
    """Cycles' direct light on the original scene (no bounce), the lights on now."""
    import bpy

    scene = bpy.context.scene
    pic.show_results(False)
    pic.configure_cycles(scene, DIRECT_SAMPLES, seed=seed)
    scene.cycles.max_bounces = 0
    return pic.render_exr(scene)[0]


def measure(name, views, reference_samples, log=print):
    """Per view: the reference's surface sum and, per kind and group, the picture's surface sum."""
    walk = scenes.build(name, views)
    refs = walking.references(walk, reference_samples, log)
    walking.solve(seed=0)
    groups = light_groups(walk)
    emitters = [walk.info.meshes.index(n) for n in walk.info.emitters]
    out = []
    for k, (view, ref) in enumerate(zip(walk.views, refs)):
        walking.set_view(walk, view)
        mask = pm.surface_mask(ref["object_id"], emitters, ref["lamp"])
        sums = {"reference": float(pm.luminance(0.5 * (ref["first"] + ref["second"]))[mask].sum())}
        for group in [NONE, *groups]:
            with only(walk, group):
                sums[f"eevee|{group}"] = float(pm.luminance(shown.eevee_image()[0])[mask].sum())
                if group != NONE:
                    sums[f"cycles|{group}"] = float(pm.luminance(direct_image(k))[mask].sum())
        out.append(sums)
        log(f"{name}: view {k + 1} taken apart")
    return groups, out


def page(name, groups, views, command):
    """The markdown page: each light's part of the walk in Cycles and in EEVEE."""
    total = {key: sum(v[key] for v in views) for key in views[0]}
    ref = total["reference"]

    def part(kind, group, sums):
        if kind == "eevee":
            return sums[f"eevee|{group}"] - (0.0 if group == NONE else sums[f"eevee|{NONE}"])
        if group == NONE:
            return sums["reference"] - sum(sums[f"cycles|{g}"] for g in groups)
        return sums[f"cycles|{group}"]

    lines = [f"# EEVEE against Cycles, light by light: {name}", "",
             f"`{command}` ({len(views)} views; made by `benchmarks/walkthrough_parts.py`). Each light's direct part of "
             "the picture and the light after a bounce, summed over the surface pixels of every view, over the "
             "reference's sum (every light on). EEVEE: a light's picture alone less the one with no light; the light "
             "after a bounce is the stored light it shows. Cycles: a light's direct light alone on the original scene "
             "(no bounce); the light after a bounce is the reference less those.", "",
             "| light | Cycles' part | EEVEE's part | EEVEE over Cycles |", "|---|---|---|---|"]
    for group in [NONE, *groups]:
        p, e = part("cycles", group, total) / ref, part("eevee", group, total) / ref
        lines.append(f"| {group} | {p:.3f} | {e:.3f} | {e / p if p > 0 else float('nan'):.2f} |")
    e_all = sum(part("eevee", g, total) for g in [NONE, *groups]) / ref
    lines += [f"| all (the sum) | 1.000 | {e_all:.3f} | {e_all:.2f} |", "",
              "View by view, EEVEE's part over Cycles':", "",
              "| view | " + " | ".join([NONE, *groups]) + " |", "|---|" + "---|" * (len(groups) + 1)]
    for k, sums in enumerate(views):
        cells = []
        for group in [NONE, *groups]:
            p, e = part("cycles", group, sums), part("eevee", group, sums)
            cells.append(f"{e / p:.2f}" if p > 1e-3 * sums["reference"] else "-")
        lines.append(f"| {k + 1} | " + " | ".join(cells) + " |")
    return "\n".join(lines + [""])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--interior", default="skylight_hall", choices=scenes.NAMES)
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--reference-samples", type=int, default=1024, help="the walkthrough's (its cache)")
    parser.add_argument("--samples", type=int, default=shown.EEVEE_SAMPLES, help="EEVEE's samples")
    parser.add_argument("--out", type=Path, default=walking.RESULTS)
    args = parser.parse_args(argv)
    shown.EEVEE_SAMPLES = args.samples
    groups, views = measure(args.interior, args.views, args.reference_samples)
    command = "python -m benchmarks.walkthrough_parts " + " ".join(argv if argv is not None else sys.argv[1:])
    path = args.out / f"walkthrough_parts_{args.interior}.md"
    path.write_text(page(args.interior, groups, views, command.strip()))
    print(path.read_text())


if __name__ == "__main__":
    main()
