"""Tests of addon.core.meshing (pure numpy, no bpy)."""

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from addon.core import meshing
from addon.core.meshing import (
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
