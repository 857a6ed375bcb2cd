"""Emitting patches emit from their front and their back, as Cycles' emission does (its closure's
|cos| of either side), against exact references: the discrete system with the backs' form
factors (closed form for rectangles that see each other whole), the gathered direct light, and
which backs emit at all."""
import math

import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.estimate.reference import (
    back_form_factors,
    form_factors_raycast,
    path_variances,
    rectangle_form_factors,
    solve_radiosity_system,
)
from addon.core.methods.first_shot import direct_irradiance
from boxes import CEILING, box_rectangles, box_scene, rectangles_to_mesh

N = 4
R_FLOOR, R_WALL, E_PANEL = 0.5, 0.7, 2.0


def _grid(origin, u, v, n):
    """n x n rectangles (origin, u, v) of the rectangle ``origin``, ``u``, ``v``."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    o = np.asarray(origin, float) + np.outer(i.ravel(), np.divide(u, n)) + np.outer(j.ravel(), np.divide(v, n))
    return o, np.tile(np.divide(u, n), (n * n, 1)), np.tile(np.divide(v, n), (n * n, 1))


def panel_scene(n=N):
    """A unit floor (n x n, facing up), a unit wall at x = 1 (n x n, facing -x) and an emitting
    panel 0.5 x 0.5 at half height over the floor's left half, facing up: its back lights the
    floor and the wall's lower half, its front the wall's upper half. No rectangle hides another
    from a third (the panel ends where the floor's middle line meets it), so the closed-form form
    factors are exact. (PatchScene, origin, u, v, R, E) of P = 2 n^2 + 1 patches."""
    floor = _grid((0, 0, 0), (1, 0, 0), (0, 1, 0), n)
    wall = _grid((1, 0, 0), (0, 0, 1), (0, 1, 0), n)
    panel = (np.array([[0.0, 0.25, 0.5]]), np.array([[0.5, 0, 0]]), np.array([[0, 0.5, 0]]))
    origin, u, v = (np.vstack([floor[k], wall[k], panel[k]]) for k in range(3))
    P = origin.shape[0]
    R = np.r_[np.full(n * n, R_FLOOR), np.full(n * n, R_WALL), 0.0]
    E = np.zeros(P)
    E[-1] = E_PANEL
    return PatchScene(*rectangles_to_mesh(origin, u, v), R, E), origin, u, v, R, E


@pytest.fixture(scope="module")
def panel():
    scene, origin, u, v, R, E = panel_scene()
    F, F_back = rectangle_form_factors(origin, u, v), back_form_factors(origin, u, v)
    return scene, F, F_back, R, E


def test_the_backs_form_factors_are_the_ray_casts():
    """back_form_factors of the panel scene against cast rays' hits on back sides: every entry
    within 5 of its binomial standard errors (and the panel's back is what the floor sees)."""
    scene, origin, u, v, _, _ = panel_scene()
    rays = 200_000
    F_cast, back_cast = form_factors_raycast(scene, rays, seed=1, backs=True)
    F_back = back_form_factors(origin, u, v)
    error = np.sqrt(np.maximum(F_back * (1 - F_back), 1 / rays) / rays)
    assert np.abs(back_cast - F_back).max() < 5 * error.max()
    assert (np.abs(back_cast - F_back) < 5 * error).all()
    assert F_back[:N * N, -1].min() > 0.02 and rectangle_form_factors(origin, u, v)[:N * N, -1].max() == 0


def test_only_backs_with_something_to_light_emit():
    """The panel's back emits (Phi_T = 2 E A); a closed room's lit ceiling faces out of the
    scene and a lamp box's faces into the solid it bounds: they emit from the front alone."""
    scene = panel_scene()[0]
    assert scene.back_emits.tolist() == [False] * (2 * N * N) + [True]
    assert scene.total_power == pytest.approx(2 * E_PANEL * 0.25)
    room, _, face = box_scene([0.5] * 6, [0, 1, 0, 0, 0, 0], n=2)
    assert not room.back_emits.any() and room.total_power == pytest.approx(1.0)
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), 2)
    lamp, lu, lv, _ = box_rectangles((0.2, 0.2, 0.05), 1, offset=(0.4, 0.4, 0.9))
    origin, u, v = np.vstack([origin, lamp]), np.vstack([u, lv]), np.vstack([v, lu])  # (its faces outwards)
    P = origin.shape[0]
    E = np.zeros(P)
    E[-6:] = 1.0
    boxed = PatchScene(*rectangles_to_mesh(origin, u, v), np.full(P, 0.5), E)
    assert not boxed.back_emits.any()
    E = np.zeros(P)
    E[np.flatnonzero(face == CEILING)] = 1.0
    E[-6:] = 0.0
    lit = PatchScene(*rectangles_to_mesh(origin, u, v), np.full(P, 0.5), E)
    assert not lit.back_emits.any()  # (the ceiling's back: nothing behind it, the lamp box in front)


# The discrete method (random exit) of every kind of solve: what the discrete system says.
METHODS = [
    dict(method="walk", direct_light="shot"),
    dict(method="walk", direct_light="gathered"),
    dict(method="jacobi", direct_light="shot"),
    dict(method="two_way"),
    dict(method="walk", direct_light="shot", estimator="biased_infinite", threshold=1e-3),
]


@pytest.mark.parametrize("settings", METHODS, ids=lambda s: "-".join(str(v) for v in s.values()))
def test_a_panels_back_lights_the_floor_as_the_discrete_system_says(panel, settings):
    """Every receiving patch's radiosity against B = E + R F B + R F_back E solved directly:
    batch-means z over at least 16 chunks (t with >= 15 degrees of freedom over 32 patches,
    P(max |t| > 6) < 1e-3), their mean square within a band around 1; the front alone (the
    solve before emitters had backs) would leave the floor under the panel 40 z dark or more."""
    scene, F, F_back, R, E = panel
    exact = solve_radiosity_system(F, R, E, F_back)[:, 0]
    front_only = solve_radiosity_system(F, R, E)[:, 0]
    r = solve(scene, paths=300_000, seed=5, exit_point="random", threads=1, **settings)
    assert r.chunks >= 16
    rows = np.arange(2 * N * N)
    se = np.sqrt(r.reflected_variance[rows, 0])
    z = (r.radiosity[rows, 0] - exact[rows]) / se
    assert np.abs(z).max() < 6.0, (np.abs(z).max(), r.radiosity[rows, 0] / exact[rows])
    assert 0.3 < np.mean(z**2) < 2.5, np.mean(z**2)
    assert ((exact[rows] - front_only[rows]) / se).max() > 40


def test_the_error_model_counts_both_sides(panel):
    """The finite walk's per-patch variance, measured over batch means, against table 1's exact
    per-path variance with Phi_T of both sides and the back's form factors: over 8 seeds, each
    seed's mean ratio over the receivers (its patches' estimates share its paths, so seeds are
    what is independent) averages to 1 within 4.5 of its standard errors (t of 7 degrees of
    freedom); with the front's Phi_T and light alone the formula is far off."""
    scene, F, F_back, R, E = panel
    var, _ = path_variances(F, R, E, scene.patch_area, F_back, scene.emitting_sides)
    one_side, _ = path_variances(F, R, E, scene.patch_area)
    paths, rows = 200_000, np.flatnonzero(var > 0)
    measured = np.array([solve(scene, paths=paths, seed=seed, method="walk", direct_light="shot", exit_point="random",
                               estimator="finite", threads=1).reflected_variance[rows, 0] * paths for seed in range(8)])
    ratios = (measured / var[rows]).mean(axis=1)
    t = (ratios.mean() - 1) / (ratios.std(ddof=1) / math.sqrt(len(ratios)))
    assert abs(t) < 4.5, (ratios.mean(), t)
    wrong = (measured / one_side[rows]).mean(axis=1)
    assert abs(wrong.mean() - 1) > 10 * wrong.std(ddof=1), wrong


def test_the_gathered_direct_light_sees_the_back(panel):
    """The first shot's direct irradiance (shadow and cosine rays) on every receiver: E F_back
    from the panel's back, E F from its front, each patch within 5 standard errors of 16
    independent rounds."""
    scene, F, F_back, R, E = panel
    exact = (F + F_back) @ E
    rounds = np.stack([direct_irradiance(scene, samples=64, seed=seed)[:, 0] for seed in range(16)])
    rows = np.arange(2 * N * N)
    mean, se = rounds.mean(axis=0)[rows], rounds.std(axis=0, ddof=1)[rows] / 4
    assert (np.abs(mean - exact[rows]) < 5 * np.maximum(se, 1e-12)).all(), (mean / exact[rows])
    assert (F_back @ E)[:N * N].min() > 20 * se[:N * N].max() / E_PANEL


def test_each_source_groups_light_counts_its_emitters_backs():
    """Per-source results of the panel scene with a wall patch emitting too (another emittance:
    another group, whose back faces out of the scene): each group's power is its sides' (the
    panel's 2 E A, the wall patch's E A), and each group's reflected power on the receivers, over
    8 seeds, is the discrete system's for its emitters alone within 4.5 of its standard errors (a
    t of 7 degrees of freedom passes 4.5 once in 350)."""
    scene, origin, u, v, R, E = panel_scene()
    wall = N * N + 1
    E = E.copy()
    E[wall] = 0.5
    scene = scene.with_materials(R, E)
    F, F_back = rectangle_form_factors(origin, u, v), back_form_factors(origin, u, v)
    A, rows = scene.patch_area, np.arange(2 * N * N)
    runs = [solve(scene, paths=100_000, seed=seed, exit_point="random", method="walk", direct_light="shot",
                  per_source=True, threads=1) for seed in range(8)]
    ps = runs[0].per_source
    panel, lit_wall = ps.patch_group[-1], ps.patch_group[wall]
    np.testing.assert_allclose(ps.power[panel], 2 * E_PANEL * A[-1])
    np.testing.assert_allclose(ps.power[lit_wall], 0.5 * A[wall])
    for group, alone in ((panel, np.where(np.arange(E.size) == E.size - 1, E, 0.0)), (lit_wall, np.where(np.arange(E.size) == wall, E, 0.0))):
        exact = solve_radiosity_system(F, R, alone, F_back)[:, 0] - alone
        truth = float((exact[rows] * A[rows]).sum())
        ratios = np.array([float(((r.per_source.radiosity[group, rows, 0] - alone[rows]) * A[rows]).sum()) / truth - 1
                           for r in runs])
        t = ratios.mean() / (ratios.std(ddof=1) / math.sqrt(len(ratios)))
        assert abs(t) < 4.5, (group, ratios.mean(), t)
