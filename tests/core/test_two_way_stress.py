"""The stress cases of test_stress, for the two-way iteration (method="two_way"), which Automatic
takes in most scenes: scale and position, slivers, mirrored and awkward geometry, and where the
light goes when it finds nothing or a back side.

The two-way iteration's variance has no closed form: the bands are its batch means (chunks are
independent replicas; TWO_WAY_MIN_CHUNKS of them give a t-distribution with that many less one
degrees of freedom, |t| < 5.5 over tens of patches: about 1e-3 false failures a test) and, for
the fractions of light that end a given way, the same batch means of the energy accounts.
"""
import math

import numpy as np
import pytest
from boxes import box_rectangles, rectangles_to_mesh
from test_stress import SIZE, _exact_box, _rotation, _sliver_fan

from addon.core import PatchScene, solve
from addon.core.methods.first_shot import FATE_RAYS
from addon.core.estimate.reference import rectangle_form_factors

T = 5.5
PATHS = 100_000


def _two_way(scene, seed, exit_point="random", paths=PATHS):
    r = solve(scene, paths=paths, seed=seed, threads=2, method="two_way", exit_point=exit_point)
    assert r.method == "two_way"
    assert np.isfinite(r.radiosity).all() and np.isfinite(r.reflected_variance).all()
    return r


def _t(r, exact):
    """Per patch (red channel), the run's distance from ``exact`` in its batch standard errors."""
    return (r.reflected[:, 0] - exact) / np.sqrt(r.reflected_variance[:, 0])


@pytest.mark.parametrize("exit_point", ["random", "hit"])
@pytest.mark.parametrize("scale, offset", [(1e-4, 0.0), (1e4, 0.0), (1e-4, 1e5), (1e11, 0.0), (1e-7, 1e2)])
def test_scaled_rotated_and_moved_box(scale, offset, exit_point):
    """A closed box rotated off the axes, scaled and moved far from the origin: no light meets a
    back side through the seams, and the result is the unscaled one: the exact discrete
    solution (exit point random), or the same box at unit scale (hit). (A closed scene's
    "escaped" is the gathering's noise about 0 in the direct light's total, split_lost: with
    the same seed, the same share of the power as at unit scale.)"""
    origin, u, v, R, E, b, _ = _exact_box()
    V, Tr, TP = rectangles_to_mesh(origin, u, v)
    scene = PatchScene((V - 0.5) @ _rotation(5).T * scale + offset, Tr, TP, R, E)
    r = _two_way(scene, 64, exit_point)
    unit = _two_way(PatchScene((V - 0.5) @ _rotation(5).T, Tr, TP, R, E), 64, exit_point)
    assert r.energy["blocked"].max() == 0
    share = r.energy["escaped"] / r.energy["emitted"]
    np.testing.assert_allclose(share, unit.energy["escaped"] / unit.energy["emitted"], rtol=1e-3, atol=1e-6)
    if exit_point == "random":
        t = _t(r, b)
    else:
        other = _two_way(PatchScene(V, Tr, TP, R, E), 65, "hit")
        t = (r.reflected[:, 0] - other.reflected[:, 0]) / np.sqrt(r.reflected_variance[:, 0] + other.reflected_variance[:, 0])
    assert np.abs(t).max() < T, np.abs(t).max()


def test_sliver_triangles():
    """Every patch a fan of triangles down to 1e-12 of its area: still the exact solution (the
    two-way rays leave from triangles chosen by area, the gathering samples too)."""
    origin, u, v, R, E, b, _ = _exact_box()
    V, Tr, TP = _sliver_fan(origin, u, v, [0.0, 1e-12, 1e-6, 1e-3, 0.5, 1 - 1e-6, 1.0])
    r = _two_way(PatchScene(V, Tr, TP, R, E), 71)
    assert r.energy["blocked"].max() == 0
    assert np.abs(_t(r, b)).max() < T


def test_mirrored_box_with_reversed_winding():
    origin, u, v, R, E, b, _ = _exact_box()
    V, Tr, TP = rectangles_to_mesh(origin, u, v)
    r = _two_way(PatchScene(V * [-1, 1, 1], Tr[:, ::-1], TP, R, E), 72)
    assert np.abs(_t(r, b)).max() < T


def test_non_manifold_fin_agrees_with_the_walk():
    """A one-sided card standing on an interior edge of the floor's patches: the two-way iteration
    and the paper's walk agree within both runs' batch noise, and the card's back takes light
    (blocked)."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    card = (np.array([[0.5, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 0.0, 0.5]]))
    origin, u, v = (np.vstack([a, c]) for a, c in zip((origin, u, v), card))
    P = len(origin)
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), np.full(P, 0.6), np.where(np.r_[face, -1] == 1, 1.0, 0.0))
    a = _two_way(scene, 74)
    w = solve(scene, paths=PATHS, seed=75, threads=2)
    assert a.energy["blocked"].min() > 0
    t = (a.reflected[:, 0] - w.reflected[:, 0]) / np.sqrt(a.reflected_variance[:, 0] + w.reflected_variance[:, 0])
    assert np.abs(t).max() < T, np.abs(t).max()


def test_an_emitter_facing_the_void():
    """A single emitter facing nothing: all its power escapes, nothing is reflected."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    scene = PatchScene(V, [[0, 1, 2], [0, 2, 3]], [0, 0], [0.5], [2.0])
    r = _two_way(scene, 76, paths=10_000)
    assert np.array_equal(r.radiosity, scene.emission)
    np.testing.assert_allclose(r.energy["escaped"], r.energy["emitted"], rtol=1e-12)
    np.testing.assert_allclose(r.energy["emitted"], scene.total_power, rtol=1e-12)


def test_a_card_seen_from_behind_gets_nothing_and_its_back_takes_the_form_factor():
    """An emitting square under a parallel card that faces away: the card gets no light, and the
    share of the power its back takes (blocked) is the exact form factor. The gathering finds
    no front lit, so all the power is split between escaped and blocked by the solve's
    FATE_RAYS rays from the emitter (methods.base.fate_shares): a binomial count."""
    origin = np.array([[0.0, 0, 0], [0.0, 0, 0.5]])
    u = np.array([[1.0, 0, 0], [1.0, 0, 0]])
    v = np.array([[0.0, 1, 0], [0.0, 1, 0]])
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), [0.5, 0.7], [1.0, 0.0])
    F = rectangle_form_factors(origin, np.array([[1.0, 0, 0], [0.0, 1, 0]]), np.array([[0.0, 1, 0], [1.0, 0, 0]]))[0, 1]
    r = _two_way(scene, 77)
    assert np.array_equal(r.reflected, np.zeros((2, 3)))
    np.testing.assert_allclose(r.energy["absorbed"], r.energy["blocked"], rtol=1e-12)
    share = r.energy["blocked"][0] / r.energy["emitted"][0]
    assert abs(share - F) < T * math.sqrt(F * (1 - F) / FATE_RAYS), (share, F)


@pytest.mark.parametrize("emitter_inside", [False, True])
def test_flipped_normals_reflect_nothing_and_say_where_the_light_went(emitter_inside):
    """A closed box with every normal out: its emitting ceiling shines into the void (all
    escapes); an emitter inside facing in lights only back sides (all blocked)."""
    origin, u, v, face = box_rectangles(SIZE, n=1)
    V, Tr, TP = rectangles_to_mesh(origin, u, v)
    Tr = Tr[:, ::-1]
    R, E = np.full(6, 0.5), np.where(face == 1, 1.0, 0.0)
    if emitter_inside:
        lamp = np.array([[0.4, 0.5, 0.3], [0.6, 0.5, 0.3], [0.6, 0.7, 0.3], [0.4, 0.7, 0.3]])
        Tr = np.vstack([Tr, len(V) + np.array([[0, 1, 2], [0, 2, 3]])])
        V, TP = np.vstack([V, lamp]), np.r_[TP, 6, 6]
        R, E = np.r_[R, 0.0], np.r_[np.zeros(6), 1.0]
    r = _two_way(PatchScene(V, Tr, TP, R, E), 78, paths=20_000)
    assert np.array_equal(r.reflected, np.zeros_like(r.reflected))
    where = "blocked" if emitter_inside else "escaped"
    np.testing.assert_allclose(r.energy[where], r.energy["emitted"], rtol=1e-12)
