"""Peak memory of the whole command-line process, ``python -m addon``, at about a million patches.

    python -m benchmarks.memory_cli                      # into benchmarks/results/memory_cli.md
    python -m benchmarks.memory_cli --patch-sizes 0.01   # one size (about 82k patches), into out/

Each run is a fresh ``python -m addon --scene cornell --patch-size S`` process (the built-in
Cornell box meshed finer): it builds the scene in ``bpy``, says the estimate, solves through the
operator, writes the colours, renders the Cycles preview and saves the .blend. Its peak resident
set is the kernel's for the whole process (``os.wait4``'s ``ru_maxrss``), measured from outside,
with the preview and with ``--no-preview``.

A second process per run (``--trace``) runs the same ``main()`` with its stages marked: the
functions the command line calls (``build_sample_scene``, ``pipeline.estimate``, the operator's
``read_selection``, ``make_patches``, ``scene_and_notes``, the solve's ``WalkTables`` and
``solve``, ``write_results``, ``render_preview``) are wrapped, and at every entry and exit the
peak resident set since the last mark is read (``VmHWM``) and reset (``/proc/self/clear_refs``),
so that each interval between two marks has its own peak. (Resetting it spoils the kernel's
whole-process figure for that process, which is why the plain run is separate.)
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = Path(__file__).parent / "results"
MIB = 1 << 20
GIB = 1 << 30
# Patch sizes of the built-in Cornell box (6.35 m^2 of faces): about 823k, 1.01M and 1.25M patches.
PATCH_SIZES = (0.0029, 0.0026, 0.00233)
# A loose error target: the peak does not depend on the path count (memory.md, memory_operator.md)
# and a 5% target at a million patches takes about 5 minutes on this machine's 2 cores.
ERROR = 20.0


def _status(field):
    with open("/proc/self/status") as f:
        return int(re.search(rf"{field}:\s+(\d+) kB", f.read()).group(1)) * 1024


class Marks:
    """Per-interval peaks of the resident set: ``mark(name)`` ends the interval since the last mark."""

    def __init__(self):
        self.entries = []
        self.last = time.perf_counter()
        self.can_reset = self._reset()

    @staticmethod
    def _reset():
        try:
            with open("/proc/self/clear_refs", "w") as f:
                f.write("5")  # resets VmHWM to the current resident set
            return True
        except OSError:
            return False

    def mark(self, name):
        now = time.perf_counter()
        self.entries.append({"mark": name, "peak": _status("VmHWM"), "current": _status("VmRSS"),
                             "seconds": now - self.last})
        self._reset()
        self.last = time.perf_counter()


def traced_main(argv, out_path):
    """Run the command line's main() with its stages marked; writes the marks as JSON."""
    sys.path.insert(0, str(ROOT))
    marks = Marks()
    import bpy  # noqa: F401

    from addon.bpy_free import pipeline
    from addon.blender_read import selection
    from addon.cli import preview, run, scenes
    from addon.core import solver
    from addon.ui import operators

    marks.mark("bpy imported")

    def wrap(owner, name, label):
        function = getattr(owner, name, None)
        if function is None:  # (an earlier version of the command line)
            return

        def wrapped(*args, **kwargs):
            marks.mark(f"before {label}")
            try:
                return function(*args, **kwargs)
            finally:
                marks.mark(label)

        setattr(owner, name, wrapped)

    wrap(scenes, "build_sample_scene", "scene built in bpy")
    wrap(pipeline, "estimate", "estimate (meshing, scene, calibration)")
    wrap(selection, "read_selection", "objects read")
    wrap(operators, "read_selection", "objects read")
    wrap(pipeline, "make_patches", "patches meshed")
    wrap(pipeline, "scene_and_notes", "core scene")
    wrap(solver, "WalkTables", "tables and BVH")
    wrap(pipeline, "solve", "solve")
    wrap(operators, "write_results", "colours written")
    wrap(run, "release_solve_memory", "solve's memory released")
    wrap(preview, "auto_exposure", "exposure read")
    wrap(preview, "preview_settings", "preview set up")
    wrap(preview, "render_preview", "preview rendered")
    status = run.main(argv)
    marks.mark("saved (main returned)")
    Path(out_path).write_text(json.dumps({"status": status, "marks": marks.entries, "can_reset": marks.can_reset}))
    return status


def _run(cmd, log):
    """(exit status, peak resident set in bytes, seconds) of a child process, from os.wait4."""
    t = time.perf_counter()
    with open(log, "w") as f:
        process = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(process.pid, 0)
    process.returncode = os.waitstatus_to_exitcode(status)
    return process.returncode, usage.ru_maxrss * 1024, time.perf_counter() - t


def cli_args(patch_size, error, preview, blend):
    args = ["--scene", "cornell", "--patch-size", repr(patch_size), "--error", repr(error), "-o", str(blend), "-q"]
    return args + ([] if preview else ["--no-preview"])


def _summary_line(log):
    text = Path(log).read_text()
    found = re.search(r"cornell: ([\d,]+) patches, ([\d,]+) paths, ([\d,]+) rays, ([\d.]+) s \(([^)]*)\)", text)
    if not found:
        raise RuntimeError(text[-3000:])
    return {"patches": int(found.group(1).replace(",", "")), "paths": int(found.group(2).replace(",", "")),
            "rays": int(found.group(3).replace(",", "")), "solve_seconds": float(found.group(4)),
            "method": found.group(5)}


def measure(patch_size, error, preview, work, trace=True):
    """A plain run (the whole process's peak) and, if ``trace``, a traced one (per stage)."""
    tag = f"{patch_size:g}_{'preview' if preview else 'no_preview'}"
    blend = work / f"cornell_{tag}.blend"
    args = cli_args(patch_size, error, preview, blend)
    status, peak, seconds = _run([sys.executable, "-m", "addon", *args], work / f"{tag}.log")
    if status:
        raise RuntimeError(f"exit {status}: " + (work / f"{tag}.log").read_text()[-3000:])
    run = {"patch_size": patch_size, "error": error, "preview": preview, "peak": peak, "seconds": seconds,
           **_summary_line(work / f"{tag}.log")}
    if trace:
        marks = work / f"{tag}_marks.json"
        status, _, _ = _run([sys.executable, "-m", "benchmarks.memory_cli", "--trace", str(marks), "--", *args],
                            work / f"{tag}_trace.log")
        if status:
            raise RuntimeError(f"traced exit {status}: " + (work / f"{tag}_trace.log").read_text()[-3000:])
        run["marks"] = json.loads(marks.read_text())["marks"]
    return run


def stage_table(runs):
    """Markdown: per interval between marks, its peak resident set (MiB) for each traced run."""
    traced = [r for r in runs if r.get("marks")]
    head = "| interval ending at | " + " | ".join(
        f"{r['patches']:,} patches{'' if r['preview'] else ', no preview'}: peak MiB | at its end MiB"
        for r in traced) + " |"
    lines = [head, "|---|" + "---:|---:|" * len(traced)]
    names = [m["mark"] for m in traced[0]["marks"]] if traced else []
    for k, name in enumerate(names):
        cells = []
        for r in traced:
            m = r["marks"][k] if k < len(r["marks"]) and r["marks"][k]["mark"] == name else None
            cells.append(f"{m['peak'] / MIB:.0f} | {m['current'] / MIB:.0f}" if m else " | ")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def crossing(runs):
    """The patch count at which the whole process's peak (with the preview) reaches 1 GiB, by a
    straight line between the two runs around it (None if no two runs bracket it)."""
    points = sorted((r["patches"], r["peak"]) for r in runs if r["preview"])
    for (p0, m0), (p1, m1) in zip(points, points[1:]):
        if m0 < GIB <= m1:
            return p0 + (GIB - m0) * (p1 - p0) / (m1 - m0)
    return None


def report(runs, argv):
    peaks = [r for r in runs if r["preview"]]
    per_patch = [(r["peak"], r["patches"]) for r in peaks]
    L = [
        "# Peak memory of the whole command line, `python -m addon`, at about a million patches",
        "",
        f"`python -m benchmarks.memory_cli {' '.join(argv)}`".replace(" `", "`"),
        f"Machine: {platform.machine()}, Python {platform.python_version()}, `bpy` {_bpy_version()}; "
        "each run a fresh `python -m addon --scene cornell --patch-size S "
        f"--error {runs[0]['error']:g} -q` (the built-in Cornell box meshed finer: it builds the scene in "
        "`bpy`, says the estimate, solves through the operator, writes face and vertex colours, renders the "
        "Cycles preview at 480 px and 16 samples, and saves the .blend); peak resident set of the whole "
        "process from `os.wait4` (`ru_maxrss`, what `/usr/bin/time -v` prints). The peak does not depend "
        "on the path count (`memory.md`, `memory_operator.md`), so a loose error target keeps the runs short. "
        "Method: `benchmarks/memory_cli.py`.",
        "",
        "| patch size | patches | method | paths | preview | whole process peak MiB | run s |",
        "|---:|---:|---|---:|---|---:|---:|",
    ]
    for r in runs:
        L.append(f"| {r['patch_size']:g} | {r['patches']:,} | {r['method']} | {r['paths']:,} | "
                 f"{'yes' if r['preview'] else 'no (`--no-preview`)'} | **{r['peak'] / MIB:.0f}** | {r['seconds']:.0f} |")
    cross = crossing(runs)
    if per_patch:
        L += ["", "Largest peak: " + ", ".join(f"{peak / MIB:.0f} MiB at {patches:,} patches" for peak, patches in per_patch)
              + (f"; 1 GiB is reached at about {round(cross, -4):,.0f} patches (a straight line between the runs around it)."
                 if cross else ".")]
    L += ["", "Per interval between two marks of a traced run (same arguments): the peak resident set during it "
          "(`VmHWM`, reset at every mark) and the resident set at its end. `before X` ends where X starts.", ""]
    L += stage_table(runs)
    return L


def _bpy_version():
    try:
        out = subprocess.run([sys.executable, "-c", "import bpy; print(bpy.app.version_string)"], capture_output=True,
                             text=True, cwd=ROOT, timeout=120)
        return out.stdout.strip().splitlines()[-1]
    except Exception:  # noqa: BLE001
        return "?"


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "--trace":
        cli = argv[3:] if len(argv) > 2 and argv[2] == "--" else argv[2:]
        sys.exit(traced_main(cli, argv[1]))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--patch-sizes", type=float, nargs="+", default=list(PATCH_SIZES))
    ap.add_argument("--error", type=float, default=ERROR, help="the error target in %% (default %(default)s)")
    ap.add_argument("--no-preview-at", type=float, nargs="*", default=None,
                    help="patch sizes also run with --no-preview (default: the middle one)")
    ap.add_argument("--no-trace", action="store_true", help="only the plain runs")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    default_sizes = args.patch_sizes == list(PATCH_SIZES)
    out = Path(args.out) if args.out else (RESULTS if default_sizes else ROOT / "out" / "memory_cli")
    out.mkdir(parents=True, exist_ok=True)
    work = ROOT / "out" / "memory_cli_runs"
    work.mkdir(parents=True, exist_ok=True)
    no_preview = args.no_preview_at if args.no_preview_at is not None else [args.patch_sizes[len(args.patch_sizes) // 2]]
    runs = []
    for size in args.patch_sizes:
        for preview in (True, False) if size in no_preview else (True,):
            run = measure(size, args.error, preview, work, trace=not args.no_trace)
            runs.append(run)
            print(f"patch size {size:g}: {run['patches']:,} patches, preview {preview}: peak {run['peak'] / MIB:.0f} MiB, "
                  f"{run['seconds']:.0f} s", flush=True)
    L = report(runs, argv)
    (out / "memory_cli.md").write_text("\n".join(L) + "\n")
    (out / "memory_cli.json").write_text(json.dumps(runs, indent=1))
    print("\n".join(L))


if __name__ == "__main__":
    main()
