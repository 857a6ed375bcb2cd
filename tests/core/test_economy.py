"""What a scene does not need costs nothing: a scene that reflects nothing traces one
bounce per path; grey walks never touch per-channel weights; rays that leave an open scene end
at once (test_stress.test_open_scene_everything_escapes)."""
import numpy as np
import pytest

from addon.core import solve
from addon.core.methods.tables import WalkTables
from addon.core.methods.walk import walk_chunk
from boxes import box_scene


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
@pytest.mark.parametrize("exit_point", ["random", "hit"])
@pytest.mark.parametrize("colour", [False, True])
def test_a_scene_that_reflects_nothing_traces_one_bounce(estimator, exit_point, colour):
    emission = [[0, 0, 0], [1.0, 0.5, 0.2], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]] if colour else [0, 1.0, 0, 0, 0, 0]
    scene, _, _ = box_scene([0.0] * 6, emission, (1.0, 1.4, 0.8), n=2)
    N = 20_000
    r = solve(scene, estimator=estimator, paths=N, seed=3, exit_point=exit_point)
    assert r.rays == N  # every path: one ray, then it ends
    ended = "absorbed" if estimator == "finite" else "threshold"
    assert r.path_ends[ended] == N
    assert np.array_equal(r.radiosity, scene.emission)
    e = r.energy
    np.testing.assert_allclose(e["absorbed"], e["emitted"], rtol=1e-12)
    assert (e["undistributed"] == 0).all()


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_grey_walks_never_touch_per_channel_weights(estimator, exit_point):
    scene, _, _ = box_scene([0.3, 0.5, 0.7, 0.9, 0.6, 0.8], [0, 2.0, 0, 0, 0, 0], n=2)
    assert scene.is_grey
    tables = WalkTables(scene, estimator, 1e-3, exit_point)
    assert tables.channels == 1
    reference = walk_chunk(tables, 5_000, np.random.default_rng(1))
    # Without the per-channel weights and reflectivities at all the walk runs, and gives the same numbers.
    tables.survivor_weight = tables.start_weight = tables.reflectivity = None
    bare = walk_chunk(tables, 5_000, np.random.default_rng(1))
    assert bare.rays == reference.rays
    assert np.array_equal(bare.incident, reference.incident)
    assert bare.incident.shape == (1, scene.patch_count)


def test_colour_walks_make_their_weights_for_the_patches_and_sources_asked():
    """R_jc / R_bar_j (0 where R_bar is 0) and E_ic / E_bar_i (0 where nothing is emitted), made
    for the columns a step asks for (no (C,P) tables beside the scene's materials), equal to
    the whole tables' columns bit for bit; a light's emitters (P + its index) start with its
    power's weights."""
    from addon.core.lights.lights import PointLight

    R = [[0.3, 0.5, 0.7], [0.6, 0.2, 0.4], [0.7, 0.7, 0.1], [0.5, 0.5, 0.5], [0.4, 0.6, 0.2], [0.0, 0.0, 0.0]]
    E = [[0, 0, 0], [1.0, 0.5, 2.0], [0, 0, 0], [0, 0, 0], [0, 0, 0], [0.5, 0.5, 0.5]]
    scene, _, _ = box_scene(R, E, n=2)
    tables = WalkTables(scene, "finite", 1e-3, "random")
    assert tables.channels == 3 and not any(v.dtype == np.float64 and v.shape == (3, scene.patch_count)
                                            for k, v in vars(tables).items() if isinstance(v, np.ndarray) and k != "reflectivity")
    R_bar = scene.reflectivity.mean(axis=1)
    E_bar = scene.emission.mean(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        expected_survivor = np.where(R_bar > 0, scene.reflectivity.T / R_bar, 0.0)
        expected_start = np.where(E_bar > 0, scene.emission.T / E_bar, 0.0)
    ids = np.random.default_rng(3).integers(0, scene.patch_count, 500)
    np.testing.assert_array_equal(tables.survivor_weight(ids), expected_survivor[:, ids])
    np.testing.assert_array_equal(tables.start_weight(ids), expected_start[:, ids])
    from addon.core import PatchScene

    lit = PatchScene(scene.vertices, scene.triangles, scene.triangle_patch, scene.reflectivity, scene.emission,
                     lights=[PointLight(np.array([0.5, 0.5, 0.5]), np.array([2.0, 1.0, 0.5]))])
    tables = WalkTables(lit, "finite", 1e-3, "random")
    P = lit.patch_count
    power = lit.lights.power[0]
    np.testing.assert_array_equal(tables.start_weight(np.array([P, 7, P])),
                                  np.stack([power / power.mean(), expected_start[:, 7], power / power.mean()], axis=1))


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_patches_no_path_can_reach_cost_nothing(estimator, exit_point):
    """A room with a closed crate in it, and the same room where the crate also has inner
    walls (facing into the crate, which no ray from outside can reach): with the same seed,
    every path is the same ray for ray, the unreachable patches get nothing, and no ray is
    spent on them."""
    from addon.core import PatchScene
    from boxes import box_rectangles, rectangles_to_mesh

    room = box_rectangles((1.0, 1.0, 1.0), n=3)
    crate = box_rectangles((0.3, 0.3, 0.3), n=2, offset=(0.35, 0.35, 0.05))
    crate_out = (crate[0], crate[2], crate[1])  # u and v swapped: faces turned outwards
    inner = box_rectangles((0.26, 0.26, 0.26), n=4, offset=(0.37, 0.37, 0.07))[:3]  # facing in

    def scene(parts):
        origin, u, v = (np.concatenate(x) for x in zip(*parts))
        V, T, TP = rectangles_to_mesh(origin, u, v)
        P = origin.shape[0]
        E = np.zeros(P)
        E[9 + 4] = 3.0  # the ceiling's middle patch
        return PatchScene(V, T, TP, np.full(P, 0.6), E)

    plain = scene([room[:3], crate_out])
    with_inner = scene([room[:3], crate_out, inner])
    assert with_inner.patch_count == plain.patch_count + 96
    a = solve(plain, estimator=estimator, paths=40_000, seed=81, exit_point=exit_point)
    b = solve(with_inner, estimator=estimator, paths=40_000, seed=81, exit_point=exit_point)
    assert a.rays == b.rays and a.path_ends == b.path_ends
    np.testing.assert_array_equal(b.radiosity[: plain.patch_count], a.radiosity)
    assert not b.reflected[plain.patch_count :].any()
