"""The panel's default exit point is the one closer to the continuous light, which a render shows.

A closed lamp room: a unit box of 3 x 3 patches a face (albedo 0.5), lit by the ceiling's middle
patch. The random exit point converges to the discrete radiosity system of these 54 flat
patches; the hit point to the continuous light averaged over each patch, what Cycles' bake of a
patch averages. The reference is that continuous light: the exact discrete solutions on 2x and
4x finer patches, averaged back and extrapolated (Richardson, the observed order), its
uncertainty the size of the extrapolation step. The discrete answer differs from it by 1.4%
per patch here, a discretization error no run's error estimate shows.
"""
import math

import numpy as np
import pytest

from addon.bpy_free import options
from addon.core import PatchScene, solve
from addon.core.estimate.reference import rectangle_form_factors, solve_radiosity_system
from boxes import box_rectangles, rectangles_to_mesh

N = 3
ALBEDO = 0.5
Z = 4.0
# Paths a run: the walk's noise per patch ~0.3%, the two-way iteration's ~0.05%.
PATHS = {"walk": 4_000_000, "two_way": 1_000_000, "auto": 1_000_000}


def _room(n):
    origin, u, v, face = box_rectangles(n=n)
    centre = origin + 0.5 * (u + v)
    light = (face == 1) & (np.abs(centre[:, 0] - 0.5) < 1 / 6) & (np.abs(centre[:, 1] - 0.5) < 1 / 6)
    return origin, u, v, light


def _to_coarse(values, n):
    f = n // N
    return values.reshape(6, N, f, N, f).mean(axis=(2, 4)).reshape(-1)


@pytest.fixture(scope="module")
def room():
    """(scene, continuous reference (P,), its uncertainty (P,), the discrete solution (P,), lit)."""
    solutions = {}
    for k in (1, 2, 4):
        origin, u, v, light = _room(N * k)
        B = solve_radiosity_system(rectangle_form_factors(origin, u, v), np.full(len(origin), ALBEDO), light * 1.0)
        solutions[k] = _to_coarse(B.reshape(len(origin), -1)[:, 0], N * k)
    b1, b2, b4 = solutions[1], solutions[2], solutions[4]
    order = math.log2(np.sqrt(np.mean((b2 - b1) ** 2)) / np.sqrt(np.mean((b4 - b2) ** 2)))
    step = (b4 - b2) / (2**order - 1)
    origin, u, v, light = _room(N)
    vertices, triangles, triangle_patch = rectangles_to_mesh(origin, u, v)
    scene = PatchScene(vertices, triangles, triangle_patch, np.full(len(origin), ALBEDO), light * 1.0)
    return scene, b4 + step, np.abs(step), b1, ~light


def _default_exit_point(method):
    """The exit point the panel and the command line run ``method`` with by default."""
    per_method = getattr(options, "exit_point_for", None)
    return per_method(method) if per_method else options.EXIT_POINT.default


def _relative_square(result, reference, measured):
    """(mean over patches of the squared relative error, its Monte Carlo variance (plug-in:
    each patch's e^2 has variance 4 e^2 s^2 + 2 s^4, s^2 its batch-means variance), RMS error)."""
    e = ((result.radiosity[:, 0] - reference) / reference)[measured]
    s2 = (result.reflected_variance[:, 0] / reference**2)[measured]
    variance = np.sum(4 * e**2 * s2 + 2 * s2**2) / e.size**2
    return float(np.mean(e**2)), float(variance), float(np.sqrt(np.mean(e**2)))


def test_the_reference_differs_from_the_discrete_answer(room):
    """The case is one where the exits disagree: the discrete solution is 1.4% off the
    continuous light per patch, ten times the reference's own uncertainty."""
    _, continuous, uncertainty, discrete, measured = room
    gap = np.sqrt(np.mean(((discrete - continuous) / continuous)[measured] ** 2))
    bound = np.sqrt(np.mean((uncertainty / continuous)[measured] ** 2))
    assert 0.010 < gap < 0.020 and bound < gap / 8, (gap, bound)


@pytest.mark.parametrize("method", ["walk", "two_way", "auto"])
def test_the_default_exit_point_is_closer_to_the_continuous_light(room, method):
    """Each method the panel offers, at its default exit point, is closer to the continuous
    light than at the other one, by more than Z standard deviations of the Monte Carlo noise
    of the difference plus the most the reference's uncertainty can move it."""
    scene, continuous, uncertainty, _, measured = room
    default = _default_exit_point(method)
    other = "random" if default == "hit" else "hit"
    runs = {exit_point: solve(scene, estimator=options.ESTIMATOR.default, paths=PATHS[method], seed=11, exit_point=exit_point,
                              method=method, threads=2) for exit_point in (default, other)}
    (d2, d_var, d_rms), (o2, o_var, o_rms) = (_relative_square(runs[x], continuous, measured) for x in (default, other))
    # A reference off by delta moves each mean square by at most 2 rms(e) rms(delta) (Cauchy-Schwarz).
    shift = 2 * (d_rms + o_rms) * np.sqrt(np.mean((uncertainty / continuous)[measured] ** 2))
    assert o2 - d2 > Z * math.sqrt(d_var + o_var) + shift, (default, d_rms, other, o_rms)


def test_the_options_say_what_the_error_target_covers():
    """The error target is the noise of the patch values, not the flat patches' difference from
    the continuous light: the option says both."""
    words = options.TARGET_ERROR.description.lower()
    assert "noise" in words and "patch" in words and "continuous" in words, words
    assert "closer to the continuous" in options.EXIT_POINT.description.lower() or any(
        "continuous" in d.lower() for _, _, d in options.EXIT_POINT.items)


def test_the_detail_option_on_the_command_line():
    """--detail takes off/low/medium/high in any case and refuses anything else in one line."""
    from addon.bpy_free import options
    from addon.cli.arguments import checked, parser

    assert checked(parser().parse_args(["--detail", "medium"])).detail == "MEDIUM"
    assert checked(parser().parse_args([])).detail == "OFF"
    with pytest.raises(ValueError, match="--detail must be one of OFF, LOW, MEDIUM, HIGH; got 'finest'"):
        options.DETAIL.check("finest")
    from addon.core.refine.adaptive_light import DETAILS

    assert set(DETAILS) == {i for i, _, _ in options.DETAIL.items} - {"OFF"}


def test_the_preview_takes_its_samples_by_live_lamps_unless_told():
    """The command line's preview: LIVE_SAMPLES with live lamps on textured results (the default:
    the renderer draws the lamps' light and a bounce, a Monte Carlo render, denoised); 16 baked, with
    --no-live-lamps or another output (no noise to average); an explicit --samples wins either
    way, and is still checked against its range."""
    from addon.cli.arguments import LIVE_SAMPLES, SAMPLES, checked, parser

    assert options.LIVE_LAMPS.default is True
    assert checked(parser().parse_args([])).samples == LIVE_SAMPLES == 16
    assert checked(parser().parse_args(["--no-live-lamps"])).samples == SAMPLES.default == 16
    assert checked(parser().parse_args(["--colours", "vertex"])).samples == 16
    assert checked(parser().parse_args(["--live-lamps", "--samples", "8"])).samples == 8
    with pytest.raises(ValueError, match="samples"):
        checked(parser().parse_args(["--samples", "0"]))
