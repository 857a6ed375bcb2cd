"""Time to 1% and to 0.25% against Cycles on a suite of scenes nobody tuned for.

    python -m benchmarks.suite             # the whole suite (about 30 minutes on 2 cores)
    python -m benchmarks.suite --quick     # small sample and path counts, to out/
    python -m benchmarks.suite --scenes cornell open_sun_world

Scenes (every patch a quad of its own, every material Lambertian: a Principled BSDF with
Specular IOR Level 0, so Cycles' and ours are the same surfaces; emitting patches flush with the
ceiling, so their back side, which Cycles lets emit too, faces out of the scene):

- ``empty_room``: the closed 1 m room of ``cycles_comparison`` (600 patches, albedo 0.5, a 0.2 m
  ceiling light of emittance 1 that also reflects);
- ``cornell``: ``sample_scenes.cornell_box`` at 5 cm patches (red and green walls, two blocks,
  open front), its 0.3 m light moved into the ceiling;
- ``lamp_room``: the same box closed, without its light panel, lit only by a point light
  (radius 5 cm) and a 0.3 m square area light;
- ``open_sun_world``: ``cycles_lights``' open floor, red wall and block under a sun and a uniform
  sky together;
- ``fig4_room``: the paper's figure 4 room (``sample_scenes.room_fig4``, 66,572 patches, R_ave
  0.5, four 1.5 m panels hanging 1 cm under the ceiling) with a black 2 m plate 2 mm above each
  panel: Cycles lets a panel's back emit too, into the plate, which absorbs it, as our panels'
  backs do; 2 x 2 bake pixels a patch (4.4 million at 8 x 8 would take Cycles an hour a bake),
  a quarter of the samples a pixel and 8 times the paths (66,576 patches need them for a
  batch-means error of their own).

Each side's error comes from its own estimate, both unbiased (the agreement columns check it:
ours against the mean of the two bakes): Cycles' from two bakes of different seeds (a patch's
variance is half their squared difference), ours from batch means. Emitting patches are left
out. Two measures: the per-patch relative RMS (over the patches lit above 2% of the brightest)
and the RMS over patches divided by the mean radiosity (the panel's). The error goes as
1 / sqrt(work) (samples a pixel, paths); time = fixed + work x rate, fitted from a small and a
large run of each; the time to a level is that line at the work the level needs. Ours: the
operator's pipeline (``pipeline.run_solve``: reading the scene, meshing, solving, colours) with
the paper's walk (finite estimator, exit point hit, "shot"), with the first bounce gathered
by shadow rays ("gathered", exit point hit: the reflected light leaves from where the direct
light landed) and with the two-way iteration ("two-way", below), 2 threads; Cycles: the COMBINED bake's wall time
(``cycles_comparison.configure_bake``), 2 threads. And ours with the two-way iteration
(``method="two_way"``, exit point hit: the direct light gathered, its first reflection leaving
from where it landed, every later ray used both ways about a control variate).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"

from benchmarks.cycles_comparison import block_mesh, configure_bake, quads as rectangle_quads, room_rectangles, selected_object  # noqa: E402
from benchmarks.cycles_lights import bake  # noqa: E402

LEVELS = (0.01, 0.0025)
MEASURES = ("per_patch", "rms_over_mean")
LIT = 0.02  # patches darker than this share of the brightest are left out of the per-patch measure


@dataclass
class Spec:
    """A suite scene: quads (P,4,3) with reflectivity and emission (P,3); lights as
    (type, data settings, location, rotation); a world colour x strength or None."""

    corners: np.ndarray
    reflectivity: np.ndarray
    emission: np.ndarray
    lights: list = field(default_factory=list)
    world: tuple | None = None
    block: int = 8
    samples_scale: float = 1.0  # of the suite's samples a pixel and paths
    paths_scale: float = 1.0


def _from_sample(sample):
    P = sample.patch_count
    return sample.vertices.reshape(P, 4, 3).copy(), sample.reflectivity.copy(), sample.emission.copy(), sample


def empty_room():
    origin, u, v, light = room_rectangles()
    P = len(origin)
    return Spec(rectangle_quads(origin, u, v), np.full((P, 3), 0.5), np.where(light[:, None], 1.0, 0.0) * np.ones(3))


def _cornell(closed, keep_light):
    import sample_scenes

    corners, R, E, sample = _from_sample(sample_scenes.build("cornell_box", divisions=20, closed=closed))
    part = np.array(sample.part_names)[sample.patch_part]
    centre = corners.mean(axis=1)
    under_light = (part == "ceiling") & (np.abs(centre[:, 0] - 0.5) < 0.15) & (np.abs(centre[:, 1] - 0.5) < 0.15)
    keep = ~under_light if keep_light else part != "light"
    if keep_light:
        corners[part == "light", :, 2] = 1.0  # flush with the ceiling, in place of its patches there
    return corners[keep], R[keep], E[keep]


def cornell():
    return Spec(*_cornell(closed=False, keep_light=True))


def lamp_room():
    corners, R, E = _cornell(closed=True, keep_light=False)
    lights = [("POINT", {"energy": 30.0, "shadow_soft_size": 0.05, "use_soft_falloff": False}, (0.7, 0.6, 0.8), (0, 0, 0)),
              ("AREA", {"energy": 40.0, "shape": "SQUARE", "size": 0.3}, (0.3, 0.3, 0.97), (0, 0, 0))]
    return Spec(corners, R, E, lights=lights)


def open_sun_world():
    from benchmarks.cycles_lights import quads as open_quads

    corners, R = open_quads()
    lights = [("SUN", {"energy": 3.0, "angle": math.radians(8)}, (0, 0, 3), (math.radians(35), 0, math.radians(20)))]
    return Spec(corners, R, np.zeros_like(R), lights=lights, world=((0.3, 0.35, 0.4), 1.0), block=12)


def fig4_room():
    import sample_scenes

    import sample_scenes.room_fig4 as fig4

    corners, R, E, _ = _from_sample(sample_scenes.build("fig4_room"))
    plates = []
    for cx, cy in fig4.LIGHT_CENTRES:
        x0, x1, y0, y1 = cx - 1.0, cx + 1.0, cy - 1.0, cy + 1.0
        z = fig4.ROOM[2] - fig4.LIGHT_DROP + 0.002
        plates.append([(x0, y0, z), (x0, y1, z), (x1, y1, z), (x1, y0, z)])  # facing down, onto the panel's back
    zeros = np.zeros((len(plates), 3))
    return Spec(np.concatenate([corners, plates]), np.concatenate([R, zeros]), np.concatenate([E, zeros]), block=2,
                samples_scale=0.25, paths_scale=8)


SCENES = {"empty_room": empty_room, "cornell": cornell, "lamp_room": lamp_room, "open_sun_world": open_sun_world,
          "fig4_room": fig4_room}
# Our ways of solving (SolveSettings beside paths, seed, threads, exit point hit), by name.
SIDES = {"shot": {"method": "walk", "direct_light": "shot"}, "gathered": {"method": "walk", "direct_light": "gathered"},
         "two_way": {"method": "two_way"}}
LABELS = {"cycles": "Cycles", "shot": "ours, paper walk", "gathered": "ours, gathered first bounce",
          "two_way": "ours, two-way iteration", "direct": "ours, direct light alone (a bound)"}


def _material(name, reflectivity, emission, image):
    import bpy

    m = bpy.data.materials.new(name)
    tree = m.node_tree
    node = tree.nodes.get("Principled BSDF")
    node.inputs["Base Color"].default_value = (*map(float, reflectivity), 1.0)
    node.inputs["Specular IOR Level"].default_value = 0.0  # no dielectric layer: Lambertian
    strength = float(np.max(emission))
    node.inputs["Emission Color"].default_value = (*(np.asarray(emission) / strength if strength > 0 else np.zeros(3)), 1.0)
    node.inputs["Emission Strength"].default_value = strength
    texture = tree.nodes.new("ShaderNodeTexImage")
    texture.image = image
    tree.nodes.active = texture
    m.diffuse_color = (*map(float, reflectivity), 1.0)
    return m


def build(spec):
    """The scene in Blender: (the mesh object, its bake image, rows, columns)."""
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    import addon

    addon.register()
    P = len(spec.corners)
    columns = max(1, int(math.ceil(math.sqrt(P))))
    mesh, image, rows = block_mesh("Scene", spec.corners, spec.block, columns)
    rows_of = np.round(np.concatenate([spec.reflectivity, spec.emission], axis=1), 9)
    unique, index = np.unique(rows_of, axis=0, return_inverse=True)
    for k, row in enumerate(unique):
        mesh.materials.append(_material(f"M{k}", row[:3], row[3:], image))
    mesh.polygons.foreach_set("material_index", index.ravel().astype(np.int32))
    mesh.update()
    obj = selected_object(mesh)
    scene = bpy.context.scene
    for k, (kind, settings, location, rotation) in enumerate(spec.lights):
        data = bpy.data.lights.new(f"{kind.title()} {k}", kind)
        for key, value in settings.items():
            setattr(data, key, value)
        lamp = bpy.data.objects.new(data.name, data)
        lamp.location, lamp.rotation_euler = location, rotation
        scene.collection.objects.link(lamp)
    if spec.world is not None:
        world = bpy.data.worlds.new("Sky")
        scene.world = world
        background = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
        background.inputs["Color"].default_value = (*spec.world[0], 1.0)
        background.inputs["Strength"].default_value = spec.world[1]
    configure_bake(scene, threads=2)
    return obj, image, rows, columns


def ours(paths, side, seed=0):
    """(B (P,3) in face order, its variance, wall seconds, sources) from the operator's pipeline."""
    import bpy

    from addon.bpy_free import pipeline
    from addon.blender_read.selection import read_selection

    objects, _ = read_selection(bpy.context)
    settings = pipeline.SolveSettings(paths=paths, patch_size=1e6, seed=seed, threads=2, exit_point="hit", **SIDES[side])
    wall = time.perf_counter()
    out = pipeline.run_solve(objects, settings)
    wall = time.perf_counter() - wall
    B, variance = face_values(out)
    return B, variance, wall, out.sources


def face_values(out):
    """(B, variance) (P,3) of a one-object solve, in its polygons' order (the reference's)."""
    face = out.patches.meshes[0].patch_face
    B, variance = np.zeros_like(out.result.radiosity), np.zeros_like(out.result.radiosity)
    B[face], variance[face] = out.result.radiosity, out.result.reflected_variance
    return B, variance


def direct_only(paths, chunks=32):
    """The direct light alone as the two-way iteration gathers it (``first_shot.gather_direct``,
    its samples for chunks of paths / 32 paths, on 2 threads): (R H per chunk (K,P) in face
    order, wall seconds). What it takes to bring R H alone to an error bounds every method of
    ours that gathers it this way, Cycles' way (next-event estimation)."""
    import bpy
    from concurrent.futures import ThreadPoolExecutor

    from addon.bpy_free import patches as patch_making
    from addon.bpy_free.scene_notes import scene_and_notes
    from addon.blender_read.selection import read_selection
    from addon.core.methods.first_shot import Gathering, gather_direct
    from addon.core.methods.tables import WalkTables
    from addon.core.methods.two_way import direct_samples, pilot_irradiance
    from addon.core.methods.walk import FreeTurn

    objects, _ = read_selection(bpy.context)
    patches = patch_making.make_patches(objects, 1e6)
    scene, _ = scene_and_notes(patches)
    tables = WalkTables(scene, "finite", 1e-3, "hit").with_turn(FreeTurn())  # (as the two-way iteration gathers: walk.takes_turns)
    gathering = Gathering(scene, direct_samples(math.ceil(paths / chunks), scene))
    with tables.numpy_turn:  # (the samples allotted as a solve allots them: half by a pilot's light)
        pilot = pilot_irradiance(tables, gathering, 9)
    gathering = Gathering(scene, direct_samples(math.ceil(paths / chunks), scene, pilot))
    R = scene.reflectivity.T

    def run(k):
        rng = np.random.default_rng(np.random.SeedSequence(9, spawn_key=(k,)))
        with tables.numpy_turn:
            return (R * gather_direct(tables, gathering, rng)[0]).T

    wall = time.perf_counter()
    with ThreadPoolExecutor(2) as pool:
        parts = list(pool.map(run, range(chunks)))
    wall = time.perf_counter() - wall
    face = patches.meshes[0].patch_face
    out = np.zeros((chunks, scene.patch_count))
    out[:, face] = np.array(parts).mean(axis=2)
    return out, wall


def errors(variance, mean, measured):
    """Both measures of an estimate with per-patch variance (P,) around ``mean`` (P,), over the
    patches ``measured``."""
    v, m = variance[measured], mean[measured]
    lit = m > LIT * m.max()
    return {"per_patch": float(np.sqrt(np.mean(v[lit] / m[lit] ** 2))),
            "rms_over_mean": float(np.sqrt(v.mean()) / m.mean())}


def line(small_work, small_seconds, work, seconds):
    """(fixed, rate): time = fixed + rate x work through a small and a large run."""
    rate = max(seconds - small_seconds, 1e-9) / (work - small_work)
    return max(small_seconds - rate * small_work, 0.0), rate


def seconds_to(level, error, work, fixed, rate):
    return fixed + rate * work * (error / level) ** 2


def measure(name, samples, paths):
    spec = SCENES[name]()
    samples, paths = max(1, round(samples * spec.samples_scale)), round(paths * spec.paths_scale)
    obj, image, rows, columns = build(spec)
    P = len(spec.corners)
    measured = ~(spec.emission > 0).any(axis=1)
    _, small = bake(image, rows, columns, spec.block, P, 1, seed=3)
    a, seconds_a = bake(image, rows, columns, spec.block, P, samples, seed=1)
    b, seconds_b = bake(image, rows, columns, spec.block, P, samples, seed=2)
    mean = 0.5 * (a + b).mean(axis=1)
    row = {"scene": name, "patches": P, "samples": samples, "paths": paths}
    fixed, rate = line(1, small, samples, 0.5 * (seconds_a + seconds_b))
    cycles_error = errors(0.5 * (a - b).mean(axis=1) ** 2, mean, measured)
    row["cycles"] = {"error": cycles_error, "fixed": fixed, "rate": rate, "work": samples,
                     "seconds": {m: {str(l): seconds_to(l, cycles_error[m], samples, fixed, rate) for l in LEVELS} for m in MEASURES}}
    direct, seconds = direct_only(paths)
    e = errors(direct.var(axis=0, ddof=1) / len(direct), mean, measured)
    row["direct"] = {"error": e, "fixed": 0.0, "rate": seconds / paths, "work": paths,
                     "seconds": {m: {str(l): seconds_to(l, e[m], paths, 0.0, seconds / paths) for l in LEVELS} for m in MEASURES}}
    for light in SIDES:
        _, _, small, _ = ours(max(paths // 16, 4096), light)
        B, variance, seconds, sources = ours(paths, light)
        fixed, rate = line(max(paths // 16, 4096), small, paths, seconds)
        e = errors(variance.mean(axis=1), mean, measured)
        grey = B.mean(axis=1)
        lit = measured & (mean > LIT * mean[measured].max())
        # agreement: ours against the two bakes' mean, in units of both sides' noise
        noise = np.sqrt(variance.mean(axis=1) + 0.25 * (a - b).mean(axis=1) ** 2)  # the two bakes' mean: half a bake's variance
        z = (grey - mean)[lit] / np.maximum(noise[lit], 1e-300)
        row[light] = {"error": e, "fixed": fixed, "rate": rate, "work": paths, "sources": sources,
                      "ratio": float(grey[lit].sum() / mean[lit].sum()), "z_rms": float(np.sqrt(np.mean(z**2))),
                      "seconds": {m: {str(l): seconds_to(l, e[m], paths, fixed, rate) for l in LEVELS} for m in MEASURES}}
    return row


def plot(rows, path):
    """Time against error per scene (per-patch measure): each side's fitted line, its measured point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, len(rows), figsize=(4.2 * len(rows), 3.8), squeeze=False)
    for ax, row in zip(axes[0], rows):
        for side, label in LABELS.items():
            if side not in row:
                continue
            r = row[side]
            error = r["error"]["per_patch"]
            levels = np.geomspace(0.002, 0.05, 40)
            ax.loglog(levels * 100, [seconds_to(l, error, r["work"], r["fixed"], r["rate"]) for l in levels], label=label,
                      ls=":" if side == "direct" else "-")
            ax.plot(error * 100, seconds_to(error, error, r["work"], r["fixed"], r["rate"]), "o", color=ax.lines[-1].get_color())
        for level in LEVELS:
            ax.axvline(level * 100, color="grey", lw=0.6, ls=":")
        ax.set_xticks([0.25, 1, 5], ["0.25", "1", "5"])
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax.set_title(f"{row['scene']} ({row['patches']} patches)")
        ax.set_xlabel("per-patch relative RMS error, %")
        ax.set_ylabel("wall seconds (2 cores)")
        ax.invert_xaxis()
    axes[0][0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _ours(row):
    return [side for side in SIDES if side in row]


def report(rows, command, out):
    sides = [side for side in SIDES if any(side in r for r in rows)]
    lines = ["# The suite: time to 1% and 0.25% against Cycles", "", f"`{command}`", "",
             (__doc__.split("\n\n", 2)[2]).strip(), "",
             "## Agreement", "",
             "| scene | patches | " + " | ".join(f"{LABELS[k][6:]} / Cycles | z RMS" for k in sides) + " | sources |",
             "|---|---:|" + "---:|---:|" * len(sides) + "---|"]
    for r in rows:
        cells = [f"{r[k]['ratio']:.4f} | {r[k]['z_rms']:.2f}" if k in r else "- | -" for k in sides]
        lines.append(f"| {r['scene']} | {r['patches']} | " + " | ".join(cells) + f" | {r[_ours(r)[0]]['sources']} |")
    lines += ["", "z RMS: the RMS over lit patches of (ours - Cycles) over both sides' noise; about 1 when both agree.", "",
              "*Direct light alone*: each patch's direct light times its reflectivity, gathered as the two-way "
              "iteration gathers it (next-event estimation, as Cycles does), with nothing after it: the seconds it "
              "alone needs to reach the level (on 2 threads, no fixed cost) bound every method of ours that "
              "gathers the direct light this way.", ""]
    for measure_name, title in (("per_patch", "per-patch relative RMS"), ("rms_over_mean", "RMS over patches / mean radiosity")):
        lines += [f"## Seconds to a {title}", "",
                  "| scene | level | Cycles s | " + " | ".join(f"{LABELS[k][6:]} s | / Cycles" for k in sides)
                  + " | direct light alone s | / Cycles |",
                  "|---|---:|---:|" + "---:|---:|" * (len(sides) + 1)]
        for r in rows:
            for level in LEVELS:
                c = r["cycles"]["seconds"][measure_name][str(level)]
                cells = []
                for k in sides:
                    t = r[k]["seconds"][measure_name][str(level)] if k in r else math.nan
                    cells.append(f"{t:.2f} | **{t / c:.2f}**" if k == "two_way" else f"{t:.2f} | {t / c:.2f}")
                t = r["direct"]["seconds"][measure_name][str(level)] if "direct" in r else math.nan
                cells.append(f"{t:.2f} | {t / c:.2f}")
                lines.append(f"| {r['scene']} | {level:.2%} | {c:.2f} | " + " | ".join(cells) + " |")
        lines.append("")
    lines += ["Measured per-patch errors (at the work run): " + "; ".join(
        f"{r['scene']}: Cycles {r['cycles']['error']['per_patch']:.4f} at {r['samples']} samples, "
        + ", ".join(f"{LABELS[k][6:]} {r[k]['error']['per_patch']:.4f}" for k in _ours(r)) + f" at {r['paths']:,} paths"
        for r in rows), "", "Fixed seconds and seconds per unit of work (time = fixed + rate x work, from the small and the "
        "large run): " + "; ".join(f"{r['scene']}: " + ", ".join(
            f"{LABELS[k].replace('ours, ', '')} {r[k]['fixed']:.3f} + {r[k]['rate']:.3g}" for k in ("cycles", *_ours(r)))
        for r in rows), "", f"![time against error]({out.with_suffix('.png').name})"]
    out.write_text("\n".join(lines) + "\n")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true")
    p.add_argument("--scenes", nargs="+", default=list(SCENES), choices=list(SCENES))
    p.add_argument("--replot", type=Path, help="only the report and plot, from a run's JSON")
    args = p.parse_args(argv)
    if args.replot:
        rows = json.loads(args.replot.read_text())
        plot(rows, args.replot.with_suffix(".png"))
        report(rows, "python -m benchmarks.suite", args.replot.with_suffix(".md"))
        return
    samples, paths = (16, 100_000) if args.quick else (256, 2_000_000)
    out = (ROOT / "out" if args.quick else RESULTS) / "suite.md"
    out.parent.mkdir(exist_ok=True)
    # Scenes run alone are merged into the results of the others (in SCENES' order).
    kept = json.loads(out.with_suffix(".json").read_text()) if out.with_suffix(".json").exists() else []
    rows = {r["scene"]: r for r in kept if r["scene"] in SCENES}
    for name in args.scenes:
        started = time.perf_counter()
        row = measure(name, samples, paths)
        rows[name] = row
        print(f"{name}: " + ", ".join(f"{k} {row[k]['seconds']['per_patch']['0.01']:.2f} s" for k in ("cycles", *SIDES))
              + f" to 1% per patch ({time.perf_counter() - started:.0f} s)", flush=True)
        out.with_suffix(".json").write_text(json.dumps([rows[n] for n in SCENES if n in rows], indent=1))
    rows = [rows[n] for n in SCENES if n in rows]
    plot(rows, out.with_suffix(".png"))
    report(rows, "python -m benchmarks.suite" + (" --quick" if args.quick else ""), out)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
