"""The walk's speed-ups: each named, chosen for a scene in one place, and switchable one by one.

None of them changes what a walk estimates. Most change no bit of the result either (grids,
patch classes, sorted paths, grouped chunks trace and score the same rays in another order or
layout); the interchangeable and counted walks pair the same random numbers with paths in
another order, so they give another sample of the same estimator. ``docs/performance.md`` says
what each one buys.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace

from ..names import EXIT_RANDOM, FINITE

# Interchangeable paths are counted per patch (one bincount a step) in scenes of at most this
# many patches; above it the bincount's pass over the patches costs more than a sort.
COUNTED_MAX_PATCHES = 1 << 12
# Paths that carry weights or hit points go on sorted by patch in scenes of at least this many
# patches (below it every table fits in cache and the sort gains nothing).
SORT_MIN_PATCHES = 1 << 13
# Patch classes pay where the per-patch tables outgrow the caches.
CLASSES_MIN_PATCHES = 1 << 13


@dataclass(frozen=True)
class Speedups:
    """Which speed-ups a walk uses. None: chosen for the scene (:meth:`resolve`); True or
    False: on (where the scene and walk allow it) or off."""

    interchangeable: bool | None = None  # grey finite random-exit paths are only their patch
    counted: bool | None = None          # ... and counted per patch and outcome each step
    sorted_paths: bool | None = None     # other walks go on grouped by patch each step
    patch_classes: bool | None = None    # frames and R_bar read per class of alike patches
    grids: bool | None = None            # Embree traces the grids patches tile, not their triangles
    grouped_chunks: bool | None = None   # small chunks traced together as one wavefront

    def resolve(self, scene, estimator, exit_point):
        """These speed-ups with every None chosen for ``scene`` and the walk (all bool)."""
        geometry = scene.geometry
        P = scene.patch_count

        def choose(name, allowed, wanted):
            forced = getattr(self, name)
            return bool(allowed and (wanted if forced is None else forced))

        interchangeable = choose("interchangeable", estimator == FINITE and scene.is_grey and exit_point == EXIT_RANDOM, True)
        return Speedups(
            interchangeable=interchangeable,
            counted=choose("counted", interchangeable, P <= COUNTED_MAX_PATCHES),
            sorted_paths=choose("sorted_paths", not interchangeable, P >= SORT_MIN_PATCHES),
            patch_classes=choose("patch_classes", geometry.all_parallelograms, P >= CLASSES_MIN_PATCHES),
            grids=choose("grids", self.grids is not False and geometry.patch_grids is not None, True),
            grouped_chunks=choose("grouped_chunks", True, True),
        )

    def without(self, name):
        """These speed-ups with ``name`` off (a walk found the scene does not allow it)."""
        return replace(self, **{name: False})

    def names_on(self):
        """The names of the speed-ups that are on."""
        return tuple(f.name for f in fields(self) if getattr(self, f.name))
