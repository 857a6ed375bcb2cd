"""Corners that share one evaluation of the direct light (addon/core/display/shared_corners.py): a
flat surface's points one estimate each, which every corner at them reads (one light, no seam of
noise between neighbouring patches); a partition standing on a row of points leaves the corners on
either side their own light."""
import numpy as np
from boxes import rectangles_to_mesh

from addon.core import PatchScene
from addon.core.display import point_direct, smoothing
from addon.core.display.shared_corners import shared_rows
from addon.core.lights.lights import PointLight


def _floor(n=4, side=2.0, extra=()):
    """(origin, u, v) of an n x n floor (z = 0, facing up) of ``side`` m, and ``extra`` rectangles."""
    step = side / n
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    origin = np.stack([i.ravel() * step, j.ravel() * step, np.zeros(n * n)], axis=1)
    u = np.tile([step, 0.0, 0.0], (n * n, 1))
    v = np.tile([0.0, step, 0.0], (n * n, 1))
    for o, a, b in extra:
        origin, u, v = np.vstack([origin, o]), np.vstack([u, a]), np.vstack([v, b])
    return origin, u, v


def _scene(origin, u, v, lamp):
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = len(origin)
    scene = PatchScene(V, T, TP, np.full(P, 0.5), np.zeros(P), lights=[PointLight(np.asarray(lamp, float), np.ones(3))])
    return scene, smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)


def _corner_points(scene, surface):
    """(T,3) each corner's welded point, (T,3,3) its world position."""
    return surface.point, scene.vertices[scene.triangles]


def test_a_flat_floors_points_take_one_evaluation_each_read_by_every_corner_at_them():
    """A 4 x 4 floor under a lamp: 25 points, 64 corners; each point evaluated once (before: once a
    corner, 64), and the corners at a point read the same light."""
    scene, surface = _scene(*_floor(), lamp=(0.9, 1.1, 0.6))
    P = scene.patch_count
    keys = np.unique(surface.point.ravel().astype(np.int64) * P + np.repeat(surface.triangle_patch, 3))
    position = scene.vertices[np.zeros(len(keys), np.int64)]  # (positions matter only for the probes' reach)
    rows, read, _ = shared_rows(surface, scene.geometry, keys // P, keys % P, position, point_direct.INWARD)
    assert len(keys) == 64 and len(rows) == 25
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=2)
    point = surface.point.ravel()
    value = direct.corners[..., 0].ravel()
    for p in np.unique(point):
        assert np.ptp(value[point == p]) == 0.0
    assert value.min() > 0


def test_a_partition_standing_on_a_row_of_points_leaves_each_side_its_own_light():
    """A thin partition (1 m high, no thickness) stands on the floor's points at x = 1, the lamp on
    its west side below its top: the floor's corners there on the west get the lamp's light as
    before (I cos / r^2 a hundredth of the way in), those on the east none. One evaluation shared
    by both sides would give both half."""
    partition = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 2.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    lamp = np.array([0.5, 1.0, 0.6])
    scene, surface = _scene(*_floor(extra=[partition]), lamp=lamp)
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=4)
    corners = scene.vertices[scene.triangles]
    patch = scene.triangle_patch
    on_floor = (patch < 16)[:, None] & np.isclose(corners[..., 0], 1.0) & np.isclose(corners[..., 2], 0.0)
    west = on_floor & (surface.patch_centroid[patch][:, 0] < 1.0)[:, None]
    east = on_floor & ~west
    assert west.sum() >= 6 and east.sum() >= 6
    inward = corners + point_direct.INWARD * (surface.patch_centroid[patch][:, None, :] - corners)
    towards = lamp - inward
    exact = towards[..., 2] / np.linalg.norm(towards, axis=-1) ** 3
    np.testing.assert_allclose(direct.corners[..., 0][west], exact[west], rtol=1e-5)
    assert (direct.corners[..., 0][east] == 0.0).all()
