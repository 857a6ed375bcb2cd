"""The walk's shortcuts for grey scenes give what the general colour code gives."""
import numpy as np
import pytest

from addon.core import Speedups, predict
from addon.core.methods.tables import WalkTables
from addon.core.methods.walk import walk_chunk
from boxes import box_scene


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_grey_biased_weights_are_the_accumulated_reflectivity(exit_point):
    # Different reflectivities per face (0.99 ... 0.3), one emitting face, threshold mid-way.
    scene, _, _ = box_scene([0.3, 0.5, 0.7, 0.9, 0.6, 0.99], [0, 2.0, 0, 0, 0, 0], n=2)
    assert scene.is_grey
    fast = WalkTables(scene, "biased_infinite", 1e-3, exit_point)
    general = WalkTables(scene, "biased_infinite", 1e-3, exit_point)
    assert fast.weight_is_accumulated
    general.weight_is_accumulated = False  # the colour code path, on one channel
    a = walk_chunk(fast, 4000, np.random.default_rng(5))
    b = walk_chunk(general, 4000, np.random.default_rng(5))
    assert a.rays == b.rays and a.ended == b.ended  # the same random numbers, the same paths
    assert a.ended["threshold"] > 0
    np.testing.assert_allclose(a.incident, b.incident, rtol=1e-12)
    for field in ("emitted", "escaped", "blocked", "undistributed"):
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=1e-12)


def test_grey_reflectivity_is_exact_in_grey_scenes():
    scene, _, _ = box_scene([0.1, 0.7, 0.3, 0.9, 0.6, 0.2], [1.0] * 6)
    np.testing.assert_array_equal(scene.grey_reflectivity, scene.reflectivity[:, 0])


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
def test_facing_by_patch_normal_is_facing_by_triangle_normal(estimator):
    """In a scene of parallelograms the random exit's facing test reads the hit patch's normal
    (from the leave table) instead of the triangle's: the two triangles of a parallelogram are
    coplanar, so with the same random numbers every path is the same, back-side hits included."""
    from boxes import open_box_with_card

    scene = open_box_with_card()  # rays escape at the top and hit a card's back
    triangles = Speedups(grids=False)  # (both trace the triangles: hits are triangles)
    by_patch = WalkTables(scene, estimator, 1e-3, "random", speedups=triangles)
    by_triangle = WalkTables(scene, estimator, 1e-3, "random", speedups=triangles)
    assert by_patch.facing_by_patch and by_patch.grids is None
    by_triangle.facing_by_patch = False
    by_triangle.facing_rows = scene.geometry.triangle_normal_rows
    a = walk_chunk(by_patch, 20_000, np.random.default_rng(7))
    b = walk_chunk(by_triangle, 20_000, np.random.default_rng(7))
    assert a.ended["blocked"] > 100 and a.ended["escaped"] > 100
    assert a.rays == b.rays and a.ended == b.ended
    np.testing.assert_array_equal(a.incident, b.incident)


@pytest.mark.parametrize("traced", ["triangles", "grids"])
@pytest.mark.parametrize("classes", [False, True])
def test_hit_points_keep_clear_of_edges(classes, traced):
    """A hit-point exit goes on from origin + t direction, except within the clearance of an
    edge of the triangle traced, where it maps the hit's barycentric coordinates onto the
    triangle's inset leaving frame (on the grids, its rectangle's). Rays aimed at points on
    and next to the edges (down to 0) of a box turned off the axes: every point lies in the
    plane of what it hit and at least the edge inset inside each of its edges (the patch
    triangle's, or on the grids the rectangle's: float32 rounding would otherwise put some
    past the edge, behind the adjacent wall), and points away from the edges are the hit
    points. With classes (as in big scenes) the triangles' edge thresholds are read per patch
    class."""
    from addon.core import PatchScene
    from addon.core.scene import rays
    from addon.core.mesh.frames import RELATIVE_EDGE_INSET
    from boxes import box_rectangles, rays_to_triangle_points, rectangles_to_mesh

    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    q, _ = np.linalg.qr(np.random.default_rng(5).normal(size=(3, 3)))
    scene = PatchScene((V - 0.5) @ q.T, T, TP, np.full(len(origin), 0.5), (face == 1).astype(float))
    g = scene.geometry
    assert g.patch_grids is not None and g.patch_grids.rectangles == 6
    speedups = Speedups(patch_classes=classes, grids=traced == "grids")
    tables = WalkTables(scene, "finite", 1e-3, "hit", speedups=speedups)
    assert (tables.patch_class is not None) == classes
    assert (tables.grids is None) == (traced == "triangles")
    assert (tables.class_edge_barycentric is not None) == (classes and traced == "triangles")
    n = 40_000
    # From near the box's centre (unit space: the origin) to points of its triangles, half of
    # them on or next to an edge.
    o, d, bary, target = rays_to_triangle_points(g, np.random.default_rng(8), n)
    hit, bu, bv, t, ng = tables.tracer.first_hit_barycentric(o, d)
    front = (np.einsum("ij,ij->i", ng, d) < 0) & (hit >= 0)
    assert front.all()
    points = rays.hit_points(
        tables, np.ascontiguousarray(o.T), np.ascontiguousarray(d.T), t, hit, rays.hit_patches(tables, hit, bu, bv), bu, bv, front
    ).T.astype(np.float64)

    if traced == "triangles":
        c = g.triangle_corners[hit].astype(np.float64)  # (n,3,3)
    else:  # the rectangle: (c00, c_a, c11) and (c00, c11, c_b) -> (c00, c_a, c11, c_b)
        grid = tables.grids.corners.astype(np.float64)
        first = hit - hit % 2
        c = np.stack([grid[first, 0], grid[first, 1], grid[first, 2], grid[first + 1, 2]], axis=1)
    normal = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    assert np.abs(np.einsum("ij,ij->i", points - c[:, 0], normal)).max() < 1e-6  # in the plane
    # Distance inside each edge (i, i+1): positive inside the triangle (rectangle).
    inside = []
    sides = c.shape[1]
    for i in range(sides):
        a, b = c[:, i], c[:, (i + 1) % sides]
        inward = np.cross(normal, b - a)
        inward /= np.linalg.norm(inward, axis=1)[:, None]
        inside.append(np.einsum("ij,ij->i", points - a, inward))
    inside = np.min(inside, axis=0)
    assert inside.min() > 0.5 * RELATIVE_EDGE_INSET, inside.min()
    away = bary.min(axis=1) > 1e-3
    assert away.sum() > n // 3
    assert np.abs(points[away] - target[away]).max() < 1e-6
    # A remapped point moves from where the ray hit by at most the inset over the frame's
    # shrink: 2 insets on a rectangle (d_a |A| + d_b |B|), on the box's right isosceles
    # triangles (shrunk about the incentre) 2.61 insets; plus float32's rounding.
    assert np.linalg.norm(points - target, axis=1).max() < 3 * RELATIVE_EDGE_INSET + 5e-7
    if traced == "grids":
        # Hits near the patches' own edges inside a rectangle are hit points too.
        on_own_edge = (inside > 1e-3) & (bary.min(axis=1) < 1e-6)
        assert on_own_edge.sum() > n // 20
        assert np.abs(points[on_own_edge] - target[on_own_edge]).max() < 1e-6


def test_walks_on_threads_take_turns_at_their_numpy_work(monkeypatch):
    """A walk holds the tables' numpy turn except while it traces: its numpy work (here, the
    scoring) runs holding it, its ray casts without. A walk whose ray cast is held up (until
    another thread's whole walk has run) lets that other walk take its turns meanwhile."""
    import threading

    from addon.core.estimate import tallies
    from boxes import box_scene

    scene, _, _ = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], n=2)
    tables = WalkTables(scene, "biased_infinite", 1e-3, "random")  # a walk that scores with Scores
    # (a random exit traces the box's grids, with their barycentric query)
    tracer, query = tables.grids.tracer, "first_hit_barycentric"
    real_trace, real_add = getattr(tracer, query), tallies.Scores.add
    held = {"tracing": [], "scoring": []}
    other_done = threading.Event()
    first_cast = threading.Event()

    def tracing(origins, directions):
        held["tracing"].append(tables.numpy_turn.locked())
        if threading.current_thread().name == "held-up" and not first_cast.is_set():
            first_cast.set()
            assert other_done.wait(timeout=30), "the other walk never got the numpy turn"
        return real_trace(origins, directions)

    def scoring(self, patch, weights):
        held["scoring"].append(tables.numpy_turn.locked())
        return real_add(self, patch, weights)

    monkeypatch.setattr(tracer, query, tracing)
    monkeypatch.setattr(tallies.Scores, "add", scoring)
    results = {}

    def walk(name, seed):
        results[name] = walk_chunk(tables, 3_000, np.random.default_rng(seed))

    held_up = threading.Thread(target=walk, args=("held-up", 1), name="held-up", daemon=True)
    held_up.start()
    assert first_cast.wait(timeout=30)
    # The other walk needs the turn while the held-up walk is inside its ray cast.
    other = threading.Thread(target=walk, args=("other", 2), daemon=True)
    other.start()
    other.join(timeout=30)
    other_done.set()
    held_up.join(timeout=60)
    assert set(results) == {"held-up", "other"} and all(r.paths == 3_000 for r in results.values())
    assert held["scoring"] and all(held["scoring"])  # numpy work under the turn
    assert not tables.numpy_turn.locked()


def test_chunk_wide_work_does_not_wait_for_a_turn(monkeypatch):
    """The two-way iteration's generations (whole-chunk arrays, numpy lets go of the GIL inside
    them) run without the numpy turn, so that two threads' numpy work overlaps, unless the
    chunk is small; the paper's walk takes turns (the test above). benchmarks/turns.py and the
    rule's comment give the measurements."""
    from addon.core.methods import jacobi, tables as walk_tables, two_way, walk
    from addon.core.methods import generations
    from addon.core.methods.first_shot import Gathering

    scene, _, _ = box_scene([0.5] * 6, [0, 1.0, 0, 0, 0, 0], n=2)
    tables = WalkTables(scene, "finite", 1e-3, "hit")
    big = walk_tables.TURN_FREE_SIZE
    assert not walk_tables.takes_turns(tables, big) and walk_tables.takes_turns(tables, big - 1)  # (small chunks' arrays are short)
    chunks = two_way.TwoWayChunks(tables, Gathering(scene, two_way.direct_samples(big, scene)))
    held = []
    real = generations.generation

    def generation(t, *args):
        held.append(tables.numpy_turn.locked() or t.numpy_turn.locked())
        return real(t, *args)

    monkeypatch.setattr(two_way, "generation", generation)  # (the name the chunk calls)
    tally = chunks.run([big], np.random.default_rng(1))[0]
    assert held and not any(held) and tally.paths == big
    held.clear()
    chunks.run([2_000], np.random.default_rng(1))
    assert held and all(held)
    # Jacobi iteration and the gathered walk run chunk-wide too; the paper's walk always takes turns.
    asked = []
    for module in (walk, jacobi):
        monkeypatch.setattr(module, "chunk_wide", lambda t, paths: asked.append(paths) or t)
    jacobi.Jacobi().create(scene, tables, big, 0, None).run([64], np.random.default_rng(1))
    gathered = walk.Walk("gathered").create(scene, tables, big, 0, predict(scene))
    gathered.run([64], np.random.default_rng(1))
    walk.Walk().create(scene, tables, big, 0, None).run([64], np.random.default_rng(1))
    assert asked == [64, 64] and not tables.numpy_turn.locked()
