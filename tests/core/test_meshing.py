"""Tests of addon.core.mesh.meshing (pure numpy, no bpy)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from addon.core.mesh import meshing
from addon.core.mesh.meshing import (
    concatenate,
    fan_triangulation,
    mesh_patches,
    point_average,
    reverse_faces,
    triangle_areas,
)


def polygon_area_vector(points, face_sizes, corner_verts):
    """Vector area (normal * area) of every face, shoelace in 3D."""
    starts = np.concatenate([[0], np.cumsum(face_sizes)[:-1]])
    out = []
    for s, n in zip(starts, face_sizes):
        p = points[corner_verts[s : s + n]]
        out.append(0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0))
    return np.array(out)


def unit_quad(size=1.0):
    v = np.array([[0, 0, 0], [size, 0, 0], [size, size, 0], [0, size, 0]], float)
    return v, np.array([4]), np.array([0, 1, 2, 3])


def test_small_faces_are_kept_as_they_are():
    v, fs, cv = unit_quad(1.0)
    m = mesh_patches(v, fs, cv, patch_size=2.0)
    assert m.patch_count == 1
    np.testing.assert_array_equal(m.face_sizes, [4])
    np.testing.assert_allclose(m.points[m.corner_verts], v)
    assert m.patch_area[0] == pytest.approx(1.0)
    assert len(m.triangles) == 2


def test_face_exactly_patch_size_is_not_cut():
    v, fs, cv = unit_quad(1.0)
    assert mesh_patches(v, fs, cv, patch_size=1.0).patch_count == 1


def test_quad_becomes_grid_of_equal_cells():
    v = np.array([[0, 0, 0], [3, 0, 0], [3, 1, 0], [0, 1, 0]], float)
    m = mesh_patches(v, [4], [0, 1, 2, 3], patch_size=0.5)
    # 3 / 0.5 = 6 along u, 1 / 0.5 = 2 along v
    assert m.patch_count == 12
    assert np.all(m.face_sizes == 4)
    np.testing.assert_allclose(m.patch_area, 0.25)
    assert len(m.points) == 7 * 3  # welded grid
    # every cell edge <= patch size
    c = m.corner_verts.reshape(-1, 4)
    p = m.points[c]
    assert np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2).max() <= 0.5 + 1e-12
    # orientation kept: all normals +z
    n = polygon_area_vector(m.points, m.face_sizes, m.corner_verts)
    assert np.all(n[:, 2] > 0)


def test_triangle_regular_subdivision():
    v = np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0]], float)
    m = mesh_patches(v, [3], [0, 1, 2], patch_size=1.0)
    # longest edge 2*sqrt(2) -> n = 3 -> 9 triangles of equal area
    assert m.patch_count == 9
    np.testing.assert_allclose(m.patch_area, 2.0 / 9)
    assert len(m.points) == 10
    n = polygon_area_vector(m.points, m.face_sizes, m.corner_verts)
    assert np.all(n[:, 2] > 0)


def test_ngon_is_triangulated_then_subdivided_and_area_preserved():
    angles = np.linspace(0, 2 * np.pi, 9)[:-1]
    v = np.stack([np.cos(angles), np.sin(angles), np.zeros(8)], axis=1) * 2
    m = mesh_patches(v, [8], np.arange(8), patch_size=0.7)
    assert np.all(m.face_sizes == 3)
    assert m.patch_count > 6
    exact = 0.5 * 8 * 4 * np.sin(2 * np.pi / 8)
    assert m.patch_area.sum() == pytest.approx(exact)
    n = polygon_area_vector(m.points, m.face_sizes, m.corner_verts)
    assert np.all(n[:, 2] > 0)


def test_small_ngon_kept_with_given_triangulation():
    # concave "L" hexagon; the fan from corner 0 would be wrong here only if
    # corner 0 were the reflex corner, so give an explicit triangulation
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5]])
    m = mesh_patches(v, [6], np.arange(6), patch_size=5.0, face_triangles=tris, triangle_face=np.zeros(4, int))
    assert m.patch_count == 1
    assert m.face_sizes[0] == 6
    assert m.patch_area[0] == pytest.approx(3.0)
    np.testing.assert_array_equal(m.triangle_patch, 0)


def test_kept_quad_uses_the_given_triangulation():
    # concave "dart" quad: corner 3 is reflex, so a fan from corner 0 is
    # wrong (its triangles overlap); the given triangulation is right
    v = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [1.5, 0.5, 0]], float)
    tris = np.array([[3, 0, 1], [3, 1, 2]])
    m = mesh_patches(v, [4], [0, 1, 2, 3], patch_size=5.0, face_triangles=tris, triangle_face=[0, 0])
    assert m.patch_count == 1 and m.face_sizes[0] == 4
    exact = 0.5 * abs(np.cross(v[1] - v[3], v[2] - v[3])[2]) + 0.5 * abs(np.cross(v[0] - v[3], v[1] - v[3])[2])
    assert m.patch_area[0] == pytest.approx(exact)
    np.testing.assert_allclose(m.points[m.triangles], v[tris])


def test_neighbouring_faces_share_points_on_the_common_edge():
    # two unit quads side by side, same subdivision -> conforming grid
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0], [2, 1, 0]], float)
    cv = np.array([0, 1, 4, 3, 1, 2, 5, 4])
    m = mesh_patches(v, [4, 4], cv, patch_size=0.25)
    assert m.patch_count == 32
    assert len(m.points) == 9 * 5  # 2x4 by 4 grid welded: (8+1) * (4+1)
    assert len(np.unique(np.round(m.points, 9), axis=0)) == len(m.points)
    # patches are in source-face order
    np.testing.assert_array_equal(m.patch_face, [0] * 16 + [1] * 16)


def test_quad_and_triangle_sharing_an_edge_are_welded():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 1.6, 0]], float)
    cv = np.array([0, 1, 2, 3, 3, 2, 4])
    m = mesh_patches(v, [4, 3], cv, patch_size=0.5)
    # edge 2-3 cut in two by both faces: its midpoint is one point
    mid = np.array([0.5, 1.0, 0.0])
    assert np.sum(np.all(np.isclose(m.points, mid), axis=1)) == 1


def test_mixed_mesh_keeps_small_and_cuts_big():
    v = np.array(
        [[0, 0, 0], [4, 0, 0], [4, 4, 0], [0, 4, 0], [5, 0, 0], [5, 0.5, 0], [4.5, 0.5, 0]], float
    )
    cv = np.array([0, 1, 2, 3, 1, 4, 5, 6])
    m = mesh_patches(v, [4, 4], cv, patch_size=1.0)
    assert np.sum(m.patch_face == 0) == 16
    assert np.sum(m.patch_face == 1) == 1
    kept = np.nonzero(m.patch_face == 1)[0][0]
    s = m.face_starts[kept]
    np.testing.assert_allclose(m.points[m.corner_verts[s : s + 4]], v[[1, 4, 5, 6]])


def test_reverse_faces_flips_normals():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]], float)
    fs = np.array([4, 3])
    cv = np.array([0, 1, 2, 3, 1, 4, 2])
    r = reverse_faces(fs, cv)
    np.testing.assert_array_equal(r, [0, 3, 2, 1, 1, 2, 4])
    n0 = polygon_area_vector(v, fs, cv)
    n1 = polygon_area_vector(v, fs, r)
    np.testing.assert_allclose(n1, -n0)


def test_fan_triangulation():
    tris, tf = fan_triangulation([3, 5], [0, 1, 2, 3, 4, 5, 6, 7])
    np.testing.assert_array_equal(tris, [[0, 1, 2], [3, 4, 5], [3, 5, 6], [3, 6, 7]])
    np.testing.assert_array_equal(tf, [0, 1, 1, 1])


def test_point_average_is_area_weighted():
    # a 1x1 quad next to a 2x1 quad (kept): shared edge points see both
    v = np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0], [0, 1, 0], [1, 1, 0], [3, 1, 0]], float)
    cv = np.array([0, 1, 4, 3, 1, 2, 5, 4])
    m = mesh_patches(v, [4, 4], cv, patch_size=10.0)
    values = np.array([[1.0, 0.0, 0.0], [4.0, 3.0, 0.0]])
    avg = point_average(m, values)
    np.testing.assert_allclose(m.patch_area, [1.0, 2.0])
    for k, p in enumerate(m.points):
        if p[0] == 1.0:
            np.testing.assert_allclose(avg[k], (1 * values[0] + 2 * values[1]) / 3)
        elif p[0] == 0.0:
            np.testing.assert_allclose(avg[k], values[0])
        else:
            np.testing.assert_allclose(avg[k], values[1])


def test_concatenate_offsets():
    v, fs, cv = unit_quad(1.0)
    a = mesh_patches(v, fs, cv, patch_size=0.5)
    b = mesh_patches(v + [0, 0, 2], fs, cv, patch_size=1.0)
    c = concatenate([a, b])
    assert c.patch_count == 5
    np.testing.assert_array_equal(c.patch_object, [0, 0, 0, 0, 1])
    np.testing.assert_array_equal(c.patch_offsets, [0, 4, 5])
    assert c.triangles.max() == len(c.vertices) - 1
    area = np.bincount(c.triangle_patch, triangle_areas(c.vertices, c.triangles))
    np.testing.assert_allclose(area, c.patch_area)
    np.testing.assert_allclose(c.vertices[c.triangles[c.triangle_patch == 4]][..., 2], 2.0)


def test_bad_input_is_rejected():
    v, fs, cv = unit_quad()
    with pytest.raises(ValueError, match="patch size"):
        mesh_patches(v, fs, cv, patch_size=0)
    with pytest.raises(ValueError, match="patch size"):
        mesh_patches(v, fs, cv, patch_size=float("nan"))
    with pytest.raises(ValueError, match="corners"):
        mesh_patches(v, [5], cv, patch_size=1)
    with pytest.raises(ValueError, match="NaN"):
        mesh_patches(v * np.nan, fs, cv, patch_size=1)


def test_large_mesh_is_fast_and_consistent():
    # 200x200 grid of unit quads, each cut 2x2
    n = 200
    x, y = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1).astype(float)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1)
    import time

    t0 = time.perf_counter()
    m = mesh_patches(v, np.full(n * n, 4), q, patch_size=0.5)
    elapsed = time.perf_counter() - t0
    assert m.patch_count == 4 * n * n
    assert len(m.points) == (2 * n + 1) ** 2
    assert m.patch_area.sum() == pytest.approx(n * n)
    assert elapsed < 10.0


@settings(max_examples=30, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.floats(0.05, 3.0), st.floats(0.05, 3.0), st.floats(-1, 1), st.integers(3, 7)
        ),
        min_size=1,
        max_size=4,
    ),
    st.floats(0.2, 2.0),
)
def test_random_convex_polygons_preserve_area_and_orientation(polys, patch_size):
    verts, sizes, corners = [], [], []
    for k, (rx, ry, z, n) in enumerate(polys):
        a = np.linspace(0, 2 * np.pi, n + 1)[:-1] + 0.3
        p = np.stack([rx * np.cos(a) + 10 * k, ry * np.sin(a), np.full(n, z)], axis=1)
        corners.extend(range(sum(sizes), sum(sizes) + n))
        verts.append(p)
        sizes.append(n)
    v = np.concatenate(verts)
    m = mesh_patches(v, sizes, corners, patch_size=patch_size)
    expected = np.linalg.norm(polygon_area_vector(v, np.array(sizes), np.array(corners)), axis=1)
    got = np.bincount(m.patch_face, m.patch_area, minlength=len(sizes))
    np.testing.assert_allclose(got, expected, rtol=1e-9)
    n_out = polygon_area_vector(m.points, m.face_sizes, m.corner_verts)
    assert np.all(n_out[:, 2] > 0)
    # subdivided faces obey the patch size
    c = m.corner_verts
    starts = m.face_starts
    for s, n in zip(starts, m.face_sizes):
        if n <= 4 and np.sum(m.patch_face == m.patch_face[np.searchsorted(starts, s)]) > 1:
            p = m.points[c[s : s + n]]
            assert np.linalg.norm(p - np.roll(p, -1, axis=0), axis=1).max() <= patch_size * (1 + 1e-6)
    # triangulation covers each patch exactly once
    np.testing.assert_allclose(
        np.bincount(m.triangle_patch, triangle_areas(m.points, m.triangles), minlength=m.patch_count),
        m.patch_area,
    )


# ---------------------------------------------------------------------------
# Non-planar faces: each triangle of their triangulation is a patch (the core
# refuses a patch whose triangles face different ways).
# ---------------------------------------------------------------------------

from addon.core import PatchScene  # noqa: E402
from addon.core.mesh.meshing import PLANAR_ANGLE_DEGREES, nonplanar_faces  # noqa: E402


def accepted(m):
    """The core builds a scene of the patch mesh without refusing it (and nothing is dropped)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "dropped degenerate triangles" either
        scene = PatchScene(m.points, m.triangles, m.triangle_patch, np.full(m.patch_count, 0.5),
                           np.ones(m.patch_count))
    np.testing.assert_allclose(scene.patch_area, m.patch_area, rtol=1e-9)
    return scene


def max_patch_tilt(m):
    """Largest angle (degrees) between a patch's triangle and the patch's area-weighted normal."""
    p = m.points[m.triangles]
    c = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n = np.stack([np.bincount(m.triangle_patch, c[:, k], minlength=m.patch_count) for k in range(3)], axis=1)
    n /= np.linalg.norm(n, axis=1)[:, None]
    cos = np.einsum("ij,ij->i", c / np.linalg.norm(c, axis=1)[:, None], n[m.triangle_patch])
    return float(np.degrees(np.arccos(np.clip(cos, -1, 1))).max())


def triangulation_area(v, tris, tf, F):
    return np.bincount(tf, triangle_areas(v, tris), minlength=F)


def twisted_quad(lift=0.3):
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, lift], [0, 1, 0]], float)
    return v, np.array([4]), np.array([0, 1, 2, 3])


@pytest.mark.parametrize("patch_size", [5.0, 0.3, 0.07])
def test_twisted_quad_becomes_triangle_patches_the_core_accepts(patch_size):
    # folded over its diagonal, one quad (or a bilinear grid of it) is refused by the core
    v, fs, cv = twisted_quad(lift=0.0)
    v[3] = [1.2, 0.5, 1.0]
    tris, tf = fan_triangulation(fs, cv)
    with pytest.raises(ValueError, match="mix triangles of different orientation"):
        PatchScene(v, tris, [0, 0], [0.5], [1.0])
    accepted(mesh_patches(v, fs, cv, patch_size))
    v, fs, cv = twisted_quad()
    m = mesh_patches(v, fs, cv, patch_size)
    assert np.all(m.face_sizes == 3) and np.all(m.patch_face == 0)
    accepted(m)
    assert max_patch_tilt(m) < 1e-5  # every patch is coplanar (one flat triangle each)
    assert m.patch_area.sum() == pytest.approx(triangulation_area(v, tris, tf, 1)[0], rel=1e-12)
    if patch_size > 2:  # small enough: exactly the two triangles of the triangulation
        np.testing.assert_array_equal(m.points[m.triangles], v[tris])
    else:
        c = m.corner_verts.reshape(-1, 3)
        p = m.points[c]
        assert np.linalg.norm(p - np.roll(p, -1, axis=1), axis=2).max() <= patch_size * (1 + 1e-9)
    # orientation: every patch faces the way the quad does (+z, roughly)
    assert np.all(polygon_area_vector(m.points, m.face_sizes, m.corner_verts)[:, 2] > 0)


def test_nonplanar_ngon_is_cut_into_its_given_triangles():
    # a hexagon with corners alternately up and down (a "crown"), Blender-like triangulation
    a = np.linspace(0, 2 * np.pi, 7)[:-1]
    v = np.stack([np.cos(a), np.sin(a), 0.25 * (-1.0) ** np.arange(6)], axis=1)
    tris = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 0], [0, 2, 4]])
    tf = np.zeros(4, int)
    m = mesh_patches(v, [6], np.arange(6), 10.0, face_triangles=tris, triangle_face=tf)
    assert m.patch_count == 4 and np.all(m.face_sizes == 3)
    np.testing.assert_array_equal(m.points[m.triangles], v[tris])  # in the triangulation's order
    accepted(m)
    small = mesh_patches(v, [6], np.arange(6), 0.4, face_triangles=tris, triangle_face=tf)
    assert small.patch_count > 4 and np.all(small.face_sizes == 3)
    accepted(small)
    assert max_patch_tilt(small) < 1e-5
    assert small.patch_area.sum() == pytest.approx(triangle_areas(v, tris).sum(), rel=1e-12)


def saddle(n=6, height=0.5, size=1.0):
    """An n x n grid of quads on z = height * x * y (every quad twisted), and its fan triangulation."""
    x, y = np.meshgrid(np.linspace(-size, size, n + 1), np.linspace(-size, size, n + 1), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), height * (x * y).ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], axis=-1).reshape(-1, 4)
    return v, np.full(n * n, 4), q.ravel()


@pytest.mark.parametrize("patch_size", [2.0, 0.2, 0.05])
def test_saddle_grid_of_twisted_quads(patch_size):
    v, fs, cv = saddle()
    tris, tf = fan_triangulation(fs, cv)
    nonplanar, _ = nonplanar_faces(v, len(fs), tris, tf)
    assert nonplanar.all()
    m = mesh_patches(v, fs, cv, patch_size, face_triangles=tris, triangle_face=tf)
    assert np.all(m.face_sizes == 3)
    accepted(m)
    assert max_patch_tilt(m) < 1e-5
    # each face covers exactly its triangulation, patches in source-face order
    np.testing.assert_allclose(np.bincount(m.patch_face, m.patch_area, minlength=len(fs)),
                               triangulation_area(v, tris, tf, len(fs)), rtol=1e-12)
    assert np.all(np.diff(m.patch_face) >= 0)
    # neighbouring faces share their points: no duplicated positions
    assert len(np.unique(np.round(m.points, 12), axis=0)) == len(m.points)
    if patch_size > 1:
        assert m.patch_count == 2 * len(fs)


def test_cells_of_a_twisted_quads_bilinear_grid_are_twisted_too():
    """Why a twisted quad is not gridded: the cells of its bilinear grid are twisted too."""
    v, fs, cv = twisted_quad(lift=0.8)
    from addon.core.mesh.subdivision import _grid_template

    i, j, cells = _grid_template(2, 2)
    u, w = (i / 2)[:, None], (j / 2)[:, None]
    pos = (1 - u) * (1 - w) * v[0] + u * (1 - w) * v[1] + u * w * v[2] + (1 - u) * w * v[3]
    tris = np.concatenate([cells[:, [0, 1, 2]], cells[:, [0, 2, 3]]])
    nonplanar, _ = nonplanar_faces(pos, 4, tris, np.tile(np.arange(4), 2))
    assert nonplanar[3]  # the cell at the lifted corner


def test_planar_faces_are_unchanged_by_rotation_and_float32_rounding():
    """Faces planar but for float32 rounding (a rotated, moved mesh as Blender stores it) stay
    quads, grids and n-gons, exactly as the same faces lying in the plane z = 0."""
    a = np.linspace(0, 2 * np.pi, 9)[:-1]
    v = np.concatenate([
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]],          # unit quad
        [[2, 0, 0], [5, 0, 0], [5, 2, 0], [2, 2, 0]],          # big quad: a grid
        np.stack([7 + np.cos(a), np.sin(a), np.zeros(8)], 1),  # octagon
        [[0, 3, 0], [2.5, 3, 0], [0, 5, 0]],                   # triangle
    ]).astype(float)
    fs = np.array([4, 4, 8, 3])
    cv = np.arange(len(v))
    flat = mesh_patches(v, fs, cv, 0.55)
    rng = np.random.default_rng(5)
    for _ in range(20):
        q, _r = np.linalg.qr(rng.normal(size=(3, 3)))
        if np.linalg.det(q) < 0:
            q[:, 0] *= -1
        moved = (v @ q.T * rng.uniform(0.01, 100) + rng.normal(size=3) * 100).astype(np.float32).astype(float)
        tris, tf = fan_triangulation(fs, cv)
        assert not nonplanar_faces(moved, len(fs), tris, tf)[0].any()
        m = mesh_patches(moved, fs, cv, 0.55 * np.linalg.norm(moved[1] - moved[0]))
        np.testing.assert_array_equal(m.face_sizes, flat.face_sizes)
        np.testing.assert_array_equal(m.corner_verts, flat.corner_verts)
        np.testing.assert_array_equal(m.patch_face, flat.patch_face)
        accepted(m)


def test_tolerance_is_one_degree_and_cells_of_a_nearly_planar_quad_stay_flat():
    from addon.core.mesh.meshing import PLANAR_COSINE
    from addon.core.mesh.validation import MIN_PATCH_NORMAL_COSINE

    # a face within the tolerance, or a grid cell of one (within about twice it), is far
    # inside the core's limit on a patch's triangles
    assert np.cos(np.radians(2 * PLANAR_ANGLE_DEGREES)) < PLANAR_COSINE
    assert np.cos(np.radians(4 * PLANAR_ANGLE_DEGREES)) > MIN_PATCH_NORMAL_COSINE

    def quad_tilted(degrees):
        # lifting corner 2 by h tilts the fan's two triangles by about h / sqrt(2) radians each
        v, fs, cv = twisted_quad(0.0)
        lo, hi = 0.0, 0.1
        for _ in range(60):  # the lift whose largest tilt (against the mean normal) is `degrees`
            h = 0.5 * (lo + hi)
            v[2, 2] = h
            tris, tf = fan_triangulation(fs, cv)
            m = PatchMesh_of(v, tris)
            lo, hi = (h, hi) if max_patch_tilt(m) < degrees else (lo, h)
        v[2, 2] = lo
        return v, fs, cv

    under, fs, cv = quad_tilted(PLANAR_ANGLE_DEGREES * 0.99)
    over, _, _ = quad_tilted(PLANAR_ANGLE_DEGREES * 1.01)
    assert mesh_patches(under, fs, cv, 5.0).face_sizes.tolist() == [4]
    assert mesh_patches(over, fs, cv, 5.0).face_sizes.tolist() == [3, 3]
    grid = mesh_patches(under, fs, cv, 0.105)
    assert np.all(grid.face_sizes == 4) and grid.patch_count == 100
    accepted(grid)
    assert max_patch_tilt(grid) <= 2 * PLANAR_ANGLE_DEGREES


def PatchMesh_of(v, tris):
    """A one-patch mesh of these triangles (for measuring their tilt)."""
    return meshing.PatchMesh(v, np.array([len(v)]), np.arange(len(v)), np.zeros(1, int), tris,
                             np.zeros(len(tris), int), np.zeros(1))


def test_pole_quad_with_almost_coincident_corners_is_accepted():
    """A NURBS sphere's pole: quads whose two pole corners differ by float32 rounding. The
    sliver between them has a tiny area and a normal that is rounding noise; the quad is cut,
    the sliver is a patch of its own (the core keeps it: its area is far above the degenerate
    limit), and no patch is made of dropped triangles."""
    ring = np.array([[0.15, 0.0, -0.9883], [0.14, 0.056, -0.9883], [0.127, 0.0836, -0.9883]])
    pole = np.array([[0, 0, -1.0], [0, 0, -1.0 + 2**-24], [0, 0, -1.0]])
    v = np.concatenate([pole, ring])
    # face 0: (P0, R0, R1, P1): P1 a rounding away from P0; face 1: (P1, R1, R2, P2), P2 == P0
    fs = np.array([4, 4])
    cv = np.array([0, 3, 4, 1, 1, 4, 5, 2])
    tris = np.array([[0, 3, 4], [0, 4, 1], [1, 4, 5], [1, 5, 2]])
    tf = np.array([0, 0, 1, 1])
    m = mesh_patches(v, fs, cv, 1.0, face_triangles=tris, triangle_face=tf)
    assert m.face_sizes.tolist() == [3, 3, 3, 3]
    accepted(m)
    # with the pole corners exactly equal, the sliver has no area: the face is planar, kept,
    # as before (the core drops the zero-area triangle and says so)
    v[1] = v[0]
    m = mesh_patches(v, fs, cv, 1.0, face_triangles=tris, triangle_face=tf)
    assert m.face_sizes.tolist() == [4, 4]


def test_zero_area_triangles_of_a_cut_face_are_left_out():
    # a twisted pentagon whose corner 1 lies exactly on the edge 0 -> 2: the triangle (0,1,2)
    # has no area; as a patch of its own it would be empty (and refused)
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [2, 2, 0.7], [0, 2, 0]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    for size in (10.0, 0.5):
        m = mesh_patches(v, [5], np.arange(5), size, face_triangles=tris, triangle_face=[0, 0, 0])
        assert np.all(m.face_sizes == 3)
        accepted(m)
        assert m.patch_area.sum() == pytest.approx(triangle_areas(v, tris).sum())
        assert np.all(m.patch_area > 0)
    m = mesh_patches(v, [5], np.arange(5), 10.0, face_triangles=tris, triangle_face=[0, 0, 0])
    np.testing.assert_array_equal(m.points[m.triangles], v[tris[1:]])
    # a caller's larger min_area (the whole scene's) leaves out what the core would drop
    tiny = v.copy()
    tiny[1, 1] = 1e-9  # area 1e-9: kept by default, left out below the scene's limit
    assert mesh_patches(tiny, [5], np.arange(5), 10.0, tris, [0, 0, 0]).patch_count == 3
    assert mesh_patches(tiny, [5], np.arange(5), 10.0, tris, [0, 0, 0], min_area=1e-8).patch_count == 2


def test_mixed_planar_and_nonplanar_faces_keep_face_order_and_colours_per_face():
    # four quads around a centre vertex; lifting a corner vertex twists one of them only
    v, fs, cv = saddle(n=2, height=0.0)
    v = v.copy()
    v[8, 2] = 0.4
    m = mesh_patches(v, fs, cv, 0.35)
    accepted(m)
    assert np.all(np.diff(m.patch_face) >= 0)
    np.testing.assert_array_equal(np.unique(m.face_sizes[m.patch_face == 3]), [3])
    np.testing.assert_array_equal(np.unique(m.face_sizes[m.patch_face != 3]), [4])
    values = np.arange(len(fs), dtype=float)[m.patch_face][:, None] * [1.0, 2.0, 3.0]
    flat = meshing.corner_values(m, values)
    assert flat.shape == (len(m.corner_verts), 3)
    np.testing.assert_array_equal(flat[:, 0], np.repeat(m.patch_face, m.face_sizes))
    avg = point_average(m, values)
    assert np.all((avg[:, 0] >= 0) & (avg[:, 0] <= len(fs) - 1 + 1e-12))
    # the points of every patch lie on its source face's triangulation
    tris, tf = fan_triangulation(fs, cv)
    for f in range(len(fs)):
        p = m.points[m.corner_verts[np.repeat(m.patch_face == f, m.face_sizes)]]
        t = v[tris[tf == f]]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        d = np.abs(np.einsum("tk,ptk->pt", n / np.linalg.norm(n, axis=1)[:, None], p[:, None] - t[None, :, 0]))
        assert d.min(axis=1).max() < 1e-12


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31), st.integers(2, 7), st.floats(0.0, 0.6), st.floats(0.05, 3.0))
def test_random_displaced_meshes_are_accepted_and_cover_their_triangulation(seed, n, bump, patch_size):
    rng = np.random.default_rng(seed)
    v, fs, cv = saddle(n=n, height=0.0)
    v = v.copy()
    v[:, 2] = bump * rng.uniform(-1, 1, len(v)) / n
    v[:, :2] += rng.uniform(-0.2, 0.2, (len(v), 2)) / n
    tris, tf = fan_triangulation(fs, cv)
    m = mesh_patches(v, fs, cv, patch_size, face_triangles=tris, triangle_face=tf)
    accepted(m)
    assert max_patch_tilt(m) <= 2 * PLANAR_ANGLE_DEGREES
    expected = triangulation_area(v, tris, tf, len(fs))
    got = np.bincount(m.patch_face, m.patch_area, minlength=len(fs))
    nonplanar, _ = nonplanar_faces(v, len(fs), tris, tf)
    np.testing.assert_allclose(got[nonplanar], expected[nonplanar], rtol=1e-9)
    np.testing.assert_allclose(got, expected, rtol=1e-3)  # planar within 1 degree: a bilinear grid
    assert np.all(m.face_sizes[nonplanar[m.patch_face]] == 3)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**31), st.integers(2, 7), st.floats(0.0, 0.6), st.floats(0.05, 3.0))
def test_count_patches_is_the_number_mesh_patches_makes(seed, n, bump, patch_size):
    """The patch limit is checked from count_patches before meshing: it must be exact, for
    grids, kept faces, n-gons and non-planar faces alike."""
    rng = np.random.default_rng(seed)
    v, fs, cv = saddle(n=n, height=0.0)
    v = v.copy()
    v[:, 2] = bump * rng.uniform(-1, 1, len(v)) / n
    # plus a triangle and a pentagon, big or small
    base = len(v)
    v = np.vstack([v, [[2, 0, 0], [3, 0, 0], [2, 1, 0], [2, 2, 0], [3, 2, 0], [3.5, 2.5, 0.2], [3, 3, 0], [2, 3, 0]]])
    fs = np.concatenate([fs, [3, 5]])
    cv = np.concatenate([cv, base + np.array([0, 1, 2, 3, 4, 5, 6, 7])])
    tris, tf = fan_triangulation(fs, cv)
    m = mesh_patches(v, fs, cv, patch_size, face_triangles=tris, triangle_face=tf)
    assert meshing.count_patches(v, fs, cv, patch_size, tris, tf) == m.patch_count


def test_large_displaced_mesh_is_fast():
    n = 200
    rng = np.random.default_rng(1)
    v, fs, cv = saddle(n=n, height=0.0, size=n / 2)
    v = v.copy()
    v[:, 2] = rng.normal(0, 0.1, len(v))
    v[rng.random(len(v)) < 0.5, 2] = 0.0  # some quads planar, most not
    import time

    t0 = time.perf_counter()
    m = mesh_patches(v, fs, cv, patch_size=0.5)
    elapsed = time.perf_counter() - t0
    tris, tf = fan_triangulation(fs, cv)
    assert m.patch_area.sum() == pytest.approx(triangle_areas(v, tris).sum(), rel=1e-4)
    assert 3 in m.face_sizes and 4 in m.face_sizes
    assert elapsed < 10.0
