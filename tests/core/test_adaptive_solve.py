"""Refinement from a solve's own estimates (core.adaptive_solve): neighbours on one surface whose
solved light differs by more than its noise and a visible share split; the closed box's exact
answers hold on a mesh refined twice that way."""
import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.mesh import meshing
from addon.core.refine.adaptive import cells_of, patch_mesh
from addon.core.refine.adaptive_light import DETAILS, Detail
from addon.core.refine.adaptive_solve import neighbours, refine_by_solve
from addon.core.lights.lights import PointLight

from test_adaptive import assert_furnace, box_mesh, edge_uses

WIDE = Detail(levels=2, contrast=0.25, budget=10.0)


def floor(size=0.5):
    v = np.array([[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0]], float)
    return meshing.mesh_patches(v, [4], [0, 1, 2, 3], size)


def centres(mesh):
    """(P,3) area-weighted centre of each patch."""
    t = np.asarray(mesh.triangles)
    corners = mesh.points[t]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    tp = np.asarray(mesh.triangle_patch)
    total = np.bincount(tp, weights=area, minlength=mesh.patch_count)
    return np.stack([np.bincount(tp, weights=area * corners[:, :, k].mean(axis=1), minlength=mesh.patch_count)
                     for k in range(3)], axis=1) / total[:, None]


def step_light(mesh, low=1.0, high=2.0):
    """(P,3): light ``low`` left of x = 2, ``high`` right of it."""
    x = centres(mesh)[:, 0]
    return np.repeat(np.where(x < 2, low, high)[:, None], 3, axis=1)


def test_neighbours_share_an_edge_on_one_surface():
    """A grid's patches pair with the four beside them; the box's walls meet the floor at a
    crease and do not pair across it."""
    mesh = floor(1.0)  # 4 x 4
    a, b = neighbours(mesh)
    assert len(a) == 2 * 4 * 3 and (a < b).all()
    box = box_mesh(1.0)
    a, b = neighbours(box)
    normal = np.array([np.cross(*(box.points[box.corner_verts[4 * p + 1:4 * p + 3]] - box.points[box.corner_verts[4 * p]]))
                       for p in range(box.patch_count)])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    assert len(a) and np.allclose(np.einsum("ij,ij->i", normal[a], normal[b]), 1.0)


def test_a_step_in_the_solved_light_splits_its_border_only():
    mesh = floor()
    cells = cells_of(mesh)
    light = step_light(mesh)
    out, step = refine_by_solve([cells], [mesh], light, np.full_like(light, 1e-4), WIDE, np.sqrt(32), mesh.patch_count)
    x = centres(mesh)[:, 0]
    _, parent = out[0], None
    counts = np.bincount(out[0].origin, minlength=mesh.patch_count)
    border = np.abs(x - 2) < 0.3  # the columns either side of x = 2
    assert (counts[border] == 4).all() and (counts[~border] == 1).all()
    assert step["split"] == border.sum() and step["patches"] == out[0].count


def test_a_difference_within_the_noise_or_below_the_visible_share_does_not_split():
    mesh = floor()
    cells = cells_of(mesh)
    light = step_light(mesh)
    # the step is 1.0: below 3 standard errors of the difference (sd 0.5 a patch: 0.71 of the difference)
    _, noisy = refine_by_solve([cells], [mesh], light, np.full_like(light, 0.25), WIDE, np.sqrt(32), mesh.patch_count)
    assert noisy["split"] == 0
    # a 10% step, well measured, below a quarter of the local light
    _, faint = refine_by_solve([cells], [mesh], step_light(mesh, 1.0, 1.1), np.full_like(light, 1e-8), WIDE,
                               np.sqrt(32), mesh.patch_count)
    assert faint["split"] == 0
    # no measured variance (one batch): nothing is known, nothing splits
    _, unknown = refine_by_solve([cells], [mesh], light, np.full_like(light, np.nan), WIDE, np.sqrt(32), mesh.patch_count)
    assert unknown["split"] == 0


def test_the_smallest_size_and_the_budget_bound_the_splits():
    mesh = floor()
    cells = cells_of(mesh)
    light = step_light(mesh)
    variance = np.full_like(light, 1e-4)
    tight = Detail(levels=2, contrast=0.25, budget=1.2)  # room for 64 * 0.2 / 3 = 4 splits
    out, step = refine_by_solve([cells], [mesh], light, variance, tight, np.sqrt(32), mesh.patch_count)
    assert step["split"] == 4 and out[0].count == 64 + 12
    once = Detail(levels=1, contrast=0.25, budget=10.0)
    out, _ = refine_by_solve([cells], [mesh], light, variance, once, np.sqrt(32), mesh.patch_count)
    refined, _ = patch_mesh(out[0])
    again, step = refine_by_solve(out, [refined], step_light(refined), np.full((refined.patch_count, 3), 1e-4), once,
                                  np.sqrt(32), mesh.patch_count)
    assert step["split"] == 0  # (every cell at the border is at the Detail's last level)
    keep = np.zeros(mesh.patch_count, bool)
    keep[np.abs(centres(mesh)[:, 0] - 2) < 0.3] = True
    _, kept = refine_by_solve([cells], [mesh], light, variance, WIDE, np.sqrt(32), mesh.patch_count, keep_whole=keep)
    assert kept["split"] == 0


def lamp_box():
    mesh = box_mesh(1.0)
    P = mesh.patch_count
    lamp = PointLight(np.array([2.0, 1.5, 2.3]), np.full(3, 4.0))
    return mesh, PatchScene(mesh.points, mesh.triangles, mesh.triangle_patch, np.full(P, 0.5), np.zeros(P), lights=[lamp])


def twice_refined():
    """The lamp box's mesh refined by two solves' own estimates (Medium's rule, a budget of 6x)."""
    mesh, scene = lamp_box()
    detail = Detail(levels=2, contrast=0.25, budget=6.0)
    cells, current = [cells_of(mesh)], mesh
    counts = [mesh.patch_count]
    for round_ in range(2):
        P = current.patch_count
        s = PatchScene(current.points, current.triangles, current.triangle_patch, np.full(P, 0.5), np.zeros(P),
                       lights=list(scene.lights.lights))
        result = solve(s, estimator="finite", paths=40_000, seed=10 + round_, direct_light="gathered")
        cells, step = refine_by_solve(cells, [current], result.irradiance, result.irradiance_variance, detail,
                                      s.geometry.diagonal, mesh.patch_count)
        current, _ = patch_mesh(cells[0])
        counts.append(current.patch_count)
    return mesh, current, counts, scene, cells[0].origin


def test_furnace_and_energy_balance_on_a_mesh_refined_twice_by_solves():
    """The lamp box refined by two solves (each splitting where its own light changes: the hot
    spot under the lamp): the mesh stays closed, and the closed box's answers hold on it: every
    patch emitting E and reflecting R has B = E / (1 - R), and under the lamp everything emitted
    is absorbed."""
    mesh, refined, counts, scene, _ = twice_refined()
    assert counts[0] < counts[1] < counts[2]
    assert set(edge_uses(refined).values()) == {2}
    assert refined.patch_area.sum() == pytest.approx(mesh.patch_area.sum(), rel=1e-12)
    assert_furnace(refined)
    P = refined.patch_count
    lit = PatchScene(refined.points, refined.triangles, refined.triangle_patch, np.full(P, 0.5), np.zeros(P),
                     lights=list(scene.lights.lights))
    energy = solve(lit, estimator="finite", paths=20_000, seed=2).energy
    emitted = float(np.sum(energy["emitted"]))
    assert float(np.sum(energy["escaped"])) == 0.0
    assert float(np.sum(energy["absorbed"])) == pytest.approx(emitted, rel=1e-9)


def test_the_refining_splits_are_where_the_light_changes():
    """The ceiling's patches nearest the lamp (its hot spot: the light changes by half across
    one) split; far down the walls, where the light changes slowly, patches stay whole."""
    mesh, refined, _, _, origin = twice_refined()
    counts = np.bincount(origin, minlength=mesh.patch_count)
    c = centres(mesh)
    hot = np.flatnonzero((np.abs(c[:, 2] - 2.5) < 1e-9) & (np.linalg.norm(c[:, :2] - [2.0, 1.5], axis=1) < 0.8))
    assert hot.size and (counts[hot] > 1).all()
    assert np.median(counts[hot]) > np.median(counts)


def test_what_balance_adds_stays_within_the_budget():
    """A step of light across the refined column (well measured there, noisy outside): its finer
    cells split, and so must their coarse neighbours outside (balance); the step takes only as
    many of the largest differences as fit in the budget with what balance adds."""
    mesh = floor()
    cells = cells_of(mesh)
    once, _ = refine_by_solve([cells], [mesh], step_light(mesh), np.full((mesh.patch_count, 3), 1e-4), WIDE,
                              np.sqrt(32), mesh.patch_count)
    refined, _ = patch_mesh(once[0])
    c = centres(refined)
    column = np.abs(c[:, 0] - 2) < 0.5
    light = np.repeat((1.0 + (column & (c[:, 1] > 2)))[:, None], 3, axis=1)
    variance = np.repeat(np.where(column, 1e-4, 100.0)[:, None], 3, axis=1)
    free = Detail(levels=2, contrast=0.25, budget=10.0)
    out, step = refine_by_solve(once, [refined], light, variance, free, np.sqrt(32), mesh.patch_count)
    assert out[0].count > once[0].count + 3 * step["split"]  # (balance split coarse cells beside them)
    for budget in (1.9, 2.0, 2.1, 2.2):
        detail = Detail(levels=2, contrast=0.25, budget=budget)
        out, step = refine_by_solve(once, [refined], light, variance, detail, np.sqrt(32), mesh.patch_count)
        assert step["split"] > 0 and out[0].count <= int(budget * mesh.patch_count), budget
