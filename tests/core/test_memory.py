"""Memory of a solve on the figure-4 room: under 1 GiB, and not growing with the paths (issue 5).

Runs in a fresh Python process, so that its peak resident set is its own: the 66,572-patch room
(sample_scenes.room_fig4) is solved with N paths and then with 4N paths, both with chunks of
the maximum size (solver.chunk_paths_for), so the second run's extra chunks (96) are the only
difference. To keep the test short the child caps chunks at 65,536 paths (production: 2^19 paths
or 2^20 rays), so that N is 32 chunks: what a chunk holds while it runs does not depend on its
size beyond the wavefront (path_walk.WAVEFRONT_PATHS) and the scores kept between bincounts
(tallies.SCORE_FLUSH), which are the same. The second run's peak resident set may exceed
the first run's by at most MARGIN_RSS, and its tracemalloc peak (numpy and Python allocations
during the solve, exact) by at most MARGIN_TRACED. benchmarks/memory.py measures the
production chunk sizes.

What this catches: anything kept per chunk or per path (chunk tallies retained, per-path
records, growing lists of scores): one (1, P) float64 tally is 0.5 MB here, so 96 extra retained
chunks are 51 MB, and one float64 per extra path is 50 MB. Checked by hand by patching the
solver in the child: retaining every chunk tally raised the large run's resident peak by 67 MiB
and its tracemalloc peak by 46 MiB; keeping one float64 per path, by 15 MiB and 45 MiB (the
resident peak is less sensitive: memory freed after building the scene absorbs part of the
growth); unpatched, the differences were within +1.25 MiB and -1.8 MiB.
"""
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
MIB = 1 << 20
# Resident set: pages of freed numpy buffers go back to the system or are reused, but glibc's
# arenas for the worker threads can keep a few MiB more; 12 MiB is below the smallest growth
# seen in the by-hand check above.
MARGIN_RSS = 12 * MIB
# tracemalloc counts live allocations exactly; what can differ between the two runs is how many
# chunks are in flight when the peak is reached (at most threads + 1 pending and one being added).
MARGIN_TRACED = 8 * MIB

CHILD = textwrap.dedent(
    """
    import json, resource, sys, tracemalloc
    sys.path.insert(0, {root!r})
    import numpy as np
    import addon.core.solver as solver
    from addon.core import predict, solve

    from sample_scenes import room_fig4

    scene = room_fig4.build().scene
    solver.MAX_CHUNK_PATHS = 1 << 16
    chunk = solver.chunk_paths_for(predict(scene, "finite").expected_path_length, 10**12)
    assert chunk == 1 << 16 and solver.chunk_paths_for(2.0, solver.MIN_CHUNKS * chunk) == chunk
    out = {{"patches": scene.patch_count, "chunk": chunk}}
    for name, paths in (("small", solver.MIN_CHUNKS * chunk), ("large", 4 * solver.MIN_CHUNKS * chunk)):
        tracemalloc.start()
        result = solve(scene, "finite", paths=paths, threads=2, seed=1)
        traced = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        del result
        out[name] = dict(paths=paths, rss=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, traced=traced)
    print(json.dumps(out))
    """
)


def test_solve_memory_does_not_grow_with_paths():
    code = CHILD.format(root=str(ROOT))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    small, large = out["small"], out["large"]
    assert out["patches"] == 66_572
    assert large["rss"] < 1 << 30, large  # issue 5's bound (about 200 MiB measured)
    # the peak resident set after the 4x longer run: no more than MARGIN above the first run's
    assert large["rss"] - small["rss"] <= MARGIN_RSS, (small, large)
    assert large["traced"] - small["traced"] <= MARGIN_TRACED, (small, large)
    # and the solve's own allocations are bounded by the chunk size, not the path count: under
    # half a float64 per path of the large run (32 MiB; the chunks in flight need about 17 MiB)
    assert large["traced"] < 8 * large["paths"] / 2, (small, large)


# --- The scene's arrays (issue 26) ----------------------------------------------------------
# A solve of a million patches through the operator peaked at 2.4 GiB (benchmarks/results/
# memory_operator.md), most of it when the patches became a core scene: build_geometry's float64
# temporaries of the whole scene (about 1.2 kB a patch), an Embree scene of every triangle that
# only the diagnostics traced, and per-triangle float32 arrays a walk over grids never reads.
# Measured on the room below (24,697 patches) with tracemalloc, per patch, above the meshed
# patches: before, a peak of 1,451 B and 323 B held after, with both of those built; after,
# 787 B and 143 B (the peak is then the grids' own search, patch_grids), neither built.
SCENE_PEAK_BYTES = 1100  # per patch: 40% above the 787 measured, 25% below the 1,451 before
SCENE_HELD_BYTES = 200   # per patch: 40% above the 143 measured, 38% below the 323 before


def _room_objects(n, side=4.0):
    """Six walls of n x n quads facing into a room, and an emitting quad under the ceiling, as
    scene_io reads them (ObjectArrays; one face, one patch)."""
    from addon.patches import ObjectArrays

    L = side
    walls = [((0, 0, 0), (L, 0, 0), (0, L, 0)), ((0, 0, L), (0, L, 0), (L, 0, 0)), ((0, 0, 0), (0, L, 0), (0, 0, L)),
             ((L, 0, 0), (0, 0, L), (0, L, 0)), ((0, 0, 0), (0, 0, L), (L, 0, 0)), ((0, L, 0), (L, 0, 0), (0, 0, L)),
             ((0.375 * L, 0.375 * L, 0.98 * L), (0, 0.25 * L, 0), (0.25 * L, 0, 0))]
    objects = []
    for k, (origin, u, v) in enumerate(walls):
        d = 1 if k == 6 else n
        t = np.linspace(0, 1, d + 1)
        a, b = np.meshgrid(t, t, indexing="ij")
        vertices = np.asarray(origin, float) + a.reshape(-1, 1) * np.asarray(u, float) + b.reshape(-1, 1) * np.asarray(v, float)
        i = (np.arange(d)[:, None] * (d + 1) + np.arange(d)).reshape(-1)
        quads = np.stack([i, i + d + 1, i + d + 2, i + 1], axis=1)
        F = len(quads)
        objects.append(ObjectArrays(
            name=f"wall {k}", vertices=vertices, face_sizes=np.full(F, 4), corner_verts=quads.reshape(-1),
            triangles=np.stack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]], axis=1).reshape(-1, 3),
            triangle_face=np.repeat(np.arange(F), 2),
            face_reflectivity=np.tile([0.6, 0.3 if k == 2 else 0.6, 0.6], (F, 1)),  # a coloured wall: 3 channels
            face_emission=np.full((F, 3), 10.0 if k == 6 else 0.0),
        ))
    return objects, L / n * 1.5  # faces a little smaller than a patch: one patch each


def test_scene_arrays_stay_within_a_per_patch_budget(monkeypatch):
    import tracemalloc

    import addon.core.geometry as geometry
    from addon import patches
    from addon.core import solve

    # blocks of 4,096 triangles, as a million-patch scene has blocks of 2^16 among 2 million
    monkeypatch.setattr(geometry, "BLOCK_TRIANGLES", 1 << 12)
    objects, patch_size = _room_objects(64)
    patches._GEOMETRY_CACHE.clear()
    tracing = tracemalloc.is_tracing()
    if not tracing:
        tracemalloc.start()
    try:
        made = patches.make_patches(objects, patch_size)
        meshed = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        scene, _ = patches.scene_and_notes(made)  # the core scene and the diagnostics' rays
        held, peak = tracemalloc.get_traced_memory()
    finally:
        if not tracing:
            tracemalloc.stop()
    P = scene.patch_count
    assert P == 6 * 64 * 64 + 121
    assert (peak - meshed) / P < SCENE_PEAK_BYTES, (peak - meshed) / P
    assert (held - meshed) / P < SCENE_HELD_BYTES, (held - meshed) / P
    # A walk over grids makes neither the Embree scene of every triangle nor per-triangle arrays.
    solve(scene, paths=20_000, threads=2, seed=1)
    made_lazily = ("tracer", "triangle_corners", "triangle_frame", "triangle_normal")
    assert not [name for name in made_lazily if name in scene.geometry.__dict__]
    patches._GEOMETRY_CACHE.clear()
