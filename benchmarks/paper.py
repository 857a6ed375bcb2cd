"""Reproduce the experiments of Sbert & Brusi on the sample scenes; write markdown and PNGs.

    nice .venv/bin/python -m benchmarks.paper            # full run: ~2.5 min on 2 cores from scratch, ~1 min once references are cached
    .venv/bin/python -m benchmarks.paper --quick         # smoke run, ~10 s, into out/benchmarks_quick/
    .venv/bin/python -m benchmarks.paper --only fig12,fig4,fig6,cornell

Outputs (benchmarks/results/, or out/benchmarks_quick/ with --quick; both overwritten):
    fig1_fig2.md, fig1.png, fig2.png       expected vs experimental MSE, figure 2(d)
    table3_fig4_room.md, fig3.png          the 66,572-patch room (table 3, figure 3), formula (1) for both
                                           estimators, rays per path from the formulas to the walk
    table4_fig6_room.md, fig5.png          the 2,200-patch room (table 4, figure 5), the same analyses
    cornell_box.md                         the artists' box, and the same box in grey
    time_vs_error.png                      MSE against seconds, both estimators, every scene
    summary.json                           every number above
Reference solutions are cached in out/benchmarks_cache/ (ignored by git).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from . import experiments as ex

RESULTS = Path(__file__).resolve().parent / "results"
QUICK_RESULTS = Path(__file__).resolve().parent.parent / "out" / "benchmarks_quick"  # ignored by git

# The paper's tables 3 and 4 (paths, total rays, expected error, experimental error).
PAPER_TABLE3 = {
    "biased": [(900_000, 8_771_091, 0.0012, 0.0013), (1_800_000, 17_542_182, 0.00061, 0.00068),
               (2_700_000, 26_313_273, 0.00041, 0.00045), (3_600_000, 35_084_364, 0.00030, 0.00034)],
    "finite": [(3_600_000, 7_216_927, 0.00045, 0.00050), (7_200_000, 14_437_655, 0.00023, 0.00026),
               (10_800_000, 21_664_960, 0.00015, 0.00018), (14_400_000, 28_880_485, 0.00011, 0.00013)],
}
PAPER_TABLE4 = {
    "biased": [(40_000, 476_902, 0.000366, 0.00249), (120_000, 1_430_706, 0.00012, 0.000081),
               (240_000, 2_861_412, 0.000061, 0.000044), (400_000, 4_769_020, 0.000036, 0.000027)],
    "finite": [(200_000, 425_406, 0.00011, 0.000085), (600_000, 1_274_494, 0.000038, 0.00003),
               (1_200_000, 2_554_032, 0.000019, 0.000017), (2_000_000, 4_251_203, 0.000012, 0.000011)],
}
POSITIONS = ["top left", "top right", "bottom left", "bottom right"]

FULL = {
    "fig1": dict(enclosure_divisions=8, cube_divisions=1, rays_per_patch=500_000, first_paths=15_625, points=7,
                 reps=5),
    "fig4": dict(scale=1.0, reference_factor=8),
    "fig6": dict(scale=1.0, reference_factor=20),
    "cornell": dict(divisions=20, first_paths=10_000, points=9, reference_paths=40_000_000, check_paths=640_000),
}
QUICK = {
    "fig1": dict(enclosure_divisions=4, cube_divisions=1, rays_per_patch=20_000, first_paths=2_000, points=4,
                 reps=2),
    "fig4": dict(scale=0.005, reference_factor=4, beta_paths=200_000, first_hit_paths=200_000),
    "fig6": dict(scale=0.05, reference_factor=8, beta_paths=200_000, first_hit_paths=200_000),
    "cornell": dict(divisions=10, first_paths=2_000, points=4, reference_paths=1_000_000, check_paths=20_000),
}
FIG1_R = (0.2, 0.5, 0.8)
CONFIGS = (("finite", None), ("biased_infinite", 0.01), ("biased_infinite", 0.001))


def log(*a):
    print(time.strftime("%H:%M:%S"), *a, flush=True)


def cfg_label(estimator, t):
    return "finite" if estimator == "finite" else f"biased t={t:g}"


def fmt(x, digits=3):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    if isinstance(x, (int, np.integer)):
        return f"{x:,}"
    return f"{x:.{digits}g}"


def md_table(header, rows):
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for r in rows:
        lines.append("| " + " | ".join(fmt(c) if not isinstance(c, str) else c for c in r) + " |")
    return "\n".join(lines)


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams.update({"font.size": 10, "axes.grid": True, "grid.alpha": 0.3, "figure.dpi": 110})
    return plt


def _human(x, _pos=None):
    for div, suffix in ((1e6, "M"), (1e3, "k")):
        if abs(x) >= div:
            v = x / div
            return f"{v:g}{suffix}"
    return f"{x:g}"


def readable_log_x(ax):
    """Log x axis with ticks at 1, 2, 5 x 10^k labelled 20k, 1M, 0.5 ..."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_xscale("log")
    lo, hi = ax.get_xlim()
    subs = (1.0, 2.0, 5.0) if hi / lo > 8 else (1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0)
    ax.xaxis.set_major_locator(LogLocator(base=10, subs=subs))
    ax.xaxis.set_major_formatter(FuncFormatter(_human))
    ax.xaxis.set_minor_formatter(NullFormatter())


COLORS = {"finite": "tab:blue", "biased": "tab:purple", "biased t=0.001": "tab:purple", "biased t=0.01": "tab:orange"}


# --------------------------------------------------------------------------------------------
# Figures 1, 2 and 2(d): the cube enclosure with 27 cubes
# --------------------------------------------------------------------------------------------

def run_fig12(c, threads, out):
    from sample_scenes import cube_enclosure

    base = cube_enclosure.build(reflectivity=0.5, enclosure_divisions=c["enclosure_divisions"],
                                cube_divisions=c["cube_divisions"])
    P = base.patch_count
    area = base.patch_area
    log(f"fig1/2: {P} patches; reference form factors with {c['rays_per_patch']:,} rays per patch")
    F1, F2, ff_seconds = ex.raycast_form_factors_halves(base, c["rays_per_patch"])
    emission = base.arrays()[4]
    batches = ex.doubling_batches(c["first_paths"], c["points"])
    results = {"patches": P, "rays_per_patch": c["rays_per_patch"], "ff_seconds": ff_seconds,
               "paths": np.cumsum(batches).tolist(), "reps": c["reps"], "by_r": {}}
    for R in FIG1_R:
        refl = np.full(P, R)
        ref = ex.direct_reference(F1, F2, refl, emission, area, rays=P * c["rays_per_patch"], seconds=ff_seconds)
        scene = base.scene.with_materials(refl, emission)
        from addon.core.estimate.reference import path_variances

        var_finite, var_infinite = path_variances(0.5 * (F1 + F2), refl, emission, area)
        entry = {"reference_mse": ref.mse, "configs": {},
                 # table 1's exact per-path variances, area-weighted: E(MSE) x N with nothing neglected
                 "table1_mse_per_path": {"finite": float(np.sum(area * var_finite) / area.sum()),
                                         "infinite": float(np.sum(area * var_infinite) / area.sum())},
                 "formula1_mse_per_path": formula1_per_path(scene, ref.radiosity)}
        for est, t in CONFIGS:
            label = cfg_label(est, t)
            mses, rays, secs, cpus, lengths, batch = [], [], [], [], [], []
            for rep in range(c["reps"]):
                pts = ex.cumulative_runs(scene, est, batches, seed=100 + rep, threshold=t or 1e-3, threads=threads)
                mses.append([ex.mse(p.radiosity, ref.radiosity, area) for p in pts])
                rays.append([p.rays for p in pts])
                secs.append([p.seconds for p in pts])
                cpus.append([p.cpu_seconds for p in pts])
                batch.append([p.batch_mse for p in pts])
                lengths.append(pts[-1].rays / pts[-1].paths)
            pred = [p.predicted_mse for p in pts]
            from addon.core import predict

            # The biased estimator's bias: with a uniform R every path scores exactly K hits
            # (K = its deterministic length), so its expectation is the Neumann series of
            # B = E + R F B cut after K bounces; bias^2 is the MSE of that truncation.
            K = int(round(float(np.mean(lengths))))
            Fm = 0.5 * (F1 + F2)
            term, B_K = emission.astype(float), emission.astype(float)
            for _ in range(K):
                term = refl * (Fm @ term)
                B_K = B_K + term
            bias_sq = ex.mse(B_K, ref.radiosity[:, 0], area) if est != "finite" else 0.0
            pr = predict(scene, est, threshold=t or 1e-3)
            m = np.mean(mses, axis=0)
            entry["configs"][label] = {
                "predicted": pred, "measured": m.tolist(), "measured_corrected": (m - ref.mse).tolist(),
                "measured_sd_of_mean": (np.std(mses, axis=0, ddof=1) / np.sqrt(c["reps"])).tolist()
                if c["reps"] > 1 else None,
                "batch_estimate": np.mean(batch, axis=0).tolist(),
                "rays": np.mean(rays, axis=0).tolist(), "seconds": np.mean(secs, axis=0).tolist(),
                "cpu_seconds": np.mean(cpus, axis=0).tolist(),
                "mean_path_length": float(np.mean(lengths)), "expected_path_length": pr.expected_path_length,
                "formula4": pr.relative_efficiency if est != "finite" else None,
                "bias_squared": bias_sq,
            }
            ratio = (m - ref.mse) / np.array(pred)
            log(f"  R={R} {label}: measured/predicted {np.round(ratio, 3).tolist()}, "
                f"rays/path {np.mean(lengths):.3f} (formula {pr.expected_path_length:.3f})")
        fin = entry["configs"]["finite"]
        for t in (0.01, 0.001):
            b = entry["configs"][f"biased t={t:g}"]
            re = [ex.relative_efficiency_measured(mb, rb, mf, rf) for mb, rb, mf, rf in
                  zip(b["measured_corrected"], b["rays"], fin["measured_corrected"], fin["rays"])]
            b["relative_efficiency_measured"] = ex.geometric_mean(re)
            b["relative_efficiency_points"] = re
        results["by_r"][str(R)] = entry
    write_fig12(results, out)
    return results


def formula1_per_path(scene, B_ref):
    """Formula (1) before the paper's averaging: Phi_T / A_T * sum_i b_i R_i, with b from a reference."""
    b = (np.asarray(B_ref) - scene.emission).mean(axis=1)
    return float(scene.total_power / scene.total_area * np.sum(b * scene.grey_reflectivity))


def write_fig12(res, out):
    plt = _plt()
    paths = np.array(res["paths"])
    lines = [
        "# Figures 1, 2 and 2(d): cube enclosure with 27 cubes",
        "",
        f"Scene: `sample_scenes.cube_enclosure`, {res['patches']} patches, uniform reflectivity R = R_ave, whole top "
        f"face emitting (emittance 1). Each experimental value is the mean of {res['reps']} runs (different seeds); "
        "a run's points are the cumulative estimates of independent batches (same distribution as one run of that "
        "many paths).",
        "",
        f"Reference: direct solve of B = E + R F B with F ray-cast from every patch, {res['rays_per_patch']:,} rays "
        f"per patch in two independent halves ({res['patches'] * res['rays_per_patch']:,} rays, "
        f"{res['ff_seconds']:.0f} s). Its own MSE is estimated as MSE(B(F1), B(F2))/4 and is listed below; "
        "'measured' is the raw MSE against the reference, 'corrected' subtracts the reference's MSE (the two errors "
        "are independent, so they add).",
        "",
    ]
    # table per R
    for R, entry in res["by_r"].items():
        cfgs = entry["configs"]
        smallest = min(min(v["measured"]) for v in cfgs.values())
        lines += [f"## R_ave = {R}", "",
                  f"Reference MSE {entry['reference_mse']:.3g} = {100 * entry['reference_mse'] / smallest:.2g}% of the "
                  "smallest measured MSE in this table.", ""]
        header = ["paths"]
        for label in cfgs:
            header += [f"{label} expected", f"{label} measured", f"{label} corrected", "ratio"]
        rows = []
        for k, n in enumerate(paths):
            row = [int(n)]
            for label, v in cfgs.items():
                row += [v["predicted"][k], v["measured"][k], v["measured_corrected"][k],
                        f"{v['measured_corrected'][k] / v['predicted'][k]:.3f}"]
            rows.append(row)
        lines += [md_table(header, rows), ""]
        rows = []
        for label, v in cfgs.items():
            ratios = np.array(v["measured_corrected"]) / np.array(v["predicted"])
            rows.append([label, fmt(v.get("bias_squared", 0.0)), f"{v['mean_path_length']:.3f}",
                         f"{v['expected_path_length']:.3f}",
                         f"{ex.geometric_mean(ratios):.3f}", f"{ratios.min():.3f}-{ratios.max():.3f}",
                         f"{v['relative_efficiency_measured']:.3f}" if "relative_efficiency_measured" in v else "-",
                         f"{v['formula4']:.3f}" if v["formula4"] else "-",
                         f"{v['seconds'][-1]:.2f}", f"{v.get('cpu_seconds', [math.nan])[-1]:.2f}",
                         f"{v['rays'][-1] / v.get('cpu_seconds', [math.nan])[-1] / 1e6:.2f}"])
        lines += [md_table(["estimator", "bias^2 (truncated Neumann series)", "rays/path measured", "rays/path formula",
                            "measured/expected (geo. mean)", "range", "rel. efficiency measured",
                            "formula (4)", f"wall s, {paths[-1]:,} paths", "CPU s", "Mrays per CPU s"], rows), ""]
        if "table1_mse_per_path" in entry:
            t1 = entry["table1_mse_per_path"]
            f2 = cfgs["finite"]["predicted"][0] * paths[0]
            f3 = cfgs["biased t=0.001"]["predicted"][0] * paths[0]
            lines += ["Where the heuristic loses accuracy (MSE x paths, i.e. per path):", "",
                      md_table(["", "finite", "infinite"],
                               [["formula (2) / (3)", f2, f3],
                                ["formula (1): Phi_T/A_T sum b_i R_i, reference b_i (finite only)",
                                 entry["formula1_mse_per_path"], "-"],
                                ["table 1 exact (xi_i and b_i^2 kept; F of the reference)", t1["finite"],
                                 t1["infinite"]],
                                ["table 1 exact / formula", f"{t1['finite'] / f2:.3f}",
                                 f"{t1['infinite'] / f3:.3f}"]]), ""]
    (out / "fig1_fig2.md").write_text("\n".join(lines) + "\n")

    # Figure 1: finite
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.6))
    for k, (ax, (R, entry)) in enumerate(zip(axes, res["by_r"].items())):
        v = entry["configs"]["finite"]
        ax.loglog(paths, v["predicted"], "-", color=COLORS["finite"], lw=2.5, alpha=0.45,
                  label="expected, formula (2)")
        ax.loglog(paths, v["measured_corrected"], ":o", color=COLORS["finite"], ms=6,
                  label=f"experimental (mean of {res['reps']} runs)")
        readable_log_x(ax)
        ax.set_title(f"({'bcd'[k]}) R_ave = {R}")
        ax.set_xlabel("paths")
        if k == 0:
            ax.set_ylabel("MSE")
        ax.legend(loc="lower left")
    fig.suptitle(f"Figure 1: finite ($\\Phi_T$) estimator on the cube enclosure with 27 cubes "
                 f"({res['patches']} patches): expected vs experimental MSE")
    fig.tight_layout()
    fig.savefig(out / "fig1.png")
    plt.close(fig)

    # Figure 2 (a)-(c) and (d), 2 x 2
    fig, axes = plt.subplots(2, 2, figsize=(12.5, 10))
    axes = axes.ravel()
    for k, (ax, (R, entry)) in enumerate(zip(axes[:3], res["by_r"].items())):
        # formula (3) does not depend on t: one line serves both thresholds
        v3 = entry["configs"]["biased t=0.001"]["predicted"]
        ax.loglog(paths, v3, "-", color="0.4", lw=5, alpha=0.35, zorder=1, label="expected, formula (3) (both t)")
        for t in (0.01, 0.001):
            c = COLORS[f"biased t={t:g}"]
            v = entry["configs"][f"biased t={t:g}"]
            if v.get("bias_squared", 0) > 0:
                ax.loglog(paths, np.array(v["predicted"]) + v["bias_squared"], "--", color=c, lw=1.5,
                          label=f"(3) + bias$^2$, t = {t:g}")
            ax.loglog(paths, v["measured_corrected"], ":o", color=c, ms=6, mfc="white", mew=1.5,
                      label=f"experimental, t = {t:g}")
        readable_log_x(ax)
        ax.set_title(f"({'abc'[k]}) R_ave = {R}")
        ax.set_xlabel("paths")
        ax.set_ylabel("MSE")
        ax.legend(loc="lower left")
    ax = axes[3]
    Rs = np.linspace(0.05, 0.95, 200)
    for t in (0.01, 0.001):
        c = COLORS[f"biased t={t:g}"]
        ax.plot(Rs, (1 - Rs) * (1 + np.log(t) / np.log(Rs)) / (1 + Rs), "-", color=c, lw=2, alpha=0.6,
                label=f"formula (4), t = {t:g}")
        meas = [res["by_r"][R]["configs"][f"biased t={t:g}"]["relative_efficiency_measured"] for R in res["by_r"]]
        ax.plot([float(R) for R in res["by_r"]], meas, "o", color=c, mfc="white", ms=8, mew=2,
                label=f"measured, cube enclosure, t = {t:g}")
    rooms = res.get("rooms", {})
    if rooms:
        names = {"fig4": "figure 4 room", "fig6": "figure 6 room"}
        ax.plot([v["R_ave"] for v in rooms.values()], [v["re_measured"] for v in rooms.values()], "s",
                color=COLORS["biased t=0.001"], ms=8, label="measured, rooms, t = 0.001")
        for name, v in rooms.items():
            left = name == "fig4"  # the figure 6 room (R_ave 0.58) is just to its right
            ax.annotate(names.get(name, name), (v["R_ave"], v["re_measured"]), textcoords="offset points",
                        xytext=(-9 if left else 9, -4), ha="right" if left else "left", va="center", fontsize=9)
    ax.axhline(1, color="grey", lw=0.8)
    ax.set_ylim(0.8, 4.2)
    ax.set_xlabel("R_ave")
    ax.set_ylabel("MSE x rays, biased / finite (above 1: finite better)")
    ax.set_title("(d) relative efficiency")
    ax.legend(loc="lower right")
    fig.suptitle("Figure 2: biased infinite estimator on the cube enclosure, expected (3) vs experimental MSE;\n"
                 "(d) relative efficiency of the two estimators, measured vs formula (4)")
    fig.tight_layout()
    fig.savefig(out / "fig2.png")
    plt.close(fig)


# --------------------------------------------------------------------------------------------
# Tables 3 and 4, figures 3 and 5: the rooms
# --------------------------------------------------------------------------------------------

def run_room(which, c, threads, out):
    from sample_scenes import room_fig4, room_fig6

    module, paper = (room_fig4, PAPER_TABLE3) if which == "fig4" else (room_fig6, PAPER_TABLE4)
    sample = module.build(paper_units=True)
    scene = sample.scene
    area = sample.patch_area
    scale = c["scale"]
    runs = {}
    for est, key in (("biased_infinite", "biased"), ("finite", "finite")):
        targets = [max(1, int(round(p[0] * scale))) for p in paper[key]]
        runs[key] = np.diff([0] + targets).tolist()
    ref_paths = int(c["reference_factor"] * sum(runs["finite"]))
    log(f"{which}: {sample.patch_count} patches, reference: finite run of {ref_paths:,} paths")
    ref = ex.long_run_reference(sample, ref_paths, threads=threads, label=which)
    log(f"  reference done: {ref.seconds:.0f} s, its MSE {ref.mse:.3g}")
    res = {"formula1_mse_per_path": formula1_per_path(scene, ref.radiosity),
           "patches": sample.patch_count, "R_ave": sample.r_ave, "scale": scale, "threads": threads,
           "reference_paths": ref_paths,
           "reference_mse": ref.mse, "reference_seconds": ref.seconds, "reference_rays": ref.rays, "rows": {}}
    from addon.core import predict

    # Where the formulas' gaps come from (untimed).
    res["formula1_infinite_mse_per_path"], res["formula1_infinite_rel_error"] = ex.formula1_infinite_per_path(
        scene, paths=c.get("beta_paths", 4_000_000), threads=threads)
    res["path_length_analysis"] = ex.path_length_analysis(scene, 1e-3, threads=threads,
                                                          first_hit_paths=c.get("first_hit_paths", 2_000_000))

    for est, key in (("biased_infinite", "biased"), ("finite", "finite")):
        pts = ex.cumulative_runs(scene, est, runs[key], seed=7 if key == "biased" else 8, threshold=1e-3,
                                 threads=threads)
        pr = predict(scene, est, threshold=1e-3)
        rows = []
        for p in pts:
            m = ex.mse(p.radiosity, ref.radiosity, area)
            rows.append({"paths": p.paths, "rays": p.rays, "rays_per_path": p.rays / p.paths,
                         "expected": p.predicted_mse, "measured": m, "corrected": m - ref.mse,
                         "batch_estimate": p.batch_mse, "seconds": p.seconds, "cpu_seconds": p.cpu_seconds,
                         "percent_area": ex.percent_area_error(p.radiosity, ref.radiosity, area)})
        res["rows"][key] = rows
        res[f"{key}_expected_path_length"] = pr.expected_path_length
        res["formula4"] = predict(scene, "biased_infinite", threshold=1e-3).relative_efficiency
        log(f"  {key}: " + ", ".join(f"{r['paths']:,}: {r['corrected'] / r['expected']:.3f}" for r in rows))
    # Beyond the paper: the finite estimator with stratified sources and a low-discrepancy first ray.
    pts = ex.cumulative_runs(scene, "finite", runs["finite"], seed=9, threads=threads, sampling="stratified")
    res["rows"]["finite_stratified"] = [
        {"paths": p.paths, "rays": p.rays, "seconds": p.seconds, "cpu_seconds": p.cpu_seconds,
         "corrected": ex.mse(p.radiosity, ref.radiosity, area) - ref.mse} for p in pts]
    re = [ex.relative_efficiency_measured(b["corrected"], b["rays"], f["corrected"], f["rays"])
          for b in res["rows"]["biased"] for f in res["rows"]["finite"]]
    res["re_measured"] = ex.geometric_mean(re)
    write_room(which, res, paper, out)
    return res


def write_room(which, res, paper, out):
    plt = _plt()
    tname, fname = ("Table 3", "Figure 3") if which == "fig4" else ("Table 4", "Figure 5")
    scene_doc = "room_fig4 (figure 4)" if which == "fig4" else "room_fig6 (figure 6)"
    lines = [f"# {tname} and {fname}: `sample_scenes.{scene_doc}`", "",
             f"{res['patches']:,} patches, R_ave = {res['R_ave']:.2f}; emittance scaled (`paper_units=True`) so "
             "that formula (2)'s expected MSE at the paper's first finite path count equals the paper's expected "
             "error: absolute MSEs are on the paper's scale. Biased estimator: t = 0.001.",
             f"Path counts: the paper's x {res['scale']:g}. Reference: one finite run of "
             f"{res['reference_paths']:,} paths ({res['reference_rays']:,} rays, {res['reference_seconds']:.0f} s), "
             f"whose own MSE, {res['reference_mse']:.3g} (batch estimate), is subtracted in the 'corrected' column.",
             f"Seconds: wall time of the solves with {res.get('threads', 2)} threads (on a 2-core machine that may be shared "
             "with other work); CPU "
             "seconds: the process's CPU time over all threads, which that other work disturbs much less (the plots "
             "use it). %A: percentage of the area "
             "whose radiosity has a relative error of at least 10% against the reference.", ""]
    for key, label in (("biased", "biased infinite, t = 0.001"), ("finite", "finite (Phi_T)")):
        lines += [f"## {label}", ""]
        rows = []
        for pos, r, pp in zip(POSITIONS, res["rows"][key], paper[key]):
            rows.append([pos, r["paths"], r["rays"], f"{r['rays_per_path']:.2f}", r["expected"], r["measured"],
                         r["corrected"], f"{r['corrected'] / r['expected']:.2f}", r["batch_estimate"],
                         f"{r['seconds']:.1f}", f"{r['cpu_seconds']:.1f}", f"{r['percent_area']:.1f}",
                         pp[0], pp[1], f"{pp[1] / pp[0]:.2f}", pp[2], pp[3], f"{pp[3] / pp[2]:.2f}"])
        lines += [md_table(["image", "paths", "rays", "rays/path", "expected MSE", "measured MSE", "corrected",
                            "corrected/expected", "core batch estimate", "seconds", "CPU seconds", "%A",
                            "paper paths", "paper rays", "paper rays/path", "paper expected", "paper experimental",
                            "paper exp./expected"], rows), ""]
    lines += [f"Expected rays per path: finite {res['finite_expected_path_length']:.2f}, biased "
              f"{res['biased_expected_path_length']:.2f} (1 + log t / log R_ave).",
              f"Relative efficiency (MSE x rays, biased / finite; geometric mean over all pairs of points): "
              f"measured {res['re_measured']:.2f}, formula (4) {res['formula4']:.2f}.", ""]
    if "formula1_mse_per_path" in res:
        f2 = res["rows"]["finite"][0]["expected"] * res["rows"]["finite"][0]["paths"]
        f3 = res["rows"]["biased"][0]["expected"] * res["rows"]["biased"][0]["paths"]
        ratio = {k: [r["corrected"] / r["expected"] for r in res["rows"][k]] for k in ("finite", "biased")}
        rows = [["finite: Phi_T/A_T sum_i b_i R_i (b_i from the reference)", "formula (2)",
                 f"{res['formula1_mse_per_path'] / f2:.3f}",
                 f"{min(ratio['finite']):.3f}-{max(ratio['finite']):.3f}"]]
        if "formula1_infinite_mse_per_path" in res:
            rows.append(["biased: Phi_T/A_T sum_i beta_i (beta_i: reflected radiosity with every R squared)",
                         "formula (3)", f"{res['formula1_infinite_mse_per_path'] / f3:.3f}",
                         f"{min(ratio['biased']):.3f}-{max(ratio['biased']):.3f}"])
        lines += ["## Formula (1) before the paper's averaging", "",
                  "Formula (1) keeps each patch's b_i R_i (finite) or beta_i (infinite) where formulas (2) and (3) "
                  "put the scene averages in; like them it neglects the xi_i and b_i^2 terms of table 1. "
                  "beta_i comes from two independent finite runs of the room with squared reflectivities "
                  f"(relative disagreement {res.get('formula1_infinite_rel_error', math.nan):.1e}).", "",
                  md_table(["estimator: formula (1) with this room's own b_i", "over", "ratio",
                            "measured / expected (corrected)"], rows), ""]
    pla = res.get("path_length_analysis")
    if pla:
        fin = res["rows"]["finite"][-1]["rays_per_path"]
        bia = res["rows"]["biased"][-1]["rays_per_path"]
        lines += ["## Rays per path: from the formulas to the walk", "",
                  f"Reflectivity: R_ave {pla['R_ave']:.3f} (area-weighted); geometric mean of the reflecting "
                  f"patches {pla['geometric_mean_R']:.3f}; area with R = 0 (the lights) "
                  f"{100 * pla['absorbing_area_fraction']:.2f}%; mean R of the first hit (where the emitted power "
                  f"lands first, from a probe run) {pla['first_hit_mean_R']:.3f}. The model rows draw each hit's "
                  "reflectivity independently (by area, the walk's long-run distribution in a closed room; the "
                  "first hit optionally from the probe) and cut the path exactly as the biased estimator does.",
                  "",
                  md_table(["biased (t = 0.001)", "rays/path"],
                           [["formula: 1 + log t / log R_ave", f"{pla['biased_formula']:.2f}"],
                            ["same with the geometric mean of R (a product of varied R falls faster)",
                             f"{pla['biased_geometric']:.2f}"],
                            ["model: reflecting patches by area, whole hits (the paper's 'about 1')",
                             f"{pla['biased_model_area_reflecting']:.2f}"],
                            ["model: all patches by area (R = 0 patches end paths)", f"{pla['biased_model_area']:.2f}"],
                            ["model: first hit where the light lands, then by area",
                             f"{pla['biased_model_first_hit']:.2f}"],
                            ["measured", f"{bia:.2f}"]]), "",
                  md_table(["finite", "rays/path"],
                           [["formula: 1 / (1 - R_ave)", f"{pla['finite_formula']:.2f}"],
                            ["model: 1 + (mean R of the first hit) / (1 - R_ave)",
                             f"{pla['finite_model_first_hit']:.2f}"],
                            ["measured", f"{fin:.2f}"]]), ""]
    (out / f"{'table3_fig4_room' if which == 'fig4' else 'table4_fig6_room'}.md").write_text("\n".join(lines) + "\n")

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
    for key, marker, label in (("finite", "s", "finite ($\\Phi_T$)"), ("biased", "o", "biased infinite, t = 0.001")):
        rows = res["rows"][key]
        s = [r["cpu_seconds"] for r in rows]
        c = COLORS[key]
        axes[0].loglog(s, [r["expected"] for r in rows], "-", color=c, lw=2.5, alpha=0.45,
                       label=f"{label}: expected, formula ({'2' if key == 'finite' else '3'})")
        axes[0].loglog(s, [r["corrected"] for r in rows], ":" + marker, color=c, ms=7,
                       label=f"{label}: experimental")
        axes[1].semilogx(s, [r["percent_area"] for r in rows], ":" + marker, color=c, ms=7)
    axes[0].set_xlabel("CPU seconds (all threads)")
    axes[0].set_ylabel("MSE")
    axes[0].set_title("MSE against run time")
    axes[1].set_xlabel("CPU seconds (all threads)")
    axes[1].set_ylabel("%A: % of area with relative error >= 10%")
    axes[1].set_ylim(bottom=0)
    axes[1].set_title("%A against run time")
    for ax in axes:
        readable_log_x(ax)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, frameon=False)
    fig.suptitle(f"{fname}: {res['patches']:,}-patch room, R_ave = {res['R_ave']:.2f}, "
                 f"the paper's path counts (each point one run)")
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    fig.savefig(out / ("fig3.png" if which == "fig4" else "fig5.png"))
    plt.close(fig)


# --------------------------------------------------------------------------------------------
# Cornell box
# --------------------------------------------------------------------------------------------

def run_cornell(c, threads, out):
    from addon.core import predict
    from sample_scenes import cornell_box

    sample = cornell_box.build(divisions=c["divisions"])
    area = sample.patch_area
    log(f"cornell: {sample.patch_count} patches, reference finite run of {c['reference_paths']:,} paths")
    ref = ex.long_run_reference(sample, c["reference_paths"], threads=threads, label="cornell")
    batches = ex.doubling_batches(c["first_paths"], c["points"])
    res = {"patches": sample.patch_count, "R_ave": sample.r_ave, "reference_mse": ref.mse,
           "reference_paths": c["reference_paths"], "rows": {}}
    for est, key in (("finite", "finite"), ("biased_infinite", "biased")):
        pts = ex.cumulative_runs(sample.scene, est, batches, seed=11, threshold=1e-3, threads=threads)
        pr = predict(sample.scene, est, threshold=1e-3)
        res["rows"][key] = [{"paths": p.paths, "rays": p.rays, "seconds": p.seconds, "cpu_seconds": p.cpu_seconds,
                             "expected": p.predicted_mse,
                             "measured": ex.mse(p.radiosity, ref.radiosity, area),
                             "corrected": ex.mse(p.radiosity, ref.radiosity, area) - ref.mse,
                             "percent_area": ex.percent_area_error(p.radiosity, ref.radiosity, area)} for p in pts]
        res[f"{key}_expected_path_length"] = pr.expected_path_length
        res[f"{key}_mean_path_length"] = pts[-1].rays / pts[-1].paths
    pts = ex.cumulative_runs(sample.scene, "finite", batches, seed=12, threads=threads, sampling="stratified")
    res["rows"]["finite_stratified"] = [
        {"paths": p.paths, "rays": p.rays, "seconds": p.seconds, "cpu_seconds": p.cpu_seconds,
         "corrected": ex.mse(p.radiosity, ref.radiosity, area) - ref.mse} for p in pts]
    # Colour against grey: the same box with each patch's channel-mean reflectivity and emittance (the paper's
    # formulas are for grey scenes; formula (2)/(3) gives the same prediction for both).
    from addon.core import solve

    grey = sample.scene.with_materials(sample.scene.grey_reflectivity, sample.scene.emission.mean(axis=1))
    res["colour_vs_grey"] = {}
    for name, sc in (("colour", sample.scene), ("grey", grey)):
        for est, key in (("finite", "finite"), ("biased_infinite", "biased")):
            runs = [solve(sc, estimator=est, paths=c.get("check_paths", 640_000), seed=21 + k, threshold=1e-3, threads=threads,
                          **ex.paper_sampling()) for k in range(3)]
            res["colour_vs_grey"][f"{name} {key}"] = float(np.mean([r.measured_mse / r.predicted_mse for r in runs]))
    lines = ["# Cornell box (`sample_scenes.cornell_box`, open front, RGB)", "",
             f"{sample.patch_count} patches, R_ave = {sample.r_ave:.3f} (channel mean). The front is open, so paths "
             "escape and formula (2)/(3), derived for closed scenes, is only indicative. Reference: finite run of "
             f"{c['reference_paths']:,} paths, its MSE {ref.mse:.3g} subtracted in 'corrected'.", ""]
    for key in ("finite", "biased"):
        lines += [f"## {key}" + (" (t = 0.001)" if key == "biased" else ""), "",
                  f"rays/path measured {res[f'{key}_mean_path_length']:.3f}, formula "
                  f"{res[f'{key}_expected_path_length']:.3f}", ""]
        lines += [md_table(["paths", "rays", "seconds", "CPU seconds", "expected MSE", "measured", "corrected",
                            "corrected/expected", "%A"],
                           [[r["paths"], r["rays"], f"{r['seconds']:.2f}", f"{r['cpu_seconds']:.2f}", r["expected"],
                             r["measured"], r["corrected"],
                             f"{r['corrected'] / r['expected']:.2f}", f"{r['percent_area']:.1f}"]
                            for r in res["rows"][key]]), ""]
    cg = res["colour_vs_grey"]
    lines += ["## Colour against grey", "",
              f"The core's batch estimate of the MSE over formula (2)/(3), mean of 3 runs of "
              f"{c.get('check_paths', 640_000):,} paths each, for this box and for the same box in grey (each patch "
              "given its channel-mean reflectivity and emittance; the formulas predict the same for both):", "",
              md_table(["", "finite", "biased t = 0.001"],
                       [["colour", f"{cg['colour finite']:.2f}", f"{cg['colour biased']:.2f}"],
                        ["grey", f"{cg['grey finite']:.2f}", f"{cg['grey biased']:.2f}"]]), ""]
    (out / "cornell_box.md").write_text("\n".join(lines) + "\n")
    return res


# --------------------------------------------------------------------------------------------
# Run time against error, every scene
# --------------------------------------------------------------------------------------------

def write_time_vs_error(summary, out):
    plt = _plt()
    panels = []
    if "fig12" in summary:
        for R, entry in summary["fig12"]["by_r"].items():
            panels.append((f"Figure 1 scene, R_ave = {R}", {
                "finite": (entry["configs"]["finite"]["cpu_seconds"], entry["configs"]["finite"]["measured_corrected"]),
                "biased t=0.001": (entry["configs"]["biased t=0.001"]["cpu_seconds"],
                                   entry["configs"]["biased t=0.001"]["measured_corrected"]),
                "biased t=0.01": (entry["configs"]["biased t=0.01"]["cpu_seconds"],
                                  entry["configs"]["biased t=0.01"]["measured_corrected"]),
            }))
    for key, title in (("fig4", "Figure 4 room (66,572 patches)"), ("fig6", "Figure 6 room (2,200 patches)"),
                       ("cornell", "Cornell box")):
        if key in summary:
            rows = summary[key]["rows"]
            curves = {
                "finite": ([r["cpu_seconds"] for r in rows["finite"]], [r["corrected"] for r in rows["finite"]]),
                "biased t=0.001": ([r["cpu_seconds"] for r in rows["biased"]], [r["corrected"] for r in rows["biased"]]),
            }
            if "finite_stratified" in rows:
                curves["finite, stratified (beyond the paper)"] = (
                    [r["cpu_seconds"] for r in rows["finite_stratified"]], [r["corrected"] for r in rows["finite_stratified"]])
            panels.append((title, curves))
    if not panels:
        return
    cols = 3
    rows_n = math.ceil(len(panels) / cols)
    fig, axes = plt.subplots(rows_n, cols, figsize=(5 * cols, 3.9 * rows_n), squeeze=False)
    styles = {"finite": ("-s", "tab:blue"), "biased t=0.001": (":o", "tab:purple"), "biased t=0.01": (":^", "tab:orange"),
              "finite, stratified (beyond the paper)": ("--d", "tab:green")}
    for ax, (title, curves) in zip(axes.ravel(), panels):
        for label, (s, m) in curves.items():
            s, m = np.asarray(s), np.asarray(m)
            ok = m > 0
            st, c = styles[label]
            ax.loglog(s[ok], m[ok], st, color=c, label=label, ms=4)
        readable_log_x(ax)
        ax.set_title(title)
        ax.set_xlabel("CPU seconds (all threads)")
        ax.set_ylabel("MSE (vs reference)")
    for ax in axes.ravel()[len(panels):]:
        ax.axis("off")
    legend = {}
    for ax in axes.ravel():
        for h, lab in zip(*ax.get_legend_handles_labels()):
            legend.setdefault(lab, h)
    names = {"finite": "finite ($\\Phi_T$)", "biased t=0.001": "biased infinite, t = 0.001",
             "biased t=0.01": "biased infinite, t = 0.01"}
    fig.legend(list(legend.values()), [names.get(k, k) for k in legend], loc="lower center", ncol=len(legend),
               frameon=False)
    fig.suptitle("Run time against error (lower left is better); experimental MSE against the reference, minus the reference's own MSE")
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    fig.savefig(out / "time_vs_error.png")
    plt.close(fig)


def _jsonable(o):
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    return o


def core_version():
    import subprocess

    root = Path(__file__).resolve().parent.parent
    try:
        commit = subprocess.run(["git", "log", "-1", "--format=%h %cd", "--date=iso", "--", "addon/core"], cwd=root,
                                capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "addon/core"], cwd=root, capture_output=True,
                               text=True, timeout=10).stdout.strip()
        return commit + (" (+ uncommitted changes)" if dirty else "")
    except Exception:  # noqa: BLE001 - only a label
        return "unknown"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small scenes and path counts, into out/benchmarks_quick/")
    ap.add_argument("--only", default="fig12,fig4,fig6,cornell", help="comma-separated subset")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--replot", action="store_true", help="only rewrite tables and plots from summary.json")
    args = ap.parse_args(argv)
    cfg = QUICK if args.quick else FULL
    out = args.out or (QUICK_RESULTS if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    only = set(args.only.split(","))
    summary_path = out / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.exists() else {}
    if args.replot:
        for which, paper in (("fig4", PAPER_TABLE3), ("fig6", PAPER_TABLE4)):
            if which in summary:
                write_room(which, summary[which], paper, out)
        if "fig12" in summary:
            write_fig12(summary["fig12"], out)
        write_time_vs_error(summary, out)
        log(f"replotted from {summary_path}")
        return 0
    summary["config"] = {"quick": args.quick, "threads": args.threads, "core": core_version(),
                         **{k: v for k, v in cfg.items()}}
    log(f"core: {summary['config']['core']}")
    start = time.perf_counter()
    if "fig4" in only:
        summary["fig4"] = run_room("fig4", cfg["fig4"], args.threads, out)
    if "fig6" in only:
        summary["fig6"] = run_room("fig6", cfg["fig6"], args.threads, out)
    if "fig12" in only:
        summary["fig12"] = run_fig12(cfg["fig1"], args.threads, out)
    if "cornell" in only:
        summary["cornell"] = run_cornell(cfg["cornell"], args.threads, out)
    if "fig12" in summary:
        summary["fig12"]["rooms"] = {
            k: {"R_ave": summary[k]["R_ave"], "re_measured": summary[k]["re_measured"]}
            for k in ("fig4", "fig6") if k in summary}
        write_fig12(summary["fig12"], out)  # again, with the rooms' points on figure 2(d)
    write_time_vs_error(summary, out)
    summary_path.write_text(json.dumps(_jsonable(summary), indent=1))
    log(f"done in {time.perf_counter() - start:.0f} s; results in {out}")


if __name__ == "__main__":
    sys.exit(main())
