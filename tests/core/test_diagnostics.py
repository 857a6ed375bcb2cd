"""Where light meets the back of faces, and whether the selection sees those back sides
(core.diagnostics.back_light): the part of the solve's blocked light a user is warned about."""
import numpy as np
import pytest
from boxes import CEILING, FLOOR, box_rectangles, rectangles_to_mesh

from addon.core import PatchScene, solve
from addon.core.scene.diagnostics import BACK_RAYS, back_light
from addon.core.lights.lights import PointLight, WorldLight


def _open_box(flip_floor=False, lights=(), inside_out=False, keep_ceiling=False):
    """A unit box (n = 2), open at the top unless ``keep_ceiling``, faces inward (outward with
    ``inside_out``), the floor facing down with ``flip_floor``. (scene, face of each patch)."""
    origin, u, v, face = box_rectangles((1.0, 1.0, 1.0), n=2)
    keep = (face != CEILING) | keep_ceiling
    origin, u, v, face = origin[keep], u[keep], v[keep], face[keep]
    flip = (face == FLOOR) & flip_floor | inside_out
    origin, u, v = np.where(flip[:, None], origin + u, origin), np.where(flip[:, None], -u, u), v
    scene = PatchScene(*rectangles_to_mesh(origin, u, v), np.full(len(origin), 0.6), np.zeros(len(origin)),
                       lights=lights)
    return scene, face


SKY = WorldLight(irradiance=np.full(3, 0.05), name="Sky")


def test_the_sky_on_the_outside_of_an_open_box_is_out_of_view():
    """Under a sky, the walls' and the floor's back sides (outside) take much of the light that
    meets the box; rays from those back sides escape without meeting a receiver's front: none
    of it is in view. Its total agrees with the solve's measured blocked share."""
    scene, face = _open_box(lights=[SKY])
    source, patch, share, in_view = back_light(scene, np.ones(scene.patch_count, bool))
    assert share.sum() > 0.3 and not in_view.any()
    assert (source == scene.patch_count).all()  # the sky: the first (only) light's row
    r = solve(scene, estimator="finite", paths=1 << 14, seed=1)
    blocked = r.energy["blocked"].mean() / r.energy["emitted"].mean()
    # Each ray's share is 1/BACK_RAYS: a binomial proportion's sd; the solve's own error is smaller.
    sd = np.sqrt(share.sum() * (1 - share.sum()) / BACK_RAYS)
    assert abs(share.sum() - blocked) < 5 * sd + 0.02, (share.sum(), blocked)


def test_a_floor_facing_down_is_in_view_and_its_source_named():
    """The floor built facing down: the sky that comes in meets its back side, which the walls
    see (rays from it meet their fronts). Its patches are in view; the walls' outsides are not."""
    scene, face = _open_box(flip_floor=True, lights=[SKY])
    source, patch, share, in_view = back_light(scene, np.ones(scene.patch_count, bool))
    floor = face[patch] == FLOOR
    assert in_view[floor].all() and not in_view[~floor].any()
    assert share[floor].sum() > 0.02  # (about 10% of the sky enters the opening, a fifth of it straight down)
    # With the walls not receiving (the rest of the scene), no receiver sees the floor's back:
    # rays from it escape through the opening, so it is outside every receiver.
    receives = face == FLOOR
    assert not back_light(scene, receives)[3].any()


def test_a_closed_box_built_inside_out_is_in_view():
    """A closed box whose faces point out, a lamp inside: all its light meets back sides, and
    the back sides close a region (no ray from them escapes), so it is in view though no
    receiver's front is there to see it."""
    lamp = PointLight(np.full(3, 0.5), np.ones(3), name="Bulb")
    scene, face = _open_box(lights=[lamp], inside_out=True, keep_ceiling=True)
    source, patch, share, in_view = back_light(scene, np.ones(scene.patch_count, bool))
    assert share.sum() == pytest.approx(1.0) and in_view.all()
