"""A room beside one small object far away: the scene's extent (its bounding box's diagonal) is
the far object's distance, and the room is small beside it. Its light must not depend on that
distance: no ray may leave the room through an offset or an inset of the whole scene's size.

The room is test_stress's closed box (exact discrete solution and exact per-patch variance of
the paper's walk, random exit); the far triangle is outside it, gets no light and changes
nothing inside. Bands as in test_stress (Z, exact variance) and test_two_way_stress (T, batch
means); where no exact reference holds (the hit-point exit, a lamp), the same room without the
far triangle, another seed, within both runs' batch noise.
"""
import numpy as np
import pytest
from boxes import rectangles_to_mesh
from test_stress import Z, _exact_box, _rotation
from test_two_way_stress import T

from addon.core import PatchScene, solve
from addon.core.lights import PointLight

PATHS = 100_000


def _room(distance, lamp=False, reflectivity=None):
    """test_stress's box, with a 1 m triangle ``distance`` m away along x (None: none), the
    box's emission replaced by a point lamp where ``lamp``. (scene, exact b, exact variance)."""
    origin, u, v, R, E, b, var = _exact_box()
    V, Tr, TP = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    if reflectivity is not None:
        R = np.full(P, reflectivity)
    if distance is not None:
        V = np.vstack([V, [[distance, 0, 0], [distance + 1, 0, 0], [distance, 1, 0]]])
        Tr = np.vstack([Tr, [[len(V) - 3, len(V) - 2, len(V) - 1]]])
        TP = np.append(TP, P)
        R, E = np.append(R, 0.5), np.append(E, 0.0)
    lights = []
    if lamp:
        E = np.zeros_like(E)
        lights = [PointLight(np.array([0.37, 0.44, 0.62]) * [1.0, 1.3, 0.7], np.ones(3))]
    return PatchScene(V, Tr, TP, R, E, lights), b, var


def _against_near_room(r, near):
    P = near.reflected.shape[0]
    return (r.reflected[:P, 0] - near.reflected[:, 0]) / np.sqrt(r.reflected_variance[:P, 0] + near.reflected_variance[:, 0])


# Beyond about 1e4 times the room's size, the float32 spacing of the scene's coordinates (6 mm
# at 1e5 m) sets the offsets: no light is lost, but rays leave the room's walls a few cm off
# them and its form factors drift (strict: a pass would mean the limit moved).
FLOAT32_LIMIT = pytest.mark.xfail(reason="offsets of 8 float32 spacings of a 1e5 m scene shift a 1 m room's form factors", strict=True)


@pytest.mark.parametrize("distance", [1e4, 1e5, 1e6])
def test_walk_loses_no_light_beside_a_far_object(distance):
    """The paper's walk (random exit) in the closed room: every path ends absorbed, none
    escapes. (Before offsets of the patches' own size, two thirds of the light escaped at 1e5
    m, all of it at 1e6 m.)"""
    scene, b, var = _room(distance)
    r = solve(scene, paths=PATHS, seed=81, threads=2, method="walk")
    assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0
    assert r.energy["escaped"].max() == 0
    assert (r.reflected[b.size:] == 0).all()  # the far triangle sees none of it


@pytest.mark.parametrize("distance", [1e4, pytest.param(1e5, marks=FLOAT32_LIMIT)])
def test_walk_matches_the_exact_solution_beside_a_far_object(distance):
    """Patch by patch, the exact solution within the walk's exact variance."""
    scene, b, var = _room(distance)
    r = solve(scene, paths=PATHS, seed=81, threads=2, method="walk")
    z = (r.reflected[: b.size, 0] - b) / np.sqrt(var / PATHS)
    assert np.abs(z).max() < Z, np.abs(z).max()


@pytest.mark.parametrize("method, exit_point, distance", [
    ("walk", "hit", 1e4), ("walk", "hit", 1e5), pytest.param("walk", "hit", 1e6, marks=FLOAT32_LIMIT),
    ("two_way", "random", 1e4), pytest.param("two_way", "random", 1e5, marks=FLOAT32_LIMIT),
])
def test_lamp_lit_room_beside_a_far_object(distance, method, exit_point):
    """Lit by a point lamp: the room is the room without the far triangle (both runs' batch
    noise), and with the walk no light escapes. (Before, the lamp's rays started 1e-5 of the
    scene's diagonal off it, 10 cm at 1e4 m: a third of its light escaped there with the walk,
    a fifth with the two-way iteration; the room was black at 1e5 m and the lamp was blamed.)"""
    scene, _, _ = _room(distance, lamp=True, reflectivity=0.5)
    r = solve(scene, paths=PATHS, seed=82, threads=2, method=method, exit_point=exit_point)
    near = solve(_room(None, lamp=True, reflectivity=0.5)[0], paths=PATHS, seed=83, threads=2, method=method, exit_point=exit_point)
    if method == "walk":
        assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0
    z = _against_near_room(r, near)
    assert np.abs(z).max() < (Z if method == "walk" else T), np.abs(z).max()


@pytest.mark.parametrize("distance", [1e4, pytest.param(1e5, marks=FLOAT32_LIMIT)])
def test_two_way_keeps_the_rooms_light_beside_a_far_object(distance):
    """The two-way iteration (what Automatic runs here): the exact solution within its batch
    noise, and the light it finds on no front (escaped) within the same noise of none. On main
    at 1e4 m 0.8% of the light was lost, 55% at 1e5 m."""
    scene, b, _ = _room(distance)
    r = solve(scene, paths=PATHS, seed=84, threads=2, method="two_way")
    t = (r.reflected[: b.size, 0] - b) / np.sqrt(r.reflected_variance[: b.size, 0])
    assert np.abs(t).max() < T, np.abs(t).max()
    assert r.energy["blocked"].max() == 0


def test_a_room_too_small_for_the_scenes_float32_positions_is_reported():
    """Where the float32 spacing of the scene's coordinates sets offsets of more than 2% of a
    patch's size (the room at 1e5 m, whose per-patch results drift), the build says how many
    patches and how far; at 1e4 m (exact within the noise, above) and alone it says nothing."""
    with pytest.warns(UserWarning, match=r"25 patches are small beside the scene's extent .* up to 0\.0477 off them"):
        _room(1e5)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _room(1e4)
        _room(None)


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_no_ray_slips_out_of_a_rotated_room_beside_a_far_object(exit_point):
    """A room of 4 x 4 patches a face, rotated off the axes, beside a triangle 1e4 m away: no
    path escapes. (Merged into rectangles of cells, the faces met in T-junctions whose float32
    cracks, a spacing of the scene's coordinates wide, let 1 and 7 paths in 200,000 out.)"""
    origin, u, v, R, E, _, _ = _exact_box(n=4)
    V, Tr, TP = rectangles_to_mesh(origin, u, v)
    V = np.vstack([(V - 0.5) @ _rotation(5).T, [[1e4, 0, 0], [1e4 + 1, 0, 0], [1e4, 1, 0]]])
    P = origin.shape[0]
    scene = PatchScene(V, np.vstack([Tr, [[len(V) - 3, len(V) - 2, len(V) - 1]]]), np.append(TP, P),
                       np.append(R, 0.5), np.append(E, 0.0))
    r = solve(scene, paths=200_000, seed=3, threads=2, method="walk", exit_point=exit_point)
    assert r.path_ends["escaped"] == 0 and r.path_ends["blocked"] == 0
