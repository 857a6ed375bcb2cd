"""Whether walks on two threads should take turns at their numpy work, per way of solving.

    python -m benchmarks.turns [--scenes small_room cornell room_fig4] [--rounds 5]

Walks on several threads hold a lock (``tables.numpy_turn``) for their numpy work and let go of
it while they trace, so that one traces while the other computes. Without the lock both may
compute at once: numpy lets go of the GIL inside most operations on large arrays. Which is
faster depends on the arrays' size. Each case solves the same scene and seed with turns taken
and not (``walk.takes_turns`` forced either way, the paper's walk run as chunk-wide work for "not"), alternating which goes first, over 2
threads; reported: median wall seconds of each and the median of the rounds' ratios (no turns /
turns; below 1: faster without), with its range. The rule in ``walk.takes_turns`` is read off
this table.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from benchmarks.throughput import build_scene

RESULTS = Path(__file__).resolve().parent / "results"
# (label, solve arguments, paths by scene)
CASES = (
    ("paper walk", {}, {"small_room": 2_000_000, "cornell": 4_000_000, "room_fig4": 2_000_000}),
    ("gathered walk", {"direct_light": "gathered"}, {"small_room": 1_000_000, "cornell": 2_000_000, "room_fig4": 1_000_000}),
    ("Jacobi iteration", {"method": "jacobi"}, {"small_room": 1_000_000, "cornell": 2_000_000, "room_fig4": 2_000_000}),
    ("two-way iteration", {"method": "two_way"}, {"small_room": 1_000_000, "cornell": 2_000_000, "room_fig4": 1_000_000}),
    # a small plan: 16 chunks of 1,250 paths (of 8,000 in the figure 4 room, whose chunks grow to 8 chunks)
    ("two-way iteration, small plan", {"method": "two_way"}, {"small_room": 20_000, "cornell": 20_000, "room_fig4": 64_000}),
)


def timed(scene, turns, paths, arguments, seed):
    from addon.core import solve
    from addon.core.methods import walk
    from addon.core.methods.walk import ShotWalk

    rule, shot = walk.takes_turns, ShotWalk.run
    walk.takes_turns = lambda tables, paths: turns
    if not turns:  # (the paper's walk always takes turns: run it as chunk-wide work)
        ShotWalk.run = lambda self, sizes, rng, abort=None: walk.walk_chunks(
            walk.chunk_wide(self.tables, sum(sizes)), sizes, rng, abort)
    try:
        start = time.perf_counter()
        result = solve(scene, estimator="finite", paths=paths, threads=2, seed=seed, exit_point="hit", **arguments)
        return time.perf_counter() - start, result
    finally:
        walk.takes_turns, ShotWalk.run = rule, shot


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=["small_room", "cornell", "room_fig4"])
    parser.add_argument("--rounds", type=int, default=5)
    args = parser.parse_args(argv)
    from addon.core.methods import walk

    rows = []
    for name in args.scenes:
        scene = build_scene(name)
        for label, arguments, paths in CASES:
            timed(scene, True, paths[name] // 10, arguments, 0)  # (warm the tables' caches)
            seconds = {True: [], False: []}
            for k in range(args.rounds):
                for turns in ((True, False) if k % 2 == 0 else (False, True)):
                    t, result = timed(scene, turns, paths[name], arguments, k)
                    seconds[turns].append(t)
            ratio = np.array(seconds[False]) / np.array(seconds[True])
            rows.append((name, label, np.median(seconds[True]), np.median(seconds[False]), np.median(ratio), ratio.min(), ratio.max(),
                         _rule(walk, scene, arguments, result.paths // result.chunks)))
            print(rows[-1], flush=True)
    lines = ["# Taking turns at numpy, or not, on 2 threads", "", "`" + " ".join(["python -m benchmarks.turns", *(sys.argv[1:] if argv is None else argv)]) + "`", "",
             __doc__.split("\n\n", 2)[2].strip(), "",
             "| scene | way of solving | turns s | no turns s | no turns / turns | range | the rule takes |",
             "|---|---|---:|---:|---:|---|---|"]
    for name, label, on, off, r, lo, hi, rule in rows:
        lines.append(f"| {name} | {label} | {on:.3f} | {off:.3f} | **{r:.2f}** | {lo:.2f}–{hi:.2f} | {rule} |")
    (RESULTS / "turns.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def _rule(walk, scene, arguments, chunk_paths):
    """What the rule takes for a solve with ``arguments``: the paper's walk always turns;
    chunk-wide work by walk.takes_turns."""
    from types import SimpleNamespace

    if not arguments:
        return "turns"
    return "turns" if walk.takes_turns(SimpleNamespace(patch_count=scene.patch_count), chunk_paths) else "no turns"


if __name__ == "__main__":
    main()
