"""Patches partly covered by a near surface (addon/core/refine/covered_parts.py): a box room whose
ceiling has an emitting slab 2 cm under it. The ceiling's patches the slab's outline crosses are
split along it, nothing else splits, and the room's light then matches the solve on a mesh whose
patches follow the outline: before, the straddling patches re-emitted the gap's light into the room."""
import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.mesh import meshing
from addon.core.refine.adaptive import patch_mesh
from addon.core.display import smoothing
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


def meshes(room_size, slab_size, slab=SLAB):
    """[the room's PatchMesh, the slab's] at those patch sizes."""
    (room, room_faces), (slab, slab_faces) = box((0, 0, 0), ROOM, True), box(*slab, False)
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
    made = split_covered(first, scene.geometry)
    assert made is not None
    return first, scene, made


def test_the_patches_the_outline_crosses_split_along_it_and_the_cells_beside_it_finer(coarse):
    """The four 0.5 m ceiling patches the slab's outline crosses split with their split lines moved
    onto the outline: every cell lies wholly over the slab or wholly beside it (probed on 8 x 8
    points). The cells beside the outline split on, down to the last level (the light leaking from
    the gap is a strip there); nothing farther than a patch from the slab splits, the slab not at
    all, and the ceiling's area is kept."""
    first, _, made = coarse
    cells = made.cells
    room = cells[0]
    assert cells[1].level.max(initial=0) == 0  # (the slab: its top wholly covered, nothing crosses it)
    c = centres(first[0])
    ceiling = c[:, 2] > ROOM[2] - 1e-9
    crossed = np.flatnonzero(ceiling & under_slab(c, 0.25) & ~under_slab(c, -0.25))
    assert len(crossed) == 4
    split_ones = np.unique(room.origin[room.level > 0])
    assert set(crossed) <= set(split_ones) and (ceiling & under_slab(c, 0.75))[split_ones].all()
    grid = (np.arange(8) + 0.5) / 8
    s, t = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    q = room.points[room.corners]  # (n,4,3): quads
    points = sum(w[None, :, None] * q[:, None, k] for k, w in enumerate([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t]))
    on_ceiling = np.abs(q[:, :, 2] - ROOM[2]).max(axis=1) < 1e-9
    inside = under_slab(points.reshape(-1, 3)).reshape(len(q), -1) & on_ceiling[:, None]
    assert not (inside.any(axis=1) & ~inside.all(axis=1)).any()
    covered = inside.all(axis=1)
    beside = np.isin(room.corners, room.corners[covered]).any(axis=1) & ~covered & on_ceiling
    assert beside.sum() > 0 and (room.level[beside] == LEVELS).all()
    mesh, _ = patch_mesh(room)
    assert mesh.patch_area.sum() == pytest.approx(first[0].patch_area.sum(), rel=1e-12)


def _cell_points(cells):
    """(L,64,3) 8 x 8 points spread over each quad cell."""
    grid = (np.arange(8) + 0.5) / 8
    s, t = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    q = cells.points[cells.corners]
    return sum(w[None, :, None] * q[:, None, k] for k, w in enumerate([(1 - s) * (1 - t), s * (1 - t), s * t, (1 - s) * t]))


def test_each_cell_knows_its_side_of_the_outline(coarse):
    """The split gives each cell its side of the outline: a ceiling cell is covered exactly where it
    lies over the slab (64 points a cell), the slab's top (facing the ceiling 2 cm away) covered,
    nothing else (walls, floor, the slab's sides and bottom)."""
    _, _, made = coarse
    room, slab = made.cells
    assert [len(f) for f in made.covered] == [room.count, slab.count]
    points = _cell_points(room)
    on_ceiling = np.abs(points[:, :, 2] - ROOM[2]).max(axis=1) < 1e-9
    over = under_slab(points.reshape(-1, 3)).reshape(len(points), -1).all(axis=1) & on_ceiling
    np.testing.assert_array_equal(made.covered[0], over)
    assert over.sum() >= 4
    top = np.abs(_cell_points(slab)[:, :, 2] - SLAB[1][2]).max(axis=1) < 1e-9
    np.testing.assert_array_equal(made.covered[1], top)


def test_a_sliver_of_cover_along_a_patchs_edge_is_split_off():
    """A slab reaching 2 cm past the 0.5 m patches' lines (a twenty-fifth of a patch along its edge,
    between the probes' outer rows and the edge before): the patches with that sliver split too, and
    every ceiling cell lies wholly over the slab or wholly beside it (its overlap with the slab's
    outline, the cells being axis-aligned rectangles, none or all of it to the split lines' bisection,
    a thousandth of a cell); before, they stayed whole, a room-side patch holding 4% of the gap's light."""
    slab = ((0.48, 0.48, 0.94), (1.52, 1.52, 0.98))
    first = meshes(0.5, 0.5, slab)
    scene, _ = scene_of(first)
    made = split_covered(first, scene.geometry)
    assert made is not None
    room = made.cells[0]
    q = room.points[room.corners]
    ceiling = np.abs(q[:, :, 2] - ROOM[2]).max(axis=1) < 1e-9
    low, high = q[ceiling, :, :2].min(axis=1), q[ceiling, :, :2].max(axis=1)
    overlap = np.prod(np.clip(np.minimum(high, slab[1][:2]) - np.maximum(low, slab[0][:2]), 0, None), axis=1)
    share = overlap / np.prod(high - low, axis=1)
    assert ((share < 1e-3) | (share > 1 - 1e-3)).all(), np.sort(share[(share > 1e-3) & (share < 1 - 1e-3)])
    np.testing.assert_array_equal(made.covered[0][ceiling], share > 0.5)


def test_the_room_side_of_the_outline_keeps_the_rooms_light_in_the_smoothing(coarse):
    """The display's smoothing on the split mesh with given values (the gap's cells 25, the room's
    1, the slab 2): every corner of a room cell is 1, the outline's included, and every corner of a
    gap cell 25. Joined at the outline (no sides), the room's corners there take the gap's light
    (the spikes round a ceiling panel) and the gap's corners dip toward the room's."""
    _, _, made = coarse
    meshes_ = [patch_mesh(c)[0] for c in made.cells]
    combined = meshing.concatenate(meshes_)
    start = np.cumsum([0] + [len(m.points) for m in meshes_])
    triangles = np.concatenate([np.asarray(m.shading_triangles, np.int64) + start[k] for k, m in enumerate(meshes_)])
    triangle_patch = np.concatenate([np.asarray(m.shading_triangle_patch, np.int64) + combined.patch_offsets[k]
                                     for k, m in enumerate(meshes_)])
    covered = np.concatenate(made.covered)
    in_room = np.arange(combined.patch_count) < meshes_[0].patch_count
    values = np.where(in_room, np.where(covered, 25.0, 1.0), 2.0)[:, None] * np.ones(3)
    room = in_room[triangle_patch] & ~covered[triangle_patch]
    gap = in_room[triangle_patch] & covered[triangle_patch]
    for sides, kept in ((covered, True), (None, False)):
        surface = smoothing.Surface.of(combined.vertices, triangles, triangle_patch, combined.patch_count, covered=sides)
        corners = surface.corner_values(values)
        assert np.allclose(corners[room], 1.0, rtol=1e-9) == kept and np.allclose(corners[gap], 25.0, rtol=1e-9) == kept
    assert corners[room].max() > 3.0 and corners[gap].min() < 20.0


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
    first, _, made = coarse
    split_meshes = [patch_mesh(c)[0] for c in made.cells]
    # (the reference: 0.05 m patches, which the outline at 0.65 and 1.35 m runs along: none straddles)
    return {name: floor_light(m, seed) for (name, m), seed in zip(
        [("straddling", first), ("split", split_meshes), ("following", meshes(0.05, 0.05))], (11, 12, 13))}


def test_the_floor_gets_the_light_of_a_mesh_that_follows_the_outline(lights):
    """The floor's mean irradiance against the solve on 0.05 m patches, which follow the outline
    (0.025 m ones change it by 0.7%). Straddling, the four 0.5 m patches round the slab re-emit the
    gap's light into the room: the floor 29% too bright. Split along the outline, what is left is
    the 0.5 m patches' own discretization (2.6% here): within 3%, and no light lost (not below the
    reference by 4 standard errors)."""
    (ref, ref_se), (split, split_se), (straddling, straddling_se) = lights["following"], lights["split"], lights["straddling"]
    assert straddling - ref > 4 * np.hypot(ref_se, straddling_se) and straddling > 1.2 * ref, (straddling, ref)
    assert -4 * np.hypot(ref_se, split_se) < split - ref < 0.03 * ref, (split, ref, straddling)


def test_the_error_a_solve_measures_leaves_the_covered_patches_out(coarse):
    """Patches under a near cover (the gap over the slab: seen only through the slit) are
    ``hidden`` in the scene: the measured MSE is the area-weighted mean of the variance over the
    other patches alone, and the mean reflected light it is relative to too, to rounding; a scene
    without them measures every patch as before, bit for bit."""
    _, _, made = coarse
    split_meshes = [patch_mesh(c)[0] for c in made.cells]
    plain, _ = scene_of(split_meshes)
    hidden = np.concatenate(made.covered)
    assert 0 < hidden.sum() < hidden.size
    scene = plain.with_materials(plain.reflectivity, plain.emission)
    covered = PatchScene(plain.vertices, plain.triangles, plain.triangle_patch, plain.reflectivity, plain.emission,
                         hidden=hidden, _geometry=plain.geometry)
    share = covered.area_share
    assert share[hidden].sum() == 0 and share.sum() == pytest.approx(1.0)
    np.testing.assert_array_equal(covered.with_materials(covered.reflectivity, covered.emission).hidden, hidden)
    runs = [solve(s, paths=40_000, seed=3, threads=1) for s in (scene, covered)]
    # (the same paths: the scene's light is the same, only what is measured of it differs)
    np.testing.assert_array_equal(runs[0].radiosity, runs[1].radiosity)
    variance, reflected = runs[1].reflected_variance.mean(axis=1), runs[1].reflected.mean(axis=1)
    assert runs[1].measured_mse == pytest.approx(float(share @ variance), rel=1e-9)
    assert runs[1].mean_reflected == pytest.approx(float(share @ reflected), rel=1e-9)
    everything = scene.patch_area / scene.total_area
    assert runs[0].measured_mse == pytest.approx(float(everything @ runs[0].reflected_variance.mean(axis=1)), rel=1e-9)
    # the gap's light, tens of times the room's, held most of the error: left out, the rest is far smaller
    assert runs[1].measured_mse < 0.5 * runs[0].measured_mse, (runs[1].measured_mse, runs[0].measured_mse)


def test_a_hidden_flag_a_patch_is_checked():
    """A hidden mask of another length is one clear error; all hidden or none is no mask."""
    first = meshes(0.5, 0.5)
    plain, _ = scene_of(first)
    args = (plain.vertices, plain.triangles, plain.triangle_patch, plain.reflectivity, plain.emission)
    with pytest.raises(ValueError, match="one flag a patch"):
        PatchScene(*args, hidden=np.zeros(3, bool))
    for flags in (np.zeros(plain.patch_count, bool), np.ones(plain.patch_count, bool)):
        assert PatchScene(*args, hidden=flags).hidden is None
