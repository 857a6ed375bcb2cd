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
