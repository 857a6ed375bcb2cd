"""Each patch's direct light as the display estimates it, in place of the solve's.

The solve gathers the direct light with shadow rays to sources chosen by power: a weak lamp
beside a sun whose power counts over the whole scene (a spot on a painting in a hall under a
skylight) gets a thousandth of the rays, and its patches' light comes out heavy-tailed, most
of them far below it (the painting at half its light, the error estimate none the wiser). The
display looks at every lamp by what it would give the point (``lamp_choice``), each sun apart,
and samples a patch again where its mean is noisier than the eye would see
(``point_direct.live_means``: SAMPLES points a patch, the noisy ones 8 and 64 times as many):
its patch means of the direct light are the better estimate. Where the solve kept its gathered
direct light apart (``SolveResult.direct_irradiance``), the display's light is the solve's
indirect part, H - D_solve, plus the display's own direct means D; the reflected light and the
radiosity change by the reflectivity times D - D_solve.
"""
from __future__ import annotations

from dataclasses import replace

from .point_direct import SAMPLES, has_live, live_means


def corrected(scene, result, deadline=None):
    """``result`` (a SolveResult) with the display's direct light in place of the solve's: its
    irradiance, reflected light, radiosity and direct part, and each source group's (its
    ``per_source``); as it is where the solve did not keep its direct light apart or the scene
    has none. The display's patch means' retries within ``deadline``."""
    ps = result.per_source
    if result.direct_irradiance is None or not has_live(scene) or (ps is not None and ps.direct_irradiance is None):
        return result
    grouped = ps is not None
    groups = {} if not grouped else {"light_group": ps.light_group, "patch_group": ps.patch_group, "groups": ps.count}
    # (SAMPLES points a patch first, as a corner's: the noisy patches are sampled again, 8x then 64x)
    direct = live_means(scene, samples=SAMPLES, seed=result.seed, light=result.irradiance, deadline=deadline, **groups)
    whole = direct.sum(axis=0) if grouped else direct
    change = whole - result.direct_irradiance
    reflected = result.reflected + scene.reflectivity * change
    out = replace(result, irradiance=result.irradiance + change, reflected=reflected, radiosity=scene.emission + reflected,
                  direct_irradiance=whole)
    if grouped:
        parts = direct - ps.direct_irradiance
        out.per_source = replace(ps, irradiance=ps.irradiance + parts, radiosity=ps.radiosity + scene.reflectivity * parts,
                                 direct_irradiance=direct)
    return out


def arriving(surface, scene, result, live=False):
    """(P,3) the light arriving shown for a ``result`` whose direct part is known: its indirect
    part noise-filtered (``Surface.arriving_light``, within the solve's measured variance, which
    is the solve's noise), and the direct part added after, as it is (the display's own:
    ``corrected``), unless ``live`` (the renderer draws it)."""
    direct = result.direct_irradiance
    light = surface.arriving_light(result.irradiance - direct, result.irradiance_variance, scene.reflectivity)
    return light if live else light + direct


def reflected(surface, scene, result):
    """(P,3) the reflected light shown for a ``result`` whose direct part is known: its indirect
    part noise-filtered (``Surface.filter_light``), the direct part's reflection added after."""
    direct = scene.reflectivity * result.direct_irradiance
    out = surface.filter_light(result.reflected - direct, result.reflected_variance)
    out += direct
    return out
