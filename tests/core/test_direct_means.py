"""The display's direct light of each lamp in place of the solve's (addon/core/display/direct_means.py):
a weak spot beside a sun the room shuts out. The solve's gathering looks at sources by power,
and the sun's counts over the whole scene: the spot gets a thousandth of its shadow rays, and
its floor came out at 0.67-0.68 of its light (the hall's painting under its spot at 0.51). The
room's walls and ceiling are black, so the floor's light is the spot's direct light alone,
exact by quadrature."""
import numpy as np
from many_lamps import Selection, _object

from addon.bpy_free import pipeline, shown_mesh
from addon.core.display.direct_means import MEAN_SAMPLES
from addon.core.lights.lights import PointLight, Spot, SunLight

ROOM = (4.0, 4.0, 3.0)
SPOT_AT = np.array([2.0, 2.0, 2.5])
COS_OUTER, COS_INNER = np.cos(np.radians(20.0)), np.cos(np.radians(16.0))
SUN = 30.0  # on a surface facing it; none reaches in


def _objects():
    room = _object("Room", [((0.0, 0.0, 0.0), ROOM)], True, 0.0)
    floor = np.array([np.allclose(room.vertices[room.corner_verts[4 * f:4 * f + 4], 2], 0.0)
                      for f in range(len(room.face_sizes))])
    room.face_reflectivity[floor] = 0.5
    objects = Selection([room])
    sun = np.array([0.3, 0.2, -1.0])
    objects.lights = (PointLight(SPOT_AT, np.ones(3), spot=Spot(np.array([0.0, 0.0, -1.0]), COS_OUTER, COS_INNER), name="Spot"),
                      SunLight(sun / np.linalg.norm(sun), np.full(3, SUN), name="Sun"))
    return objects


def _spot_light(x, y):
    """The spot's irradiance I cos / r^2 times its cone's mask at floor points."""
    d = SPOT_AT - np.stack([x, y, np.zeros_like(x)], axis=-1)
    r = np.linalg.norm(d, axis=-1)
    cosine = d[..., 2] / r
    t = np.clip((cosine - COS_OUTER) / (COS_INNER - COS_OUTER), 0.0, 1.0)
    return cosine * t * t * (3.0 - 2.0 * t) / r**2


def _floor_light(mesh, corners):
    """The floor's area-weighted mean of corner values (C,3), grey, over the polygons' fans, as a
    mesh interpolates them."""
    start = np.r_[0, np.cumsum(mesh.face_sizes)[:-1]]
    means, areas = [], []
    for s, k in zip(start, mesh.face_sizes):
        ids = mesh.corner_verts[s:s + k]
        points = mesh.points[ids]
        if not np.allclose(points[:, 2], 0.0):
            continue
        total = area = 0.0
        for i in range(1, k - 1):
            a = 0.5 * np.linalg.norm(np.cross(points[i] - points[0], points[i + 1] - points[0]))
            total += a * corners[[s, s + i, s + i + 1]].mean()
            area += a
        means.append(total / area)
        areas.append(area)
    means, areas = np.array(means), np.array(areas)
    return (means * areas).sum() / areas.sum()


def test_a_weak_spot_beside_a_shut_out_sun_lights_the_floor_with_all_its_light():
    """The textured output's light and the smooth 'Radiosity' (over the floor's 0.5) against the
    exact mean of the spot's light over the floor (a 2000 x 2000 midpoint rule), per-light
    results on (two sources: the spot's group is a lamp's alone). Band: the display's mean of a
    patch is of MEAN_SAMPLES stratified points, each exact at its point (one spot, no radius), so
    its variance is at most the light's variance over the patch over MEAN_SAMPLES (as if the
    points were independent); the floor's mean within 3 of the standard errors that gives."""
    settings = pipeline.SolveSettings(seed=0, output="TEXTURED", live_lamps=False, patch_size=0.5, relative_rms=0.1)
    out = pipeline.run_solve(_objects(), settings)
    assert out.sources_out is not None  # (per-light results: Automatic keeps them for two sources)
    s = (np.arange(2000) + 0.5) / 2000
    fine = _spot_light(*np.meshgrid(s * ROOM[0], s * ROOM[1]))
    exact = fine.mean()
    cells = fine.reshape(8, 250, 8, 250)  # (the floor's 8 x 8 patches of 0.5 m)
    error = np.sqrt((cells.var(axis=(1, 3)) / MEAN_SAMPLES).sum()) / 64
    band = 3 * error / exact
    assert 0 < band < 0.1, band
    mesh = shown_mesh.mesh_of(out, 0)  # (the display's cells the colours are written on)
    light = _floor_light(mesh, out.light_colours[0])
    assert abs(light / exact - 1) < band, (light / exact, band)
    smooth = _floor_light(mesh, out.smooth_colours[0]) / 0.5
    assert abs(smooth / exact - 1) < band, (smooth / exact, band)


def test_only_groups_of_lamps_alone_take_the_displays_direct_light():
    """Groups of a point lamp with an emitting material, of a sun, of an area lamp, of the world:
    only the area lamp's group is lamps alone (the solve's choice serves suns, the world and
    emitting patches; the display's one round would miss the sky through an opening)."""
    from types import SimpleNamespace

    from addon.core.display.direct_means import lamp_groups
    from addon.core.lights.lights import AreaLight, WorldLight

    lights = [PointLight(np.zeros(3), np.ones(3)), SunLight(np.array([0.0, 0.0, -1.0]), np.ones(3)),
              AreaLight(np.zeros(3), np.array([0.1, 0, 0]), np.array([0, 0.1, 0]), np.array([0, 0, -1.0]), np.ones(3)),
              WorldLight(np.ones(3))]
    scene = SimpleNamespace(lights=SimpleNamespace(lights=lights))
    groups = SimpleNamespace(count=4, light_group=np.array([0, 1, 2, 3]), patch_group=np.array([-1, 0, -1]))
    np.testing.assert_array_equal(lamp_groups(scene, groups), [2])
    groups.patch_group = None
    np.testing.assert_array_equal(lamp_groups(scene, groups), [0, 2])
