"""Memory of a solve does not grow with the number of paths (issue 5).

Runs in a fresh Python process, so that its peak resident set is its own: a box of 21,600
patches is solved with N paths and then with 4N paths. N = 32 x 65,536 is the smallest path
count whose chunks have the maximum size, so both runs work with chunks of the same size and
the second run's extra chunks (128 instead of 32) are the only difference. Its peak resident
set may exceed the first run's by at most MARGIN, and so may its tracemalloc peak (numpy and
Python allocations during the solve), which is exact and so gets a tighter margin.

What this catches: anything kept per chunk or per path (chunk tallies retained, per-path
records, growing lists of scores): at 21,600 patches one (1, P) float64 tally is 170 kB, so
96 extra retained chunks are 16 MB, and one float64 per extra path is 50 MB. Checked by hand by
patching the solver in the child: retaining every chunk tally raised the resident peak of the
large run by 23 MiB and its tracemalloc peak by 15.5 MiB; keeping one float64 per path, by 64 and
46 MiB; unpatched, the differences were 0 MiB and within +-0.75 MiB.
"""
import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MIB = 1 << 20
# Resident set: pages of freed numpy buffers go back to the system or are reused, but glibc's
# arenas for the worker threads can keep a few MiB more; 12 MiB is below the 16 MB of the
# smallest growth this test is meant to catch.
MARGIN_RSS = 12 * MIB
# tracemalloc counts live allocations exactly; what can differ between the two runs is how many
# chunks are in flight when the peak is reached (at most threads + 1 pending and one being added).
MARGIN_TRACED = 8 * MIB

CHILD = textwrap.dedent(
    """
    import json, resource, sys, tracemalloc
    sys.path.insert(0, {root!r})
    sys.path.insert(0, {tests!r})
    import numpy as np
    from addon.core import PatchScene, solve
    from boxes import box_rectangles, rectangles_to_mesh

    origin, u, v, face = box_rectangles(n=60)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    emission = np.where(face == 1, 1.0, 0.0)
    scene = PatchScene(vertices, triangles, triangle_patch, np.full(P, 0.3), emission)
    out = {{"patches": P}}
    for name, paths in (("small", 32 * 65536), ("large", 128 * 65536)):
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
    code = CHILD.format(root=str(ROOT), tests=str(Path(__file__).parent))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout.strip().splitlines()[-1])
    small, large = out["small"], out["large"]
    assert out["patches"] == 21_600
    # the peak resident set after the 4x longer run: no more than MARGIN above the first run's
    assert large["rss"] - small["rss"] <= MARGIN_RSS, (small, large)
    assert large["traced"] - small["traced"] <= MARGIN_TRACED, (small, large)
    # and the solve's own allocations are bounded by the chunk size, not the path count: under
    # half a float64 per path of the large run (32 MiB; the chunks in flight need about 13 MiB)
    assert large["traced"] < 8 * large["paths"] / 2, (small, large)
