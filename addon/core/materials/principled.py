"""The diffuse energy of Blender's Principled BSDF as Cycles (Blender 5.0) renders it.

Radiosity keeps one number per colour: the fraction of the light falling on a surface that it
sends back into the room. For a Principled BSDF that is not the base colour alone: its specular
layer (GGX microfacets, Fresnel from IOR, Specular IOR Level and Specular Tint) reflects light too,
and Cycles lets the diffuse base have what that layer leaves. Under light that comes evenly from
every direction (the radiosity assumption), seen along a direction of cosine ``mu``:

    out(mu) = sum over layers of  weight(mu) * albedo(mu)

where a layer's ``albedo(mu)`` is its directional albedo and ``weight(mu)`` what the layers above
it leave, as Cycles computes them (svm closure node): the specular layer leaves the diffuse base
``1 - max over colours of its estimated albedo``, a metallic fraction ``m`` takes ``m`` of the weight
(F82-tint conductor Fresnel, its colour the base colour), a transmission fraction its share (only
its reflection is counted), and a coat above all leaves ``1 - coat x its albedo`` and its tint.
The surface's hemispherical albedo is the cosine-weighted mean ``integral 2 mu out(mu) dmu``.
It is linear in the base colour except through the metallic layer, which is linearised at the
material's own base colour: reflectivity = scale * base + offset.

GGX as Cycles has it: height-correlated Smith masking, and with Multiscatter GGX (the default) the
single-scattering loss put back by ``1/E(mu)`` and darkened by the multiple-bounce Fresnel of
Kulla and Conty. Directional albedos are integrals over the visible normals, evaluated by a fixed
midpoint rule over the spherical-cap sampling of Dupuy and Benyoub (smooth at any roughness),
not by Cycles' tables; tests compare them with a brute-force integral over outgoing directions.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

# Quadrature sizes: Gauss-Legendre nodes in mu, and a midpoint grid (cap height x azimuth) of
# visible normals for each mu.
MU_NODES = 32
VIEW_POINTS = 33  # view cosines a result material's curves hold (view_terms)
CAP_ROWS = 96
CAP_COLUMNS = 48
ROUGHNESS_FLOOR = 1e-4  # Cycles' tables clamp roughness likewise


def f0_from_ior(eta):
    eta = np.asarray(eta, dtype=np.float64)
    return ((eta - 1.0) / (eta + 1.0)) ** 2


def ior_from_f0(f0):
    s = np.sqrt(np.clip(f0, 0.0, 1.0 - 1e-9))
    return (1.0 + s) / (1.0 - s)


def fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric of relative index ``eta`` (1 where the
    light is totally reflected)."""
    c = np.abs(np.asarray(cos_i, dtype=np.float64))
    g2 = eta * eta - 1.0 + c * c
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (g - c) / (g + c)
        b = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * a * a * (1.0 + b * b)
    return np.where(g2 > 0.0, np.nan_to_num(f, nan=1.0), 1.0)


def fresnel_dielectric_fss(eta):
    """Cycles' fit (Kulla and Conty) of the cosine-weighted mean dielectric Fresnel, eta >= 1."""
    return (eta - 1.0) / (4.08567 + 1.00071 * eta)


def smith_lambda(alpha, cos_n):
    cos_n = np.clip(cos_n, 1e-12, 1.0)
    tan2 = np.maximum(1.0 / (cos_n * cos_n) - 1.0, 0.0)
    return 0.5 * (np.sqrt(1.0 + alpha * alpha * tan2) - 1.0)


def mu_nodes(n=MU_NODES):
    """(mu, w): Gauss-Legendre nodes on (0, 1) with weights for the cosine-weighted mean
    ``sum(w * f(mu))`` = integral of 2 mu f(mu) dmu (copies: the caller may write to them)."""
    mu, w = _mu_nodes(int(n))
    return mu.copy(), w.copy()


@lru_cache(maxsize=8)
def _mu_nodes(n):
    x, w = np.polynomial.legendre.leggauss(n)  # (an eigenvalue solve: 4 ms a material otherwise)
    mu = 0.5 * (x + 1.0)
    return mu, w * mu  # (w/2 for the interval) x 2 mu


@dataclass(frozen=True)
class VisibleNormals:
    """For each view cosine ``mu`` (M,), visible microfacet normals of GGX at ``roughness`` on a
    midpoint grid (each carries equal probability): ``cos_h`` (M,N) = view . normal, ``weight``
    (M,N) = masking-shadowing ratio G2/G1 where the reflected ray leaves above the surface, else 0
    (so that a layer's directional albedo is ``mean(weight * F(cos_h))``), and ``valid`` (M,N)."""

    mu: np.ndarray
    cos_h: np.ndarray
    weight: np.ndarray
    valid: np.ndarray = field(repr=False)

    def albedo(self, fresnel=None):
        """(M,) directional albedo with Fresnel ``fresnel(cos_h)`` (None: 1)."""
        if fresnel is None:
            return self.weight.mean(axis=1)
        return (self.weight * fresnel(self.cos_h)).mean(axis=1)


@lru_cache(maxsize=24)  # (2.5 MB each)
def visible_normals(roughness, mu=None, rows=CAP_ROWS, columns=CAP_COLUMNS):
    """VisibleNormals of GGX (alpha = roughness squared, as the Principled BSDF) at the view
    cosines ``mu`` (a tuple; None: the Gauss-Legendre nodes)."""
    mu = mu_nodes()[0] if mu is None else np.asarray(mu, dtype=np.float64)
    alpha = max(float(roughness), ROUGHNESS_FLOOR) ** 2
    sin = np.sqrt(np.maximum(1.0 - mu * mu, 0.0))
    # the view stretched to the unit-roughness configuration
    wi = np.stack([alpha * sin, np.zeros_like(mu), mu], axis=1)
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    u2 = (np.arange(rows) + 0.5) / rows
    phi = 2.0 * np.pi * (np.arange(columns) + 0.5) / columns
    u2, phi = (a.ravel() for a in np.meshgrid(u2, phi, indexing="ij"))
    # a point of the spherical cap below the view, plus the view: a visible normal (unstretched)
    z = (1.0 - u2)[None, :] * (1.0 + wi[:, 2:3]) - wi[:, 2:3]
    r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    h = np.stack([r * np.cos(phi) + wi[:, 0:1], r * np.sin(phi) + wi[:, 1:2], z + wi[:, 2:3]], axis=2)
    h[..., :2] *= alpha
    h /= np.maximum(np.linalg.norm(h, axis=2, keepdims=True), 1e-300)
    view = np.stack([sin, np.zeros_like(mu), mu], axis=1)[:, None, :]
    cos_h = np.clip((view * h).sum(axis=2), 0.0, 1.0)
    out_z = 2.0 * cos_h * h[..., 2] - mu[:, None]
    valid = out_z > 0.0
    lambda_i = smith_lambda(alpha, mu)[:, None]
    lambda_o = smith_lambda(alpha, np.where(valid, out_z, 1.0))
    weight = np.where(valid, (1.0 + lambda_i) / (1.0 + lambda_i + lambda_o), 0.0)
    return VisibleNormals(mu, cos_h, weight, valid)


@dataclass(frozen=True)
class Ggx:
    """Single-scattering GGX albedo ``E(mu)`` at the Gauss-Legendre nodes and its cosine-weighted
    mean ``E_avg``, for the multiple-scattering compensation."""

    E: np.ndarray
    E_avg: float


@lru_cache(maxsize=256)
def ggx(roughness):
    E = np.clip(visible_normals(float(roughness)).albedo(), 1e-6, 1.0)
    return Ggx(E, float((mu_nodes()[1] * E).sum()))


def _darkening(layer, fss, multiscatter):
    """(M,C) Cycles' multiple-scattering GGX factor on a layer's weight, ``E + Fms (1 - E)``, the
    Fresnel of repeated bounces ``Fms`` from the mean Fresnel ``fss`` (C,); the BSDF itself is
    also scaled by ``1/E``. 1 without multiple scattering."""
    if not multiscatter:
        return np.ones((len(layer.E), len(fss)))
    E = layer.E[:, None]
    fms = fss * layer.E_avg / (1.0 - fss * (1.0 - layer.E_avg))
    return E + fms[None, :] * (1.0 - E)


def _compensated(layer, single, fss, multiscatter):
    """(M,C) directional albedo of a layer whose single-scattering albedo is ``single`` (M,C)."""
    darkening = _darkening(layer, fss, multiscatter)
    return single * darkening / layer.E[:, None] if multiscatter else single


def blurred_roughness(roughness, filter_glossy, nodes=8):
    """((K,) roughness, (K,) weights): what Cycles' Filter Glossy makes of a glossy closure reached
    by a diffuse bounce, averaged over that bounce. Cycles widens the lobe to alpha at least
    ``0.5 sqrt(1 - filter_glossy x pdf)``, the pdf of the diffuse bounce being cos/pi for the
    cosine at the surface the light goes on to (cosine-weighted over that surface's hemisphere);
    its multiple-scattering compensation stays that of the unblurred lobe. ``filter_glossy`` 0:
    the lobe itself."""
    roughness = max(float(roughness), ROUGHNESS_FLOOR)
    if filter_glossy <= 0.0:
        return np.array([roughness]), np.array([1.0])
    c, w = mu_nodes(nodes)
    blur_pdf = filter_glossy * c / np.pi
    alpha = np.where(blur_pdf < 1.0, 0.5 * np.sqrt(np.maximum(1.0 - blur_pdf, 0.0)), 0.0)
    return np.sqrt(np.maximum(alpha, roughness * roughness)), w


def _blurred_means(roughness, filter_glossy, integrands):
    """(K, M) means over the visible normals of ``integrands(cos_h)`` (K, M, N) times the masking
    weight, averaged over Filter Glossy's blur (``blurred_roughness``)."""
    out = 0.0
    for r, w in zip(*blurred_roughness(roughness, filter_glossy)):
        n = visible_normals(float(r))
        out = out + w * (n.weight[None] * integrands(n.cos_h)).mean(axis=2)
    return out


@lru_cache(maxsize=256)
def _dielectric_moments(roughness, eta, filter_glossy):
    """((M,) mean masking weight, (M,) its mean with the remap factor s, blurred; (M,) Cycles'
    estimate of s, unblurred) of GGX at ``roughness`` under the Fresnel of ``eta``: a layer's
    albedo is linear in its F0 through these."""
    f0_real = float(f0_from_ior(eta))

    def s_of(cos_h):
        return np.clip((fresnel_dielectric(cos_h, eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0)

    W, S = _blurred_means(roughness, filter_glossy, lambda c: np.stack([np.ones_like(c), s_of(c)]))
    n = visible_normals(float(roughness))
    # Cycles' table of s averages it over the visible normals whose reflection leaves the surface
    # (unweighted by masking)
    return W, S, (s_of(n.cos_h) * n.valid).mean(axis=1)


@lru_cache(maxsize=256)
def _metallic_moments(roughness, filter_glossy):
    """(M,) means of the masking weight times 1, (1 - cos)^5 and cos (1 - cos)^6 (blurred): the
    F82-tint Fresnel is linear in these."""
    def integrands(c):
        s = 1.0 - c
        return np.stack([np.ones_like(c), s ** 5, c * s ** 6])

    return tuple(_blurred_means(roughness, filter_glossy, integrands))


def dielectric_layer(roughness, eta, f0, multiscatter=True, filter_glossy=0.0):
    """(albedo (M,C), estimate (M,C)) of a reflecting dielectric layer as the Principled BSDF's
    specular (or coat) closure: Fresnel from ``eta`` remapped to start at ``f0`` (C,) (its tint
    times the level's F0), as Cycles' generalised Schlick with a negative exponent. ``estimate``
    is what Cycles takes as the layer's albedo to weight the layers below (the Fresnel averaged over
    visible normals, times the multiple-scattering darkening of the closure's weight, not counting
    the masking), ``albedo`` what the layer actually reflects (``filter_glossy``: after a diffuse
    bounce, with Cycles' Filter Glossy of that value)."""
    f0 = np.clip(np.atleast_1d(np.asarray(f0, dtype=np.float64)), 0.0, 1.0)
    layer = ggx(roughness)
    f0_real = float(f0_from_ior(eta))
    if abs(eta - 1.0) < 1e-12 or f0_real <= 0.0:
        zero = np.zeros((len(layer.E), len(f0)))
        return zero, zero
    W, S, s_estimate = _dielectric_moments(float(roughness), float(eta), float(filter_glossy))
    single = W[:, None] * f0[None, :] + (1.0 - f0[None, :]) * S[:, None]
    s_mean = np.clip((fresnel_dielectric_fss(eta) - f0_real) / (1.0 - f0_real), 0.0, 1.0)
    fss = f0 + (1.0 - f0) * s_mean
    estimate = (f0[None, :] + (1.0 - f0[None, :]) * s_estimate[:, None]) * _darkening(layer, fss, multiscatter)
    return _compensated(layer, single, fss, multiscatter), estimate


def metallic_layer(roughness, base, edge_tint=(1.0, 1.0, 1.0), multiscatter=True, filter_glossy=0.0):
    """(M,C) directional albedo of the Principled BSDF's metallic closure: GGX with the F82-tint
    conductor Fresnel, F0 = the base colour (clamped to 1), the 82-degree tint = Specular Tint
    (Cycles clamps the Fresnel to [0, 1]; with a tint at most 1 it stays there but for a sliver of
    grazing normals, left unclamped here)."""
    f0 = np.clip(np.atleast_1d(np.asarray(base, dtype=np.float64)), 0.0, 1.0)
    tint = np.minimum(np.broadcast_to(np.asarray(edge_tint, dtype=np.float64), f0.shape), 1.0)
    layer = ggx(roughness)
    f = 6.0 / 7.0
    f5 = f ** 5
    b = (f0 + (1.0 - f0) * f5) * (7.0 / (f5 * f)) * (1.0 - tint)
    W, S5, S6 = _metallic_moments(float(roughness), float(filter_glossy))
    single = W[:, None] * f0 + S5[:, None] * (1.0 - f0) - S6[:, None] * b
    fss = f0 + (1.0 - f0) / 21.0 - b / 126.0
    return _compensated(layer, single, fss, multiscatter)


@dataclass(frozen=True)
class PrincipledInputs:
    """The inputs of a Principled BSDF that change how much light it returns (plain values)."""

    base: tuple = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    roughness: float = 0.5
    ior: float = 1.5
    specular_ior_level: float = 0.5
    specular_tint: tuple = (1.0, 1.0, 1.0)
    transmission: float = 0.0
    coat: float = 0.0
    coat_roughness: float = 0.03
    coat_ior: float = 1.5
    coat_tint: tuple = (1.0, 1.0, 1.0)
    multiscatter: bool = True
    filter_glossy: float = 0.0  # Cycles' Filter Glossy for light that reaches the surface by a diffuse bounce


def specular_eta_f0(ior, level):
    """Cycles' Specular IOR Level: F0 scaled by 2 x level, and the IOR that has that F0."""
    ior = max(float(ior), 1e-5)
    f0 = float(f0_from_ior(ior))
    eta = ior
    if level != 0.5:
        f0 = min(f0 * 2.0 * max(float(level), 0.0), 1.0)
        eta = float(ior_from_f0(f0))
        if ior < 1.0:
            eta = 1.0 / eta
    return eta, f0


def _layers_out(p: PrincipledInputs, base):
    """(M,3) cosine-resolved ``out(mu)`` of the base-independent part and (M,3) the factor of the
    diffuse base, at the Gauss-Legendre nodes, with the metallic part at ``base`` (3,)."""
    rough = float(np.clip(p.roughness, 0.0, 1.0))
    M = MU_NODES
    weight = np.ones((M, 3))
    energy = np.zeros((M, 3))
    coat = max(float(p.coat), 0.0)
    if coat > 1e-5:
        coat_ior = max(float(p.coat_ior), 1.0)
        # (Cycles compensates the coat's multiple scattering whatever the distribution)
        albedo, estimate = dielectric_layer(float(np.clip(p.coat_roughness, 0, 1)), coat_ior,
                                            np.full(3, float(f0_from_ior(coat_ior))), True, p.filter_glossy)
        energy += coat * albedo
        weight *= np.clip(1.0 - (coat * estimate).max(axis=1, keepdims=True), 0.0, 1.0)
        tint = np.maximum(np.asarray(p.coat_tint, dtype=np.float64), 0.0)
        if not np.allclose(tint, 1.0):
            mu = mu_nodes()[0]
            cos_t = np.sqrt(1.0 - (1.0 - mu * mu) / coat_ior ** 2)
            weight *= 1.0 + coat * (tint[None, :] ** (1.0 / cos_t[:, None]) - 1.0)
    metallic = float(np.clip(p.metallic, 0.0, 1.0))
    if metallic > 1e-5:
        energy += weight * metallic * metallic_layer(rough, np.minimum(base, 1.0), p.specular_tint,
                                                     p.multiscatter, p.filter_glossy)
        weight = weight * (1.0 - metallic)
    transmission = float(np.clip(p.transmission, 0.0, 1.0))
    if transmission > 1e-5:
        eta = max(float(p.ior), 1e-5)
        f0 = float(f0_from_ior(eta)) * np.maximum(np.asarray(p.specular_tint, dtype=np.float64), 0.0)
        albedo, _ = dielectric_layer(rough, eta, f0, False, p.filter_glossy)
        energy += weight * transmission * albedo
        weight = weight * (1.0 - transmission)
    eta, f0 = specular_eta_f0(p.ior, p.specular_ior_level)
    if eta != 1.0:
        tint = np.maximum(np.asarray(p.specular_tint, dtype=np.float64), 0.0)
        albedo, estimate = dielectric_layer(rough, eta, f0 * tint, p.multiscatter, p.filter_glossy)
        energy += weight * albedo
        weight = weight * np.clip(1.0 - estimate.max(axis=1, keepdims=True), 0.0, 1.0)
    return energy, weight


def principled_albedo(p: PrincipledInputs, base=None):
    """(3,) hemispherical albedo of the Principled BSDF ``p`` under even light, at base colour
    ``base`` (default: ``p.base``)."""
    base = np.maximum(np.asarray(p.base if base is None else base, dtype=np.float64), 0.0)
    energy, weight = _layers_out(p, base)
    w = mu_nodes()[1][:, None]
    return (w * (energy + weight * base[None, :])).sum(axis=0)


def surface_terms(p: PrincipledInputs):
    """(scale (3,), offset (3,)): reflectivity = scale * base colour + offset, exact for a
    dielectric and, with metallic, the tangent at ``p.base`` (the metallic albedo is not linear in
    its colour)."""
    base = np.maximum(np.asarray(p.base, dtype=np.float64), 0.0)
    w = mu_nodes()[1][:, None]
    energy, weight = _layers_out(p, base)
    scale = (w * weight).sum(axis=0)
    offset = (w * energy).sum(axis=0)
    if float(np.clip(p.metallic, 0.0, 1.0)) > 1e-5:
        h = 1e-3
        up = (w * _layers_out(p, np.minimum(base + h, 1.0))[0]).sum(axis=0)
        down = (w * _layers_out(p, np.maximum(base - h, 0.0))[0]).sum(axis=0)
        slope = (up - down) / (np.minimum(base + h, 1.0) - np.maximum(base - h, 0.0))
        scale = scale + slope
        offset = offset - slope * base
    return scale, offset


def view_terms(p: PrincipledInputs, count=VIEW_POINTS):
    """(mu (count,), scale (count,3), offset (count,3)): ``surface_terms`` as a viewer at the
    cosine mu sees the surface under even light, at ``count`` evenly spaced cosines from 0 to 1
    (linear between the Gauss-Legendre nodes, held beyond them). The glossy layers' directional
    albedo rises towards grazing and the base colour's weight falls with it (the layering
    ``_layers_out`` models); their cosine-weighted means are ``surface_terms``' (up to the
    interpolation). A dielectric's (the tangent at the base colour for metallic is not kept)."""
    base = np.maximum(np.asarray(p.base, dtype=np.float64), 0.0)
    energy, weight = _layers_out(p, base)
    nodes = mu_nodes()[0]
    mu = np.linspace(0.0, 1.0, int(count))
    at = lambda values: np.stack([np.interp(mu, nodes, values[:, c]) for c in range(3)], axis=1)
    return mu, at(weight), at(energy)


def glossy_terms(p: PrincipledInputs):
    """(share (3,), alpha): the part of the hemispherical albedo its glossy layers reflect (the
    specular layer's, the metallic's at ``p.base``, a coat's and transmission's reflection), and
    the GGX alpha of the lobe it leaves along: the base roughness squared, widened as Filter
    Glossy widens it (the weighted mean of ``blurred_roughness``'s alphas; a coat's light is
    given the same lobe)."""
    base = np.maximum(np.asarray(p.base, dtype=np.float64), 0.0)
    energy, _ = _layers_out(p, base)
    share = (mu_nodes()[1][:, None] * energy).sum(axis=0)
    roughness, weight = blurred_roughness(float(np.clip(p.roughness, 0.0, 1.0)), p.filter_glossy)
    return share, float((weight * roughness ** 2).sum() / weight.sum())
