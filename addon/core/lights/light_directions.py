"""Directions and origins the lights draw: spheres, cones, cosine lobes, discs, and the pixels
of an equirectangular sky (as Blender maps a world image). (3, n) rows, float64, world space.
"""
from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi


def equirectangular_direction(row, column, shape):
    """The direction (3, n) towards the sky at the centre of pixel (row, column) of an
    equirectangular image of ``shape`` (H, W): row 0 at the top (z = 1), column 0 at azimuth
    pi (the -x direction), azimuth falling to the right, as Blender maps a world image."""
    H, W = shape
    theta = (np.asarray(row) + 0.5) / H * np.pi
    phi = np.pi - (np.asarray(column) + 0.5) / W * TWO_PI
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def equirectangular_pixel(direction, shape):
    """(row, column) of the pixel of an equirectangular image of ``shape`` (H, W) that holds
    each unit direction (3, n): the inverse of :func:`pixel_directions`."""
    H, W = shape
    z = np.clip(direction[2], -1.0, 1.0)
    row = np.minimum((np.arccos(z) / np.pi * H).astype(np.int64), H - 1)
    phi = np.arctan2(direction[1], direction[0])
    column = np.floor((np.pi - phi) / TWO_PI * W).astype(np.int64) % W
    return row, column


def pixel_solid_angles(shape):
    """(H, W) solid angle of each pixel of an equirectangular image."""
    H, W = shape
    edges = np.cos(np.arange(H + 1) * np.pi / H)
    band = (edges[:-1] - edges[1:]) * TWO_PI / W
    return np.repeat(band[:, None], W, axis=1)


def pixel_directions(shape, pixel, u_z, u_phi):
    """Uniform directions (in solid angle) within the given pixels of an equirectangular image."""
    H, W = shape
    row, column = np.divmod(np.asarray(pixel), W)
    z_top, z_bottom = np.cos(row * np.pi / H), np.cos((row + 1) * np.pi / H)
    z = z_top + (z_bottom - z_top) * u_z.astype(np.float64)
    phi = np.pi - (column + u_phi.astype(np.float64)) / W * TWO_PI
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z])


def direction_to(points, x):
    """Unit directions (3, n) from each x to each point, and the distances."""
    d = points - x
    distance = np.sqrt(dot(d, d))
    return d / distance, distance


def dot(a, b):
    return np.einsum("in,in->n", a, b) if a.shape[1] == b.shape[1] else (a * b).sum(axis=0)


def rotate(matrix, vectors):
    """(3, n) ``matrix`` (3, 3) times ``vectors`` (3, n), without BLAS (whose threads, woken by a
    large product, spin on and take the CPUs from the solve's other threads: two_way._sums)."""
    return np.einsum("ij,jn->in", np.asarray(matrix, np.float64), vectors)


def sphere_directions(u1, u2):
    """Uniform unit directions (3, n)."""
    z = 1.0 - 2.0 * u1.astype(np.float64)
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    phi = TWO_PI * u2.astype(np.float64)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z])


def basis(direction):
    """Two unit vectors (3, n) perpendicular to each unit direction (3, n) and to each other."""
    d = direction
    helper = np.where(np.abs(d[0]) < 0.9, 1.0, 0.0)
    other = np.stack([helper, 1.0 - helper, np.zeros_like(helper)])
    a = cross_rows(d, other)
    a /= np.linalg.norm(a, axis=0)
    return a, cross_rows(d, a)


def cross_rows(a, b):
    """np.cross of (3, n) rows, term for term as it computes it, without its per-call cost
    (a solve's small chunks call this a few times each)."""
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def cone_directions(axis, cos_theta, u_phi):
    """Unit directions (3, n) at angles arccos(cos_theta) from ``axis`` ((3,), or one (3, n) a
    direction), azimuth 2 pi u."""
    axis = np.asarray(axis, np.float64)
    axis = axis[:, None] if axis.ndim == 1 else axis
    a, b = basis(axis)
    sin_theta = np.sqrt(np.maximum(1.0 - cos_theta**2, 0.0))
    phi = TWO_PI * u_phi.astype(np.float64)
    return axis * cos_theta + a * (sin_theta * np.cos(phi)) + b * (sin_theta * np.sin(phi))


def cosine_directions_about(normal, u1, u2):
    """Cosine-distributed unit directions (3, n) about ``normal`` ((3,) or (3, n)): cos(theta)
    = sqrt(1 - u1) has the density cos / pi (Malley)."""
    return cone_directions(normal, np.sqrt(1.0 - u1.astype(np.float64)), u2)


def disc_origins(direction, u1, u2, aim, reach):
    """Origins on a disc perpendicular to each direction that covers the ``aim`` sphere
    (centre, radius), ``reach`` back from its centre (beyond the whole scene)."""
    centre, radius = aim
    a, b = basis(direction)
    r = radius * np.sqrt(u1.astype(np.float64))
    phi = TWO_PI * u2.astype(np.float64)
    return np.asarray(centre, np.float64)[:, None] - direction * reach + a * (r * np.cos(phi)) + b * (r * np.sin(phi))
