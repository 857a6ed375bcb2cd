"""Sampling for shooting random walks: sources in proportion to power, uniform points on
patches, cosine-distributed directions. All functions are vectorised over paths and take the
uniform random numbers they consume as arguments, so that they are deterministic and testable.
"""
from __future__ import annotations

import numpy as np

TWO_PI = np.float32(2.0 * np.pi)


class SourceTable:
    """Chooses emitting patches with probability Phi_i / Phi_T (power summed over channels)."""

    def __init__(self, patch_area, emission):
        power = patch_area * emission.sum(axis=1)
        self.patches = np.flatnonzero(power > 0)
        cumulative = np.cumsum(power[self.patches])
        self.cdf = cumulative / cumulative[-1]
        self.cdf[-1] = 1.0
        self.probability = power[self.patches] / cumulative[-1]

    def choose(self, u):
        """Patch index for each uniform u in [0, 1)."""
        k = np.searchsorted(self.cdf, u, side="right")
        np.minimum(k, self.patches.size - 1, out=k)
        return self.patches[k]


def choose_triangles(geometry, patch, u):
    """A triangle of each patch, chosen with probability proportional to its area."""
    first = geometry.patch_first_triangle[patch]
    if geometry.max_triangles_per_patch == 1:
        return first
    k = np.searchsorted(geometry.triangle_key, patch + u.astype(np.float64), side="right")
    last = first + geometry.patch_triangle_count[patch] - 1
    return np.clip(k, first, last)


def points_on_triangles(geometry, triangle, u1, u2):
    """Uniform points on the given triangles, already pushed off the surface along its normal.

    The square [0,1)^2 is folded onto the triangle (u1 + u2 > 1 reflects), which is uniform
    and needs no square root. float32 (n,3), centred coordinates.
    """
    fold = (u1 + u2) > 1
    a = np.where(fold, 1 - u1, u1)
    b = np.where(fold, 1 - u2, u2)
    points = geometry.triangle_origin[triangle]
    points += geometry.triangle_edge1[triangle] * a[:, None]
    points += geometry.triangle_edge2[triangle] * b[:, None]
    return points


def cosine_directions(geometry, patch, u1, u2):
    """Directions about each patch's normal with density cos(theta)/pi. float32 (n,3) unit."""
    phi = TWO_PI * u1
    sin_theta = np.sqrt(u2)
    cos_theta = np.sqrt(1 - u2)
    x = (sin_theta * np.cos(phi))[:, None]
    y = (sin_theta * np.sin(phi))[:, None]
    directions = geometry.patch_normal[patch] * cos_theta[:, None]
    directions += geometry.patch_tangent[patch] * x
    directions += geometry.patch_bitangent[patch] * y
    return directions
