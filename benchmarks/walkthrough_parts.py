"""Which light EEVEE draws otherwise: EEVEE against the product's own Cycles preview, light by
light, on the same results (the walkthrough's interiors and views).

    nice -n 10 .venv/bin/python -m benchmarks.walkthrough_parts --interior skylight_hall   # -> results/walkthrough_parts_<interior>.md

Per interior, in one process: the solve at the panel's defaults (Live lamps), then each view drawn
by EEVEE and by the product's preview with one light on at a time (the world, each lamp, the
emitting meshes) and with none (the solved light alone, which both draw). A light's part of a
picture is its picture less the one with none: its luminance summed over the surface pixels, over
the reference's (``walkthrough.references``, cached; the reference has every light on). The preview
draws the lights as Cycles does (its brightness and objects within a few percent of the reference:
``walkthrough_<interior>.md``), so EEVEE's part over the preview's says how EEVEE draws that light.
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

NONE = "none (the solved light alone)"
KINDS = {"eevee": shown.eevee_image, "preview": lambda: shown.preview_image(walking.SIZE[0])}


def light_groups(walk):
    """The lights to take apart: the world where it gives light, each lamp, the emitting meshes."""
    import bpy

    from addon.blender_read.lights import world_gives_light

    groups = ["world"] if world_gives_light(bpy.context.scene) else []
    return groups + list(walk.info.lamps) + (["emitters"] if walk.info.emitters else [])


def emitting_nodes():
    """The Principled nodes of the live result materials that emit (their own shader lights the others)."""
    import bpy

    from addon.blender_write.materials import LIVE_EMITS_PROPERTY

    return [node for m in bpy.data.materials if m.get(LIVE_EMITS_PROPERTY) and m.node_tree is not None
            for node in m.node_tree.nodes if node.bl_idname == "ShaderNodeBsdfPrincipled"]


@contextlib.contextmanager
def only(walk, group):
    """Every light off but ``group`` (NONE: all off): lamps hidden, the world taken away, the
    emitting result materials' strength 0; put back after."""
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
        for kind, draw in KINDS.items():
            for group in [NONE, *groups]:
                with only(walk, group):
                    sums[f"{kind}|{group}"] = float(pm.luminance(draw()[0])[mask].sum())
        out.append(sums)
        log(f"{name}: view {k + 1} taken apart")
    return groups, out


def page(name, groups, views, command):
    """The markdown page: each light's part of the walk in the preview and in EEVEE."""
    total = {key: sum(v[key] for v in views) for key in views[0]}
    ref = total["reference"]

    def part(kind, group, sums):
        return sums[f"{kind}|{group}"] - (0.0 if group == NONE else sums[f"{kind}|{NONE}"])

    lines = [f"# EEVEE against the preview, light by light: {name}", "",
             f"`{command}` ({len(views)} views; made by `benchmarks/walkthrough_parts.py`). Each light's part of the "
             "picture (its picture less the one with every light off), summed over the surface pixels of every view, "
             "over the reference's sum (every light on); the preview draws the lights as Cycles does.", "",
             "| light | the preview's part | EEVEE's part | EEVEE over the preview |", "|---|---|---|---|"]
    for group in [NONE, *groups]:
        p, e = part("preview", group, total) / ref, part("eevee", group, total) / ref
        lines.append(f"| {group} | {p:.3f} | {e:.3f} | {e / p if p > 0 else float('nan'):.2f} |")
    p_all = sum(part("preview", g, total) for g in [NONE, *groups]) / ref
    e_all = sum(part("eevee", g, total) for g in [NONE, *groups]) / ref
    lines += [f"| all (the sum) | {p_all:.3f} | {e_all:.3f} | {e_all / p_all:.2f} |", "",
              "View by view, EEVEE's part over the preview's:", "",
              "| view | " + " | ".join(groups) + " |", "|---|" + "---|" * len(groups)]
    for k, sums in enumerate(views):
        cells = []
        for group in groups:
            p, e = part("preview", group, sums), part("eevee", group, sums)
            cells.append(f"{e / p:.2f}" if p > 1e-3 * sums["reference"] else "-")
        lines.append(f"| {k + 1} | " + " | ".join(cells) + " |")
    return "\n".join(lines + [""])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--interior", default="skylight_hall", choices=scenes.NAMES)
    parser.add_argument("--views", type=int, default=10)
    parser.add_argument("--reference-samples", type=int, default=1024, help="the walkthrough's (its cache)")
    parser.add_argument("--samples", type=int, default=16, help="EEVEE's and the preview's samples (the parts are sums "
                        "over many pixels)")
    parser.add_argument("--out", type=Path, default=walking.RESULTS)
    args = parser.parse_args(argv)
    shown.EEVEE_SAMPLES = pic.PREVIEW_SAMPLES = args.samples
    groups, views = measure(args.interior, args.views, args.reference_samples)
    command = "python -m benchmarks.walkthrough_parts " + " ".join(argv if argv is not None else sys.argv[1:])
    path = args.out / f"walkthrough_parts_{args.interior}.md"
    path.write_text(page(args.interior, groups, views, command.strip()))
    print(path.read_text())


if __name__ == "__main__":
    main()
