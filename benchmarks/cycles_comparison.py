"""Time to a given patch error: this product's solve() against Cycles' COMBINED bake.

    python -m benchmarks.cycles_comparison            # full run (about 12 minutes on 2 cores, +5 without the cached reference)
    python -m benchmarks.cycles_comparison --quick    # a smoke run (about a minute), to out/
    python -m benchmarks.cycles_comparison --recompute-reference   # redo the 5-minute reference
    python -m benchmarks.cycles_comparison --replot benchmarks/results/cycles_comparison.json   # report only

A run's JSON may carry a list "notes": checks made by hand after the run, printed at the end of the
reading (and kept by --replot).

The scene: a closed room [0,1]^3 m, every face meshed into 10 x 10 square patches of
0.1 m (600 patches), all with albedo 0.5 (pure Lambertian). The light is the 2 x 2 ceiling
patches in [0.4,0.6]^2 at z = 1 (a 0.2 m square flush with the ceiling, facing down), emitting
1 (Cycles: an Emission shader of strength 1 added to the Diffuse BSDF of albedo 0.5, so the
light reflects like the walls). Both products see exactly these 600 patches.

References. The discrete radiosity system B = E + R F B with exact form factors (closed-form
contour integrals between the axis-aligned rectangles) is what this product's default
``exit_point="random"`` converges to. Cycles, and our ``exit_point="hit"``, converge instead to
the *continuous* solution averaged over each patch; we approximate it by solving the same system
on 2x (2,400 patches) and 4x (9,600 patches) finer meshes, averaging back onto the 600 patches,
and extrapolating with the observed order p (Richardson, from the 1x, 2x and 4x solutions). The
size of the extrapolation step is the stated uncertainty of the continuous reference. The
references are cached in ``benchmarks/results/cycles_comparison_reference.npz``.

Metric. The relative RMS patch error sqrt(mean_i ((B_i - B*_i) / B*_i)^2) of the radiosity
B = E + reflected over all 600 (equal-area) patches. Also reported: the panel's convention,
RMS(B - B*) / mean reflected radiosity of the reference.

Cycles: ``bpy.ops.object.bake(type="COMBINED")`` on CPU with 2 threads (fixed), into a float
image in which each patch owns a block of BLOCK x BLOCK pixels exactly (pixel edges on patch
edges, no margin), so the mean of a block is the patch average; max bounces 64 (diffuse 64), no
clamping, no adaptive sampling, no denoising, default sampling pattern and light tree. Its time
is the wall time of the bake call: Cycles' session and scene sync, BVH build, the path tracing
and the write into the image (scene construction in bpy and reading the pixels back are
excluded). A fit t = a + b * samples estimates the fixed part a, reported separately.

Ours: ``solve(scene, estimator="finite", paths=N, threads=2)``, timed from the construction of the
PatchScene from arrays (validation, patch frames, Embree BVH) to the returned result.

Both sides are measured alternately, level by level, in the same process, so both see the same
machine load; wall-clock and process CPU time are both recorded. The time to reach an error
level comes from a line fitted in log-log to the (median time, RMS over repetitions of the error)
points near that level.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from addon.core import PatchScene, solve  # noqa: E402
from addon.core.estimate.reference import rectangle_form_factors  # noqa: E402

RESULTS = Path(__file__).parent / "results"
REFERENCE_FILE = RESULTS / "cycles_comparison_reference.npz"

N = 10             # patches per side of each face
ALBEDO = 0.5
EMISSION = 1.0
LIGHT = (0.4, 0.6)  # the light's x and y range on the ceiling
BLOCK = 8          # pixels per side of a patch's block in the bake image
COLUMNS = 25       # blocks per image row: 25 x 24 blocks = 600 patches, no unused pixel
LEVELS = (0.01, 0.0025)
THREADS = 2

# Six faces of the unit box as (origin, u, v), u x v pointing into the box.
FACES = (
    ((0, 0, 0), (1, 0, 0), (0, 1, 0)),  # floor
    ((0, 0, 1), (0, 1, 0), (1, 0, 0)),  # ceiling
    ((0, 0, 0), (0, 1, 0), (0, 0, 1)),  # x = 0
    ((1, 0, 0), (0, 0, 1), (0, 1, 0)),  # x = 1
    ((0, 0, 0), (0, 0, 1), (1, 0, 0)),  # y = 0
    ((0, 1, 0), (1, 0, 0), (0, 0, 1)),  # y = 1
)


# --- the scene -------------------------------------------------------------------------------

def room_rectangles(n=N):
    """(origin, u, v, light) of the n x n patches of every face; patch index face*n*n + i*n + j."""
    origins, us, vs = [], [], []
    for o, u, v in FACES:
        o, u, v = (np.asarray(x, np.float64) for x in (o, u, v))
        i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        i, j = i.ravel(), j.ravel()
        origins.append(o + np.outer(i, u / n) + np.outer(j, v / n))
        us.append(np.tile(u / n, (n * n, 1)))
        vs.append(np.tile(v / n, (n * n, 1)))
    origin, u, v = np.concatenate(origins), np.concatenate(us), np.concatenate(vs)
    centre = origin + 0.5 * (u + v)
    lo, hi = LIGHT
    light = (np.abs(centre[:, 2] - 1) < 1e-9) & (centre[:, 0] > lo) & (centre[:, 0] < hi) \
        & (centre[:, 1] > lo) & (centre[:, 1] < hi)
    return origin, u, v, light


def to_coarse(values, n, m=N):
    """Average a per-patch array of the n x n mesh onto the m x m one (equal-area children)."""
    f = n // m
    return np.asarray(values).reshape(6, m, f, m, f).mean(axis=(2, 4)).reshape(-1)


def quads(origin, u, v):
    return np.stack([origin, origin + u, origin + u + v, origin + v], axis=1)  # (P,4,3), normal u x v


def patch_scene():
    origin, u, v, light = room_rectangles()
    P = origin.shape[0]
    vertices = quads(origin, u, v).reshape(-1, 3)
    base = 4 * np.arange(P)[:, None]
    triangles = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return PatchScene(vertices, triangles, np.repeat(np.arange(P), 2), np.full(P, ALBEDO), EMISSION * light)


# --- references ------------------------------------------------------------------------------

def discrete_solution(n):
    origin, u, v, light = room_rectangles(n)
    F = rectangle_form_factors(origin, u, v, block=16 if n > 20 else 64)
    E = EMISSION * light.astype(np.float64)
    B = E.copy()
    # B = E + R F B by its Neumann series: R F has norm R = 0.5 in a closed box, 80 terms ~ 1e-24.
    for _ in range(80):
        B = E + ALBEDO * (F @ B)
    return B


def references(recompute=False, log=print):
    key = np.array([N, ALBEDO, EMISSION, *LIGHT])
    if REFERENCE_FILE.exists() and not recompute:
        data = np.load(REFERENCE_FILE)
        if data["key"].shape == key.shape and np.allclose(data["key"], key):
            return {k: data[k] for k in data.files}
    solutions = {}
    for factor in (1, 2, 4):
        t = time.perf_counter()
        solutions[factor] = to_coarse(discrete_solution(N * factor), N * factor)
        log(f"reference: {N * factor} x {N * factor} per face solved in {time.perf_counter() - t:.0f} s")
    b1, b2, b4 = solutions[1], solutions[2], solutions[4]
    d12 = np.sqrt(np.mean((b2 - b1) ** 2))
    d24 = np.sqrt(np.mean((b4 - b2) ** 2))
    order = math.log2(d12 / d24)
    continuous = b4 + (b4 - b2) / (2**order - 1)
    out = dict(key=key, discrete=b1, fine2=b2, fine4=b4, continuous=continuous, order=np.array(order))
    RESULTS.mkdir(parents=True, exist_ok=True)
    np.savez(REFERENCE_FILE, **out)
    return out


def relative_rms(B, ref):
    return float(np.sqrt(np.mean(((B - ref) / ref) ** 2)))


def rms_over_mean_reflected(B, ref):
    return float(np.sqrt(np.mean((B - ref) ** 2)) / np.mean(ref - EMISSION * room_rectangles()[3]))


# --- Cycles ----------------------------------------------------------------------------------

def configure_bake(scene, threads=None):
    """Cycles on the CPU for an unbiased COMBINED bake into image blocks: 64 bounces, no
    clamping, no adaptive sampling, no denoising, no margin. Returns scene.cycles."""
    scene.render.engine = "CYCLES"
    if threads:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = threads
    c = scene.cycles
    c.device = "CPU"
    c.max_bounces = c.diffuse_bounces = 64
    c.sample_clamp_direct = c.sample_clamp_indirect = 0.0
    c.use_adaptive_sampling = False
    c.use_denoising = False
    bake = scene.render.bake
    bake.target, bake.margin, bake.use_clear = "IMAGE_TEXTURES", 0, True
    return c


def block_mesh(name, corners, block, columns):
    """A mesh of quads ``corners`` (P,4,3), each UV-mapped onto its own block x block pixels of a
    new float image (``columns`` blocks a row): (mesh, image, rows)."""
    import bpy

    P = len(corners)
    rows = math.ceil(P / columns)
    width, height = columns * block, rows * block
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(np.asarray(corners).reshape(-1, 3).tolist(), [], np.arange(4 * P).reshape(P, 4).tolist())
    bx, by = (np.arange(P) % columns) * block, (np.arange(P) // columns) * block
    uv = np.stack([np.stack(c, axis=1) for c in ((bx, by), (bx + block, by), (bx + block, by + block), (bx, by + block))], axis=1)
    mesh.uv_layers.new(name="Patches").data.foreach_set("uv", (uv / [width, height]).reshape(-1).astype(np.float32))
    image = bpy.data.images.new("Bake", width, height, float_buffer=True, alpha=False)
    return mesh, image, rows


def selected_object(mesh):
    """``mesh`` as the scene's only selected, active object."""
    import bpy

    obj = bpy.data.objects.new(mesh.name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    return obj


class CyclesBaker:
    """The room as one Blender mesh of 600 quads, UV-mapped so each patch owns a pixel block."""

    def __init__(self, block=BLOCK, threads=THREADS):
        import bpy

        self.bpy = bpy
        bpy.ops.wm.read_factory_settings(use_empty=True)
        origin, u, v, light = room_rectangles()
        P = origin.shape[0]
        self.block, self.rows = block, math.ceil(P / COLUMNS)
        self.width, self.height = COLUMNS * block, self.rows * block
        mesh, self.image, _ = block_mesh("Room", quads(origin, u, v), block, COLUMNS)
        mesh.materials.append(self._material("Wall", emit=False))
        mesh.materials.append(self._material("Light", emit=True))
        mesh.polygons.foreach_set("material_index", light.astype(np.int32))
        mesh.update()
        selected_object(mesh)
        scene = bpy.context.scene
        c = configure_bake(scene, threads)
        self.scene = scene
        self.patches = P
        self.settings = {
            "Blender": bpy.app.version_string, "threads": threads, "block": f"{block}x{block} px per patch",
            "image": f"{self.width}x{self.height} float", "sampling pattern": c.sampling_pattern,
            "light tree": c.use_light_tree, "max bounces": c.max_bounces,
        }

    def _material(self, name, emit):
        m = self.bpy.data.materials.new(name)
        tree = m.node_tree
        for node in list(tree.nodes):
            tree.nodes.remove(node)
        out = tree.nodes.new("ShaderNodeOutputMaterial")
        diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
        diffuse.inputs["Color"].default_value = (ALBEDO, ALBEDO, ALBEDO, 1.0)
        shader = diffuse.outputs["BSDF"]
        if emit:
            emission = tree.nodes.new("ShaderNodeEmission")
            emission.inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
            emission.inputs["Strength"].default_value = EMISSION
            add = tree.nodes.new("ShaderNodeAddShader")
            tree.links.new(shader, add.inputs[0])
            tree.links.new(emission.outputs["Emission"], add.inputs[1])
            shader = add.outputs["Shader"]
        tree.links.new(shader, out.inputs["Surface"])
        texture = tree.nodes.new("ShaderNodeTexImage")  # the bake target: the active image node
        texture.image = self.image
        tree.nodes.active = texture
        return m

    def bake(self, samples, seed):
        self.scene.cycles.samples = samples
        self.scene.cycles.seed = seed
        wall, cpu = time.perf_counter(), time.process_time()
        result = self.bpy.ops.object.bake(type="COMBINED")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if result != {"FINISHED"}:
            raise RuntimeError(f"Cycles bake failed: {result}")
        pixels = np.empty(self.width * self.height * 4, np.float32)
        self.image.pixels.foreach_get(pixels)
        grey = pixels.reshape(self.height, self.width, 4)[..., :3].astype(np.float64).mean(axis=2)
        k = self.block
        B = grey.reshape(self.rows, k, COLUMNS, k).mean(axis=(1, 3)).reshape(-1)[: self.patches]
        return B, wall, cpu


# --- ours ------------------------------------------------------------------------------------

def ours(paths, exit_point, seed, threads=THREADS, estimator="finite", sampling="independent"):
    wall, cpu = time.perf_counter(), time.process_time()
    scene = patch_scene()
    result = solve(scene, estimator=estimator, paths=paths, seed=seed, exit_point=exit_point, threads=threads, sampling=sampling)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return result.radiosity.mean(axis=1), wall, cpu


# --- analysis --------------------------------------------------------------------------------

def time_to_reach(times, errors, target, span=3.0):
    """Time at which the log-log curve (times, errors) reaches ``target``: a least-squares line
    in log-log through the points whose error lies within a factor ``span`` of the target (at
    least the two nearest), which averages out the noise of single points. Beyond the measured
    range it is extrapolated with the Monte Carlo slope -1/2 from the nearest point (flagged)."""
    t, e = np.log(np.asarray(times)), np.log(np.asarray(errors))
    g = math.log(target)
    if g > e.max() or g < e.min():
        k = int(np.argmin(np.abs(e - g)))
        return float(math.exp(t[k] - 2.0 * (g - e[k]))), True
    near = np.abs(e - g) <= math.log(span)
    if near.sum() < 2:
        near = np.zeros_like(near)
        near[np.argsort(np.abs(e - g))[:2]] = True
    slope, intercept = np.polyfit(e[near], t[near], 1)
    return float(math.exp(intercept + slope * g)), False


SERIES = {
    # name: (label, product, reference it converges to)
    "cycles": ("Cycles COMBINED bake", "cycles", "continuous"),
    "random": ('ours, exit_point="random"', "ours", "discrete"),
    "hit": ('ours, exit_point="hit"', "ours", "continuous"),
    # beyond the paper, off by default in the product: systematic sources and a Halton first ray
    "stratified": ('ours, exit_point="random", sampling="stratified"', "ours", "discrete"),
}
# series name -> (exit point, sampling) of our runs
OUR_RUNS = {"random": ("random", "independent"), "hit": ("hit", "independent"), "stratified": ("random", "stratified")}


def present(records):
    """The series of SERIES that a run measured (older runs lack some)."""
    names = {r["series"] for r in records}
    return {k: v for k, v in SERIES.items() if k in names}


def run(args, log=print):
    refs = references(args.recompute_reference, log)
    baker = CyclesBaker(block=args.block, threads=args.threads)
    samples = [2**k for k in range(args.cycles_levels)]
    paths = [args.first_paths * 2**k for k in range(args.our_levels)]
    ours(20_000, "random", 0, args.threads)  # warm up imports and thread pools
    baker.bake(1, 0)
    records = []
    for rep in range(args.reps):
        for level in range(max(len(samples), len(paths))):
            jobs = []
            if level < len(samples):
                jobs.append(("cycles", samples[level], lambda s=samples[level]: baker.bake(s, 1000 * rep + level)))
            if level < len(paths):
                for name, (exit_point, sampling) in OUR_RUNS.items():
                    jobs.append((name, paths[level],
                                 lambda n=paths[level], x=exit_point, m=sampling: ours(n, x, 1000 * rep + level,
                                                                                       args.threads, sampling=m)))
            for series, amount, job in jobs:
                B, wall, cpu = job()
                rec = dict(series=series, amount=amount, rep=rep, wall=wall, cpu=cpu)
                for ref in ("discrete", "continuous"):
                    rec[f"rel_{ref}"] = relative_rms(B, refs[ref])
                    rec[f"bave_{ref}"] = rms_over_mean_reflected(B, refs[ref])
                records.append(rec)
                log(f"rep {rep} {series:6s} {amount:>10d}  {wall:7.2f} s wall {cpu:7.2f} s cpu  "
                    f"rel err vs discrete {rec['rel_discrete']:.4%} vs continuous {rec['rel_continuous']:.4%}")
    return refs, dict(baker.settings, cpu=cpu_model()), records


def cpu_model():
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def block_check(refs, threads, samples_per_patch=4096, reps=2, log=print):
    """Cycles' time and error at equal samples per patch with 4x4, 8x8 and 16x16 pixel blocks:
    whether the block size chosen for the comparison handicaps it."""
    rows = []
    for block in (4, 8, 16):
        baker = CyclesBaker(block=block, threads=threads)
        baker.bake(1, 0)
        samples = samples_per_patch // (block * block)
        for rep in range(reps):
            B, wall, cpu = baker.bake(samples, 5000 + rep)
            rows.append(dict(block=block, samples=samples, rep=rep, wall=wall, cpu=cpu,
                             rel_continuous=relative_rms(B, refs["continuous"])))
            log(f"block check: {block}x{block} px, {samples} samples: {wall:.2f} s, {rows[-1]['rel_continuous']:.3%}")
    return rows


def curves(records, series, ref, metric="rel", clock="wall"):
    """Per level: median time, RMS over repetitions of the error."""
    rows = [r for r in records if r["series"] == series]
    amounts = sorted({r["amount"] for r in rows})
    t = [float(np.median([r[clock] for r in rows if r["amount"] == a])) for a in amounts]
    e = [float(np.sqrt(np.mean([r[f"{metric}_{ref}"] ** 2 for r in rows if r["amount"] == a]))) for a in amounts]
    return amounts, t, e


def cycles_fixed_cost(records):
    """An upper bound on the fixed part of a bake call: the median time of a 1-sample bake."""
    return float(np.median([r["wall"] for r in records if r["series"] == "cycles" and r["amount"] == 1]))


def analyse(records):
    table = {}
    for metric in ("rel", "bave"):
        for clock in ("wall", "cpu"):
            for series, (_, _, native) in present(records).items():
                for ref in ("native", "continuous"):
                    r = native if ref == "native" else "continuous"
                    _, t, e = curves(records, series, r, metric, clock)
                    for level in LEVELS:
                        table[(metric, clock, series, ref, level)] = time_to_reach(t, e, level)
    return table


def plot(records, refs, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig, axes = plt.subplots(1, 2, figsize=(13, 6.2), sharey=True)
    styles = {"cycles": ("tab:red", "o"), "random": ("tab:blue", "s"), "hit": ("tab:green", "^"),
              "stratified": ("tab:orange", "D")}
    for ax, clock in zip(axes, ("wall", "cpu")):
        for series, (label, _, native) in present(records).items():
            colour, marker = styles[series]
            _, t, e = curves(records, series, native, "rel", clock)
            ax.loglog(t, e, marker=marker, color=colour, label=f"{label} vs {native} reference")
            if native != "continuous":
                _, t2, e2 = curves(records, series, "continuous", "rel", clock)
                ax.loglog(t2, e2, marker=marker, color=colour, ls=":", alpha=0.6, mfc="none",
                          label=f"{label} vs continuous reference")
        for level in LEVELS:
            ax.axhline(level, color="grey", lw=0.8, ls="--")
            ax.text(0.02, level * 1.05, f"{level:.2%}", color="grey", transform=ax.get_yaxis_transform())
        gap = relative_rms(refs["discrete"], refs["continuous"])
        ax.axhline(gap, color="tab:purple", lw=0.8, ls="-.")
        ax.text(0.02, gap * 0.96, f"discrete vs continuous reference: {gap:.2%}", color="tab:purple",
                transform=ax.get_yaxis_transform(), fontsize=8, va="top")
        ax.set_xlabel("wall-clock seconds (2 threads)" if clock == "wall" else "process CPU seconds (all threads)")
        ax.grid(True, which="both", alpha=0.3)
        ax.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.yaxis.set_major_formatter(FuncFormatter(lambda y, _: f"{100 * y:g}%"))
        ax.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g} s"))
    axes[0].set_ylabel("relative RMS patch error")
    # below the plots: inside, the legend would hide the first points of the curves
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, fontsize=8, loc="lower center", ncol=3, frameon=False)
    fig.suptitle("Closed 1 m room, 600 patches, albedo 0.5, 0.2 m ceiling light: time to a patch error")
    fig.tight_layout(rect=(0, 0.09, 1, 1))
    fig.savefig(path, dpi=110)
    plt.close(fig)


def fmt_time(value):
    t, extrapolated = value
    return f"{t:.2f}{'*' if extrapolated else ''}"


def report(command, refs, settings, records, table, out, png_name, total_seconds, blocks=(), notes=()):
    a = cycles_fixed_cost(records)
    gap = relative_rms(refs["discrete"], refs["continuous"])
    uncertainty = relative_rms(refs["fine4"], refs["continuous"])
    L = []
    L.append("# Time to a patch error: solve() against Cycles' COMBINED bake ")
    L.append("")
    L.append(f"`python -m benchmarks.cycles_comparison {command}`".replace(" `", "`"))
    cpu = f" ({settings['cpu']})" if settings.get("cpu") else ""
    L.append(f"Machine: {platform.machine()}{cpu}, {os.cpu_count()} CPUs shared with other work, Python "
             f"{platform.python_version()}; Blender {settings['Blender']} (bpy module); run took {total_seconds / 60:.1f} min.")
    L.append("")
    L.append("Scene: closed room [0,1]^3 m, 10 x 10 patches of 0.1 m per face (600 patches), albedo 0.5 "
             "everywhere; the light is the 2 x 2 ceiling patches over [0.4,0.6]^2 (a 0.2 m square flush with "
             "the ceiling), emission 1, reflecting like the walls. Both products see exactly these 600 patches.")
    L.append("")
    L.append("## References")
    L.append(f"* discrete: B = E + R F B with exact form factors, 600 patches (what `exit_point=\"random\"` converges to);")
    L.append(f"* continuous: the same system on 2,400 and 9,600 patches averaged back onto the 600, extrapolated "
             f"with the observed order p = {float(refs['order']):.2f} (what Cycles and `exit_point=\"hit\"` converge to). "
             f"Its uncertainty, taken as the size of the extrapolation step, is {uncertainty:.3%} relative RMS;")
    d = ((refs["discrete"] - refs["continuous"]) / refs["continuous"]).reshape(6, N, N)
    edge = np.zeros((N, N), bool)
    edge[[0, -1], :] = edge[:, [0, -1]] = True
    L.append(f"* the two differ by {gap:.3%} relative RMS: {np.sqrt(np.mean(d[1] ** 2)):.2%} on the ceiling (lit only "
             f"by reflected light), {np.sqrt(np.mean(d[:, edge] ** 2)):.2%} on patches along the room's edges and "
             f"{np.sqrt(np.mean(d[:, ~edge] ** 2)):.2%} on the others; a product measured against the other one's "
             "reference cannot go below that.")
    L.append("")
    L.append("## Set-up")
    L.append(f"* Cycles: `bpy.ops.object.bake(type=\"COMBINED\")`, CPU, {settings['threads']} threads, "
             f"{settings['block']} ({settings['image']} image, one block per patch, block mean = patch mean), "
             f"Diffuse BSDF, max bounces {settings['max bounces']}, no clamping, no adaptive sampling, no denoising, "
             f"sampling pattern {settings['sampling pattern']}, light tree {settings['light tree']}. Time: the bake "
             "call (session, scene sync, BVH, path tracing, writing the image); building the bpy scene and reading "
             f"pixels back excluded. A whole 1-sample bake takes {a:.2f} s, an upper bound on the fixed part of a call.")
    L.append(f"* Ours: `solve(scene, \"finite\", paths=N, threads={settings['threads']})`, timed from building the PatchScene "
             "from arrays (validation, frames, Embree BVH) to the result.")
    reps = len({r["rep"] for r in records})
    samples = sorted({r["amount"] for r in records if r["series"] == "cycles"})
    paths = sorted({r["amount"] for r in records if r["series"] != "cycles"})
    L.append(f"* {reps} repetitions; Cycles samples {', '.join(str(s) for s in samples)}; "
             f"our paths {paths[0]:,} to {paths[-1]:,} (doubling). Runs alternate between the products level "
             "by level. Curves: median time and RMS (over repetitions) of the error at each level; the time to "
             "reach an error level comes from a straight line in log-log fitted to the points within a factor 3 "
             "of that error (* = beyond the measured range, extrapolated with slope -1/2).")
    L.append("")
    L.append("## Result: time to reach a relative RMS patch error")
    L.append("")
    L.append("Each product against the reference of what it converges to (ours `random` and `stratified` -> "
             "discrete; Cycles and ours `hit` -> continuous). Ratio = ours / Cycles (the target: at most 0.5; the aim: 0.33). "
             "`stratified` is `sampling=\"stratified\"` with `exit_point=\"random\"` (beyond the paper, off by default).")
    L.append("")
    ours_ = [k for k in present(records) if k != "cycles"]
    short = {k: "ours " + k for k in ours_}
    L.append("| error | clock | Cycles s | " + " | ".join(f"{short[k]} s | ratio" for k in ours_) + " |")
    L.append("|---|---|---:|" + "---:|---:|" * len(ours_))
    for level in LEVELS:
        for clock in ("wall", "cpu"):
            c = table[("rel", clock, "cycles", "native", level)]
            cells = [f"{fmt_time(table[('rel', clock, k, 'native', level)])} | "
                     f"{table[('rel', clock, k, 'native', level)][0] / c[0]:.2f}" for k in ours_]
            L.append(f"| {level:.2%} | {clock} | {fmt_time(c)} | " + " | ".join(cells) + " |")
    L.append("")
    L.append(f"Cycles with the time of a whole 1-sample bake ({a:.2f} s, more than its fixed per-call cost) "
             "subtracted from its wall time, in its favour:")
    L.append("")
    L.append("| error | Cycles s | " + " | ".join(f"ratio {short[k]}" for k in ours_) + " |")
    L.append("|---|---:|" + "---:|" * len(ours_))
    for level in LEVELS:
        c = table[("rel", "wall", "cycles", "native", level)][0] - a
        cells = [f"{table[('rel', 'wall', k, 'native', level)][0] / c:.2f}" for k in ours_]
        L.append(f"| {level:.2%} | {c:.2f} | " + " | ".join(cells) + " |")
    L.append("")
    L.append("All against the continuous reference (wall clock); `-` = never reached, the error floor being "
             "the discrete/continuous gap:")
    L.append("")
    L.append("| error | Cycles s | " + " | ".join(f"{short[k]} s" for k in ours_) + " |")
    L.append("|---|---:|" + "---:|" * len(ours_))
    for level in LEVELS:
        cells = []
        for k in ["cycles"] + ours_:
            floor = SERIES[k][2] == "discrete" and level <= gap * 1.2
            cells.append("-" if floor else fmt_time(table[("rel", "wall", k, "continuous", level)]))
        L.append(f"| {level:.2%} | " + " | ".join(cells) + " |")
    L.append("")
    L.append("The panel's convention, RMS(B - B*) / mean reflected radiosity, against each product's own reference "
             "(wall clock):")
    L.append("")
    L.append("| error | Cycles s | " + " | ".join(f"{short[k]} s | ratio" for k in ours_) + " |")
    L.append("|---|---:|" + "---:|---:|" * len(ours_))
    for level in LEVELS:
        c = table[("bave", "wall", "cycles", "native", level)]
        cells = [f"{fmt_time(table[('bave', 'wall', k, 'native', level)])} | "
                 f"{table[('bave', 'wall', k, 'native', level)][0] / c[0]:.2f}" for k in ours_]
        L.append(f"| {level:.2%} | {fmt_time(c)} | " + " | ".join(cells) + " |")
    L.append("")
    if blocks:
        L.append("Does the pixel block size matter to Cycles? The same samples per patch with other blocks "
                 "(median of the repetitions):")
        L.append("")
        L.append("| block | samples | wall s | CPU s | rel. RMS vs continuous |")
        L.append("|---|---:|---:|---:|---:|")
        for block in sorted({b["block"] for b in blocks}):
            rows = [b for b in blocks if b["block"] == block]
            L.append(f"| {block}x{block} | {rows[0]['samples']} | {np.median([b['wall'] for b in rows]):.2f} | "
                     f"{np.median([b['cpu'] for b in rows]):.2f} | "
                     f"{np.sqrt(np.mean([b['rel_continuous'] ** 2 for b in rows])):.3%} |")
        L.append("")
    L.append(f"![time against error]({png_name})")
    L.append("")
    L += reading(refs, settings, records, table)
    if notes:
        L[-1:-1] = [f"* Checked by hand after this run: {note}" for note in notes]
    L.append("## Measured points")
    L.append("")
    L.append("| product | samples / paths | median wall s | median CPU s | rel. RMS vs own ref. | vs continuous |")
    L.append("|---|---:|---:|---:|---:|---:|")
    for series, (label, _, native) in present(records).items():
        amounts, t, e = curves(records, series, native)
        _, tc, _ = curves(records, series, native, clock="cpu")
        _, _, ec = curves(records, series, "continuous")
        for k, amount in enumerate(amounts):
            L.append(f"| {label} | {amount:,} | {t[k]:.3f} | {tc[k]:.3f} | {e[k]:.3%} | {ec[k]:.3%} |")
    L.append("")
    out.write_text("\n".join(L) + "\n")


def first_bounce_share():
    """Exact split of the finite estimator's per-path variance (table 1) in this room: the share
    due to the first bounce from the light alone (a multinomial count of first hits)."""
    from addon.core.estimate.reference import path_variances

    origin, u, v, light = room_rectangles()
    F = rectangle_form_factors(origin, u, v)
    area = np.linalg.norm(np.cross(u, v), axis=1)
    R = np.full(len(area), ALBEDO)
    E = EMISSION * light
    total, _ = path_variances(F, R, E, area)
    power = E * area
    first = (power[light, None] * F[light]).sum(axis=0) / power.sum()  # P(first hit on j)
    score = R * power.sum() / area                                   # what a visit scores
    direct = score**2 * first * (1 - first)
    lit = ~light
    return float(direct.sum() / total.sum()), float(np.mean(direct[lit] / total[lit]))


def reading(refs, settings, records, table):
    L = ["## Reading", ""]

    def ratio(series, clock, level, metric="rel"):
        return (table[(metric, clock, series, "native", level)][0]
                / table[(metric, clock, "cycles", "native", level)][0])

    def verdict(values):
        """The target (at most half of Cycles' time) and aim (a third), for all of ``values``."""
        worst = max(values)
        if worst <= 1 / 3:
            text = "meets the target (at most half) and the aim (a third)"
            if worst > 1 / 3 - 0.02:
                text += f" by a narrow margin (largest ratio {worst:.3f})"
        elif worst <= 0.5:
            text = "meets the target (at most half), not the aim (a third)"
        elif min(values) <= 0.5:
            text = "meets the target (at most half) only in part"
        else:
            text = "misses the target (at most half)"
        return text

    for level in LEVELS:
        w = [ratio(x, "wall", level) for x in ("random", "hit")]
        c = [ratio(x, "cpu", level) for x in ("random", "hit")]
        cw = table[("rel", "wall", "cycles", "native", level)][0] - cycles_fixed_cost(records)
        f = [table[("rel", "wall", x, "native", level)][0] / cw for x in ("random", "hit")]
        L.append(f"* {level:.2%}: the plain estimator needs {w[0]:.2f} (exit `random`) / {w[1]:.2f} (exit `hit`) of "
                 f"Cycles' wall-clock time and {c[0]:.2f} / {c[1]:.2f} of its CPU time: {verdict(w + c)} on both clocks"
                 f" with both exit points. With Cycles' 1-sample bake time subtracted (in its favour): {f[0]:.2f} / "
                 f"{f[1]:.2f}, {verdict(f)}.")
    ratios = {clock: np.mean([ratio(x, clock, level) for x in ("random", "hit") for level in LEVELS])
              for clock in ("wall", "cpu")}
    if ratios["wall"] > ratios["cpu"] + 0.03:
        clocks = (f" Our ratios are worse on wall-clock time ({ratios['wall']:.2f} on average) than on CPU time "
                  f"({ratios['cpu']:.2f}): our two threads are less busy than Cycles' (Python work between ray casts).")
    else:
        clocks = f" Wall-clock and CPU-time ratios agree ({ratios['wall']:.2f} and {ratios['cpu']:.2f} on average)."
    clocks += (" Other work on this shared 2-CPU machine makes the wall-clock curves jagged (both products alike, "
               "being measured alternately); the CPU-time curves are the smoother ones.")
    if "stratified" in present(records):
        parts, values = [], []
        for level in LEVELS:
            w = [table[("rel", "wall", k, "native", level)][0] for k in ("cycles", "random", "stratified")]
            c = [table[("rel", "cpu", k, "native", level)][0] for k in ("cycles", "random", "stratified")]
            values += [w[2] / w[0], c[2] / c[0]]
            parts.append(f"{level:.2%}: {w[2] / w[0]:.2f} of Cycles' wall-clock time ({c[2] / c[0]:.2f} CPU), "
                         f"{w[2] / w[1]:.2f} of the plain estimator's ({c[2] / c[1]:.2f} CPU)")
        L.append("* `sampling=\"stratified\"` (systematic sources, Halton first ray; off by default because the "
                 "paper's path-count predictions are derived for the plain estimator): " + "; ".join(parts)
                 + f": {verdict(values)} at both levels on both clocks.")
    gap = relative_rms(refs["discrete"], refs["continuous"])
    c1 = table[("rel", "wall", "cycles", "continuous", LEVELS[0])][0]
    r1 = table[("rel", "wall", "random", "continuous", LEVELS[0])][0]
    L.append(f"* Against the continuous solution (what a Cycles user would call right), our default "
             f"`exit_point=\"random\"` carries the mesh's discretisation error ({gap:.2%} here), which eats most of a "
             f"1% budget: it then needs {r1 / c1:.2f} of Cycles' time at 1% and never reaches 0.25%; "
             "`exit_point=\"hit\"` converges to the continuous solution at the same cost per path and keeps its lead.")
    last = max(a for a in (r["amount"] for r in records if r["series"] == "cycles"))
    cyc = [r for r in records if r["series"] == "cycles" and r["amount"] == last]
    n_px = 600 * int(settings["block"].split("x")[0]) ** 2
    cw, cc_ = float(np.median([r["wall"] for r in cyc])), float(np.median([r["cpu"] for r in cyc]))
    top = max(r["amount"] for r in records if r["series"] == "random")
    our = [r for r in records if r["series"] == "random" and r["amount"] == top]
    ow, oc = float(np.median([r["wall"] for r in our])), float(np.median([r["cpu"] for r in our]))
    L.append(f"* Speeds at the longest runs: Cycles {n_px * last / cw / 1e6:.2f} M pixel samples/s "
             f"(each a path with next-event estimation), {cc_ / cw:.2f} cores busy; ours {top / ow / 1e6:.1f} M paths/s "
             f"(about 2 rays each at albedo 0.5), {oc / ow:.2f} cores busy." + clocks)
    share, mean_share = first_bounce_share()
    L.append(f"* Why the lead is not larger: the room is convex and its light small, and Cycles' next-event "
             "estimation sees the light from every wall and floor point, so its direct light has little noise; "
             "our shooting walks have no such term and count first hits instead. By the exact variances "
             f"of table 1, the first bounce alone is {share:.0%} of our per-path variance (summed over patches; "
             f"{mean_share:.0%} on average per patch). Stratifying the starting points and the first bounce ("
             "'beyond the paper') attacks exactly that part; a higher ray rate helps everywhere.")
    L.append("* Both curves fall as t^-1/2 down to about 0.2% against their own references, so neither shows a "
             "bias above that (and both give the light patches B = 1.004: the same units).")
    ours_ = [k for k in ("random", "hit", "stratified") if k in present(records)]
    panel = np.mean([ratio(k, "wall", level, "bave") for k in ours_ for level in LEVELS])
    relative = np.mean([ratio(k, "wall", level) for k in ours_ for level in LEVELS])
    L.append(f"* Under the panel's convention (RMS / mean reflected radiosity) our ratio is "
             f"{'worse' if panel > relative else 'not worse'} ({panel:.2f} against {relative:.2f} on average over "
             "our series and both levels, wall clock): that measure is "
             "dominated by the bright patches under the light, where the shooting estimator's variance "
             "(proportional to b_i) is largest and where Cycles' direct light is easiest; the per-patch relative "
             "measure weighs the dim patches (the ceiling, reached only by reflected light) as much, and there "
             "Cycles has to find the light through bounces.")
    L.append("")
    return L


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="few levels, one repetition, results under out/")
    ap.add_argument("--reps", type=int, default=5)
    ap.add_argument("--threads", type=int, default=THREADS)
    ap.add_argument("--block", type=int, default=BLOCK, help="pixels per side of a patch's block")
    ap.add_argument("--cycles-levels", type=int, default=10, help="Cycles samples 1, 2, 4, ... (this many)")
    ap.add_argument("--first-paths", type=int, default=125_000)
    ap.add_argument("--our-levels", type=int, default=10, help="our paths first-paths x 1, 2, 4, ... (this many)")
    ap.add_argument("--recompute-reference", action="store_true")
    ap.add_argument("--out", default=None, help="directory for the markdown, plot and JSON")
    ap.add_argument("--replot", default=None, metavar="JSON", help="redo the tables and plot from a run's JSON")
    args = ap.parse_args(argv)
    if args.replot:
        data = json.loads(Path(args.replot).read_text())
        out = Path(args.out) if args.out else Path(args.replot).parent
        out.mkdir(parents=True, exist_ok=True)
        write(data.get("command", ""), references(), data["settings"], data["records"], out,
              data.get("seconds", float("nan")), data.get("blocks", ()), data.get("notes", ()))
        return
    if args.quick:
        args.reps, args.cycles_levels, args.our_levels = 1, 6, 6
    out = Path(args.out) if args.out else (ROOT / "out" / "cycles_comparison_quick" if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    refs, settings, records = run(args)
    blocks = [] if args.quick else block_check(refs, args.threads)
    command = " ".join(sys.argv[1:] if argv is None else argv)
    seconds = time.perf_counter() - start
    (out / "cycles_comparison.json").write_text(json.dumps(
        {"command": command, "seconds": seconds, "settings": settings, "records": records, "blocks": blocks}, indent=1))
    write(command, refs, settings, records, out, seconds, blocks)


def write(command, refs, settings, records, out, seconds, blocks=(), notes=()):
    table = analyse(records)
    png = "cycles_comparison.png"
    plot(records, refs, out / png)
    report(command, refs, settings, records, table, out / "cycles_comparison.md", png, seconds, blocks, notes)
    print((out / "cycles_comparison.md").read_text())


if __name__ == "__main__":
    main()
