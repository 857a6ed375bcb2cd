"""A coloured Cornell-style box for artists: red left wall, green right wall, white floor,
ceiling and back wall, a square ceiling light and two white blocks.

All choices are ours (sample_scenes/README.md):

* box [0, 1]^3 m (x left to right, y front to back, z up); the camera looks along +y from the
  open front (y < 0). Walls meshed into ``divisions`` x ``divisions`` square patches (default
  20 x 20, 5 cm), normals into the box. ``closed=True`` adds a white front wall (then no ray
  escapes; by default the front is open like the classic box, and rays leaving it are lost);
* light: a 0.3 x 0.3 m panel centred 1 cm under the ceiling, shining down, emittance
  RGB (17, 12, 4) (the classic box's warm light), reflectivity 0.78;
* short block 0.3 x 0.3 x 0.3 m at x 0.55-0.85, y 0.15-0.45; tall block 0.3 x 0.3 x 0.6 m at
  x 0.15-0.45, y 0.50-0.80, both axis-aligned (the classic box rotates them), no face on the
  floor, same patch size as the walls;
* reflectivities RGB: white (0.73, 0.73, 0.73), red (0.63, 0.065, 0.05), green (0.14, 0.45, 0.091).
"""
from __future__ import annotations

import math

from .geometry import MeshBuilder

WHITE = (0.73, 0.73, 0.73)
RED = (0.63, 0.065, 0.05)
GREEN = (0.14, 0.45, 0.091)
LIGHT_EMITTANCE = (17.0, 12.0, 4.0)
LIGHT_REFLECTIVITY = (0.78, 0.78, 0.78)
NO_BOTTOM = ("x-", "x+", "y-", "y+", "z+")


def build(divisions=20, closed=False, emittance=LIGHT_EMITTANCE):
    n = int(divisions)
    if n < 10 or n % 10:
        raise ValueError("divisions must be a multiple of 10 so the 0.3 m light and blocks are whole patches")
    p = 1.0 / n
    m = MeshBuilder()
    box = ((0, 0, 0), (1, 1, 1))
    m.add_box(*box, p, "left_wall_red", RED, faces=("x-",), inward=True)
    m.add_box(*box, p, "right_wall_green", GREEN, faces=("x+",), inward=True)
    m.add_box(*box, p, "back_wall", WHITE, faces=("y+",), inward=True)
    m.add_box(*box, p, "floor", WHITE, faces=("z-",), inward=True)
    m.add_box(*box, p, "ceiling", WHITE, faces=("z+",), inward=True)
    if closed:
        m.add_box(*box, p, "front_wall", WHITE, faces=("y-",), inward=True)
    k = int(round(0.3 / p))
    m.add_grid((0.35, 0.35, 0.99), (0, 0.3, 0), (0.3, 0, 0), k, k, "light", LIGHT_REFLECTIVITY, emittance)
    m.add_box((0.55, 0.15, 0.0), (0.85, 0.45, 0.3), p, "short_block", WHITE, faces=NO_BOTTOM)
    m.add_box((0.15, 0.50, 0.0), (0.45, 0.80, 0.6), p, "tall_block", WHITE, faces=NO_BOTTOM)
    return m.finish(
        "cornell_box" + ("_closed" if closed else ""),
        "Coloured Cornell-style box: red/green side walls, ceiling light, two axis-aligned blocks",
        divisions=n, closed=closed, emittance=tuple(emittance),
        # The classic view, from outside the open front: the whole box, both blocks and the light
        # (a square frame, 35 mm: the front opening just fills it). Closed, the box has none.
        camera=None if closed else {"location": (0.5, -1.06, 0.5), "rotation": (math.pi / 2, 0.0, 0.0),
                                    "lens": 35.0, "resolution": (512, 512)},
        # The main job's picture without tile noise (the 5% default leaves low-frequency mottling on
        # the walls; at 2% the preview's bounce averages it away); the command line's --error still decides.
        settings=None if closed else {"target_error": 2.0},
    )
