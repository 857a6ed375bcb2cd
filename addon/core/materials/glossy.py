"""The glossy share of the first reflection, sent along its lobe instead of evenly.

Beyond the paper. A Principled surface's specular layer (and metallic) reflects a share of the
light it receives (``core.principled``: the ``offset`` of reflectivity = scale x base + offset,
for a dielectric) about the mirror direction, not as a Lambertian surface does. Radiosity keeps
one number per patch and spreads every reflection evenly; for the light after a bounce, which
arrives from everywhere, that is the mean of the lobe over its directions. The direct light of a
lamp, a sun, a window's sky or an emitter arrives from a few directions, and its glossy share leaves towards one
side: a sunlit floor's specular light goes on towards the wall opposite the window.

Where the gathering knows that direction (each sample's shadow ray to a source and its cosine
ray to an emitter or the sky, ``first_shot``), the share ``glossy`` (P,3) of what each ray found
leaves along the GGX lobe about the mirror of the light's direction (``reflect``), from the
sample's point; the rest stays diffuse. The amount is the material's hemispherical mean (as
everywhere else, so the accounts and the reflectivity are those of the diffuse solve); only its
direction is the lobe's: the single-scattering GGX lobe times the cosine, as Cycles'
multiple-scattering GGX scales it (visible normals seen from the light, Dupuy and Benyoub's
spherical caps; the direction mirrored about one kept with the chance G2/G1 of its masking, none
below the surface). Not carried along its lobe: the light after the first bounce (spread evenly,
as before), the random exit and the paper's shot walk.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .principled import smith_lambda

# A patch whose glossy share is below this in every channel reflects evenly.
LEAST_SHARE = 1e-6
# Draws of a lobe direction before a ray takes the mirror direction (each kept with the chance
# G2/G1: at 45 degrees and alpha 0.36 about nine in ten are).
TRIES = 8


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
            raise ValueError(f"glossy share must be (P, 3) and alpha (P,) with P = {P}; "
                             f"got {share.shape} and {alpha.shape}")
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


def reflect(normal, towards, alpha, rng, tries=TRIES):
    """(3,n) unit directions of light arriving from unit ``towards`` (3,n, from the surface to
    the light) on surfaces of unit ``normal`` (3,n) reflected by GGX microfacets of ``alpha``
    (n,), distributed as the single-scattering lobe times the cosine (with a constant Fresnel):
    a visible normal h seen from the light, the light mirrored about it, kept with the chance
    G2/G1 (the masking of the way out; none below the surface), else drawn again (``rng``), up
    to ``tries`` times; a ray still without one takes the mirror direction."""
    normal = np.asarray(normal, dtype=np.float64)
    towards = np.asarray(towards, dtype=np.float64)
    alpha = np.asarray(alpha, dtype=np.float64)
    tangent, bitangent = frame(normal)
    local = np.stack([np.einsum("in,in->n", f, towards) for f in (tangent, bitangent, normal)])
    local[2] = np.maximum(local[2], 1e-9)
    local /= np.sqrt(np.einsum("in,in->n", local, local))
    out = local * np.array([[-1.0], [-1.0], [1.0]])  # the mirror direction, for the rays left without one
    pending = np.arange(alpha.size)
    lambda_in = smith_lambda(alpha, local[2])
    for _ in range(tries):
        if not pending.size:
            break
        u = rng.random((3, pending.size))
        wi, a = local[:, pending], alpha[pending]
        o = _mirrored(wi, a, u[0], u[1])
        up = np.maximum(o[2], 1e-12)
        keep = (o[2] > 0) & (u[2] * (1.0 + lambda_in[pending] + smith_lambda(a, up)) < 1.0 + lambda_in[pending])
        out[:, pending[keep]] = o[:, keep]
        pending = pending[~keep]
    return tangent * out[0] + bitangent * out[1] + normal * out[2]


def _mirrored(local, alpha, u1, u2):
    """(3,n) ``local`` (unit, in the surface's frame) mirrored about a visible normal of GGX
    (alpha (n,)) drawn from uniforms ``u1``, ``u2``: the view stretched to unit roughness, a
    point of the spherical cap below it plus the view, unstretched (Dupuy and Benyoub)."""
    stretched = local * np.stack([alpha, alpha, np.ones_like(alpha)])
    stretched /= np.sqrt(np.einsum("in,in->n", stretched, stretched))
    phi = 2.0 * np.pi * u1
    z = (1.0 - u2) * (1.0 + stretched[2]) - stretched[2]
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    h = np.stack([r * np.cos(phi), r * np.sin(phi), z]) + stretched
    h[:2] *= alpha
    h /= np.maximum(np.sqrt(np.einsum("in,in->n", h, h)), 1e-300)
    return 2.0 * np.einsum("in,in->n", local, h) * h - local
