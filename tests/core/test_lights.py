"""Lights as sources beside emissive patches (addon/core/lights/lights.py), against exact references:
solid angles and form factors for the first bounce and the direct solve of B = E + R F B for the
rest; a sun on a plane (H cos theta); a uniform world over an open plane; energy balance with
every kind; a furnace with a light inside. Bands are z-scores from each run's own batch
variances (>= 32 batches; P(max |t| > 5) over these patch counts < 1e-3)."""
import math

import numpy as np
import pytest
from boxes import box_rectangles, rectangles_to_mesh

from addon.core import PatchScene, solve
from addon.core.lights.lights import AreaLight, PointLight, Spot, SunLight, WorldLight
from addon.core.estimate.reference import rectangle_form_factors, solve_radiosity_system

Z = 5.0
DIRECT_LIGHTS = ("shot", "gathered")  # every light, shot by the walk and gathered (first_shot)
R_FACES = np.array([0.3, 0.5, 0.7, 0.5, 0.6, 0.4])
SIZE = (1.0, 1.2, 0.9)


def _box(n=3, reflectivity=None, lights=()):
    origin, u, v, face = box_rectangles(SIZE, n=n)
    V, T, TP = rectangles_to_mesh(origin, u, v)
    R = R_FACES[face] if reflectivity is None else np.asarray(reflectivity)[face]
    scene = PatchScene(V, T, TP, R, np.zeros(len(origin)), lights=lights)
    return scene, (origin, u, v), rectangle_form_factors(origin, u, v)


def _solid_angle_of_triangles(a, b, c):
    """Solid angle of triangles with corners a, b, c (n,3) seen from the origin (Van Oosterom
    and Strackee)."""
    la, lb, lc = (np.linalg.norm(x, axis=-1) for x in (a, b, c))
    dot = lambda x, y: np.einsum("ij,ij->i", x, y)  # noqa: E731
    numerator = np.abs(dot(a, np.cross(b, c)))
    return 2 * np.arctan2(numerator, la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la)


def _solid_angles(point, rectangles):
    origin, u, v = rectangles
    a, b, c, d = origin - point, origin + u - point, origin + u + v - point, origin + v - point
    return _solid_angle_of_triangles(a, b, c) + _solid_angle_of_triangles(a, c, d)


def _z(result, exact, channel=0):
    """z-scores of the reflected radiosity; 0 where an estimate without variance is exact (a
    gathered sky over an open plane), inf where it is not."""
    error = result.reflected[:, channel] - exact
    sd = np.sqrt(result.reflected_variance[:, channel])
    exact_enough = np.abs(error) <= 1e-12 * np.maximum(np.abs(exact), 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(sd > 0, error / sd, np.where(exact_enough, 0.0, np.inf))


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_a_point_light_in_a_closed_box_is_the_direct_solve(estimator, direct_light):
    """First bounce: a patch of solid angle Omega seen from a light of intensity I receives
    I Omega; then B' = D + R F B' with D = R I Omega / A (the discrete solution, random exit)."""
    position, intensity = np.array([0.3, 0.7, 0.5]), 2.0
    scene, rectangles, F = _box(lights=[PointLight(position, np.full(3, intensity))])
    omega = _solid_angles(position, rectangles)
    assert omega.sum() == pytest.approx(4 * math.pi, rel=1e-12)
    direct = R_FACES.repeat(9) * intensity * omega / scene.patch_area
    exact = solve_radiosity_system(F, scene.reflectivity, direct)[:, 0]
    r = solve(scene, estimator=estimator, paths=600_000, seed=3, threshold=1e-6, direct_light=direct_light)
    assert r.chunks >= 32
    assert np.abs(_z(r, exact)).max() < Z
    np.testing.assert_allclose(r.energy["emitted"], 4 * math.pi * intensity, rtol=1e-12)


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_a_sphere_light_is_a_point_light_seen_from_far_and_keeps_its_power(direct_light):
    """A sphere light of radius r gives what a point light of the same intensity gives (a
    uniformly radiant sphere wholly above a surface's horizon lights it exactly as a point
    does: here r = 0.02 m, 0.3 m or more from any wall), and emits 4 pi I."""
    position, intensity = np.array([0.5, 0.6, 0.45]), 1.5
    point = _box(lights=[PointLight(position, np.full(3, intensity))])[0]
    sphere = _box(lights=[PointLight(position, np.full(3, intensity), radius=0.02)])[0]
    a = solve(point, paths=400_000, seed=4, direct_light=direct_light)
    b = solve(sphere, paths=400_000, seed=5, direct_light=direct_light)
    np.testing.assert_allclose(b.energy["emitted"], 4 * math.pi * intensity, rtol=1e-12)
    sd = np.sqrt(a.reflected_variance[:, 0] + b.reflected_variance[:, 0])
    assert np.abs((a.reflected[:, 0] - b.reflected[:, 0]) / sd).max() < Z


def _floor_under_spot(position, spot, n, seed, direct_light):
    """A box whose floor alone reflects (0.5) under a spot of intensity 1: the solve (checked to
    emit I times the mask's solid angle), the scene, the floor's exact reflected light if it
    received the whole point light (0.5 I Omega / A), and the floor patches' corners from the light."""
    scene = _box(n=n, reflectivity=[0.0] * 6, lights=[PointLight(position, np.full(3, 1.0), spot=spot)])[0]
    lit = scene.with_materials(np.where(np.arange(scene.patch_count) < n * n, 0.5, 0.0), scene.emission)
    r = solve(lit, paths=500_000, seed=seed, direct_light=direct_light)
    np.testing.assert_allclose(r.energy["emitted"], spot.solid_angle(), rtol=1e-12)
    origin, u, v, _ = box_rectangles(SIZE, n=n)
    floor = slice(0, n * n)
    omega = _solid_angles(position, (origin[floor], u[floor], v[floor]))
    corners = np.stack([origin[floor], origin[floor] + u[floor], origin[floor] + v[floor], origin[floor] + u[floor] + v[floor]]) - position
    return r, lit, 0.5 * omega / lit.patch_area[floor], corners


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_a_spot_light_masks_a_point_light(direct_light):
    """A spot aimed at the floor: its power is I times the mask's solid angle, and the floor
    patches under the full cone receive what the point light gives them, patches outside the
    cone nothing directly (the walls' light then comes from the floor)."""
    position = np.array([0.5, 0.6, 0.5])
    spot = Spot(axis=np.array([0.0, 0.0, -1.0]), cos_outer=math.cos(math.radians(30)), cos_inner=math.cos(math.radians(25)))
    assert spot.solid_angle() == pytest.approx(2 * math.pi * ((1 - spot.cos_inner) + 0.5 * (spot.cos_inner - spot.cos_outer)))
    # The mask's inverse CDF: sampled cosines follow the mask (a chi-square test on 40 bins).
    x = spot.sample_cosine(np.random.default_rng(1).random(400_000))
    edges = np.linspace(spot.cos_outer, 1.0, 41)
    observed = np.histogram(x, edges)[0]
    fine = np.linspace(spot.cos_outer, 1.0, 40_001)
    mass = np.add.reduceat(spot.mask(0.5 * (fine[1:] + fine[:-1])), np.arange(0, 40_000, 1000))
    expected = mass / mass.sum() * x.size
    chi2 = float(((observed - expected) ** 2 / expected).sum())
    assert chi2 < 80, chi2  # 39 degrees of freedom: P(chi2 > 80) < 1e-4
    n = 8
    r, lit, exact, corners = _floor_under_spot(position, spot, n, 6, direct_light)
    floor = slice(0, n * n)
    angle = np.degrees(np.arccos(-corners[..., 2] / np.linalg.norm(corners, axis=-1)))  # (4, 16)
    inside = angle.max(axis=0) < 25  # the whole patch inside the full cone
    outside = angle.min(axis=0) > 30  # the whole patch outside the cone
    assert inside.any() and outside.any()
    b, variance = r.reflected[floor, 0][inside], r.reflected_variance[floor, 0][inside]
    assert np.abs((b - exact[inside]) / np.sqrt(variance)).max() < Z
    assert (r.reflected[floor, 0][outside] == 0).all()


def _spot_of_matrix(matrix, degrees_outer, degrees_inner):
    """A spot shining along the light matrix's -Z, its cone shaped by the matrix as Cycles does:
    the local direction is the inverse matrix's image with its z turned."""
    to_local = np.linalg.inv(matrix) * np.array([1.0, 1.0, -1.0])[:, None]
    axis = -matrix[:, 2] / np.linalg.norm(matrix[:, 2])
    return Spot(axis, math.cos(math.radians(degrees_outer)), math.cos(math.radians(degrees_inner)), to_local=to_local)


def test_an_unevenly_scaled_spot_is_an_elliptical_cone():
    """Scaled evenly, the spot is its round cone (same mask, same solid angle). Scaled (2, 1, 1)
    with a hard edge, along each azimuth phi its edge is at tan(theta) = tan(theta_o) / m(phi),
    m = sqrt(cos^2 phi / 4 + sin^2 phi): the solid angle is the integral over phi of 1 - cos
    theta, and the sampled directions' azimuths follow 1 - cos theta(phi) (chi-square); with a
    blend, the solid angle is a uniform-sphere Monte Carlo estimate's, within 5 of its sd."""
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 degrees about z
    round_ = Spot(np.array([0.0, 0.0, -1.0]), math.cos(math.radians(30)), math.cos(math.radians(25)))
    even = _spot_of_matrix(rotation * 3.0, 30, 25)
    assert even.solid_angle() == pytest.approx(round_.solid_angle(), rel=1e-9)
    d = np.random.default_rng(2).normal(size=(3, 1000))
    d /= np.linalg.norm(d, axis=0)
    np.testing.assert_allclose(even.local_cosine(d), round_.local_cosine(d), atol=1e-12)

    scale = np.diag([2.0, 1.0, 1.0])
    hard = _spot_of_matrix(rotation @ scale, 30, 30)
    phi = 2 * math.pi * (np.arange(180_000) + 0.5) / 180_000  # the light's own x-y azimuth
    m = np.sqrt(np.cos(phi) ** 2 / 4 + np.sin(phi) ** 2)
    one_minus_cos = 1 - np.cos(np.arctan(math.tan(math.radians(30)) / m))
    assert hard.solid_angle() == pytest.approx(one_minus_cos.mean() * 2 * math.pi, rel=1e-6)
    rng = np.random.default_rng(3)
    u = rng.random((2, 300_000)).astype(np.float32)
    directions = hard.sample(u[0], u[1])
    assert (hard.mask(hard.local_cosine(directions)) > 0).all()
    np.testing.assert_array_equal(directions, hard.sample(u[0], u[1]))  # reproducible
    light_x, light_y = rotation[:, 0], rotation[:, 1]  # the light's own axes in the world
    azimuth = np.arctan2(light_y @ directions, light_x @ directions) % (2 * math.pi)
    observed = np.histogram(azimuth, np.linspace(0, 2 * math.pi, 37))[0]
    expected = one_minus_cos.reshape(36, -1).sum(axis=1) / one_minus_cos.sum() * azimuth.size
    chi2 = float(((observed - expected) ** 2 / expected).sum())
    assert chi2 < 75, chi2  # 35 degrees of freedom: P(chi2 > 75) < 1e-4

    blended = _spot_of_matrix(rotation @ scale, 40, 20)
    d = rng.normal(size=(3, 4_000_000))
    d /= np.linalg.norm(d, axis=0)
    f = 4 * math.pi * blended.mask(blended.local_cosine(d))
    assert abs(blended.solid_angle() - f.mean()) < 5 * f.std() / math.sqrt(f.size)
    assert blended.bounding_cos() < blended.cos_outer  # the long side reaches wider


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_an_elliptical_spot_lights_the_floor_of_its_ellipse(direct_light):
    """A spot scaled (2, 1, 1) aimed at the floor: power I times its solid angle; floor patches
    wholly inside its full (elliptical) cone get what the point light gives, patches wholly
    outside its bounding cone nothing directly."""
    position, n = np.array([0.5, 0.6, 0.5]), 10
    spot = _spot_of_matrix(np.diag([2.0, 1.0, 1.0]), 28, 25)
    r, lit, exact, corners = _floor_under_spot(position, spot, n, 7, direct_light)
    floor = slice(0, n * n)
    corners = corners / np.linalg.norm(corners, axis=-1, keepdims=True)
    local = np.stack([spot.local_cosine(c.T) for c in corners])  # (4, patches)
    inside = local.min(axis=0) > spot.cos_inner
    outside = (-corners[..., 2]).max(axis=0) < spot.bounding_cos()
    assert inside.sum() > 4 and outside.any()
    assert (inside & ((-corners[..., 2]).min(axis=0) < math.cos(math.radians(28)))).any()  # beyond the round cone
    b, variance = r.reflected[floor, 0][inside], r.reflected_variance[floor, 0][inside]
    assert np.abs((b - exact[inside]) / np.sqrt(variance)).max() < Z
    assert (r.reflected[floor, 0][outside] == 0).all()


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_an_area_light_is_a_rectangle_of_the_form_factor_reference(direct_light):
    """A rectangle light facing down, in the plane between the walls' top and middle rows of
    patches: the power a patch in front of it receives directly is M A_light F(light -> patch)
    (exact form factors between axis-aligned rectangles), a patch behind it none."""
    n = 3
    origin, u, v, face = box_rectangles(SIZE, n=n)
    light_origin, light_u, light_v = np.array([0.3, 0.4, 0.6]), np.array([0.0, 0.4, 0.0]), np.array([0.3, 0.0, 0.0])
    assert np.cross(light_u, light_v)[2] < 0  # u x v faces down: the light's front
    F_all = rectangle_form_factors(np.vstack([origin, light_origin]), np.vstack([u, light_u]), np.vstack([v, light_v]))
    behind = (origin + 0.5 * (u + v))[:, 2] > 0.6
    F_all[-1, :-1][behind] = 0.0
    exitance = 3.0
    light = AreaLight(centre=light_origin + 0.5 * (light_u + light_v), half_u=0.5 * light_u, half_v=0.5 * light_v,
                      normal=np.array([0.0, 0.0, -1.0]), exitance=np.full(3, exitance))
    scene, _, F = _box(n=n, lights=[light])
    light_area = 0.4 * 0.3
    direct = R_FACES[face] * exitance * light_area * F_all[-1, :-1] / scene.patch_area
    exact = solve_radiosity_system(F, scene.reflectivity, direct)[:, 0]
    r = solve(scene, paths=600_000, seed=7, direct_light=direct_light)
    np.testing.assert_allclose(r.energy["emitted"], exitance * light_area, rtol=1e-12)
    assert np.abs(_z(r, exact)).max() < Z


def test_an_ellipse_light_has_the_area_of_its_ellipse():
    light = AreaLight(centre=np.zeros(3), half_u=np.array([0.2, 0, 0]), half_v=np.array([0, 0.1, 0]),
                      normal=np.array([0, 0, -1.0]), exitance=np.ones(3), ellipse=True)
    assert light.area == pytest.approx(math.pi * 0.2 * 0.1)
    o, d = light.emit(np.zeros(50_000, dtype=np.int64), np.random.default_rng(2).random((4, 50_000), dtype=np.float32), None, None)
    assert ((o[0] / 0.2) ** 2 + (o[1] / 0.1) ** 2 <= 1 + 1e-12).all()
    # Cosine-distributed about the normal: E[cos] = 2/3 (z-score from its variance 1/18).
    cos = -d[2]
    assert abs(cos.mean() - 2 / 3) < 5 * math.sqrt((1 / 2 - 4 / 9) / cos.size)


def _plane(size=2.0, n=4, reflectivity=0.5):
    """An open square plane facing up (z = 0), n x n patches."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    cell = size / n
    origin = np.column_stack([i.ravel() * cell, j.ravel() * cell, np.zeros(n * n)]) - [size / 2, size / 2, 0]
    u = np.tile([cell, 0.0, 0.0], (n * n, 1))
    v = np.tile([0.0, cell, 0.0], (n * n, 1))
    return rectangles_to_mesh(origin, u, v), np.full(n * n, reflectivity)


@pytest.mark.parametrize("angle", [0.0, math.radians(10)])
@pytest.mark.parametrize("tilt", [0.0, 40.0])
@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_a_sun_on_a_plane_gives_h_cos_theta(tilt, angle, direct_light):
    """An open plane under a sun at ``tilt`` from the zenith: every patch receives H cos(tilt)
    (b = R H cos), whatever the sun's angular size (the cone's mean cosine: exact for it)."""
    (V, T, TP), R = _plane()
    t = math.radians(tilt)
    direction = np.array([math.sin(t), 0.0, -math.cos(t)])
    H = 2.0
    sun = SunLight(direction=direction, irradiance=np.full(3, H), angle=angle)
    scene = PatchScene(V, T, TP, R, np.zeros(R.size), lights=[sun])
    r = solve(scene, paths=400_000, seed=8, direct_light=direct_light)
    half = angle / 2
    # Mean cosine to the plane's normal over the sun's cone (uniform in solid angle about the axis).
    mean_cos = math.cos(t) * (1 + math.cos(half)) / 2
    exact = 0.5 * H * mean_cos * sun._beam_factor()
    assert np.abs(_z(r, exact)).max() < Z
    assert r.energy["escaped"][0] > 0  # the disc is wider than the plane


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_a_uniform_world_over_an_open_plane_gives_its_irradiance(direct_light):
    """An unoccluded plane under a uniform world W receives W (b = R W); half of the world's
    rays come from below and escape (or meet the plane's back: blocked)."""
    (V, T, TP), R = _plane()
    W = np.array([1.0, 0.5, 0.25])
    scene = PatchScene(V, T, TP, R, np.zeros(R.size), lights=[WorldLight(irradiance=W)])
    r = solve(scene, paths=600_000, seed=9, direct_light=direct_light)
    for c in range(3):
        assert np.abs(_z(r, 0.5 * W[c], c)).max() < Z
    if direct_light == "shot":  # (gathered, the sky's light from below is never traced)
        assert r.energy["blocked"].sum() > 0


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_an_equirectangular_world_of_one_bright_band_lights_a_plane_as_its_integral(direct_light):
    """A world image black but for the rows above 30 degrees of elevation: an up-facing plane
    receives (W / pi) times the projected solid angle of that cap, pi sin^2(60 deg) = 3 pi / 4."""
    (V, T, TP), R = _plane()
    H, Wd = 60, 120
    image = np.zeros((H, Wd, 3))
    image[: H // 3] = 2.0  # rows 0..19: polar angle 0..60 degrees
    scene = PatchScene(V, T, TP, R, np.zeros(R.size), lights=[WorldLight(image=image)])
    r = solve(scene, paths=500_000, seed=10, direct_light=direct_light)
    exact = 0.5 * 2.0 / math.pi * (math.pi * math.sin(math.radians(60)) ** 2)
    assert np.abs(_z(r, exact)).max() < Z


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_every_kind_balances_its_energy(estimator, direct_light):
    """In an open box with a card, lit by one light of every kind and an emissive patch: what
    the run emits is the scene's Phi_T, and it is absorbed, escapes, is blocked or (biased)
    undistributed, exactly."""
    from boxes import open_box_with_card

    base = open_box_with_card()
    lights = [
        PointLight(np.array([0.5, 0.5, 0.3]), np.array([1.0, 0.8, 0.6]), radius=0.05),
        PointLight(np.array([0.2, 0.2, 0.7]), np.ones(3), spot=Spot(np.array([0, 0, -1.0]), 0.8, 0.9)),
        AreaLight(np.array([0.7, 0.3, 0.9]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), np.array([0, 0, -1.0]), np.full(3, 2.0)),
        SunLight(np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0]), np.full(3, 1.5), angle=0.1),
        WorldLight(irradiance=np.array([0.2, 0.3, 0.4])),
    ]
    scene = base.with_materials(base.reflectivity, base.emission, lights=lights)
    assert not scene.is_grey
    r = solve(scene, estimator=estimator, paths=300_000, seed=11, threshold=1e-3, direct_light=direct_light)
    e = r.energy
    np.testing.assert_allclose(e["emitted"].mean(), scene.total_power, rtol=1e-9)
    np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)
    assert (e["escaped"] > 0).all() and (e["blocked"] > 0).all()


@pytest.mark.parametrize("direct_light", DIRECT_LIGHTS)
def test_a_furnace_with_a_light_inside_reflects_r_over_one_minus_r_of_its_power(direct_light):
    """A closed box of uniform R lit by a light anywhere inside: everything it emits is absorbed
    by the walls at (1 - R) a bounce, so sum_j b_j A_j = R Phi / (1 - R) in expectation."""
    R = 0.6
    scene = _box(reflectivity=[R] * 6, lights=[PointLight(np.array([0.2, 0.3, 0.7]), np.full(3, 1.0))])[0]
    r = solve(scene, paths=400_000, seed=12, direct_light=direct_light)
    total = float((r.reflected[:, 0] * scene.patch_area).sum())
    sd = math.sqrt(float((r.reflected_variance[:, 0] * scene.patch_area**2).sum()))  # (patches' errors are correlated: an upper bound would be their sum)
    exact = R * 4 * math.pi / (1 - R)
    assert abs(total - exact) < Z * float((np.sqrt(r.reflected_variance[:, 0]) * scene.patch_area).sum()), (total, exact, sd)


def test_lights_alone_light_a_scene_without_emissive_patches_and_bad_lights_are_refused():
    with pytest.raises(ValueError, match="no source"):
        _box(lights=[PointLight(np.zeros(3) + 0.5, np.zeros(3))])
    with pytest.raises(ValueError, match="negative"):
        _box(lights=[PointLight(np.zeros(3) + 0.5, np.array([1.0, -1.0, 1.0]), name="Lamp")])
    with pytest.raises(ValueError, match="'Lamp'.*NaN"):
        _box(lights=[PointLight(np.zeros(3) + 0.5, np.array([1.0, np.nan, 1.0]), name="Lamp")])


@pytest.mark.parametrize("light, field", [
    (PointLight(np.array([np.nan, 0.5, 0.5]), np.ones(3), name="Lamp"), "position"),
    (PointLight(np.full(3, 0.5), np.ones(3), radius=np.inf, name="Lamp"), "radius"),
    (PointLight(np.full(3, 0.5), np.ones(3), spot=Spot(np.array([0.0, 0.0, np.nan]), 0.5, 0.7), name="Lamp"),
     "spot axis"),
    (AreaLight(np.full(3, 0.5), np.array([0.1, 0, 0]), np.array([0, np.nan, 0]), np.array([0, 0, -1.0]), np.ones(3),
               name="Panel"), "half v"),
    (SunLight(np.array([0.0, np.nan, -1.0]), np.ones(3), name="Sun"), "direction"),
    (SunLight(np.array([0.0, 0.0, -1.0]), np.ones(3), angle=np.nan, name="Sun"), "angle"),
    (WorldLight(image=np.where(np.eye(4)[:, :, None] > 0, np.nan, 1.0) * np.ones((4, 4, 3)), name="Sky"), "image"),
])
def test_a_light_with_a_number_that_is_not_finite_is_refused_by_its_name_and_field(light, field):
    """A light at a NaN position (a driver, a script) lit nothing and left a black scene
    with a warning about the light's placement: it is refused, naming the light and the field."""
    with pytest.raises(ValueError, match=f"^light '{light.name}': its {field} is NaN or infinite$"):
        _box(lights=[light])


@pytest.mark.parametrize("kind", ["point", "area"])
def test_a_light_that_casts_no_shadow_lights_the_floor_through_an_occluder(kind):
    """A light above a board that hides part of the floor: with Cast Shadow off (Cycles) the
    floor under the board gets the light's unoccluded direct light, the exact solid-angle (point)
    or form-factor (area) value; a shooting walk cannot do that and is refused by name."""
    n = 6
    origin, u, v, face = box_rectangles(SIZE, n=n)
    board = (np.array([[0.3, 0.35, 0.4]]), np.array([[0.4, 0.0, 0.0]]), np.array([[0.0, 0.5, 0.0]]))  # faces up
    V, T, TP = rectangles_to_mesh(*(np.concatenate([a, b]) for a, b in zip((origin, u, v), board)))
    floor = np.arange(len(origin) + 1) < n * n
    if kind == "point":
        position = np.array([0.5, 0.6, 0.7])
        light = PointLight(position, np.full(3, 1.0), name="Lamp", casts_shadow=False)
        omega = _solid_angles(position, (origin[:n * n], u[:n * n], v[:n * n]))
    else:
        light = AreaLight(np.array([0.5, 0.6, 0.85]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]),
                          np.array([0, 0, -1.0]), np.full(3, 1.0), name="Lamp", casts_shadow=False)
        lamp = (np.array([[0.4, 0.5, 0.85]]), np.array([[0.0, 0.2, 0.0]]), np.array([[0.2, 0.0, 0.0]]))  # faces down
        F = rectangle_form_factors(*(np.concatenate([a, b]) for a, b in zip(lamp, (origin[:n * n], u[:n * n], v[:n * n]))))
        omega = F[0, 1:] * light.area  # H_j A_j = M A_lamp F_lamp->j, with M = 1
    scene = PatchScene(V, T, TP, np.where(floor, 0.5, 0.0), np.zeros(len(origin) + 1), lights=[light])
    with pytest.raises(ValueError, match="'Lamp' casts no shadow"):
        solve(scene, paths=1000)
    r = solve(scene, paths=300_000, seed=8, direct_light="gathered")
    area = scene.patch_area[:n * n]
    exact = 0.5 * omega / area
    hidden = (origin[:n * n, 0] + u[:n * n, 0] <= 0.7) & (origin[:n * n, 0] >= 0.3) \
        & (origin[:n * n, 1] >= 0.35) & (origin[:n * n, 1] + v[:n * n, 1] <= 0.85)
    assert hidden.any()
    b, variance = r.reflected[:n * n, 0], r.reflected_variance[:n * n, 0]
    assert np.abs((b - exact) / np.sqrt(variance)).max() < Z
    lit = r.reflected[:n * n, 0][hidden]
    assert (lit > 0.5 * exact[hidden]).all()  # not in the board's shadow


def _soft_falloff_irradiance(points, normal, centre, radius, intensity, nodes=(10, 48)):
    """Irradiance at ``points`` (n,3) with ``normal`` from Cycles' soft-falloff point light: a
    disc of radius r and radiance I / (pi r^2) facing each point (Gauss-Legendre in the radius,
    trapezoid around)."""
    g, w = np.polynomial.legendre.leggauss(nodes[0])
    rho, w_rho = 0.5 * radius * (g + 1), 0.5 * radius * w * 0.5 * radius * (g + 1)  # rho d rho
    phi = 2 * math.pi * np.arange(nodes[1]) / nodes[1]
    out = np.empty(len(points))
    for k, x in enumerate(points):
        axis = (centre - x) / np.linalg.norm(centre - x)
        a = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0])
        a /= np.linalg.norm(a)
        b = np.cross(axis, a)
        y = centre + (rho[:, None, None] * (np.cos(phi)[None, :, None] * a + np.sin(phi)[None, :, None] * b))
        d = y - x
        t = np.linalg.norm(d, axis=-1)
        cos_x = np.maximum(d @ normal / t, 0)
        cos_y = np.maximum(d @ axis / t, 0)
        out[k] = intensity / (math.pi * radius**2) * np.sum(w_rho[:, None] * (2 * math.pi / nodes[1]) * cos_x * cos_y / t**2)
    return out


def test_soft_falloff_is_cycles_disc_facing_each_receiver_and_cannot_be_shot():
    """A point light of radius 0.2 with soft falloff, 0.45 m over a floor that alone reflects
    (0.5): each floor patch's reflected light is 0.5 x the disc's irradiance averaged over it
    (quadrature), up to 20% less than a sphere's; a shooting walk is refused by name."""
    n, position, radius = 4, np.array([0.5, 0.6, 0.45]), 0.2
    light = PointLight(position, np.full(3, 1.0), radius=radius, name="Soft", soft_falloff=True)
    scene = _box(n=n, reflectivity=[0.0] * 6, lights=[light])[0]
    lit = scene.with_materials(np.where(np.arange(scene.patch_count) < n * n, 0.5, 0.0), scene.emission)
    with pytest.raises(ValueError, match="'Soft' has soft falloff"):
        solve(lit, paths=1000)
    r = solve(lit, paths=400_000, seed=9, direct_light="gathered")
    origin, u, v, _ = box_rectangles(SIZE, n=n)
    g, w = np.polynomial.legendre.leggauss(6)
    s = 0.5 * (g + 1)
    exact, sphere = np.empty(n * n), np.empty(n * n)
    for p in range(n * n):
        points = origin[p] + s[:, None, None] * u[p] + s[None, :, None] * v[p]
        weights = (0.25 * w[:, None] * w[None, :]).ravel()
        E = _soft_falloff_irradiance(points.reshape(-1, 3), np.array([0, 0, 1.0]), position, radius, 1.0)
        exact[p] = 0.5 * weights @ E
        d = position - points.reshape(-1, 3)
        sphere[p] = 0.5 * weights @ (d[:, 2] / np.linalg.norm(d, axis=1) ** 3)  # I cos / d^2
    assert (sphere / exact).max() > 1.1  # the two models differ far beyond the noise here
    sd = np.sqrt(r.reflected_variance[:n * n, 0])
    assert np.abs((r.reflected[:n * n, 0] - exact) / sd).max() < Z
