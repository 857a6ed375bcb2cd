"""Peak memory of the Solve operator on a room of about a million patches.

    python -m benchmarks.memory --operator            # into benchmarks/results/memory_operator.md
    python -m benchmarks.memory --operator --quick    # a 100k-patch room, into out/
    python -m benchmarks.memory --operator --repeat 2 # each plain run twice, the highest peak reported

Each measurement runs in a fresh process that imports ``bpy`` (Blender as a Python module,
headless), registers the extension, builds the room in Blender, selects it and runs
``bpy.ops.radiosity.solve()``: the operator's synchronous mode (``execute``: ``SolveJob.run`` on
the calling thread, then ``write_results``), with the panel's settings (error target,
measured stop rule, both colour outputs, threads automatic). The stages are timed by wrapping
the functions the operator calls (``read_selection``, ``make_patches``, ``scene_and_notes``, the
solve's ``WalkTables``, which builds the Embree scene, ``solve``, ``run_solve`` and
``write_results``): after each, the peak resident set so far (``ru_maxrss``) and the current
one. A second process per measurement runs the same under ``tracemalloc``, whose per-stage peak
counts the numpy and Python allocations of that stage alone (not Blender's nor Embree's).

Headless Blender has no window, so the modal run's live view cannot draw. Its arrays are made
as its draw handler makes them: the job keeps the result so far (``SolveJob.live``, as the
threaded run does) and, after every batch, ``live_view.triangles`` is computed and kept until
the next (standing for the vertex buffer the batch holds), and let go of before the results are
written, as the modal run removes its live view then. Nor does headless Blender keep an undo
stack: the undo step the operator pushes in the interface is not measured.

The room: six walls facing inwards (two of them coloured, so that the walk carries three
channels) and an emitting quad under the ceiling. ``grids``: each wall is a grid of N x N
faces, one patch each, so Blender holds a million source faces too; ``planes``: each wall is
one quad, meshed into N x N patches by the patch size. The floor below which no fix can go is
what Blender holds at the end, the scene and the result objects, measured once our arrays are
released (``after release``: garbage collected and ``malloc_trim``).
"""
from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

from addon.bpy_free import options
from addon.core import names

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).parent / "results"
MIB = 1 << 20
GIB = 1 << 30
# Walls N x N: six walls of 408^2 patches are 998,784, and the light adds a few thousand.
WALL_DIVISIONS = 408
ROOM = 4.0
STAGES = ("bpy imported", "scene built", "objects read", "patches meshed", "scene arrays", "tables and BVH",
          "solve (with live view)", "colours computed", "colours written", "after release")


def peak_rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


def current_rss():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _grid(origin, u, v, n):
    """(vertices, quads) of an n x n grid on origin + [0,1]u + [0,1]v, faces along u x v."""
    import numpy as np

    t = np.linspace(0.0, 1.0, n + 1)
    a, b = np.meshgrid(t, t, indexing="ij")
    vertices = origin + a.reshape(-1, 1) * u + b.reshape(-1, 1) * v
    k = (np.arange(n)[:, None] * (n + 1) + np.arange(n)).reshape(-1)
    quads = np.stack([k, k + n + 1, k + n + 2, k + 1], axis=1)
    return vertices, quads


def _material(bpy, name, base, strength=0.0):
    m = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        m.use_nodes = True
    node = m.node_tree.nodes["Principled BSDF"]
    node.inputs["Base Color"].default_value = (*base, 1.0)
    node.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    node.inputs["Emission Strength"].default_value = strength
    return m


def build_room(bpy, layout, n):
    """The room's objects, selected; returns the patch size that makes N x N patches a wall."""
    import numpy as np

    L = ROOM
    walls = {  # name: (origin, u, v, base colour); u x v points into the room
        "Floor": ((0, 0, 0), (L, 0, 0), (0, L, 0), (0.6, 0.6, 0.6)),
        "Ceiling": ((0, 0, L), (0, L, 0), (L, 0, 0), (0.7, 0.7, 0.7)),
        "Wall -X": ((0, 0, 0), (0, L, 0), (0, 0, L), (0.6, 0.15, 0.1)),
        "Wall +X": ((L, 0, 0), (0, 0, L), (0, L, 0), (0.1, 0.5, 0.15)),
        "Wall -Y": ((0, 0, 0), (0, 0, L), (L, 0, 0), (0.6, 0.6, 0.6)),
        "Wall +Y": ((0, L, 0), (L, 0, 0), (0, 0, L), (0.6, 0.6, 0.6)),
        "Light": ((0.375 * L, 0.375 * L, 0.98 * L), (0, 0.25 * L, 0), (0.25 * L, 0, 0), (0.0, 0.0, 0.0)),
    }
    for name, (origin, u, v, base) in walls.items():
        divisions = n if layout == "grids" and name != "Light" else 1
        vertices, quads = _grid(np.array(origin, float), np.array(u, float), np.array(v, float), divisions)
        mesh = bpy.data.meshes.new(name)
        mesh.vertices.add(len(vertices))
        mesh.vertices.foreach_set("co", vertices.astype(np.float32).ravel())
        mesh.loops.add(quads.size)
        mesh.loops.foreach_set("vertex_index", quads.astype(np.int32).ravel())
        mesh.polygons.add(len(quads))
        mesh.polygons.foreach_set("loop_start", np.arange(0, quads.size, 4, dtype=np.int32))
        mesh.update(calc_edges=True)
        mesh.materials.append(_material(bpy, name, base, 10.0 if name == "Light" else 0.0))
        obj = bpy.data.objects.new(name, mesh)
        bpy.context.scene.collection.objects.link(obj)
        obj.select_set(True)
    # grids: faces a little smaller than a patch stay one patch each; planes: N x N a wall
    return L / n * (1.5 if layout == "grids" else 1.0)


def child(layout, n, target_error, method, use_tracemalloc):
    """One measurement; prints a JSON line."""
    sys.path.insert(0, str(ROOT))
    out = {"layout": layout, "divisions": n, "target_error": target_error, "tracemalloc": use_tracemalloc, "method": method}
    stages = out["stages"] = []
    if use_tracemalloc:
        import tracemalloc

    def mark(name):
        entry = {"stage": name, "peak": peak_rss(), "current": current_rss(), "time": time.perf_counter()}
        if use_tracemalloc and tracemalloc.is_tracing():
            entry["traced_current"], entry["traced_peak"] = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
        stages.append(entry)

    import bpy

    import addon
    from addon.bpy_free import pipeline
    from addon.blender_read.selection import read_selection
    from addon.blender_read.objects import is_result_object
    from addon.blender_write.results import write_results
    from addon.bpy_free import worker
    from addon.blender_write import solve_job
    from addon.ui import live_view
    from addon.core import chunks

    mark("bpy imported")
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    patch_size = build_room(bpy, layout, n)
    settings = bpy.context.scene.radiosity
    settings.patch_size = patch_size
    settings.target_error = target_error
    settings.method = method
    bpy.context.view_layer.update()
    if use_tracemalloc:
        tracemalloc.start()
    mark("scene built")

    def after(stage, function):
        def wrapped(*args, **kwargs):
            result = function(*args, **kwargs)
            mark(stage)
            return result
        return wrapped

    solve_job.read_selection = after("objects read", read_selection)
    pipeline.make_patches = after("patches meshed", pipeline.make_patches)
    pipeline.scene_and_notes = after("scene arrays", pipeline.scene_and_notes)
    chunks.WalkTables = after("tables and BVH", chunks.WalkTables)
    pipeline.solve = after("solve (with live view)", pipeline.solve)
    # (SolveJob.run, not run_solve: a wrapper's arguments would keep the objects' arrays alive)
    worker.SolveJob.run = after("colours computed", worker.SolveJob.run)
    live = {"version": None, "arrays": None, "bytes": 0}

    def write_without_live_view(*args, **kwargs):
        live["arrays"] = None  # the modal run removes its live view before writing (the operator's _cleanup)
        return write_results(*args, **kwargs)

    solve_job.write_results = after("colours written", write_without_live_view)

    def draw_live(job):
        """What the live view's draw handler makes, after every batch (a window-less stand-in)."""
        job.live_view = True
        version, radiosity = job.live
        if radiosity is not None and version != live["version"]:
            live["arrays"] = None  # the old batch goes when the new one is made
            live["arrays"] = live_view.triangles(job.patches, radiosity)
            live["version"] = version
            live["bytes"] = sum(a.nbytes for a in live["arrays"]) + radiosity.nbytes

    t = time.perf_counter()
    finished = solve_job.run(bpy.context, progress_listener=draw_live)  # (what the operator runs)
    out["seconds"] = time.perf_counter() - t
    assert finished.status == "FINISHED", finished.error
    out["live_bytes"] = live["bytes"]
    radiosity = bpy.context.scene.radiosity
    out["patches"] = int(radiosity.last_patches)
    out["paths"] = int(radiosity.last_paths)
    out["rays"] = int(radiosity.last_rays)
    out["source_faces"] = sum(len(o.data.polygons) for o in bpy.data.objects if not is_result_object(o))
    out["result_corners"] = sum(len(o.data.loops) for o in bpy.data.objects if is_result_object(o))
    # Release every array of ours: the live view's, the geometry cache, the operator's job
    # (Blender keeps the last operator, and so its job, for the redo panel).
    live["arrays"] = None
    from addon.bpy_free import patches

    patches.GEOMETRY_CACHE.clear()
    pipeline.RAY_RATES.clear()
    for op in bpy.context.window_manager.operators:
        getattr(op, "_job", None) and setattr(op, "_job", None)
    worker.set_running_job(None)
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    mark("after release")
    print(json.dumps(out))


def measure(layout, n, target_error, method, use_tracemalloc=False):
    cmd = [sys.executable, "-m", "benchmarks.memory_operator", "--child", layout, str(n), str(target_error), method]
    if use_tracemalloc:
        cmd.append("--tracemalloc")
    done = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    if done.returncode:
        raise RuntimeError(done.stderr[-4000:])
    return json.loads(done.stdout.strip().splitlines()[-1])


def _peak(run):
    return max(s["peak"] for s in run["stages"])


def _by_stage(run):
    return {s["stage"]: s for s in run["stages"]}


def table(rows):
    """Markdown rows: per stage, peak and current resident set, and the tracemalloc peak."""
    head = ["| stage |"]
    rule = ["|---|"]
    for plain, _ in rows:
        label = f"{plain['layout']}, {plain['paths']:,} paths"
        head.append(f" peak RSS MiB ({label}) | current MiB | numpy peak during MiB | numpy held after MiB |")
        rule.append("---:|---:|---:|---:|")
    lines = ["".join(head), "".join(rule)]
    for stage in STAGES:
        cells = [f"| {stage} |"]
        for plain, traced in rows:
            p, t = _by_stage(plain).get(stage), _by_stage(traced).get(stage)
            if p is None:
                cells.append(" | | | |")
                continue
            numpy_peak = f"{t['traced_peak'] / MIB:.0f}" if t and "traced_peak" in t else ""
            numpy_now = f"{t['traced_current'] / MIB:.0f}" if t and "traced_current" in t else ""
            cells.append(f" {p['peak'] / MIB:.0f} | {p['current'] / MIB:.0f} | {numpy_peak} | {numpy_now} |")
        lines.append("".join(cells))
    return lines


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--child", nargs=4, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--tracemalloc", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--layouts", nargs="+", default=["grids", "planes"])
    ap.add_argument("--method", choices=names.METHODS, default=options.METHOD.default,
                    help=f"the panel's Method (default: its default, {options.METHOD.default})")
    ap.add_argument("--divisions", type=int, default=None, help=f"N, patches a wall side (default {WALL_DIVISIONS})")
    ap.add_argument("--errors", type=float, nargs="+", default=[12.0, 6.0],
                    help="error targets in %% (the panel's setting): two path counts")
    ap.add_argument("--before", default=None, help="the JSON of an earlier run, shown beside this one")
    ap.add_argument("--before-label", default=None, help="what the earlier run measured (a commit)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="plain runs of each measurement (the peak reported is the highest; thread timing and "
                         "the allocator move it by a few tens of MiB)")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    if args.child is not None:
        layout, n, error, method = args.child
        child(layout, int(n), float(error), method, args.tracemalloc)
        return
    n = args.divisions or (128 if args.quick else WALL_DIVISIONS)
    out = Path(args.out) if args.out else (ROOT / "out" / "memory_operator_quick" if args.quick else RESULTS)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for layout in args.layouts:
        for k, error in enumerate(args.errors):
            runs = [measure(layout, n, error, args.method) for _ in range(max(1, args.repeat))]
            plain = max(runs, key=_peak)  # the highest of the runs, stage by stage
            plain["run_peaks"] = [_peak(run) for run in runs]
            # tracemalloc at the first error target only (the second checks the peak's independence of the paths)
            traced = measure(layout, n, error, args.method, use_tracemalloc=True) if k == 0 else {"stages": []}
            rows.append((plain, traced))
            print(f"{layout} {plain['patches']:,} patches, {plain['paths']:,} paths ({error:g}%): peaks "
                  f"{', '.join(f'{p / MIB:.0f}' for p in plain['run_peaks'])} MiB, {plain['seconds']:.0f} s", flush=True)
    L = [
        "# Peak memory of the Solve operator on a room of a million patches",
        "",
        f"`python -m benchmarks.memory --operator {' '.join(argv or [])}`".replace(" `", "`"),
        f"Machine: {platform.machine()}, Python {platform.python_version()}; each measurement in a fresh process "
        f"(`bpy`, headless); `bpy.ops.radiosity.solve()` with the panel's settings (method `{args.method}`, "
        "measured stop rule at the error target, face and vertex colours, 2 threads). Method: "
        "`benchmarks/memory_operator.py`.",
        "",
    ]
    for plain, traced in rows:
        last = _by_stage(plain)
        peak = _peak(plain)
        floor = last["after release"]["current"]
        runs = plain.get("run_peaks", [peak])
        of_runs = f" (the highest of {len(runs)} runs: {', '.join(f'{p / MIB:.0f}' for p in runs)})" if len(runs) > 1 else ""
        L.append(
            f"- `{plain['layout']}`: {plain['patches']:,} patches ({plain['source_faces']:,} source faces, "
            f"{plain['result_corners']:,} result corners), {plain['target_error']:g}% target: {plain['paths']:,} paths, "
            f"{plain['rays']:,} rays, {plain['seconds']:.0f} s. **Peak {peak / MIB:.0f} MiB**{of_runs}; Blender holding the "
            f"scene and the results at the end {floor / MIB:.0f} MiB; peak above that {(peak - floor) / MIB:.0f} MiB; "
            f"live view arrays {plain['live_bytes'] / MIB:.0f} MiB."
        )
    if args.before:
        before = json.loads(Path(args.before).read_text())
        L += ["", f"Before (`{args.before_label}`):" if getattr(args, "before_label", None) else "Before:", ""]
        for run in before:
            plain = run["plain"]
            peak = max(s["peak"] for s in plain["stages"])
            floor = _by_stage(plain)["after release"]["current"]
            L.append(f"- `{plain['layout']}`: {plain['patches']:,} patches, {plain['paths']:,} paths: peak {peak / MIB:.0f} MiB, "
                     f"{(peak - floor) / MIB:.0f} MiB above Blender holding the scene and the results ({floor / MIB:.0f} MiB)")
        L += ["", "Before, per stage:", ""] + table([(run["plain"], run["traced"]) for run in before])
    L += ["", "Per stage, at its end: the peak resident set so far and the current one (of the run with the "
          "highest peak); from the tracemalloc run "
          "(started once the scene is built), the peak of the numpy and Python allocations live during the stage "
          "and what is still allocated at its end.", ""]
    L += table(rows)
    (out / "memory_operator.md").write_text("\n".join(L) + "\n")
    (out / "memory_operator.json").write_text(json.dumps([{"plain": p, "traced": t} for p, t in rows], indent=1))
    print("\n".join(L))


if __name__ == "__main__":
    main()
