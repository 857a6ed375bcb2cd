"""The smooth colours of a solve's whole (``smooth_corners``): the live parts, the light arriving and
the radiosity at every corner of the shading triangles, with the direct light's shape (core
point_direct), the noise filtered (core noise_filter) and the display's cells (shown_mesh.display);
a per-source solve's groups are made alongside in relit.SmoothSources."""
from __future__ import annotations

import numpy as np

from ..core.display import direct_means, live_sources, point_direct, smoothing
from ..core.display.covered import seen_parts
from ..core.display.slack import light_slack, reflected_slack
from ..core.distributed.runners import beside


def smooth_corners(scene, result, light=False, shading=None, live=False, dtype=np.float32, deadline=None, surface=None,
                    direct=None, display=None):
    """With ``light`` and ``live`` first ("bounced", (T,3,3)): the light arriving (``Surface.arriving_light``)
    at every corner of the scene's triangles less the lamps', suns', emitters' and world's direct light,
    smooth (what the renderer draws live), and where there are lamps ("lampless", (T,3,3)) it less the
    lamps' and suns' alone (what EEVEE draws live: ``live_sources.lamp_part``); then with ``light``
    ("light", (T,3,3)): the light arriving; then ("smooth", (T,3,3)): the reflected light, its
    tile noise filtered within its measured variance, joined across objects (not across hidden
    patches: core covered) and kept apart at creases (core smoothing), plus each patch's own
    emission, flat; light and smooth with the direct light's shape within each patch (core point_direct).
    Made one at a time (a generator), so that the caller lets go of one before the next is made; given as
    ``dtype`` (float32: as written). ``shading``: the (triangles, patch of each) to make them on, if not the
    scene's (a refined mesh's, with every polygon corner: adaptive_patches.shading_arrays); ``deadline``:
    the direct light's retries within it (core sample_rounds). ``surface`` and ``direct``: the display's
    own (shown_mesh.display: its finer cells), else made on the shading triangles; or ``surface`` the
    shading triangles' and ``display`` a callable giving the display's (surface, direct), called once the
    filters and the live parts are made on ``surface`` (core relighting.smooth_sources)."""
    triangles, triangle_patch = shading if shading is not None else (scene.triangles, scene.triangle_patch)
    if surface is None:
        surface = smoothing.Surface.of(scene.vertices, triangles, triangle_patch, scene.patch_count,
                                       **seen_parts(scene, triangles, triangle_patch))
    early = []  # (the live parts, on ``surface``)
    with beside(getattr(display, "beside", False)):
        drawn = live_sources.live_light(scene, result, deadline) if light and live else None
        if result.direct_irradiance is not None:  # (the solve's noise is in its indirect part alone: core direct_means)
            rest = direct_means.arriving(surface, scene, result, True) if light else None
            arriving = None if rest is None else rest + result.direct_irradiance  # (direct_means.arriving's, one filter)
            bounced = rest if drawn is not None else None
            reflected = direct_means.reflected(surface, scene, result)
        else:  # (filters first: with the direct light held, the peak)
            arriving = live_sources.arriving(surface, scene, result, False, deadline) if light else None
            bounced = live_sources.arriving(surface, scene, result, True, deadline, drawn) if drawn is not None else None
            reflected = surface.filter_light(result.reflected, result.reflected_variance)
        # (each patch's shown mean within its slack of its light: no square where noise set it apart)
        slack = light_slack(result) if light or bounced is not None else None
        if bounced is not None:
            bounced = point_direct.light_corners(surface, scene, bounced, None, True, dtype, slack)
            early.append(("bounced", bounced))
            if live_sources.draws_highlights(scene):  # (EEVEE's: the light less the lamps' it draws live; the rest put back)
                unlit = drawn - live_sources.lamp_part(scene, drawn, seed=result.seed, light=result.irradiance,
                                                       deadline=deadline)
                early.append(("lampless", bounced + surface.corner_values(unlit, dtype=dtype) if unlit.any() else bounced))
            del bounced
    if display is not None:
        surface, direct = display()
    elif direct is None:
        direct = point_direct.corner_direct(surface, scene, triangles, seed=result.seed, deadline=deadline,
                                            light=result.irradiance)
    while early:
        name, corners = early.pop(0)
        yield name, surface.interpolated(corners)
        del corners
    if light:
        yield "light", point_direct.light_corners(surface, scene, arriving, direct, False, dtype, slack)
    del slack
    corners = point_direct.shown(surface, reflected, direct and point_direct.scaled(surface, direct, scene.reflectivity, True),
                                 dtype=dtype, slack=reflected_slack(result, scene.reflectivity))
    corners += scene.emission[surface.triangle_patch][:, None, :]
    yield "smooth", corners


def smooth_light(scene, result, light=False):
    """(smooth radiosity, smooth light arriving or None), each (T,3,3) (``smooth_corners``)."""
    made = dict(smooth_corners(scene, result, light, dtype=np.float64))
    return made["smooth"], made.get("light")
