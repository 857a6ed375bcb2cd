"""The display's own finer cells (addon/core/refine/display_cells.py): cells split where a lamp's light
changes across a patch and nowhere it is flat, within the budget; the solve's smooth values
interpolated exactly at the new points; every patch's mean its solved value; a point lamp's hot spot
drawn far closer to the exact light than on the patches' own corners; layers carried linearly."""
import numpy as np
import pytest

from addon.core import PatchScene
from addon.core.display import live_sources, point_direct, smoothing
from addon.core.refine import cell_meshes, display_cells
from addon.core.lights.lights import PointLight, SunLight
from addon.core.mesh.meshing import mesh_patches

SIDE, PATCH = 2.0, 0.5  # a 2 m ceiling of 0.5 m patches (4 x 4)
LAMP = np.array([1.1, 0.95, -0.3])  # 30 cm under it, off its grid's points


def _ceiling(lights):
    """A ceiling facing down (z = 0) meshed into 0.5 m patches, and its PatchScene."""
    vertices = np.array([[0, 0, 0], [0, SIDE, 0], [SIDE, SIDE, 0], [SIDE, 0, 0]], float)
    mesh = mesh_patches(vertices, np.array([4]), np.array([0, 1, 2, 3]), PATCH)
    P = mesh.patch_count
    scene = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(P, 0.5), np.zeros(P), lights=lights)
    assert np.allclose(smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch).patch_normal, [0, 0, -1])
    return mesh, scene


def _exact(points):
    """The point lamp's irradiance I cos / r^2 at ``points`` (...,3) of the ceiling (normal -z), I = 1."""
    towards = LAMP - points
    return np.maximum(-towards[..., 2], 0.0) / np.linalg.norm(towards, axis=-1) ** 3


def _display(mesh, scene, light, **limits):
    """(coarse surface, coarse CornerDirect, refine's answer) with the module's limits changed."""
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=3, light=light)

    def at_points(position, patch, level):
        return point_direct.points_direct(surface, scene, position, patch, seed=11 + level, light=light)

    saved = {name: getattr(display_cells, name) for name in limits}
    try:
        for name, value in limits.items():
            setattr(display_cells, name, value)
        made = display_cells.refine(surface, direct, scene, scene.triangles, [mesh], [True], light, at_points)
    finally:
        for name, value in saved.items():
            setattr(display_cells, name, value)
    return surface, direct, made


def _patch_means_exact(scene, n=64):
    """(P,3) each patch's exact mean irradiance (midpoint rule on n x n cells of it)."""
    out = np.zeros((scene.patch_count, 3))
    corners = scene.vertices[scene.triangles]
    for p in range(scene.patch_count):
        low = corners[scene.triangle_patch == p].reshape(-1, 3).min(axis=0)
        high = corners[scene.triangle_patch == p].reshape(-1, 3).max(axis=0)
        s = (np.arange(n) + 0.5) / n
        x, y = np.meshgrid(low[0] + s * (high[0] - low[0]), low[1] + s * (high[1] - low[1]))
        out[p] = _exact(np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)).mean()
    return out


def _shown_error(vertices, triangles, corners, samples=40):
    """Mean absolute error, over the ceiling, of the display's linear interpolation of ``corners``
    (T,3,3) on ``triangles`` against the exact light, at ``samples`` x ``samples`` points a triangle,
    weighted by area."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    i, j = np.meshgrid(np.arange(samples), np.arange(samples), indexing="ij")
    keep = i + j < samples
    u, v = ((i[keep] + 1 / 3) / samples), ((j[keep] + 1 / 3) / samples)
    w = 1 - u - v
    points = a[:, None] * w[None, :, None] + b[:, None] * u[None, :, None] + c[:, None] * v[None, :, None]
    shown = (corners[:, None, 0, 0] * w + corners[:, None, 1, 0] * u + corners[:, None, 2, 0] * v)
    error = np.abs(shown - _exact(points)).mean(axis=1)
    return float((error * area).sum() / area.sum())


def test_a_hot_spot_splits_cells_near_the_lamp_and_is_drawn_far_closer_to_the_exact_light():
    """A point lamp 30 cm under a ceiling of 50 cm patches: its hot spot is about as wide as a patch.
    The patches' own corners draw it with a large error; the split cells (a budget the size of the hot
    spot), smaller beside the lamp than in the far corner, draw it within a fifth of that. Both keep each patch's
    exact mean (the solved light is here exact, so only the shape inside patches differs)."""
    mesh, scene = _ceiling([PointLight(LAMP, np.ones(3))])
    light = _patch_means_exact(scene)
    surface, direct, made = _display(mesh, scene, light, BUDGET=16.0)  # (the whole ceiling is the hot spot here)
    assert made is not None
    fine_surface, fine_direct, shown = made
    coarse = point_direct.shown(surface, light, direct)
    fine = point_direct.shown(fine_surface, light, fine_direct)
    np.testing.assert_allclose(surface.corner_means(coarse[..., 0].ravel()), light[:, 0], rtol=1e-9)
    np.testing.assert_allclose(fine_surface.corner_means(fine[..., 0].ravel()), light[:, 0], rtol=1e-9)
    before = _shown_error(scene.vertices, scene.triangles, coarse)
    after = _shown_error(shown.vertices, shown.triangles, fine)
    assert after < before / 5, (before, after)
    # split where the light changes: the cells beside the lamp are small, the far corner's patch whole
    polygon_patch = shown.origin[0]
    far = np.argmax(np.linalg.norm(surface.patch_centroid - LAMP * [1, 1, 0], axis=1))
    near = np.argmin(np.linalg.norm(surface.patch_centroid - LAMP * [1, 1, 0], axis=1))
    assert (polygon_patch == far).sum() < (polygon_patch == near).sum() and (polygon_patch == near).sum() >= 16


def test_a_mesh_the_outline_split_made_splits_where_its_light_changes_on_its_shading_triangles_with_no_t_junction(monkeypatch):
    """A ceiling whose patch under the lamp was split as the outline split does round a panel (its
    four cells under the cover; its neighbours' polygons carry the split's midpoints, their core
    triangles do not) is kept as made without ``covered`` (a Detail refinement's mesh); with it, its
    patches split on their shading triangles where the direct light changes, as any mesh's do, the
    ones whose light is even (far from the lamp) whole or halved by a neighbour's balance: every patch keeps its mean,
    the light is drawn closer to the exact light, and every edge inside the ceiling is two
    triangles' (no T-junction, no crack). (Before, only the patches round the outline of a gap
    brighter than the room split: a sun's patch on a floor with a rug on it kept the solve's wide
    patches.)"""
    from addon.core.refine.adaptive import cells_of, patch_mesh, split

    square = np.array([[0, 0, 0], [0, 2 * SIDE, 0], [2 * SIDE, 2 * SIDE, 0], [2 * SIDE, 0, 0]], float)
    cells = cells_of(mesh_patches(square, np.array([4]), np.array([0, 1, 2, 3]), PATCH))  # (8 x 8, facing down)
    under = np.argmin(np.linalg.norm(cells.points[cells.corners].mean(axis=1) - LAMP * [1, 1, 0], axis=1))
    made_cells, parent = split(cells, np.arange(cells.count) == under)
    mesh, _ = patch_mesh(made_cells)
    assert mesh.patch_count == 67 and mesh.face_sizes.max() > 4  # (its neighbours' polygons carry midpoints)
    covered = parent == under  # (one patch a cell, in cell order)
    P = mesh.patch_count
    scene = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(P, 0.5), np.zeros(P),
                       lights=[PointLight(LAMP, np.ones(3))])
    triangles, patch = np.asarray(mesh.shading_triangles), np.asarray(mesh.shading_triangle_patch)
    surface = smoothing.Surface.of(scene.vertices, triangles, patch, P, covered=covered)
    direct = point_direct.corner_direct(surface, scene, triangles, seed=3)
    light = _patch_means_exact(scene)

    def at_points(position, patch_, level):
        return point_direct.points_direct(surface, scene, position, patch_, seed=11 + level)

    monkeypatch.setattr(display_cells, "BUDGET", 16.0)  # (the whole ceiling is the hot spot here)
    assert display_cells.refine(surface, direct, scene, triangles, [mesh], [True], light, at_points) is None
    dark = np.where(covered[:, None], 0.0, light)  # (a gap no brighter than the room: its outline no reason, the hot spot one)
    made = display_cells.refine(surface, direct, scene, triangles, [mesh], [True], dark, at_points, covered=covered)
    assert made is not None and (np.bincount(made[2].origin[0], minlength=mesh.patch_count)[~covered] > 1).sum() >= 16
    made = display_cells.refine(surface, direct, scene, triangles, [mesh], [True], light, at_points, covered=covered)
    assert made is not None
    fine_surface, fine_direct, shown = made
    fine = point_direct.shown(fine_surface, light, fine_direct)
    np.testing.assert_allclose(fine_surface.corner_means(fine[..., 0].ravel()), light[:, 0], rtol=1e-9)
    coarse = point_direct.shown(surface, light, direct)
    polygons = np.bincount(shown.origin[0], minlength=P)
    grey = direct.corners.sum(axis=-1)
    changes = np.zeros(P)
    np.maximum.at(changes, patch, np.ptp(grey, axis=1))
    even = changes < display_cells.CHANGE * np.maximum(light.sum(axis=1), display_cells.FLOOR * light.sum(axis=1).mean())
    far = even & (np.linalg.norm(surface.patch_centroid[:, :2] - LAMP[:2], axis=1) > 2.5)
    assert far.sum() >= 4 and (polygons[far] <= 2).all() and np.median(polygons[far]) == 1, polygons  # (2: a neighbour's balance)
    split_ = (polygons > 1) & ~covered
    assert split_.sum() >= 16, polygons
    rows = np.flatnonzero(split_[shown.triangle_patch])
    after = _shown_error(shown.vertices, shown.triangles[rows], fine[rows])
    before = _shown_error(scene.vertices, triangles[split_[patch]], coarse[split_[patch]])
    assert after < before / 3, (before, after)
    edges = np.sort(shown.triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    key, count = np.unique(edges, axis=0, return_counts=True)
    ends = shown.vertices[key]
    border = np.any([np.all(np.isclose(ends[:, :, a], v), axis=1) for a in (0, 1) for v in (0.0, 2 * SIDE)], axis=0)
    assert (count[~border] == 2).all() and (count[border] == 1).all()


def test_the_new_points_direct_light_is_the_lamps_exact_light():
    """Every corner of the split cells, new points included, gets the point lamp's I cos / r^2 (a
    hundredth of the way to its patch's centre, as every corner)."""
    mesh, scene = _ceiling([PointLight(LAMP, np.ones(3))])
    surface, _, (fine_surface, fine_direct, shown) = _display(mesh, scene, _patch_means_exact(scene))
    points = shown.vertices[shown.triangles]
    inward = points + point_direct.INWARD * (fine_surface.patch_centroid[shown.triangle_patch][:, None] - points)
    # (the mesh's own points where their patches share one evaluation: there, shared_corners')
    coarse = _evaluated(surface, scene)
    for t, c in zip(*np.nonzero(shown.triangles < len(mesh.points))):
        inward[t, c] = coarse[(int(shown.triangle_patch[t]), int(shown.triangles[t, c]))]
    np.testing.assert_allclose(fine_direct.corners[..., 0], _exact(inward), rtol=1e-4)


def _evaluated(surface, scene):
    """{(patch, vertex): where the coarse corner there is evaluated} (``point_direct.corner_direct``)."""
    from addon.core.display.shared_corners import shared_rows

    P = scene.patch_count
    keys, first = np.unique(surface.point.ravel().astype(np.int64) * P + np.repeat(surface.triangle_patch, 3),
                            return_index=True)
    vertex = scene.triangles.ravel()[first]
    position = scene.vertices[vertex]
    rows, read, towards = shared_rows(surface, scene.geometry, keys // P, keys % P, position, point_direct.INWARD)
    at = position[rows] + point_direct.INWARD * (towards - position[rows])
    return {(int(p), int(v)): at[read[k]] for k, (p, v) in enumerate(zip(keys % P, vertex))}


def test_flat_light_splits_nothing():
    """A sun at an angle onto the ceiling's face: the same light everywhere, nothing to split."""
    sun = SunLight(np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0]), np.ones(3))
    mesh, scene = _ceiling([sun])
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=3)
    assert np.ptp(direct.corners[..., 0]) < 1e-6 * direct.corners[..., 0].max() and direct.corners.max() > 0
    assert _display(mesh, scene, direct.means)[2] is None


@pytest.mark.parametrize("budget", [0.5, 1.0, 2.0])
def test_the_split_stays_within_its_budget_of_new_points(budget):
    """New points at most the budget's share of the mesh's points, plus one level's rounding (a quad's
    split makes about NEW_POINTS of them; balancing may split a neighbour with it)."""
    mesh, scene = _ceiling([PointLight(LAMP, np.ones(3))])
    made = _display(mesh, scene, _patch_means_exact(scene), BUDGET=budget)[2]
    assert made is not None
    shown = made[2]
    new = len(shown.vertices) - len(mesh.points)
    assert 0 < new <= budget * len(mesh.points) + 4 * display_cells.NEW_POINTS + 8
    # a patch none of whose cells split nor took a neighbour's point is written as its own quad
    polygons = np.bincount(shown.origin[0], minlength=scene.patch_count)
    whole = np.flatnonzero(polygons == 1)
    assert whole.size and (shown.meshes[0].face_sizes[np.isin(shown.origin[0], whole)] == 4).all()


def test_interpolation_is_exact_for_light_linear_in_each_patch():
    """Coarse corner values linear in position (a different plane per patch) come out at every fine
    corner as that plane's value there: the interpolation is linear within each patch."""
    mesh, scene = _ceiling([PointLight(LAMP, np.ones(3))])
    fine_surface, _, shown = _display(mesh, scene, _patch_means_exact(scene))[2]
    rng = np.random.default_rng(5)
    planes = rng.uniform(0.5, 2.0, (scene.patch_count, 3))

    def linear(points, patch):
        return planes[patch, 0] + planes[patch, 1] * points[..., 0] + planes[patch, 2] * points[..., 1]

    coarse = linear(scene.vertices[scene.triangles], scene.triangle_patch[:, None])[..., None].repeat(3, axis=-1)
    fine = fine_surface.interpolated(coarse)
    expected = linear(shown.vertices[shown.triangles], shown.triangle_patch[:, None])
    np.testing.assert_allclose(fine[..., 0], expected, rtol=1e-12)


def test_layers_at_the_new_polygon_corners_are_interpolated_linearly():
    """A UV map linear over the ceiling, kept at the coarse polygon corners, is the same linear map at
    every polygon corner of the split cells (``corner_weights``)."""
    mesh, scene = _ceiling([PointLight(LAMP, np.ones(3))])
    _, _, shown = _display(mesh, scene, _patch_means_exact(scene))[2]
    uv = mesh.points[mesh.corner_verts][:, :2] * [0.5, 0.25]
    corners, weights = cell_meshes.corner_weights(mesh, shown.meshes[0], shown.origin[0])
    fine_uv = (uv[corners] * weights[..., None]).sum(axis=1)
    np.testing.assert_allclose(fine_uv, shown.meshes[0].points[shown.meshes[0].corner_verts][:, :2] * [0.5, 0.25],
                               atol=1e-12)


def test_a_patch_whose_corners_miss_its_mean_direct_light_splits_and_keeps_its_mean():
    """A sun at an angle lights the ceiling evenly (nothing splits: the corners agree); told that one
    patch's mean direct light is three times what its corners show (a spot's cone on a wall between
    a patch's corners, none of which it reaches), that patch splits (its neighbours at most by the
    balance), the others stay whole, and every patch's mean is still its light."""
    sun = SunLight(np.array([0.3, 0.2, 1.0]) / np.linalg.norm([0.3, 0.2, 1.0]), np.ones(3))
    mesh, scene = _ceiling([sun])
    light = np.full((scene.patch_count, 3), float(sun.direction[2]))
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=3, light=light)

    def at_points(position, patch, level):
        return point_direct.points_direct(surface, scene, position, patch, seed=11 + level, light=light)

    def refined(means, light=light):
        return display_cells.refine(surface, direct, scene, scene.triangles, [mesh], [True], light, at_points, means=means)

    assert refined(None) is None and refined(direct.means) is None  # (the corners show the means: nothing missed)
    lit = 5
    means = direct.means.copy()
    means[lit] *= 3.0
    light = light.copy()
    light[lit] *= 3.0
    made = refined(means, light)
    assert made is not None
    fine_surface, fine_direct, shown = made
    polygons = np.bincount(shown.origin[0], minlength=scene.patch_count)
    assert polygons[lit] >= 4 and (polygons <= 2).sum() >= scene.patch_count - 5, polygons
    fine = point_direct.shown(fine_surface, light, fine_direct)
    np.testing.assert_allclose(fine_surface.corner_means(fine[..., 0].ravel()), light[:, 0], rtol=1e-9)


def test_a_patch_a_box_stands_on_splits_and_its_points_inside_the_box_show_the_coarse_light():
    """A floor of 0.5 m patches with a closed box standing on it, a lamp 15 cm up beside the box's
    corner: the floor patch the box covers a third of (partly buried) splits where the lamp's hot
    spot is (before, such patches were kept whole), every new point inside the box takes its coarse
    triangle's interpolation of the corners (no rays: no dark corner inside the box pulls the
    visible part down), and every patch keeps its mean."""
    floor = mesh_patches(np.array([[0, 0, 0], [SIDE, 0, 0], [SIDE, SIDE, 0], [0, SIDE, 0]], float), np.array([4]),
                         np.array([0, 1, 2, 3]), PATCH)  # (facing up)
    lo, hi = np.array([0.6, 0.6, 0.0]), np.array([1.3, 1.3, 0.4])
    corners = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]])  # (outward)
    box = mesh_patches(corners, np.full(6, 4), quads.ravel(), PATCH)
    V = np.vstack([floor.points, box.points])
    T = np.vstack([floor.triangles, box.triangles + len(floor.points)])
    TP = np.concatenate([floor.triangle_patch, box.triangle_patch + floor.patch_count])
    P = floor.patch_count + box.patch_count
    lamp = np.array([1.45, 1.45, 0.15])
    scene = PatchScene(V, T, TP, np.full(P, 0.5), np.zeros(P), lights=[PointLight(lamp, np.ones(3))])
    g = scene.geometry
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, P)
    corner = np.argmin(np.linalg.norm(surface.patch_centroid - [1.25, 1.25, 0.0], axis=1))
    assert g.buried is not None and corner in g.buried.patch and corner not in g.buried.whole
    light = live_sources.live_means(scene, samples=256, seed=5)
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=3, light=light)

    def at_points(position, patch, level):
        return point_direct.points_direct(surface, scene, position, patch, seed=11 + level, light=light)

    made = display_cells.refine(surface, direct, scene, scene.triangles, [floor, box], [True, True], light, at_points)
    assert made is not None
    fine_surface, fine_direct, shown = made
    assert (shown.origin[0] == corner).sum() >= 4
    fine = point_direct.shown(fine_surface, light, fine_direct)
    np.testing.assert_allclose(fine_surface.corner_means(fine[..., 0].ravel()), light[:, 0], rtol=1e-6)
    # the new points of that patch inside the box's footprint: their coarse triangle's interpolation
    rows = np.flatnonzero(shown.triangle_patch == corner)
    at = shown.vertices[shown.triangles[rows]].reshape(-1, 3)
    value = fine_direct.corners[rows][..., 0].ravel()
    inside = ((at[:, :2] > lo[:2] + 1e-6) & (at[:, :2] < hi[:2] - 1e-6)).all(axis=1) & ~np.isin(
        np.round(at, 9), np.round(scene.vertices, 9)).all(axis=1)
    assert inside.sum() >= 3
    own = np.flatnonzero(scene.triangle_patch == corner)
    expected = []
    for point in at[inside]:
        for t in own:
            a, b, c = scene.vertices[scene.triangles[t]]
            m = np.column_stack([b - a, c - a])[:2]
            w1, w2 = np.linalg.solve(m, (point - a)[:2])
            if min(w1, w2, 1 - w1 - w2) > -1e-9:
                expected.append(direct.corners[t, :, 0] @ [1 - w1 - w2, w1, w2])
                break
    np.testing.assert_allclose(value[inside], expected, rtol=1e-5)
    assert (value[inside] > 0).all()
