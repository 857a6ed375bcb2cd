"""Automatic (method="auto"): the two-way iteration where it pays, else the paper's walk.

The two-way iteration pays where its chunks give every patch enough first-generation rays
(``TwoWay.pays``: at error targets that plan at least plan.MIN_MEASURED_CHUNKS such chunks, or
whose chunks grow to them at the stop rule's balance, ``two_way_sizes.balanced_chunk``; under a time
limit, in chunks of the usual size), in a scene of at most AUTO_MAX_PATCHES
patches; elsewhere the walk needs fewer rays to the same error.

It does not pay where the light the sources send lands on few patches (a narrow spot lamp, a
small source in a corner, a lamp a few centimetres from the ceiling): its rays are allotted by
area and reflectivity, so the few patches that reflect most of the light shoot it with few rays,
and its gathered direct light finds a narrow spot's light rarely. ``concentration`` measures that
from rays cast from the sources, and above MAX_CONCENTRATION the walk runs, where it can shoot
every light (a lamp with soft falloff or no shadow is gathered by the walk too, which is no
better).

With per-source results the two-way iteration carries every group's share on every ray, and its
cost grows with the groups while the walk's hardly does (benchmarks/results/relight.md): where
the rule above picks the two-way iteration, a pilot of each with per-source results
(``forecast.measured_choice``, which the solver runs on the candidates ``choose`` names) measures
their time to the same error on this machine, and the cheaper runs (not under a time limit below MEASURED_MIN_SECONDS, which the pilots would eat).
"""
from __future__ import annotations

import numpy as np

from ..estimate.grouping import source_groups
from ..names import EXIT_RANDOM, FINITE, GATHERED, TWO_WAY, WALK
from ..estimate.plan import chunk_plan
from ..scene.rays import cast, leave_random, leave_sources, region_of
from .tables import WalkTables
from .two_way import TwoWay, allotment_weight

# The largest scene Automatic runs the two-way iteration in: a two-way chunk holds several (C,P)
# arrays, and this bound keeps a two-way solve through the operator under 1 GiB, as the walk
# keeps a million patches (docs/performance.md, memory_two_way_sizes.md); the rule was measured
# up to 535,815 patches (benchmarks/results/auto_method.md).
AUTO_MAX_PATCHES = 3 << 17
# With per-source results, the pilots that measure the choice run only under no time limit or one
# of at least this many seconds: they take a few seconds (at most about 18), all of a short limit.
MEASURED_MIN_SECONDS = 60.0
# ... and the walk runs where its measured cost is below the two-way iteration's by this factor:
# the pilots' cost ratio spread by about a quarter over seeds in the Cornell box (the rule's
# choice stays where the two are close).
MEASURED_MARGIN = 1.3
# Above this concentration of the first reflected light the walk runs: in rooms lit by one spot
# lamp the two-way iteration took 0.6-0.9 of the walk's time to 5% at 6.4 (a 75-degree cone) and
# about the same at 10.9 (60 degrees), 3.4x the walk's at 20 (45 degrees), 3.9x at 16 (a point
# lamp 5 cm under the ceiling) and ran to its path cap at 280 (10 degrees); ordinary rooms and
# the Cornell box measure 1.4-4 (benchmarks/results/concentration.md).
MAX_CONCENTRATION = 12.0
# ... measured with this many rays from the sources, from a stream of its own (the scene alone
# decides, whatever the seed).
CONCENTRATION_RAYS = 1 << 13
CONCENTRATION_STREAM = (1 << 62) + 2


def choose(scene, settings):
    """The method (its name) Automatic runs for a solve with ``settings`` (a settings.Settings),
    or, with per-source results where the two-way iteration would otherwise run, the candidates
    (a tuple of names, the rule's first) whose pilots on this machine decide
    (``forecast.measured_choice``, with MEASURED_MARGIN)."""
    if scene.patch_count > AUTO_MAX_PATCHES:
        return WALK
    two_way = TwoWay()
    chunk = chunk_plan(scene, two_way, settings.but(stop_rule=None)).chunk  # (the chunks its run would have)
    if not two_way.pays(scene.patch_count, chunk):
        return WALK
    shoots = settings.direct_light != GATHERED and not scene.lights.gathered_only()
    if shoots and concentration(scene) > MAX_CONCENTRATION:
        return WALK
    groups = settings.groups
    if not settings.per_source or (groups if groups is not None else source_groups(scene)).count <= 1:
        return TWO_WAY  # (one group is the total: nothing more to carry)
    if settings.max_seconds is not None and settings.max_seconds < MEASURED_MIN_SECONDS:
        return TWO_WAY
    return TWO_WAY, WALK


def concentration(scene, rays=CONCENTRATION_RAYS):
    """How much more noise the two-way iteration's first generation shoots the first reflection
    with than rays allotted by its power would: sum_j q_j^2 / w_j, q_j each patch's share of the
    power the sources' light reflects where it first lands and w_j its share of the two-way
    iteration's rays (two_way.allotment_weight). 1 where the light lands as the rays are allotted;
    the patch count over k where it lands evenly on k of them. From ``rays`` rays cast from the
    sources, each landing counted where a ray reflected from its patch meets a front, q_j^2 from
    their counts unbiased (c_j (c_j - 1)); 0 where none lands on a front."""
    tables = WalkTables(scene, FINITE, 1e-3, EXIT_RANDOM)
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(0, spawn_key=(CONCENTRATION_STREAM,))))
    source = tables.sources.sample(rays, rng)
    u = rng.random((tables.uniforms_per_ray, rays), dtype=np.float32)
    with tables.numpy_turn:
        hits = cast(tables, *leave_sources(tables, source, u), region_of(tables, source))
        # Only the reflected light that goes on to a front counts: what a patch sends into back
        # sides (the ceiling over a panel, to its back) or out of the scene adds no patch's noise.
        landed = hits.patch[hits.front]
        u = rng.random((tables.uniforms_per_ray, landed.size), dtype=np.float32)
        goes_on = cast(tables, *leave_random(tables, landed, u), region_of(tables, landed)).front
    counts = np.bincount(landed[goes_on], minlength=scene.patch_count).astype(np.float64)
    reflected = scene.grey_reflectivity * counts
    if rays < 2 or not reflected.sum() > 0:
        return 0.0
    weight = allotment_weight(scene.patch_area, scene.reflectivity.max(axis=1), scene.geometry)
    share = weight / weight.sum()
    lit = counts > 1  # (buried patches, which no ray meets, have no share)
    pairs = np.sum(scene.grey_reflectivity[lit] ** 2 * counts[lit] * (counts[lit] - 1) / share[lit])
    return float(pairs / (rays * (rays - 1)) / (reflected.sum() / rays) ** 2)


def patches_text():
    """AUTO_MAX_PATCHES in words for the panel, e.g. "about 390,000"."""
    return f"about {round(AUTO_MAX_PATCHES, -4):,}"
