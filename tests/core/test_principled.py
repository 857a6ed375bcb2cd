"""The Principled BSDF's hemispherical albedo (addon/core/materials/principled.py) against independent
integrals over outgoing directions and known limits."""
import numpy as np
import pytest

from addon.core.materials import principled as pr


def brute_force(roughness, mu, eta, f0, n_theta=1200, n_phi=720):
    """(single-scattering albedo, Cycles' layering estimate) of the Principled specular layer at
    view cosine ``mu``, integrated over outgoing directions (Gauss-Legendre in cos theta, midpoint
    in phi) from the GGX density, height-correlated Smith masking and the remapped Fresnel."""
    alpha = roughness ** 2
    x, w = np.polynomial.legendre.leggauss(n_theta)
    cos_o, w = 0.5 * (x + 1.0), 0.5 * w
    phi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    cos_o, phi = np.meshgrid(cos_o, phi, indexing="ij")
    sin_o = np.sqrt(1 - cos_o ** 2)
    wo = np.stack([sin_o * np.cos(phi), sin_o * np.sin(phi), cos_o], axis=-1)
    wi = np.array([np.sqrt(1 - mu * mu), 0.0, mu])
    h = wo + wi
    h /= np.linalg.norm(h, axis=-1, keepdims=True)
    cos_nh, cos_ih = h[..., 2], (h * wi).sum(axis=-1)
    D = alpha ** 2 / (np.pi * (cos_nh ** 2 * (alpha ** 2 - 1) + 1) ** 2)
    lam = lambda c: 0.5 * (np.sqrt(1 + alpha ** 2 * (1 / c ** 2 - 1)) - 1)  # noqa: E731
    f0_real = ((eta - 1) / (eta + 1)) ** 2
    s = np.clip((pr.fresnel_dielectric(cos_ih, eta) - f0_real) / (1 - f0_real), 0, 1)
    F = f0 + (1 - f0) * s
    dw = (w[:, None] * np.full(n_phi, 2 * np.pi / n_phi)[None, :])  # d(cos) d(phi)
    single = (D * F / (4 * mu * (1 + lam(mu) + lam(cos_o))) * dw).sum()
    s_estimate = (D * s / (4 * mu * (1 + lam(mu))) * dw).sum()
    return single, f0 + (1 - f0) * s_estimate


@pytest.mark.parametrize("roughness", [0.3, 0.5, 1.0])
def test_single_scattering_albedo_matches_an_integral_over_outgoing_directions(roughness):
    """The visible-normal quadrature against a brute-force integral of the BRDF over the
    outgoing hemisphere, at Gauss-Legendre view cosines (not the most grazing, where the brute
    force's grid does not resolve the lobe): its own error, measured by halving its grid, is far
    below the tolerance, which is the midpoint rule's error where reflections cross the horizon."""
    mu = pr.mu_nodes()[0]
    eta, f0 = 1.5, 0.04
    albedo, estimate = pr.dielectric_layer(roughness, eta, [f0], multiscatter=False)
    for k in (8, 12, 20, 28):
        single, est = brute_force(roughness, mu[k], eta, f0)
        coarse, _ = brute_force(roughness, mu[k], eta, f0, 600, 360)
        assert abs(single - coarse) < 2e-4
        assert albedo[k, 0] == pytest.approx(single, abs=2e-3)
        assert estimate[k, 0] == pytest.approx(est, abs=2e-3)


def test_no_fresnel_ggx_albedo_matches_the_brute_force_and_is_one_when_smooth():
    mu = pr.mu_nodes()[0]
    for roughness in (0.5, 1.0):
        E = pr.ggx(roughness).E
        for k in (5, 25):
            single, _ = brute_force(roughness, mu[k], 1e6, 1.0)  # F = 1 everywhere
            assert E[k] == pytest.approx(single, abs=1.5e-3)
    np.testing.assert_allclose(pr.ggx(0.0).E, 1.0, atol=1e-9)
    assert pr.ggx(1.0).E_avg < pr.ggx(0.5).E_avg < pr.ggx(0.1).E_avg < 1.0


def test_a_smooth_surface_reflects_the_fresnel_reflectance():
    """Roughness 0: a mirror, whose directional albedo is the Fresnel reflectance at the view."""
    mu = pr.mu_nodes()[0]
    for eta in (1.33, 1.5, 2.4):
        albedo, estimate = pr.dielectric_layer(0.0, eta, [float(pr.f0_from_ior(eta))])
        np.testing.assert_allclose(albedo[:, 0], pr.fresnel_dielectric(mu, eta), atol=1e-8)
        np.testing.assert_allclose(estimate[:, 0], pr.fresnel_dielectric(mu, eta), atol=1e-8)


def test_default_principled_returns_its_specular_light_on_top_of_a_scaled_base():
    """Defaults (roughness 0.5, IOR 1.5, level 0.5, Multiscatter GGX): the diffuse base keeps
    1 - the layering estimate, the specular layer adds its own multiple-scattering albedo; both
    from the brute-force integrals (a 32-node cosine-weighted mean over the view). Cycles' own
    furnace render of these materials is in benchmarks/results/principled.md."""
    p = pr.PrincipledInputs()
    scale, offset = pr.surface_terms(p)
    mu, w = pr.mu_nodes()
    layer = pr.ggx(0.5)
    single = np.empty(len(mu))
    est = np.empty(len(mu))
    for k, m in enumerate(mu):
        single[k], est[k] = brute_force(0.5, m, 1.5, 0.04, 400, 240)
    fss = 0.04 + 0.96 * np.clip((pr.fresnel_dielectric_fss(1.5) - 0.04) / 0.96, 0, 1)
    fms = fss * layer.E_avg / (1 - fss * (1 - layer.E_avg))
    darkening = layer.E + fms * (1 - layer.E)  # on the closure's weight, so on its estimate too
    albedo = single / layer.E * darkening
    np.testing.assert_allclose(scale, (w * (1 - est * darkening)).sum(), atol=1e-3)
    np.testing.assert_allclose(offset, (w * albedo).sum(), atol=1e-3)
    base = np.array([0.8, 0.8, 0.8])
    total = pr.principled_albedo(p)
    np.testing.assert_allclose(total, scale * base + offset, rtol=1e-12)
    assert 0.05 < offset[0] < 0.07 and 0.93 < scale[0] < 0.95
    # a saturated floor: its blue channel gets more than twice its base colour's light
    brown = pr.principled_albedo(pr.PrincipledInputs(base=(0.3, 0.1, 0.02)))
    assert brown[2] > 2 * 0.02 and brown[0] < 0.3 + offset[0]


def test_the_terms_as_a_viewer_sees_them_are_the_layers_at_the_view_and_average_to_the_surface_terms():
    """``view_terms``: at each view cosine the glossy layers' directional albedo and the base's
    weight (the layering at that view), here at the Gauss-Legendre nodes themselves; a mirror's
    the Fresnel reflectance at the view; between the points linear, and their cosine-weighted
    means the surface terms (within 0.5% of the offset: the linear interpolation's)."""
    for p in (pr.PrincipledInputs(), pr.PrincipledInputs(roughness=0.2), pr.PrincipledInputs(roughness=0.05, coat=0.5)):
        energy, weight = pr._layers_out(p, np.zeros(3))
        nodes = pr.mu_nodes()[0]
        mu, scale, offset = pr.view_terms(p, count=len(nodes))
        assert mu[0] == 0 and mu[-1] == 1 and np.all(np.diff(mu) > 0)
        inside = (mu > nodes[0]) & (mu < nodes[-1])
        np.testing.assert_allclose(offset[inside, 0], np.interp(mu[inside], nodes, energy[:, 0]), rtol=1e-12)
        assert offset[0, 0] > 4 * offset[-1, 0] and scale[0, 0] < scale[-1, 0]  # (grazing: more glossy, less base)
        x = np.linspace(0.0, 1.0, 200_001)
        mean = lambda values: np.trapz(2 * x * np.interp(x, *pr.view_terms(p)[:1], values[:, 0]), x)
        s, o = pr.surface_terms(p)
        _, view_scale, view_offset = pr.view_terms(p)
        assert abs(mean(view_offset) - o[0]) < 0.005 * o[0] and abs(mean(view_scale) - s[0]) < 0.005 * o[0]
    eta = 1.5
    mu, _, offset = pr.view_terms(pr.PrincipledInputs(roughness=0.0, ior=eta))
    inside = mu > pr.mu_nodes()[0][0]
    exact = np.interp(mu[inside], pr.mu_nodes()[0], pr.fresnel_dielectric(pr.mu_nodes()[0], eta))
    np.testing.assert_allclose(offset[inside, 0], exact, atol=1e-8)


def test_limits_give_the_plain_diffuse_or_all_the_light():
    for p in (pr.PrincipledInputs(specular_ior_level=0.0), pr.PrincipledInputs(ior=1.0),
              pr.PrincipledInputs(specular_ior_level=0.0, roughness=1.0)):
        scale, offset = pr.surface_terms(p)
        np.testing.assert_allclose(scale, 1.0)
        np.testing.assert_allclose(offset, 0.0)
    # a white metal with Multiscatter GGX returns all the light, at every roughness
    for roughness in (0.0, 0.3, 1.0):
        np.testing.assert_allclose(pr.principled_albedo(pr.PrincipledInputs(base=(1, 1, 1), metallic=1.0,
                                                                             roughness=roughness)), 1.0, atol=1e-9)
    # single-scattering GGX loses light as it gets rough; Multiscatter keeps a white dielectric at 1
    # within what Cycles' layering by an estimate leaves
    for roughness in (0.0, 0.5, 1.0):
        white = pr.principled_albedo(pr.PrincipledInputs(base=(1, 1, 1), roughness=roughness))
        np.testing.assert_allclose(white, 1.0, atol=3e-3)
    single = pr.principled_albedo(pr.PrincipledInputs(base=(1, 1, 1), metallic=1.0, roughness=1.0,
                                                      multiscatter=False))
    np.testing.assert_allclose(single, pr.ggx(1.0).E_avg, rtol=1e-9)


def test_metallic_terms_are_the_tangent_at_the_base_colour():
    p = pr.PrincipledInputs(base=(0.9, 0.6, 0.2), metallic=1.0, roughness=0.3)
    scale, offset = pr.surface_terms(p)
    base = np.array(p.base)
    np.testing.assert_allclose(scale * base + offset, pr.principled_albedo(p), atol=1e-12)
    near = base + 0.01
    np.testing.assert_allclose(scale * near + offset, pr.principled_albedo(p, near), atol=2e-4)
    # a metal reflects about its colour (F0) and more towards grazing views
    assert np.all(pr.principled_albedo(p) > base)


def test_coat_and_tint_and_transmission_change_the_terms_as_layers():
    plain = pr.surface_terms(pr.PrincipledInputs())
    coat = pr.surface_terms(pr.PrincipledInputs(coat=1.0))
    assert coat[0][0] < plain[0][0] and coat[1][0] > plain[1][0]  # the coat takes from below, adds on top
    tinted = pr.surface_terms(pr.PrincipledInputs(coat=1.0, coat_tint=(1.0, 0.5, 0.5)))
    assert tinted[0][1] < tinted[0][0]
    glass = pr.surface_terms(pr.PrincipledInputs(transmission=1.0))
    np.testing.assert_allclose(glass[0], 0.0, atol=1e-12)  # nothing of the base colour is diffuse
    assert 0.03 < glass[1][0] < 0.12  # only the glass's reflection is counted
    red_tint = pr.surface_terms(pr.PrincipledInputs(specular_tint=(1.0, 0.0, 0.0)))
    assert red_tint[1][1] == pytest.approx(red_tint[1][2]) and red_tint[1][0] > red_tint[1][1]
    assert red_tint[0][0] == pytest.approx(plain[0][0])  # the layer below is weighted by its strongest colour


def test_filter_glossy_widens_lobes_reached_by_a_diffuse_bounce_and_keeps_their_compensation():
    """Cycles' Filter Glossy 1: after a diffuse bounce of pdf cos/pi a lobe's alpha is at least
    0.5 sqrt(1 - cos/pi); its multiple-scattering compensation stays that of the unblurred lobe,
    so a smooth lobe loses light and a rough one (alpha >= 0.5) is untouched."""
    r, w = pr.blurred_roughness(0.5, 1.0)
    np.testing.assert_allclose(w.sum(), 1.0)
    assert np.all((r ** 2 >= 0.5 * np.sqrt(1 - 1 / np.pi) - 1e-12) & (r ** 2 <= 0.5))
    np.testing.assert_array_equal(pr.blurred_roughness(0.9, 1.0)[0], 0.9)
    np.testing.assert_array_equal(pr.blurred_roughness(0.2, 0.0)[0], 0.2)
    rough = pr.PrincipledInputs(base=(1, 1, 1), metallic=1.0, roughness=0.8, filter_glossy=1.0)
    np.testing.assert_allclose(pr.principled_albedo(rough), 1.0, atol=1e-9)
    smooth = pr.PrincipledInputs(base=(1, 1, 1), metallic=1.0, roughness=0.3, filter_glossy=1.0)
    assert 0.7 < pr.principled_albedo(smooth)[0] < 0.95
    # the diffuse base keeps the unblurred layer's estimate: only the specular light changes
    seen, passed = pr.surface_terms(pr.PrincipledInputs()), pr.surface_terms(pr.PrincipledInputs(filter_glossy=1.0))
    np.testing.assert_allclose(seen[0], passed[0])
    assert 0.6 * seen[1][0] < passed[1][0] < 0.8 * seen[1][0]
