"""Adaptive patches (core.adaptive): split patches, a mesh without T-junctions, and where to split."""
from collections import Counter

import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.mesh import meshing
from addon.core.display import smoothing
from addon.core.refine.adaptive import cells_of, patch_mesh, refine, shading_triangulation, split
from addon.core.refine.adaptive_light import DETAILS, Detail, refine_by_direct_light
from addon.core.mesh.faces import polygon_corner_values, starts_of, triangle_areas
from addon.core.lights.lights import PointLight, SunLight

# A closed box 4 x 3 x 2.5 of six quads, faces towards the inside.
BOX = np.array([[0, 0, 0], [4, 0, 0], [4, 3, 0], [0, 3, 0], [0, 0, 2.5], [4, 0, 2.5], [4, 3, 2.5], [0, 3, 2.5]], float)
BOX_FACES = [[0, 1, 2, 3], [4, 7, 6, 5], [0, 4, 5, 1], [1, 5, 6, 2], [2, 6, 7, 3], [3, 7, 4, 0]]


def box_mesh(size=0.5):
    return meshing.mesh_patches(BOX, [4] * 6, sum(BOX_FACES, []), size)


def plane_and_triangle():
    """A quad and a triangle sharing an edge, meshed into grids and triangles."""
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0], [3, 0.5, 0]], float)
    return meshing.mesh_patches(v, [4, 3], [0, 1, 2, 3, 1, 4, 2], 0.4)


def edge_uses(mesh):
    """Counter: edge (point pair) -> how many polygons have it."""
    sizes = np.asarray(mesh.face_sizes)
    starts = starts_of(sizes)
    uses = Counter()
    for f in range(len(sizes)):
        corners = mesh.corner_verts[starts[f]:starts[f] + sizes[f]]
        for a, b in zip(corners, np.roll(corners, -1)):
            uses[(min(a, b), max(a, b))] += 1
    return uses


def randomly_refined(mesh, rounds, seed, share=0.3):
    rng = np.random.default_rng(seed)
    cells = cells_of(mesh)
    for _ in range(rounds):
        cells, _ = split(cells, rng.random(cells.count) < share)
    return cells


@pytest.mark.parametrize("make", [box_mesh, plane_and_triangle])
def test_refined_mesh_has_no_crack(make):
    """Every edge of the refined mesh is shared by as many polygons as its first mesh's edges
    (two inside a surface, one on its border: no T-junction), areas add up to the first
    patches', no triangle is without area, and every triangle faces its patch's way."""
    mesh = make()
    before = Counter(edge_uses(mesh).values())
    cells = randomly_refined(mesh, 3, seed=4)
    refined, origin = patch_mesh(cells)
    assert cells.level.max() == 3 and refined.patch_count > 3 * mesh.patch_count
    uses = Counter(edge_uses(refined).values())
    assert set(uses) <= set(before), uses  # (the box: 2 only; the plane: 1 on its border, 2 inside)
    if make is box_mesh:
        assert set(uses) == {2}
    np.testing.assert_allclose(np.bincount(origin, weights=refined.patch_area, minlength=mesh.patch_count),
                               mesh.patch_area, rtol=1e-12)
    base_normal = np.cross(*(mesh.points[mesh.triangles[:, k]] - mesh.points[mesh.triangles[:, 0]] for k in (1, 2)))
    patch_normal = np.zeros((mesh.patch_count, 3))
    np.add.at(patch_normal, mesh.triangle_patch, base_normal)
    # both triangulations: the core's (each cell's own) and the shading's (every polygon corner)
    for triangles, triangle_patch in ((refined.triangles, refined.triangle_patch), shading_triangulation(refined)):
        areas = triangle_areas(refined.points, triangles)
        assert areas.min() > 1e-3 * np.median(areas)
        np.testing.assert_allclose(np.bincount(triangle_patch, weights=areas), refined.patch_area, rtol=1e-12)
        cross = np.cross(*(refined.points[triangles[:, k]] - refined.points[triangles[:, 0]] for k in (1, 2)))
        assert (np.einsum("ij,ij->i", cross, patch_normal[origin[triangle_patch]]) > 0).all()
    # every polygon corner is a corner of the shading's triangles of its patch (and no other point)
    triangles, triangle_patch = shading_triangulation(refined)
    used = {(p, v) for p, row in zip(triangle_patch, triangles) for v in row}
    assert used == set(zip(refined.corner_patch, refined.corner_verts))


def test_neighbours_differ_by_one_split_at_most():
    cells = randomly_refined(box_mesh(), 3, seed=5, share=0.15)
    refined, _ = patch_mesh(cells)
    uses = {}
    sizes = np.asarray(refined.face_sizes)
    starts = starts_of(sizes)
    for f in range(len(sizes)):
        corners = refined.corner_verts[starts[f]:starts[f] + sizes[f]]
        for a, b in zip(corners, np.roll(corners, -1)):
            uses.setdefault((min(a, b), max(a, b)), []).append(cells.level[f])
    assert max(abs(levels[0] - levels[1]) for levels in uses.values()) <= 1


def test_only_what_is_asked_splits():
    mesh = box_mesh(1.0)
    marked = np.zeros(mesh.patch_count, bool)
    marked[5] = True
    refined, origin, _ = refine(mesh, marked)
    assert refined.patch_count == mesh.patch_count + 3
    assert np.count_nonzero(origin == 5) == 4
    # the unsplit neighbours take the midpoints as corners: polygons of 5 corners
    assert np.count_nonzero(np.asarray(refined.face_sizes) == 5) == 4


def test_ngons_and_their_neighbours_never_split():
    # a hexagon (kept whole: smaller than the patch size) beside a quad grid
    v = np.array([[0, 0, 0], [.5, 0, 0], [.75, .25, 0], [.5, .5, 0], [0, .5, 0], [-.25, .25, 0], [-.25, 3, 0], [.75, 3, 0]])
    mesh = meshing.mesh_patches(v, [6, 4], [0, 1, 2, 3, 4, 5, 4, 3, 7, 6], 1.5)
    assert list(mesh.face_sizes) == [6, 4, 4]  # the quad: a cell beside the hexagon, one beyond
    refined, origin, cells = refine(mesh, np.ones(3, bool))
    assert list(np.bincount(origin)) == [1, 1, 4]
    assert sorted(refined.face_sizes[:2]) == [5, 6]  # the hexagon as it was; its neighbour takes a midpoint
    uses = edge_uses(refined)
    assert set(uses.values()) == {1, 2} and uses[(3, 4)] == 2


def assert_furnace(mesh, method="walk", exit_point="hit", paths=200_000, seed=3):
    """A closed ``mesh`` whose every patch emits E = 1 and reflects R = 0.5 has B = E / (1 - R)
    everywhere: each patch within 5 of its measured standard errors, and for the paper's finite
    walk the area-weighted mean within 4 standard deviations of its hit count's exact variance."""
    E, R = 1.0, 0.5
    P = mesh.patch_count
    scene = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(P, R), np.full(P, E))
    result = solve(scene, estimator="finite", method=method, paths=paths, seed=seed, exit_point=exit_point)
    if method == "walk":
        A = scene.patch_area
        mean_b = (A * result.reflected[:, 0]).sum() / A.sum()
        sd = R * scene.total_power / A.sum() * (np.sqrt(R) / (1 - R)) / np.sqrt(paths)
        assert abs(mean_b - E * R / (1 - R)) < 4.0 * sd
    z = (result.radiosity[:, 0] - E / (1 - R)) / np.sqrt(result.reflected_variance[:, 0])
    assert np.abs(z).max() < 5.0, np.abs(z).max()


def test_furnace_on_a_refined_mesh():
    """The closed box's furnace (``assert_furnace``) holds on a mesh refined twice at random."""
    refined, _ = patch_mesh(randomly_refined(box_mesh(1.0), 2, seed=6))
    assert_furnace(refined)


@pytest.mark.parametrize("method,exit_point", [("walk", "hit"), ("walk", "random"), ("two_way", "hit"),
                                               ("two_way", "random")])
def test_every_method_and_exit_point_meets_the_furnace_on_a_refined_mesh(method, exit_point):
    """The paper's walk and the two-way iteration, from hit points and random points, on a mesh
    refined twice at random (cells of three sizes, n-gons at the borders): ``assert_furnace``."""
    refined, _ = patch_mesh(randomly_refined(box_mesh(1.0), 2, seed=8))
    assert_furnace(refined, method, exit_point, paths=100_000, seed=4)


def test_energy_balance_on_a_refined_mesh():
    """Under a lamp in a closed box, everything emitted is absorbed (nothing escapes) on the
    refined mesh as on the first."""
    mesh = box_mesh(1.0)
    P = mesh.patch_count
    scene = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(P, 0.5), np.zeros(P),
                       lights=[PointLight(np.array([2.0, 1.5, 2.2]), np.full(3, 2.0))])
    refined = refine_by_direct_light([mesh], scene, DETAILS["MEDIUM"], seed=1)
    m = refined.meshes[0]
    assert m.patch_count > P
    rscene = PatchScene(m.points, m.triangles, m.triangle_patch, np.full(m.patch_count, 0.5), np.zeros(m.patch_count),
                        lights=list(scene.lights.lights))
    result = solve(rscene, estimator="finite", paths=20_000, seed=2)
    energy = result.energy
    emitted = float(np.sum(energy["emitted"]))
    assert float(np.sum(energy["escaped"])) == 0.0
    assert float(np.sum(energy["absorbed"])) == pytest.approx(emitted, rel=1e-9)


def test_smooth_colours_agree_at_a_refinement_border():
    """Where a split patch meets an unsplit one, the smooth light at each polygon corner of the
    border (the midpoint included) is one value on both sides: for light that changes linearly
    (which a continuous answer can show exactly), the same value within rounding."""
    mesh = box_mesh(1.0)
    marked = np.zeros(mesh.patch_count, bool)
    marked[[3, 4]] = True
    refined, origin, _ = refine(mesh, marked)
    triangles, triangle_patch = shading_triangulation(refined)
    surface = smoothing.Surface.of(refined.points, triangles, triangle_patch, refined.patch_count)
    values = 1.0 + surface.patch_centroid @ np.array([[0.3, 0.1, 0.2], [0.2, 0.3, 0.1], [0.1, 0.2, 0.3]])
    corners = surface.corner_values(values, iterations=300)  # (converged: no leftover of the last scale)
    at = polygon_corner_values(corners, triangles, triangle_patch, refined.corner_patch,
                                         refined.corner_verts)
    # polygon corners at one point on one face of the box (one normal): one value
    normal = np.round(surface.patch_normal[refined.corner_patch], 6)
    key = [tuple(k) for k in np.column_stack([refined.corner_verts, normal])]
    seen = {}
    border = 0
    for k, value in zip(key, at):
        if k in seen:
            np.testing.assert_allclose(value, seen[k], rtol=1e-6)
        seen[k] = value
    sizes = np.asarray(refined.face_sizes)
    border = np.count_nonzero(sizes > 4)
    assert border >= 4  # (unsplit neighbours with a midpoint corner were there to compare)
    # each patch's mean light is still its own value
    means = surface.corner_means(corners[:, :, 0].ravel())
    np.testing.assert_allclose(means, values[:, 0], rtol=1e-9)


def floor_under_lamp(size=0.5, height=0.3):
    """A 4 x 4 floor (patches of ``size``) under a point lamp ``height`` above its centre."""
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]], float)
    mesh = meshing.mesh_patches(v, [4], [0, 1, 2, 3], size)
    P = mesh.patch_count
    scene = PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(P, 0.5), np.zeros(P),
                       lights=[PointLight(np.array([2.1, 2.1, height]), np.full(3, 1.0))])
    return mesh, scene


def test_the_hot_spot_splits_and_the_flat_far_floor_does_not():
    mesh, scene = floor_under_lamp()
    refined = refine_by_direct_light([mesh], scene, Detail(levels=2, contrast=0.25, budget=10.0), seed=0)
    m, origin = refined.meshes[0], refined.origins[0]
    below = np.flatnonzero(np.all(np.abs(np.stack([mesh.points[mesh.corner_verts[4 * p:4 * p + 4]].mean(axis=0)
                                                    for p in range(mesh.patch_count)])[:, :2] - 2.1) < 0.3, axis=1))
    counts = np.bincount(origin, minlength=mesh.patch_count)
    assert (counts[below] >= 4).all() and counts.max() >= 7  # under the lamp: split, and split again
    corner_patch = 0  # the patch at (0, 0), 2.9 m away: the light changes by a few percent across it
    assert counts[corner_patch] == 1
    assert m.patch_area.sum() == pytest.approx(16.0, rel=1e-12)
    assert refined.steps[0]["split"] > 0 and len(refined.steps) == 2


@pytest.mark.parametrize("source", ["lamp", "sun"])
def test_a_shadow_edge_splits(source):
    """A blocker's shadow on a floor under a lamp or the sun: the patches its edge crosses split;
    the lit and the shadowed floor far from it do not (beyond the hot spot)."""
    floor = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]], float)
    blocker = np.array([[0, 0, 1.0], [4, 0, 1.0], [4, 2.14, 1.0], [0, 2.14, 1.0]], float)  # faces down
    m_floor = meshing.mesh_patches(floor, [4], [0, 1, 2, 3], 0.5)
    m_block = meshing.mesh_patches(blocker, [4], [0, 3, 2, 1], 4.0)
    combined = meshing.concatenate([m_floor, m_block])
    P = combined.patch_count
    scene = PatchScene(combined.vertices, combined.triangles, combined.triangle_patch, np.full(P, 0.5), np.zeros(P),
                       lights=[PointLight(np.array([2.0, 2.0, 20.0]), np.full(3, 400.0)) if source == "lamp" else
                               SunLight(np.array([0.0, 0.0, -1.0]), np.full(3, 1.0))])
    refined = refine_by_direct_light([m_floor, m_block], scene, Detail(levels=1, contrast=0.25, budget=10.0), seed=0,
                                     receives=[True, False])
    counts = np.bincount(refined.origins[0], minlength=m_floor.patch_count)
    centre_y = np.array([m_floor.points[m_floor.corner_verts[4 * p:4 * p + 4], 1].mean() for p in range(m_floor.patch_count)])
    # the shadow edge on the floor: y = 2 + 0.14 * 20 / 19 = 2.147 (the sun's: 2.14), in the row of patches 2.0-2.5
    edge_row = np.abs(centre_y - 2.25) < 0.01
    assert (counts[edge_row] == 4).all()
    assert (counts[~edge_row] == 1).all()
    assert refined.meshes[1].patch_count == m_block.patch_count  # (not receiving: not refined)



def test_cells_another_object_runs_into_stay_whole():
    """A wall box standing through a floor under a low lamp: the floor's patches it crosses
    (partly buried) do not split, their lit neighbours do."""
    floor = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]], float)
    m_floor = meshing.mesh_patches(floor, [4], [0, 1, 2, 3], 0.5)
    lo, hi = np.array([1.9, -0.5, -0.3]), np.array([2.1, 4.5, 2.0])
    corners = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1]) for x in (lo[0], hi[0])])
    # an outward box: 0 1 3 2 bottom (down), 4 6 7 5 top (up), sides outward
    faces = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    m_wall = meshing.mesh_patches(corners, [4] * 6, sum(faces, []), 0.5)
    combined = meshing.concatenate([m_floor, m_wall])
    P = combined.patch_count
    scene = PatchScene(combined.vertices, combined.triangles, combined.triangle_patch, np.full(P, 0.5), np.zeros(P),
                       lights=[PointLight(np.array([1.5, 2.0, 0.6]), np.full(3, 1.0))])
    assert scene.geometry.buried is not None
    refined = refine_by_direct_light([m_floor, m_wall], scene, Detail(levels=1, contrast=0.1, budget=10.0), seed=0,
                                     receives=[True, False])
    counts = np.bincount(refined.origins[0], minlength=m_floor.patch_count)
    centre_x = np.array([m_floor.points[m_floor.corner_verts[4 * p:4 * p + 4], 0].mean() for p in range(m_floor.patch_count)])
    crossed = np.abs(centre_x - 2.0) < 0.3  # the columns 1.5-2.0 and 2.0-2.5
    assert (counts[crossed] == 1).all()
    assert (counts[np.abs(centre_x - 1.25) < 0.01] == 4).any()  # under the lamp, beside the wall: split
