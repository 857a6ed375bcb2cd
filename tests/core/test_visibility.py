"""Patches partly inside other objects (rooms of overlapping boxes): their visible part found,
their light spread over it, nothing emitted or reflected from inside a neighbour.

Exact references: a closed room of uniform emittance E and reflectivity R has B = E / (1 - R)
on every inner patch, however its walls overlap; and the discrete system on the visible
rectangles (closed-form form factors) is what the random exit estimates.
"""
import threading

import numpy as np
import pytest

from addon.core import PatchScene, solve
from addon.core.scene.geometry_build import build_geometry
from addon.core.estimate.reference import path_variances, rectangle_form_factors, solve_radiosity_system
from addon.core.lights.sampling import patch_point_rows
from addon.core.scene import visibility
from boxes import rectangles_to_mesh
from overlap_boxes import slab_room, slab_scene, solid_box, visible_rectangles

E, R = 1.0, 0.5
SEEDS = (11, 12, 13, 14)


def _area(u, v):
    return np.linalg.norm(np.cross(u, v), axis=1)


@pytest.fixture(scope="module")
def uniform_room():
    return slab_scene(R, E)


def test_visible_fraction_is_the_exact_rectangle(uniform_room):
    """Every inner patch's f is its visible rectangle's share, exactly: 1, 1/2 or 1/4."""
    scene, origin, u, v, inner = uniform_room
    vo, vu, vv = visible_rectangles(origin, u, v)
    analytic = _area(vu, vv) / _area(u, v)
    f = scene.patch_area / _area(u, v)
    assert set(np.round(analytic[inner], 12)) == {0.25, 0.5, 1.0}
    np.testing.assert_allclose(f[inner], analytic[inner], rtol=1e-12)
    assert np.array_equal(scene.geometry.buried.visible_fraction(scene.patch_count)[inner], analytic[inner])


# (method, exit, direct light): every method reads its points and areas through the same hooks.
METHODS = [
    dict(method="walk"),
    dict(method="walk", exit_point="hit"),
    dict(method="walk", direct_light="gathered"),
    dict(method="two_way"),
    dict(method="jacobi"),
]


@pytest.mark.parametrize("settings", METHODS, ids=lambda s: "-".join(str(v) for v in s.values()))
def test_uniform_room_of_overlapping_slabs_is_exact(uniform_room, settings):
    """B = E / (1 - R) on every inner patch, edge and corner patches included (today's main
    loses the buried halves' light and gives edge patches about 0.8 of it). Batch-means
    variances with at least 16 chunks: t with >= 15 degrees of freedom, 90 patches,
    P(max |t| > 6) < 3e-3."""
    scene, _, _, _, inner = uniform_room
    r = solve(scene, paths=400_000, seed=7, **settings)
    assert r.chunks >= 16
    exact = E / (1 - R)
    b = r.radiosity[inner, 0]
    z = (b - exact) / np.sqrt(r.reflected_variance[inner, 0])
    assert np.abs(z).max() < 6.0, (np.abs(z).max(), b.min(), b.max())


def test_light_is_not_lost_into_buried_parts():
    """With only the inner faces emitting, no ray leaves from inside a neighbour: nothing meets
    a back face, every path ends by absorption, and the run's accounts balance exactly."""
    scene, *_ = slab_scene(R, lambda inner: np.where(inner, E, 0.0))
    for settings in ({}, {"exit_point": "hit"}):
        r = solve(scene, paths=100_000, seed=3, **settings)
        assert np.all(r.energy["blocked"] == 0) and np.all(r.energy["escaped"] == 0), r.energy
        assert r.path_ends.get("blocked", 0) == 0
        np.testing.assert_allclose(r.energy["absorbed"], r.energy["emitted"], rtol=1e-9)


@pytest.fixture(scope="module")
def lit_room():
    """Per-face reflectivities, only the inner ceiling emitting; the exact discrete solution on
    the visible rectangles and the table-1 variances."""
    face_R = {(0, 0): 0.3, (0, 1): 0.6, (1, 0): 0.7, (1, 1): 0.5, (2, 0): 0.4, (2, 1): 0.65}
    origin, u, v, inner = slab_room()
    normal = np.cross(u, v)
    axis = np.argmax(np.abs(normal), axis=1)
    side = (origin[np.arange(origin.shape[0]), axis] >= 1.0).astype(int)  # slabs at 1 are the upper ones
    refl = np.array([face_R[(a, s)] for a, s in zip(axis, side)])
    ceiling = inner & (axis == 2) & (side == 1)
    emission = np.where(ceiling, 1.0, 0.0)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    scene = PatchScene(V, T, TP, refl, emission)
    vo, vu, vv = visible_rectangles(origin[inner], u[inner], v[inner])
    F = rectangle_form_factors(vo, vu, vv)
    A = _area(vu, vv)
    B = solve_radiosity_system(F, refl[inner], emission[inner])[:, 0]
    var, _ = path_variances(F, refl[inner], emission[inner], A)
    return scene, inner, F, A, B, var


def test_direct_solve_of_the_overlapping_room(lit_room):
    """The random exit's expectation is the discrete solution on the visible rectangles (their
    form factors in closed form): z within 4 over 90 patches (P(max |z| > 4) < 6e-3), table 1's
    exact variances with the visible areas."""
    scene, inner, F, A, B, var = lit_room
    np.testing.assert_allclose(F.sum(axis=1), 1.0, atol=1e-12)  # the visible rectangles close the room
    N = 200_000
    runs = [solve(scene, estimator="finite", paths=N, seed=s) for s in SEEDS]
    b = np.mean([r.reflected[inner, 0] for r in runs], axis=0)
    z = (b - (B - scene.emission[inner, 0])) / np.sqrt(var / (N * len(SEEDS)))
    assert np.abs(z).max() < 4.0, np.abs(z).max()
    np.testing.assert_allclose(scene.patch_area[inner], A, rtol=1e-12)  # (f_j A_j: the visible areas)
    # Table 1 with the visible areas is the walk's own variance: the measured batch variances
    # (32 batches a run, 4 runs, 90 patches) average to it within a few of their spread.
    measured = np.mean([r.reflected_variance[inner, 0] for r in runs], axis=0) * N
    ratio = float(np.mean(measured / var))
    assert abs(ratio - 1) < 5 * np.sqrt(2 / (31 * len(SEEDS) * inner.sum())) * 2, ratio


def test_the_same_room_without_overlaps_is_untouched():
    """Slabs that only meet at the cube's edges: nothing is buried, the geometry is built as
    before, bit for bit."""
    origin, u, v, _ = slab_room(overlap=False)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    g = build_geometry(V, T, TP, origin.shape[0])
    assert g.buried is None
    assert np.array_equal(g.patch_area, build_geometry(V, T, TP, origin.shape[0], visible_parts=False).patch_area)


def test_points_are_drawn_uniformly_on_the_visible_part(uniform_room):
    """The remapped uniforms put every point of a partly buried patch on its visible rectangle,
    uniformly (chi-square over a 4 x 4 grid of it: 15 degrees of freedom, < 40 at p 5e-4)."""
    scene, origin, u, v, inner = uniform_room
    g = scene.geometry
    vo, vu, vv = visible_rectangles(origin, u, v)
    corner = np.flatnonzero(inner & (_area(vu, vv) < 0.3 * _area(u, v)))[0]
    rng = np.random.default_rng(5)
    n = 160_000
    u0, u1 = rng.random((2, n), dtype=np.float32)
    x = g.to_world(patch_point_rows(g, np.full(n, corner), None, u0, u1).T)
    o, a, b = vo[corner], vu[corner], vv[corner]
    s = (x - o) @ a / (a @ a)
    t = (x - o) @ b / (b @ b)
    assert s.min() > -1e-5 and s.max() < 1 + 1e-5 and t.min() > -1e-5 and t.max() < 1 + 1e-5
    counts = np.histogram2d(s, t, bins=4, range=[[0, 1], [0, 1]])[0].ravel()
    expected = n / 16
    assert ((counts - expected) ** 2 / expected).sum() < 40


def _card(origin, u, v):
    return np.asarray([origin], float), np.asarray([u], float), np.asarray([v], float)


def _box_and_cards(cards):
    o, u, v, _ = solid_box((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), (2, 2, 2))
    for co, cu, cv in cards:
        o, u, v = np.vstack([o, co]), np.vstack([u, cu]), np.vstack([v, cv])
    V, T, TP = rectangles_to_mesh(o, u, v)
    return build_geometry(V, T, TP, o.shape[0]), o.shape[0] - len(cards)


@pytest.mark.parametrize("card", [
    _card((1.0, 0.2, 0.3), (0, 0.6, 0), (1.5, 0, 0)),     # standing out of the box's side, edge on it (T)
    _card((1.0, 0.0, 1.0), (1.5, 0, 0), (0, 1.0, 0)),     # the box's top face carried on past its edge (L)
    _card((1.0, 1.0, 0.5), (0.8, 0.8, 0), (0, 0, 0.5)),   # touching only the box's vertical edge
], ids=["T", "L", "edge"])
def test_a_one_sided_plane_touching_a_box_is_not_buried(card):
    """A card meeting a box only along its boundary keeps its whole area, and so does the box."""
    g, first_card = _box_and_cards([card])
    assert g.buried is None


def test_a_floor_under_a_box_is_buried_under_it_only():
    """A one-sided floor a closed box stands on (the box's bottom on it): the square under the
    box is inside the box, the rest is not (its 2 x 2 m, the box's 1 x 1)."""
    g, first = _box_and_cards([_card((-0.5, -0.5, 0.0), (2.0, 0, 0), (0, 2.0, 0))])
    f = g.buried.visible_fraction(g.patch_count)
    assert f[first] == 0.75 and np.all(f[:first] == 1.0)


def test_a_card_through_a_box_loses_its_inside_and_a_table_top_buries_nothing():
    """A one-sided card running into a box loses exactly the part inside; a one-sided table top
    (seen from behind by the floor under it) with a box leg crossing the floor buries only the
    floor under the leg: the floor's probes near the horizon escape under the top."""
    through = _card((0.5, 0.25, 0.5), (1.0, 0, 0), (0, 0.5, 0))  # half inside the box, face up
    g, first = _box_and_cards([through])
    assert g.buried.visible_fraction(g.patch_count)[first] == 0.5
    floor = _card((-3.0, -3.0, 0.0), (4.0, 0, 0), (0, 4.0, 0))     # the box is the leg: x, y in [0, 1]
    top = _card((-3.0, -3.0, 1.5), (4.0, 0, 0), (0, 4.0, 0))       # face up, the floor sees its back
    g, first = _box_and_cards([floor, top])
    f = g.buried.visible_fraction(g.patch_count)
    assert f[first] == 1 - 1 / 16 and f[first + 1] == 1.0


def test_visibility_cells_map_uniforms_onto_uniforms():
    """remap keeps points of wholly visible patches as they are and sends the others' into
    their visible cells, each visible cell equally often."""
    g, first = _box_and_cards([_card((0.5, 0.25, 0.5), (1.0, 0, 0), (0, 0.5, 0))])
    b = g.buried
    n = visibility.CELLS**2 * 400
    rng = np.random.default_rng(1)
    u0, u1 = rng.random((2, n), dtype=np.float32)
    patch = np.where(np.arange(n) % 2 == 0, first, 0).astype(np.int32)
    before = u0.copy(), u1.copy()
    b.remap(patch, None, u0, u1)
    other = patch == 0
    assert np.array_equal(u0[other], before[0][other]) and np.array_equal(u1[other], before[1][other])
    cell = np.floor(u0[~other] * visibility.CELLS).astype(int) * visibility.CELLS + np.floor(u1[~other] * visibility.CELLS).astype(int)
    visible = b.cells[b.first[0]:b.first[1]]
    assert np.isin(cell, visible).mean() > 1 - 1e-4  # (float32 may round a point onto a cell's far side)
    counts = np.bincount(cell, minlength=visibility.CELLS**2)[visible]
    expected = cell.size / visible.size
    assert ((counts - expected) ** 2 / expected).sum() < visible.size + 6 * np.sqrt(2 * visible.size)


@pytest.mark.parametrize("name", ["fig1_r0.2", "fig1_r0.5", "fig1_r0.8", "fig4_room", "fig6_room", "cornell_box",
                                  "pinned:card", "pinned:mixed"])
def test_no_sample_scene_has_a_buried_patch(name):
    """f_j = 1 on every patch of every sample scene (their boxes stand on the floor with no
    bottom, whole floor patches under them: those are buried whole and keep their area), so the
    geometry, and every pinned result, is bit for bit what it was."""
    import sample_scenes
    from pinned_cases import SCENES

    scene = SCENES[name.split(":")[1]]() if name.startswith("pinned:") else sample_scenes.build(name).scene
    assert scene.geometry.buried is None
    g = scene.geometry
    plain = build_geometry(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count, visible_parts=False)
    assert np.array_equal(g.patch_area, plain.patch_area)
    crossed = visibility.crossed_patches(g)
    if crossed.size:  # (patches some surface crosses: each is wholly visible or wholly buried)
        bins = np.where(g.patch_parallelogram[crossed], 1, visibility.TRIANGLE_BINS)
        cells = np.concatenate([np.arange(b * visibility.CELLS**2) for b in bins])
        patch = np.repeat(crossed, bins * visibility.CELLS**2)
        buried = visibility.buried_points(g, patch, *visibility.cell_uniforms(cells, np.repeat(bins, bins * visibility.CELLS**2)))
        share = np.bincount(np.searchsorted(crossed, patch), weights=buried) / (bins * visibility.CELLS**2)
        assert np.all((share == 0) | (share == 1))


def _triangle_share(s0, s1, t0, t1, n=200_000):
    """Share of the triangle a, b >= 0, a + b <= 1 inside [s0, s1] x [t0, t1] (midpoint rule
    in a over a piecewise linear integrand: exact to about n^-2)."""
    a = s0 + (np.arange(n) + 0.5) / n * (s1 - s0)
    return 2 * (np.clip(np.minimum(t1, 1 - a) - t0, 0, None).sum() * (s1 - s0) / n)


def test_triangle_patches_of_overlapping_slabs_are_exact():
    """The same room with every rectangle cut into two right triangles, each a patch of its own
    (no parallelograms: the triangles' own in-plane rays, cells over each triangle's folded
    square, whose lines run along its legs): f is the visible share of each triangle, and
    B = E / (1 - R) on every inner patch for the walk and the two-way iteration. (The
    triangles buried whole are left dark: an emitter inside another object would shoot from
    there, and the walk's rays from inside can land on the buried halves of its neighbours.)"""
    origin, u, v, inner = slab_room()
    corners, _, _ = rectangles_to_mesh(origin, u, v)  # (o, o + u, o + u + v, o + v) of each
    base = 4 * np.arange(origin.shape[0])[:, None]
    T = np.concatenate([base + [0, 1, 3], base + [2, 3, 1]], axis=1).reshape(-1, 3)  # right angles at o, o + u + v
    P = 2 * origin.shape[0]
    scene = PatchScene(corners, T, np.arange(P), np.full(P, R), np.full(P, E))
    assert not scene.geometry.patch_parallelogram.any()
    vo, vu, vv = visible_rectangles(origin, u, v)
    uu, vv2 = (u * u).sum(axis=1), (v * v).sum(axis=1)
    s0 = ((vo - origin) * u).sum(axis=1) / uu
    s1 = s0 + _area(vu, vv) / np.maximum(_area(vu, vv), 1e-300) * np.linalg.norm(vu, axis=1) / np.sqrt(uu)
    t0 = ((vo - origin) * v).sum(axis=1) / vv2
    t1 = t0 + np.linalg.norm(vv, axis=1) / np.sqrt(vv2)
    rows = np.flatnonzero(inner)
    analytic = np.ones(P)
    for k in rows:
        analytic[2 * k] = _triangle_share(s0[k], s1[k], t0[k], t1[k])
        analytic[2 * k + 1] = _triangle_share(1 - s1[k], 1 - s0[k], 1 - t1[k], 1 - t0[k])
    whole = analytic == 0  # (triangles of the corner rectangles wholly inside: they keep their area)
    inner2 = np.repeat(inner, 2) & ~whole
    b = scene.geometry.buried
    f = b.visible_fraction(P)
    assert np.all(f[whole] == 1) and np.isin(np.flatnonzero(inner2 & whole), b.whole).all()
    scene = scene.with_materials(np.full(P, R), np.where(np.isin(np.arange(P), b.whole), 0.0, E))
    np.testing.assert_allclose(f[inner2], analytic[inner2], atol=1e-9)
    for settings in ({}, {"method": "two_way"}):
        r = solve(scene, paths=400_000, seed=9, **settings)
        z = (r.radiosity[inner2, 0] - E / (1 - R)) / np.sqrt(r.reflected_variance[inner2, 0])
        assert np.abs(z).max() < 6.0, (settings, np.abs(z).max())


def test_a_patch_inside_a_box_flush_with_another_is_still_buried():
    """Artists' boxes are often flush: a wall box standing on the floor slab shares the slab's
    bottom plane, and a probe that leaves through both coincident faces counts only one of them.
    A one-sided strip (normal down, like a ceiling's edge) runs 0.25 into the wall box
    [0,1] x [0,1] x [0,1], whose bottom is flush with the slab [0,3] x [0,1] x [0,0.2]: its first
    patch is half buried (f = 1/2 exactly, on a cell line), the others whole. Before, the normal
    probe (down, out through the flush bottoms) said 'outside' and the patch kept its buried half."""
    wall = solid_box((0, 0, 0), (1, 1, 1), (2, 2, 2))
    slab = solid_box((0, 0, 0), (3, 1, 0.2), (6, 2, 1))
    n = 4  # the strip: x from 0.75 to 2.75 in patches of 0.5, facing down at z = 0.8
    strip = (np.column_stack([0.75 + 0.5 * np.arange(n), np.full(n, 0.25), np.full(n, 0.8)]),
             np.tile([0.0, 0.5, 0.0], (n, 1)), np.tile([0.5, 0.0, 0.0], (n, 1)))
    origin = np.concatenate([wall[0], slab[0], strip[0]])
    u = np.concatenate([wall[1], slab[1], strip[1]])
    v = np.concatenate([wall[2], slab[2], strip[2]])
    assert np.allclose(np.cross(strip[1], strip[2]), [0, 0, -0.25])
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    g = build_geometry(vertices, triangles, triangle_patch, origin.shape[0])
    f = g.buried.visible_fraction(origin.shape[0])
    np.testing.assert_array_equal(f[-n:], [0.5, 1.0, 1.0, 1.0])


@pytest.mark.parametrize("method", ["walk", "two_way"])
def test_per_source_results_of_an_overlapping_room_add_up_to_its_solve(method):
    """Buried parts and per-source results together: two groups of emitting inner patches (two
    emittances) in the slab room: the groups' results add up to the solve's total, and that total
    agrees with a solve without per-source results within their joint measured noise."""
    def emission(inner):
        e = np.where(inner, E, 0.0)
        e[np.flatnonzero(inner)[::2]] = 2 * E
        return e

    scene = slab_scene(R, emission)[0]
    plain = solve(scene, paths=40_000, seed=3, method=method, exit_point="hit")
    split = solve(scene, paths=40_000, seed=3, method=method, exit_point="hit", per_source=True)
    assert split.per_source.count == 2
    np.testing.assert_allclose(split.per_source.radiosity.sum(axis=0), split.radiosity, rtol=1e-9, atol=1e-12)
    joint = np.sqrt(split.reflected_variance + plain.reflected_variance)
    lit = joint > 0
    z = (split.radiosity - plain.radiosity)[lit] / joint[lit]
    assert min(split.chunks, plain.chunks) >= 16  # t with >= 15 degrees of freedom: P(max |t| > 6) small
    assert np.abs(z).max() < 6, np.abs(z).max()


def test_probes_count_every_coincident_face_of_flush_boxes():
    """Where flush boxes leave faces on each other, a probe meets them at one distance and the
    tracer returns one of them. A wall of three boxes end to end (a left and a right wall sunk to
    the floor slab's bottom, a lintel between them: the window room's south wall), the ceiling's
    edge strip facing down into it (y from 0.1 to 0.3, the wall's face at y = 0.2): every strip
    patch is half buried. Before, probes out through the coincident bottoms (both face down: 2)
    and the boxes' touching ends (facing each other: 0) counted one face, and patches came out
    0.56, 0.85 and 0.57 visible: the two-way iteration's rays then left from inside the wall. Now
    every face at a hit point counts (core coincident): 1/2 exactly; and a box wholly inside
    another (a sofa's seat pushed into its back) is buried whole."""
    left, lintel = solid_box((0, 0, 0), (1, 0.2, 1), (2, 1, 2)), solid_box((1, 0, 0.5), (2, 0.2, 1), (2, 1, 1))
    right, slab = solid_box((2, 0, 0), (3, 0.2, 1), (2, 1, 2)), solid_box((0, 0, 0), (3, 1, 0.1), (6, 2, 1))
    seat = solid_box((2.3, 0.05, 0.3), (2.6, 0.15, 0.5), (1, 1, 1))  # wholly inside the right wall
    n = 6
    strip = (np.column_stack([0.5 * np.arange(n), np.full(n, 0.1), np.full(n, 0.9)]),
             np.tile([0.0, 0.2, 0.0], (n, 1)), np.tile([0.5, 0.0, 0.0], (n, 1)))
    parts = [left, lintel, right, slab, seat, strip]
    origin, u, v = (np.concatenate([p[k] for p in parts]) for k in range(3))
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    g = build_geometry(vertices, triangles, triangle_patch, origin.shape[0])
    np.testing.assert_array_equal(g.buried.visible_fraction(origin.shape[0])[-n:], np.full(n, 0.5))
    first_seat = sum(p[0].shape[0] for p in parts[:4])
    assert set(range(first_seat, first_seat + seat[0].shape[0])) <= set(g.buried.whole.tolist())


def test_probes_run_on_the_local_threads_and_give_the_same_bits(uniform_room, monkeypatch):
    """The probes of buried parts go in blocks (PROBE_BLOCK points) shared among the local
    threads: with two, both threads probe at once (each one's first probe waits for the other's),
    and every answer is the same bit for bit as on one thread (a point's answer is its own
    rays'). Blocks of 64 points: the slab room's probes are thousands of points, dozens of blocks."""
    from addon.core.distributed import runners

    g = uniform_room[0].geometry
    monkeypatch.setattr(visibility, "PROBE_BLOCK", 64)
    windings, seen, waited = visibility.windings, set(), set()
    meet = threading.Barrier(2, timeout=20)

    def probe(*args):
        ident = threading.get_ident()
        seen.add(ident)
        if threads == 2 and len(waited) < 2 and ident not in waited:  # (the first two threads to probe)
            waited.add(ident)
            meet.wait()  # (a second thread that never probes breaks the barrier: the test fails)
        return windings(*args)

    monkeypatch.setattr(visibility, "windings", probe)
    answers = []
    for threads in (1, 2):
        seen.clear()
        with runners.local_threads(threads):
            answers.append(visibility.find_buried(g))
        assert (len(seen) == 1) if threads == 1 else (len(seen) >= 2), (threads, len(seen))
    one, two = answers
    for field in ("slot", "patch", "bins", "first", "cells", "fraction", "whole"):
        assert np.array_equal(getattr(one, field), getattr(two, field)), field
    assert one.patch.size > 0
