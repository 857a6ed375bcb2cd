"""The gathered direct light's noise per ray: this tree against another commit's.

    python -m benchmarks.direct_strategies --base fd326da [--scenes empty_room cornell fig4_room cube]

Written when the third strategy of the direct light, rays shot from the emitting patches (each
hit a sample of the patch it met, weighted against the shadow and cosine rays by the power
heuristic), was taken out: ``--base fd326da`` is the last commit with it. Both cores gather the
direct light of the same scene for 32 chunks of the two-way iteration's samples (``chunk``
paths a chunk), each chunk from its own seed; reported per core: the rays a sample traced, the
variance of the 32 chunks' mean of R H per patch (relative, over the patches lit above 2% of
the brightest; and the RMS over patches over the mean, squared), and that variance times the
rays: the noise per ray, what the choice is made by. The base commit's core is unpacked as in
``benchmarks.ab``.
"""
from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from benchmarks.ab import base_core, same_scene

RESULTS = Path(__file__).resolve().parent / "results"
CHUNK = {"empty_room": 62_500, "cornell": 62_500, "fig4_room": 500_000, "cube": 62_500}
CHUNKS = 32


def scene_of(name):
    """(PatchScene, measured patches (P,) bool: those that do not emit)."""
    if name == "cube":
        from sample_scenes import cube_enclosure

        scene = cube_enclosure.build(reflectivity=0.5).scene
        return scene, ~scene.emission.any(axis=1)
    from benchmarks import suite
    from benchmarks.methods import core_scene

    spec = suite.SCENES[name]()
    return core_scene(spec), ~(spec.emission > 0).any(axis=1)


def noise(core, scene, measured, chunk):
    """(rays a sample, relative variance per patch, (RMS / mean)^2) of the chunks' mean of R H."""
    tables = core.tables.WalkTables(scene, "finite", 1e-3, "hit")
    gathering = core.first_shot.Gathering(scene, core.two_way.direct_samples(chunk, scene))
    R = scene.reflectivity.T
    out, rays = [], 0
    with tables.numpy_turn:
        for k in range(CHUNKS):
            H, traced, _ = core.first_shot.gather_direct(tables, gathering, np.random.default_rng([k, 11]))
            out.append((R * H).mean(axis=0))
            rays += traced
    out = np.array(out)[:, measured]
    mean, variance = out.mean(axis=0), out.var(axis=0, ddof=1) / CHUNKS
    lit = mean > 0.02 * mean.max()
    return rays / CHUNKS / gathering.samples.sum(), np.mean(variance[lit] / mean[lit] ** 2), variance.mean() / mean.mean() ** 2


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True)
    parser.add_argument("--scenes", nargs="+", default=list(CHUNK))
    args = parser.parse_args(argv)
    import importlib

    new = importlib.import_module("addon.core")
    for module in ("tables", "first_shot", "two_way"):
        importlib.import_module(f"addon.core.{module}")
    with tempfile.TemporaryDirectory() as into:
        base = base_core(args.base, into)
        for module in ("tables", "first_shot", "two_way"):
            importlib.import_module(f"addon_base.core.{module}")
        rows = []
        for name in args.scenes:
            scene, measured = scene_of(name)
            b = noise(base, same_scene(base, scene), measured, CHUNK[name])
            n = noise(new, scene, measured, CHUNK[name])
            rows.append((name, b, n))
            print(name, b, n, flush=True)
    lines = ["# The direct light's noise per ray: with and without rays shot from the emitters", "",
             f"`python -m benchmarks.direct_strategies --base {args.base}`", "",
             __doc__.split("\n\n", 2)[2].strip(), "",
             "| scene | rays a sample, base | now | per-patch variance x rays, base | now | now / base "
             "| (RMS/mean)^2 x rays, base | now | now / base |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for name, (rb, pb, mb), (rn, pn, mn) in rows:
        lines.append(f"| {name} | {rb:.2f} | {rn:.2f} | {pb * rb:.3g} | {pn * rn:.3g} | **{pn * rn / (pb * rb):.2f}** "
                     f"| {mb * rb:.3g} | {mn * rn:.3g} | **{mn * rn / (mb * rb):.2f}** |")
    (RESULTS / "direct_strategies.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
