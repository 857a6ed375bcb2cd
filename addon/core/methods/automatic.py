"""Automatic (method="auto"): the two-way iteration where it pays, else the paper's walk.

The two-way iteration pays where its chunks give every patch enough first-generation rays
(``TwoWay.pays``: at error targets that plan at least plan.MIN_MEASURED_CHUNKS such chunks, or
whose chunks grow to them at the stop rule's balance, ``two_way.balanced_chunk``; under a time
limit, in chunks of the usual size), in a scene of at most AUTO_MAX_PATCHES
patches; elsewhere the walk needs fewer rays to the same error.

With per-source results the two-way iteration carries every group's share on every ray, and its
cost grows with the groups while the walk's hardly does (benchmarks/results/relight.md): where
the rule above picks the two-way iteration, a pilot of each with per-source results
(``forecast.measured_choice``) measures their time to the same error on this machine, and the
cheaper runs (not under a time limit below MEASURED_MIN_SECONDS, which the pilots would eat).
"""
from __future__ import annotations

from ..grouping import source_groups
from ..names import FINITE, TWO_WAY, WALK
from ..plan import chunk_plan
from .two_way import TwoWay

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


def choose(scene, estimator=FINITE, *, paths=None, target_mse=None, threshold=1e-3, max_seconds=None, per_source=False,
           **pilot):
    """The method (its name) Automatic runs for a solve with these arguments; with
    ``per_source``, measured where the two-way iteration would otherwise run (``pilot``: the
    solve's groups, direct_light, exit_point, sampling, threads, seed for the pilots)."""
    if scene.patch_count > AUTO_MAX_PATCHES:
        return WALK
    two_way = TwoWay()
    chunk = chunk_plan(scene, two_way, estimator, paths=paths, target_mse=target_mse, threshold=threshold,
                       max_seconds=max_seconds).chunk  # (the chunks its run would have)
    if not two_way.pays(scene.patch_count, chunk):
        return WALK
    groups = pilot.get("groups")
    if not per_source or (groups if groups is not None else source_groups(scene)).count <= 1:
        return TWO_WAY  # (one group is the total: nothing more to carry)
    if max_seconds is not None and max_seconds < MEASURED_MIN_SECONDS:
        return TWO_WAY
    from ..forecast import measured_choice  # (the forecast runs solves)

    return measured_choice(scene, estimator, (TWO_WAY, WALK), paths=paths, target_mse=target_mse, threshold=threshold,
                           max_seconds=max_seconds, per_source=True, margin=MEASURED_MARGIN, **pilot)[0]


def patches_text():
    """AUTO_MAX_PATCHES in words for the panel, e.g. "about 390,000"."""
    return f"about {round(AUTO_MAX_PATCHES, -4):,}"
