"""The glossy share of the first reflection, sent along its lobe instead of evenly.

Beyond the paper. A Principled surface's specular layer (and metallic) reflects a share of the
light it receives (``core.principled``: the ``offset`` of reflectivity = scale x base + offset,
for a dielectric) about the mirror direction, not as a Lambertian surface does. Radiosity keeps
one number per patch and spreads every reflection evenly; for the light after a bounce, which
arrives from everywhere, that is the mean of the lobe over its directions. The direct light of a
lamp, a sun or an emitter arrives from one direction, and its glossy share leaves towards one
side: a sunlit floor's specular light goes on towards the wall opposite the window.

Where the gathering knows that direction (each sample's shadow ray, ``first_shot``), the share
``glossy`` (P,3) of what the sample found leaves along the GGX lobe about the mirror of the
light's direction (``reflect``), from the sample's point; the rest stays diffuse. The amount is
the material's hemispherical mean (as everywhere else, so the accounts and the reflectivity are
those of the diffuse solve); only its direction is the lobe's: visible normals of GGX seen from
the light (Dupuy and Benyoub's spherical caps), the direction mirrored about one, and a direction
that would leave below the surface (which masking and multiple scattering share out) mirrored
back above it. Not carried along its lobe: the light after the first bounce, a sky's and a
cosine ray's light (spread evenly, as before), and the paper's shot walk.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# A patch whose glossy share is below this in every channel reflects evenly.
LEAST_SHARE = 1e-6


@dataclass(frozen=True)
class GlossyLobe:
    """Per patch, the share of the reflectivity that leaves along a GGX lobe (``share`` (P,3),
    each at most the patch's reflectivity) and the lobe's ``alpha`` (P,) (roughness squared)."""

    share: np.ndarray
    alpha: np.ndarray

    @classmethod
    def checked(cls, share, alpha, reflectivity):
        """The lobe of (P,3) ``share`` and (P,) ``alpha`` for patches of (P,3) ``reflectivity``;
        ValueError where they are not finite, negative, or alpha is outside (0, 1]; each
        share is held to the patch's reflectivity. None where no patch has a share."""
        share = np.asarray(share, dtype=np.float64)
        alpha = np.asarray(alpha, dtype=np.float64)
        P = reflectivity.shape[0]
        if share.shape != (P, 3) or alpha.shape != (P,):
            raise ValueError(f"glossy share must be (P, 3) and alpha (P,) with P = {P}; got {share.shape} and {alpha.shape}")
        if not (np.isfinite(share).all() and np.isfinite(alpha).all()) or (share < 0).any():
            raise ValueError("glossy share and alpha must be finite and the share >= 0")
        if ((alpha <= 0) | (alpha > 1)).any():
            raise ValueError("glossy alpha must be in (0, 1]")
        share = np.minimum(share, reflectivity)
        if not (share > LEAST_SHARE).any():
            return None
        return cls(share, alpha)

    def take(self, rows):
        """The lobe of the patches ``rows`` (a finer mesh's parents, say)."""
        return GlossyLobe(self.share[rows], self.alpha[rows])


def frame(normal):
    """(tangent, bitangent) (3,n) each, with ``normal`` (3,n) unit a right-handed orthonormal
    frame (Duff et al.: no branch, no division by a small number)."""
    x, y, z = normal
    sign = np.where(z >= 0, 1.0, -1.0)
    a = -1.0 / (sign + z)
    b = x * y * a
    tangent = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x])
    bitangent = np.stack([b, sign + y * y * a, -y])
    return tangent, bitangent


def reflect(normal, towards, alpha, u1, u2):
    """(3,n) unit directions of light arriving from unit ``towards`` (3,n, from the surface to
    the light) on surfaces of unit ``normal`` (3,n) reflected by GGX microfacets of ``alpha``
    (n,): a visible normal h seen from the light (uniforms ``u1``, ``u2`` (n,)), the light
    mirrored about it; one that would leave below the surface mirrored back above it."""
    normal = np.asarray(normal, dtype=np.float64)
    towards = np.asarray(towards, dtype=np.float64)
    tangent, bitangent = frame(normal)
    local = np.stack([np.einsum("in,in->n", f, towards) for f in (tangent, bitangent, normal)])
    local[2] = np.maximum(local[2], 1e-9)
    local /= np.sqrt(np.einsum("in,in->n", local, local))
    stretched = local * np.stack([alpha, alpha, np.ones_like(alpha)])  # the unit-roughness configuration
    stretched /= np.sqrt(np.einsum("in,in->n", stretched, stretched))
    phi = 2.0 * np.pi * np.asarray(u1, dtype=np.float64)
    z = (1.0 - np.asarray(u2, dtype=np.float64)) * (1.0 + stretched[2]) - stretched[2]
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    h = np.stack([r * np.cos(phi), r * np.sin(phi), z]) + stretched  # a visible normal, stretched
    h[:2] *= alpha
    h /= np.maximum(np.sqrt(np.einsum("in,in->n", h, h)), 1e-300)
    out = 2.0 * np.einsum("in,in->n", local, h) * h - local
    out[2] = np.abs(out[2])  # (below the surface: mirrored back above it)
    return tangent * out[0] + bitangent * out[1] + normal * out[2]
