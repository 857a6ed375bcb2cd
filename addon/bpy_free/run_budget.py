"""A run's time: the display's colours forecast, and a time limit kept over the whole run.

What the user waits for is the meshing, the solve and the display's colours (the smooth light
with each lamp's and emitter's direct light at the shading mesh's corners, ``core.point_direct``;
the patches' means of the light drawn live). The display's part is forecast by timing its
direct light at a few hundred corners (and patches) drawn at random (``corner_seconds``,
``live_seconds``), plus the smoothing at a measured pace a triangle. Under a time limit the solve
gets what is left of it once the display's forecast is set aside (at least LEAST_SOLVE of what
is left), and the display's retries (corners sampled again where noisy) stop at the limit: the
first samples of every corner are the least it needs and always run.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ..core import methods
from ..core.display import direct_means, live_sources, point_direct
from ..core.lights.lamp_choice import patch_spheres
from ..core.names import GATHERED, TWO_WAY
from ..core.display.sample_rounds import Spent
from ..core.distributed.runners import local_threads
from . import adaptive_patches, options

# The display's cells (bpy_free shown_mesh) over the corners' direct light they add to: at most as many
# new points as the meshes have points, about a quarter of the corners, each sampled again once at most.
CELLS_SHARE = 0.25
PILOT_CORNERS = 512  # patches a pilot of the live light's means times
# Corners a pilot of the display's direct light times: a pass's cost a point falls with its size
# (its blocks' and rounds' own costs), and a pilot of 512 took two to three times the pass's.
CORNER_PILOT = 2048
# Seconds of the display a shading triangle beyond the direct light (the smoothing, the noise
# filter, the polygon corners): 25-110 microseconds in the rooms measured (docs/performance.md).
REST_PER_TRIANGLE = 5e-5
# Of the time left when the solve starts, the least it keeps (the display's retries give way).
LEAST_SOLVE = 0.5
# Of the smoothing's forecast, the share that comes after the direct light (its deadline is
# the run's less this).
AFTER_DIRECT = 0.5


@dataclass(frozen=True)
class Display:
    """The display's forecast seconds: the corners' direct light, the live light's patch means
    (and the lamps' direct means of a per-light run: ``lamp_means_seconds``), the rest (smoothing); ``least`` what it takes at the least (the direct light's first samples
    and the rest: its retries stop at a deadline)."""

    corners: float = 0.0
    live: float = 0.0
    rest: float = 0.0
    least: float = 0.0

    @property
    def seconds(self):
        return self.corners + self.live + self.rest


def corner_seconds(scene, triangles, triangle_patch, seed=0, corners=CORNER_PILOT, light_group=None, patch_group=None,
                   groups=0):
    """(the seconds ``point_direct.corner_direct`` would take at the corners of ``triangles``
    (T,3) of ``triangle_patch`` (T,) (with these groups), those of its first samples alone (the
    least it takes within a deadline)), from the pass timed at up to ``corners`` of them drawn at
    random; (0, 0) where the scene has no direct light to show."""
    if not point_direct.has_direct(scene):
        return 0.0, 0.0
    P = scene.patch_count
    keys = np.unique(np.asarray(triangles, np.int64).ravel() * P + np.repeat(np.asarray(triangle_patch, np.int64), 3))
    chosen = keys[np.sort(np.random.default_rng(seed).choice(keys.size, min(corners, keys.size), replace=False))]
    patch = chosen % P
    position = scene.vertices[chosen // P]
    position += point_direct.INWARD * (patch_spheres(scene)[0][patch] - position)
    spent = Spent()  # (a corner's noise is measured against its patch's light, as the run's: ``solved_light``)
    point_direct.direct_at(scene, position, patch, point_direct.SAMPLES, seed, light_group, patch_group, groups,
                           spent=spent, shown=solved_light(scene)[patch].sum(axis=1))
    return spent.seconds * keys.size / chosen.size, spent.first * keys.size / chosen.size


def live_seconds(scene, seed=0, patches=PILOT_CORNERS):
    """(the seconds ``live_sources.live_means`` would take, those of its first samples alone),
    from it timed at up to ``patches`` patches drawn at random; (0, 0) without live light."""
    if not live_sources.has_live(scene):
        return 0.0, 0.0
    rows = np.sort(np.random.default_rng(seed).choice(scene.patch_count, min(patches, scene.patch_count), replace=False))
    spent = Spent()
    live_sources.live_means(scene, seed=seed, light=solved_light(scene), spent=spent, rows=rows)
    return spent.seconds * scene.patch_count / rows.size, spent.first * scene.patch_count / rows.size


def solved_light(scene):
    """(P,3) a stand-in for each patch's solved light arriving (the run measures a point's noise
    against its patch's irradiance, ``result.irradiance``) before the solve: the mean power a unit
    of area gets, over 1 - R of the mean reflectivity R, as in a closed room (each unit of power
    arrives 1 / (1 - R) times)."""
    R = float(np.average(scene.grey_reflectivity, weights=scene.patch_area))
    return np.full((scene.patch_count, 3), scene.total_power / scene.total_area / max(1.0 - R, 1e-3))


def smooth_made(settings, scene):
    """Whether the run makes smooth colours (the pipeline's rule)."""
    return settings.output == "VERTEX" or (settings.output in ("BOTH", "TEXTURED")
                                           and scene.patch_count <= options.SMOOTH_MAX_PATCHES)


def live_made(settings, scene):
    """Whether the run takes the live light's patch means by their own samples
    (``live_sources.live_means``): live lamps in the textured output, where the solve did not
    gather the direct light apart (the two-way iteration and the gathered walk do)."""
    if settings.output != "TEXTURED" or not settings.live_lamps or not live_sources.has_live(scene):
        return False
    return not gathers(settings, scene)


def gathers(settings, scene):
    """Whether the run's solve gathers its direct light (and keeps it apart)."""
    return settings.method == TWO_WAY or methods.direct_light_for(settings.method, settings.direct_light,
                                                                  scene.lights) == GATHERED


def lamp_means_seconds(scene, settings, groups, seed=0, patches=PILOT_CORNERS):
    """The seconds of the display's direct light of the groups of lamps alone on every patch
    (``direct_means.lamp_means``: one round), from it timed at up to ``patches`` patches drawn at
    random; 0 without per-source groups, a gathered direct light or such a group."""
    if groups is None or not gathers(settings, scene):
        return 0.0
    made = direct_means.lamp_scene(scene, groups.light_group, groups.patch_group(scene.patch_count), groups.count)
    if made is None:
        return 0.0
    rows = np.sort(np.random.default_rng(seed).choice(scene.patch_count, min(patches, scene.patch_count), replace=False))
    spent = Spent()
    direct_means.lamp_means(made, seed, rows=rows, spent=spent)
    return spent.seconds * scene.patch_count / rows.size


def display_forecast(scene, patches, settings, groups=None) -> Display:
    """The Display forecast of a run of ``settings`` (its method resolved) on ``scene`` made of
    ``patches``; ``groups`` the run's per-source groups (each group's lamps sampled apart)."""
    with local_threads(settings.threads):  # (timed on the threads the run's display takes)
        return _forecast(scene, patches, settings, groups)


def _forecast(scene, patches, settings, groups):
    """``display_forecast``'s work."""
    seed = int(settings.seed)
    live, live_least = live_seconds(scene, seed) if live_made(settings, scene) else (0.0, 0.0)
    means = lamp_means_seconds(scene, settings, groups, seed)  # (one round: the least too)
    live, live_least = live + means, live_least + means
    if not smooth_made(settings, scene):
        return Display(live=live, least=live_least)
    shading = adaptive_patches.shading_arrays(patches, scene) or (scene.triangles, scene.triangle_patch)
    apart = {} if groups is None else dict(light_group=groups.light_group,
                                           patch_group=groups.patch_group(scene.patch_count), groups=groups.count)
    corners, least = corner_seconds(scene, *shading, seed=seed, **apart)
    if getattr(settings, "display_cells", False):  # (their new points, and the larger meshes written)
        corners *= 1.0 + CELLS_SHARE
    rest = REST_PER_TRIANGLE * len(shading[0])
    return Display(corners, live, rest, least + live_least + rest)


class Budget:
    """A run's time limit (``max_seconds``, None: none) from ``started`` (a perf_counter
    reading), the display's forecast set aside for it."""

    def __init__(self, started, max_seconds, display=None):
        self.started, self.max_seconds, self.display = started, max_seconds, display or Display()

    @classmethod
    def of(cls, started, limit, scene, patches, settings, groups=None):
        """The Budget of a run started at ``started`` with the time limit ``limit`` (0 or None:
        none): a forecast of its display where it has one."""
        if not limit:
            return cls(started, None)
        return cls(started, limit, display_forecast(scene, patches, settings, groups))

    def solve_seconds(self):
        """The solve's time limit (None: none): what is left less the least the display takes
        (its retries take what the solve leaves), at least LEAST_SOLVE of it."""
        if self.max_seconds is None:
            return None
        left = self.started + self.max_seconds - time.perf_counter()
        return max(left - self.display.least, LEAST_SOLVE * left, 1e-3)

    def deadline(self):
        """The perf_counter reading the display's retries end by (None: none)."""
        if self.max_seconds is None:
            return None
        return self.started + self.max_seconds - AFTER_DIRECT * self.display.rest
