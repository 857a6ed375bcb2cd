"""The first shot gathered (direct_light="gathered"): unbiased against the direct solve, its
accounts balanced, bitwise reproducible, and its error measured by batch means."""
import numpy as np
import pytest
from boxes import box_scene

from addon.core import solve
from addon.core.names import GATHERED
from addon.core.methods.first_shot import Gathering, gather_direct
from addon.core.estimate.reference import solve_radiosity_system
from addon.core.methods.tables import WalkTables

R_FACES = [(0.7, 0.7, 0.7), (0.5, 0.5, 0.5), (0.8, 0.2, 0.2), (0.2, 0.8, 0.2), (0.6, 0.6, 0.6), (0.4, 0.4, 0.9)]
E_FACES = [(0, 0, 0), (1, 1, 1), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0)]


def _box_with_one_emitter(n=4):
    """A closed colour box whose only emitter is one ceiling patch (so that the gathering's
    shadow rays, its cosine rays and the walk all matter), and its discrete exact solution."""
    scene, F, face = box_scene(R_FACES, E_FACES, n=n)
    emission = np.zeros((scene.patch_count, 3))
    emission[n * n + n + 1] = (10.0, 9.0, 8.0)
    scene = scene.with_materials(scene.reflectivity, emission)
    return scene, solve_radiosity_system(F, scene.reflectivity, scene.emission)


@pytest.mark.parametrize("estimator", ["finite", "biased_infinite"])
def test_gathered_first_shot_is_the_direct_solve(estimator):
    """Per patch and channel, the result against the exact discrete solution, in batch-means
    standard errors: no |z| above 5 over the 288 values, and their mean square near 1 (32
    chunks: a t-distribution of 31 degrees of freedom, variance 31/29; bound 5 standard errors
    of a chi-square mean)."""
    scene, exact = _box_with_one_emitter()
    r = solve(scene, estimator=estimator, paths=400_000, seed=1, direct_light=GATHERED, threshold=1e-6)
    assert r.chunks == 32 and r.gather_rays > 0
    z = ((r.radiosity - exact) / np.sqrt(r.reflected_variance)).ravel()
    assert np.abs(z).max() < 5
    assert abs(np.mean(z**2) - 31 / 29) < 5 * np.sqrt(2 / z.size) * 1.2


@pytest.mark.parametrize("exit_point", ["random", "hit"])
def test_gathered_accounts_balance_and_runs_are_bitwise_reproducible(exit_point):
    scene, _ = _box_with_one_emitter()
    a = solve(scene, paths=100_000, seed=3, direct_light=GATHERED, threads=1, exit_point=exit_point)
    b = solve(scene, paths=100_000, seed=3, direct_light=GATHERED, threads=2, exit_point=exit_point)
    assert np.array_equal(a.radiosity, b.radiosity) and a.rays == b.rays
    e = a.energy
    np.testing.assert_allclose(e["emitted"].mean(), scene.total_power, rtol=1e-12)
    np.testing.assert_allclose(e["absorbed"] + e["escaped"] + e["undistributed"], e["emitted"], rtol=1e-9)
    # A closed box: what the gathering found no patch for is noise about zero (here under 1%).
    assert np.all(np.abs(e["escaped"]) < 0.01 * e["emitted"])
    assert np.isnan(a.predicted_mse)  # the paper's formulas do not predict it


def test_gathered_first_shot_stops_on_the_measured_error_and_refuses_unknown_names():
    scene, _ = _box_with_one_emitter()
    target = 4e-6
    r = solve(scene, target_mse=target, seed=4, direct_light=GATHERED)
    assert r.stopped == "target" and r.measured_mse <= target
    with pytest.raises(ValueError, match="direct_light"):
        solve(scene, paths=1000, direct_light="gathering")


def test_irradiance_is_what_the_reflected_light_comes_from_and_direct_light_alone_is_exact():
    """SolveResult.irradiance H: R H is the reflected radiosity, to rounding (Cycles' DIFFUSE
    bake without colour). direct_irradiance: a point light in a closed box gives each patch
    I Omega / A directly (the solid angle it subtends), here within 5 standard errors of the
    mean ratio over the patches (the standard error from two independent estimates)."""
    import math

    from test_lights import _box, _solid_angles

    from addon.core.methods.first_shot import direct_irradiance
    from addon.core.lights.lights import PointLight

    scene, exact = _box_with_one_emitter()
    r = solve(scene, paths=50_000, seed=5, direct_light=GATHERED)
    np.testing.assert_allclose(scene.reflectivity * r.irradiance, r.reflected, rtol=1e-12, atol=1e-15)
    position, intensity = np.array([0.4, 0.6, 0.45]), 2.0
    for radius in (0.0, 0.1):  # a sphere wholly above every wall's horizon lights it as a point does
        box, rectangles, _ = _box(lights=[PointLight(position, np.full(3, intensity), radius=radius)])
        truth = intensity * _solid_angles(position, rectangles) / box.patch_area
        a = direct_irradiance(box, samples=64, seed=1)[:, 0] / truth
        b = direct_irradiance(box, samples=64, seed=2)[:, 0] / truth
        se = np.std(a - b, ddof=1) / math.sqrt(2) / math.sqrt(a.size)
        assert abs(0.5 * (a + b).mean() - 1) < 5 * se / math.sqrt(2), radius


def _gauss_legendre(n):
    x, w = np.polynomial.legendre.leggauss(n)
    return (x + 1) / 2, w / 2


def floor_lit_unevenly_and_a_wall(R_floor=0.5, R_wall=0.01):
    """A one-patch floor lit unevenly by a point light low beside it, and a one-patch wall above
    the light's height, behind whose plane the light is: (scene, the wall's irradiance from the
    floor's first reflection by a 32^4-point Gauss-Legendre quadrature of R_f H(x) cos cos /
    (pi r^2), the same with the floor's light reflected uniformly, the rectangles (origin, u, v))."""
    from boxes import rectangles_to_mesh

    from addon.core import PatchScene
    from addon.core.lights.lights import PointLight

    origin = np.array([[0.0, 0.0, 0.0], [-0.1, 0.0, 0.3]])
    u, v = np.array([[1.0, 0, 0], [0, 1, 0]]), np.array([[0.0, 1, 0], [0, 0, 1]])
    light = np.array([-0.15, 0.5, 0.2])
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), np.array([R_floor, R_wall]), np.zeros(2),
                       lights=[PointLight(light, np.ones(3))])
    a, w = _gauss_legendre(32)
    s, t = (g.ravel() for g in np.meshgrid(a, a, indexing="ij"))
    weight = np.outer(w, w).ravel()
    floor = np.stack([s, t, np.zeros_like(s)], axis=1)
    wall = np.stack([np.full_like(s, -0.1), t, 0.3 + s], axis=1)
    d = light - floor
    H = d[:, 2] / np.linalg.norm(d, axis=1) ** 3  # I cos / d^2
    r = wall[None] - floor[:, None]
    r2 = np.einsum("fwi,fwi->fw", r, r)
    kernel = np.maximum(r[..., 2], 0) * np.maximum(-r[..., 0], 0) / (np.pi * r2 * r2)
    exact = R_floor * (weight * H) @ (kernel @ weight)
    uniform = R_floor * (weight @ H) * (weight @ kernel @ weight)
    assert uniform < 0.9 * exact
    return scene, exact, uniform, (origin, u, v)


def test_reflected_light_leaves_from_where_the_direct_light_landed():
    """Leaving from hit points, the gathered first reflection leaves each patch from where its
    direct light arrived. A one-patch floor (R 0.5) lit unevenly by a point light low beside
    it, and a one-patch wall above the light's height, which the light does not reach (it is
    behind the wall's plane) and which reflects 0.01 (the biased walk's t = 0.05 ends every
    path at its first hit: the wall receives exactly the floor's first reflection). The wall's
    irradiance against a Gauss-Legendre quadrature of 0.5 H(x) cos cos / (pi r^2) over floor
    and wall (converged to 1e-10): within 5 batch-means standard errors, as the shooting walk
    is; the same light reflected uniformly from the floor (the discrete method's assumption,
    15% less) is more than 5 away, and is what a random exit gives."""
    scene, exact, uniform, _ = floor_lit_unevenly_and_a_wall()
    R_wall = scene.reflectivity[1, 0]
    for exit_point, truth, other in (("hit", exact, uniform), ("random", uniform, exact)):
        result = solve(scene, estimator="biased_infinite", threshold=0.05, paths=400_000, seed=1,
                       direct_light=GATHERED, exit_point=exit_point)
        H, sd = result.irradiance[1, 0], np.sqrt(result.reflected_variance[1, 0]) / R_wall
        assert abs(H - truth) < 5 * sd < abs(H - other), exit_point


def test_cosine_rays_are_cast_in_proportion_to_the_emitters_share_of_the_area(monkeypatch):
    """A sky needs every cosine ray and lamps none; emitting patches get about the chance that a
    cosine ray meets one (10 A_E / A_T, at least 0.1): the one-emitter box casts about a tenth
    as many, and its gathered estimate stays the direct solve (test above: the balance
    heuristic counts the share)."""
    from addon.core.methods.first_shot import cosine_share

    scene, _ = _box_with_one_emitter()
    assert cosine_share(scene, world=True) == 1.0
    assert cosine_share(scene, world=False) == pytest.approx(10 / 96)
    whole_face = scene.with_materials(scene.reflectivity, np.where(np.arange(96)[:, None] < 16, 1.0, 0.0) * np.ones(3))
    assert cosine_share(whole_face, world=False) == 1.0
    from addon.core.methods import first_shot

    traced = []
    trace = first_shot.trace
    monkeypatch.setattr(first_shot, "trace", lambda t, o, d, *region: traced.append(o.shape[1]) or trace(t, o, d, *region))
    tables = WalkTables(scene, "finite", 1e-3, "random")
    gathering = Gathering(scene, np.full(scene.patch_count, 4.0))
    with tables.numpy_turn:
        _, _, (patch, _, _) = gather_direct(tables, gathering, np.random.default_rng(0))
    samples = patch.size
    assert len(traced) == 2  # the shadow rays' cast, then the cosine rays'
    cosine = traced[1]
    share = 10 / 96
    assert abs(cosine - samples * share) < 5 * np.sqrt(samples * share * (1 - share))


def test_an_emitter_seen_at_a_grazing_angle_from_far_away_is_seen_whole():
    """A 1 m emitter facing down at z = 1 and a wall 10 m away whose top reaches nearly its
    height: the wall sees its underside at under half a degree. A shadow ray aims at a point a
    ray offset below the emitter; near the emitter's far edge it passes that point and misses
    the emitter (it would reach the emitter's height a few centimetres on): such a point is
    seen, as nothing stands before it. The wall's direct irradiance against the exact rectangle
    form factor, within 5 standard errors (16 chunks; asking for a hit on the emitter alone was
    2% low here)."""
    from boxes import rectangles_to_mesh

    from addon.core import PatchScene
    from addon.core.estimate.reference import rectangle_form_factors

    origin = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 0.9]])
    u, v = np.array([[0, 1.0, 0], [0, 0, 0.099]]), np.array([[1.0, 0, 0], [0, 1.0, 0]])
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), np.array([0.0, 0.5]), np.array([1.0, 0.0]))
    exact = rectangle_form_factors(origin, u, v)[1, 0]
    tables = WalkTables(scene, "finite", 1e-3, "random")
    gathering = Gathering(scene, np.array([1e-3, 20_000.0]))
    rng = np.random.default_rng(2)
    with tables.numpy_turn:
        H = np.array([gather_direct(tables, gathering, rng)[0][0, 1] for _ in range(16)])
    assert abs(H.mean() - exact) < 5 * H.std(ddof=1) / 4


def test_stratified_gathering_has_less_variance_than_independent_samples_and_the_same_mean():
    """The colour box with one emitting ceiling patch, 64 chunks' direct irradiance each way:
    per patch, stratified samples' variance is under half of independent ones' in the mean over
    the lit patches (measured about a fifth; a ratio of two 63-degree variances, averaged over
    80 lit patches, is within a few percent), and the two means agree within 5 standard errors."""
    from addon.core.methods.first_shot import gather_samples

    scene, _ = _box_with_one_emitter()
    tables = WalkTables(scene, "finite", 1e-3, "random")
    H = {}
    for stratified in (True, False):
        gathering = Gathering(scene, gather_samples(12_500, 2.5, scene), stratified=stratified)
        rng = np.random.default_rng(5)
        with tables.numpy_turn:
            H[stratified] = np.array([gather_direct(tables, gathering, rng)[0][0] for _ in range(64)])
    lit = H[False].mean(axis=0) > 0
    a, b = H[True][:, lit], H[False][:, lit]
    assert np.mean(a.var(axis=0) / b.var(axis=0)) < 0.5
    z = (a.mean(axis=0) - b.mean(axis=0)) / np.sqrt((a.var(axis=0, ddof=1) + b.var(axis=0, ddof=1)) / 64)
    assert np.abs(z).max() < 5


def test_a_patch_s_estimate_is_its_samples_mean_whatever_their_count():
    """A floor alone under a sun straight above (no shadow, no sky): every sample finds the
    sun's irradiance H, so a patch's estimate is H exactly in every chunk, whether the chunk drew
    10 or 11 of its 10.05 samples (summed over 10.05, it was 0.5% low in most chunks and 9.5%
    high in about one of twenty, a noise that stratified samples no longer hid); a patch of 0.5
    samples is H / 0.5 or 0, H on average (within 5 standard errors over 400 chunks)."""
    from boxes import rectangles_to_mesh

    from addon.core import PatchScene
    from addon.core.lights.lights import SunLight

    origin = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]])
    u, v = np.array([[1.0, 0, 0], [1.0, 0, 0]]), np.array([[0.0, 1, 0], [0.0, 1, 0]])
    sun = SunLight(np.array([0.0, 0.0, -1.0]), np.full(3, 2.0))
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), np.array([0.5, 0.5]), np.zeros(2), lights=[sun])
    tables = WalkTables(scene, "finite", 1e-3, "random")
    gathering = Gathering(scene, np.array([10.05, 0.5]))
    rng = np.random.default_rng(4)
    with tables.numpy_turn:
        H = np.array([gather_direct(tables, gathering, rng)[0][0] for _ in range(400)])
    np.testing.assert_allclose(H[:, 0], 2.0, rtol=1e-6)
    assert set(np.round(H[:, 1], 6)) == {0.0, 4.0}
    assert abs(H[:, 1].mean() - 2.0) < 5 * H[:, 1].std(ddof=1) / np.sqrt(400)


def test_paths_leaving_from_the_gathering_samples_never_index_patch_tables_with_their_ids(monkeypatch):
    """With the hit exit the walk's sources are the gathering samples, ids P, P+1, ... up to a
    million. A patch table read with such an id in take's "wrap" mode steps down by P at a time
    (12 ms a call for a million ids against a 600-patch table): every patch index a walk step
    reads its normals with must be a patch's."""
    from addon.core.scene import rays

    scene, _ = _box_with_one_emitter()
    real, seen = rays.patch_normals, []

    def checked(tables, patch):
        seen.append(int(patch.max(initial=0)))
        return real(tables, patch)

    monkeypatch.setattr(rays, "patch_normals", checked)
    # (chunks of more paths than a wavefront holds, so that new paths join live ones)
    solve(scene, paths=1_000_000, seed=1, direct_light=GATHERED, threads=1, exit_point="hit")
    assert seen and max(seen) < scene.patch_count
