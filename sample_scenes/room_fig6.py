"""Figure 6 of Sbert & Brusi: a coarsely meshed room of 2,200 patches with one small area
light, floor reflectivity 0.3, R_ave = 0.58.

From the paper: each wall meshed into 200 square patches, ceiling and floor into 400 each,
about 2200 patches, one small area light, the floor's reflectivity 0.3 and R_ave 0.58.
Everything else is our choice (sample_scenes/README.md):

* room 10 x 10 x 5 m (x, y horizontal, z up), shell patches 0.5 m: walls 20 x 10, floor and
  ceiling 20 x 20; normals into the room;
* one light panel 0.5 x 0.5 m (2 x 2 patches of 0.25 m) centred under the ceiling, hanging
  1 cm below it and shining down (its back absorbs); emittance 1 by default;
* furniture: axis-aligned boxes meshed into 0.25 m patches, normals out, no face resting on
  the floor, at least 25 cm from the walls: a table with four legs, a bed, a wardrobe, a
  bookshelf, and a cabinet whose size is solved for so the total is exactly 2,200 patches;
* reflectivities (grey): floor 0.3, ceiling 0.8, furniture 0.5, light 0; the four walls share
  the one value (about 0.62) that makes the area-weighted R_ave exactly 0.58.
* ``paper_units=True`` scales the emittance so that formula (2)'s expected MSE for 200,000
  finite paths is the paper's 0.00011 (table 4).
"""
from __future__ import annotations

import itertools

import numpy as np

from .geometry import MeshBuilder, box_patch_count, solve_for_reflectivity
from .room_fig4 import _scale_to_paper

ROOM = (10.0, 10.0, 5.0)
SHELL_PATCH = 0.5
FURNITURE_PATCH = 0.25
LIGHT_SIZE = 0.5
LIGHT_DIVISIONS = 2
LIGHT_DROP = 0.01
TARGET_PATCHES = 2200
R_AVE = 0.58
FLOOR_R = 0.3
NO_BOTTOM = ("x-", "x+", "y-", "y+", "z+")
SIDES = ("x-", "x+", "y-", "y+")

FURNITURE = [
    ("table", (4.0, 4.0, 0.5), (6.0, 5.0, 0.75), None),
    ("table", (4.0, 4.0, 0.0), (4.25, 4.25, 0.5), SIDES),
    ("table", (5.75, 4.0, 0.0), (6.0, 4.25, 0.5), SIDES),
    ("table", (4.0, 4.75, 0.0), (4.25, 5.0, 0.5), SIDES),
    ("table", (5.75, 4.75, 0.0), (6.0, 5.0, 0.5), SIDES),
    ("bed", (6.5, 8.25, 0.0), (8.5, 9.75, 0.5), NO_BOTTOM),
    ("wardrobe", (9.25, 3.0, 0.0), (9.75, 4.5, 2.0), NO_BOTTOM),
    ("bookshelf", (0.25, 1.0, 0.0), (0.75, 3.0, 2.0), NO_BOTTOM),
]
CABINET_CORNER = (1.0, 8.75, 0.0)  # against the y = 10 wall, 25 cm gap
FURNITURE_R = 0.5


def _cabinet_units(remainder):
    best = None
    for nx, ny, nz in itertools.product(range(1, 17), range(1, 5), range(1, 13)):
        if box_patch_count(nx, ny, nz, NO_BOTTOM) == remainder:
            key = (max(nx, ny, nz) - min(nx, ny, nz), nx, ny, nz)
            if best is None or key < best:
                best = key
    if best is None:
        raise ValueError(f"no cabinet of at most 16 x 4 x 12 patch units has exactly {remainder} patches")
    return best[1:]


def build(paper_units=False, emittance=None):
    m = MeshBuilder()
    s = SHELL_PATCH
    for face, part in (("x-", "wall_x0"), ("x+", "wall_x10"), ("y-", "wall_y0"), ("y+", "wall_y10")):
        m.add_box((0, 0, 0), ROOM, s, part, 0.5, faces=(face,), inward=True)
    m.add_box((0, 0, 0), ROOM, s, "floor", FLOOR_R, faces=("z-",), inward=True)
    m.add_box((0, 0, 0), ROOM, s, "ceiling", 0.8, faces=("z+",), inward=True)
    e = 1.0 if emittance is None else float(emittance)
    h = LIGHT_SIZE / 2
    cx, cy, z = ROOM[0] / 2, ROOM[1] / 2, ROOM[2] - LIGHT_DROP
    m.add_grid((cx - h, cy - h, z), (0, LIGHT_SIZE, 0), (LIGHT_SIZE, 0, 0), LIGHT_DIVISIONS, LIGHT_DIVISIONS,
               "light", 0.0, e)
    for part, lo, hi, faces in FURNITURE:
        m.add_box(lo, hi, FURNITURE_PATCH, part, FURNITURE_R, faces=faces or ("x-", "x+", "y-", "y+", "z-", "z+"))
    nx, ny, nz = _cabinet_units(TARGET_PATCHES - m.patch_count)
    lo = np.array(CABINET_CORNER)
    hi = lo + FURNITURE_PATCH * np.array([nx, ny, nz])
    m.add_box(lo, hi, FURNITURE_PATCH, "cabinet", FURNITURE_R, faces=NO_BOTTOM)
    sample = m.finish(
        "fig6_room", "Sbert & Brusi figure 6: coarse 10x10x5 m room, one small ceiling light, 2,200 patches",
        room=ROOM, shell_patch=s, furniture_patch=FURNITURE_PATCH, light_size=LIGHT_SIZE,
        cabinet_units=(nx, ny, nz), cabinet_lo=tuple(lo), cabinet_hi=tuple(hi),
    )
    walls = np.isin(sample.patch_part, [sample.part_names.index(p) for p in ("wall_x0", "wall_x10", "wall_y0", "wall_y10")])
    rw = solve_for_reflectivity(sample.patch_area, sample.reflectivity, walls, R_AVE)
    sample.reflectivity[walls] = rw
    sample.metadata["wall_reflectivity"] = rw
    if paper_units and emittance is None:
        _scale_to_paper(sample, finite_paths=200_000, expected_mse=0.00011)
    sample.metadata["emittance"] = float(sample.emission.max())
    assert sample.patch_count == TARGET_PATCHES, sample.patch_count
    return sample
