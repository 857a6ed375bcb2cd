"""Checks of the arrays a scene is made of: errors that name the problem and the patches at fault.

A ValueError (PatchError where particular patches are at fault) for anything the walks cannot
use; warnings for what they can use but the user should know (coincident faces).
"""
from __future__ import annotations

import dataclasses
import warnings

import numpy as np

CHANNELS = 3


# Scenes whose bounding-box diagonal lies outside this range are refused: float32 ray tracing
# and float64 areas stay far from overflow and underflow inside it.
MIN_DIAGONAL, MAX_DIAGONAL = 1e-12, 1e12

# Above this mean reflectivity a finite path takes on average more than 2^24 (16.7 million)
# bounces on the patch's neighbourhood: such a run would never end in practice, so it is refused.
MAX_GREY_REFLECTIVITY = 1.0 - 2.0**-24

# The sources' power over the smallest patch's area (the largest value a patch's estimate can
# carry) is held at most this: its square, summed over millions of patches and divided by
# 1 - R, stays far below float64's largest number (1.8e308).
MAX_POWER_DENSITY = 1e100

# A triangle whose area is below this fraction of diagonal**2 is degenerate.
RELATIVE_DEGENERATE_AREA = 1e-14

# Triangles of one patch must share its orientation: a triangle whose normal is further than
# this (cosine) from the patch's mean normal has the wrong winding or is not coplanar.
MIN_PATCH_NORMAL_COSINE = 0.5


class PatchError(ValueError):
    """A ValueError about particular patches; ``patches`` holds their indices, so that a caller
    that knows where patches came from (the Blender layer) can name the objects instead."""

    def __init__(self, message, patches):
        super().__init__(message)
        self.patches = np.asarray(patches, dtype=np.int64)


def indices_of(mask_or_indices):
    a = np.asarray(mask_or_indices)
    return np.flatnonzero(a) if a.dtype == bool else a


class CoincidentFacesWarning(UserWarning):
    """Triangles lying exactly on top of others; ``patches`` holds the patches involved."""

    def __init__(self, message, patches):
        super().__init__(message)
        self.patches = patches


# Per-triangle keys of warn_coincident are made this many triangles at a time.
BLOCK_TRIANGLES = 1 << 16


def warn_coincident(corners, triangle_patch, block=None):
    """Warn about triangles with exactly the same corners as another (in any order or winding):
    a ray hits one of them at random, so each shows only part of the light it gets.
    ``corners[rows]`` gives the (n,3,3) corners of triangle rows (an array or triangles.UnitCorners)."""
    # A key that does not depend on the corners' order: each corner's projection, sorted, then
    # projected again. Equal triangles get equal keys; neighbours with equal keys are then
    # compared exactly (corners in lexicographic order). O(T log T), no false positives. The
    # keys are made a block of triangles at a time (elementwise: equal corners, equal keys).
    key = np.empty(len(corners))
    block = block or BLOCK_TRIANGLES
    for start in range(0, len(key), block):
        rows = corners[start:start + block]
        a, b, c = (rows[:, k, 0] + 1.37 * rows[:, k, 1] + 1.73 * rows[:, k, 2] for k in range(3))
        low, high = np.minimum(np.minimum(a, b), c), np.maximum(np.maximum(a, b), c)
        middle = np.maximum(np.minimum(a, b), np.minimum(np.maximum(a, b), c))  # exact, order-free
        key[start:start + block] = low + 2.3 * middle + 3.1 * high
    by_key = np.argsort(key, kind="stable")
    candidates = np.flatnonzero(key[by_key[1:]] == key[by_key[:-1]])
    if candidates.size == 0:
        return
    first, second = by_key[candidates], by_key[candidates + 1]

    def canonical(c):
        order = np.lexsort((c[:, :, 2], c[:, :, 1], c[:, :, 0]), axis=-1)
        return np.take_along_axis(c, order[:, :, None], axis=1)

    same = (canonical(corners[first]) == canonical(corners[second])).all(axis=(1, 2))
    if not same.any():
        return
    flagged = np.zeros(len(corners), dtype=bool)
    flagged[first[same]] = True
    flagged[second[same]] = True
    patches = np.unique(triangle_patch[flagged])
    warnings.warn(
        CoincidentFacesWarning(
            f"{int(flagged.sum())} triangles lie exactly on top of others (duplicated faces), on patches "
            f"{indices_text(patches)}: a ray hits one of each pair at random, so each shows only part "
            "of the light (and where they face opposite ways, the one seen from behind absorbs it); "
            "delete the duplicates, or give a two-sided wall some thickness",
            patches,
        ),
        stacklevel=4,
    )


def indices_text(mask_or_indices, limit=10):
    idx = np.flatnonzero(mask_or_indices) if np.asarray(mask_or_indices).dtype == bool else np.asarray(mask_or_indices)
    shown = ", ".join(str(int(i)) for i in idx[:limit])
    more = f" and {idx.size - limit} more" if idx.size > limit else ""
    return f"{shown}{more}"


def _as_channels(values, patch_count, name):
    """(P,) grey or (P,3) RGB -> (P,3) float64, with shape errors that say what was expected."""
    array = np.asarray(values, dtype=np.float64)
    if array.ndim == 1:
        if array.shape[0] != patch_count:
            raise ValueError(f"{name} has {array.shape[0]} values but the scene has {patch_count} patches")
        return np.repeat(array[:, None], CHANNELS, axis=1)
    if array.ndim == 2 and array.shape[1] == CHANNELS:
        if array.shape[0] != patch_count:
            raise ValueError(f"{name} has {array.shape[0]} rows but the scene has {patch_count} patches")
        return np.ascontiguousarray(array)
    raise ValueError(f"{name} must have shape (P,) or (P, 3); got {array.shape}")


def material_rows(reflectivity, emission, triangle_patch):
    """The patch count P the material arrays give, one row per patch. Where reflectivity and
    emission disagree, the one that matches the patches the triangles name is taken, so that
    the error names the array that is short or long."""
    rows = {}
    for name, values in (("reflectivity", reflectivity), ("emission", emission)):
        shape = np.shape(values)
        rows[name] = shape[0] if len(shape) in (1, 2) else None
    if rows["emission"] is None or rows["emission"] == rows["reflectivity"]:
        return rows["reflectivity"]
    tp = np.asarray(triangle_patch)
    named = int(tp.max()) + 1 if tp.size and np.issubdtype(tp.dtype, np.integer) else None
    if named in rows.values():
        return named
    raise ValueError(
        f"reflectivity has {rows['reflectivity']} rows and emission {rows['emission']}: each needs one row per patch"
        + (f" (the triangles name {named} patches)" if named is not None else "")
    )


def validate_materials(reflectivity, emission, patch_count, require_emitter=True):
    """Check reflectivity and emission arrays; return them as (P,3) float64.

    Raises ValueError naming the problem and the offending patch indices.
    """
    R = _as_channels(reflectivity, patch_count, "reflectivity")
    E = _as_channels(emission, patch_count, "emission")
    for name, values in (("reflectivity", R), ("emission", E)):
        bad = ~np.isfinite(values).all(axis=1)
        if bad.any():
            raise PatchError(f"{name} is NaN or infinite on patches {indices_text(bad)}", indices_of(bad))
    negative = (E < 0).any(axis=1)
    if negative.any():
        raise PatchError(f"emission is negative on patches {indices_text(negative)}", indices_of(negative))
    outside = ((R < 0) | (R >= 1)).any(axis=1)
    if outside.any():
        raise PatchError(
            f"reflectivity must lie in [0, 1) but does not on patches {indices_text(outside)} "
            "(a reflectivity of 1 or more creates energy or never lets a path end)",
            indices_of(outside),
        )
    unresolved = R.mean(axis=1) > MAX_GREY_REFLECTIVITY
    if unresolved.any():
        raise PatchError(
            f"reflectivity is within 2^-24 of 1 (mean over channels above {MAX_GREY_REFLECTIVITY:.9f}) on patches "
            f"{indices_text(unresolved)}: a path would take more than 16 million bounces there and would never end "
            "in practice",
            indices_of(unresolved),
        )
    if require_emitter and not (E > 0).any():
        raise ValueError("the scene has no emitting patch: every emission is zero")
    return R, E


def _light_numbers(light, prefix=""):
    """(field, values) of each numeric field of a light (a dataclass; a spot's cone within it)."""
    for item in dataclasses.fields(light):
        value = getattr(light, item.name)
        if dataclasses.is_dataclass(value):
            yield from _light_numbers(value, f"{prefix}{item.name} ")
        elif value is not None and not isinstance(value, (str, bool)):
            yield prefix + item.name, np.asarray(value, dtype=np.float64)


def validate_light_numbers(lights):
    """Check that every number of every light (a sequence of them) is finite: its position,
    direction, size, colour... (ValueError naming the light and the field), before any is used."""
    for light in lights:
        if dataclasses.is_dataclass(light):
            for name, values in _light_numbers(light):
                if not np.isfinite(values).all():
                    raise ValueError(f"light '{light.name}': its {name.replace('_', ' ')} is NaN or infinite")


def validate_lights(lights):
    """Check that every light's power is finite and not negative (ValueError naming it)."""
    validate_light_numbers(lights.lights)
    for light in lights.lights:
        power = np.asarray(light.emitter_powers(lights.aim), np.float64)
        if not np.isfinite(power).all():
            raise ValueError(f"light '{light.name}' has a power that is NaN or infinite")
        if (power < 0).any():
            raise ValueError(f"light '{light.name}' has a negative power (colour or strength)")
    if lights.aim[1] <= 0 or not np.isfinite(lights.aim[1]) or not np.isfinite(lights.aim[0]).all():
        raise ValueError(f"the lights' aim sphere must have a finite centre and a positive radius; got {lights.aim}")



def validate_power_scale(total_power, patch_area):
    """ValueError, in one line, where the sources' power over the smallest patch's area passes
    MAX_POWER_DENSITY: the squares the error estimates are made of would overflow."""
    smallest = float(np.min(patch_area, initial=np.inf, where=patch_area > 0))
    density = total_power / smallest
    if not density <= MAX_POWER_DENSITY:
        raise ValueError(
            f"the sources' power ({total_power:.3g}) over the smallest patch's area ({smallest:.3g}) is {density:.3g}, "
            f"above {MAX_POWER_DENSITY:g}: the squares of the light's estimates would overflow; scale the emission "
            "and the lights' power down (the light is linear in them)")


def _indices(array):
    """Integer indices as int32 (kept: half of int64's memory) or int64."""
    return array if array.dtype == np.int32 else array.astype(np.int64, copy=False)


def validate_mesh(vertices, triangles, triangle_patch, patch_count):
    """Check the mesh arrays; return (V (V,3) float64, T (T,3) and triangle_patch (T,) as int32
    or int64 (int32 as given, without a copy; other integers as int64), centre (3,), diagonal)
    of the bounding box of the vertices the triangles use."""
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3); got {V.shape}")
    if V.shape[0] == 0:
        raise ValueError("the scene has no vertices")
    bad_vertex = ~np.isfinite(V).all(axis=1)
    if bad_vertex.any():
        raise ValueError(f"vertices are NaN or infinite at vertex indices {indices_text(bad_vertex)}")
    T_raw = np.asarray(triangles)
    if T_raw.ndim != 2 or T_raw.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3); got {T_raw.shape}")
    if T_raw.shape[0] == 0:
        raise ValueError("the scene has no triangles")
    if T_raw.shape[0] >= 2**31 or V.shape[0] >= 2**31:
        raise ValueError(f"the scene has {T_raw.shape[0]:,} triangles and {V.shape[0]:,} vertices: at most 2^31 - 1 of each")
    if not np.issubdtype(T_raw.dtype, np.integer):
        raise ValueError(f"triangles must hold integer vertex indices; got dtype {T_raw.dtype}")
    T = _indices(T_raw)
    out_of_range = ((T < 0) | (T >= V.shape[0])).any(axis=1)
    if out_of_range.any():
        raise ValueError(
            f"triangles {indices_text(out_of_range)} use vertex indices outside [0, {V.shape[0]})"
        )
    tp_raw = np.asarray(triangle_patch)
    if tp_raw.shape != (T.shape[0],):
        raise ValueError(f"triangle_patch must have shape ({T.shape[0]},) to match triangles; got {tp_raw.shape}")
    if not np.issubdtype(tp_raw.dtype, np.integer):
        raise ValueError(f"triangle_patch must hold integer patch indices; got dtype {tp_raw.dtype}")
    tp = _indices(tp_raw)
    bad_patch = (tp < 0) | (tp >= patch_count)
    if bad_patch.any():
        raise ValueError(
            f"triangles {indices_text(bad_patch)} name patches outside [0, {patch_count}) "
            f"(the scene has {patch_count} patches, one per row of reflectivity and emission)"
        )

    is_used = np.zeros(V.shape[0], dtype=bool)
    is_used[T.ravel()] = True
    used = V[is_used]
    lo, hi = used.min(axis=0), used.max(axis=0)
    centre = 0.5 * (lo + hi)
    with np.errstate(over="ignore", invalid="ignore"):
        diagonal = float(np.linalg.norm(hi - lo))
    if not diagonal > 0:
        raise ValueError("the scene has no extent: all vertices coincide")
    if not MIN_DIAGONAL <= diagonal <= MAX_DIAGONAL:
        raise ValueError(
            f"the scene's size (bounding-box diagonal {diagonal:.3g}) is outside [{MIN_DIAGONAL:g}, {MAX_DIAGONAL:g}] "
            "scene units: rescale it (radiosity does not depend on the unit of length)"
        )
    return V, T, tp, centre, diagonal
