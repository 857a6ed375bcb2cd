"""Throughput of solve() against Embree's raw ray rate, measured in the same run.

    python -m benchmarks.throughput [--scene small_room cornell room_fig4 room_fig4_sphere] [--threads 1 2] [--seconds 3]
    python -m benchmarks.throughput --short     # short runs: ratio against the path count

Scenes: ``small_room`` is the Cycles comparison's closed room (10 x 10 patches per face, 1,200
triangles), ``cornell`` the coloured Cornell box (5,080 triangles), ``room_fig4`` the paper's
figure 4 room (133,144 triangles), ``room_fig4_sphere`` that room with a sphere of 5,120
triangle patches on its floor (138,264 triangles: a mixed scene, not all parallelograms).

The raw rate traces the same kind of rays (uniform points on patches, cosine directions,
drawn once beforehand) with embreex alone, split over the same number of threads; the
end-to-end rate is rays / seconds of a whole solve (sampling, tracing, scoring, threads).
Machines here are shared and noisy, so only the ratio of the two is meaningful.
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from addon.core import Speedups, predict, solve
from addon.core.lights.sampling import cosine_directions, points_on_patches

RESULTS = Path(__file__).parent / "results"


def sample_rays(scene, count, seed=0):
    """Rays as the walks cast them: a patch by area, a uniform point on it, a cosine direction."""
    g = scene.geometry
    rng = np.random.default_rng(seed)
    cdf = np.cumsum(g.patch_area) / g.patch_area.sum()
    patch = np.minimum(np.searchsorted(cdf, rng.random(count), side="right"), scene.patch_count - 1)
    u = rng.random((5, count), dtype=np.float32)
    return points_on_patches(g, patch, u[0], u[1], u[2]), cosine_directions(g, patch, u[3], u[4], normalize=False)


def walk_tracer(scene, exit_point="random"):
    """The Embree scene a walk traces: the patches' grids where the scene has them
    (addon/core/scene/patch_grids.py), else the patches' triangles."""
    from addon.core.methods.tables import WalkTables

    return WalkTables(scene, "finite", 1e-3, exit_point).tracer


def raw_rate(scene, threads, seconds, batch=1 << 16, tracer=None):
    """Rays per second of embreex alone (first hits) on pre-drawn rays, over ``threads``
    threads, on ``tracer`` (default: the patches' triangles)."""
    origins, directions = sample_rays(scene, batch * 8)
    tracer = scene.tracer if tracer is None else tracer
    tracer.first_hit(origins[:batch], directions[:batch])  # warm up

    def worker(offset):
        rays, k = 0, offset
        start = time.perf_counter()
        while time.perf_counter() - start < seconds:
            s = (k % 8) * batch
            tracer.first_hit(origins[s : s + batch], directions[s : s + batch])
            rays += batch
            k += 1
        return rays, time.perf_counter() - start

    cpu = time.process_time()
    with ThreadPoolExecutor(threads) as pool:
        results = list(pool.map(worker, range(threads)))
    cpu = time.process_time() - cpu
    rays = sum(r for r, _ in results)
    return rays / max(t for _, t in results), rays / cpu


def own_rays_factor(scene, estimator, threads, paths, rounds=5, every=4, limit=1 << 21, **kw):
    """How much faster Embree traces a solve's own rays than the pre-drawn random rays: the
    rays of every ``every``-th ray cast of a solve (up to ``limit`` rays; the first chunks, each
    from its first step to its last), traced again in the casts they came in, against as many
    pre-drawn random rays in casts of 2^16, each over ``threads`` threads, in alternation.
    Returns the median ratio of the two rates on the scene the walk traces, and (where that is
    the patches' grids) the median ratio of the own rays' rate on the patches' triangles to
    the pre-drawn rays' rate on the grids, else NaN. (A walk's rays are not the pre-drawn ones:
    paths start more often where light arrives, and walks trace rays grouped by patch; the
    target's "the same rays" is this stricter reading.)"""
    tracer = walk_tracer(scene, kw.get("exit_point", "random"))
    casts, lock, calls = [], threading.Lock(), [0]

    def keep(origins, directions):
        with lock:
            calls[0] += 1
            if calls[0] % every == 0 and sum(len(o) for o, _ in casts) < limit:
                casts.append((np.ascontiguousarray(origins), np.ascontiguousarray(directions)))

    real_first, real_bary = tracer.first_hit, tracer.first_hit_barycentric
    tracer.first_hit = lambda o, d, *region: (keep(o, d), real_first(o, d, *region))[1]
    tracer.first_hit_barycentric = lambda o, d, *region: (keep(o, d), real_bary(o, d, *region))[1]
    try:
        solve(scene, estimator=estimator, paths=paths, threads=threads, seed=99, **kw)
    finally:
        del tracer.first_hit, tracer.first_hit_barycentric
    total = sum(len(o) for o, _ in casts)
    o_raw, d_raw = sample_rays(scene, 1 << 16)
    raw_casts = [(o_raw, d_raw)] * max(1, round(total / len(o_raw)))

    def rate(batches, on=tracer):
        def worker(k):
            for o, d in batches[k::threads]:
                on.first_hit(o, d)

        start = time.perf_counter()
        with ThreadPoolExecutor(threads) as pool:
            list(pool.map(worker, range(threads)))
        return sum(len(o) for o, _ in batches) / (time.perf_counter() - start)

    on_triangles = tracer is not scene.tracer
    rate(casts[:4])  # warm up
    if on_triangles:
        rate(casts[:4], scene.tracer)
    factors, triangle_factors = [], []
    for _ in range(rounds):
        raw = rate(raw_casts)
        factors.append(rate(casts) / raw)
        if on_triangles:
            triangle_factors.append(rate(casts, scene.tracer) / raw)
    return float(np.median(factors)), float(np.median(triangle_factors)) if on_triangles else np.nan


def solve_rate(scene, estimator, threads, paths, seed=1, **kw):
    """Rays per second of a whole solve of ``paths`` paths (wall clock, and per CPU second).

    A fixed path count, not a time limit: a run stopped by its time limit drops the chunks
    still in flight, whose rays would be traced but not counted."""
    cpu = time.process_time()
    r = solve(scene, estimator=estimator, paths=paths, threads=threads, seed=seed, **kw)
    cpu = time.process_time() - cpu
    return r.rays / r.seconds, r.rays / cpu


def expected_rays_per_path(scene, estimator, method="walk", threshold=1e-3, exit_point="random", **_):
    """About the rays a path of ``method`` costs, to size a run to its seconds: the paper's
    expected path length for the walk, the two-way iteration's own count
    (``two_way.rays_per_path``, and its first reflection's rays with the hit exit)."""
    from addon.core.methods import two_way

    length = predict(scene, estimator, threshold=threshold).expected_path_length
    if method != "two_way":
        return length
    return two_way.rays_per_path(length) + (two_way.FIRST_REFLECTION_RAYS if exit_point == "hit" else 0.0)


def stolen_seconds():
    """CPU time the hypervisor has given to other guests while this machine's CPUs had work
    (/proc/stat's steal, summed over CPUs), or NaN where the system does not say."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return math.nan


def _with_steal(measure, threads):
    """``measure()``'s result and the share of its ``threads`` CPUs' wall time stolen meanwhile."""
    stolen, start = stolen_seconds(), time.perf_counter()
    result = measure()
    return result, (stolen_seconds() - stolen) / (threads * (time.perf_counter() - start))


def is_quiet(stolen_shares, quiet_steal=0.02):
    """Whether a round's measurements each lost at most ``quiet_steal`` of their CPU time to
    other guests (True where steal cannot be read: NaN)."""
    shares = np.asarray(stolen_shares, dtype=float)
    return bool(np.isnan(shares).any() or (shares <= quiet_steal).all())


def paired_ratio(scene, estimator, threads, seconds, rounds=5, max_rounds=12, quiet_steal=0.02, **kw):
    """Raw and end-to-end rates measured in alternation, so both see the same machine load:
    each round brackets one solve between two raw measurements and takes the solve's rate over
    their mean. Each solve runs the paths that would take about ``seconds`` at the raw rate.

    The machines here are virtual, and their hypervisor lends the CPUs to other guests at
    times (steal time). A stolen CPU hurts a 2-thread solve more than Embree alone: a walk
    stalled while it holds the numpy turn stalls the other thread too, where Embree's
    threads go on alone. A round is *quiet* when at most ``quiet_steal`` of its CPUs' time
    was stolen during each of its three measurements; rounds run until ``rounds`` are quiet
    (or ``max_rounds`` have run), and the medians are the quiet rounds' (every round's if
    fewer than 3 are quiet, or where steal cannot be read).
    Returns the medians of the raw and solve rates, the median, lowest and highest per-round
    ratio, by wall clock and per CPU second, and the quiet and all rounds' counts."""
    rays_a_path = expected_rays_per_path(scene, estimator, **kw)
    solve(scene, estimator=estimator, paths=20_000, threads=threads, **kw)  # warm up
    tracer = walk_tracer(scene, kw.get("exit_point", "random"))

    def raw_now():
        return _with_steal(lambda: np.array(raw_rate(scene, threads, seconds / 4, tracer=tracer)), threads)

    raws, rates, ratios, quiet = [], [], [], []
    before, before_steal = raw_now()
    while len(raws) < max_rounds and sum(quiet) < rounds:
        paths = max(1, int(before[0] * seconds / rays_a_path))
        rate, solve_steal = _with_steal(
            lambda: np.array(solve_rate(scene, estimator, threads, paths, seed=len(raws) + 1, **kw)), threads)
        after, after_steal = raw_now()
        raw = (before + after) / 2  # columns: wall-clock rate, CPU-time rate
        raws.append(raw)
        rates.append(rate)
        ratios.append(rate / raw)
        quiet.append(is_quiet((before_steal, solve_steal, after_steal), quiet_steal))
        before, before_steal = after, after_steal
    raws, rates, ratios = np.array(raws), np.array(rates), np.array(ratios)
    pick = np.array(quiet) if sum(quiet) >= 3 else np.ones(len(quiet), dtype=bool)
    raws, rates, ratios = raws[pick], rates[pick], ratios[pick]
    own, own_on_triangles = own_rays_factor(scene, estimator, threads, paths, **kw)
    # For scale: Embree on the patches' triangles (where the walk traces grids).
    raw_triangles = raw_rate(scene, threads, seconds / 4)[0] if tracer is not scene.tracer else np.nan
    return {
        "traced_triangles": tracer.triangle_count,
        "raw_triangles": float(raw_triangles),
        "own_rays_factor": own,
        "own_rays_on_triangles_factor": own_on_triangles,
        "raw": float(np.median(raws[:, 0])),
        "solve": float(np.median(rates[:, 0])),
        "ratio": float(np.median(ratios[:, 0])),
        "ratio_low": float(ratios[:, 0].min()),
        "ratio_high": float(ratios[:, 0].max()),
        "cpu_ratio": float(np.median(ratios[:, 1])),
        "quiet_rounds": int(sum(quiet)),
        "rounds": len(quiet),
    }


def breakdown(scene, estimator, rounds=4, **kw):
    """Where a walk's time goes (one thread): the share spent inside Embree, Embree's rate
    inside the walk, the same rays traced again on their own (with the walk's query: the
    hit-point exit asks for the hit's distance, barycentrics and normal too), twice, and the
    raw rate on pre-drawn random rays (first hits only). Medians over ``rounds`` chunks of a
    full-size chunk each. The walk is timed as it runs in a solve; its rays are kept from a
    second walk with the same random numbers (the same rays), so that copying them does not
    disturb the timed one.

    The two replays, in alternating order: back to back, and with a pause before each cast as
    long as the walk's numpy work before it (the walk's time outside Embree, shared out by
    rays), spent spinning in Python, which reads next to no memory. If Embree is as slow after
    such pauses as inside the walk, what slows it there is the time away from its scene (the
    host's other cores use the shared cache meanwhile), not what the numpy work reads. Where
    the processor's counters can be read (``benchmarks.counters``), also the lines Embree
    fetches from memory a ray: inside the walk, back to back and after pauses; else NaN."""
    from addon.core.methods.tables import WalkTables
    from addon.core.methods.walk import walk_chunk
    from addon.core.estimate.plan import chunk_paths_for

    from .counters import Counters

    threshold = kw.get("threshold", 1e-3)
    tables = WalkTables(scene, estimator, threshold, kw.get("exit_point", "random"))
    paths = chunk_paths_for(predict(scene, estimator, threshold=threshold).expected_path_length, 10**15)
    tracer = tables.tracer
    # (a walk tracing grids asks for barycentrics: a hit's patch is its grid cell)
    query = "first_hit" if tables.exit_random and tables.grids is None else "first_hit_barycentric"
    real = getattr(tracer, query)
    walk_chunk(tables, paths // 8, np.random.default_rng(0))
    o_raw, d_raw = sample_rays(scene, 1 << 16)
    counters = Counters.open()

    def from_memory():
        return counters.read()["from_memory"] if counters else np.nan

    def counted(trace, origins, directions):
        if counters:
            counters.start()
        try:
            return trace(origins, directions)
        finally:
            if counters:
                counters.stop()

    rows = []
    for k in range(rounds):
        inside = {"cpu": 0.0, "rays": 0}

        def timed(origins, directions):
            cpu = time.process_time()
            hit = counted(real, origins, directions)
            inside["cpu"] += time.process_time() - cpu
            inside["rays"] += len(origins)
            return hit

        kept = []

        def keep(origins, directions):
            kept.append((origins.copy(), directions.copy()))  # every cast of the chunk
            return real(origins, directions)

        before = from_memory()
        setattr(tracer, query, timed)
        try:
            cpu = time.process_time()
            rays = walk_chunk(tables, paths, np.random.default_rng(k + 1)).rays
            total = time.process_time() - cpu
            setattr(tracer, query, keep)
            walk_chunk(tables, paths, np.random.default_rng(k + 1))  # the same rays again
        finally:
            delattr(tracer, query)
        from_memory_inside = (from_memory() - before) / rays
        numpy_seconds_a_ray = (total - inside["cpu"]) / rays
        replays = {}
        for pause in ((0.0, numpy_seconds_a_ray) if k % 2 == 0 else (numpy_seconds_a_ray, 0.0)):
            replays[pause > 0] = replay(real, kept, pause, counted, from_memory)
        (again, from_memory_alone), (paused, from_memory_paused) = replays[False], replays[True]
        cpu, raw = time.process_time(), 0
        while raw < 1_000_000:
            tracer.first_hit(o_raw, d_raw)
            raw += len(o_raw)
        raw /= time.process_time() - cpu
        rows.append((rays / total, inside["cpu"] / total, inside["rays"] / inside["cpu"], again, paused, raw,
                     from_memory_inside, from_memory_alone, from_memory_paused))
    if counters:
        counters.close()
    return np.median(np.array(rows), axis=0)


def replay(trace, casts, pause_a_ray, counted, from_memory):
    """Traces ``casts`` again, one by one, each after spinning ``pause_a_ray`` seconds per ray
    of it (0: back to back). Returns Embree's rays per CPU second over the casts alone, and
    the lines it fetched from memory a ray."""
    before, seconds, rays = from_memory(), 0.0, 0
    for origins, directions in casts:
        if pause_a_ray:
            until = time.perf_counter() + pause_a_ray * len(origins)
            while time.perf_counter() < until:
                pass
        cpu = time.process_time()
        counted(trace, origins, directions)
        seconds += time.process_time() - cpu
        rays += len(origins)
    return rays / seconds, (from_memory() - before) / rays


SHORT_PATHS = (30_000, 100_000, 300_000, 1_000_000, 3_000_000)


def short_runs(scene, threads, path_counts=SHORT_PATHS, rounds=5):
    """The default estimator's ratio to the raw rate in short runs, whose chunks are small (a
    run makes at least plan.MIN_CHUNKS of them): with small chunks traced in groups
    (walk.walk_chunks, the default) and one by one (Speedups(grouped_chunks=False), as
    before groups). Each round brackets one solve of each kind, in alternating order, between
    two raw measurements. Returns {paths: (ratio grouped, ratio one by one, seconds grouped,
    chunks per group)}, medians over the rounds."""
    from addon.core.estimate import plan
    from addon.core.methods.walk import ShotWalk
    from addon.core.methods.tables import WalkTables

    solve(scene, estimator="finite", paths=20_000, threads=threads)  # warm up
    length = predict(scene, "finite").expected_path_length
    tables = WalkTables(scene, "finite", 1e-3, "random")
    out = {}
    for paths in path_counts:
        group = ShotWalk(tables).group(plan.chunk_paths_for(length, paths), length)
        ratios = {True: [], False: []}
        seconds = []
        before = raw_rate(scene, threads, 0.25, tracer=tables.tracer)[0]
        for k in range(rounds):
            rates = {}
            for grouped in ((True, False) if k % 2 == 0 else (False, True)):
                r = solve(scene, estimator="finite", paths=paths, threads=threads, seed=k, speedups=Speedups(grouped_chunks=grouped))
                rates[grouped] = r.rays / r.seconds
                if grouped:
                    seconds.append(r.seconds)
            after = raw_rate(scene, threads, 0.25, tracer=tables.tracer)[0]
            raw = (before + after) / 2
            for grouped, rate in rates.items():
                ratios[grouped].append(rate / raw)
            before = after
        out[paths] = (float(np.median(ratios[True])), float(np.median(ratios[False])), float(np.median(seconds)), group)
    return out


def write_short(args):
    scenes = [name for name in args.scene]
    results = {}
    for name in scenes:
        scene = build_scene(name)
        for threads in args.threads:
            results[name, threads] = short_runs(scene, threads)
            for paths, (g, one, sec, group) in results[name, threads].items():
                print(f"{name:10s} {threads} thr {paths:>9,d} paths  {sec:6.3f} s  {group} chunks a group  "
                      f"ratio grouped {g:.2f}  one by one {one:.2f}", flush=True)
    lines = [
        "# Short runs: solve() against Embree's raw ray rate, by path count",
        "",
        f"`python -m benchmarks.throughput --short {' '.join(a for a in sys.argv[1:] if a != '--short')}`; "
        f"{platform.processor() or platform.machine()}, {platform.python_version()}. Default estimator "
        "(finite, random exit, independent sampling).",
        "",
        "A run of N paths makes at least 32 chunks (the batch error estimate wants them), so short runs have",
        "small chunks, and a chunk ends in steps of few rays each. Small chunks are traced up to 16 at a",
        "time as one wavefront (`walk.walk_chunks`, each path tagged with its chunk); *one by one* is",
        "the same solve with `Speedups(grouped_chunks=False)`, as before groups. Ratio: rays per second of the",
        "whole solve (tables, threads, walks, sums) over embreex's raw rate on pre-drawn rays, bracketing",
        "each round; medians of 5 rounds. The Cornell box is coloured (its walk carries weights); the others",
        "are grey. Where a group is 1 chunk, both columns run the same code: their difference is the",
        "machine's noise.",
        "",
        "| scene | threads | paths | chunks a group | seconds | ratio, grouped | ratio, one by one | speed-up |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for (name, threads), rows in results.items():
        for paths, (g, one, sec, group) in rows.items():
            lines.append(f"| {name} | {threads} | {paths:,} | {group} | {sec:.3f} | **{g:.2f}** | {one:.2f} | x{g / one:.2f} |")
    out = Path(args.out).with_name("throughput_short.md")
    out.write_text("\n".join(lines) + "\n")
    plot_short(results, out.with_suffix(".png"))
    print(f"wrote {out} and {out.with_suffix('.png')}")


def plot_short(results, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    thread_counts = sorted({t for _, t in results})
    fig, axes = plt.subplots(1, len(thread_counts), figsize=(5.2 * len(thread_counts), 4.2), sharey=True, squeeze=False)
    colours = dict(zip(sorted({n for n, _ in results}), ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    for ax, threads in zip(axes[0], thread_counts):
        for (name, t), rows in results.items():
            if t != threads:
                continue
            paths = list(rows)
            ax.plot(paths, [rows[p][0] for p in paths], "o-", color=colours[name], label=f"{name}, grouped")
            ax.plot(paths, [rows[p][1] for p in paths], "o--", color=colours[name], alpha=0.6, label=f"{name}, one by one")
        ax.axhline(0.8, color="grey", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_xlabel("paths in the run")
        ax.set_title(f"{threads} thread{'s' if threads > 1 else ''}")
        ax.grid(True, which="both", alpha=0.3)
    axes[0][0].set_ylabel("solve rate / Embree's raw rate")
    axes[0][0].set_ylim(0, 1.0)
    axes[0][-1].legend(fontsize=8, loc="lower right")
    fig.suptitle("Short runs: the share of Embree's speed a whole solve keeps")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def build_scene(name):
    if name == "small_room":
        from benchmarks.cycles_comparison import patch_scene

        return patch_scene()
    if name == "room_fig4":
        from sample_scenes import room_fig4

        return room_fig4.build().scene
    if name == "cornell":
        from sample_scenes import cornell_box

        return cornell_box.build().scene
    if name == "room_fig4_sphere":
        return room_with_sphere()
    raise SystemExit(f"unknown scene {name}")


def icosphere(level):
    """A unit icosphere: the icosahedron's faces cut into 4^level triangles, pushed onto the
    sphere. (V,3) float64 vertices, (20 4^level, 3) int64 triangles wound outwards."""
    t = (1 + 5**0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    V /= np.linalg.norm(V, axis=1)[:, None]
    for _ in range(level):
        a, b, c = F.T
        # each edge's midpoint once: edges keyed by their sorted vertex pair
        edges = np.sort(np.stack([np.stack([a, b], 1), np.stack([b, c], 1), np.stack([c, a], 1)]), axis=2)
        unique, inverse = np.unique(edges.reshape(-1, 2), axis=0, return_inverse=True)
        mid = V[unique].mean(axis=1)
        mid /= np.linalg.norm(mid, axis=1)[:, None]
        ab, bc, ca = (V.shape[0] + inverse.reshape(3, -1))
        V = np.vstack([V, mid])
        F = np.concatenate([np.stack(f, 1) for f in ((a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca))])
    return V, F


def room_with_sphere(level=4, centre=(5.0, 4.0, 0.61), radius=0.6, reflectivity=0.5):
    """The figure 4 room with a sphere on its floor (a mixed scene: 66,572 square patches and
    5,120 triangle patches, 138,264 triangles), grey."""
    from addon.core import PatchScene
    from sample_scenes import room_fig4

    sample = room_fig4.build()
    V, F = icosphere(level)
    V = V * radius + np.asarray(centre)
    P = sample.patch_count
    vertices = np.vstack([sample.vertices, V])
    triangles = np.vstack([sample.triangles, F + sample.vertices.shape[0]])
    triangle_patch = np.concatenate([sample.triangle_patch, P + np.arange(F.shape[0])])
    reflectivity = np.concatenate([sample.reflectivity[:, 0], np.full(F.shape[0], reflectivity)])
    emission = np.concatenate([sample.emission[:, 0], np.zeros(F.shape[0])])
    return PatchScene(vertices, triangles, triangle_patch, reflectivity, emission)


# The paper's estimators (the default table), and the methods beyond the paper (--methods).
ESTIMATOR_CASES = (("finite", {}), ("biased_infinite", {"threshold": 1e-3}))
METHOD_CASES = (("finite", {"method": "two_way"}), ("finite", {"direct_light": "gathered"}))
METHOD_LABELS = {("two_way", None): "two-way iteration", (None, "gathered"): "walk, gathered first bounce"}
METHODS_NOTE = [
    "The two-way iteration (the panel's Automatic takes it in most scenes) and the finite walk with its",
    "direct light gathered by shadow rays. Their rays are all counted: the gathering's shadow and",
    "cosine rays, the hit exit's first-reflection rays, every generation's. Embree's raw rate is the",
    "same as the walks' (pre-drawn random rays, first hits), so the ratio says how much of a solve's",
    "time the tracing is, not how well its rays are chosen (the suite, `suite.md`, measures that).",
    "",
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scene", nargs="+", default=["small_room", "cornell", "room_fig4", "room_fig4_sphere"])
    ap.add_argument("--threads", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--out", default=None, help="default: results/throughput.md, with --methods throughput_methods.md")
    ap.add_argument("--methods", action="store_true",
                    help="the two-way iteration and the walk with its direct light gathered instead of the paper's estimators")
    ap.add_argument("--breakdown", action="store_true",
                    help="where a walk's time goes (1 thread), into results/throughput_breakdown.md")
    ap.add_argument("--short", action="store_true",
                    help="short runs (3e4 to 3e6 paths), chunks grouped or one by one, into results/throughput_short.md")
    args = ap.parse_args(argv)
    args.out = args.out or str(RESULTS / ("throughput_methods.md" if args.methods else "throughput.md"))
    if args.breakdown:
        return write_breakdown(args)
    if args.short:
        return write_short(args)

    def case_row(name, scene, threads, estimator, exit_point, kw):
        m = paired_ratio(scene, estimator, threads, args.seconds, exit_point=exit_point, **kw)
        label = METHOD_LABELS.get((kw.get("method"), kw.get("direct_light")), estimator)
        row = (name, scene.triangle_count, m["traced_triangles"], threads, label, exit_point,
               m["raw"] / 1e6, m["solve"] / 1e6, m["ratio"], m["ratio_low"], m["ratio_high"], m["cpu_ratio"],
               m["own_rays_factor"], m["ratio"] / m["own_rays_factor"], m["raw_triangles"] / 1e6,
               m["solve"] / m["raw_triangles"], m["ratio"] / m["own_rays_on_triangles_factor"],
               m["quiet_rounds"], m["rounds"])
        print("{:10s} {:7d} tris ({} traced)  {} thr  {:16s} {:6s}  raw {:6.2f} Mray/s  solve {:6.2f} Mray/s  "
              "ratio {:.2f} ({:.2f}-{:.2f})  (per CPU second {:.2f})  own rays x{:.2f}: {:.2f}  "
              "raw on the patch triangles {:.2f}: x{:.2f}, own rays there: {:.2f}  "
              "({} of {} rounds quiet)".format(*row),
              flush=True)
        return row

    rows, cases = [], []
    for name in args.scene:
        scene = build_scene(name)
        for threads in args.threads:
            for estimator, kw in (METHOD_CASES if args.methods else ESTIMATOR_CASES):
                for exit_point in ("random", "hit"):
                    cases.append((name, scene, threads, estimator, exit_point, kw))
                    rows.append(case_row(*cases[-1]))
    # A case that met a noisy spell (fewer than 3 quiet rounds) runs once more at the end; the
    # table keeps the run with more quiet rounds.
    for k, case in enumerate(cases):
        if rows[k][-2] < 3:
            print("again, fewer than 3 rounds were quiet:", flush=True)
            again = case_row(*case)
            if again[-2] > rows[k][-2]:
                rows[k] = again
    lines = [
        "# Throughput: solve() against Embree's raw ray rate" + (", the methods beyond the paper" if args.methods else ""),
        "",
        *(METHODS_NOTE if args.methods else []),
        f"Machine: {platform.processor() or platform.machine()}, {platform.python_version()}; "
        f"`python -m benchmarks.throughput {' '.join(sys.argv[1:])}`.",
        "Raw: embreex alone (first hits) on pre-drawn rays of the same kind over the same threads, on the scene the "
        "solve traces: the patches' grids, two triangles each, where the patches tile them, beside the other "
        "patches' own triangles (*traced*; addon/core/scene/patch_grids.py). Each round brackets one solve between two raw "
        "measurements, so both see the same load; the ratio is the median of the per-round ratios, with the lowest "
        "and highest round beside it (the spread is the machine's noise: these machines are shared).",
        "",
        "These machines are virtual: at times their hypervisor gives the CPUs to other guests (steal time, "
        "/proc/stat). A stolen CPU costs a 2-thread solve more than Embree alone, since a walk stalled while it holds "
        "the numpy turn stalls the other thread too. A round is *quiet* when at most 2% of its CPUs' time was stolen "
        "during each of its three measurements. Rounds run until 5 are quiet, or 12 have run; the medians are over "
        "the quiet rounds (over all, where fewer than 3 were quiet). *Rounds* gives how many were quiet of how many ran. "
        "A case with fewer than 3 quiet rounds runs once more after the others, and the table keeps the run with "
        "more quiet rounds.",
        "",
        "The ratio per CPU second divides rays by the process's CPU time instead of wall time: it is",
        "immune to other processes taking the processor, but not to their use of caches and memory,",
        "and blind to threads waiting for each other.",
        "",
        "The walks' own rays are not the pre-drawn ones: paths start more often where light arrives, and",
        "walks send the rays leaving one patch together. *Own rays* is how much faster Embree alone traces",
        "a solve's own rays (every 4th ray cast of a solve, up to 2 million rays, traced again in the same",
        "casts over the same threads) than the pre-drawn random rays, median of 5 alternations; the",
        "column after it is the ratio against that rate: the strict reading of \"the same rays\".",
        "",
        "The last three columns, for walks that trace grids, are against Embree alone on the scene's",
        "own triangles, the patches' (what the walk traced before grids): its rate on pre-drawn rays",
        "(measured once after the rounds) and the solve's rate over it; then the solve's rate over",
        "Embree's on the solve's own rays (the same casts as *own rays*, traced on the patches'",
        "triangles in the same alternation): the target read on the scene it names (its",
        "triangles), for the same rays and threads.",
        "",
        "| scene | triangles | traced | threads | " + ("method" if args.methods else "estimator") + " | exit point | raw Mray/s | solve Mray/s | ratio | rounds "
        "| ratio per CPU second | own rays | ratio, own rays | raw on the patch triangles Mray/s | solve / that "
        "| solve / own rays on the patch triangles |",
        "|---|---:|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        lines.append("| {} | {} | {} | {} | {} | {} | {:.2f} | {:.2f} | **{:.2f}** | {:.2f}–{:.2f} ({}/{} quiet) | {:.2f} | x{:.2f} "
                     "| {:.2f} ".format(*r[:11], *r[17:19], *r[11:14])
                     + ("| – | – | – |" if np.isnan(r[14]) else "| {:.2f} | x{:.2f} | x{:.2f} |".format(*r[14:17])))
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}")


def write_breakdown(args):
    lines = [
        "# Where a walk's time goes",
        "",
        f"`python -m benchmarks.throughput --breakdown`; {platform.processor() or platform.machine()}, one thread, "
        "full-size chunks, CPU time, medians of 4 chunks.",
        "",
        "| scene | estimator | exit point | walk Mray/s | share of the walk inside Embree | Embree inside the walk Mray/s "
        "| the same rays again, back to back Mray/s | the same rays again, after pauses Mray/s "
        "| Embree's lines from memory a ray: inside / back to back / after pauses "
        "| raw (pre-drawn random rays) Mray/s | walk / raw |",
        "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name in args.scene:
        scene = build_scene(name)
        for estimator in ("finite", "biased_infinite"):
            for exit_point in ("random", "hit"):
                walk, share, inside, again, paused, raw, *fetched = breakdown(scene, estimator, exit_point=exit_point)
                fetched = "n/a" if np.isnan(fetched[0]) else " / ".join(f"{lines:.2f}" for lines in fetched)
                row = (f"| {name} | {estimator} | {exit_point} | {walk / 1e6:.2f} | {share:.2f} | {inside / 1e6:.2f} "
                       f"| {again / 1e6:.2f} | {paused / 1e6:.2f} | {fetched} | {raw / 1e6:.2f} | {walk / raw:.2f} |")
                print(row, flush=True)
                lines.append(row)
    lines += [
        "",
        "The walk / raw ratio is the product of two factors: the share of the walk spent inside Embree",
        "(the rest is numpy: random numbers, the frame gather, points and directions, the facing test,",
        "survival, scoring) and how fast Embree traces inside the walk compared with the raw run. Walks",
        "trace the patches' grids where the patches tile them (the raw run too:",
        "addon/core/scene/patch_grids.py), a scene of a few kB that stays in cache (the figure 4 room's",
        "196 triangles), and ask Embree for barycentrics, from which a hit's grid cell is its patch.",
        "",
        "The two replays and the processor's counters (lines from memory: fills from DRAM on AMD Zen 3",
        "and later, last-level read misses elsewhere; `benchmarks/counters.py`) measure what the time",
        "between casts does to Embree: the same casts traced again back to back, and again each after",
        "a pause as long as the walk's numpy work before it (spinning in Python, which reads next to no",
        "memory). On the patches' triangles (the figure 4 room's 133,144, about 10 MB; what every walk traced",
        "before grids) Embree inside a walk was 7-24%",
        "slower than back to back: it fetched lines of its scene from memory that back to back it found",
        "in the shared L3 cache. On the grids it runs inside the walk as fast as back to back, and reads",
        "next to nothing from memory. The walk is timed alone; its rays are kept from a second walk",
        "with the same random numbers, so that copying them (about 24 MB a chunk) does not disturb the",
        "timed walk.",
        "",
        "A walk on grids asks Embree for the hit's barycentric coordinates and geometric normal",
        "(embreex's `output=1`, a few percent slower than the raw run's first hits alone): the cell",
        "gives the patch, the normal's sign the side. A walk leaving from hit points takes the hit's",
        "distance too: its next ray starts at origin + t direction, with no table of triangles read,",
        "and it gathers 3 rows of patch normals (in big scenes, its patches' classes') where a walk",
        "leaving from new random points gathers a leaving frame.",
    ]
    out = Path(args.out).with_name("throughput_breakdown.md")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
