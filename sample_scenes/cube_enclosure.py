"""Figure 1 of Sbert & Brusi: a cube enclosure with 27 small cubes inside (3 x 3 x 3) and one
whole face of the enclosure as the emitter.

Choices where the paper is silent (written down in sample_scenes/README.md):

* enclosure: the cube [0, 1]^3 m, each face meshed into ``enclosure_divisions`` x
  ``enclosure_divisions`` square patches (default 8 x 8 = 64 per face, 0.125 m patches), normals
  facing into the enclosure;
* small cubes: edge ``cube_edge`` (0.15 m) centred on the 3 x 3 x 3 lattice {0.25, 0.5, 0.75}^3
  (0.1 m gaps between neighbours, 0.175 m to the walls), each face meshed into
  ``cube_divisions`` x ``cube_divisions`` patches (default 1), normals facing out;
* emitter: the whole top face (z = 1, shining down) with emittance ``emittance`` (default 1);
* reflectivity: the same value on every patch, emitter included, so R_ave equals it exactly
  (the paper gives only the average: 0.2, 0.5, 0.8). ``spread`` > 0 instead draws each part's
  reflectivity deterministically around the average and rescales so R_ave is still exact.

The scene is closed: every ray hits a front face, so a finite walk has exactly 1/(1-R) rays on
average when the reflectivity is uniform.
"""
from __future__ import annotations

import numpy as np

from .geometry import MeshBuilder, box_patch_count

LATTICE = (0.25, 0.5, 0.75)


def build(reflectivity=0.5, enclosure_divisions=8, cube_divisions=1, cube_edge=0.15, emittance=1.0,
          spread=0.0):
    if not 0 <= reflectivity < 1:
        raise ValueError("reflectivity must lie in [0, 1)")
    if not 0 < cube_edge < 0.25:
        raise ValueError("cube_edge must lie in (0, 0.25) m so the 27 cubes do not touch")
    m = MeshBuilder()
    n = int(enclosure_divisions)
    # enclosure walls (inward normals); the top face is the emitter
    for face in ("x-", "x+", "y-", "y+", "z-"):
        m.add_box((0, 0, 0), (1, 1, 1), 1.0 / n, "enclosure", reflectivity, faces=(face,), inward=True)
    m.add_box((0, 0, 0), (1, 1, 1), 1.0 / n, "emitter", reflectivity, emission=emittance, faces=("z+",),
              inward=True)
    h = cube_edge / 2
    for i, x in enumerate(LATTICE):
        for j, y in enumerate(LATTICE):
            for k, z in enumerate(LATTICE):
                m.add_box((x - h, y - h, z - h), (x + h, y + h, z + h), cube_edge / cube_divisions,
                          f"cube_{i}{j}{k}", reflectivity)
    sample = m.finish(
        f"fig1_cube_enclosure_r{reflectivity:g}",
        "Sbert & Brusi figure 1: unit cube enclosure, 27 small cubes (3x3x3), whole top face emitting",
        enclosure_divisions=n, cube_divisions=int(cube_divisions), cube_edge=cube_edge,
        emittance=emittance, target_r_ave=reflectivity,
    )
    if spread > 0:
        rng = np.random.default_rng(12345)
        part_r = np.clip(reflectivity * (1 + spread * rng.uniform(-1, 1, len(sample.part_names))), 0.01, 0.95)
        r = part_r[sample.patch_part]
        r *= reflectivity / (np.sum(sample.patch_area * r) / sample.total_area)
        if r.max() >= 1:
            raise ValueError("spread too large for this average reflectivity")
        sample.reflectivity = np.repeat(r[:, None], 3, axis=1)
    assert sample.patch_count == 6 * n * n + 27 * box_patch_count(*(int(cube_divisions),) * 3)
    return sample
