"""The glossy share of the first reflection sent along its lobe (addon/core/materials/glossy.py): the lobe's
directions as GGX makes them, and a sunlit floor's glossy light landing where its mirror image
falls, against the exact irradiance of an open floor-and-wall scene."""
import numpy as np
import pytest
from boxes import rectangles_to_mesh

from addon.core import PatchScene
from addon.core.materials import glossy, principled
from addon.core.lights.lights import SunLight
from addon.core.estimate.reference import rectangle_form_factors
from addon.core.solver import solve

S = np.sqrt(0.5)


def test_a_smooth_lobe_is_the_mirror_and_every_direction_leaves_above_the_surface():
    rng = np.random.default_rng(3)
    n = 4000
    normal = rng.normal(size=(3, n))
    normal /= np.linalg.norm(normal, axis=0)
    towards = rng.normal(size=(3, n))
    towards /= np.linalg.norm(towards, axis=0)
    towards *= np.where(np.einsum("in,in->n", normal, towards) < 0, -1.0, 1.0)  # (the light in front)
    keep = np.einsum("in,in->n", normal, towards) > 0.05  # (not grazing: there even a smooth lobe dips below)
    normal, towards, n = normal[:, keep], towards[:, keep], int(keep.sum())
    mirror = 2.0 * np.einsum("in,in->n", normal, towards) * normal - towards
    for alpha, closest in ((1e-6, 0.9999), (0.25, -1.0)):  # (GGX's tails: 1e-6 to keep them off)
        out = glossy.reflect(normal, towards, np.full(n, alpha), rng)
        assert np.allclose(np.linalg.norm(out, axis=0), 1.0, atol=1e-9)
        assert (np.einsum("in,in->n", normal, out) > 0).all()
        assert (np.einsum("in,in->n", mirror, out) >= closest).all()


@pytest.mark.parametrize("alpha,degrees", [(0.09, 45.0), (0.36, 45.0), (0.36, 75.0)])
def test_the_lobe_is_ggxs_single_scattering_lobe_times_the_cosine(alpha, degrees):
    """Light from ``degrees`` off the normal: the outgoing elevation of 200,000 directions, in 12
    bins of cos, against the brute-force integral of D(h) G2 / (4 cos_i) (GGX, height-correlated
    masking, Fresnel 1) over the hemisphere: every bin within 4.5 standard errors."""
    n = 200_000
    mu = np.cos(np.radians(degrees))
    towards = np.tile([[np.sqrt(1 - mu * mu)], [0.0], [mu]], n)
    normal = np.tile([[0.0], [0.0], [1.0]], n)
    out = glossy.reflect(normal, towards, np.full(n, alpha), np.random.default_rng(8))
    edges = np.linspace(0.0, 1.0, 13)
    found = np.histogram(out[2], edges)[0] / n
    # the integral: a fine grid over (cos_o, phi), the density times the area element dcos dphi
    c = np.linspace(0.0, 1.0, 4001)[1:] - 0.5 / 4000
    phi = (np.arange(720) + 0.5) * (2 * np.pi / 720)
    C, PHI = np.meshgrid(c, phi, indexing="ij")
    S = np.sqrt(1 - C * C)
    wo = np.stack([S * np.cos(PHI), S * np.sin(PHI), C])
    wi = np.array([np.sqrt(1 - mu * mu), 0.0, mu])[:, None, None]
    h = wo + wi
    h /= np.linalg.norm(h, axis=0)
    a2 = alpha * alpha
    D = a2 / (np.pi * (h[2] ** 2 * (a2 - 1) + 1) ** 2)
    G2 = 1.0 / (1.0 + principled.smith_lambda(alpha, mu) + principled.smith_lambda(alpha, C))
    density = (D * G2).sum(axis=1)
    expected = np.array([density[(c >= lo) & (c < hi)].sum() for lo, hi in zip(edges[:-1], edges[1:])])
    expected /= expected.sum()
    error = np.sqrt(expected * (1 - expected) / n) + 1e-6
    assert np.abs(found - expected).max() < 4.5 * error.max()
    assert (np.abs(found - expected) < 4.5 * error + 2e-4).all()


def _floor_and_wall(share):
    """A unit floor (8 x 8 patches, R 0.5 of which ``share`` glossy, alpha 1e-6: a mirror, GGX's
    tails and all) and a grey wall (R 0.3) 0.5 beyond it facing it (x = 1.5, 8 x 8 patches of
    0.25), lit by two suns travelling along (1, 0, -1) / sqrt 2 of irradiance 0.6 and 0.4. (scene, F, R (P,), g (P,), origin)."""
    rows = []
    for i in range(8):
        for j in range(8):
            rows.append(((i / 8, j / 8, 0.0), (1 / 8, 0, 0), (0, 1 / 8, 0)))
    for i in range(8):
        for j in range(8):
            rows.append(((1.5, -0.5 + i / 4, j / 4), (0, 0, 0.25), (0, 0.25, 0)))
    origin, u, v = (np.array([r[k] for r in rows], dtype=np.float64) for k in range(3))
    V, T, TP = rectangles_to_mesh(origin, u, v)
    P = len(rows)
    R = np.r_[np.full(64, 0.5), np.full(64, 0.3)]
    g = np.r_[np.full(64, share), np.zeros(64)]
    suns = [SunLight(np.array([S, 0.0, -S]), np.full(3, e), name=name) for e, name in ((0.6, "a"), (0.4, "b"))]
    lobe = (np.repeat(g[:, None], 3, axis=1), np.full(P, 1e-6)) if share > 0 else None
    scene = PatchScene(V, T, TP, np.repeat(R[:, None], 3, axis=1), np.zeros((P, 3)), lights=suns, glossy=lobe)
    return scene, rectangle_form_factors(origin, u, v), R, g, origin


def _exact(F, R, g, origin):
    """(P,) the exact irradiance H = H0 + X: the suns' H0 = S on every patch; the floor's first
    reflection of it, its diffuse part (R - g) H0 spread by the form factors and its glossy part
    mirrored onto the wall's band the floor's image covers (y in [0, 1], z in [0.5, 1.5]) at
    g S (a mirror keeps the beam's footprint: z = 1.5 - x); every later reflection R X diffuse:
    (I - F R) X = H_g + F (R - g) H0."""
    H0 = np.full(R.size, S)
    wall = origin[:, 0] > 1.2
    y, z = origin[:, 1], origin[:, 2]
    band = wall & (y >= 0) & (y < 1) & (z >= 0.5) & (z < 1.5)
    glossy = band * g.max() * S
    X = np.linalg.solve(np.eye(R.size) - F * R[None, :], glossy + F @ ((R - g) * H0))
    return H0 + X, band


@pytest.mark.parametrize("method,per_source", [("two_way", False), ("two_way", True), ("walk", False), ("walk", True)])
def test_a_sunlit_floors_glossy_light_lands_where_its_mirror_image_falls(method, per_source):
    """Floor share 0.4 glossy: the 128 patches' irradiance within 4.5 of their batch standard
    errors of the exact one (mean squared z below 2), each sun's per-source part its share of it;
    the same floor reflecting all of it evenly (the product before this lobe) is far off."""
    scene, F, R, g, origin = _floor_and_wall(0.4)
    exact, band = _exact(F, R, g, origin)
    kwargs = dict(direct_light="gathered") if method == "walk" else {}
    result = solve(scene, paths=300_000, seed=2, exit_point="hit", method=method, per_source=per_source, **kwargs)
    H = result.irradiance[:, 0]
    error = np.sqrt(result.irradiance_variance[:, 0])
    z = (H - exact) / error
    assert np.abs(z).max() < 4.5 and (z ** 2).mean() < 2.0
    if per_source:  # each sun's part of the band's light: its share of the exact within 1% (6 of its standard errors)
        ps = result.per_source
        for name, part in (("a", 0.6), ("b", 0.4)):
            found = ps.irradiance[list(ps.names).index(name), band, 0].mean()
            assert found / (part * exact[band].mean()) == pytest.approx(1.0, abs=0.01)
    plain = solve(scene.with_materials(scene.reflectivity, scene.emission, glossy=None), paths=300_000, seed=2,
                  exit_point="hit", method=method, **kwargs)
    z_plain = (plain.irradiance[:, 0] - exact) / error
    assert np.abs(z_plain[band]).min() > 10


@pytest.mark.parametrize("method", ["two_way", "walk"])
def test_a_mirror_floor_shows_the_wall_the_sky_it_reflects(method):
    """The same floor and wall under a sky bright only above and behind the floor (radiance
    W / pi in the directions x < 0, z > 0; black elsewhere), found by the gathering's cosine rays
    alone. Each patch sees half of its cosine-weighted hemisphere bright and nothing of the
    other surface there: H0 = W / 2. The mirror floor (share 0.4) shows the wall the bright sky
    wherever the wall sees the floor: 0.4 W times its form factor to the floor (the floor
    reflecting evenly would give it half of that). Against (I - F R) X = 0.4 W F_wall,floor +
    F (R - g) H0: the 128 patches within 4.5 batch standard errors (mean squared z below 2);
    the floor reflecting evenly leaves the wall's mean more than 10 of its standard errors off."""
    from addon.core.lights.lights import WorldLight

    scene, F, R, g, origin = _floor_and_wall(0.4)
    W = 0.7
    sky = np.zeros((16, 32, 3))  # equirectangular: rows from +z down, columns of x < 0 the outer quarters
    sky[:8, :8] = sky[:8, 24:] = W
    scene = scene.with_materials(scene.reflectivity, scene.emission, lights=[WorldLight(image=sky)])
    wall = origin[:, 0] > 1.2
    H0 = np.full(R.size, 0.5 * W)
    glossy = wall * g.max() * W * F[:, ~wall].sum(axis=1)
    exact = H0 + np.linalg.solve(np.eye(R.size) - F * R[None, :], glossy + F @ ((R - g) * H0))
    kwargs = dict(direct_light="gathered") if method == "walk" else {}
    result = solve(scene, paths=400_000, seed=4, exit_point="hit", method=method, **kwargs)
    error = np.sqrt(result.irradiance_variance[:, 0])
    z = (result.irradiance[:, 0] - exact) / error
    assert np.abs(z).max() < 4.5 and (z ** 2).mean() < 2.0
    plain = solve(scene.with_materials(scene.reflectivity, scene.emission, glossy=None), paths=400_000, seed=4,
                  exit_point="hit", method=method, **kwargs)
    mean_error = np.sqrt((error[wall] ** 2).sum()) / wall.sum()  # the wall's mean's standard error
    assert abs((plain.irradiance[wall, 0] - exact[wall]).mean()) > 10 * mean_error
