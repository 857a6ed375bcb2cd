"""The predicted time against the real one, for the default settings' method (Automatic).

    python -m benchmarks.prediction                 # suite and other scenes -> results/prediction.{md,json,png}
    python -m benchmarks.prediction --quick         # a few small cases, to out/
    python -m benchmarks.prediction --estimates-only out/prediction_before.json   # (run in a checkout of an
                                                    # earlier commit: its estimates, for the "before" column)
    python -m benchmarks.prediction --replot benchmarks/results/prediction.json

Each case: the scene built in Blender (bpy module), selected, the panel's settings but the
error target (5% is the default) and 2 threads. The estimate (``pipeline.estimate``: what the
panel and the command line show before a run) is made three times, with seeds 0, 1 and 2 (its
pilot's chunks differ; the machine's load too); then the run (``pipeline.run_solve``, seed 0),
whose wall time, meshing included, is the real time. During the run, the prediction it updates
(elapsed + the seconds left, from its measured error) is read at its first finite value (after
two chunks) and when half the run has passed. Ratios are predicted over real; the summary gives
the median and the worst (furthest from 1, either way) over the cases.

Scenes: the suite's (``benchmarks.suite``, each patch a quad of its own, patch size 1e6 keeps
them) and scenes it was not tuned for: the sample scenes' figure 6 room and Cornell box (paper
units), the figure 1 cube at R = 0.8, the figure 6 room cut into 0.1 m patches (about 44,000)
and 0.03 m ones (about 490,000: Automatic takes the paper's walk there), and a closed room of base
colour 0.999 (1,000 bounces a path).
"""
from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

SUITE = ("empty_room", "cornell", "lamp_room", "open_sun_world", "fig4_room")
# (name, scene, error target %, patch size); scene "suite:NAME" or "sample:NAME" or "white:R"
CASES = [(f"{s} {e:g}%", f"suite:{s}", e, 1e6) for s in SUITE for e in ((5.0, 2.0) if s == "fig4_room" else (5.0, 2.0, 1.0))]
CASES += [
    ("fig6 room 5%", "sample:fig6_room", 5.0, 1e6),
    ("fig6 room 1%", "sample:fig6_room", 1.0, 1e6),
    ("Cornell box (sample) 2%", "sample:cornell_box", 2.0, 1e6),
    ("fig1 cube R 0.8 2%", "sample:fig1_r0.8", 2.0, 1e6),
    ("fig6 room, 0.1 m patches 5%", "sample:fig6_room", 5.0, 0.1),
    ("fig6 room, 0.03 m patches 5%", "sample:fig6_room", 5.0, 0.03),
    ("white room 0.999 5%", "white:0.999", 5.0, 0.1),
]
QUICK = [c for c in CASES if c[0] in ("empty_room 5%", "cornell 1%", "white room 0.999 5%")]
SEEDS = (0, 1, 2)


def build(scene):
    """The scene in a fresh Blender file, its objects selected."""
    import bpy

    kind, name = scene.split(":")
    if kind == "suite":
        from benchmarks import suite

        suite.build(suite.SCENES[name]())  # (registers the extension)
        return
    bpy.ops.wm.read_factory_settings(use_empty=True)
    import addon

    addon.register()
    if kind == "sample":
        import sample_scenes
        from sample_scenes.blender import to_blender

        for o in to_blender(sample_scenes.build(name)):
            o.select_set(True)
    else:
        from tests.blender.conftest import box_arrays, make_object, principled

        base = float(name)
        v, f = box_arrays((0, 0, 0), (1, 1, 1), inward=True)
        room = make_object("Room", v, f, [principled("White", (base,) * 3),
                                          principled("Emitter", (base,) * 3, (1, 1, 1), 4.0)], [0, 1, 0, 0, 0, 0])
        room.select_set(True)


def settings_for(error, patch_size, seed=0):
    from addon.bpy_free import pipeline

    return pipeline.SolveSettings(relative_rms=error / 100, patch_size=patch_size, threads=2, seed=seed)


def estimates(case):
    import bpy

    from addon.bpy_free import pipeline
    from addon.blender_read.selection import read_selection

    name, scene, error, patch_size = case
    build(scene)
    objects, _ = read_selection(bpy.context)
    out = []
    for seed in SEEDS:
        started = time.perf_counter()
        value = pipeline.estimate(objects, settings_for(error, patch_size, seed))
        out.append({"seconds": value["seconds"], "paths": value["paths"], "rays": value["rays"], "method": value["method"],
                    "patches": value["patches"], "took": time.perf_counter() - started})
    return objects, out


def measure(case):
    from addon.bpy_free import pipeline

    objects, predicted = estimates(case)
    seen = []
    started = time.perf_counter()

    def progress(fraction, stats):
        seen.append((time.perf_counter() - started, stats.get("seconds_left", math.nan)))

    out = pipeline.run_solve(objects, settings_for(case[2], case[3]), progress=progress)
    real = time.perf_counter() - started
    during = [(t, t + left) for t, left in seen if left == left]
    first = during[0] if during else (math.nan, math.nan)
    half = next(((t, p) for t, p in during if t >= real / 2), first)
    r = out.result
    return {"case": case[0], "patches": int(r.radiosity.shape[0]), "method": r.method, "paths": r.paths, "rays": r.rays,
            "chunks": r.chunks, "stopped": r.stopped, "real": real, "estimates": predicted,
            "during_first": {"at": first[0], "predicted": first[1]}, "during_half": {"at": half[0], "predicted": half[1]}}


def _worst(ratios):
    return max(ratios, key=lambda x: abs(math.log(x))) if ratios else math.nan


def _summary(ratios):
    return f"median {statistics.median(ratios):.2f}, worst {_worst(ratios):.2f}" if ratios else "-"


def report(rows, before, command, out):
    lines = ["# The predicted time against the real one", "", f"`{command}`", "",
             (__doc__.split("\n\n", 2)[2]).strip(), "",
             "| case | patches | method | real s | paths (chunks) | predicted s (3 estimates) | ratios | "
             "during: at s, predicted s, ratio | half-way: ratio | before: predicted s, ratio |",
             "|---|---:|---|---:|---:|---|---|---|---:|---|"]
    before_by = {b["case"]: b for b in before or []}
    after_all, long_all, first_all, half_all, before_all = [], [], [], [], []
    for r in rows:
        real = r["real"]
        ratios = [e["seconds"] / real for e in r["estimates"]]
        after_all += ratios
        if real >= 1.0:
            long_all += ratios
        d, h = r["during_first"], r["during_half"]
        first_ratio = d["predicted"] / real if d["predicted"] == d["predicted"] else math.nan
        half_ratio = h["predicted"] / real if h["predicted"] == h["predicted"] else math.nan
        if first_ratio == first_ratio:
            first_all.append(first_ratio)
        if half_ratio == half_ratio:
            half_all.append(half_ratio)
        b = before_by.get(r["case"])
        cell = "-"
        if b:
            old = [e["seconds"] / real for e in b["estimates"] if e["seconds"] == e["seconds"]]
            before_all += old
            cell = ", ".join(f"{e['seconds']:.3g}" for e in b["estimates"]) + ": " + (
                ", ".join(f"{x:.2f}" for x in old) if old else "NaN")
        lines.append(f"| {r['case']} | {r['patches']:,} | {r['method']} | {real:.2f} | {r['paths']:,} ({r['chunks']}) | "
                     + ", ".join(f"{e['seconds']:.3g}" for e in r["estimates"]) + " | "
                     + ", ".join(f"{x:.2f}" for x in ratios)
                     + f" | {d['at']:.2f}, {d['predicted']:.3g}, {first_ratio:.2f} | {half_ratio:.2f} | {cell} |")
    rows_text = lines
    summary = ["", "## Summary (ratio predicted / real over every estimate of every case)", "",
               f"- before the run (this estimate): {_summary(after_all)}; within 2x: "
               f"{sum(0.5 <= x <= 2 for x in after_all)} of {len(after_all)}",
               f"- the same, runs of a second or more: {_summary(long_all)}; within 2x: "
               f"{sum(0.5 <= x <= 2 for x in long_all)} of {len(long_all)}",
               f"- during the run, its first prediction (after two chunks): {_summary(first_all)}",
               f"- during the run, half-way: {_summary(half_all)}"]
    if before_all:
        summary.append(f"- before this change (the estimate of the earlier commit, same cases, same real times): "
                       f"{_summary(before_all)}; within 2x: {sum(0.5 <= x <= 2 for x in before_all)} of {len(before_all)}")
    out.write_text("\n".join(rows_text + summary + ["", f"![predicted against real]({out.with_suffix('.png').name})", ""]))


def plot(rows, before, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 5.2))
    before_by = {b["case"]: b for b in before or []}
    for k, r in enumerate(rows):
        real = r["real"]
        ax.plot([real] * len(r["estimates"]), [e["seconds"] for e in r["estimates"]], "o", color="C0",
                label="this estimate" if k == 0 else None)
        b = before_by.get(r["case"])
        if b:
            old = [e["seconds"] for e in b["estimates"] if e["seconds"] == e["seconds"] and e["seconds"] > 0]
            ax.plot([real] * len(old), old, "x", color="C3", label="before" if k == 0 else None)
        if r["during_first"]["predicted"] == r["during_first"]["predicted"]:
            ax.plot(real, r["during_first"]["predicted"], "s", color="C2", ms=4, label="during the run (first)" if k == 0 else None)
    lo = min(r["real"] for r in rows) / 3
    hi = max(r["real"] for r in rows) * 3
    xs = [lo, hi]
    ax.plot(xs, xs, color="k", lw=0.8)
    ax.fill_between(xs, [x / 2 for x in xs], [x * 2 for x in xs], color="grey", alpha=0.2, label="within 2x")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("real seconds (meshing and solve, 2 threads)")
    ax.set_ylabel("predicted seconds")
    ax.set_title("Predicted against real time, default method")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--cases", nargs="+", help="names of cases to run (default: all)")
    p.add_argument("--estimates-only", type=Path, help="only the estimates, as JSON, to this file")
    p.add_argument("--before", type=Path, help="JSON of --estimates-only from an earlier commit")
    p.add_argument("--replot", type=Path)
    args = p.parse_args(argv)
    cases = QUICK if args.quick else CASES
    if args.cases:
        cases = [c for c in CASES if c[0] in args.cases]
    out = (ROOT / "out" if args.quick else RESULTS) / "prediction.md"
    out.parent.mkdir(exist_ok=True)
    before = json.loads(args.before.read_text()) if args.before else None
    if args.replot:
        data = json.loads(args.replot.read_text())
        plot(data["rows"], data.get("before"), args.replot.with_suffix(".png"))
        report(data["rows"], data.get("before"), data["command"], args.replot.with_suffix(".md"))
        return
    if args.estimates_only:
        rows = []
        for case in cases:
            _, predicted = estimates(case)
            rows.append({"case": case[0], "estimates": predicted})
            print(case[0], [round(e["seconds"], 2) for e in predicted], flush=True)
        args.estimates_only.write_text(json.dumps(rows, indent=1))
        return
    rows = []
    for case in cases:
        row = measure(case)
        rows.append(row)
        print(f"{row['case']}: real {row['real']:.2f} s, predicted "
              + ", ".join(f"{e['seconds']:.2f}" for e in row["estimates"]), flush=True)
    command = "python -m benchmarks.prediction" + (" --quick" if args.quick else "")
    data = {"command": command, "rows": rows, "before": before}
    out.with_suffix(".json").write_text(json.dumps(data, indent=1))
    plot(rows, before, out.with_suffix(".png"))
    report(rows, before, command, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
