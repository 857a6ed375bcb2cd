"""Recombinations whose error the solve's batches cannot give (addon/core/relight/relit_checks.py,
``unmeasured``): a source whose share of the paths was hidden by a far brighter one drew
no path, so its own result is 0 with 0 batch variance; relit to most of the light, the error is
unknown (NaN) and the group named, never "0%". Below its share, or with its light within the
error, the solve's own error stands; re-solved alone it is measured again; no light at all is
no error relative to it."""
import math

import numpy as np
import pytest
from test_relighting import IDS, METHODS, Z, case_kwargs, every_light, joint_noise_z, open_box, solve_case

from addon.core import relight
from addon.core.lights.lights import PointLight
from addon.core.relight.resolve import resolve
from addon.core.relight.relit_checks import REST_SHARE

CASES = [METHODS[0], METHODS[3], METHODS[7]]


def _swamped(emitter=1e6):
    """The open box's two emitting floor patches ``emitter`` times as strong, beside its point
    lamp alone: the lamp's share of the power (and of the paths) about 1e-6 at 1e6."""
    box = open_box()
    return box.with_materials(box.reflectivity, box.emission * emitter, every_light()[:1])


@pytest.mark.parametrize("case", CASES, ids=[IDS[0], IDS[3], IDS[7]])
def test_a_lamp_hidden_by_a_far_brighter_emitter_is_unmeasured_when_relit_to_most_of_the_light(case):
    scene = _swamped()
    ps = solve_case(scene, case, paths=40_000, seed=3, per_source=True).per_source
    assert ps.names[1] == "point"
    # the emitter off: the lamp's light is all of it, and the solve drew none of its paths
    alone = relight(ps, [0.0, 1.0])
    assert not alone.radiosity.any()  # (what relighting cannot know: a fresh solve is lit)
    assert math.isnan(alone.relative_rms) and not alone.past_target  # (not "error 0%")
    assert alone.unmeasured == ("point",) and ps.sampled_share[1] < 1e-5 and ps.lit_batches[1] < 2
    # at the solve's strengths, or the emitter halved (the lamp a millionth of the light, within
    # the error), the solve's own error stands
    for weights in ([1.0, 1.0], [0.5, 1.0]):
        relit = relight(ps, weights)
        assert relit.unmeasured == () and 0 < relit.relative_rms < 0.2, relit.relative_rms
    # the emitter dimmed until the lamp has half the power: still unmeasured
    assert relight(ps, [ps.power[1].sum() / ps.power[0].sum(), 1.0]).unmeasured == ("point",)
    # re-solved alone (Update), it is measured, and agrees with a fresh solve of the lamp alone
    redone = resolve(scene, ps, ["point"], **case_kwargs(case, paths=40_000, seed=4))
    assert redone.sampled_share[1] == 1.0 and redone.lit_batches[1] >= 2
    relit = relight(redone, [0.0, 1.0])
    assert relit.unmeasured == () and math.isfinite(relit.relative_rms)
    lamp = scene.with_materials(scene.reflectivity, np.zeros_like(scene.emission), every_light()[:1])
    fresh = solve_case(lamp, case, paths=40_000, seed=5)
    z = joint_noise_z(relit.radiosity, fresh.radiosity, relit.mse, fresh.measured_mse, fresh.reflected_variance,
                       scene.patch_area)
    assert abs(z) < Z, z


def test_a_lamp_that_lights_nothing_is_measured_once_re_solved_alone():
    """A point lamp under the floor lights only the floor's back (no patch's front): its group is
    lit in no batch. Relit to more than its share it is unmeasured (nothing says it lights
    nothing but its few paths); re-solved alone (its share of those samples all of them) it is not
    again, and alone its result is dark: no light, no error relative to it."""
    box = open_box()
    under = PointLight(np.array([0.5, 0.5, -0.3]), np.full(3, 0.2), radius=0.05, name="under")
    scene = box.with_materials(box.reflectivity, box.emission, every_light()[1:] + [under])
    ps = solve_case(scene, METHODS[0], paths=40_000, seed=3, per_source=True).per_source
    g = ps.names.index("under")
    assert ps.lit_batches[g] == 0 and ps.sampled_share[g] > 0.01
    others_dimmed = np.full((ps.count, 3), 0.2)
    others_dimmed[g] = 1.0
    assert relight(ps, np.ones((ps.count, 3))).unmeasured == ()
    assert relight(ps, others_dimmed).unmeasured == ("under",)
    redone = resolve(scene, ps, ["under"], **case_kwargs(METHODS[0], paths=40_000, seed=4))
    assert relight(redone, others_dimmed).unmeasured == ()
    alone = np.zeros((ps.count, 3))
    alone[g] = 1.0
    dark = relight(redone, alone)
    assert dark.dark and math.isnan(dark.relative_rms) and dark.unmeasured == () and not dark.past_target


def test_every_source_off_is_dark_not_an_error_of_0():
    ps = solve_case(open_box(), METHODS[0], paths=20_000, seed=1, per_source=True).per_source
    off = relight(ps, np.zeros(ps.count))
    assert off.dark and math.isnan(off.relative_rms) and off.unmeasured == () and not off.radiosity.any()


def test_a_recombination_past_the_target_names_the_groups_whose_re_solve_would_meet_it():
    """The dimmest source alone at full strength, the rest off (as in test_relighting): past the
    solve's target, and that source is the one to solve again; re-solved to the same relative
    error of its own light (the re-solved share of it, as Update holds it to), the recombination
    meets it.
    At the solve's strengths nothing is past it."""
    scene = open_box()
    first = solve_case(scene, METHODS[0], paths=40_000, seed=1, per_source=True)
    ps = solve_case(scene, METHODS[0], target_mse=2 * first.measured_mse, seed=1, per_source=True,
                stop_rule="measured").per_source
    assert relight(ps, np.ones(ps.count)).over_target == ()
    alone = np.zeros(ps.count)
    dimmest = int(np.argmin(ps.power.mean(axis=1)))
    alone[dimmest] = 1.0
    relit = relight(ps, alone)
    assert relit.past_target and relit.over_target == (ps.names[dimmest],)
    as_relit = ps.target_error * math.sqrt(1 - REST_SHARE)
    redone = resolve(scene, ps, [ps.names[dimmest]], **case_kwargs(METHODS[0], target_error=as_relit, seed=2,
                                                                 stop_rule="measured"))
    again = relight(redone, alone)
    assert again.over_target == () and not again.past_target, (again.relative_rms, again.target_relative_rms)


def test_a_re_solved_source_at_a_new_strength_keeps_the_solve_s_relative_target():
    """resolve keeps the solve's target as the same relative error of the light as it is now:
    the area lamp re-solved at twice its strength, the target's relative RMS is the solve's (before:
    the absolute target_mse of the solve over the brighter light's mean, a tighter relative one,
    and a relight meeting the target said past it)."""
    scene = open_box()
    first = solve_case(scene, METHODS[0], paths=20_000, seed=1, per_source=True)
    ps = solve_case(scene, METHODS[0], target_mse=2 * first.measured_mse, seed=1, per_source=True,
                stop_rule="measured").per_source
    brighter = open_box(np.array([(1, 1, 1)] * 3 + [(2, 2, 2)] + [(1, 1, 1)] * 2))
    redone = resolve(brighter, ps, ["area"], **case_kwargs(METHODS[0], paths=20_000, seed=2))
    solved = relight(ps, np.ones(ps.count)).target_relative_rms
    assert relight(redone, np.ones(ps.count)).target_relative_rms == pytest.approx(solved, rel=1e-12)
