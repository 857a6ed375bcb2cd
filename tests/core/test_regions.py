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
from addon.core.lights.lights import PointLight

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


@pytest.mark.parametrize("distance", [1e4, 1e5, 1e6])
def test_walk_matches_the_exact_solution_beside_a_far_object(distance):
    """Patch by patch, the exact solution within the walk's exact variance."""
    scene, b, var = _room(distance)
    r = solve(scene, paths=PATHS, seed=81, threads=2, method="walk")
    z = (r.reflected[: b.size, 0] - b) / np.sqrt(var / PATHS)
    assert np.abs(z).max() < Z, np.abs(z).max()


@pytest.mark.parametrize("method, exit_point, distance", [
    ("walk", "hit", 1e4), ("walk", "hit", 1e5), ("walk", "hit", 1e6),
    ("two_way", "random", 1e4), ("two_way", "random", 1e5), ("two_way", "random", 1e6),
    ("two_way", "hit", 1e6), ("walk", "random", 1e6),
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


@pytest.mark.parametrize("distance", [1e4, 1e5, 1e6])
def test_two_way_keeps_the_rooms_light_beside_a_far_object(distance):
    """The two-way iteration (what Automatic runs here): the exact solution within its batch
    noise, and the light it finds on no front (escaped) within the same noise of none. On main
    at 1e4 m 0.8% of the light was lost, 55% at 1e5 m."""
    scene, b, _ = _room(distance)
    r = solve(scene, paths=PATHS, seed=84, threads=2, method="two_way")
    t = (r.reflected[: b.size, 0] - b) / np.sqrt(r.reflected_variance[: b.size, 0])
    assert np.abs(t).max() < T, np.abs(t).max()
    assert r.energy["blocked"].max() == 0


def test_far_parts_of_the_scene_take_region_frames_of_their_own():
    """The room and the far triangle are two regions (each traced in its own frame, so the
    room's offsets are its patches' own size at any distance); an ordinary scene is one frame,
    traced as before."""
    for distance in (1e4, 1e6):
        g = _room(distance)[0].geometry
        assert g.regions is not None and g.regions.count == 2
        P = g.patch_count
        assert (g.regions.patch_region[: P - 1] == g.regions.patch_region[0]).all()
        assert g.regions.patch_region[P - 1] != g.regions.patch_region[0]
        np.testing.assert_allclose(g.patch_ray_offset[: P - 1], 1e-2 * np.sqrt(g.patch_area[: P - 1]) / g.diagonal, rtol=1e-9)
    assert _room(None)[0].geometry.regions is None


def _room_on_a_strip(length, pieces=1):
    """test_stress's box beside a 1 m wide strip ``length`` m long along x, of ``pieces`` patches
    (each then length / pieces m long), which touches its floor's edge: no empty gap parts them.
    (scene, exact b, exact variance of the box)."""
    origin, u, v, R, E, b, var = _exact_box()
    P = origin.shape[0]
    step = length / pieces
    strip = np.stack([np.arange(pieces) * step, np.full(pieces, 1.3), np.zeros(pieces)], axis=1)  # (the box is 1.3 deep)
    V, Tr, TP = rectangles_to_mesh(np.vstack([origin, strip]), np.vstack([u, np.tile([step, 0, 0], (pieces, 1))]),
                                   np.vstack([v, np.tile([0, 1, 0], (pieces, 1))]))
    scene = PatchScene(V, Tr, TP, np.append(R, np.full(pieces, 0.5)), np.append(E, np.zeros(pieces)))
    return scene, b, var


def test_a_room_on_a_strip_of_one_long_face_is_a_region_of_its_own():
    """A box standing on one face 1e5 m long (a terrain of large faces, no gap between them):
    the long face, large enough for a frame of the whole scene, is a region apart, and the box
    is its exact solution patch by patch."""
    scene, b, var = _room_on_a_strip(1e5)
    assert scene.geometry.regions is not None and scene.geometry.regions.count == 2
    r = solve(scene, paths=PATHS, seed=87, threads=2, method="walk")
    z = (r.reflected[: b.size, 0] - b) / np.sqrt(var / PATHS)
    assert np.abs(z).max() < Z, np.abs(z).max()


def test_a_room_too_small_for_its_regions_float32_positions_is_reported():
    """Where a region is itself large beside its patches (a room on a strip 1e5 m long of 50 m
    pieces: no gap parts them, and no piece is large enough for a frame of the whole), float32
    spacings of its coordinates set offsets of more than 2% of a patch's size: the build says
    how many patches and how far; beside a far object (two regions) and alone it says nothing."""
    with pytest.warns(UserWarning, match=r"\d+ patches are small beside the scene's extent .* off them"):
        g = _room_on_a_strip(1e5, pieces=2000)[0].geometry
    assert g.regions is None
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _room_on_a_strip(1e3, pieces=20)
        _room(1e6)
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


def _lit_open_box(far):
    """boxes.open_box_with_card with a light of every kind besides its emitting floor, aimed at
    itself, and 1 m triangles at the points ``far`` (n,3) around it: a sky of far objects."""
    from boxes import open_box_with_card

    from addon.core.lights.lights import AreaLight, SunLight, WorldLight

    base = open_box_with_card()
    V, Tr, TP = base.vertices, base.triangles, base.triangle_patch
    P = base.patch_count
    R, E = base.reflectivity[:, 0], base.emission[:, 0]
    for k, p in enumerate(far):
        V = np.vstack([V, p + np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.3]])])
        Tr = np.vstack([Tr, [[len(V) - 3, len(V) - 2, len(V) - 1]]])
        TP, R, E = np.append(TP, P + k), np.append(R, 0.5), np.append(E, 0.0)
    lights = [
        PointLight(np.array([0.5, 0.5, 0.3]), np.array([1.0, 0.8, 0.6]), radius=0.05),
        AreaLight(np.array([0.7, 0.3, 0.9]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), np.array([0, 0, -1.0]), np.full(3, 2.0)),
        SunLight(np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]), np.full(3, 1.5), angle=0.1),
        WorldLight(irradiance=np.array([0.2, 0.3, 0.4])),
    ]
    return PatchScene(V, Tr, TP, R, E, lights, aim=(np.full(3, 0.5), 0.9))


# Eight far triangles in different directions, from 1e5 to 1e6 m: none in the sun's way.
SKY_OF_OBJECTS = np.array([[1e5, 0, 0], [-3e5, 2e5, 0], [0, 1e6, -5e4], [0, -4e5, -2e5],
                           [7e5, -7e5, -1e5], [-1e6, -1e6, 0], [2e5, 5e5, -9e5], [-6e5, 0, -1e6]])


@pytest.mark.parametrize("method, exit_point", [("walk", "random"), ("walk", "hit"), ("two_way", "random")])
def test_every_source_kind_lights_a_box_in_a_sky_of_far_objects_as_alone(method, exit_point):
    """An open box lit by its floor, a point, an area light, the sun and the world, among eight
    far triangles (each its own region): the box comes out as without them, within both runs'
    batch noise, for every source kind at once."""
    scene = _lit_open_box(SKY_OF_OBJECTS)
    assert scene.geometry.regions.count == 1 + len(SKY_OF_OBJECTS)
    r = solve(scene, paths=PATHS, seed=85, threads=2, method=method, exit_point=exit_point)
    near = solve(_lit_open_box(np.zeros((0, 3))), paths=PATHS, seed=86, threads=2, method=method, exit_point=exit_point)
    P = near.reflected.shape[0]
    for c in range(3):
        z = (r.reflected[:P, c] - near.reflected[:, c]) / np.sqrt(r.reflected_variance[:P, c] + near.reflected_variance[:, c])
        assert np.abs(z).max() < (Z if method == "walk" else T), (c, np.abs(z).max())


def test_rays_between_regions_and_from_beyond_them_meet_what_they_aim_at():
    """The region tracer against float64 geometry: a 1 m card of 4 x 4 patches facing up and a
    1 m triangle 1e6 m away above it. Rays from the card's leaving points to interior points of
    the far triangle meet it, at its distance (to float32's precision of the distance). Rays
    from 2e6 m beyond the scene (as a sun's) aimed at the card's middle meet the card at their
    distance: given in float32 at 2e6 m from any frame's centre, their origins and directions
    are rounded by about 0.1 m there, which no frame can undo (which triangle they meet is
    that rounding's), but the tracer adds none of its own."""
    n = 4
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    origin = np.stack([i.ravel() / n, j.ravel() / n, np.zeros(n * n)], axis=1)
    V, Tr, TP = rectangles_to_mesh(origin, np.tile([1 / n, 0, 0], (n * n, 1)), np.tile([0, 1 / n, 0], (n * n, 1)))
    V = np.vstack([V, [[0, 0, 1e6], [0, 1, 1e6], [1, 0, 1e6]]])  # (facing down)
    Tr = np.vstack([Tr, [[len(V) - 3, len(V) - 2, len(V) - 1]]])
    scene = PatchScene(V, Tr, np.append(TP, n * n), np.full(n * n + 1, 0.5), np.append(np.ones(n * n), 0.0))
    g = scene.geometry
    assert g.regions.count == 2
    rng = np.random.default_rng(7)
    far_triangle = np.flatnonzero(g.triangle_patch == n * n)[0]
    card = np.flatnonzero(g.triangle_patch < n * n)
    shift = g.regions.centre[g.regions.of(g.triangle_patch)]  # (T,3) each triangle's frame

    def interior(triangles):
        bary = rng.dirichlet((4.0, 4.0, 4.0), triangles.size)  # (clear of the edges)
        return np.einsum("nk,nki->ni", bary, g.corners[triangles] + shift[triangles][:, None, :])

    start = card[rng.integers(0, card.size, 500)]
    origins = g.frames_of(start)[0:3].T.astype(np.float64) + shift[start]
    target = interior(np.full(500, far_triangle))
    middle = card[np.isin(g.triangle_patch[card], [5, 6, 9, 10])]  # (the inner 2 x 2 patches)
    goal = interior(middle[rng.integers(0, middle.size, 500)])
    direction = rng.normal(size=(500, 3))
    direction[:, 2] = -np.abs(direction[:, 2]) - 1  # (down onto the card's front)
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    beyond = goal - 2e6 / g.diagonal * direction
    o = np.vstack([origins, beyond])
    d = np.vstack([target - origins, goal - beyond])
    distance = np.linalg.norm(d, axis=1)
    d /= distance[:, None]
    # (the rays from beyond start in the far triangle's frame, as a sun's may)
    region = np.concatenate([g.regions.of(g.triangle_patch[start]), g.regions.of(np.full(500, n * n))])
    local = (o - g.regions.centre[region]).astype(np.float32)
    hit, _, _, t, _ = g.tracer.first_hit_barycentric(local, d.astype(np.float32), region)
    assert (hit[:500] == far_triangle).all()
    assert np.isin(hit[500:], card).all()
    np.testing.assert_allclose(t, distance, rtol=1e-6)



def test_a_room_with_a_finely_divided_card_is_one_frame():
    """A closed 7 x 5 x 2.7 m room (4 x 4 patches a face, a ceiling patch glowing) with a 36 cm
    card of 8 mm patches on a table (as a subdivided vase's: a nine-hundredth of the room's
    diagonal): their offsets are their own size, far above float32's spacing of the room's
    coordinates, so the room stays one frame. (Before, any patch below a thousandth of the
    diagonal split the scene: the card went into a region whose box lies inside the room's, and
    every ray of the room was tested against that box and traced in it too: the walkthrough's
    studio flat ran 1.5x the time a path.) No light leaves the closed room."""
    from boxes import box_rectangles

    origin, u, v, face = box_rectangles((7.0, 5.0, 2.7), 4)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    cells = 45
    side = 0.36 / cells
    i, j = (x.ravel() for x in np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij"))
    card = rectangles_to_mesh(np.stack([5.3 + side * i, np.full(i.size, 1.9), 0.76 + side * j], axis=1),
                              np.tile([side, 0.0, 0.0], (i.size, 1)), np.tile([0.0, 0.0, side], (i.size, 1)))
    P, count = origin.shape[0], origin.shape[0] + i.size
    emission = np.zeros(count)
    emission[np.flatnonzero(face == 1)[5]] = 1.0
    scene = PatchScene(np.vstack([vertices, card[0]]), np.vstack([triangles, card[1] + len(vertices)]),
                       np.concatenate([triangle_patch, card[2] + P]), np.full(count, 0.5), emission)
    g = scene.geometry
    assert g.diagonal > 1e3 * side  # (below a thousandth of it: what split the scene before)
    assert g.patch_ray_offset is not None and g.regions is None
    r = solve(scene, paths=20_000, seed=1, threads=1)
    assert r.energy["escaped"].max() < 1e-9 * r.energy["emitted"].max()
