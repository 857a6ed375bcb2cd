"""The error target is a promise: with the default stop rule the error reached is at most the
target; the paper's predicted path count is the plan, and where reflectivities vary from patch
to patch formula (2) under-predicts the error. The measured rule keeps it with every method,
where one small source lights a bright room too."""
import math

import numpy as np
import pytest
from boxes import CEILING, FLOOR, box_rectangles, box_scene, rectangles_to_mesh, small_source_box

from addon.core import PatchScene, predict, relative_rms_to_mse, solve
from addon.core.estimate import plan
from addon.core.estimate.batches import Batches
from addon.core.estimate.reference import area_weighted_mse, rectangle_form_factors, solve_radiosity_system
from addon.bpy_free.options import ERROR_SCALE, STOP_RULE
from addon.bpy_free.pipeline import SolveSettings

R_FACES = [(0.9, 0.9, 0.9), (0.2, 0.2, 0.2), (0.8, 0.3, 0.1), (0.1, 0.7, 0.3), (0.85, 0.85, 0.85), (0.3, 0.3, 0.6)]
E_FACES = [(0, 0, 0), (1, 1, 1), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0)]
SEEDS = range(8)


def _ratios(stop_rule):
    """True MSE (against the exact discrete solution) over the target, one per seed."""
    scene, F, _ = box_scene(R_FACES, E_FACES, n=4)
    exact = solve_radiosity_system(F, scene.reflectivity, scene.emission)
    target = relative_rms_to_mse(predict(scene), SolveSettings().relative_rms)
    ratios = []
    for seed in SEEDS:
        r = solve(scene, target_mse=target, seed=seed, stop_rule=stop_rule, threads=1)
        ratios.append(area_weighted_mse(r.radiosity - scene.emission, exact - scene.emission, scene.patch_area) / target)
    return np.array(ratios)


def test_the_default_stop_rule_keeps_the_error_at_most_the_target():
    """The default (options.STOP_RULE, the panel's and the command line's) stops on the measured
    error: over 8 seeds the mean error reached is below the target, by more than its own
    standard error; the predicted count reaches more than the target on the same scene."""
    assert STOP_RULE.default == "measured" and SolveSettings().stop_rule == "measured"
    measured = _ratios("measured")
    assert measured.mean() + 2 * measured.std(ddof=1) / np.sqrt(len(SEEDS)) < 1.0, measured
    predicted = _ratios("predicted")
    assert predicted.mean() - 2 * predicted.std(ddof=1) / np.sqrt(len(SEEDS)) > 1.0, predicted


SMALL_SOURCE_SEEDS = range(12)
SMALL_SOURCE_CASES = [  # (source in a corner, patches a face's side, relative target, method)
    *[(True, 4, 0.05, m) for m in ("walk", "two_way", "jacobi", "auto")],
    *[(True, 8, 0.05, m) for m in ("walk", "two_way", "jacobi", "auto")],
    *[(False, 8, 0.05, m) for m in ("walk", "two_way", "jacobi", "auto")],
    *[(False, 8, 0.02, m) for m in ("two_way", "auto")],
]


@pytest.mark.parametrize("corner,n,relative,method", SMALL_SOURCE_CASES)
def test_the_measured_rule_keeps_the_target_where_one_small_source_lights_a_bright_room(corner, n, relative, method):
    """A closed box (R 0.8) lit by one ceiling patch (1/n^2 of the ceiling), in its middle or a
    corner, at the panel's 5% (and 2%) on the run's own mean, every method, 12 seeds, against the
    exact discrete solution (random exit): the mean error delivered is under 1.1 times the
    target's and within two of its standard errors of it (a run's error is one draw: where two
    patches hold most of it, it scatters by a third about its mean), and no run is over twice
    it. The estimate alone, read
    after every chunk, stopped on lucky low readings (at 2% one run in 12 delivered 2.6 times the
    target): a run now stops on it plus two of its standard errors. With the source in a corner
    the two wall patches beside it take about 40% of its light, and their gathered direct light
    was heavy-tailed (shadow rays alone met the source's edge at 1/d^2): two-way chunks were
    skewed past what their batches saw, and in the 96-patch box one run in these 12 delivered 2.3
    times the target (3.2 in 48). Automatic runs the walk where the light lands on few patches
    (the corner of the 384-patch box; methods.automatic.concentration)."""
    scene, F = small_source_box(n=n, corner=corner)
    exact = solve_radiosity_system(F, scene.reflectivity, scene.emission) - scene.emission
    target = relative_rms_to_mse(predict(scene), relative)
    ratios = []
    for seed in SMALL_SOURCE_SEEDS:
        r = solve(scene, target_mse=target, seed=seed, stop_rule="measured", threads=1, method=method,
                  error_scale=ERROR_SCALE)
        assert r.stopped == "target"
        ratios.append(area_weighted_mse(r.reflected, exact, scene.patch_area) / target)
    ratios = np.array(ratios)
    se = ratios.std(ddof=1) / math.sqrt(len(ratios))
    assert ratios.mean() < 1.1 and ratios.mean() - 2 * se < 1.0 and ratios.max() < 2.0, ratios
    if method == "auto":
        assert r.method == ("walk" if corner and n == 8 else "two_way")


def test_the_stop_rule_waits_for_its_margin_and_its_chunks(monkeypatch):
    """The measured rule stops only once the estimate plus MEASURED_STOP_Z of its standard
    errors meets the target, on MEASURED_STOP_CHUNKS chunks at least; the chunks' increments
    sum to the batch estimate (Welford's update of its sum of squares), so the bound is the
    estimate plus a margin, never below it."""
    bounds = []
    real = Batches.mse_upper_bound
    monkeypatch.setattr(Batches, "mse_upper_bound", lambda self, z: (bounds.append((self.chunks, self.measured_mse(), real(self, z))), bounds[-1][2])[1])
    kept = {}
    let_go = Batches.let_go_of_squares
    monkeypatch.setattr(Batches, "let_go_of_squares", lambda self: (kept.update(inc=list(self.increments), n=self.paths, k=self.chunks), let_go(self))[1])
    scene, _ = small_source_box()
    target = relative_rms_to_mse(predict(scene), 0.05)
    r = solve(scene, target_mse=target, seed=3, stop_rule="measured", threads=1, method="two_way")
    assert r.stopped == "target" and r.chunks >= plan.MEASURED_STOP_CHUNKS
    assert len(kept["inc"]) == kept["k"] - 1
    assert sum(kept["inc"]) / ((kept["k"] - 1) * kept["n"]) == pytest.approx(r.measured_mse, rel=1e-9)
    assert all(mse <= bound for _, mse, bound in bounds)
    assert bounds[-1][0] == r.chunks and bounds[-1][2] <= target
    assert all(bound > target for _, _, bound in bounds[:-1])


def open_box(n=4, reflectivity=0.7, height=0.3):
    """A tray: a unit square box of ``height``, open at the top (n x n patches a face, no
    ceiling), its floor's middle patch emitting 1: most light leaves. (PatchScene, exact
    reflected radiosity (P,3))."""
    origin, u, v, face = box_rectangles((1.0, 1.0, height), n)
    keep = face != CEILING
    origin, u, v = origin[keep], u[keep], v[keep]
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    emission = np.zeros(origin.shape[0])
    emission[np.flatnonzero(face[keep] == FLOOR)[n * n // 2 + n // 2]] = 1.0
    scene = PatchScene(vertices, triangles, triangle_patch, np.full(origin.shape[0], reflectivity), emission)
    exact = solve_radiosity_system(rectangle_form_factors(origin, u, v), scene.reflectivity, scene.emission)
    return scene, exact - scene.emission


@pytest.mark.parametrize("method", ["walk", "two_way"])
def test_the_target_is_kept_relative_to_the_light_that_stays_in_an_open_scene(method):
    """The product's error target is relative to the scene's own mean reflected radiosity
    (options.ERROR_SCALE). The paper's b_ave = R_ave Phi_T / (A_T (1 - R_ave)) is a closed
    scene's; in an open tray (R 0.7, lit from its floor's middle) it is 7.3x the mean the tray
    really holds, and the walk stopped on it at 2% delivered 3.4-4.6x the target against the
    exact solution's own mean (in the window room the noise inside came out about 3x its target
    so). On the measured scale, over 8 seeds, the error delivered (as an MSE over the target's)
    is at most the target within two standard errors and never twice it, and the run's own
    report of it is the truth's within a ratio band; the walk on the paper's scale, the same
    seeds, is above the target by more than two standard errors."""
    scene, exact = open_box()
    mean = float(np.sum(scene.patch_area[:, None] * exact) / (3 * scene.total_area))
    relative = 0.02
    target = relative_rms_to_mse(predict(scene), relative)
    assert predict(scene).mean_reflected_radiosity > 5 * mean

    def delivered(scale):
        """(MSE over the target's, the run's reported error over the true) per seed."""
        out = []
        for seed in range(8):
            r = solve(scene, target_mse=target, seed=seed, stop_rule="measured", threads=1, method=method, error_scale=scale)
            assert r.stopped == "target"
            truth = math.sqrt(area_weighted_mse(r.reflected, exact, scene.patch_area)) / mean
            out.append(((truth / relative) ** 2, r.relative_error / truth))
        return np.array(out)

    measured = delivered(ERROR_SCALE)
    ratios, se = measured[:, 0], measured[:, 0].std(ddof=1) / math.sqrt(len(measured))
    assert ratios.mean() - 2 * se < 1.0 and ratios.max() < 2.0, measured
    assert np.all((measured[:, 1] > 0.7) & (measured[:, 1] < 1.4)), measured
    if method == "walk":
        paper = delivered("paper")[:, 0]
        assert paper.mean() - 2 * paper.std(ddof=1) / math.sqrt(len(paper)) > 1.0, paper


def test_a_relit_error_speaks_of_the_same_scale_as_the_solves():
    """Relit at the solved strengths, a per-source solve's error is the solve's own, on its scale:
    in the open tray the measured one (the paper's b_ave there is 7.3x the mean, and the relit
    error read on it was 7.3x too low beside the solve's); the target is still the relative
    target asked for; doubling every source leaves the relative error alone. Saved with the
    results (relit.relit_error from the stored numbers) it reads the same."""
    from addon.bpy_free.relit import relit_error
    from addon.core.relight.relighting import relight

    scene, _ = open_box()
    target = relative_rms_to_mse(predict(scene), 0.02)
    r = solve(scene, target_mse=target, seed=1, stop_rule="measured", threads=1, method="two_way",
              per_source=True, error_scale=ERROR_SCALE)
    same = relight(r.per_source, np.ones(r.per_source.count))
    assert same.relative_rms == pytest.approx(r.relative_error, rel=1e-6)
    assert same.target_relative_rms == pytest.approx(0.02, rel=1e-9)
    assert relight(r.per_source, 2 * np.ones(r.per_source.count)).relative_rms == pytest.approx(same.relative_rms, rel=1e-9)
    ps = r.per_source
    meta = {"names": list(ps.names), "power": ps.power.tolist(), "covariance": ps.covariance.tolist(),
            "scale": ps.scale, "target_error": ps.target_error, "reflected_means": ps.reflected_means.tolist()}
    assert relit_error(meta, np.ones((ps.count, 3))).relative_rms == pytest.approx(same.relative_rms, rel=1e-9)
    # results saved before the target was kept as a relative error kept the paper's MSE: read the same
    old = {k: v for k, v in meta.items() if k != "target_error"} | {"target_mse": target}
    assert relit_error(old, np.ones((ps.count, 3))).target_relative_rms == pytest.approx(0.02, rel=1e-9)
    paper = solve(scene, target_mse=target, seed=1, stop_rule="measured", threads=1, method="two_way", per_source=True)
    assert paper.per_source.reflected_means is None
    assert relight(paper.per_source, np.ones(paper.per_source.count)).relative_rms == pytest.approx(paper.relative_error, rel=1e-6)
