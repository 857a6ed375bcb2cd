"""The selection read and checked: its objects' arrays, the rest of the scene when asked, the
lamps and the world; bad values in materials refused with a message naming them (bpy)."""

from __future__ import annotations

import numpy as np

from . import SceneError, images, objects as object_reading
from .lights import LightError, read_lights, world_later

#: With "Clamp bright colours" on, reflectivity above this is lowered to it (the random walks
#: need R < 1; without the setting, a base colour of 1 or more is refused).
MAX_REFLECTIVITY = 0.99
#: Reflectivity counted as 1: a white metal's albedo is 1 up to the rounding of its integral.
ONE = 1.0 - 1e-9


def _materials_where(o, bad_faces):
    """Names of the materials of object arrays ``o`` on the faces flagged in ``bad_faces``."""
    slots = np.unique(o.face_slot[bad_faces]) if o.face_slot is not None else []
    return ", ".join(f"'{o.slot_names[k]}'" for k in slots) if len(slots) else "a material"


def read_selection(context, later=False):
    """(objects, notes) for the selected meshes; SceneError for bad input. With ``later``, what
    needs no bpy (the images' pixels converted, the materials' values and their checks, the
    world's sky) is left to ``objects.resolve(notes)``, which a thread may run (the panel's
    estimate's, the run's) and which gives the notes.

    Raises, naming the objects and materials, when nothing usable is selected, when no
    selected face emits, or when materials hold values the solver cannot use: NaN,
    negative colours or strengths, and reflectivity (base colour) of 1 or more -- unless
    the scene's "Clamp bright colours" setting is on, which lowers those to
    MAX_REFLECTIVITY and says so.
    """
    notes = []
    candidates = object_reading.source_objects(context)
    others = object_reading.skipped_objects(context)
    if not candidates and not others:
        raise SceneError("Select one or more mesh objects (result objects in 'Radiosity' do not count)")
    settings = getattr(context.scene, "radiosity", None)
    clamp = bool(getattr(settings, "clamp_reflectivity", False))
    depsgraph = context.evaluated_depsgraph_get()
    with images.one_read():  # (an image is read once however many sockets and objects use it)
        objects = _read_objects(context, depsgraph, candidates, others, settings, notes)
        lights, world = _read_lights(context, depsgraph, notes)
    groups = {o.session_uid: o.lightgroup for o in context.view_layer.objects}
    for o in objects:  # (an instance takes its parent's light group)
        o.lightgroup = groups.get(o.uid, "") or ""
    labels = light_labels(context, lights) + ((getattr(context.scene.world, "lightgroup", "") or None,) if world else ())
    selection = Selection(objects, lights, labels)
    selection.pending = (clamp, world)
    return (selection, notes) if later else (selection, selection.resolve(notes))


def _read_objects(context, depsgraph, candidates, others, settings, notes):
    """The arrays of the selected objects, their instances and (when asked) the rest of the
    scene; SceneError when none of the selection has faces."""
    objects = []
    for obj in candidates:
        arrays = object_reading.read_object(obj, depsgraph, notes)
        if arrays is not None:
            objects.append(arrays)
    # Instances (collection instances, geometry nodes, instancing on vertices or faces) are
    # realised: each instance is read as an object of its own.
    instances = object_reading.read_instances([*candidates, *others], depsgraph, notes)
    objects.extend(instances)
    receivers = len(objects)
    if getattr(settings, "use_scene_objects", False) and objects:
        objects.extend(object_reading.read_rest_of_scene(context, depsgraph, notes))
    instancers = {o.uid for o in instances}
    skipped = [o for o in others if o.session_uid not in instancers]
    if not receivers:
        if skipped and not candidates:
            raise SceneError("No mesh among the selected objects: "
                             + "; ".join(object_reading.describe(o) for o in skipped))
        raise SceneError("The selected mesh objects have no faces")
    for o in skipped:
        notes.append(object_reading.describe(o) + ": skipped")
    return objects


def _check_materials(o, clamp, notes):
    """SceneError for colours the solver cannot use on object arrays ``o``; with ``clamp``,
    reflectivity above MAX_REFLECTIVITY lowered to it (said so)."""
    for name, values in (("base colour", o.face_reflectivity), ("emission", o.face_emission)):
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            raise SceneError(f"'{o.name}': the {name} of material {_materials_where(o, bad)} is not a "
                             "finite number (NaN or infinite, from a driver or a script?)")
    bad = (o.face_emission < 0).any(axis=1)
    if bad.any():
        raise SceneError(f"'{o.name}': material {_materials_where(o, bad)} has a negative emission "
                         "(colour or strength)")
    bad = (o.face_reflectivity < 0).any(axis=1)
    if bad.any():
        raise SceneError(f"'{o.name}': material {_materials_where(o, bad)} has a negative base colour")
    bright = (o.face_reflectivity >= ONE).any(axis=1)
    if bright.any() and not clamp:
        value = float(o.face_reflectivity[bright].max())
        raise SceneError(
            f"'{o.name}': material {_materials_where(o, bright)} has a reflectivity (base colour, with what a "
            f"Principled BSDF's other layers return) of {value:.3g}. "
            "Radiosity needs a reflectivity below 1: a surface that reflects all the light it gets "
            "never lets a random walk end in a closed room (and above 1 it creates light). "
            f"Lower the base colour below 1, or turn on 'Clamp bright colours' to use {MAX_REFLECTIVITY}"
        )
    o.slot_textures = _checked_textures(o, clamp, notes)
    over = (o.face_reflectivity > MAX_REFLECTIVITY).any(axis=1)
    if over.any() and clamp:
        notes.append(f"'{o.name}': reflectivities of material {_materials_where(o, over)} above "
                     f"{MAX_REFLECTIVITY} were clamped to {MAX_REFLECTIVITY} ('Clamp bright colours' is on)")
        o.face_reflectivity = np.minimum(o.face_reflectivity, MAX_REFLECTIVITY)


def _read_lights(context, depsgraph, notes):
    """The core's light sources of the scene's lamps, and its world's (lights.world_later) or None."""
    try:
        return read_lights(depsgraph, notes), world_later(context.scene, notes)
    except LightError as exc:
        raise SceneError(str(exc)) from exc


def _checked_textures(o, clamp, notes):
    """The object's textures with the base colour's rules: finite and not negative, below 1
    unless 'Clamp bright colours' lowers them to MAX_REFLECTIVITY (said so)."""
    for slot, colours in enumerate(o.slot_colours):
        if colours is not None:
            where = f"'{o.name}': the colour attribute of material '{o.slot_names[slot]}'"
            if not np.isfinite(colours).all() or (colours < 0).any():
                raise SceneError(f"{where} has colours that are negative or not finite")
            if colours.max() >= ONE and not clamp:
                raise SceneError(f"{where} has colours of {float(colours.max()):.3g}: a reflectivity needs to stay "
                                 f"below 1. Darken them, or turn on 'Clamp bright colours' to use {MAX_REFLECTIVITY}")
    if clamp:
        o.slot_colours = tuple(None if c is None else np.minimum(c, MAX_REFLECTIVITY) for c in o.slot_colours)
    for slot, texture in enumerate(o.slot_emission_textures):
        if texture is not None and (not np.isfinite(texture[0]).all() or (texture[0] < 0).any() or texture[3] < 0):
            raise SceneError(f"'{o.name}': the emission texture of material '{o.slot_names[slot]}' has pixels or a "
                             "strength that are negative or not finite")
    checked = []
    for slot, texture in enumerate(o.slot_textures):
        if texture is not None:
            pixels, affine, uv = texture
            where = f"'{o.name}': the image texture of material '{o.slot_names[slot]}'"
            if not np.isfinite(pixels).all() or (pixels < 0).any():
                raise SceneError(f"{where} has pixels that are negative or not finite")
            if pixels.max() >= ONE:
                if not clamp:
                    raise SceneError(f"{where} has pixels of {float(pixels.max()):.3g} (as reflectivity, with what a "
                                     "Principled BSDF's other layers return): a reflectivity needs to "
                                     "stay below 1. Darken the image, or turn on 'Clamp bright colours' to use "
                                     f"{MAX_REFLECTIVITY}")
                notes.append(f"{where}: pixels above {MAX_REFLECTIVITY} were clamped ('Clamp bright colours' is on)")
                pixels = np.minimum(pixels, MAX_REFLECTIVITY)
            texture = (pixels, affine, uv)
        checked.append(texture)
    return tuple(checked)


def light_labels(context, lights):
    """Each light's Blender light group (the world's for the world), None where it has none."""
    from ..core.lights.lights import WorldLight

    def group(light):
        owner = context.scene.world if isinstance(light, WorldLight) else context.scene.objects.get(light.name)
        return getattr(owner, "lightgroup", "") or None

    return tuple(group(light) for light in lights)


class Selection(list):
    """The selected objects' arrays (a list of ObjectArrays), with the lights that light them
    (``lights``: the core's light sources of the scene's lamps and world) and their light groups
    (``light_labels``, None where a light has none)."""

    def __init__(self, objects=(), lights=(), light_labels=None):
        super().__init__(objects)
        self.lights = tuple(lights)
        self.light_labels = tuple(light_labels) if light_labels is not None else (None,) * len(self.lights)
        self.pending = None  # read_selection(later=True): ('Clamp bright colours', the world's maker or None)

    def resolve(self, notes=()):
        """The read's notes (``notes`` and those found here, merged), the objects given their
        materials' values and checked, the world's light made: no bpy, any thread (the images'
        pixels converted here). SceneError for bad input (naming it, as ``read_selection``)."""
        notes = list(notes)
        if self.pending is not None:
            clamp, world = self.pending
            memo = {}  # (a texture scaled by the same terms for two objects is made once)
            for o in self:
                object_reading.with_materials(o, notes, memo)
                _check_materials(o, clamp, notes)
            if world is not None:
                try:
                    self.lights += (world(),)
                except LightError as exc:
                    raise SceneError(str(exc)) from exc
            if not self.lights and not any(np.any(o.face_emission > 0) for o in self):
                raise SceneError(
                    "No emitter among the selected objects (nor the rest of the scene) and no light: give a "
                    "material an emission strength > 0 (Principled BSDF 'Emission Strength' or an Emission "
                    "shader), add a light, or give the world a colour")
            self.pending = None
        # unique notes, in order; materials' Principled notes that say the same thing as one
        return merged_notes(list(dict.fromkeys(notes)))


def merged_notes(notes):
    """The notes with those of several materials that say the same thing about a Principled
    BSDF joined into one naming them all, at the first one's place."""
    out, names = [], {}
    for note in notes:
        name, _, tail = note[len("material '"):].partition("': Principled ")
        if not (note.startswith("material '") and tail):
            out.append(note)
        elif tail in names:
            names[tail].append(f"'{name}'")
        else:
            names[tail] = [f"'{name}'"]
            out.append((tail,))
    return [item if isinstance(item, str) else f"material{'s' * (len(names[item[0]]) > 1)} "
            f"{', '.join(names[item[0]])}: Principled {item[0]}" for item in out]
