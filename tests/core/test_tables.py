"""Patch classes (tables.patch_classes): big scenes of parallelograms read a patch's leaving
frame as its corner and its class's shape, and a hit patch's normal and R_bar as its class's.
The classes must give back every patch's own numbers bit for bit, so the walks give the same
results bit for bit with and without them."""
import numpy as np
import pytest

from types import SimpleNamespace

from addon.core import PatchScene, Speedups
from addon.core.scene import rays
from addon.core.scene.geometry import leave_shapes
from addon.core.methods.tables import WalkTables, patch_classes, unique_keys
from addon.core.methods.walk import walk_chunks
from boxes import box_rectangles, box_scene, rectangles_to_mesh

R_FACES = [0.3, 0.5, 0.7, 0.5, 0.6, 0.45]
E_FACES = [0, 2.0, 0, 0, 0, 0]
COLOUR = np.array([0.05, 0.0, -0.05])  # added to a grey reflectivity: the same mean
SIZES = [3_000, 700, 128]

# (estimator, exit point, colour, speed-ups forced on: what bigger scenes do)
KINDS = {
    "sorted keys": ("finite", "random", False, {"counted": False}),
    "finite hit sorted": ("finite", "hit", False, {"sorted_paths": True}),
    "biased sorted": ("biased_infinite", "random", False, {"sorted_paths": True}),
    "biased hit sorted": ("biased_infinite", "hit", False, {"sorted_paths": True}),
    "colour sorted": ("finite", "random", True, {"sorted_paths": True}),
    "colour biased hit": ("biased_infinite", "hit", True, {}),
}
CLASSES = Speedups(patch_classes=True)


def _scene(colour=False, n=4, varied=False):
    """A closed box, one reflectivity a face (varied: three a face, patch by patch), made colour
    with the same mean reflectivity."""
    scene, _, _ = box_scene(R_FACES, E_FACES, size=(1.0, 1.3, 0.8), n=n)
    if varied:
        scene = scene.with_materials(scene.reflectivity + 0.05 * (np.arange(scene.patch_count) % 3)[:, None], scene.emission)
    if colour:
        scene = scene.with_materials(scene.reflectivity[:, :1] + COLOUR, scene.emission[:, :1] * [1.0, 0.5, 0.25])
    return scene


def _box_with_a_triangle_card():
    """A closed box of 2 x 2 parallelograms a face (emitting) and one more patch, a triangle
    (a card inside the box)."""
    origin, u, v, _ = box_rectangles(n=2)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    P = origin.shape[0]
    vertices = np.vstack([vertices, [[0.2, 0.2, 0.5], [0.8, 0.2, 0.5], [0.5, 0.8, 0.5]]])
    triangles = np.vstack([triangles, [[len(vertices) - 3, len(vertices) - 2, len(vertices) - 1]]])
    return PatchScene(vertices, triangles, np.append(triangle_patch, P), np.full(P + 1, 0.5), np.append(np.ones(P), 0.0))


def _tables(scene, estimator, exit_point, options, classes, **kw):
    """The walk's tables; without classes, also without reading hit patches from pairs (the
    per-triangle table instead: the walk before either)."""
    tables = WalkTables(scene, estimator, 1e-3, exit_point, speedups=Speedups(patch_classes=classes, **options), **kw)
    assert (tables.patch_class is not None) == classes
    tables.paired_triangles = classes
    return tables


def test_classes_give_back_every_patch_frame_normal_and_reflectivity_bit_for_bit():
    scene = _scene(n=5)
    tables = WalkTables(scene, "finite", 1e-3, "random", speedups=CLASSES)
    g = scene.geometry
    patch = np.arange(scene.patch_count)
    bits = lambda a: np.ascontiguousarray(a).view(np.uint32)  # noqa: E731
    np.testing.assert_array_equal(bits(rays.leave_frames(tables, patch, None)), bits(g.leave_table))
    np.testing.assert_array_equal(bits(rays.patch_normals(tables, patch)), bits(g.patch_normal_rows))
    np.testing.assert_array_equal(
        tables.grey_reflectivity_at(patch).view(np.uint64), scene.grey_reflectivity.view(np.uint64)
    )
    # Patches meshed from one face share their shape: far fewer classes than patches, and at
    # least one per face (each face has its own normal, and R_FACES has 5 values).
    assert 6 <= tables.class_shape.shape[1] < scene.patch_count // 4
    assert tables.patch_class.dtype == np.uint16


def test_shapes_are_told_apart_by_their_bits():
    """Two parallelograms whose edges differ in one float32 ulp are two shapes; -0.0 and 0.0
    are too."""
    table = np.zeros((12, 3), dtype=np.float32)
    table[3:12] = np.array([1, 0, 0, 0, 1, 0, 0, 0, 1], dtype=np.float32)[:, None]
    table[3, 1] = np.nextafter(np.float32(1), np.float32(2))
    table[4, 2] = np.float32(-0.0)

    shapes, shape_of_patch = leave_shapes(table)
    assert shapes.shape == (9, 3)
    assert len(set(shape_of_patch.tolist())) == 3
    np.testing.assert_array_equal(shapes[:, shape_of_patch].view(np.uint32), table[3:12].view(np.uint32))


def test_shapes_that_share_a_hash_are_still_told_apart():
    """Shapes are grouped by a hash of their bits, then checked row by row: where every shape
    shares one hash (all multipliers 0), the rows themselves are sorted, and the shapes are
    the same as with the hash."""
    geometry = _scene(n=3).geometry
    hashed = geometry.leave_shapes
    shapes, shape_of_patch = leave_shapes(geometry.leave_table, shape_hash=np.zeros(9, dtype=np.uint64))
    assert shapes.shape[1] == hashed[0].shape[1] > 1
    np.testing.assert_array_equal(shapes[:, shape_of_patch].view(np.uint32), geometry.leave_table[3:12].view(np.uint32))
    # The same partition of the patches, whatever the shapes' order.
    pairs = set(zip(shape_of_patch.tolist(), hashed[1].tolist()))
    assert len(pairs) == shapes.shape[1]


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("sizes", [[3_000], SIZES], ids=["one chunk", "group"])
@pytest.mark.parametrize("by_shape", [False, True], ids=["shape and R_bar", "shape alone"])
def test_walks_with_classes_and_paired_triangles_are_the_walks_without_bit_for_bit(kind, sizes, by_shape):
    estimator, exit_point, colour, options = KINDS[kind]
    scene = _scene(colour, varied=by_shape)
    plain = walk_chunks(_tables(scene, estimator, exit_point, options, False), sizes, np.random.default_rng(7))
    # By shape: fewer classes allowed than shape and R_bar make, so the classes are the shapes alone.
    limit = {"max_classes": scene.geometry.leave_shapes[0].shape[1]} if by_shape else {}
    tables = _tables(scene, estimator, exit_point, options, True, **limit)
    assert (tables.class_grey_reflectivity is None) == by_shape
    classed = walk_chunks(tables, sizes, np.random.default_rng(7))
    for a, b in zip(plain, classed):
        assert a.rays == b.rays and a.ended == b.ended
        np.testing.assert_array_equal(a.incident, b.incident)
        for field in ("emitted", "absorbed", "escaped", "blocked", "undistributed"):
            np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_too_many_classes_or_shapes_keep_the_patch_tables():
    """Too many classes of shape and R_bar: the classes are the shapes alone, and R_bar is read
    per patch (the walk the same bit for bit); too many shapes: no classes, and the walk says
    it runs without them."""
    scene = _scene(varied=True)
    classes = WalkTables(scene, "finite", 1e-3, "random", speedups=CLASSES).class_shape.shape[1]
    shapes = scene.geometry.leave_shapes[0].shape[1]
    assert shapes < classes
    by_shape = WalkTables(scene, "finite", 1e-3, "hit", speedups=CLASSES, max_classes=classes - 1)
    assert by_shape.class_shape.shape[1] == shapes and by_shape.class_grey_reflectivity is None
    patch = np.arange(scene.patch_count)
    np.testing.assert_array_equal(by_shape.grey_reflectivity_at(patch), scene.grey_reflectivity)
    np.testing.assert_array_equal(rays.leave_frames(by_shape, patch, None), scene.geometry.leave_table)
    np.testing.assert_array_equal(rays.patch_normals(by_shape, patch), scene.geometry.patch_normal_rows)
    none = WalkTables(scene, "finite", 1e-3, "random", speedups=CLASSES, max_classes=shapes - 1)
    assert none.patch_class is None and not none.speedups.patch_classes
    assert WalkTables(scene, "finite", 1e-3, "random", speedups=CLASSES, max_classes=classes).patch_class is not None
    # Too many distinct shapes for a table of their own: no shapes, so no classes.
    assert leave_shapes(scene.geometry.leave_table, max_shapes=1) is None
    assert patch_classes(SimpleNamespace(leave_shapes=None), scene.grey_reflectivity) is None


def test_small_scenes_and_scenes_with_other_patches_keep_the_patch_tables():
    """Small scenes, and scenes where a patch is not a parallelogram (even with classes asked
    for), read per-patch tables."""
    tables = WalkTables(_scene(), "finite", 1e-3, "random")
    assert tables.patch_class is None and not tables.speedups.patch_classes
    scene = _box_with_a_triangle_card()
    assert not scene.geometry.all_parallelograms
    assert WalkTables(scene, "finite", 1e-3, "random", speedups=CLASSES).patch_class is None


@pytest.mark.parametrize("n", [1, 3])
def test_the_triangles_of_a_scene_of_parallelograms_come_in_pairs_in_patch_order(n):
    """What rays.hit_patches reads without a table: triangle t is half of patch t >> 1.
    A miss (-1) reads as patch 0, with or without pairs: no negative index reaches a gather."""
    scene = _scene(n=n)
    g = scene.geometry
    assert g.all_parallelograms
    np.testing.assert_array_equal(g.triangle_patch, np.arange(g.triangle_count) >> 1)
    tables = WalkTables(scene, "finite", 1e-3, "hit", speedups=Speedups(grids=False))  # (hits are triangles)
    assert tables.paired_triangles
    hit = np.array([0, 1, 2, 5, g.triangle_count - 1, -1], dtype=np.int32)
    expected = np.append(g.triangle_patch[hit[:-1]], 0)
    patch = rays.hit_patches(tables, hit)
    assert patch.dtype == np.int32
    np.testing.assert_array_equal(patch, expected)
    tables.paired_triangles = False
    np.testing.assert_array_equal(rays.hit_patches(tables, hit), expected)
    np.testing.assert_array_equal(hit[-1], -1)  # the hits themselves are left alone


def test_edge_thresholds_are_one_per_shape_and_never_below_a_triangles_own():
    """A hit-point exit's edge threshold (Geometry.edge_barycentric) is the largest of its
    shape's triangles' own: one per shape, so a walk can read it per patch class, and never
    smaller than a triangle's own (a larger one only remaps a few more points exactly). Without
    shapes (a triangle patch), every triangle keeps its own."""
    scene, _, _ = box_scene(R_FACES, E_FACES, size=(1.0, 1.3, 0.8), n=5)
    g = scene.geometry
    own = g._own_edge_barycentric()
    _, shape_of_patch = g.leave_shapes
    shape_of_triangle = shape_of_patch[g.triangle_patch]
    assert (g.edge_barycentric >= own).all()
    for shape in np.unique(shape_of_triangle):
        members = shape_of_triangle == shape
        assert g.edge_barycentric[members].min() == g.edge_barycentric[members].max() == own[members].max()
    mixed = _box_with_a_triangle_card()
    assert mixed.geometry.shape_edge_barycentric is None
    np.testing.assert_array_equal(mixed.geometry.edge_barycentric, mixed.geometry._own_edge_barycentric())


@pytest.mark.parametrize("size, key_count", [(66_572, 23 * 7), (5_000, 5_000), (1_000, 50), (10, 1_000), (300, 1 << 40)])
def test_unique_keys_are_numpys_unique(size, key_count):
    """Class keys are made unique with a table of the keys present where their range is small,
    with a sort otherwise: the same keys and the same inverse as np.unique either way."""
    rng = np.random.default_rng(size)
    key = rng.integers(0, key_count, size).astype(np.int64)
    keys, inverse = unique_keys(key, key_count)
    expected_keys, expected_inverse = np.unique(key, return_inverse=True)
    np.testing.assert_array_equal(keys, expected_keys)
    np.testing.assert_array_equal(inverse, expected_inverse)
    np.testing.assert_array_equal(keys[inverse], key)
