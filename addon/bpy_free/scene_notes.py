"""What the user is told about the patches' scene: the core's errors and warnings naming the
objects of their patches, lights and emitting objects whose light goes nowhere, and light
absorbed on the back of faces (no bpy)."""
from __future__ import annotations

import warnings

import numpy as np

from ..core.scene.diagnostics import back_light, escaping_light, light_fates
from .patches import Patches

#: An object whose emitting faces send at least this share of their light out of the scene
#: (none of it reaching the other objects) gets a warning.
ESCAPING_WARNING = 0.9
#: The most light a source may give, with its reflections: colour attributes are float32, and a hot
#: spot's corners reach several times its patch's mean.
STORABLE_LIGHT = float(np.finfo(np.float32).max) / 16


def objects_of_patches(patches: Patches, indices) -> str:
    """' (objects 'A', 'B')' for the source objects of the given patch indices, or ''."""
    if indices is None or len(indices) == 0:
        return ""
    owners = np.unique(patches.combined.patch_object[np.asarray(indices, dtype=np.int64)])
    names = ", ".join(f"'{patches.objects[k].name}'" for k in owners)
    return f" (in {names})"


def scene_and_notes(patches: Patches):
    """(PatchScene, notes): the core's errors and warnings name the objects of their patches."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            scene = patches.patch_scene()
        except ValueError as exc:
            where = objects_of_patches(patches, getattr(exc, "patches", None))
            raise ValueError(f"{exc}{where}") from exc
    check_storable_light(scene, patches)
    notes = list(patches.notes) + [
        f"{w.message}{objects_of_patches(patches, getattr(w.message, 'patches', None))}"
        for w in caught
        if issubclass(w.category, UserWarning)
    ]
    return scene, notes + escaping_sources(patches, scene) + light_notes(scene)


def check_storable_light(scene, patches):
    """ValueError naming the source whose light, with its reflections (up to 1 / (1 - the largest
    reflectivity) times it), passes what the results' float32 colours hold: emitting faces, area
    lamps, suns and the world (a point lamp's light has no such bound from its power)."""
    gain = 1.0 / (1.0 - float(scene.reflectivity.max(initial=0.0)))
    peak = int(np.argmax(scene.emission.max(axis=1))) if scene.patch_count else 0
    levels = [(float(scene.emission.max(initial=0.0)), f"emission{objects_of_patches(patches, [peak])}")]
    for light in scene.lights.lights:
        for field in ("exitance", "irradiance", "image"):
            value = getattr(light, field, None)
            if value is not None:
                levels.append((float(np.max(value, initial=0.0)), f"light '{light.name}'"))
    level, what = max(levels, key=lambda pair: pair[0])
    if level * gain > STORABLE_LIGHT:
        raise ValueError(f"the {what} is {level:.3g}: with its reflections its light would pass what the results' "
                         f"colours hold ({STORABLE_LIGHT:.3g}); use smaller units of power (the same picture at a "
                         "higher exposure)")


def light_notes(scene) -> list:
    """A note for each light none of whose light reaches the front of a face (inside a closed
    object, or a sun or sky outside a closed room), and for each that casts no shadow."""
    gathered = dict(scene.lights.gathered_only())
    notes = [f"light '{name}' {why} (as Cycles draws it): the direct light of every source is gathered by "
             "shadow rays from each patch, not shot" for name, why in gathered.items()]
    for light, (missed, back) in zip(scene.lights.lights, light_fates(scene)):
        if gathered.get(light.name) == "casts no shadow":  # its light passes through objects
            continue
        if missed + back < 0.999:  # some of it reaches the front of a face
            continue
        if type(light).__name__ in ("SunLight", "WorldLight"):
            if back > 0:
                notes.append(f"light '{light.name}': no light entered; it meets only the outside (the back) of "
                             "the faces, as a sun or sky outside a closed room: the result is dark")
            else:
                notes.append(f"light '{light.name}': none of its light reaches the selection")
        elif back >= ESCAPING_WARNING:
            notes.append(f"light '{light.name}': {back:.0%} of its light meets the back of faces; it sits inside "
                         "a closed object or behind faces")
        else:
            notes.append(f"light '{light.name}': none of its light reaches the front of a face")
    return notes


def escaping_sources(patches: Patches, scene) -> list:
    """A note for each object whose emitting faces send (almost) all their light out of the
    scene: neither side of them sees anything else."""
    emitting, missed = escaping_light(scene)
    if not emitting.size:
        return []
    owner = patches.combined.patch_object[emitting]
    power = scene.patch_power[emitting]
    notes = []
    for k in np.unique(owner):
        share = float(np.average(missed[owner == k], weights=power[owner == k]))
        if share >= ESCAPING_WARNING:
            notes.append(f"'{patches.objects[k].name}' sends {share:.0%} of its light out of the scene: its "
                         "emitting faces see nothing else of the scene from either side (move it nearer the objects "
                         "it should light, or turn it; see Overlays > Face Orientation)")
    return notes


#: Light absorbed on back sides in view of the selection above this share of the power gets a warning.
BLOCKED_WARNING = 0.05
#: The warning names this many (faces' object, source) pairs, the most light first.
BLOCKED_NAMED = 3


def source_label(patches: Patches, scene, row) -> str:
    """What emits source row ``row`` of ``scene.source_power``: "emissive faces of 'Lamp'",
    "sun 'Sun'", "world 'World'", "point light 'Bulb'"..."""
    if row < scene.patch_count:
        return f"emissive faces of '{patches.objects[patches.combined.patch_object[row]].name}'"
    light = scene.lights.lights[scene.lights.light_of[row - scene.patch_count]]
    return f"{light_kind(light)} '{light.name}'"


def light_kind(light) -> str:
    """"point light", "spot light", "area light", "sun" or "world"."""
    if type(light).__name__ == "PointLight":
        return "point light" if getattr(light, "spot", None) is None else "spot light"
    return {"AreaLight": "area light", "SunLight": "sun", "WorldLight": "world"}.get(type(light).__name__, "light")


def back_light_warning(patches: Patches, scene, blocked, seed=0):
    """The warning for light absorbed on back sides (``blocked``: the solve's measured share of
    the power), or None. core.diagnostics.back_light splits it by where it landed: only the share
    that met back sides in view of the selection counts, named by the faces' objects and the
    sources it came from; light that met back sides from outside every receiver (a sky under a
    room's floor) is no concern."""
    if blocked <= BLOCKED_WARNING:
        return None
    receives = np.array([o.receives for o in patches.objects])[patches.combined.patch_object]
    source, patch, weight, in_view = back_light(scene, receives, seed)
    advice = ("one-sided faces seen from behind, or flipped normals (see Overlays > Face Orientation; give thin "
              "walls thickness with a Solidify modifier)")
    if not weight.size:  # the check's rays found none of it: said as measured, without names
        return f"{blocked:.1%} of the light reached the back of faces and was absorbed there: {advice}"
    share = blocked * float(weight[in_view].sum() / weight.sum())
    if share <= BLOCKED_WARNING:
        return None
    owner = patches.combined.patch_object[patch[in_view]]
    # summed per (object, source row) at once; the few distinct pairs then named
    pair_rows, which = np.unique(np.stack([owner, source[in_view]]), axis=1, return_inverse=True)
    pair_weights = np.bincount(which.ravel(), weights=weight[in_view], minlength=pair_rows.shape[1])
    pairs = {}
    for (k, row), w in zip(pair_rows.T.tolist(), pair_weights.tolist()):
        key = (int(k), source_label(patches, scene, int(row)))
        pairs[key] = pairs.get(key, 0.0) + w
    total = sum(pairs.values())
    ranked = sorted(pairs.items(), key=lambda item: -item[1])
    named = [f"faces of '{patches.objects[k].name}' lit by {label} ({share * w / total:.1%})"
             for (k, label), w in ranked[:BLOCKED_NAMED]]
    more = f" and {len(ranked) - BLOCKED_NAMED} more" if len(ranked) > BLOCKED_NAMED else ""
    return (f"{share:.1%} of the light reached the back of faces in view of the selection and was absorbed there: "
            f"{', '.join(named)}{more}; {advice}")
