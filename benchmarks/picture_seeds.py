"""Per-object brightness over several seeds: the picture benchmark's rooms (``picture.py``: the
product's preview at the panel's defaults, or ``--error``, at ``--preview-samples``) solved with seeds 0..n-1, each
object's mean luminance over the reference's, seed by seed and their mean (one seed's objects
move by 1-2% with the solve's noise: a single round says little about 3%).

    python -m benchmarks.picture_seeds --scenes window_room lamp_room loft --seeds 4

Uses picture.py's cached references (out/picture_cache/, made there or here). Writes
benchmarks/results/picture_seeds.md (``--out``).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks import interior_scene, picture as pic, picture_metrics as pm  # noqa: E402

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])
LEAST_PIXELS = 20  # (as picture.analyse)


def measure(name, seeds, **overrides):
    """(object names, pixels (K,), ratios (seeds, K), (MAE, RMS, seconds) per seed) of one room."""
    from addon.blender_write.results import previous_results

    info = interior_scene.build(name)
    first, second, _ = pic.reference(name, 256)
    ref = 0.5 * (first + second)
    variance = pm.reference_variance(first, second)
    ratios, errors = [], []
    for seed in range(seeds):
        image, solve, shown, _ = pic.product("TEXTURED", seed=seed, **overrides)
        if seed == 0:  # (the same patch layout every seed)
            px = pic.pixel_map(info, previous_results())
            emitters = [info.meshes.index(n) for n in info.emitters]
            mask = pm.surface_mask(px["object_id"], emitters, px["lamp"])
            count = len(info.meshes)
            reference = pm.object_means(ref, px["object_id"], mask, count) @ LUMINANCE
            pixels = pm.object_pixels(px["object_id"], mask, count)
            kept = np.flatnonzero(pixels >= LEAST_PIXELS)
        ratios.append((pm.object_means(image, px["object_id"], mask, count) @ LUMINANCE)[kept] / reference[kept])
        errors.append((pm.relative_mae(image, ref, mask), pm.relative_rms(image, ref, mask, variance), solve + shown))
    return [info.meshes[i] for i in kept], pixels[kept], np.array(ratios), np.array(errors)


def section(name, names, pixels, ratios, errors):
    mean = ratios.mean(axis=0)
    distance = np.abs(mean - 1.0)
    mae, rms, seconds = errors.mean(axis=0)
    lines = [f"## {name}", "", f"{len(ratios)} seeds: the preview's image error {100 * mae:.2f}% mean absolute, "
             f"{100 * rms:.2f}% RMS (the reference's noise out), {seconds:.1f} s a run. Objects' "
             f"mean luminance over the reference's, mean over the seeds: pixel-weighted distance from 1 "
             f"{(distance * pixels).sum() / pixels.sum():.3f}, largest {distance.max():.3f}, "
             f"{int((distance > 0.03).sum())} of {len(names)} beyond 3%.", "",
             "| object | pixels | mean | seeds |", "|---|---|---|---|"]
    for k, n in enumerate(names):
        lines.append(f"| {n} | {pixels[k]:,} | {mean[k]:.3f} | {' '.join(f'{v:.3f}' for v in ratios[:, k])} |")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(interior_scene.SCENES), choices=list(interior_scene.SCENES))
    parser.add_argument("--seeds", type=int, default=4)
    parser.add_argument("--set", nargs="*", default=[], metavar="NAME=VALUE", help="the product's settings by name")
    parser.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "picture_seeds.md")
    parser.add_argument("--error", type=float, default=pic.TARGET_ERROR, help="the product's error target, percent")
    parser.add_argument("--preview-samples", type=int, default=pic.PREVIEW_SAMPLES, help="the preview's samples")
    args = parser.parse_args(argv)
    pic.TARGET_ERROR, pic.PREVIEW_SAMPLES = args.error, args.preview_samples
    overrides = dict(item.split("=", 1) for item in args.set)
    command = "python -m benchmarks.picture_seeds " + " ".join(argv if argv is not None else sys.argv[1:])
    what = __doc__.split("\n\n")[0].replace("\n", " ").split(": ", 1)[1]
    parts = ["# Per-object brightness over seeds", "", f"`{command.strip()}`: {what}", ""]
    for name in args.scenes:
        parts.append(section(name, *measure(name, args.seeds, **overrides)))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(parts))
    print(args.out.read_text())


if __name__ == "__main__":
    main()
