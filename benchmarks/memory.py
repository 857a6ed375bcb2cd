"""Peak memory of a solve on the figure-4 room (66,572 patches), at several path counts.

    python -m benchmarks.memory                 # 1M, 4M, 16M, 64M and 256M paths, into benchmarks/results/memory.md
    python -m benchmarks.memory --quick         # 250k and 1M paths, into out/
    python -m benchmarks.memory --operator      # 1M patches through the operator's code path (bpy),
                                                # into benchmarks/results/memory_operator.md

Every measurement runs in a fresh Python process, so its peak resident set (``ru_maxrss``) is its
own. A child reports the peak resident set after the imports, after building the scene (meshing,
validation, patch frames), after building the Embree BVH the solve traces (the default walk's: the
patches' grids, addon/core/scene/patch_grids.py), and after ``solve``; the solve's own
share is the last minus the one before. A second child per path count runs the same solve under
``tracemalloc``, whose peak counts the numpy and Python allocations made during the solve (not
Embree's own, which are made once with the BVH, before it).

The target: the peak stays under 1 GiB and does not grow with the number of paths.

``--operator`` measures the extension in Blender (the ``bpy`` module, headless) on a
room of about a million patches: see :mod:`benchmarks.memory_operator`.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).parent / "results"
GIB = 1 << 30
MIB = 1 << 20


def peak_rss():
    """Peak resident set of this process so far, in bytes (Linux reports KiB, macOS bytes)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak if sys.platform == "darwin" else peak * 1024


def current_rss():
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return float("nan")


def child(paths, threads, use_tracemalloc, scene_name):
    """One measurement; prints a JSON line."""
    sys.path.insert(0, str(ROOT))
    import numpy as np  # noqa: F401

    from addon.core import solve

    out = {"paths": paths, "threads": threads, "tracemalloc": use_tracemalloc, "after_imports": peak_rss()}
    t = time.perf_counter()
    if scene_name == "room_fig4":
        from sample_scenes import room_fig4

        scene = room_fig4.build().scene
    else:
        raise ValueError(scene_name)
    out["patches"] = scene.patch_count
    out["triangles"] = scene.geometry.triangle_count
    out["after_scene"] = peak_rss()
    # The Embree scene the solve traces, built once per geometry: the default walk's, the
    # patches' grids (addon/core/scene/patch_grids.py); the patches' triangles are not built.
    from addon.core.methods.tables import WalkTables

    out["traced_triangles"] = WalkTables(scene, "finite", 1e-3, "random").tracer.triangle_count
    out["after_bvh"] = peak_rss()
    out["current_before_solve"] = current_rss()
    out["build_seconds"] = time.perf_counter() - t
    if use_tracemalloc:
        import tracemalloc

        tracemalloc.start()
    t = time.perf_counter()
    result = solve(scene, estimator="finite", paths=paths, threads=threads, seed=1)
    out["solve_seconds"] = time.perf_counter() - t
    if use_tracemalloc:
        current, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        out["traced_peak"] = peak
        out["traced_after"] = current
    out["after_solve"] = peak_rss()
    out["current_after_solve"] = current_rss()
    out["rays"] = result.rays
    out["chunks"] = result.chunks
    from addon.core.estimate.plan import chunk_paths_for

    out["max_chunk"] = chunk_paths_for(result.prediction.expected_path_length, 10**15)
    print(json.dumps(out))


def measure(paths, threads=2, use_tracemalloc=False, scene="room_fig4"):
    cmd = [sys.executable, "-m", "benchmarks.memory", "--child", str(paths), "--threads", str(threads), "--scene", scene]
    if use_tracemalloc:
        cmd.append("--tracemalloc")
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--tracemalloc", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--scene", default="room_fig4")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--paths", type=int, nargs="+", default=None)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=None)
    ap.add_argument("--operator", action="store_true", help="the operator's code path in Blender (memory_operator)")
    args, rest = ap.parse_known_args(argv)
    if args.operator:
        from benchmarks import memory_operator

        memory_operator.main(rest + (["--quick"] if args.quick else []) + (["--out", args.out] if args.out else []))
        return
    args = ap.parse_args(argv)
    if args.child is not None:
        child(args.child, args.threads, args.tracemalloc, args.scene)
        return
    paths = args.paths or ([250_000, 1_000_000] if args.quick else [1_000_000, 4_000_000, 16_000_000, 64_000_000, 256_000_000])
    out = Path(args.out) if args.out else (ROOT / "out" / "memory_quick" if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for n in paths:
        plain = measure(n, args.threads, False, args.scene)
        traced = measure(n, args.threads, True, args.scene)
        rows.append((plain, traced))
        print(f"{n:>11,} paths: peak RSS {plain['after_solve'] / MIB:.0f} MiB "
              f"(before solve {plain['after_bvh'] / MIB:.0f} MiB), numpy peak in solve {traced['traced_peak'] / MIB:.1f} MiB",
              flush=True)
    p0 = rows[0][0]
    L = [
        "# Peak memory of a solve on the figure-4 room",
        "",
        f"`python -m benchmarks.memory {' '.join(a for a in (argv if argv is not None else sys.argv[1:]))}`".replace(" `", "`"),
        f"Machine: {platform.machine()}, Python {platform.python_version()}; scene `{args.scene}` "
        f"({p0['patches']:,} patches, {p0['triangles']:,} triangles, traced as {p0['traced_triangles']:,} triangles of "
        "their grids); finite estimator, random exit, "
        f"{args.threads} threads; "
        "each measurement in a fresh process.",
        "",
        "Peak resident set (ru_maxrss) after each stage, and the peak of numpy/Python allocations made during "
        "`solve` (tracemalloc, separate process). Target: peak < 1 GiB (1024 MiB), not growing with paths.",
        "",
        "| paths | rays | chunks | solve s | after imports MiB | after scene MiB | after BVH MiB | **peak after solve MiB** "
        "| solve's share MiB | tracemalloc peak in solve MiB | left allocated after solve MiB |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for plain, traced in rows:
        L.append(
            f"| {plain['paths']:,} | {plain['rays']:,} | {plain['chunks']} | {plain['solve_seconds']:.1f} | "
            f"{plain['after_imports'] / MIB:.0f} | {plain['after_scene'] / MIB:.0f} | {plain['after_bvh'] / MIB:.0f} | "
            f"**{plain['after_solve'] / MIB:.0f}** | {(plain['after_solve'] - plain['after_bvh']) / MIB:.0f} | "
            f"{traced['traced_peak'] / MIB:.1f} | {traced['traced_after'] / MIB:.2f} |"
        )
    peaks = [p["after_solve"] for p, _ in rows]
    from addon.core.estimate import plan

    # The smallest run whose chunks have the maximum size (smaller runs split into MIN_CHUNKS).
    max_chunk = rows[0][0]["max_chunk"]
    full_size = plan.MIN_CHUNKS * max_chunk
    full = next((k for k, n in enumerate(paths) if n >= full_size), len(paths) - 1)
    traced = [t["traced_peak"] for _, t in rows]
    L += [
        "",
        f"Largest peak: {max(peaks) / MIB:.0f} MiB ({'under' if max(peaks) < GIB else 'OVER'} 1 GiB). "
        f"From {paths[0]:,} to {paths[-1]:,} paths ({paths[-1] // paths[0]}x) the peak resident set changes by "
        f"{(peaks[-1] - peaks[0]) / MIB:+.0f} MiB and the solve's numpy peak by {(traced[-1] - traced[0]) / MIB:+.1f} MiB"
        + (f"; from {paths[full]:,} paths on (full-size chunks) by {(peaks[-1] - peaks[full]) / MIB:+.0f} MiB and "
           f"{(traced[-1] - traced[full]) / MIB:+.1f} MiB." if full < len(paths) - 1 else "."),
        "",
        "What the solve holds: per-patch tallies (a few float64 arrays of P per channel), and up to threads + 1 "
        f"chunks in flight, each at most {max_chunk:,} paths (about {plan.RAYS_PER_CHUNK:,} rays) with its "
        "paths' sources, a wavefront of about 16k paths and the scores of at most 2^18 hits; chunk tallies are "
        f"added in order and dropped, so nothing scales with the path count. Runs below {plan.MIN_CHUNKS} x "
        f"{max_chunk:,} = {full_size / 1e6:.1f}M paths use smaller chunks, hence a smaller peak there.",
    ]
    (out / "memory.md").write_text("\n".join(L) + "\n")
    (out / "memory.json").write_text(json.dumps([{"plain": p, "traced": t} for p, t in rows], indent=1))
    print("\n".join(L))


if __name__ == "__main__":
    main()
