"""Memory of the command line, ``python -m addon``: the whole process, preview and save included.

benchmarks/memory_cli.py measures it at about a million patches (results/memory_cli.md); here a
smaller run checks the growth per patch, and the mechanisms that keep it down are checked one by
one: the preview renders the results without making them lights for Cycles, the solve's cached
geometry is let go of before the save and the render, and the preview's exposure comes from the
solve's arrays (the same value as read back from Blender, which copies the colours to read them).
"""

import os
import subprocess
import sys

import bpy
import pytest

from ..conftest import build_test_scene, result_objects, solve_outputs

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
MIB = 1 << 20


# Linux hands a process's peak resident set (ru_maxrss) on to the children it starts: a command
# started from pytest itself reports at least the test process's own peak (1.5 GB late in the
# suite). So a small fresh launcher starts it and reports its os.wait4 peak.
LAUNCHER = (
    "import os, subprocess, sys\n"
    "p = subprocess.Popen(sys.argv[1:])\n"
    "_, status, usage = os.wait4(p.pid, 0)\n"
    "sys.stderr.write(f'\\nlauncher: {os.waitstatus_to_exitcode(status)} {usage.ru_maxrss}\\n')\n"
)


def _peak_of(cmd, cwd):
    """(exit status, output, the process's peak resident set in bytes), from os.wait4 in a
    fresh launcher."""
    log = os.path.join(cwd, "log.txt")
    with open(log, "w") as f:
        subprocess.run([sys.executable, "-c", LAUNCHER, *cmd], cwd=cwd, stdout=f, stderr=subprocess.STDOUT,
                       env={**os.environ, "PYTHONPATH": ROOT})
    with open(log) as f:
        text = f.read()
    status, kib = text.rstrip().rsplit("launcher: ", 1)[1].split()
    return int(status), text, int(kib) * 1024


# The command line's growth above Blender with the extension registered, per patch, at 162,560
# patches with the preview: 2,255 B when Cycles built a light tree over every emitting triangle of
# the preview, 1,141-1,243 B since; 1,625-1,645 B with the smooth light's direct-light corners and
# noise filters (a clean clone's CI 1,793), 1,545-1,577 B once the filter's fit went a block of
# pairs at a time (1,583-1,636 on a later day; a clean clone's CI 1,830), 1,435-1,466 B once the
# direct light's kept corners were added a block at a time, 1,429-1,469 B with the smooth
# display's ringing test (its statistics a block of corners at a time; 1,535-1,569 B when they were
# whole arrays); runs differ by up to 40 MiB (250 B a patch here); 1,803-1,822 B with the display's
# lamps sampled a round at a time; 1,912-1,998 B once a live run (the default) stores the whole light
# for EEVEE and exporters beside the part Cycles' live output reads (a second float colour of every
# corner), and 1,926-2,165 B after the display's and the main job's changes (the most on a clean clone, whose
# Blender starts at 431 MiB against 273 here); 2,290-2,378 B with the display's cells (the written
# meshes split where the direct light changes, and their colours: 596 against 641 MiB at the preview's
# peak, 630 once the colours' own arrays were let go of before it), emitters' backs and the colours on
# two threads; 2,338 B before the display's slack and 2,373-2,383 B with it (a relight map's share of
# each patch's missing light, a step of the smoothing at a time, as float16: 2,470-2,511 B as float64).
# A clean clone runs higher: standalone 2,394-2,486 B before the slack, 2,493-2,514 B with it, and
# inside the whole suite (whose Blender starts at 433 MiB against 363 standalone) 2,595-2,618 B; the
# bound went from 2.5 to 2.75 KiB with that (runs differ by up to 250 B a patch, above). At a
# million patches it is about 0.75 KiB (docs/performance.md, results/memory_cli.md).
GROWTH_PER_PATCH = 2.75 * 1024


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss in KiB and os.wait4: Linux")
def test_the_whole_command_line_grows_by_less_than_a_bound_per_patch(tmp_path):
    status, out, base = _peak_of([sys.executable, "-c", "import bpy, addon; bpy.ops.wm.read_factory_settings("
                                  "use_empty=True); addon.register()"], str(tmp_path))
    assert status == 0, out[-3000:]
    status, out, peak = _peak_of([sys.executable, "-m", "addon", "--scene", "cornell", "--patch-size", "0.007",
                                  "--error", "40", "--resolution", "64", "--samples", "1", "--threads", "2",
                                  "-o", str(tmp_path / "c.blend"), "-q"], str(tmp_path))
    assert status == 0, out[-3000:]
    assert "cornell: 162,560 patches" in out and (tmp_path / "c.png").exists(), out[-3000:]
    growth = (peak - base) / 162_560
    assert growth < GROWTH_PER_PATCH, (f"{peak / MIB:.0f} MiB at 162,560 patches, {base / MIB:.0f} MiB for Blender "
                                       f"and the extension: {growth:.0f} B a patch")


def _solve(blender, output="BOTH"):
    build_test_scene()
    settings = blender.scene.radiosity
    settings.target_error, settings.threads, settings.output = 20.0, 1, output
    assert bpy.ops.radiosity.solve() == {"FINISHED"}


def test_the_preview_renders_the_results_without_emission_sampling_and_restores_it(blender):
    from addon.cli.preview import preview_settings

    _solve(blender)
    materials = {slot.material for o in result_objects() for slot in o.material_slots}
    assert materials and all(m.cycles.emission_sampling == "AUTO" for m in materials)
    sources = [o for o in bpy.data.objects if o.type == "MESH" and "radiosity_source" not in o.keys()]
    changes = preview_settings(blender.scene, sources, 32, 1)
    # seen by camera rays only (no bounces): Cycles does not make a light of every emitting triangle
    assert all(m.cycles.emission_sampling == "NONE" for m in materials)
    changes.restore()
    assert all(m.cycles.emission_sampling == "AUTO" for m in materials)


@pytest.mark.parametrize("output", ["BOTH", "FACE", "VERTEX"])
def test_the_preview_exposure_from_the_arrays_is_the_one_read_back(blender, output, monkeypatch):
    from addon.cli.preview import auto_exposure, preview_exposure

    outputs = solve_outputs(monkeypatch)
    _solve(blender, output)
    exposures = [preview_exposure(out) for out in outputs]
    assert len(exposures) == 1 and exposures[0] != 0.0
    assert exposures[0] == auto_exposure()  # exactly: the same float32 values, the same median


def test_the_command_line_lets_go_of_the_solve_before_saving(blender, tmp_path):
    from addon.bpy_free import patches
    from addon.__main__ import main

    build_test_scene()
    assert main(["--current", "--no-preview", "--error", "30", "--threads", "1", "-q",
                 "-o", str(tmp_path / "out.blend")]) == 0
    assert result_objects()
    # the meshed geometry and the core's scene with its ray tracer, which the panel keeps for a re-run
    assert not patches.GEOMETRY_CACHE._entries
