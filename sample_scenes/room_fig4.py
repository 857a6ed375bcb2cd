"""Figure 4 of Sbert & Brusi: a furnished room of 66,572 patches, R_ave = 0.5.

From the paper: each wall meshed into 5000 square patches, ceiling and floor into 10000 each,
each light source into 225 patches, 66,572 patches in all, average reflectivity 0.5.
Everything else is our choice (sample_scenes/README.md):

* room 10 x 10 x 5 m (x, y horizontal, z up), shell patches 0.1 m: walls 100 x 50, floor and
  ceiling 100 x 100; normals into the room;
* four light panels 1.5 x 1.5 m (15 x 15 patches of 0.1 m) centred at (2.5|7.5, 2.5|7.5),
  hanging 1 cm below the ceiling and shining down (their backs, facing the ceiling, absorb);
* furniture: axis-aligned boxes meshed into 0.05 m patches, normals out, no face on the floor
  (that face would be unreachable; stacked pieces likewise drop the covered face), kept at least 5 cm from the walls so no two surfaces
  coincide: a dining table with four legs, a bed, a sofa (seat + back), a wardrobe, two
  bookshelves, a desk, a chest of drawers, two armchairs (seat + back), and a sideboard against the y = 10 wall whose
  size is solved for so the total is exactly 66,572 patches;
* reflectivities (grey): floor 0.4, ceiling 0.75, furniture 0.45 (table, shelves, desk),
  0.35 (bed, sofa, armchairs), 0.55 (wardrobe, chest, sideboard), light panels 0; the four
  walls share the one value (about 0.5) that makes the area-weighted R_ave exactly 0.5;
* emittance of the lights: 1 by default.  ``paper_units=True`` instead scales it so that
  formula (2)'s expected MSE for 3,600,000 finite paths is the paper's 0.00045 (table 3),
  which puts our absolute errors on the paper's scale.
"""
from __future__ import annotations

import itertools

import numpy as np

from .geometry import MeshBuilder, box_patch_count, solve_for_reflectivity

ROOM = (10.0, 10.0, 5.0)
SHELL_PATCH = 0.1
FURNITURE_PATCH = 0.05
LIGHT_CENTRES = ((2.5, 2.5), (7.5, 2.5), (2.5, 7.5), (7.5, 7.5))
LIGHT_SIZE = 1.5
LIGHT_DROP = 0.01
TARGET_PATCHES = 66572
R_AVE = 0.5
NO_BOTTOM = ("x-", "x+", "y-", "y+", "z+")

# (part, lo, hi, reflectivity, faces): furniture boxes in metres, multiples of 0.05 m
FURNITURE = [
    # dining table: 2.0 x 1.0 top, 5 cm thick at 0.70-0.75 m, four 10 cm legs
    ("table_top", (1.5, 5.0, 0.70), (3.5, 6.0, 0.75), 0.45, None),
    ("table_leg", (1.55, 5.05, 0.0), (1.65, 5.15, 0.70), 0.45, ("x-", "x+", "y-", "y+")),
    ("table_leg", (3.35, 5.05, 0.0), (3.45, 5.15, 0.70), 0.45, ("x-", "x+", "y-", "y+")),
    ("table_leg", (1.55, 5.85, 0.0), (1.65, 5.95, 0.70), 0.45, ("x-", "x+", "y-", "y+")),
    ("table_leg", (3.35, 5.85, 0.0), (3.45, 5.95, 0.70), 0.45, ("x-", "x+", "y-", "y+")),
    # bed against the y=10 wall (5 cm gap)
    ("bed", (6.5, 7.9, 0.0), (8.1, 9.95, 0.5), 0.35, NO_BOTTOM),
    # sofa: seat and back
    ("sofa", (4.0, 0.1, 0.0), (6.0, 1.2, 0.45), 0.35, NO_BOTTOM),
    ("sofa", (4.0, 0.1, 0.45), (6.0, 0.3, 0.9), 0.35, NO_BOTTOM),
    # wardrobe against the x=10 wall
    ("wardrobe", (9.3, 4.0, 0.0), (9.95, 5.2, 2.0), 0.55, NO_BOTTOM),
    # two bookshelves against the x=0 wall
    ("bookshelf", (0.05, 1.0, 0.0), (0.45, 3.0, 2.0), 0.45, NO_BOTTOM),
    ("bookshelf", (0.05, 7.0, 0.0), (0.45, 8.5, 1.8), 0.45, NO_BOTTOM),
    # desk with a closed side block
    ("desk", (0.6, 8.9, 0.70), (2.2, 9.6, 0.75), 0.45, None),
    ("desk", (0.6, 8.9, 0.0), (1.0, 9.6, 0.70), 0.45, ("x-", "x+", "y-", "y+")),
    # chest of drawers
    ("chest", (9.35, 1.0, 0.0), (9.85, 2.2, 1.0), 0.55, NO_BOTTOM),
    # two armchairs
    ("armchair", (6.5, 1.3, 0.0), (7.3, 2.3, 0.45), 0.35, NO_BOTTOM),
    ("armchair", (6.5, 1.3, 0.45), (7.3, 1.5, 0.85), 0.35, NO_BOTTOM),
    ("armchair", (2.7, 1.3, 0.0), (3.5, 2.3, 0.45), 0.35, NO_BOTTOM),
    ("armchair", (2.7, 1.3, 0.45), (3.5, 1.5, 0.85), 0.35, NO_BOTTOM),
]
# the sideboard fills the remainder: nx x ny x nz patch units (no bottom) at this corner
SIDEBOARD_CORNER = (5.0, 9.4, 0.0)
SIDEBOARD_R = 0.55


def _box_units(lo, hi):
    return [int(round((h - l) / FURNITURE_PATCH)) for l, h in zip(lo, hi)]


def _sideboard_units(remainder):
    """Smallest-surface-area-first search for a box (no bottom) with exactly ``remainder`` patches."""
    best = None
    for nx, ny, nz in itertools.product(range(4, 29), range(4, 12), range(4, 41)):
        if box_patch_count(nx, ny, nz, NO_BOTTOM) == remainder:
            key = (max(nx, ny, nz) - min(nx, ny, nz), nx, ny, nz)  # as cubic as possible
            if best is None or key < best:
                best = key
    if best is None:
        raise ValueError(f"no sideboard of at most 28 x 11 x 40 patch units (fits between desk and bed) has exactly {remainder} patches")
    return best[1:]


def build(paper_units=False, emittance=None):
    m = MeshBuilder()
    X, Y, Z = ROOM
    s = SHELL_PATCH
    walls_r = 0.5  # placeholder, solved below
    for face, part in (("x-", "wall_x0"), ("x+", "wall_x10"), ("y-", "wall_y0"), ("y+", "wall_y10")):
        m.add_box((0, 0, 0), ROOM, s, part, walls_r, faces=(face,), inward=True)
    m.add_box((0, 0, 0), ROOM, s, "floor", 0.4, faces=("z-",), inward=True)
    m.add_box((0, 0, 0), ROOM, s, "ceiling", 0.75, faces=("z+",), inward=True)
    e = 1.0 if emittance is None else float(emittance)
    h = LIGHT_SIZE / 2
    zl = Z - LIGHT_DROP
    for k, (cx, cy) in enumerate(LIGHT_CENTRES):
        # a single downward-facing panel: u = y, v = x gives normal y x x = -z
        m.add_grid((cx - h, cy - h, zl), (0, LIGHT_SIZE, 0), (LIGHT_SIZE, 0, 0), 15, 15, f"light_{k}", 0.0, e)
    for part, lo, hi, r, faces in FURNITURE:
        m.add_box(lo, hi, FURNITURE_PATCH, part, r, faces=faces or ("x-", "x+", "y-", "y+", "z-", "z+"))
    remainder = TARGET_PATCHES - m.patch_count
    nx, ny, nz = _sideboard_units(remainder)
    lo = np.array(SIDEBOARD_CORNER)
    hi = lo + FURNITURE_PATCH * np.array([nx, ny, nz])
    m.add_box(lo, hi, FURNITURE_PATCH, "sideboard", SIDEBOARD_R, faces=NO_BOTTOM)
    sample = m.finish(
        "fig4_room", "Sbert & Brusi figure 4: furnished 10x10x5 m room, 4 ceiling panels, 66,572 patches",
        room=ROOM, shell_patch=s, furniture_patch=FURNITURE_PATCH, light_size=LIGHT_SIZE,
        light_centres=LIGHT_CENTRES, sideboard_units=(nx, ny, nz), sideboard_lo=tuple(lo), sideboard_hi=tuple(hi),
    )
    walls = np.isin(sample.patch_part, [sample.part_names.index(p) for p in ("wall_x0", "wall_x10", "wall_y0", "wall_y10")])
    rw = solve_for_reflectivity(sample.patch_area, sample.reflectivity, walls, R_AVE)
    sample.reflectivity[walls] = rw
    sample.metadata["wall_reflectivity"] = rw
    if paper_units and emittance is None:
        _scale_to_paper(sample, finite_paths=3_600_000, expected_mse=0.00045)
    sample.metadata["emittance"] = float(sample.emission.max())
    assert sample.patch_count == TARGET_PATCHES, sample.patch_count
    return sample


def _scale_to_paper(sample, finite_paths, expected_mse):
    """Scale the emission so that formula (2) gives ``expected_mse`` for ``finite_paths`` paths."""
    A_T = sample.total_area
    A_ave = A_T / sample.patch_count
    R = sample.r_ave
    per_unit_power2 = 1.0 / (A_T * A_ave) * R**2 / (1 - R)
    phi = np.sqrt(expected_mse * finite_paths / per_unit_power2)
    sample.emission *= phi / sample.total_power
    sample.metadata["paper_units"] = True
