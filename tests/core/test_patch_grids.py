"""Patches merged back into grids (addon/core/scene/patch_grids.py): the ray tracer's scene for walks
leaving from random points. A ray must score on the patch whose triangles it would have hit."""
import numpy as np
import pytest
from boxes import box_rectangles, box_scene, rays_to_triangle_points, rectangles_to_mesh

from addon.core.scene import patch_grids as PG
from addon.core.methods.tables import WalkTables
from addon.core.mesh.frames import parallelogram_corners
from addon.core.scene.geometry_build import build_geometry


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q


def _geometry(origin, u, v, rotation=None):
    V, T, TP = rectangles_to_mesh(origin, u, v)
    if rotation is not None:
        V = V @ rotation.T
    return build_geometry(V, T, TP, origin.shape[0])


def _plane_grid(n_a, n_b, keep=None, column_shift=None):
    """An n_a x n_b grid of unit-square patches in the plane z = 0 (normal +z), those with
    ``keep`` True; ``column_shift`` = (k, d) moves the line x = k by d (patches k-1 and k then
    differ in width). Returns (origin, u, v, cell (i, j) of each patch)."""
    x = np.arange(n_a + 1, dtype=np.float64)
    if column_shift is not None:
        x[column_shift[0]] += column_shift[1]
    i, j = np.meshgrid(np.arange(n_a), np.arange(n_b), indexing="ij")
    i, j = i.ravel(), j.ravel()
    if keep is not None:
        i, j = i[keep.ravel()], j[keep.ravel()]
    origin = np.column_stack([x[i], j.astype(float), np.zeros(i.size)])
    u = np.column_stack([x[i + 1] - x[i], np.zeros(i.size), np.zeros(i.size)])
    v = np.tile([0.0, 1.0, 0.0], (i.size, 1))
    return origin, u, v, np.column_stack([i, j])


def _grids_of(g):
    return PG.patch_grids(g)


def _both(g, grids, o, d):
    """The patch each ray hits by the patches' triangles and by the grids (-1: a miss)."""
    hit = g.tracer.first_hit(o, d)
    by_triangles = np.where(hit >= 0, g.triangle_patch[np.maximum(hit, 0)], -1)
    triangle, u, v, _, _ = grids.tracer.first_hit_barycentric(o, d)
    return by_triangles, grids.hit_patches(triangle, u, v)


def _down_onto(points_world, g):
    """Rays straight down (-z) onto world points of the plane z = 0, in unit space."""
    above = points_world + [0.0, 0.0, 1.0]
    o = ((above - g.centre) / g.diagonal).astype(np.float32)
    d = np.tile(np.float32([0.0, 0.0, -1.0]), (len(o), 1))
    return o, d


def test_a_turned_box_of_patches_is_traced_as_its_six_faces():
    """A box of 6 x 7 x 7 patches turned off the axes: 6 rectangles, 12 triangles, and every
    patch in exactly one cell."""
    origin, u, v, _ = box_rectangles((1.0, 1.3, 0.8), n=7)
    g = _geometry(origin, u, v, _rotation(3))
    grids = _grids_of(g)
    assert grids.rectangles == 6 and grids.triangle_count == 12
    assert grids.cell_patch[-1] == -1
    np.testing.assert_array_equal(np.sort(grids.cell_patch[:-1]), np.arange(g.patch_count))


def test_rays_score_on_the_patch_whose_triangles_they_hit():
    """Rays from inside a turned box to points of its triangles, half of them on or next to an
    edge (down to 0): the grids give every ray the patch its triangles give it, except rays
    that end within float32's rounding of a side the patch shares with its neighbour."""
    origin, u, v, _ = box_rectangles((1.0, 1.0, 1.0), n=6)
    g = _geometry(origin - 0.5, u, v, _rotation(5))
    grids = _grids_of(g)
    assert grids.rectangles == 6
    n = 200_000
    o, d, bary, _ = rays_to_triangle_points(g, np.random.default_rng(8), n, powers=(3, 13))
    by_triangles, by_grids = _both(g, grids, o, d)
    assert (by_triangles >= 0).all() and (by_grids >= 0).all()  # a closed box
    # Where they differ, the target lies on a side of its triangle (to within about 10^-6 of
    # the unit-space scene: a fifth of the targets lie exactly on one, where either patch is
    # right).
    differ = np.flatnonzero(by_triangles != by_grids)
    near_side = bary.min(axis=1) < 1e-5  # (the triangles' altitudes are about 0.07)
    assert differ.size > 0 and near_side[differ].all()
    assert (by_triangles[~near_side] == by_grids[~near_side]).all()
    assert (~near_side).sum() > n // 2


@pytest.mark.parametrize("seed", [0, 1])
def test_holes_and_ragged_edges_are_covered_by_rectangles_of_the_patches_alone(seed):
    """A 9 x 7 grid with a third of its patches missing at random: the rectangles cover the
    patches that are there and nothing else. Rays down onto every cell's inside hit the
    patch there, or miss where there is none."""
    rng = np.random.default_rng(seed)
    keep = rng.random((9, 7)) < 0.67
    origin, u, v, cell = _plane_grid(9, 7, keep)
    g = _geometry(origin, u, v)
    grids = _grids_of(g)
    assert grids is not None and grids.rectangles < g.patch_count // 2
    # 30 points inside every cell (at least 1% of a cell from its sides).
    i, j = np.meshgrid(np.arange(9), np.arange(7), indexing="ij")
    k = np.repeat(np.column_stack([i.ravel(), j.ravel()]), 30, axis=0)
    points = np.column_stack([k + rng.uniform(0.01, 0.99, k.shape), np.zeros(len(k))])
    by_triangles, by_grids = _both(g, grids, *_down_onto(points, g))
    np.testing.assert_array_equal(by_grids, by_triangles)
    present = keep[k[:, 0], k[:, 1]]
    assert (by_grids[~present] == -1).all() and (by_grids[present] >= 0).all()


def test_an_uneven_grid_is_traced_as_its_patches():
    """One line of a 6 x 5 grid moved by 5e-7 of the grid's size: the patches still group as
    one lattice (their edges agree to within GRID_QUANTUM), but their corners lie off the even
    subdivision by more than CORNER_TOLERANCE, so the rectangle is refused and the patches
    keep their triangles. With the check switched off the grid is one rectangle, and rays
    between the moved line and where the even subdivision puts it score on the wrong patch."""
    diagonal = np.hypot(6, 5)
    shift = 5e-7 * diagonal
    origin, u, v, cell = _plane_grid(6, 5, column_shift=(3, shift))
    g = _geometry(origin, u, v)
    _, _, (p, s1, s2, _) = parallelogram_corners(g.triangle_corners, g.patch_first_triangle, g.patch_triangle_count)
    assert np.unique(PG._groups(p, s1 - p, s2 - p, g.patch_normal)).size == 1  # the corner check tells them apart
    assert _grids_of(g) is None  # every patch alone: nothing saved
    saved = PG.CORNER_TOLERANCE
    try:
        PG.CORNER_TOLERANCE = np.inf
        unchecked = _grids_of(g)
    finally:
        PG.CORNER_TOLERANCE = saved
    assert unchecked.rectangles == 1
    y = np.random.default_rng(2).uniform(0.1, 4.9, 200)
    points = np.column_stack([np.full(200, 3 + shift / 2), y, np.zeros(200)])
    by_triangles, by_unchecked = _both(g, unchecked, *_down_onto(points, g))
    assert (by_triangles == np.flatnonzero((cell[:, 0] == 2) & (cell[:, 1] == 0))[0] + y.astype(int)).all()
    assert (by_unchecked != by_triangles).sum() > 190


def test_cells_two_patches_share_are_rectangles_of_their_own():
    """Two patches on one cell (two faces in one place): each is its own rectangle; the rest of
    the group still joins into rectangles."""
    I = np.array([0, 0, 1, 1, 1, 0])
    J = np.array([0, 1, 0, 1, 1, 2])
    group = np.zeros(6, dtype=np.int64)
    rect = PG._rectangles(group, I, J)
    n_cells = rect.n_a * rect.n_b
    assert n_cells.sum() == 6
    shared = rect.of_cell[[3, 4]]
    assert shared[0] != shared[1] and (n_cells[shared] == 1).all()
    # cells (0,0), (0,1), (1,0): a run of 2 and a run of 1, (0,2) joins the first row's run
    assert np.sort(n_cells).tolist() == [1, 1, 1, 3]
    np.testing.assert_array_equal(np.sort(rect.cell), np.arange(6))


def test_scenes_the_grids_would_not_shrink_are_traced_as_triangles():
    """Patches that tile nothing bigger (each a different size) keep their triangles."""
    origin = np.column_stack([np.arange(5) * 3.0, np.zeros(5), np.zeros(5)])
    u = np.column_stack([1.0 + 0.1 * np.arange(5), np.zeros(5), np.zeros(5)])
    v = np.tile([0.0, 1.0, 0.0], (5, 1))
    assert _grids_of(_geometry(origin, u, v)) is None


def test_walks_trace_the_grids_built_once_per_geometry():
    """Walks leaving from random points and from hit points trace the grids, built once per
    geometry (another material set reuses them)."""
    scene, _, _ = box_scene([0.5] * 6, [1.0, 0, 0, 0, 0, 0], n=4)
    random_exit = WalkTables(scene, "finite", 1e-3, "random")
    assert random_exit.grids is scene.geometry.patch_grids and random_exit.grids.rectangles == 6
    assert random_exit.tracer is random_exit.grids.tracer
    other = scene.with_materials(np.full(scene.patch_count, 0.3), scene.emission)
    assert WalkTables(other, "biased_infinite", 1e-3, "random").tracer is random_exit.tracer
    hit_exit = WalkTables(scene, "finite", 1e-3, "hit")
    assert hit_exit.grids is random_exit.grids and hit_exit.tracer is random_exit.tracer
    assert hit_exit.hit_frames is random_exit.grids.hit_frames


def test_a_miss_reads_as_no_patch():
    origin, u, v, _ = _plane_grid(4, 4)
    g = _geometry(origin, u, v)
    grids = _grids_of(g)
    o = np.float32([[0.013, 0.021, 0.1], [0.013, 0.021, -0.1]])
    d = np.float32([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    by_triangles, by_grids = _both(g, grids, o, d)
    assert by_grids[0] == -1 and by_triangles[0] == -1
    assert by_grids[1] == by_triangles[1] >= 0


def _mixed_box(n=6, rotation=None, card=True):
    """A closed unit box around the origin: faces 0-3 in n x n parallelogram patches (faces 0
    and 1 with each patch's first triangle starting at its own corner, faces 2 and 3 not, so
    that the two orders of a parallelogram's corners (p, s1, s2) wind opposite ways), faces 4
    and 5 in triangle patches (each of the two triangles of an n x n cell a patch), and a
    trapezoid card inside (a patch of two triangles that is not a parallelogram), if ``card``.
    Geometry."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=n)
    V, T, TP = rectangles_to_mesh(origin - 0.5, u, v)
    T = T.reshape(-1, 2, 3)
    own_first = (face == 0) | (face == 1)
    T[own_first] = T[own_first][:, :, [1, 2, 0]]  # (0,1,2) -> (1,2,0): same winding
    T = T.reshape(-1, 3)
    TP = TP.copy()
    split = np.repeat((face == 4) | (face == 5), 2)
    P = int(np.count_nonzero(~((face == 4) | (face == 5)))) + 2 * int(np.count_nonzero((face == 4) | (face == 5)))
    kept = np.flatnonzero(~split)
    order = np.concatenate([kept, np.flatnonzero(split)])
    T = T[order]
    TP = np.concatenate([np.repeat(np.arange(kept.size // 2), 2), kept.size // 2 + np.arange(split.sum())])
    if card:
        corners = np.array([[-0.3, -0.2, 0.1], [0.1, -0.2, 0.1], [0.0, 0.2, 0.1], [-0.2, 0.2, 0.1]])
        T = np.vstack([T, V.shape[0] + np.array([[0, 1, 2], [0, 2, 3]])])
        V = np.vstack([V, corners])
        TP = np.append(TP, [P, P])
        P += 1
    if rotation is not None:
        V = V @ rotation.T
    return build_geometry(V, T, TP, P)


def test_a_mixed_scene_traces_its_grids_beside_the_other_patches_triangles():
    """Parallelogram patches in grids, triangle patches and a trapezoid traced as their own
    triangles: every ray scores on the patch its triangles give it (except within float32's
    rounding of a side), and the facing test on Embree's normal of the grids' triangles is the
    test on the hit triangle's own normal, from inside and from behind, for both orders of a
    parallelogram's corners."""
    g = _mixed_box(rotation=_rotation(11))
    assert not g.all_parallelograms and g.any_parallelograms
    _, ok, (p, s1, s2, _) = parallelogram_corners(g.triangle_corners, g.patch_first_triangle, g.patch_triangle_count)
    merged = np.flatnonzero(g.patch_triangle_count == 2)[ok]
    winding = np.sign(np.einsum("ij,ij->i", np.cross(s1 - p, s2 - p)[ok], g.patch_normal[merged]))
    assert set(winding) == {-1.0, 1.0}  # both orders of corners occur
    grids = g.patch_grids
    assert grids is not None and grids.rectangles == 4
    others = g.triangle_count - 2 * merged.size
    assert others == 2 * 36 * 2 + 2 and grids.triangle_count == 8 + others
    np.testing.assert_array_equal(np.sort(grids.cell_patch[:-1]), np.arange(g.patch_count))
    # Every triangle traced (its centre's patch) is wound like that patch's normal.
    c = grids.corners.astype(np.float64)
    centre_patch = grids.hit_patches(np.arange(grids.triangle_count, dtype=np.int32), *np.full((2, grids.triangle_count), 1 / 3, np.float32))
    assert (np.einsum("ij,ij->i", np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), g.patch_normal[centre_patch]) > 0).all()

    n = 200_000
    o, d, bary, target = rays_to_triangle_points(g, np.random.default_rng(12), n, powers=(3, 13))
    near_side = bary.min(axis=1) < 1e-5
    unit = d / np.linalg.norm(d, axis=1)[:, None]
    behind = (target + 1e-3 * unit).astype(np.float32)  # just past the target, looking back
    front_share = []
    for origins, directions in ((o, d), (behind, -d)):
        hit = g.tracer.first_hit(origins, directions)
        by_triangles = np.where(hit >= 0, g.triangle_patch[np.maximum(hit, 0)], -1)
        triangle, u, v, _, normal = grids.tracer.first_hit_barycentric(origins, directions)
        by_grids = grids.hit_patches(triangle, u, v)
        assert (by_triangles[~near_side] == by_grids[~near_side]).all()
        same = (by_grids == by_triangles) & (by_grids >= 0) & ~near_side
        assert same.sum() > n // 3
        front_by_triangles = np.einsum("ij,ij->i", directions, g.triangle_normal[hit]) < 0
        front_by_grids = np.einsum("ij,ij->i", directions, normal) < 0
        np.testing.assert_array_equal(front_by_grids[same], front_by_triangles[same])
        front_share.append(front_by_grids[same].mean())
    # From inside, rays meet the walls' front sides (and the card's back); from behind, back sides.
    assert front_share[0] > 0.5 and front_share[1] < 0.05


@pytest.mark.parametrize("walk", ["counted", "sorted", "hit"])
def test_a_walk_on_a_mixed_furnace_is_unbiased(walk):
    """The mixed box without its card as a furnace (E = 1, R = 0.5: a closed box of uniform
    emission and reflectivity has B = E / (1 - R) everywhere): walks trace its grids and the
    triangle patches' own triangles, leaving from random points (counting hits per patch, as in
    small scenes, or sorting paths by patch) or from hit points, and every patch's reflected
    radiosity is E R / (1 - R) to within 5 of the run's own batch standard errors (>= 32
    batches; P(max |t| > 5) < 1e-3 over 160 patches)."""
    from addon.core import PatchScene, Speedups, solve

    g = _mixed_box(n=4, card=False)
    speedups = Speedups(counted=walk == "counted")
    exit_point = "hit" if walk == "hit" else "random"
    corners = g.triangle_corners.astype(np.float64).reshape(-1, 3)
    triangles = np.arange(corners.shape[0]).reshape(-1, 3)
    P = g.patch_count
    scene = PatchScene(corners, triangles, g.triangle_patch, np.full(P, 0.5), np.ones(P))
    tables = WalkTables(scene, "finite", 1e-3, exit_point, speedups=speedups)
    assert tables.grids is not None and tables.grids.triangle_count < scene.geometry.triangle_count // 2
    assert tables.speedups.counted == (walk == "counted")
    result = solve(scene, estimator="finite", paths=200_000, seed=5, exit_point=exit_point, speedups=speedups)
    assert result.chunks >= 32
    z = (result.reflected[:, 0] - 0.5 / (1 - 0.5)) / np.sqrt(result.reflected_variance[:, 0])
    assert np.abs(z).max() < 5.0, np.abs(z).max()


def test_patches_facing_the_other_way_are_not_in_their_neighbours_grid():
    """A 6 x 4 grid whose first three columns face down (their triangles start at another corner,
    so their corners p, s1, s2 are the same vectors as their neighbours'): two rectangles, one
    facing each way, and rays from above and from below meet the side the patches' own
    triangles say, by the sign of Embree's normal of the grids."""
    origin, u, v, cell = _plane_grid(6, 4)
    V, T, TP = rectangles_to_mesh(origin, u, v)  # (0,1,2), (0,2,3) per patch: normal u x v = +z
    T = T.reshape(-1, 2, 3)
    down = cell[:, 0] < 3
    quad = 4 * np.arange(len(origin))[down, None]
    T[down] = np.stack([quad + [1, 0, 2], quad + [0, 3, 2]], axis=1)  # normal -z, same p, s1, s2
    g = build_geometry(V, T.reshape(-1, 3), TP, len(origin))
    np.testing.assert_array_equal(g.patch_normal[:, 2], np.where(down, -1.0, 1.0))
    _, _, (p, s1, s2, _) = parallelogram_corners(g.triangle_corners, g.patch_first_triangle, g.patch_triangle_count)
    assert np.unique(np.round(np.hstack([s1 - p, s2 - p]), 6), axis=0).shape[0] == 1  # one shape
    grids = _grids_of(g)
    assert grids.rectangles == 2
    rng = np.random.default_rng(4)
    k = np.repeat(cell, 20, axis=0)
    points = np.column_stack([k + rng.uniform(0.01, 0.99, k.shape), np.zeros(len(k))])
    o, d = _down_onto(points, g)
    for origins, directions in ((o, d), (o - 2 * (o - ((points - g.centre) / g.diagonal).astype(np.float32)), -d)):
        hit = g.tracer.first_hit(origins, directions)
        triangle, bu, bv, _, normal = grids.tracer.first_hit_barycentric(origins, directions)
        np.testing.assert_array_equal(grids.hit_patches(triangle, bu, bv), g.triangle_patch[hit])
        front = np.einsum("ij,ij->i", directions, g.triangle_normal[hit]) < 0
        np.testing.assert_array_equal(np.einsum("ij,ij->i", directions, normal) < 0, front)
        assert 0.4 < front.mean() < 0.6


@pytest.mark.parametrize("estimator, counted", [("finite", True), ("finite", False), ("biased_infinite", False)])
def test_random_exits_on_the_grids_are_the_walks_on_the_triangles(estimator, counted):
    """In the mixed box with its card (rays blocked by the card's back, triangle patches, both
    corner orders), a walk leaving from random points gives the same tallies, bit for bit, on
    the grids as on the patches' triangles with the same random numbers: the grids change which
    triangle Embree reports, not which patch or side a ray meets (but for rays within float32's
    rounding of a side, none of which these walks cast)."""
    from addon.core import PatchScene, Speedups
    from addon.core.methods.walk import walk_chunk

    g = _mixed_box(n=4, rotation=_rotation(2))
    corners = g.triangle_corners.astype(np.float64).reshape(-1, 3)
    P = g.patch_count
    reflectivity = np.random.default_rng(1).uniform(0.2, 0.8, P)
    emission = (np.arange(P) % 7 == 0).astype(float)
    scene = PatchScene(corners, np.arange(corners.shape[0]).reshape(-1, 3), g.triangle_patch, reflectivity, emission)
    on_grids = WalkTables(scene, estimator, 1e-3, "random", speedups=Speedups(counted=counted))
    on_triangles = WalkTables(scene, estimator, 1e-3, "random", speedups=Speedups(counted=counted, grids=False))
    assert on_grids.grids is not None and on_triangles.grids is None
    assert on_grids.speedups.counted == (counted and estimator == "finite")
    a = walk_chunk(on_grids, 30_000, np.random.default_rng(9))
    b = walk_chunk(on_triangles, 30_000, np.random.default_rng(9))
    assert a.ended["blocked"] > 100  # the card's back
    assert a.rays == b.rays and a.ended == b.ended
    np.testing.assert_array_equal(a.incident, b.incident)
