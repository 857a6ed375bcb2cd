"""Patches partly covered by a near surface (addon/core/refine/covered_parts.py): a box room whose
ceiling has an emitting slab 2 cm under it. The ceiling's patches the slab's outline crosses are
split until none is partly covered, nothing else splits, and the room's light then matches the
solve on a mesh whose patches follow the outline (the discretization's answer without straddling
patches): before, the straddling patches re-emitted the gap's light into the room."""
import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.mesh import meshing
from addon.core.refine.adaptive import patch_mesh
from addon.core.refine.covered_parts import LEVELS, covered_points, split_covered

ROOM = (2.0, 2.0, 1.0)
SLAB = ((0.65, 0.65, 0.94), (1.35, 1.35, 0.98))  # 2 cm under the ceiling, its outline across 0.5 m patches
R_ROOM, R_SLAB, E_SLAB = 0.8, 0.8, 5.0


def box(lo, hi, inward):
    """(vertices (8,3), six quads' corners) of the box ``lo``-``hi``, faces inward (a room) or out."""
    (x0, y0, z0), (x1, y1, z1) = lo, hi
    v = np.array([[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
                  [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], float)
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]  # (outward)
    if inward:
        faces = [f[::-1] for f in faces]
    return v, sum(faces, [])


def meshes(room_size, slab_size):
    """[the room's PatchMesh, the slab's] at those patch sizes."""
    (room, room_faces), (slab, slab_faces) = box((0, 0, 0), ROOM, True), box(*SLAB, False)
    return [meshing.mesh_patches(room, [4] * 6, room_faces, room_size),
            meshing.mesh_patches(slab, [4] * 6, slab_faces, slab_size)]


def scene_of(mesh_list):
    combined = meshing.concatenate(mesh_list)
    counts = [m.patch_count for m in mesh_list]
    R = np.repeat([R_ROOM, R_SLAB], counts)
    E = np.repeat([0.0, E_SLAB], counts)
    return PatchScene(combined.vertices, combined.triangles, combined.triangle_patch, R, E), combined


def centres(mesh):
    c = np.zeros((mesh.patch_count, 3))
    n = np.bincount(mesh.triangle_patch, minlength=mesh.patch_count)
    for k in range(3):
        c[:, k] = np.bincount(mesh.triangle_patch, weights=mesh.points[mesh.triangles].mean(axis=1)[:, k],
                              minlength=mesh.patch_count) / n
    return c


def under_slab(points, margin=0.0):
    (x0, y0, _), (x1, y1, _) = SLAB
    return ((points[:, 0] > x0 - margin) & (points[:, 0] < x1 + margin) & (points[:, 1] > y0 - margin)
            & (points[:, 1] < y1 + margin))


@pytest.fixture(scope="module")
def coarse():
    first = meshes(0.5, 0.5)
    scene, _ = scene_of(first)
    cells = split_covered(first, scene.geometry)
    return first, scene, cells


def test_only_the_ceilings_patches_the_outline_crosses_split_and_none_stays_partly_covered(coarse):
    """The four 0.5 m ceiling patches the slab's outline crosses split down to the last level (their
    neighbours once at most, the balance's), the slab not at all; of the finest cells, only those
    along the outline are still crossed by it (a strip 2^-LEVELS of a patch wide)."""
    first, _, cells = coarse
    assert cells is not None
    room = cells[0]
    assert cells[1].level.max(initial=0) == 0  # (the slab: its top wholly covered, nothing crosses it)
    c = centres(first[0])
    crossed = np.flatnonzero((c[:, 2] > ROOM[2] - 1e-9) & under_slab(c, 0.25) & ~under_slab(c, -0.25))
    assert len(crossed) == 4
    assert set(np.unique(room.origin[room.level == LEVELS])) == set(crossed)
    assert room.level[~np.isin(room.origin, crossed)].max(initial=0) <= LEVELS - 1
    fine = np.flatnonzero(room.level == LEVELS)
    grid = (np.arange(8) + 0.5) / 8
    s, t = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    q = room.points[room.corners[fine]]  # (n,4,3): quads
    points = sum(w[None, :, None] * q[:, None, k] for k, w in enumerate([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t]))
    inside = under_slab(points.reshape(-1, 3)).reshape(len(fine), -1)
    mixed = inside.any(axis=1) & ~inside.all(axis=1)
    side = 0.5 / 2**LEVELS
    perimeter = 4 * (SLAB[1][0] - SLAB[0][0])
    assert 0 < mixed.sum() <= perimeter / side + 4
    # (the cells a level up, split or not, are never crossed: each is all gap or all room)
    rest = np.flatnonzero((room.level < LEVELS) & np.isin(room.origin, crossed))
    q = room.points[room.corners[rest]]
    points = sum(w[None, :, None] * q[:, None, k] for k, w in enumerate([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t]))
    inside = under_slab(points.reshape(-1, 3)).reshape(len(rest), -1)
    assert not (inside.any(axis=1) & ~inside.all(axis=1)).any()


def test_covered_points_are_those_a_near_surface_faces():
    """Points of the ceiling: covered within 10 cm exactly where the slab lies under them; within
    1 cm nowhere (the gap is 2 cm)."""
    first = meshes(0.5, 0.5)
    scene, _ = scene_of(first)
    c = centres(first[0])
    ceiling = np.flatnonzero(c[:, 2] > ROOM[2] - 1e-9)
    rng = np.random.default_rng(3)
    points = np.column_stack([rng.random((400, 2)) * ROOM[0], np.full(400, ROOM[2])])
    patch = ceiling[np.argmin(np.abs(points[:, None, :2] - c[None, ceiling, :2]).max(axis=2), axis=1)]
    covered = covered_points(scene.geometry, points, patch, np.full(400, 0.1))
    np.testing.assert_array_equal(covered, under_slab(points))
    assert not covered_points(scene.geometry, points, patch, np.full(400, 0.01)).any()


def floor_light(mesh_list, seed):
    scene, _ = scene_of(mesh_list)
    c = centres(mesh_list[0])
    floor = np.flatnonzero(c[:, 2] < 1e-9)
    r = solve(scene, paths=400_000, seed=seed, exit_point="random", threads=1, method="walk", direct_light="shot")
    area = scene.patch_area[floor]
    value = np.sum(area * r.irradiance[floor, 0]) / area.sum()
    se = np.sqrt(np.sum(area**2 * r.irradiance_variance[floor, 0])) / area.sum()
    return value, se


@pytest.fixture(scope="module")
def lights(coarse):
    first, _, cells = coarse
    split_meshes = [patch_mesh(c)[0] for c in cells]
    # (the reference: 0.05 m patches, which the outline at 0.65 and 1.35 m runs along: none straddles)
    return {name: floor_light(m, seed) for (name, m), seed in zip(
        [("straddling", first), ("split", split_meshes), ("following", meshes(0.05, 0.05))], (11, 12, 13))}


def test_the_floor_gets_the_light_of_a_mesh_that_follows_the_outline(lights):
    """The floor's mean irradiance against the solve on 0.05 m patches, which follow the outline
    (0.025 m ones change it by 0.7%). Straddling, the four 0.5 m patches round the slab re-emit the
    gap's light into the room: the floor 29% too bright. Split, the excess left is the strip of the
    gap the finest cells along the outline still hold (0.025 of their 0.125 m, 14% of the gap's
    area the straddling patches held): under a quarter of it, and no light lost (not below the
    reference by 4 standard errors)."""
    (ref, ref_se), (split, split_se), (straddling, straddling_se) = lights["following"], lights["split"], lights["straddling"]
    excess = straddling - ref
    assert excess > 4 * np.hypot(ref_se, straddling_se) and excess > 0.2 * ref, (straddling, ref)
    assert -4 * np.hypot(ref_se, split_se) < split - ref < 0.25 * excess, (split, ref, straddling)
