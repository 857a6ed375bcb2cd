"""The walks on a Dask cluster against this machine's threads.

    python -m benchmarks.cluster            # about 10 minutes on 2 cores
    python -m benchmarks.cluster --quick    # a smoke run, to out/

Paths per second of the same solve (same seed, bitwise the same result, checked) with 1 and 2
local threads and on a LocalCluster of 1 and 2 worker processes (one thread each), on the small
room (the Cycles comparison's, 600 patches) and the paper's figure 4 room (66,572 patches); and
the fixed cost of a cluster solve: a one-chunk solve's time on the cluster over the same solve on
threads (the scene's scatter, the workers' first tables, the scheduler's round trips).
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"


def scenes(quick):
    from benchmarks.cycles_comparison import patch_scene
    from sample_scenes import build

    out = {"small_room": (patch_scene(), 3_000_000 if quick else 100_000_000)}
    if not quick:
        out["room_fig4"] = (build("fig4_room").scene, 10_000_000)
    return out


def timed(scene, paths, **options):
    from addon.core import solve

    start = time.perf_counter()
    r = solve(scene, paths=paths, seed=1, **options)
    return r, time.perf_counter() - start


def main(argv=None):
    import distributed

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    args = p.parse_args(argv)
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    import dask

    # Dask's nannies start workers with MALLOC_TRIM_THRESHOLD_=65536, which slows the walks by a
    # quarter (README, "On a cluster"): the workers here start without it, as the README advises.
    dask.config.set({"distributed.nanny.pre-spawn-environ": {}})
    rows, fixed = [], []
    all_scenes = scenes(args.quick)
    references = {}
    for name, (scene, paths) in all_scenes.items():
        for label, threads in (("1 thread", 1), ("2 threads", 2)):
            r, seconds = timed(scene, paths, threads=threads)
            references.setdefault(name, r.radiosity)
            rows.append((name, paths, label, seconds, r.paths / seconds, r.rays / seconds,
                         bool(np.array_equal(references[name], r.radiosity))))
            print(f"{name:10s} {label:9s} {seconds:8.1f} s  {r.paths / seconds / 1e6:6.2f} Mpaths/s", flush=True)
    for workers in (1, 2):  # one cluster at a time
        cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=40)
        client = distributed.Client(cluster)
        try:
            for name, (scene, paths) in all_scenes.items():
                if workers == 2:  # the fixed cost: a one-chunk solve, the scene's first on the cluster
                    _, local_small = timed(scene, 128, threads=2)
                    _, cluster_small = timed(scene, 128, cluster=client)
                    fixed.append((name, local_small, cluster_small))
                label = f"{workers} worker{'s' if workers > 1 else ''}"
                r, seconds = timed(scene, paths, cluster=client)
                same = bool(np.array_equal(references[name], r.radiosity))
                rows.append((name, paths, label, seconds, r.paths / seconds, r.rays / seconds, same))
                print(f"{name:10s} {label:9s} {seconds:8.1f} s  {r.paths / seconds / 1e6:6.2f} Mpaths/s  bitwise {same}",
                      flush=True)
        finally:
            client.close()
            cluster.close()
    rows.sort(key=lambda r: (list(all_scenes).index(r[0]), ["1 thread", "2 threads", "1 worker", "2 workers"].index(r[2])))
    write(rows, fixed, args.quick)


def write(rows, fixed, quick):
    out = (ROOT / "out" if quick else RESULTS) / "cluster.md"
    out.parent.mkdir(exist_ok=True)
    lines = ["# The walks on a Dask cluster against local threads", "",
             f"`python -m benchmarks.cluster{' --quick' if quick else ''}` on this 2-core machine: a LocalCluster of "
             "worker processes (one thread each) on the same machine, against solve()'s threads. Same seed: the "
             "radiosity is checked bitwise equal to the 1-thread run's.", "",
             "| scene | paths | runner | seconds | Mpaths/s | Mrays/s | against 2 threads | bitwise |",
             "|---|---:|---|---:|---:|---:|---:|---|"]
    two = {r[0]: r[4] for r in rows if r[2] == "2 threads"}
    for name, paths, label, seconds, pps, rps, same in rows:
        lines.append(f"| {name} | {paths:,} | {label} | {seconds:.1f} | {pps / 1e6:.3f} | {rps / 1e6:.2f} | "
                     f"{pps / two[name]:.2f} | {'yes' if same else 'NO'} |")
    lines += ["", "Fixed cost of a cluster solve (a 128-path solve: one chunk):", "",
              "| scene | 2 threads s | 2 workers s |", "|---|---:|---:|"]
    for name, local, cluster in fixed:
        lines.append(f"| {name} | {local:.2f} | {cluster:.2f} |")
    out.write_text("\n".join(lines) + "\n")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
