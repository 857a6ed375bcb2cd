"""Which exit point is closer to Cycles at equal time: the paper's random exit point against the hit point.

    nice -n 10 python -m benchmarks.exits --references   # Cycles' fine references (about 15 minutes, 1 thread)
    nice -n 10 python -m benchmarks.exits                # both exits, every method, equal time (about 15 minutes)
    python -m benchmarks.exits --quick                   # a smoke run, to out/
    python -m benchmarks.exits --replot benchmarks/results/exits.json

The random exit point (the paper's discrete method) converges to the discrete radiosity system of
the flat patches; the hit point (particle tracing) to the continuous light averaged over each
patch, which is what Cycles' bake of a patch's pixel block averages. The difference is a
discretization error that no run's error estimate shows (the batch means measure the noise about
what a method converges to). This measures it, and what it costs at equal time.

Scenes (suite.py's, every material Lambertian, each at three patch sizes that nest: coarse, the
panel's automatic size, fine):

- ``empty_room``: the closed 1 m room of ``cycles_comparison`` (albedo 0.5, a 0.2 m emitting
  ceiling square), patches 0.1, 0.05 (automatic) and 0.025 m; at 0.1 m also against the exact
  continuous reference of ``cycles_comparison`` (a direct solve on 4x finer patches,
  extrapolated), which checks the Cycles reference;
- ``lamp_room``: the closed Cornell box lit only by a point light and a 0.3 m area light
  (suite.py's), patches 0.1 and 0.05 m (automatic; the finest here: a 0.025 m reference would take
  Cycles over an hour on a shared machine);
- ``open_sun_world``: suite.py's open floor, red wall and block under a sun and a uniform sky,
  patches 0.25, 0.125 and 0.0625 m (automatic: 0.1 m).

Reference: Cycles' COMBINED bake of the finest patches (1 thread, 16 pixels a patch, two
seeds of 128 samples a pixel, 96 in the lamp room and the open scene), averaged onto the coarser patches that contain them. Its own noise (a patch's variance of
the two bakes' mean is a quarter of their squared difference) is subtracted from each measured
mean square and stated.

Ours: the operator's pipeline (``pipeline.run_solve``) on the same quads (one patch each), to an
error target of TARGET (the panel's measure, stopped on the measured error; twice that on
the fine patches, where the walk's time to a target grows with the patch count), both exit points
alternating within the run (which goes first alternates too), 2 threads, for every method: the paper's walk with the finite
and the biased infinite estimator (its direct light shot), the two-way iteration, Automatic,
and the stochastic Jacobi iteration (which always leaves from a random point: it takes no exit
point, so it runs once).

Measure: over the patches that do not emit and are lit above 2% of the brightest, the per-patch
relative mean square mean(((B - B_ref) / B_ref)^2) of the grey (channel mean) radiosity, split
into
- noise: ours (the batch means' variance per patch, mean over channels) and the reference's;
- bias: what is left, mostly the discretization error of the random exit (sqrt(max(0, ...)));
and the error against Cycles with the reference's noise subtracted, sqrt(mean square - ref
noise). At equal time: each run's noise scaled to the median run time T of its scene and patch
size (noise^2 x seconds / T, the Monte Carlo law), its bias kept. The time to 1% per patch:
seconds x noise^2 / (1%^2 - bias^2) (never, where the bias alone is above 1%).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
REFERENCE_FILE = RESULTS / "exits_reference.npz"

from benchmarks.cycles_comparison import quads as rectangle_quads, room_rectangles  # noqa: E402
from benchmarks.suite import LIT, Spec, face_values  # noqa: E402

TARGET = 0.01
FINE_TARGET = 2.0  # the fine patches' target, times TARGET (the walk's time grows with the patches)
SEEDS = (1,)
LEVEL = 0.01
SAMPLES = 128  # a reference bake's samples a pixel (two bakes)
REFERENCE_SAMPLES = {"lamp_room": 96, "open_sun_world": 96}  # where fewer (the machine's time)
# (method, estimator) configurations; Jacobi takes no exit point
CONFIGS = {"walk_finite": ("walk", "finite"), "walk_biased": ("walk", "biased_infinite"),
           "two_way": ("two_way", "finite"), "auto": ("auto", "finite"), "jacobi": ("jacobi", "finite")}
LABELS = {"walk_finite": "walk, finite", "walk_biased": "walk, biased infinite", "two_way": "two-way iteration",
          "auto": "Automatic", "jacobi": "Jacobi (random only)"}
EXITS = ("random", "hit")


# --- the scenes at a patch size ---------------------------------------------------------------

def empty_room(n):
    origin, u, v, light = room_rectangles(n)
    P = len(origin)
    return Spec(rectangle_quads(origin, u, v), np.full((P, 3), 0.5), np.where(light[:, None], 1.0, 0.0) * np.ones(3),
                block=4)


def lamp_room(n):
    import sample_scenes

    sample = sample_scenes.build("cornell_box", divisions=n, closed=True)
    P = sample.patch_count
    corners, R, E = sample.vertices.reshape(P, 4, 3), sample.reflectivity, sample.emission
    keep = np.array(sample.part_names)[sample.patch_part] != "light"
    lights = [("POINT", {"energy": 30.0, "shadow_soft_size": 0.05, "use_soft_falloff": False}, (0.7, 0.6, 0.8), (0, 0, 0)),
              ("AREA", {"energy": 40.0, "shape": "SQUARE", "size": 0.3}, (0.3, 0.3, 0.97), (0, 0, 0))]
    return Spec(corners[keep].copy(), R[keep].copy(), E[keep].copy(), lights=lights, block=4)


def open_quads(k):
    """cycles_lights.quads with every grid k times finer."""
    cells, colours = [], []

    def grid(origin, u, v, nu, nv, colour):
        o, a, b = (np.asarray(x, float) for x in (origin, u, v))
        for i in range(nu):
            for j in range(nv):
                c = o + a * i / nu + b * j / nv
                cells.append([c, c + a / nu, c + a / nu + b / nv, c + b / nv])
                colours.append(colour)

    grid((-1, -1, 0), (2, 0, 0), (0, 2, 0), 8 * k, 8 * k, (0.5, 0.5, 0.5))
    grid((-1, 1, 0), (2, 0, 0), (0, 0, 1), 8 * k, 4 * k, (0.6, 0.2, 0.2))
    lo, hi = np.array([-0.5, -0.2, 0.0]), np.array([-0.1, 0.2, 0.4])
    s = hi - lo
    for origin, u, v in (((lo[0], lo[1], hi[2]), (s[0], 0, 0), (0, s[1], 0)), ((lo[0], lo[1], lo[2]), (0, 0, s[2]), (0, s[1], 0)),
                         ((hi[0], lo[1], lo[2]), (0, s[1], 0), (0, 0, s[2])), ((lo[0], lo[1], lo[2]), (s[0], 0, 0), (0, 0, s[2])),
                         ((lo[0], hi[1], lo[2]), (0, 0, s[2]), (s[0], 0, 0))):
        grid(origin, u, v, 2 * k, 2 * k, (0.5, 0.5, 0.5))
    return np.array(cells), np.array(colours)


def open_sun_world(k):
    corners, R = open_quads(k)
    lights = [("SUN", {"energy": 3.0, "angle": math.radians(8)}, (0, 0, 3), (math.radians(35), 0, math.radians(20)))]
    return Spec(corners, R, np.zeros_like(R), lights=lights, world=((0.3, 0.35, 0.4), 1.0), block=4)


# scene: (spec maker, [(label, argument, patch edge m)] coarse to fine; the last is the reference's)
SCENES = {
    "empty_room": (empty_room, [("coarse", 10, 0.1), ("automatic", 20, 0.05), ("fine", 40, 0.025)]),
    # (its 0.025 m reference, 11,616 patches, would take Cycles over an hour on a shared machine)
    "lamp_room": (lamp_room, [("coarse", 10, 0.1), ("automatic", 20, 0.05)]),
    "open_sun_world": (open_sun_world, [("coarse", 1, 0.25), ("automatic", 2, 0.125), ("fine", 4, 0.0625)]),
}


def containing(coarse, fine):
    """(F,) the index of the coarse quad (P,4,3) that holds each fine quad's centre; every fine
    quad in exactly one (rectangles whose edges nest)."""
    o = coarse[:, 0]
    u, v = coarse[:, 1] - o, coarse[:, 3] - o
    n = np.cross(u, v)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    centre = fine.mean(axis=1)
    owner = np.full(len(fine), -1)
    for p in range(len(coarse)):
        d = centre - o[p]
        s, t = d @ u[p] / (u[p] @ u[p]), d @ v[p] / (v[p] @ v[p])
        inside = (np.abs(d @ n[p]) < 1e-7) & (s > 0) & (s < 1) & (t > 0) & (t < 1)
        if np.any(owner[inside] >= 0):
            raise ValueError("a fine patch lies in two coarse ones")
        owner[inside] = p
    if np.any(owner < 0):
        raise ValueError("a fine patch lies in no coarse one")
    return owner


def area(corners):
    return np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 3] - corners[:, 0]), axis=1)


def aggregate(values, owner, weight, count):
    """Area-weighted means of per-fine-patch values (F,...) over each coarse patch."""
    w = weight.reshape(-1, *([1] * (values.ndim - 1)))
    out = np.zeros((count, *values.shape[1:]))
    np.add.at(out, owner, values * w)
    total = np.zeros(count)
    np.add.at(total, owner, weight)
    return out / total.reshape(-1, *([1] * (values.ndim - 1)))


# --- Cycles' reference ------------------------------------------------------------------------

def bake_reference(name, samples, log=print):
    """Two bakes (P,3) of the scene's finest patches, seeds 1 and 2, on one thread."""
    import bpy

    from benchmarks.cycles_lights import bake
    from benchmarks.suite import build

    maker, levels = SCENES[name]
    spec = maker(levels[-1][1])
    _, image, rows, columns = build(spec)
    scene = bpy.context.scene
    scene.render.threads_mode, scene.render.threads = "FIXED", 1
    P = len(spec.corners)
    a, wall_a = bake(image, rows, columns, spec.block, P, samples, seed=1)
    b, wall_b = bake(image, rows, columns, spec.block, P, samples, seed=2)
    log(f"{name}: reference {P} patches, {spec.block}x{spec.block} px, 2 x {samples} samples: {wall_a + wall_b:.0f} s")
    return a, b, wall_a + wall_b


def references(names, samples=SAMPLES, recompute=False, log=print):
    stored = dict(np.load(REFERENCE_FILE)) if REFERENCE_FILE.exists() else {}
    for name in names:
        n = min(samples, REFERENCE_SAMPLES.get(name, samples))
        if f"{name}_a" in stored and not recompute and int(stored[f"{name}_samples"]) == n:
            continue
        a, b, seconds = bake_reference(name, n, log)
        made = {f"{name}_a": a, f"{name}_b": b, f"{name}_samples": np.array(n), f"{name}_seconds": np.array(seconds)}
        stored.update(made)
        REFERENCE_FILE.parent.mkdir(parents=True, exist_ok=True)
        # (read again first: another run may have stored another scene meanwhile)
        np.savez(REFERENCE_FILE, **({**dict(np.load(REFERENCE_FILE)), **made} if REFERENCE_FILE.exists() else stored))
    return stored


# --- ours -------------------------------------------------------------------------------------

def ours(config, exit_point, target, seed):
    """(B (P,3) in face order, its variance, solve seconds, paths, the method that ran, its
    measured MSE over formula (2)/(3)'s for its paths)."""
    import bpy

    from addon.blender_read.selection import read_selection
    from addon.bpy_free import pipeline

    method, estimator = CONFIGS[config]
    objects, _ = read_selection(bpy.context)
    settings = pipeline.SolveSettings(relative_rms=target, patch_size=1e6, seed=seed, threads=2,
                                      exit_point=exit_point, method=method, estimator=estimator, output="FACE")
    cpu = time.process_time()
    out = pipeline.run_solve(objects, settings)
    cpu = time.process_time() - cpu
    B, variance = face_values(out)
    r = out.result
    return B, variance, r.seconds, int(r.paths), r.method, float(r.measured_mse / r.predicted_mse), cpu


# Configurations left out at a patch size (the walk's time to a target grows with the patches;
# the biased estimator's exits behave as the finite one's at the coarser sizes), and whether
# Automatic shares the two-way iteration's runs where it takes it (set for the later scenes).
SKIPPED = {}
CPU_CLOCK = False  # time the runs by the process's CPU seconds (steadier on a shared machine) instead of wall
SHARE_AUTOMATIC = False


def automatic_choice(target):
    """The method Automatic takes for the selected scene at this target (pipeline.method_for)."""
    import bpy

    from addon.blender_read.selection import read_selection
    from addon.bpy_free import pipeline
    from addon.bpy_free.patches import make_patches
    from addon.bpy_free.scene_notes import scene_and_notes

    objects, _ = read_selection(bpy.context)
    scene, _ = scene_and_notes(make_patches(objects, 1e6))
    settings = pipeline.SolveSettings(relative_rms=target, patch_size=1e6, method="auto")
    _, mse = pipeline.prediction_for(scene, settings)
    return pipeline.method_for(scene, settings, mse).method


def measure_level(name, label, argument, edge, stored, target, seeds, log=print):
    from benchmarks.suite import build

    maker, levels = SCENES[name]
    spec, fine = maker(argument), maker(levels[-1][1])
    owner = containing(spec.corners, fine.corners)
    P = len(spec.corners)
    a = aggregate(stored[f"{name}_a"], owner, area(fine.corners), P).mean(axis=1)
    b = aggregate(stored[f"{name}_b"], owner, area(fine.corners), P).mean(axis=1)
    ref = 0.5 * (a + b)
    measured = ~(spec.emission > 0).any(axis=1)
    lit = measured & (ref > LIT * ref[measured].max())
    ref_noise = float(np.mean(0.25 * (a - b)[lit] ** 2 / ref[lit] ** 2))
    row = {"scene": name, "level": label, "edge": edge, "patches": P, "lit": int(lit.sum()), "target": target,
           "clock": "cpu" if CPU_CLOCK else "wall",
           "reference_noise": math.sqrt(ref_noise), "runs": {}}
    if name == "empty_room" and argument == 10:
        from benchmarks.cycles_comparison import references as exact

        continuous = exact()["continuous"]
        row["cycles_vs_exact"] = float(np.sqrt(np.mean(((ref - continuous) / continuous)[lit] ** 2)))
        row["cycles_vs_exact_noise"] = math.sqrt(ref_noise)
    build(spec)
    chosen = automatic_choice(target)
    for c, config in enumerate(CONFIGS):
        if config in SKIPPED.get(label, ()):
            continue
        if config == "auto" and SHARE_AUTOMATIC and chosen == "two_way" and "two_way/hit" in row["runs"]:
            # Automatic runs the two-way iteration here: its runs are that one's (same settings and seed)
            row["runs"].update({f"auto/{e}": dict(row["runs"][f"two_way/{e}"], config="auto", shared=True) for e in EXITS})
            continue
        exits = ("random",) if config == "jacobi" else EXITS
        runs = {e: [] for e in exits}
        for seed in seeds:
            order = exits if (seed + c) % 2 else exits[::-1]  # alternate which exit runs first
            for exit_point in order:
                B, variance, t, paths, ran, formula, cpu = ours(config, exit_point, target, seed)
                grey = B.mean(axis=1)
                square = float(np.mean(((grey - ref) / ref)[lit] ** 2))
                noise = float(np.mean(variance.mean(axis=1)[lit] / ref[lit] ** 2))
                runs[exit_point].append({"seed": seed, "wall": t, "seconds": cpu if CPU_CLOCK else t, "paths": paths,
                                         "method": ran, "formula": formula,
                                         "square": square, "noise": noise,
                                         "ratio": float(grey[lit].sum() / ref[lit].sum())})
        for exit_point, rs in runs.items():
            square, noise = np.mean([r["square"] for r in rs]), np.mean([r["noise"] for r in rs])
            t = float(np.mean([r["seconds"] for r in rs]))
            bias2 = square - noise - ref_noise
            error = math.sqrt(max(square - ref_noise, 0.0))
            to_level = t * noise / (LEVEL**2 - bias2) if bias2 < LEVEL**2 else math.inf
            row["runs"][f"{config}/{exit_point}"] = {
                "config": config, "exit": exit_point, "method": rs[0]["method"], "seconds": t,
                "paths": int(np.mean([r["paths"] for r in rs])), "error": error, "noise": math.sqrt(noise),
                "bias": math.sqrt(max(bias2, 0.0)), "bias_squared": bias2, "to_level": to_level,
                "ratio": float(np.mean([r["ratio"] for r in rs])), "formula": float(np.mean([r["formula"] for r in rs])),
                "each": rs}
            log(f"  {name} {label} {config:12s} {exit_point:6s} ({rs[0]['method']}): error {error:.4f} = "
                f"noise {math.sqrt(noise):.4f} + bias {math.sqrt(max(bias2, 0)):.4f}; to 1% "
                f"{to_level:.2f} s")
    # Equal time: each run's noise scaled to the level's median run time by the Monte Carlo law
    # (variance ~ 1 / time), its bias kept.
    T = float(np.median([x["seconds"] for x in row["runs"].values()]))
    row["equal_seconds"] = T
    for x in row["runs"].values():
        x["at_equal"] = math.sqrt(max(x["bias_squared"] + x["noise"] ** 2 * x["seconds"] / T, 0.0))
    return row


# --- report -----------------------------------------------------------------------------------

def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(2, len(names), figsize=(4.4 * len(names), 7.0), squeeze=False)
    for k, name in enumerate(names):
        these = [r for r in rows if r["scene"] == name]
        edges = [r["edge"] for r in these]
        for c, config in enumerate(CONFIGS):
            colour = f"C{c}"
            for exit_point, style in (("random", "--"), ("hit", "-")):
                key = f"{config}/{exit_point}"
                have = [r for r in these if key in r["runs"]]
                if not have:
                    continue
                x = [r["edge"] for r in have]
                axes[0][k].plot(x, [100 * r["runs"][key]["at_equal"] for r in have], style, marker="o", color=colour,
                                label=f"{LABELS[config]}, {exit_point}")
                axes[1][k].plot(x, [100 * r["runs"][key]["bias"] for r in have], style, marker="o", color=colour)
        axes[0][k].set_title(f"{name}: error against Cycles at equal time", fontsize=9)
        axes[1][k].set_title(f"{name}: bias (what the noise does not explain)", fontsize=9)
        for ax in (axes[0][k], axes[1][k]):
            ax.set_xscale("log")
            ax.set_xlabel("patch edge, m")
            ax.set_ylabel("per-patch relative RMS, %")
            ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("dashed: exit point random (the paper's discrete method); solid: exit point hit")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def time_to(x, level):
    """Seconds for run ``x`` to reach ``level`` (inf where its bias alone is above it)."""
    left = level**2 - max(x["bias_squared"], 0.0)
    return x["noise"] ** 2 * x["seconds"] / left if left > 0 else math.inf


def crossing(random, hit):
    """(the error where both exits take the same time, as text; random's time to 5% over hit's)."""
    loose = time_to(random, 0.05) / time_to(hit, 0.05)
    cost_r, cost_h = random["noise"] ** 2 * random["seconds"], hit["noise"] ** 2 * hit["seconds"]
    b_r, b_h = max(random["bias_squared"], 0.0), max(hit["bias_squared"], 0.0)
    gap = b_r - b_h
    if cost_h <= cost_r:
        return ("-" if gap >= 0 else "none"), loose
    if gap <= 0:
        return "none", loose
    t = (cost_h - cost_r) / gap
    return f"{math.sqrt(b_r + cost_r / t):.2%}", loose


def report(rows, meta, out):
    lines = ["# Exit points against Cycles at equal time", "", f"`{meta['command']}`", "",
             f"Machine: 2 cores shared with other work (other helpers' runs), under `nice`; {meta['when']}; "
             f"run took {meta['minutes']:.1f} min. Our runs to the error target of each row (the panel's measure), seed {meta['seeds']}.", "",
             (__doc__.split("\n\n", 2)[2]).strip(), ""]
    for r in rows:
        if "cycles_vs_exact" in r:
            lines += [f"Check of the Cycles reference: in `empty_room` at 0.1 m it differs from the exact continuous "
                      f"solution by {r['cycles_vs_exact']:.3%} per patch, its own noise being {r['cycles_vs_exact_noise']:.3%}.", ""]
    lines += ["## Error against Cycles at equal time (per-patch relative RMS, reference noise subtracted)", "",
              "Each cell: random exit / hit exit, at the median run time T of the row (wall seconds of the solve, or "
              "CPU seconds of the whole pipeline run, steadier on a shared machine); **bold** the smaller. "
              "Jacobi takes no exit point (random only).", "",
              "| scene | patches | edge m | target | T s | ref. noise | " + " | ".join(LABELS[c] for c in CONFIGS) + " |",
              "|---|---:|---:|---:|---:|---:|" + "---|" * len(CONFIGS)]
    for r in rows:
        cells = []
        for c in CONFIGS:
            ra, hi = r["runs"].get(f"{c}/random"), r["runs"].get(f"{c}/hit")
            if ra is None:
                cells.append("-")
                continue
            if hi is None:
                cells.append(f"{ra['at_equal']:.2%}")
                continue
            x, y = f"{ra['at_equal']:.2%}", f"{hi['at_equal']:.2%}"
            cells.append(f"**{x}** / {y}" if ra["at_equal"] < hi["at_equal"] else f"{x} / **{y}**")
        lines.append(f"| {r['scene']} | {r['patches']:,} | {r['edge']:g} ({r['level']}) | {r.get('target', meta['target']):.0%} | "
                     f"{r['equal_seconds']:.2f} {r.get('clock', 'wall')} | "
                     f"{r['reference_noise']:.2%} | "
                     + " | ".join(cells) + " |")
    lines += ["", "## Split, at each run's own time: noise of ours (batch means) and bias (random / hit)", "",
              "| scene | edge m | " + " | ".join(f"{LABELS[c]} noise | bias" for c in CONFIGS) + " |",
              "|---|---:|" + "---:|---:|" * len(CONFIGS)]
    for r in rows:
        cells = []
        for c in CONFIGS:
            ra, hi = r["runs"].get(f"{c}/random"), r["runs"].get(f"{c}/hit")
            pair = [x for x in (ra, hi) if x is not None]
            if not pair:
                cells.append("- | -")
                continue
            cells.append(" / ".join(f"{x['noise']:.2%}" for x in pair) + " | " + " / ".join(f"{x['bias']:.2%}" for x in pair))
        lines.append(f"| {r['scene']} | {r['edge']:g} | " + " | ".join(cells) + " |")
    lines += ["", "## Where the random exit is ahead", "",
              "Each exit's error at time t is sqrt(bias^2 + noise^2 x seconds / t). The random exit costs less a "
              "path and carries its bias; the two errors cross at one time: above the error there (per patch, "
              "against Cycles) the random exit gets there sooner, below it the hit exit does, and the random exit "
              "never goes below its bias. Cell: the crossing error (-: the hit exit is ahead at every time; "
              "none: the random exit is ahead at every time), and in brackets the random exit's time to 5% per "
              "patch over the hit exit's (how much the hit exit costs at a loose target).", "",
              "| scene | edge m | " + " | ".join(LABELS[c] for c in CONFIGS if c != "jacobi") + " |",
              "|---|---:|" + "---:|" * (len(CONFIGS) - 1)]
    for r in rows:
        cells = []
        for c in CONFIGS:
            if c == "jacobi":
                continue
            if f"{c}/hit" not in r["runs"]:
                cells.append("-")
                continue
            cross, loose = crossing(r["runs"][f"{c}/random"], r["runs"][f"{c}/hit"])
            cells.append(f"{cross} ({loose:.2f})")
        lines.append(f"| {r['scene']} | {r['edge']:g} | " + " | ".join(cells) + " |")
    lines += ["", "## Noise per path: what the paper's formulas (2)/(3) predict, for its discrete method", "",
              "The mean square noise per patch times the paths, hit exit over random exit (the paper's walk; "
              "1 = the same paths give the same noise, so the predicted path counts hold for both):", "",
              "| scene | edge m | walk, finite | walk, biased infinite | measured / formula MSE, finite (random, hit) "
              "| biased infinite (random, hit) |", "|---|---:|---:|---:|---:|---:|"]
    for r in rows:
        cells = []
        for c in ("walk_finite", "walk_biased"):
            if f"{c}/hit" not in r["runs"]:
                cells.append("-")
                continue
            ra, hi = r["runs"][f"{c}/random"], r["runs"][f"{c}/hit"]
            cells.append(f"{hi['noise'] ** 2 * hi['paths'] / (ra['noise'] ** 2 * ra['paths']):.3f}")
        for c in ("walk_finite", "walk_biased"):
            cells.append(", ".join(f"{r['runs'][f'{c}/{e}'].get('formula', math.nan):.2f}" for e in EXITS
                                   if f"{c}/{e}" in r["runs"]) or "-")
        lines.append(f"| {r['scene']} | {r['edge']:g} | " + " | ".join(cells) + " |")
    lines += ["", f"## Seconds to {LEVEL:.0%} per patch against Cycles (random / hit; never: the bias alone is above it)", "",
              "| scene | edge m | " + " | ".join(LABELS[c] for c in CONFIGS) + " |", "|---|---:|" + "---:|" * len(CONFIGS)]

    def secs(x):
        t = time_to(x, LEVEL)
        return "never" if not math.isfinite(t) else f"{t:.2f}"

    for r in rows:
        cells = [" / ".join(secs(r["runs"][k]) for k in (f"{c}/random", f"{c}/hit") if k in r["runs"]) or "-"
                 for c in CONFIGS]
        lines.append(f"| {r['scene']} | {r['edge']:g} | " + " | ".join(cells) + " |")
    lines += ["", "## Runs", "", "| scene | edge m | configuration | exit | method ran | solve s | paths | error | ours / Cycles (lit sum) |",
              "|---|---:|---|---|---|---:|---:|---:|---:|"]
    for r in rows:
        for key, x in r["runs"].items():
            lines.append(f"| {r['scene']} | {r['edge']:g} | {LABELS[x['config']]} | {x['exit']} | {x['method']} | "
                         f"{x['seconds']:.2f} | {x['paths']:,} | {x['error']:.2%} | {x['ratio']:.4f} |")
    lines += ["", f"![error against patch size]({out.with_suffix('.png').name})", ""]
    lines += meta.get("reading", [])
    out.write_text("\n".join(lines) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--references", action="store_true", help="only make Cycles' references")
    p.add_argument("--recompute-references", action="store_true")
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    p.add_argument("--target", type=float, default=TARGET, help="error target of our runs (fraction)")
    p.add_argument("--replot", type=Path)
    p.add_argument("--lean", action="store_true", help="Automatic shares the two-way runs where it takes them; "
                   "no biased walk or Jacobi on the fine patches; runs timed by CPU seconds")
    args = p.parse_args(argv)
    if args.replot:
        data = json.loads(args.replot.read_text())
        plot(data["rows"], args.replot.with_suffix(".png"))
        report(data["rows"], data["meta"], args.replot.with_suffix(".md"))
        return
    started = time.perf_counter()
    samples = 8 if args.quick else SAMPLES
    global REFERENCE_FILE
    if args.quick:
        REFERENCE_FILE = ROOT / "out" / "exits_reference.npz"
        REFERENCE_FILE.parent.mkdir(exist_ok=True)
    if args.lean:
        global SHARE_AUTOMATIC
        SHARE_AUTOMATIC = True
        SKIPPED["fine"] = ("walk_biased", "jacobi")
        global CPU_CLOCK
        CPU_CLOCK = True
    stored = references(args.scenes, samples, args.recompute_references)
    if args.references:
        return
    target, seeds = (max(args.target, 0.05) if args.quick else args.target), SEEDS
    out = (ROOT / "out" if args.quick else RESULTS) / "exits.md"
    # Scenes run alone are merged into the rows of the others (in SCENES' order); minutes add up.
    kept = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").exists() else {"rows": []}
    earlier = [r for r in kept["rows"] if r["scene"] not in args.scenes]
    minutes = kept.get("meta", {}).get("minutes", 0.0) if earlier else 0.0
    rows = []
    for name in args.scenes:
        for label, argument, edge in SCENES[name][1]:
            level_target = target * (FINE_TARGET if label == "fine" and not args.quick else 1.0)
            rows.append(measure_level(name, label, argument, edge, stored, level_target, seeds))
            meta = {"command": "python -m benchmarks.exits" + (" --quick" if args.quick else ""),
                    "when": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "target": target, "seeds": list(seeds),
                    "minutes": minutes + (time.perf_counter() - started) / 60}
            if out.with_suffix(".json").exists():  # (read again: another run may have stored other scenes)
                earlier = [r for r in json.loads(out.with_suffix(".json").read_text())["rows"] if r["scene"] not in args.scenes]
            every = sorted(earlier + rows, key=lambda r: list(SCENES).index(r["scene"]))
            out.with_suffix(".json").write_text(json.dumps({"rows": every, "meta": meta}, indent=1))
    rows = every
    plot(rows, out.with_suffix(".png"))
    report(rows, meta, out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
