"""Small chunks traced together (walk.walk_chunks): every chunk keeps its own accounts and
stays an independent batch.

A group of chunks is traced as one wavefront, each path tagged with its chunk. Mixing up the
tags would move paths, rays, hits or weight between chunks; these tests give the chunks of one
group very different sizes, and chunks of one path that cannot leave their box, so that any
such mix-up shows. Every way the walk keeps its live paths is covered.
"""
import math

import numpy as np
import pytest

from addon.core import PatchScene, Speedups, solve
from addon.core.estimate import plan
from addon.core.distributed import runners
from addon.core.methods import walk as walk_method
from addon.core.methods.tables import WalkTables
from addon.core.methods.walk import walk_chunk, walk_chunks
from addon.core.estimate.reference import path_variances
from boxes import box_rectangles, box_scene, open_box_with_card, rectangles_to_mesh

Z = 4.5  # two-sided normal bound, about 7e-6 per test (several per test, all far apart)
SIZES = [700, 30_000, 3_000, 128]
THRESHOLD = 1e-3
# The grey finite walk leaving from random points has interchangeable paths, kept as counts per
# chunk and patch, as arrays after a count (stratified first rays), or as sorted keys (bigger
# scenes; forced here). Other walks keep arrays of what each path carries, sorted by patch in
# bigger scenes (forced here too).
KINDS = {
    "counts": ("finite", "random", {}),
    "arrays": ("finite", "random", {"stratified": True}),
    "sorted": ("finite", "random", {"counted": False}),
    "finite hit": ("finite", "hit", {}),
    "biased": ("biased_infinite", "random", {}),
    "biased hit sorted": ("biased_infinite", "hit", {"sorted_paths": True}),
    "colour": ("finite", "random", {"colour": True}),
    "colour biased sorted": ("biased_infinite", "random", {"colour": True, "sorted_paths": True}),
    "finite paths": ("finite", "random", {"interchangeable": False}),
}
INTERCHANGEABLE = ("counts", "arrays", "sorted")
COLOUR = np.array([0.05, 0.0, -0.05])  # added to a grey reflectivity: the same mean


def _tables(kind, scene):
    """The kind's walk tables on a grey scene (made colour, same mean reflectivity, for the
    colour kinds)."""
    estimator, exit_point, options = KINDS[kind]
    if options.get("colour"):
        scene = scene.with_materials(scene.reflectivity[:, :1] + COLOUR, scene.emission[:, :1] * [1.0, 0.5, 0.25])
    sampling = "stratified" if options.get("stratified") else "independent"
    speedups = Speedups(**{k: v for k, v in options.items() if k in ("interchangeable", "counted", "sorted_paths")})
    return scene, WalkTables(scene, estimator, THRESHOLD, exit_point, sampling, speedups)


def _closed_box(kind, R, n=3):
    scene, _, _ = box_scene([R] * 6, [0, 1.0, 0, 0, 0, 0], n=n)
    return _tables(kind, scene)


def _balanced(t):
    """Every unit of weight a chunk's paths started with ended somewhere."""
    np.testing.assert_allclose(t.emitted, t.absorbed + t.escaped + t.blocked + t.undistributed, rtol=1e-10)


@pytest.mark.parametrize("kind", KINDS)
def test_each_chunk_of_a_group_has_its_own_paths_and_rays(kind):
    """Closed box, R = 0.6 everywhere (on average over the channels): each chunk's paths all
    end absorbed (finite: its rays per path are geometric with mean 1 / (1 - R)) or at the
    threshold (biased: 14 rays each, 0.6^14 < 1e-3 < 0.6^13), its rays are its hits, and its
    weight balances."""
    R = 0.6
    scene, tables = _closed_box(kind, R)
    tallies = walk_chunks(tables, SIZES, np.random.default_rng(11))
    assert len(tallies) == len(SIZES)
    finite = tables.estimator == "finite"
    for n, t in zip(SIZES, tallies):
        assert t.paths == n
        assert t.ended == {"escaped": 0, "blocked": 0, "absorbed": n if finite else 0, "threshold": 0 if finite else n}
        assert t.incident.shape == (tables.channels, scene.patch_count)
        # (scores may be kept as counts, but a tally is float64, each its own array)
        assert t.incident.dtype == np.float64 and t.incident.flags.c_contiguous and t.incident.flags.owndata
        if tables.channels == 1 and finite:
            assert t.emitted[0] == n and t.incident.sum() == t.rays  # every ray of a closed box scores once
        _balanced(t)
        if finite:
            length_sd = math.sqrt(R) / (1 - R) / math.sqrt(n)
            assert abs(t.rays / n - 1 / (1 - R)) < Z * length_sd, (n, t.rays / n)
        else:
            assert t.rays == 14 * n


@pytest.mark.parametrize("kind", KINDS)
def test_each_chunk_of_a_group_balances_escapes_and_back_hits(kind):
    """Open box with a card hit from behind: every chunk's paths end once (absorbed, escaped,
    blocked or at the threshold), its weight balances, and its share of escaped paths matches
    the group's (a binomial proportion per chunk)."""
    _, tables = _tables(kind, open_box_with_card())
    tallies = walk_chunks(tables, SIZES, np.random.default_rng(12))
    escaped = sum(t.ended["escaped"] for t in tallies) / sum(SIZES)
    for n, t in zip(SIZES, tallies):
        e = t.ended
        assert e["absorbed"] + e["escaped"] + e["blocked"] + e["threshold"] == n == t.paths
        _balanced(t)
        if tables.unit_weights:
            assert t.absorbed[0] == e["absorbed"] and t.escaped[0] == e["escaped"] and t.blocked[0] == e["blocked"]
            assert t.rays == t.incident.sum() + e["escaped"] + e["blocked"]
        assert abs(e["escaped"] / n - escaped) < Z * math.sqrt(escaped * (1 - escaped) / n), (n, e)
    assert sum(t.ended["blocked"] for t in tallies) > 100


@pytest.mark.parametrize("kind", KINDS)
def test_a_chunk_of_one_path_stays_in_its_box(kind):
    """Two closed boxes apart, each lit from its ceiling, R = 0.9: a path never leaves the box
    it starts in. In a group of 64 one-path chunks and one big chunk (whose paths fill the
    wavefront beside them), every one-path chunk scores in one box only, and its weight
    balances. Tags that moved between paths would spread a chunk's hits over both boxes
    (while keeping every chunk's expected counts, which the tests above would not see)."""
    R = 0.9
    boxes = [box_rectangles(n=2, offset=(2.0 * k, 0, 0)) for k in (0, 1)]
    origin, u, v, face = (np.concatenate(parts) for parts in zip(*boxes))
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    _, tables = _tables(kind, PatchScene(V, T, TP, np.full(P, R), (face == 1).astype(float)))
    in_second_box = np.arange(P) >= P // 2
    tallies = walk_chunks(tables, [1] * 64 + [3_000], np.random.default_rng(13))
    both = [t for t in tallies[:64] if t.incident[:, in_second_box].sum() and t.incident[:, ~in_second_box].sum()]
    assert not both
    assert max(t.rays for t in tallies[:64]) > 20  # paths long enough to have crossed, had their tags moved
    for t in tallies[:64]:
        assert t.paths == 1
        _balanced(t)


@pytest.mark.parametrize("kind", KINDS)
def test_one_chunk_is_walk_chunk(kind):
    _, tables = _closed_box(kind, 0.5, n=2)
    (a,) = walk_chunks(tables, [5_000], np.random.default_rng(3))
    b = walk_chunk(tables, 5_000, np.random.default_rng(3))
    assert a.rays == b.rays and a.ended == b.ended
    np.testing.assert_array_equal(a.incident, b.incident)


@pytest.mark.parametrize("kind", ["counts", "sorted", "finite paths"])
def test_chunks_of_groups_are_independent_batches(kind):
    """200 chunks of 400 paths, traced in groups of 4 (by the plain estimator's walk, and by
    the walk that keeps arrays of paths): the spread of the chunks' per-patch estimates is
    table 1's variance for 400 paths. (Tags mixed between the chunks of a group,
    or paths shared, would shrink or grow it.) K = 200 batches: each patch's variance ratio
    has a standard deviation of sqrt(2 / 199); the area-weighted mean over patches, which are
    correlated, is bounded by the same band."""
    scene, F, _ = box_scene([0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0], (1.0, 1.4, 0.8), n=2)
    scene, tables = _tables(kind, scene)
    n = 400
    estimates = []
    for group in range(50):
        for t in walk_chunks(tables, [n] * 4, np.random.default_rng(1000 + group)):
            # b_j = R_j I_j Phi_T / (A_j n)
            estimates.append(scene.reflectivity[:, 0] * t.incident[0] * scene.total_power / (scene.patch_area * n))
    estimates = np.array(estimates)
    var, _ = path_variances(F, scene.grey_reflectivity, scene.emission[:, 0], scene.patch_area)
    ratio = estimates.var(axis=0, ddof=1) / (var / n)
    band = Z * math.sqrt(2 / (len(estimates) - 1))
    assert np.abs(ratio - 1).max() < band, ratio
    mean_ratio = float((scene.patch_area * ratio).sum() / scene.total_area)
    assert abs(mean_ratio - 1) < band, mean_ratio


@pytest.mark.parametrize("estimator, exit_point", [("finite", "random"), ("biased_infinite", "hit")])
def test_small_runs_group_their_chunks_and_report_every_chunk(estimator, exit_point, monkeypatch):
    """A small run traces its chunks in groups (fewer, fuller wavefronts), still reports
    progress once per chunk, and is the same run whatever the threads."""
    groups = []
    real = runners.run_chunks

    def recorded(state, seed, first_chunk, sizes, abort=None):
        groups.append(len(sizes))
        return real(state, seed, first_chunk, sizes, abort)

    monkeypatch.setattr(runners, "run_chunks", recorded)
    scene, _, _ = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], n=2)
    tables = WalkTables(scene, estimator, THRESHOLD, exit_point)
    limit = walk_method.GROUP_RAYS_COUNTED if tables.speedups.interchangeable else walk_method.GROUP_RAYS
    assert walk_method.ShotWalk(tables).group(100, 2.0) == walk_method.GROUP_MAX_CHUNKS
    assert walk_method.ShotWalk(tables).group(limit // 2, 2.0) == 1
    # Powers of two: a run of 32 chunks makes an even number of tasks.
    assert walk_method.ShotWalk(tables).group(limit // 2 // 5, 2.0) == 4
    # A group's scores stay small in big colour scenes: 3 channels x 500,000 patches a chunk.
    from types import SimpleNamespace

    big = SimpleNamespace(speedups=tables.speedups, channels=3, patch_count=500_000, groups=None)
    assert walk_method.ShotWalk(big).group(100, 2.0) == 2
    # ... and per source, whose chunks score every group apart, as small: two groups, one chunk a task.
    per_source = SimpleNamespace(speedups=tables.speedups, channels=3, patch_count=500_000, groups=SimpleNamespace(count=2))
    assert walk_method.ShotWalk(per_source).group(100, 2.0) == 1
    fractions = []
    kw = dict(paths=20_000, seed=3, exit_point=exit_point)
    a = solve(scene, estimator=estimator, threads=1, progress=lambda f, s: fractions.append(f), **kw)
    b = solve(scene, estimator=estimator, threads=2, **kw)
    assert a.chunks == plan.MIN_CHUNKS and len(fractions) == a.chunks
    group = walk_method.ShotWalk(tables).group(20_000 // a.chunks, a.prediction.expected_path_length)
    assert group > 1 and groups[: a.chunks // group] == [group] * (a.chunks // group)  # the first run's tasks
    assert all(y > x for x, y in zip(fractions, fractions[1:])) and fractions[-1] == 1.0
    np.testing.assert_array_equal(a.radiosity, b.radiosity)
    assert a.rays == b.rays


def test_sources_drawn_as_counts_join_the_wavefront_as_the_paths_would():
    """The walk of interchangeable paths kept as counts takes its new paths from each chunk's
    counts per source (sampling.SourceRuns) instead of from every path's source: any window
    of the chunk-ordered paths adds exactly the counts of the sources in it, chunk by chunk,
    including sources that drew no path (a source of tiny power)."""
    from addon.core.lights.sampling import SourceRuns, draw_sources

    scene, _, _ = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], n=3)
    emission = scene.emission.copy()
    emission[np.flatnonzero(emission[:, 0])[:2]] *= [[1e-9], [1e-3]]  # draws no path, and few
    _, tables = _tables("counts", scene.with_materials(scene.reflectivity, emission))
    sizes = [3_000, 500, 72, 10_000]
    assert all(tables.sources.draws_counts(n) for n in sizes)
    source, source_chunk, _ = draw_sources(tables.sources, sizes, np.random.default_rng(5))
    runs = SourceRuns(tables.sources, sizes, np.random.default_rng(5))  # the same numbers
    assert np.any(runs.end == runs.start)  # a source with no path
    P = tables.patch_count
    rng = np.random.default_rng(6)
    cuts = np.unique(np.concatenate(([0, sum(sizes)], np.cumsum(sizes), rng.integers(0, sum(sizes), 40))))
    for first, last in zip(cuts[:-1], cuts[1:]):
        live = np.zeros((len(sizes), P), dtype=np.int64)
        runs.add_window(live, first, last)
        expected = np.bincount(source_chunk[first:last] * P + source[first:last], minlength=len(sizes) * P)
        np.testing.assert_array_equal(live.ravel(), expected)
    # The tables' own sample draws the same numbers.
    np.testing.assert_array_equal(tables.sources.sample(3_000, np.random.default_rng(5)), source[:3_000])
