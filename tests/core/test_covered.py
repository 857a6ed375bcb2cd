"""Patches no camera sees (addon/core/display/covered.py) and the smooth colours that leave them out:
the ceiling behind a light panel hung under it and the floor under a box with no bottom are
hidden, the floor under a one-sided table top and the rest of the room are not; a hidden black
patch pulls no visible neighbour's corner down (no dark rim, no ripples around a panel)."""
import numpy as np
from boxes import CEILING, FLOOR, box_rectangles, rectangles_to_mesh
from overlap_boxes import solid_box

from addon.core import PatchScene
from addon.core.display import smoothing
from addon.core.display.covered import hidden_patches


def _grid(origin, u, v, n):
    """n x n rectangles of the rectangle (origin, u, v)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    o = np.asarray(origin, float) + np.outer(i.ravel(), np.asarray(u, float) / n) + np.outer(j.ravel(), np.asarray(v, float) / n)
    return o, np.tile(np.asarray(u, float) / n, (n * n, 1)), np.tile(np.asarray(v, float) / n, (n * n, 1))


def _room():
    """A unit room of 0.1 m patches (inward faces), a 0.3 m light panel 1 cm under the ceiling
    facing down, a box with no bottom on the floor, a one-sided table top 0.4 m up facing up.
    (scene, face of the room's patches (-1 elsewhere), patch centres)."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=10)
    parts = [(origin, u, v)]
    panel = _grid((0.3, 0.3, 0.99), (0, 0.3, 0), (0.3, 0, 0), 3)
    o, bu, bv, box_face = solid_box((0.6, 0.1, 0.0), (0.9, 0.4, 0.3), [3, 3, 3])
    bottomless = box_face != 4  # (the face below, z = 0, left out)
    table = _grid((0.1, 0.6, 0.4), (0.3, 0, 0), (0, 0.3, 0), 3)
    parts += [panel, (o[bottomless], bu[bottomless], bv[bottomless]), table]
    origin, u, v = (np.concatenate([p[k] for p in parts]) for k in range(3))
    V, T, TP = rectangles_to_mesh(origin, u, v)
    emission = np.zeros(len(origin))
    emission[len(face):len(face) + 9] = 1.0
    scene = PatchScene(V, T, TP, np.full(len(origin), 0.5), emission)
    room_face = np.concatenate([face, np.full(len(origin) - len(face), -1)])
    return scene, room_face, origin + (u + v) / 2


def test_the_ceiling_behind_a_panel_and_the_floor_under_a_bottomless_box_are_hidden_and_nothing_else():
    scene, face, centre = _room()
    hidden = hidden_patches(scene.geometry)
    x, y = centre[:, 0], centre[:, 1]
    behind_panel = (face == CEILING) & (x > 0.3) & (x < 0.6) & (y > 0.3) & (y < 0.6)
    under_box = (face == FLOOR) & (x > 0.6) & (x < 0.9) & (y > 0.1) & (y < 0.4)
    under_table = (face == FLOOR) & (x > 0.1) & (x < 0.4) & (y > 0.6) & (y < 0.9)
    assert behind_panel.sum() == 9 and under_box.sum() == 9 and under_table.sum() == 9
    np.testing.assert_array_equal(np.flatnonzero(hidden), np.flatnonzero(behind_panel | under_box))


def test_a_hidden_black_patch_pulls_no_visible_neighbours_corner_down():
    """Light even (1) on the ceiling but behind the panel (0, hidden): with the hidden patches
    left out every visible ceiling corner shows 1 and each patch's mean is kept; counted in, the
    corners around the panel come out dark and the patches beyond them bright (ripples)."""
    scene, face, _ = _room()
    hidden = hidden_patches(scene.geometry)
    values = np.where(hidden, 0.0, 1.0)[:, None].repeat(3, axis=1)
    ceiling = np.flatnonzero(np.isin(scene.triangle_patch, np.flatnonzero((face == CEILING) & ~hidden)))
    args = (scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    left_out = smoothing.Surface.of(*args, hidden=hidden)
    shown = left_out.corner_values(values)
    np.testing.assert_allclose(shown[ceiling], 1.0, rtol=1e-12)
    means = np.stack([left_out.corner_means(np.ascontiguousarray(shown[..., c]).ravel()) for c in range(3)], axis=1)
    np.testing.assert_allclose(means, values, atol=1e-12)
    counted = smoothing.Surface.of(*args).corner_values(values)
    assert counted[ceiling].min() < 0.8 and counted[ceiling].max() > 1.1
