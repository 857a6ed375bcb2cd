"""When the two-way iteration beats the walk: its gain against the rays each patch gets in a chunk.

    python -m benchmarks.auto_method            # into benchmarks/results/auto_method.md and .png
    python -m benchmarks.auto_method --quick    # two sizes, into out/
    python -m benchmarks.auto_method --divisions 190 270   # these sizes' rows replaced in the results

The two-way iteration's chunks are independent replicas of the whole solve (the batch means
measure its error). Each generation of a chunk estimates the light every patch reflects from
the rays it got; with about one ray a patch that estimate is mostly noise, which the next
generation's gathering reads, and the iteration's gain over the walk goes. This measures it:
the closed Cornell box (two blocks, colour walls, a small ceiling light) meshed at several patch
counts, and for each, solves of 4, 16, 64 and 256 paths a patch (the plan sets the rays a patch
a chunk gets: ``methods.two_way.TwoWay.chunk_paths``, up to ``TWO_WAY_MAX_CHUNK_PATHS`` paths a chunk,
so that past about 2^19 patches no plan gives a patch 4 first-generation rays). Each solve's error is the RMS over
patches / mean of the reflected radiosity from its batch means; the gain is the walk's error^2 x
rays (and x seconds, 2 threads) over the two-way iteration's at the same plan: above 1 the
two-way iteration reaches an error with fewer rays (less time). Exit point hit (the panel's
default). ``method="auto"``'s choice (``solver.chosen_method``) is shown beside each.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from addon.core import solve  # noqa: E402
from addon.core.methods import two_way  # noqa: E402
from addon.core.settings import Settings  # noqa: E402
from addon.core.solver import chosen_method  # noqa: E402
from addon.core.estimate.error_model import predict  # noqa: E402

DIVISIONS = (20, 40, 60, 90, 120, 190, 270)
PATHS_A_PATCH = (4, 16, 64, 256)


def error(result):
    """RMS over patches of the reflected radiosity's standard error, over its mean."""
    return float(np.sqrt(result.reflected_variance.mean()) / result.reflected.mean())


def measure(divisions, paths_a_patch):
    import sample_scenes

    scene = sample_scenes.build("cornell_box", divisions=divisions, closed=True).scene
    P = scene.patch_count
    rows = []
    for k in paths_a_patch:
        paths = k * P
        chunk = two_way.TwoWay().chunk_paths(P, predict(scene).expected_path_length, paths)
        row = {"patches": P, "paths_a_patch": k, "paths": paths,
               "first_generation_rays": two_way.first_generation_rays(P, chunk),
               "auto": chosen_method(scene, Settings(method="auto", paths=paths))}
        for method in ("walk", "two_way"):
            r = solve(scene, paths=paths, seed=1, threads=2, exit_point="hit", method=method)
            row[method] = {"error": error(r), "rays": r.rays, "seconds": r.seconds, "chunks": r.chunks}
        w, t = row["walk"], row["two_way"]
        row["gain_rays"] = w["error"] ** 2 * w["rays"] / (t["error"] ** 2 * t["rays"])
        row["gain_seconds"] = w["error"] ** 2 * w["seconds"] / (t["error"] ** 2 * t["seconds"])
        rows.append(row)
        print(f"{P:,} patches, {k} paths a patch: {row['first_generation_rays']:.1f} rays a patch a generation, "
              f"gain {row['gain_rays']:.2f} (rays) {row['gain_seconds']:.2f} (s), auto {row['auto']}", flush=True)
    return rows


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), sharey=True)
    for ax, key, what in ((axes[0], "gain_rays", "error$^2$ x rays"), (axes[1], "gain_seconds", "error$^2$ x seconds")):
        for P in sorted({r["patches"] for r in rows}):
            mine = [r for r in rows if r["patches"] == P]
            ax.plot([r["paths_a_patch"] for r in mine], [r[key] for r in mine], "o-", label=f"{P:,} patches")
            for r in mine:
                ax.annotate(f"{r['first_generation_rays']:.0f}", (r["paths_a_patch"], r[key]), fontsize=7,
                            textcoords="offset points", xytext=(4, 3))
        ax.axhline(1.0, color="grey", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("paths a patch planned (labels: first-generation rays a patch, a chunk)")
        ax.set_title(f"two-way gain over the walk, {what}", fontsize=10)
    axes[0].set_ylabel("gain (above 1: the two-way iteration)")
    axes[0].legend(fontsize=8)
    fig.suptitle("Closed Cornell box: where the two-way iteration pays (auto: from 4 rays a patch, up to 393,216 patches)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def report(rows, command, out):
    lines = ["# When the two-way iteration beats the walk", "", f"`{command}`", "",
             __doc__.split("\n\n", 1)[1].strip(), "",
             "| patches | paths a patch | two-way chunks | first-generation rays a patch | walk error | two-way error | "
             "gain in rays | gain in seconds | auto takes |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lines.append(f"| {r['patches']:,} | {r['paths_a_patch']} | {r['two_way']['chunks']} | {r['first_generation_rays']:.1f} | "
                     f"{r['walk']['error']:.4f} | {r['two_way']['error']:.4f} | {r['gain_rays']:.2f} | "
                     f"{r['gain_seconds']:.2f} | {r['auto']} |")
    lines += ["", f"![gain against rays a patch]({out.stem}.png)", ""]
    out.write_text("\n".join(lines) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--plot-only", action="store_true", help="redraw the plot from the last results' JSON")
    p.add_argument("--divisions", type=int, nargs="+", default=None,
                   help="only these box sizes (cells a side), their rows replacing theirs in the last results")
    args = p.parse_args(argv)
    if args.plot_only:
        plot(json.loads((RESULTS / "auto_method.json").read_text()), RESULTS / "auto_method.png")
        return
    started = time.perf_counter()
    divisions = (20, 60) if args.quick else args.divisions or DIVISIONS
    rows = [row for d in divisions for row in measure(d, PATHS_A_PATCH[:2] if args.quick else PATHS_A_PATCH)]
    if args.divisions and not args.quick:
        sizes = {r["patches"] for r in rows}
        kept = [r for r in json.loads((RESULTS / "auto_method.json").read_text()) if r["patches"] not in sizes]
        rows = sorted(kept + rows, key=lambda r: (r["patches"], r["paths_a_patch"]))
    folder = ROOT / "out" if args.quick else RESULTS
    folder.mkdir(exist_ok=True)
    out = folder / "auto_method.md"
    (folder / "auto_method.json").write_text(json.dumps(rows, indent=1))
    plot(rows, folder / "auto_method.png")
    command = "python -m benchmarks.auto_method" + (" --quick" if args.quick else "")
    if args.divisions and not args.quick:
        command += " --divisions " + " ".join(map(str, args.divisions)) + " (the other sizes' rows from the run before)"
    report(rows, command, out)
    print(f"wrote {out} ({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
