"""Where the Solve operator's time goes on an interior, stage by stage, beside Embree's raw ray rate.

    python -m benchmarks.operator_stages [--scene window_room] [--patch-size 0.155] [--rounds 3] [--before DIR] [--again]

``--again``: each round's process solves twice, a lamp's strength changed between, and the table
gives the second run (the same geometry: what the lighting loop pays, the meshes and the scene's
arrays and Embree scenes kept from the first). ``--before DIR``: a checkout of another commit (with this file in its benchmarks/), run in
alternation with this tree, round by round; the table gives both. Into
benchmarks/results/operator_stages.md (``--out``).

Each round runs in a fresh process: it builds the room (``interior_scene``, or
``walkthrough_scenes`` for its interiors: ``--scene studio_flat --patch-size 0``, the panel's
own size), selects what the picture benchmark selects, sets the panel's defaults (5% error
target, textured output) and runs ``solve_job.run`` (what the operator runs). The stages are timed by wrapping the functions that
run them (reading the selection, meshing, the scene's arrays and Embree scenes, the prediction, the
core solve and inside it Automatic's choice, the walk tables, the method's state and the chunks,
the colours and inside them the display's direct light at corners, writing). Embree's own time
inside the solve is the tracer's calls summed over threads. After the operator the same process
measures Embree alone (first hits of pre-drawn rays on the scene the solve traced, over the
solve's threads, ``throughput.raw_rate``): the solve's rays a second over that is the throughput
ratio. The table gives each stage's median over the rounds with its range, wall and CPU seconds
(the process's, all threads: on these shared machines wall time grows with the load, CPU time
much less), and the machine's load average at each start. The room at the default patch size
0.155 m has 11,092 patches: the "11k room" the operator's target speaks of.
"""
from __future__ import annotations

import argparse
import functools
import json
import os
import platform
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).parent / "results"
# (label, module, attribute, depth): what is wrapped, and how far it is indented in the table
STAGES = (
    ("read the selection", "addon.blender_write.solve_job", "read_selection", 0),
    ("meshing (patches)", "addon.bpy_free.pipeline", "make_patches", 0),
    ("refined patches (the outline split)", "addon.bpy_free.pipeline.solve_refinement", "refined", 0),
    ("scene arrays, Embree scenes", "addon.bpy_free.pipeline", "scene_and_notes", 0),
    ("prediction, method", "addon.bpy_free.pipeline", "prediction_for", 0),
    ("per-source groups", "addon.bpy_free.pipeline.relit", "groups_for", 0),
    ("core solve", "addon.bpy_free.pipeline", "solve", 0),
    ("Automatic's choice", "addon.core.solver", "chosen_method", 1),
    ("chunk plan", "addon.core.chunks", "chunk_plan", 1),
    ("walk tables", "addon.core.chunks", "WalkTables", 1),
    ("the two-way state (pilot, gathering)", "addon.core.methods.two_way.TwoWay", "create", 1),
    ("chunks", "addon.core.chunks._Run", "chunks", 1),
    ("result", "addon.core.chunks", "_result", 1),
    ("the display's direct means", "addon.bpy_free.pipeline.direct_means", "corrected", 0),
    ("back-light warning", "addon.bpy_free.pipeline", "back_light_warning", 0),
    ("colours (display)", "addon.bpy_free.pipeline", "write_colours", 0),
    ("the final gather of the bounced light", "addon.bpy_free.pipeline.final_gather", "gathered", 1),
    ("display's direct light at corners", "addon.core.display.point_direct", "corner_direct", 1),
    ("light arriving at corners", "addon.core.display.live_sources", "arriving", 1),
    ("light arriving at corners", "addon.core.display.point_direct", "arriving", 1),  # (before 553f4cf)
    ("the display's cells (their new points' light)", "addon.core.refine.display_cells", "refine", 1),
    ("per-source results", "addon.bpy_free.pipeline.relit", "source_results", 0),
    ("writing results", "addon.blender_write.solve_job", "write_results", 0),
    ("relight keep", "addon.blender_write.relight_keep", "keep", 0),
)


def _wrap(owner, name, label, seconds):
    original = getattr(owner, name)

    @functools.wraps(original)
    def timed(*args, **kwargs):
        start, cpu = time.perf_counter(), time.process_time()
        try:
            return original(*args, **kwargs)
        finally:
            seconds[label] = seconds.get(label, 0.0) + time.perf_counter() - start
            seconds["cpu " + label] = seconds.get("cpu " + label, 0.0) + time.process_time() - cpu

    setattr(owner, name, timed)


def _owner(path):
    import importlib

    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            owner = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for part in parts[cut:]:
            owner = getattr(owner, part)
        return owner
    raise ImportError(path)


def _embree_timer(totals):
    """Wraps the tracer's queries: seconds (summed over threads) and rays."""
    from addon.core.scene import raytrace

    lock = threading.Lock()
    for name in ("first_hit", "first_hit_barycentric"):
        original = getattr(raytrace.RayTracer, name)

        def timed(self, origins, directions, region=None, _original=original):
            start = time.thread_time()  # (the calling thread's CPU time: a loaded machine's waits left out)
            out = _original(self, origins, directions, region)
            with lock:
                totals["seconds"] += time.thread_time() - start
                totals["rays"] += len(origins)
            return out

        setattr(raytrace.RayTracer, name, timed)


def one(scene_name, patch_size, seed, again=False):
    """One operator run in this process: {stage: seconds, ...} and the raw rate; ``again``: those
    of a second run after a lamp's strength changed (the same geometry: what the lighting loop pays)."""
    import bpy

    sys.path.insert(0, str(ROOT))
    from benchmarks import interior_scene, picture, walkthrough_scenes
    from benchmarks.throughput import raw_rate
    from addon.blender_write import solve_job

    load = os.getloadavg()[0]
    if scene_name in walkthrough_scenes.SCENES:
        walkthrough_scenes.build(scene_name)
    else:
        interior_scene.build(scene_name)
    scene = bpy.context.scene
    picture.source_objects()
    settings = picture.prepare_product(scene, "TEXTURED", seed)
    if patch_size:
        settings.patch_size = patch_size
    seconds, embree, captured = {}, {"seconds": 0.0, "rays": 0}, {}
    for label, module, attribute, _ in STAGES:
        try:
            owner = _owner(module)
            _wrap(owner, attribute, label, seconds)
        except (AttributeError, ImportError):  # (a stage the code measured does not have: a --before version's)
            continue
    from addon.bpy_free import pipeline

    solve = pipeline.solve

    def solve_and_keep(core_scene, *args, **kwargs):
        embree["seconds"], embree["rays"] = 0.0, 0
        result = solve(core_scene, *args, **kwargs)
        captured["scene"], captured["result"], captured["embree"] = core_scene, result, dict(embree)
        return result

    pipeline.solve = solve_and_keep
    _embree_timer(embree)
    for run in range(2 if again else 1):
        if run:  # (the lighting loop: a lamp changed, the same geometry solved again; its stages alone)
            lamp = next(o for o in bpy.data.objects if o.type == "LIGHT" and not o.hide_render)
            lamp.data.energy *= 1.5
            seconds.clear()
            picture.source_objects()
        start, cpu = time.perf_counter(), time.process_time()
        finished = solve_job.run(bpy.context)
        seconds["operator"], seconds["cpu operator"] = time.perf_counter() - start, time.process_time() - cpu
        if finished.status != "FINISHED":
            raise RuntimeError(finished.error)
    result, core_scene = captured["result"], captured["scene"]
    from addon.core.methods.tables import WalkTables

    tracer = WalkTables(core_scene, "finite", 1e-3, "hit").tracer
    # (a scene of several regions traces a ray in each it may reach: no raw rate of one Embree scene)
    raw, raw_cpu = (float("nan"),) * 2 if core_scene.geometry.regions is not None else \
        raw_rate(core_scene, result.threads, 1.0, tracer=tracer)
    return {"seconds": seconds, "patches": int(core_scene.patch_count), "paths": int(result.paths),
            "rays": int(result.rays), "solve_rays": int(captured["embree"]["rays"]),
            "embree_seconds": captured["embree"]["seconds"], "raw_rate": raw, "raw_cpu_rate": raw_cpu, "threads": int(result.threads),
            "method": result.method, "relative_error": float(result.relative_error), "chunks": int(result.chunks),
            "load": load}


def _cell(values):
    mid = statistics.median(values)
    return f"{mid:.2f} ({min(values):.2f}-{max(values):.2f})" if len(values) > 1 else f"{mid:.2f}"


def _ratios(runs):
    """{label: values} of the solve's rays against Embree's."""
    rate = [r["rays"] / r["seconds"]["core solve"] / 1e6 for r in runs]
    raw = [r["raw_rate"] / 1e6 for r in runs]
    return {
        "Embree alone, raw (pre-drawn rays, same threads) Mray/s": raw,
        "the core solve, rays / its wall seconds, Mray/s": rate,
        "**throughput: the core solve / Embree raw (wall)**": [a / b for a, b in zip(rate, raw)],
        "the chunks alone / Embree raw (wall)": [r["rays"] / r["seconds"]["chunks"] / 1e6 / (r["raw_rate"] / 1e6) for r in runs],
        "Embree alone, raw, per CPU second Mray/s": [r["raw_cpu_rate"] / 1e6 for r in runs],
        "the core solve, rays / its CPU seconds, Mray/s": [r["rays"] / r["seconds"]["cpu core solve"] / 1e6 for r in runs],
        "**throughput per CPU second: the core solve / Embree raw**":
            [r["rays"] / r["seconds"]["cpu core solve"] / r["raw_cpu_rate"] for r in runs],
        "Embree inside the solve (all its casts, per CPU second) Mray/s":
            [r["solve_rays"] / r["embree_seconds"] / 1e6 for r in runs],
        "share of the solve's CPU time inside Embree": [r["embree_seconds"] / r["seconds"]["cpu core solve"] for r in runs],
    }


def table(sets, args):
    """The markdown report of the rounds: ``sets`` [(label, runs)], this tree's last."""
    first = sets[-1][1][0]
    lines = [f"`python -m benchmarks.operator_stages --scene {args.scene} --patch-size {args.patch_size:g} "
             f"--rounds {args.rounds}{' --again' if args.again else ''}`; {platform.machine()}, Python {platform.python_version()}, "
             f"{first['threads']} threads, 2 cores shared with other work.", ""]
    for label, runs in sets:
        lines.append(f"- {label}: {runs[0]['patches']:,} patches, {runs[0]['method']}, "
                     f"{statistics.median(r['paths'] for r in runs):,.0f} paths, "
                     f"{statistics.median(r['rays'] for r in runs):,.0f} rays, {runs[0]['chunks']} chunks, error "
                     f"{statistics.median(r['relative_error'] for r in runs):.2%} (target 5%); load average at the "
                     f"starts {', '.join(format(r['load'], '.1f') for r in runs)}.")
    head = " | ".join(f"{label} wall s | {label} CPU s" for label, _ in sets)
    lines += ["", f"| stage | {head} |", "|---|" + "---:|" * (2 * len(sets))]
    for label, depth in dict((label, depth) for label, _, _, depth in STAGES).items():  # (a stage that moved: once)
        cells = " | ".join(f"{_cell([r['seconds'].get(label, 0.0) for r in runs])} | "
                           f"{_cell([r['seconds'].get('cpu ' + label, 0.0) for r in runs])}" for _, runs in sets)
        lines.append(f"| {'&nbsp;&nbsp;' * 2 * depth}{label} | {cells} |")
    cells = " | ".join(f"**{_cell([r['seconds']['operator'] for r in runs])}** | "
                       f"**{_cell([r['seconds']['cpu operator'] for r in runs])}**" for _, runs in sets)
    lines.append(f"| **the operator** | {cells} |")
    lines += ["", "| the solve's rays | " + " | ".join(label for label, _ in sets) + " |", "|---|" + "---:|" * len(sets)]
    ratios = [_ratios(runs) for _, runs in sets]
    for key in ratios[0]:
        lines.append(f"| {key} | " + " | ".join(_cell(r[key]) for r in ratios) + " |")
    return "\n".join(lines) + "\n"


def _round(tree, args):
    done = subprocess.run([sys.executable, "-m", "benchmarks.operator_stages", "--one", "--scene", args.scene,
                           "--patch-size", str(args.patch_size), "--seed", str(args.seed)] + (["--again"] if args.again else []),
                          cwd=tree, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(tree)})
    line = [x for x in done.stdout.splitlines() if x.startswith("RESULT ")]
    if not line:
        sys.exit(done.stdout[-2000:] + done.stderr[-3000:])
    return json.loads(line[-1][7:])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default="window_room")
    parser.add_argument("--patch-size", type=float, default=0.155)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--before", default=None, help="a checkout of the commit to compare with")
    parser.add_argument("--before-label", default="before")
    parser.add_argument("--out", default=str(RESULTS / "operator_stages.md"))
    parser.add_argument("--again", action="store_true",
                        help="time a second run in each process, after a lamp changed (the geometry kept)")
    parser.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.one:
        print("RESULT " + json.dumps(one(args.scene, args.patch_size, args.seed, args.again)))
        return
    trees = ([(args.before_label, Path(args.before))] if args.before else []) + [("after" if args.before else "this tree", ROOT)]
    runs = {label: [] for label, _ in trees}
    for k in range(args.rounds):
        for label, tree in trees if k % 2 == 0 else trees[::-1]:  # (alternating which goes first)
            runs[label].append(_round(tree, args))
    text = "# Where the Solve operator's time goes (the 11k room)\n\n" + table([(label, runs[label]) for label, _ in trees], args)
    print(text)
    if args.out:
        Path(args.out).write_text(text)


if __name__ == "__main__":
    main()
