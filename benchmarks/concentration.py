"""Where the sources' light lands on few patches: Automatic's concentration against the time the
walk and the two-way iteration take to the same error target.

    python -m benchmarks.concentration            # writes benchmarks/results/concentration.md

For each scene: ``methods.automatic.concentration`` (how much more noise the two-way iteration's
first generation shoots the first reflection with than rays allotted by its power: 1 where the
light lands as its rays are allotted), Automatic's choice at 5%, and the seconds the walk and the
two-way iteration take to 5% and to 2% on the run's own mean (exit point hit, the measured stop
rule, seed 0, 2 threads, at most MAX_SECONDS a run: "cap" where a run ended at its path cap
above the target). Scenes: a 4 x 3 x 2.5 room of 1,536 patches (R 0.6) lit by one spot lamp
5 cm under its ceiling, of several cone angles (360: a point lamp), the closed boxes lit by one
ceiling patch in a corner or the middle (tests/core/boxes.py), and sample scenes.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "core"))

from boxes import grey_room, small_source_box, spot_box  # noqa: E402

from addon.core import predict, relative_rms_to_mse, solve  # noqa: E402
from addon.core.methods import automatic  # noqa: E402

MAX_SECONDS = 40.0
TARGETS = (0.05, 0.02)


def scenes():
    import sample_scenes

    for degrees in (1, 10, 20, 45, 60, 75, 90, 150, 360):
        yield f"spot room, {degrees} degrees", lambda d=degrees: spot_box(d)
    for n in (4, 8, 16):
        yield f"box, corner source ({6 * n * n} patches)", lambda n=n: small_source_box(n=n, corner=True)[0]
    yield "box, middle source (384 patches)", lambda: small_source_box()[0]
    yield "grey room (384 patches)", lambda: grey_room()[0]
    yield "Cornell box, closed", lambda: sample_scenes.build("cornell_box", closed=True).scene
    yield "Cornell box", lambda: sample_scenes.build("cornell_box").scene
    yield "figure 1 cube, R 0.5", lambda: sample_scenes.build("fig1_r0.5").scene
    yield "figure 6 room", lambda: sample_scenes.build("fig6_room").scene


def seconds_to(scene, method, relative):
    target = relative_rms_to_mse(predict(scene), relative)
    start = time.perf_counter()
    r = solve(scene, target_mse=target, seed=0, stop_rule="measured", threads=2, method=method, exit_point="hit",
              error_scale="measured", max_seconds=MAX_SECONDS)
    seconds = time.perf_counter() - start
    if r.stopped == "target":
        return f"{seconds:.1f}"
    return f"{r.stopped} {r.relative_error:.1%} ({seconds:.0f} s)"


def main():
    lines = ["# Where the light lands on few patches: concentration and the time to a target", "",
             "Automatic's concentration (`methods.automatic.concentration`; it runs the walk above "
             f"{automatic.MAX_CONCENTRATION:g}), its choice at 5%, and the seconds to 5% and 2% on the run's own mean "
             "(exit point hit, measured stop rule, seed 0, 2 threads on a shared 2-core machine, at most "
             f"{MAX_SECONDS:g} s). `python -m benchmarks.concentration`.", "",
             "| scene | patches | concentration | Automatic | walk 5% | two-way 5% | walk 2% | two-way 2% |",
             "|---|---|---|---|---|---|---|---|"]
    for name, make in scenes():
        scene = make()
        choice = automatic.choose(scene, target_mse=relative_rms_to_mse(predict(scene), 0.05))
        cells = [seconds_to(scene, method, relative) for relative in TARGETS for method in ("walk", "two_way")]
        row = (f"| {name} | {scene.patch_count:,} | {automatic.concentration(scene):.1f} | {choice} | "
               + " | ".join(cells) + " |")
        print(row, flush=True)
        lines.append(row)
    out = ROOT / "benchmarks" / "results" / "concentration.md"
    out.write_text("\n".join(lines) + "\n")
    print("wrote", out)


if __name__ == "__main__":
    main()
