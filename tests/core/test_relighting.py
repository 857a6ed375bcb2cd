"""Per-source results and relighting (addon/core/estimate/grouping.py, relighting.py): each source
group's result from one solve, for every method, adds up to the solve's own; recombined with new
strengths and colours it agrees with a fresh solve of the relit scene within their joint noise,
for every source kind, tints and a source switched off; the error it reports from the groups'
batch covariances follows the empirical spread over seeds; too many patches x sources is refused
in one line.

The joint-noise test: with d_j the difference of two independent estimates of patch j (the relit
result and a fresh solve), T = sum_j A_j |d_j|^2 / (A_T (mse_relit + mse_fresh)) has expectation
1 (the measured MSEs are each estimate's area-weighted mean variance), and, were the patches'
errors independent and Gaussian, variance 2 / n_eff, n_eff = (sum_j t_j)^2 / sum_j t_j^2 over
the terms t_j = A_j v_j (v_j from the fresh solve's batch variances). A bias of the size of the
noise doubles T. The band is 5 of those standard errors, widened by 2 for the correlations between
patches that share paths (over 20 seeds, (T - 1) / sqrt(2 / n_eff) had mean -0.08 and standard
deviation 1.86 for the shot walk, -0.57 and 1.43 for the two-way iteration)."""
import math

import numpy as np
import pytest
from boxes import CEILING, box_rectangles, box_scene, rectangles_to_mesh

from addon.core import PatchScene, relight, solve, source_groups
from addon.core.relight.resolve import resolve
from addon.core.estimate import grouping
from addon.core.lights.lights import AreaLight, PointLight, Spot, SunLight, WorldLight

R_FACES = np.array([(0.7, 0.7, 0.7), (0.5, 0.5, 0.5), (0.8, 0.3, 0.2), (0.2, 0.7, 0.3), (0.6, 0.6, 0.6), (0.4, 0.4, 0.8)])
# Every method and exit point: (method, direct_light, exit_point, estimator)
METHODS = [
    ("walk", "shot", "random", "finite"),
    ("walk", "shot", "hit", "finite"),
    ("walk", "shot", "random", "biased_infinite"),
    ("walk", "gathered", "random", "finite"),
    ("walk", "gathered", "hit", "finite"),
    ("jacobi", "shot", "random", "finite"),
    ("jacobi", "gathered", "hit", "finite"),
    ("two_way", None, "random", "finite"),
    ("two_way", None, "hit", "finite"),
]
IDS = ["-".join(str(x) for x in m) for m in METHODS]
# The relit weights of the six groups (emissive patches, point, spot, area, sun, world): tints,
# strengths up and down, and the point lamp off.
WEIGHTS = np.array([(1.5, 1.0, 0.5), (0.0, 0.0, 0.0), (0.3, 0.6, 1.2), (2.0, 2.0, 2.0), (1.0, 0.9, 0.7), (0.5, 0.5, 0.5)])
Z = 5.0
CORRELATION_ALLOWANCE = 2.0


def every_light(scale=np.ones((5, 3))):
    """Every kind of light, each times its row of ``scale`` (point, spot, area, sun, world)."""
    down = np.array([0.0, 0.0, -1.0])
    sun = np.array([0.3, 0.1, -1.0]) / np.linalg.norm([0.3, 0.1, -1.0])
    return [
        PointLight(np.array([0.5, 0.5, 0.4]), np.array([0.10, 0.08, 0.06]) * scale[0], radius=0.05, name="point"),
        PointLight(np.array([0.3, 0.6, 0.7]), np.full(3, 1.0) * scale[1], spot=Spot(down, 0.8, 0.9), name="spot"),
        AreaLight(np.array([0.7, 0.3, 0.9]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), down, np.full(3, 24.0) * scale[2],
                  name="area"),
        SunLight(sun, np.full(3, 0.84) * scale[3], angle=0.1, name="sun"),
        WorldLight(irradiance=np.array([0.21, 0.315, 0.42]) * scale[4], name="world"),
    ]


def open_box(weights=None, n=4):
    """A colour box open at the top, two floor patches emitting, lit by a light of every kind
    (and the sun and the sky through the top); with ``weights`` (6,3), every source's strength
    and colour times its row (the relit scene)."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=n)
    keep = face != CEILING
    origin, u, v, face = origin[keep], u[keep], v[keep], face[keep]
    V, T, TP = rectangles_to_mesh(origin, u, v)
    emission = np.zeros((len(origin), 3))
    emission[[5, 6]] = (8.0, 7.2, 6.4)
    w = np.ones((6, 3)) if weights is None else np.asarray(weights)
    return PatchScene(V, T, TP, R_FACES[face], emission * w[0], lights=every_light(w[1:]))


def solve_case(scene, case, **kw):
    method, direct_light, exit_point, estimator = case
    return solve(scene, estimator=estimator, method=method, direct_light=direct_light, exit_point=exit_point, threads=2, **kw)


def joint_noise_z(a, b, mse_a, mse_b, variance_b, area):
    """(T - 1) over T's standard error (module docstring), for (P,3) estimates a and b."""
    weight = area / area.sum()
    T = float((weight[:, None] * (a - b) ** 2).sum() / 3) / (mse_a + mse_b)
    terms = (weight[:, None] * 2 * variance_b).ravel()
    n_eff = terms.sum() ** 2 / (terms**2).sum()
    return (T - 1.0) / (math.sqrt(2.0 / n_eff) * CORRELATION_ALLOWANCE)


def test_source_groups_name_every_light_and_emission_and_merge_what_the_caller_labels():
    scene = open_box()
    default = source_groups(scene)
    assert default.names == ("emission (8.0, 7.2, 6.4)", "point", "spot", "area", "sun", "world")
    P = scene.patch_count
    assert set(default.patch_group(P)[[5, 6]]) == {0} and (np.delete(default.patch_group(P), [5, 6]) == -1).all()
    assert list(default.light_group) == [1, 2, 3, 4, 5]
    labels = np.array(["wall"] * P, dtype=object)
    labels[6] = "lamps"
    merged = source_groups(scene, patch_labels=labels, light_labels=["lamps", "lamps", None, None, None])
    assert merged.names == ("wall", "lamps", "area", "sun", "world")
    assert merged.patch_group(P)[5] == 0 and merged.patch_group(P)[6] == 1 and list(merged.light_group) == [1, 1, 2, 3, 4]
    # Lights of one name, or of a label's name, still get groups of their own unless labelled.
    twins = scene.with_materials(scene.reflectivity, scene.emission, [PointLight(np.full(3, 0.5), np.ones(3), name="lamp"),
                                                                        PointLight(np.full(3, 0.4), np.ones(3), name="lamp")])
    assert source_groups(twins, patch_labels=np.where(np.arange(P) == 5, "lamp", "wall")).names == (
        "lamp", "wall", "lamp (0)", "lamp (1)")


@pytest.mark.parametrize("case", METHODS, ids=IDS)
def test_the_groups_add_up_to_the_solve_and_their_covariance_to_its_error(case):
    """Every method: the groups' radiosity and irradiance sum to the total to float error, and
    the error of the recombination at the solve's own strengths is the solve's measured MSE."""
    scene = open_box()
    r = solve_case(scene, case, paths=40_000, seed=3, per_source=True)
    ps = r.per_source
    assert ps.radiosity.shape == (6, scene.patch_count, 3) and ps.count == 6
    scale = np.abs(r.radiosity).max()
    np.testing.assert_allclose(ps.radiosity.sum(axis=0), r.radiosity, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(ps.irradiance.sum(axis=0), r.irradiance, rtol=0, atol=1e-13 * np.abs(r.irradiance).max())
    same = relight(ps, np.ones((6, 3)), irradiance=True)
    np.testing.assert_allclose(same.irradiance, r.irradiance, rtol=0, atol=1e-13 * np.abs(r.irradiance).max())
    np.testing.assert_allclose(same.radiosity, r.radiosity, rtol=0, atol=1e-13 * scale)
    assert same.mse == pytest.approx(r.measured_mse, rel=1e-9)


def test_a_grey_walk_of_interchangeable_paths_adds_up_too():
    """The plain grey walk (paths as counts, speedups.interchangeable) keeps each group apart."""
    scene, _, face = box_scene([(0.6,) * 3] * 6, [(0, 0, 0), (1, 1, 1), (0, 0, 0), (0, 0, 0), (0.5, 0.5, 0.5), (0, 0, 0)], n=4)
    r = solve(scene, paths=200_000, seed=5, threads=2, per_source=True)
    assert r.speedups.interchangeable and r.per_source.count == 2
    np.testing.assert_allclose(r.per_source.radiosity.sum(axis=0), r.radiosity, rtol=0, atol=1e-14 * r.radiosity.max())
    ceiling_light = r.per_source.radiosity[0] - np.where((face == 1)[:, None], 1.0, 0.0)
    assert (r.per_source.radiosity[1][face == 1] > 0).all() and (ceiling_light[face == 4] > 0).all()


@pytest.mark.parametrize("case", METHODS, ids=IDS)
def test_a_relit_solve_is_a_fresh_solve_of_the_relit_scene_within_their_joint_noise(case):
    """Every source kind (emissive patches, point, spot, area, sun, world) relit with tints,
    strengths up and down and the point lamp off, against a fresh solve of the relit scene."""
    r = solve_case(open_box(), case, paths=150_000, seed=7, per_source=True)
    relit = relight(r.per_source, WEIGHTS)
    fresh_scene = open_box(WEIGHTS)
    fresh = solve_case(fresh_scene, case, paths=150_000, seed=8)
    z = joint_noise_z(relit.radiosity, fresh.radiosity, relit.mse, fresh.measured_mse, fresh.reflected_variance,
                       fresh_scene.patch_area)
    assert abs(z) < Z, z
    # (and the area light's a fifth too strong is outside it)
    wrong = WEIGHTS.copy()
    wrong[3] *= 1.2
    z_wrong = joint_noise_z(relight(r.per_source, wrong).radiosity, fresh.radiosity, relit.mse, fresh.measured_mse,
                             fresh.reflected_variance, fresh_scene.patch_area)
    assert z_wrong > Z, z_wrong


@pytest.mark.parametrize("case", [METHODS[0], METHODS[4], METHODS[7]], ids=[IDS[0], IDS[4], IDS[7]])
def test_the_error_of_a_recombination_follows_the_spread_over_seeds(case):
    """The MSE relight reports (from the groups' batch covariances) against the area-weighted
    variance of the relit result over 16 seeds: their ratio within 1 +- 5 standard errors of the
    empirical variance (each patch's variance over 16 seeds has relative error sqrt(2/15); a mean
    over n_eff independent patches sqrt(2 / (15 n_eff)), widened as the joint-noise test is for
    correlated patches)."""
    scene = open_box()
    weight = scene.patch_area / scene.patch_area.sum()
    relit, reported = [], []
    for seed in range(16):
        ps = solve_case(scene, case, paths=20_000, seed=100 + seed, per_source=True).per_source
        r = relight(ps, WEIGHTS)
        relit.append(r.radiosity)
        reported.append(r.mse)
    _assert_reported_error_is_the_spread(weight, relit, reported)


def test_weights_of_the_wrong_shape_or_below_zero_are_refused_and_the_target_is_reported():
    r = solve(open_box(), paths=40_000, seed=1, per_source=True, threads=2)
    with pytest.raises(ValueError, match=r"weights must have shape \(6, 3\)"):
        relight(r.per_source, np.ones((5, 3)))
    with pytest.raises(ValueError, match="at least 0"):
        relight(r.per_source, -np.ones(6))
    assert relight(r.per_source, np.ones(6)).target_relative_rms is None
    target = solve(open_box(), target_mse=2 * r.measured_mse, seed=1, per_source=True, threads=2,
                   stop_rule="measured").per_source
    same = relight(target, np.ones(6))
    assert not same.past_target and same.relative_rms <= same.target_relative_rms
    # The dimmest source alone at full strength, the rest off: its relative error is far larger.
    alone = np.zeros(6)
    alone[np.argmin(target.power.mean(axis=1))] = 1.0
    assert relight(target, alone).past_target


def test_too_many_patches_x_sources_is_refused_in_one_line(monkeypatch):
    scene = open_box()
    monkeypatch.setattr(grouping, "PER_SOURCE_MAX", 6 * scene.patch_count - 1)
    with pytest.raises(ValueError, match=r"80 patches x 6 sources = 480, over the cap of 479 .*light groups"):
        solve(scene, paths=1000, per_source=True)
    with pytest.raises(ValueError, match="give per_source=True"):
        solve(scene, paths=1000, groups=source_groups(scene))
    with pytest.raises(ValueError, match="another scene"):
        solve(scene, paths=1000, per_source=True, groups=source_groups(_box_of_two()))


def _box_of_two():
    return box_scene([(0.5,) * 3] * 6, [(0, 0, 0), (1, 1, 1)] + [(0, 0, 0)] * 4, n=2)[0]


def test_a_per_source_solve_cancelled_before_its_first_chunk_keeps_the_emission_and_says_its_error_is_unknown():
    scene = open_box()
    r = solve(scene, paths=100_000_000, seed=1, per_source=True, threads=2, should_stop=lambda: True)  # (chunks of seconds)
    assert r.stopped == "cancelled" and r.paths == 0
    np.testing.assert_array_equal(r.per_source.radiosity.sum(axis=0), scene.emission)
    relit = relight(r.per_source, WEIGHTS)
    assert math.isnan(relit.mse) and math.isnan(relit.relative_rms) and not relit.past_target


@pytest.mark.parametrize("case", [METHODS[0], METHODS[7]], ids=[IDS[0], IDS[7]])
def test_each_sources_smooth_colours_add_up_to_the_solves_and_relight_as_the_flat_ones(case, monkeypatch):
    """smooth_sources: each group's smooth radiosity and light arriving, made with the whole's
    noise-filter weights, clips and corner scales, add up to what the pipeline shows for the solve
    with the groups' direct light at the corners added up (float error; each group draws its own
    lamps' rays, the whole all of them at once: the same light within their noise, as
    test_point_direct checks); recombined with new weights they are the same linear map of the
    relit values."""
    from addon.bpy_free import smooth_colours
    from addon.core.display import point_direct, slack, smoothing
    from addon.core.relight.relighting import combine, per_source_emission, smooth_sources

    scene = open_box()
    r = solve_case(scene, case, paths=40_000, seed=3, per_source=True)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    parts = dict(smooth_sources(surface, scene, r, light=True))
    grouped = point_direct.corner_direct(surface, scene, scene.triangles, seed=r.seed, light_group=r.per_source.light_group,
                                         patch_group=r.per_source.patch_group, groups=r.per_source.count, light=r.irradiance)
    summed = grouped.corners.sum(axis=0).astype(np.float32)  # (as the whole's is kept)
    with monkeypatch.context() as patched:
        patched.setattr(point_direct, "corner_direct", lambda *args, **kwargs: point_direct.CornerDirect(
            summed.copy(), point_direct.patch_means(surface, summed)))
        whole = dict(smooth_colours.smooth_corners(scene, r, light=True))
    for name in ("light", "smooth"):  # (float32 rounding: the pipeline keeps the whole's direct light as written)
        assert parts[name].shape == (6,) + whole[name].shape
        np.testing.assert_allclose(parts[name].sum(axis=0), whole[name], rtol=0, atol=1e-6 * whole[name].max())
    # recombined with new weights, the smooth parts are the whole's smoothing applied to the relit parts
    relit = combine(r.per_source, parts["smooth"], WEIGHTS)
    assert relit.shape == whole["smooth"].shape
    filtered, noise = surface.filter_light(r.reflected, r.reflected_variance, return_filter=True)
    rho = scene.reflectivity
    ps = r.per_source
    direct = point_direct.corner_direct(surface, scene, scene.triangles, seed=r.seed, light_group=ps.light_group,
                                        patch_group=ps.patch_group, groups=ps.count, light=r.irradiance)
    whole_direct = point_direct.CornerDirect(direct.corners.sum(axis=0), direct.means.sum(axis=0))
    relit_direct = point_direct.CornerDirect(np.einsum("stkc,sc->tkc", direct.corners, WEIGHTS)[None],
                                             np.einsum("spc,sc->pc", direct.means, WEIGHTS)[None])
    reflected = np.einsum("spc,sc->pc", ps.irradiance, WEIGHTS) * rho
    emission = np.einsum("spc,sc->pc", per_source_emission(scene, ps), WEIGHTS)
    expected = point_direct.shown(surface, filtered, point_direct.scaled(surface, whole_direct, rho), noise(reflected)[None],
                                  point_direct.scaled(surface, relit_direct, rho),
                                  slack=slack.slack_of(r.reflected_variance, None if r.direct_irradiance is None
                                                           else rho * (r.irradiance - r.direct_irradiance)))[1][0]
    expected += emission[scene.triangle_patch][:, None, :]
    np.testing.assert_allclose(relit, expected, rtol=0, atol=1e-12 * expected.max())
    with pytest.raises(ValueError, match=r"parts must have shape \(6, \.\.\., 3\)"):
        combine(r.per_source, parts["smooth"][:5], WEIGHTS)
    # as float32 (as they are written): half the memory, the whole's to float32 rounding
    single = dict(smooth_sources(surface, scene, r, light=True, dtype=np.float32))
    for name in ("light", "smooth"):
        assert single[name].dtype == np.float32
        np.testing.assert_allclose(single[name], parts[name], rtol=1e-6, atol=1e-6 * whole[name].max())
    # the emitting patches' own E is in their group's colours only
    emission = per_source_emission(scene, r.per_source)
    assert np.array_equal(emission.sum(axis=0), scene.emission) and not emission[1:].any()
    with pytest.raises(ValueError, match="per_source=True"):
        next(smooth_sources(surface, scene, solve_case(scene, case, paths=2_000, seed=3)))


# ---------------------------------------------------------------------------------------------
# Re-solving what changed: a lamp moved
# ---------------------------------------------------------------------------------------------

def _moved_box():
    """The open box with its area lamp moved lower and to the other side (the rest as it was)."""
    scene = open_box()
    lights = list(scene.lights.lights)
    lights[2] = AreaLight(np.array([0.25, 0.7, 0.5]), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]),
                          np.array([0.0, 0.0, -1.0]), np.full(3, 24.0), name="area")
    return scene.with_materials(scene.reflectivity, scene.emission, lights)


def case_kwargs(case, **kw):
    method, direct_light, exit_point, estimator = case
    return dict(estimator=estimator, method=method, direct_light=direct_light, exit_point=exit_point, threads=2, **kw)


@pytest.mark.parametrize("case", METHODS, ids=IDS)
def test_a_moved_lamp_re_solved_alone_recombines_to_a_fresh_solve_of_the_moved_scene(case):
    """resolve re-solves the moved area lamp's group only: the recombination at the solve's
    strengths (and relit with tints and the point lamp off) agrees with a fresh per-source solve of
    the moved scene within their joint noise, while the results before the move do not; the kept
    groups are the solve's to the bit, their covariance with the re-solved one 0."""
    r = solve_case(open_box(), case, paths=150_000, seed=7, per_source=True)
    ps, moved = r.per_source, _moved_box()
    redone = resolve(moved, ps, ["area"], **case_kwargs(case, paths=150_000, seed=9))
    fresh = solve_case(moved, case, paths=150_000, seed=8, per_source=True)
    for weights in (np.ones((6, 3)), WEIGHTS):
        relit, fresh_relit = relight(redone, weights), relight(fresh.per_source, weights)
        z = joint_noise_z(relit.radiosity, fresh_relit.radiosity, relit.mse, fresh_relit.mse, fresh.reflected_variance,
                           moved.patch_area)
        assert abs(z) < Z, z
    before = relight(ps, np.ones((6, 3)))
    z_before = joint_noise_z(before.radiosity, fresh.radiosity, before.mse, fresh.measured_mse, fresh.reflected_variance,
                              moved.patch_area)
    assert z_before > Z, z_before
    area = ps.names.index("area")
    kept = [g for g in range(6) if g != area]
    assert redone.names == ps.names
    for name in ("radiosity", "irradiance", "power"):
        assert np.array_equal(getattr(redone, name)[kept], getattr(ps, name)[kept])
    assert np.array_equal(redone.covariance[:, kept][:, :, kept], ps.covariance[:, kept][:, :, kept])
    assert not redone.covariance[:, area, kept].any() and not redone.covariance[:, kept, area].any()
    assert redone.covariance[:, area, area].min() > 0
    assert redone.scale == ps.scale and redone.target_error == ps.target_error
    np.testing.assert_array_equal(redone.patch_group, ps.patch_group)


def test_only_the_named_groups_sources_are_traced(monkeypatch):
    """A spy on the solve resolve calls: it is given only the named groups' sources (the area
    lamp; then the emitting patches' group and the sun), every other light and emission left out."""
    from addon.core.relight import resolve as resolving

    seen = []
    real = resolving.solve

    def spy(scene, settings, **kwargs):
        seen.append((scene, settings.groups))
        return real(scene, settings, **kwargs)

    ps = solve(open_box(), paths=20_000, seed=1, per_source=True, threads=2).per_source
    monkeypatch.setattr(resolving, "solve", spy)
    moved = _moved_box()
    resolve(moved, ps, ["area"], paths=20_000, seed=2, threads=2)
    scene, groups = seen[-1]
    assert [light.name for light in scene.lights.lights] == ["area"] and not scene.emission.any()
    assert groups.names == ("area",)
    emission_group = ps.names[0]
    redone = resolve(moved, ps, ["sun", emission_group], paths=20_000, seed=2, threads=2)
    scene, groups = seen[-1]
    assert [light.name for light in scene.lights.lights] == ["sun"] and groups.names == ("sun", emission_group)
    np.testing.assert_array_equal(scene.emission, moved.emission)
    assert redone.names == ps.names and len(seen) == 2


def test_resolve_refuses_a_name_it_does_not_have_and_changed_geometry_in_one_line():
    ps = solve(open_box(), paths=20_000, seed=1, per_source=True, threads=2).per_source
    with pytest.raises(ValueError, match=r"^no source group named 'lamp'; the groups are .*'area'"):
        resolve(_moved_box(), ps, ["lamp"], paths=1000)
    with pytest.raises(ValueError, match="the geometry changed, solve again"):
        resolve(open_box(n=2), ps, ["area"], paths=1000)
    # a lamp added: its group is new, and is solved where it is named
    scene = _moved_box()
    added = scene.with_materials(scene.reflectivity, scene.emission,
                                 list(scene.lights.lights) + [PointLight(np.full(3, 0.5), np.full(3, 0.1), name="new")])
    with pytest.raises(ValueError, match="'new' are new: name them"):
        resolve(added, ps, ["area"], paths=1000)
    grown = resolve(added, ps, ["area", "new"], paths=20_000, seed=3, threads=2)
    assert grown.names == ps.names + ("new",) and grown.radiosity[-1].max() > 0


def test_a_group_that_gives_no_light_now_is_re_solved_as_dark_without_tracing():
    """The area lamp at strength 0 (the scene has it, dark): its results are 0, nothing traced."""
    ps = solve(open_box(), paths=20_000, seed=1, per_source=True, threads=2).per_source
    scene = open_box(np.array([(1, 1, 1)] * 3 + [(0, 0, 0)] + [(1, 1, 1)] * 2))
    redone = resolve(scene, ps, ["area"], paths=20_000, seed=2)
    assert not redone.radiosity[3].any() and not redone.covariance[:, 3].any()
    assert np.array_equal(redone.radiosity[:3], ps.radiosity[:3])


@pytest.mark.parametrize("case", [METHODS[0], METHODS[4], METHODS[7]], ids=[IDS[0], IDS[4], IDS[7]])
def test_the_error_of_a_re_solved_recombination_follows_the_spread_over_seeds(case):
    """As for a solve's recombination (above): the MSE relight reports for the re-solved
    results, from the kept groups' covariance and the re-solved one's, against the area-weighted
    variance of the relit result over 16 seeds of the solve and the re-solve."""
    scene, moved = open_box(), _moved_box()
    weight = scene.patch_area / scene.patch_area.sum()
    relit, reported = [], []
    for seed in range(16):
        ps = solve_case(scene, case, paths=20_000, seed=100 + seed, per_source=True).per_source
        r = relight(resolve(moved, ps, ["area", "spot"], **case_kwargs(case, paths=20_000, seed=300 + seed)), WEIGHTS)
        relit.append(r.radiosity)
        reported.append(r.mse)
    _assert_reported_error_is_the_spread(weight, relit, reported)


def _assert_reported_error_is_the_spread(weight, relit, reported):
    """The mean reported MSE against the area-weighted variance over the 16 runs ``relit``:
    within Z relative standard errors of a variance of 15 degrees of freedom over n_eff
    independent patches, widened for correlated patches."""
    terms = weight[:, None] * np.var(relit, axis=0, ddof=1)
    empirical = float(terms.sum() / 3)
    n_eff = terms.sum() ** 2 / (terms**2).sum()
    band = Z * math.sqrt(2 / (15 * n_eff)) * CORRELATION_ALLOWANCE
    assert abs(np.mean(reported) / empirical - 1) < band, (np.mean(reported), empirical)


def test_each_sources_noise_filters_run_on_the_local_threads_with_the_same_bits(monkeypatch):
    """smooth_sources' two noise filters (the light arriving, the reflected light) are their own
    work: with two threads they run at once (each one's start waits for the other's), and every
    group's colours are the same bit for bit as on one thread."""
    import threading

    from addon.core.display import smoothing
    from addon.core.distributed import runners
    from addon.core.relight.relighting import smooth_sources

    scene = open_box()
    r = solve_case(scene, METHODS[0], paths=20_000, seed=3, per_source=True)
    surface = smoothing.Surface.of(scene.vertices, scene.triangles, scene.triangle_patch, scene.patch_count)
    meet, seen = threading.Barrier(2, timeout=20), []
    filter_noise = smoothing.Surface.filter_noise

    def filtered(self, *args, **kwargs):
        seen.append(threading.get_ident())
        if threads == 2 and len(seen) <= 2:
            meet.wait()  # (a filter that waits for the other to end breaks the barrier: the test fails)
        return filter_noise(self, *args, **kwargs)

    monkeypatch.setattr(smoothing.Surface, "filter_noise", filtered)
    made = []
    for threads in (1, 2):
        seen.clear()
        with runners.local_threads(threads):
            made.append(dict(smooth_sources(surface, scene, r, light=True)))
        assert len(set(seen[:2])) == threads, (threads, seen)
    assert made[0].keys() == made[1].keys() == {"light", "smooth"}
    for name in made[0]:
        assert np.array_equal(made[0][name], made[1][name]), name
