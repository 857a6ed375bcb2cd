"""Smooth display of patch values (addon/core/display/smoothing.py): what the noise filter does to the
error against exact solutions, the jumps the corner values leave, and the cost at a million patches.

    .venv/bin/python -m benchmarks.smoothing           # ~3 min, into benchmarks/results/smoothing.md
    .venv/bin/python -m benchmarks.smoothing --quick   # into out/

Noise: closed boxes of rectangles (exact form factors, direct linear solve: the exact discrete
solution), finite walk with the random exit point, 8 seeds per row. Per row: the raw estimate's
RMS error per patch against the exact solution (today's face colours), the filtered one's as a
ratio (mean over seeds, with its standard error), for cutoffs c = 2, 3 (default), 4; the filtered
estimate's bias (the mean over seeds of each patch's error, RMS over patches) against the raw
one's; the share of patches whose own RMS error over the seeds went up, and where they are.
"""
from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "core"))
RESULTS = ROOT / "benchmarks" / "results"
SEEDS = 8
SIZE = (1.0, 1.3, 0.7)
R_FACES, E_FACES = [0.3, 0.6, 0.7, 0.5, 0.4, 0.65], [0, 1.0, 0, 0, 0, 0]


def cases(quick):
    from addon.core import PatchScene
    from addon.core.estimate.reference import rectangle_form_factors
    from boxes import box_rectangles, rectangles_to_mesh, small_source_box, colour_box

    def box(n):
        o, u, v, f = box_rectangles(SIZE, n)
        V, T, TP = rectangles_to_mesh(o, u, v)
        return PatchScene(V, T, TP, np.asarray(R_FACES)[f], np.asarray(E_FACES)[f]), rectangle_form_factors(o, u, v)

    yield "box 6x6 a face, lit by its ceiling", box(6)
    if not quick:
        yield "box 12x12 a face, lit by its ceiling", box(12)
        yield "colour box 4x4, lit by its ceiling", colour_box()
        yield "small lamp in the middle of the ceiling, 8x8", small_source_box(8)
    yield "small lamp in a ceiling corner, 8x8", small_source_box(8, corner=True)


def edge_patches(scene):
    """Patches touching another face of the box (a crease), by welded points."""
    from addon.core.display import smoothing
    s = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch)
    point = s.point.ravel()
    patch = np.repeat(s.triangle_patch, 3)
    crease_point = ~s.smooth_point
    return np.bincount(patch, weights=crease_point[point], minlength=s.patch_count) > 0


def noise_rows(quick):
    from addon.core.display import smoothing
    from addon.core import solve
    from addon.core.estimate.reference import solve_radiosity_system
    rows = []
    for name, (scene, F) in cases(quick):
        exact = solve_radiosity_system(F, scene.reflectivity, scene.emission) - scene.emission
        exact = exact.reshape(len(exact), -1)
        surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch)
        edge = edge_patches(scene)
        for paths in ([20_000, 200_000] if quick else [20_000, 200_000, 2_000_000]):
            raw, out = [], {c: [] for c in (2.0, 3.0, 4.0)}
            for seed in range(SEEDS):
                r = solve(scene, estimator="finite", paths=paths, seed=500 + seed, threads=2)
                x = r.reflected.reshape(exact.shape)
                var = r.reflected_variance.reshape(exact.shape)
                raw.append(x - exact)
                for c in out:
                    out[c].append(surface.filter_noise(x, var, cutoff=c) - exact)
            raw = np.array(raw)
            row = {"case": name, "patches": scene.patch_count, "paths": paths,
                   "raw_rms": float(np.sqrt((raw ** 2).mean())), "rel_rms": float(np.sqrt((raw ** 2).mean()) / np.abs(exact).mean())}
            for c, e in out.items():
                e = np.array(e)
                ratio = np.sqrt((e ** 2).mean(axis=(1, 2)) / (raw ** 2).mean(axis=(1, 2)))
                row[f"ratio_{c:g}"] = (float(ratio.mean()), float(ratio.std(ddof=1) / np.sqrt(SEEDS)))
                if c == 3.0:
                    row["bias_raw"] = float(np.sqrt((raw.mean(axis=0) ** 2).mean()))
                    row["bias_filtered"] = float(np.sqrt((e.mean(axis=0) ** 2).mean()))
                    worse = np.sqrt((e ** 2).mean(axis=(0, 2))) > np.sqrt((raw ** 2).mean(axis=(0, 2)))
                    row["worse"] = float(worse.mean())
                    row["worse_at_edges"] = float(worse[edge].mean()) if edge.any() else float("nan")
                    row["worse_inside"] = float(worse[~edge].mean()) if (~edge).any() else float("nan")
            rows.append(row)
            print(row, flush=True)
    return rows


def jump_rows():
    """Residual jumps of the corner values (largest spread at one point / peak value) against
    iterations, where a continuous answer exists."""
    import test_smoothing as ts
    from addon.core.display import smoothing
    a, b, values = ts._two_wall_pieces()
    V, T, TP = ts._combine(a, b)
    two = (V, T, TP, np.concatenate(values))
    points, quads, triangles, patch, floor_count = ts._floor_and_wall(160.0)
    centre = points[quads].mean(axis=1)
    along = np.where(np.arange(len(quads)) < floor_count, -centre[:, 1], np.linalg.norm(centre[:, 1:], axis=1))
    fold = (points, triangles, patch, (1.0 + along)[:, None] * [1.0, 1.0, 1.0])
    rows = []
    for name, (V, T, TP, vals) in (("two 8x8 pieces meeting, a peak at the joint", two),
                                   ("4x4 floor and wall folded 20 degrees, a ramp across", fold)):
        s = smoothing.Surface.of(V, T, TP)
        for it in (0, 3, 10, 30):
            x = s.corner_values(vals, iterations=it).reshape(-1, 3)[:, 0]
            p = s.point.ravel()
            hi = np.full(p.max() + 1, -np.inf)
            lo = np.full(p.max() + 1, np.inf)
            np.maximum.at(hi, p, x)
            np.minimum.at(lo, p, x)
            rows.append((name, it, float((hi - lo).max() / vals.max())))
    return rows


def cost(n):
    """Seconds and peak memory of the three steps on an n x n grid of quads (2 triangles each),
    in this process (run as a subprocess, one size each)."""
    from addon.core.display import smoothing
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    pts = np.stack([i.ravel() * 0.01, j.ravel() * 0.01, np.zeros(i.size)], 1)
    a = (i[:-1, :-1] * (n + 1) + j[:-1, :-1]).ravel()
    q = np.stack([a, a + n + 1, a + n + 2, a + 1], 1)
    T = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]], 1).reshape(-1, 3)
    TP = np.repeat(np.arange(n * n), 2)
    rng = np.random.default_rng(0)
    vals = rng.random((n * n, 3))
    var = np.full((n * n, 3), 0.01)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t0 = time.perf_counter()
    s = smoothing.Surface.of(pts, T, TP)
    t1 = time.perf_counter()
    s.corner_values(vals)
    t2 = time.perf_counter()
    s.filter_noise(vals, var)
    t3 = time.perf_counter()
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"{n * n} {t1 - t0:.2f} {t2 - t1:.2f} {t3 - t2:.2f} {base / 1024:.0f} {peak / 1024:.0f}")


def cost_rows(quick):
    rows = []
    for n in ([100, 300] if quick else [100, 316, 1000]):
        out = subprocess.run([sys.executable, "-m", "benchmarks.smoothing", "--cost", str(n)], cwd=ROOT,
                             capture_output=True, text=True, check=True).stdout.split()
        rows.append(out)
        print(out, flush=True)
    return rows


def write(path, noise, jumps, costs):
    lines = ["# Smooth display of patch values: noise filter and corner values", "",
             "Written by `benchmarks/smoothing.py` (see its docstring). 2 shared cores.", "",
             "## Noise filter against exact solutions", "",
             "RMS error per patch against the exact discrete solution, raw (today's face colours) and filtered "
             f"(ratio filtered / raw, mean over {SEEDS} seeds +- its standard error), cutoff c in standard errors; "
             "bias: RMS over patches of each patch's mean error over the seeds; worse: share of patches whose own "
             "RMS error over the seeds went up with c = 3 (at the box's edges, patches touching another face; inside).", "",
             "| case | patches | paths | raw RMS (relative) | c = 2 | c = 3 | c = 4 | bias raw / filtered | worse: all, edges, inside |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in noise:
        ratios = " | ".join(f"{r[f'ratio_{c}'][0]:.3f} +- {r[f'ratio_{c}'][1]:.3f}" for c in ("2", "3", "4"))
        lines.append(f"| {r['case']} | {r['patches']} | {r['paths']:,} | {r['raw_rms']:.3g} ({100 * r['rel_rms']:.1f}%) | {ratios} | "
                     f"{r['bias_raw']:.2g} / {r['bias_filtered']:.2g} | {100 * r['worse']:.0f}%, {100 * r['worse_at_edges']:.0f}%, {100 * r['worse_inside']:.0f}% |")
    lines += ["", "## Corner values: jumps left where a continuous answer exists", "",
              "Largest difference between corner values at one welded point, over the peak value; each patch's "
              "mean is exact (float error) at every iteration count.", "",
              "| mesh | iterations | largest jump / peak |", "|---|---|---|"]
    lines += [f"| {name} | {it} | {100 * j:.2f}% |" for name, it, j in jumps]
    lines += ["", "## Cost on a grid of quads (2 triangles a patch), one process per size", "",
              "| patches | Surface.of s | corner_values s (10 iterations) | filter_noise s | memory before MB | peak MB |",
              "|---|---|---|---|---|---|"]
    lines += ["| " + " | ".join(row) + " |" for row in costs]
    path.write_text("\n".join(lines) + "\n")
    print(path)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--cost", type=int)
    args = ap.parse_args()
    if args.cost:
        cost(args.cost)
        return
    out = (ROOT / "out" if args.quick else RESULTS) / "smoothing.md"
    out.parent.mkdir(exist_ok=True)
    costs = cost_rows(args.quick)
    jumps = jump_rows()
    write(out, noise_rows(args.quick), jumps, costs)


if __name__ == "__main__":
    main()
