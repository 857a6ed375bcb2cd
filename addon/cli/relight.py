"""The command line's ``--relight``: a saved file's per-light results recombined with new
strengths and colours (``--strength NAME=VALUE``, ``--colour NAME=R,G,B``; a lamp, the world or
an emissive material by name), no ray traced, then saved as a solve's results are (bpy,
imported where used)."""

from __future__ import annotations


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


def apply(scene, strengths, colours):
    """Sets each named source's strength and colour; ValueError naming one that is not a lamp, the
    world or an emissive material (nothing changed then)."""
    import bpy

    from ..blender_read.sources import _background
    from ..blender_read.materials import _EMISSION, _shader_node

    targets = {}
    for name in {**strengths, **colours}:
        obj = scene.objects.get(name)
        world = scene.world if scene.world is not None and scene.world.name == name else None
        material = bpy.data.materials.get(name)
        node = _shader_node(material) if material is not None else None
        if obj is not None and obj.type == "LIGHT":
            targets[name] = (obj.data, "energy", "color")
        elif world is not None and _background(world) is not None:
            background = _background(world)
            targets[name] = (background.inputs["Strength"], "default_value", (background.inputs["Color"], "default_value"))
        elif node is not None and node.bl_idname in _EMISSION:
            colour, strength = (node.inputs[n] for n in _EMISSION[node.bl_idname])
            targets[name] = (strength, "default_value", (colour, "default_value"))
        else:
            raise ValueError(f"no lamp, world or emissive material named {name!r} in the scene")
    for name, (owner, strength, colour) in targets.items():
        if name in strengths:
            setattr(owner, strength, strengths[name][0])
        if name in colours:
            holder, attribute = (owner, colour) if isinstance(colour, str) else colour
            current = tuple(getattr(holder, attribute))
            setattr(holder, attribute, colours[name] + current[3:])


def run(args):
    """Relights the open file's scene as the arguments say; returns the one-line outcome or
    raises ValueError."""
    import bpy

    from ..ui import relight as relight_ui

    scene = bpy.context.scene
    strengths = parse_pairs(args.strength, "strength", 1)
    colours = parse_pairs(args.colour, "colour", 3)
    relight_ui.assess(scene)  # (no per-light results: said before anything changes)
    apply(scene, strengths, colours)
    bpy.context.evaluated_depsgraph_get()
    outcome = relight_ui.relight(scene)
    return outcome.text()


def solved_objects():
    """The objects the results were solved for (the preview hides them)."""
    import bpy

    from ..blender_write.relight_store import meta_of

    scene = bpy.context.scene
    return [scene.objects[name] for name in (meta_of(scene) or {}).get("selected", ()) if name in scene.objects]
