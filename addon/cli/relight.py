"""The command line's ``--relight``: a saved file's per-light results recombined with new
strengths and colours (``--strength NAME=VALUE``, ``--colour NAME=R,G,B``; a lamp, the world or
an emissive material by name), no ray traced, then saved as a solve's results are (bpy,
imported where used)."""

from __future__ import annotations

import os


def parse_pairs(values, what, width):
    """{name: tuple of ``width`` floats} of NAME=VALUE arguments; ValueError in one line."""
    out = {}
    for text in values or ():
        name, sep, value = text.rpartition("=")
        try:
            numbers = tuple(float(v) for v in value.split(","))
        except ValueError:
            numbers = ()
        if not sep or not name or len(numbers) != width or not all(n == n and n >= 0 and n != float("inf")
                                                                    for n in numbers):
            form = "NAME=VALUE" if width == 1 else "NAME=R,G,B"
            raise ValueError(f"--{what} takes {form} with finite values of at least 0; got {text!r}")
        out[name] = numbers
    return out


# An unknown name's message lists at most this many of the names that work (a line stays readable).
LISTED_NAMES = 10


def apply(scene, strengths, colours, known=()):
    """Sets each named source's strength and colour; ValueError naming one that is not a lamp, the
    world or an emissive material, and listing the ``known`` names (nothing changed then)."""
    import bpy

    from ..blender_read.sources import background_node
    from ..blender_read.materials import EMISSION, shader_node

    targets = {}
    for name in {**strengths, **colours}:
        obj = scene.objects.get(name)
        world = scene.world if scene.world is not None and scene.world.name == name else None
        material = bpy.data.materials.get(name)
        node = shader_node(material) if material is not None else None
        if obj is not None and obj.type == "LIGHT":
            targets[name] = (obj.data, "energy", "color")
        elif world is not None and background_node(world) is not None:
            background = background_node(world)
            targets[name] = (background.inputs["Strength"], "default_value", (background.inputs["Color"], "default_value"))
        elif node is not None and node.bl_idname in EMISSION:
            colour, strength = (node.inputs[n] for n in EMISSION[node.bl_idname])
            targets[name] = (strength, "default_value", (colour, "default_value"))
        else:
            raise ValueError(f"no lamp, world or emissive material named {name!r} in the scene{listed(known)}")
    for name, (owner, strength, colour) in targets.items():
        if name in strengths:
            setattr(owner, strength, strengths[name][0])
        if name in colours:
            holder, attribute = (owner, colour) if isinstance(colour, str) else colour
            current = tuple(getattr(holder, attribute))
            setattr(holder, attribute, colours[name] + current[3:])


def listed(names):
    """"; the solve's sources: 'A', 'B', ... and N more" for ``names`` (nothing for none)."""
    names = sorted(set(names), key=str.casefold)
    if not names:
        return ""
    shown = ", ".join(repr(n) for n in names[:LISTED_NAMES])
    more = len(names) - LISTED_NAMES
    return f"; the solve's sources: {shown}" + (f" and {more} more" if more > 0 else "")


def run(args):
    """Relights the open file's scene as the arguments say; returns the one-line outcome or
    raises ValueError (nothing relit) where the results cannot follow the change."""
    import bpy

    from ..ui import relight as relight_ui

    scene = bpy.context.scene
    strengths = parse_pairs(args.strength, "strength", 1)
    colours = parse_pairs(args.colour, "colour", 3)
    meta = relight_ui.assess(scene).meta  # (no per-light results: said before anything changes)
    apply(scene, strengths, colours, [member[1] for group in meta["members"] for member in group])
    bpy.context.evaluated_depsgraph_get()
    problem = cannot_follow(relight_ui.assess(scene, meta), args.open or bpy.data.filepath)
    if problem:
        raise ValueError(problem)
    return relight_ui.relight(scene).text()


def cannot_follow(outcome, path=""):
    """One line saying why the results cannot be relit to the scene as it is (the panel marks
    these stale for Update; here only a new solve of the file ``path`` helps), or None."""
    again = f"solve again (--open {os.path.basename(path) or 'FILE'} without --relight)"
    names = lambda groups: ", ".join(sorted(groups))  # noqa: E731
    if outcome.added:
        return f"{names(outcome.added)}: light the solve did not have (off, dark or absent then) cannot be relit: {again}"
    if outcome.unsolved:
        return f"{names(outcome.unsolved)}: a colour channel solved dark is lit now and cannot be relit: {again}"
    if outcome.unmeasured:
        return (f"{names(outcome.unmeasured)} had too few of the solve's paths (light in fewer than 2 batches) to be "
                f"relit to this share of the light: {again}")
    if outcome.stale:
        return f"{names(outcome.stale)} changed since the solve (moved, reshaped, or the geometry changed): {again}"
    return None


def solved_objects():
    """The objects the results were solved for (the preview hides them)."""
    import bpy

    from ..blender_write.relight_store import meta_of

    scene = bpy.context.scene
    return [scene.objects[name] for name in (meta_of(scene) or {}).get("selected", ()) if name in scene.objects]
