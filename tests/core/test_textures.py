"""Image textures averaged over each patch's UV footprint (addon/core/materials/textures.py)."""
import numpy as np

from addon.core.mesh.meshing import mesh_patches
from addon.core.materials.textures import SAMPLES, corner_layers, patch_texture_average, sample_bilinear


def _square(uv_scale=1.0):
    """A 1 x 1 m quad, UV = its xy (times uv_scale), as Blender's two loop triangles."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    corners = vertices[triangles]
    uv = corners[:, :, :2] * uv_scale
    return vertices, triangles, corners, uv


def test_the_barycentric_samples_are_the_centres_of_equal_sub_triangles():
    assert SAMPLES.shape == (16, 2) and (SAMPLES > 0).all() and (SAMPLES.sum(axis=1) < 1).all()
    np.testing.assert_allclose(SAMPLES.mean(axis=0), [1 / 3, 1 / 3])  # linear functions integrate exactly


def test_a_linear_ramp_averages_to_each_patch_centres_value():
    """An image linear in u and v (bilinear interpolation reproduces it away from the wrap), read
    through a Mapping that keeps UV inside [0.25, 0.75]: each patch's average is the ramp at
    the patch's centroid, exactly (the samples integrate linear functions exactly)."""
    W, H = 64, 32
    u = (np.arange(W) + 0.5) / W
    v = (np.arange(H) + 0.5) / H
    image = np.zeros((H, W, 3))
    image[:, :, 0] = u[None, :]
    image[:, :, 1] = v[:, None]
    image[:, :, 2] = 0.5
    vertices, triangles, corners, uv = _square()
    mesh = mesh_patches(vertices, np.array([4]), np.array([0, 1, 2, 3]), 0.25,
                        face_triangles=triangles, triangle_face=np.zeros(2, int))
    affine = np.array([[0.5, 0.0, 0.25], [0.0, 0.5, 0.25]])
    patches = np.arange(mesh.patch_count)
    got = patch_texture_average(mesh, patches, corners, uv, np.zeros(2, int), image, affine)
    centroid = np.array([mesh.points[mesh.triangles[mesh.triangle_patch == p]].reshape(-1, 3).mean(axis=0) for p in patches])
    np.testing.assert_allclose(got[:, 0], 0.25 + 0.5 * centroid[:, 0], atol=1e-9)
    np.testing.assert_allclose(got[:, 1], 0.25 + 0.5 * centroid[:, 1], atol=1e-9)
    np.testing.assert_allclose(got[:, 2], 0.5)


def test_two_halves_of_an_image_colour_their_patches_and_repeat():
    """Left half red, right half blue; patches that tile the halves take their colour, and a
    UV scale of 2 repeats the image (each patch then straddles a repeat: half of each)."""
    W = 16
    image = np.zeros((8, W, 3))
    image[:, : W // 2] = (0.8, 0.0, 0.0)
    image[:, W // 2 :] = (0.0, 0.0, 0.8)
    image[:, W // 2 - 1 : W // 2 + 1] = 0.0  # (bilinear: keep the halves' inner texels pure)
    image[:, W // 2 - 1] = (0.8, 0.0, 0.0)
    image[:, W // 2] = (0.0, 0.0, 0.8)
    vertices, triangles, corners, uv = _square()
    mesh = mesh_patches(vertices, np.array([4]), np.array([0, 1, 2, 3]), 0.5,
                        face_triangles=triangles, triangle_face=np.zeros(2, int))
    patches = np.arange(mesh.patch_count)
    got = patch_texture_average(mesh, patches, corners, uv, np.zeros(2, int), image, np.eye(2, 3))
    x = np.array([mesh.points[mesh.triangles[mesh.triangle_patch == p]].reshape(-1, 3)[:, 0].mean() for p in patches])
    left = x < 0.5
    # the texels next to the seam and the wrap blend over half a texel: 1/16 of the patch width
    assert (got[left, 0] > 0.7).all() and (got[left, 2] < 0.1).all()
    assert (got[~left, 2] > 0.7).all() and (got[~left, 0] < 0.1).all()
    assert sample_bilinear(image, np.array([[0.25, 0.5]]))[0, 0] == 0.8


def test_corner_layers_carry_the_source_uv_and_colours_to_every_patch_corner():
    """A quad whose two loop triangles carry UVs that no single affine map fits (the fourth
    corner's UV is pulled in), and a colour attribute: every corner of the patch mesh takes,
    from the triangle it lies in, the linear interpolation of that triangle's corners, so that
    the result mesh shows the same texture at the same surface point as the source."""
    vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    triangles = np.array([[0, 1, 2], [0, 2, 3]])
    corners = vertices[triangles]
    uv_at = np.array([[0.1, 0.2], [0.9, 0.1], [0.7, 0.8], [0.3, 0.95]])  # (not affine in position)
    colour_at = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [1, 1, 1, 0.5]], np.float32)
    mesh = mesh_patches(vertices, np.array([4]), np.array([0, 1, 2, 3]), 0.3,
                        face_triangles=triangles, triangle_face=np.zeros(2, int))
    corner_face = np.repeat(mesh.patch_face, mesh.face_sizes)
    uv, colours = corner_layers(mesh.points, mesh.corner_verts, corner_face, corners, np.zeros(2, int),
                                [uv_at[triangles].astype(np.float32), colour_at[triangles]], block=7)
    assert uv.dtype == np.float32 and uv.shape == (len(mesh.corner_verts), 2) and colours.shape[1] == 4
    p = mesh.points[mesh.corner_verts]
    # the triangle each point lies in: (0,1,2) below the diagonal y = x / 2, (0,2,3) above it
    upper = p[:, 1] > p[:, 0] / 2 + 1e-12
    for inside, tri in ((~upper, triangles[0]), (upper, triangles[1])):
        a, b, c = vertices[tri]
        # barycentric weights of the points in that triangle, solved in the plane z = 0
        M = np.column_stack([(b - a)[:2], (c - a)[:2]])
        w12 = np.linalg.solve(M, (p[inside, :2] - a[:2]).T).T
        w = np.column_stack([1 - w12.sum(axis=1), w12])
        np.testing.assert_allclose(uv[inside], w @ uv_at[tri], atol=2e-6)
        np.testing.assert_allclose(colours[inside], w @ colour_at[tri], atol=2e-6)
    assert upper.any() and (~upper).any() and len(mesh.corner_verts) > 40


def test_a_corner_on_a_face_edge_takes_that_face_s_uv_not_its_neighbour_s():
    """Two faces sharing an edge with a UV seam between them (each its own island): the patch
    corners on the shared edge take the UV of the face their patch lies on."""
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], float)
    corner_verts = np.array([0, 1, 2, 3, 1, 4, 5, 2])
    triangles = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]])
    triangle_face = np.array([0, 0, 1, 1])
    loop_uv = np.array([[0, 0], [0.5, 0], [0.5, 0.5], [0, 0.5], [0.6, 0.6], [1.1, 0.6], [1.1, 1.1], [0.6, 1.1]])
    triangle_loops = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    mesh = mesh_patches(vertices, np.array([4, 4]), corner_verts, 0.5, face_triangles=triangles,
                        triangle_face=triangle_face)
    corner_face = np.repeat(mesh.patch_face, mesh.face_sizes)
    (uv,) = corner_layers(mesh.points, mesh.corner_verts, corner_face, vertices[triangles], triangle_face,
                          [loop_uv[triangle_loops].astype(np.float32)])
    p = mesh.points[mesh.corner_verts]
    on_edge = np.abs(p[:, 0] - 1.0) < 1e-12
    expected = np.where(corner_face[:, None] == 0, 0.5 * p[:, :2], 0.6 + 0.5 * (p[:, :2] - [1, 0]))
    np.testing.assert_allclose(uv, expected, atol=2e-6)
    assert set(corner_face[on_edge]) == {0, 1}
