"""Image textures averaged over each patch's UV footprint (addon/core/textures.py)."""
import numpy as np

from addon.core.meshing import mesh_patches
from addon.core.textures import SAMPLES, patch_texture_average, sample_bilinear


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
