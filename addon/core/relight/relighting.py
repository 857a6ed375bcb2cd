"""Per-source results and relighting: every source group's light from one solve, recombined.

Radiosity is linear in emission, channel by channel: the result for any strengths and colours
of the sources is sum_s w_s B_s, B_s the result of group s alone at the solve's strengths and
w_s (S,3) the new strength and colour over the solved ones. A per-source solve
(``solve(..., per_source=True)``) tallies each group's incident power apart from the same rays
(``grouping``); ``estimate.per_source`` sums them chunk by chunk, with what the error of any
recombination needs (the groups' batch covariance), and :func:`relight` recombines without tracing a ray;
``resolve`` solves groups again alone.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..display import live_sources, point_direct
from ..display.slack import light_slack, reflected_slack
from ..distributed.runners import beside, each_on_threads
from . import relit_checks


@dataclass
class Relit:
    """A recombination: ``radiosity`` (P,3), ``irradiance`` (P,3) or None, the measured MSE
    ``mse`` of its reflected radiosity and the ``relative_rms`` error (over b_ave at the new
    powers; NaN below 2 batches, ``dark`` or with groups ``unmeasured``), ``target_relative_rms``
    the solve's target in the same terms (None without one), and ``past_target``: whether the new
    weights move the error past it, and the groups whose re-solve would meet it (``over_target``;
    ``relit_checks`` has these)."""

    radiosity: np.ndarray
    irradiance: np.ndarray | None
    mse: float
    relative_rms: float
    target_relative_rms: float | None
    past_target: bool
    unmeasured: tuple = ()
    dark: bool = False
    over_target: tuple = ()


def check_weights(per_source, weights):
    """``weights`` as (S,3) float64; ValueError in one line where they cannot be."""
    w = np.asarray(weights, dtype=np.float64)
    S = per_source.count
    if w.ndim == 1 and w.shape == (S,):
        w = np.repeat(w[:, None], 3, axis=1)
    if w.shape != (S, 3):
        raise ValueError(f"weights must have shape ({S}, 3) (or ({S},)): one RGB factor a source; got {w.shape}")
    if not np.isfinite(w).all() or (w < 0).any():
        raise ValueError("weights must be finite and at least 0 (0 switches a source off)")
    return w


def relight(per_source, weights, irradiance=False):
    """The solve's result with each source group's light times ``weights`` (S,3) (or (S,): the
    same in every channel), new strength times colour over the solved ones (0: off), and its
    error estimate at those weights: a Relit (its irradiance too with ``irradiance``). Traces no
    ray; the results keep the stored results' dtype (float32 results take half the time)."""
    w = check_weights(per_source, weights)
    radiosity = _combine(per_source.radiosity, w)
    light = _combine(per_source.irradiance, w) if irradiance else None
    mse = per_source.mse(w)
    scale = per_source.mean_reflected(w)
    dark = relit_checks.dark(per_source, w) or not scale > 0
    unmeasured = relit_checks.unmeasured(per_source, w, scale) if math.isfinite(mse) else ()
    relative = math.nan if dark or unmeasured else math.sqrt(mse) / scale  # (no light: no error relative to it)
    target = None
    if per_source.target_error is not None:
        target = per_source.target_error
    past = target is not None and relative > target
    return Relit(radiosity, light, mse, relative, target, past, unmeasured, dark,
                 relit_checks.over_target(per_source, w, scale, target) if past else ())


def _combine(values, w):
    """(P,3) sum_s w_s values_s of (S,P,3) ``values`` (one pass over them: it is memory-bound)."""
    return np.einsum("spc,sc->pc", values, w.astype(values.dtype, copy=False))


def combine(per_source, parts, weights):
    """sum_s w_s parts_s (...,3) of any per-source ``parts`` (S,...,3) (smooth corners of
    ``smooth_sources``, an object's polygon corners), with ``weights`` as ``relight`` takes them;
    in the parts' dtype."""
    w = check_weights(per_source, weights)
    parts = np.asarray(parts)
    if parts.shape[:1] != (per_source.count,) or parts.shape[-1] != 3:
        raise ValueError(f"parts must have shape ({per_source.count}, ..., 3): one a source; got {parts.shape}")
    flat = parts.reshape(per_source.count, -1, 3)
    return _combine(flat, w).reshape(parts.shape[1:])


def smooth_sources(surface, scene, result, light=False, dtype=np.float64, triangles=None, live=False, deadline=None,
                   direct=None, display=None):
    """Each source group's smooth colours, made as the solve's own are (the pipeline's smooth
    output) with the whole's noise-filter weights, clips and corner scales held fixed, so that
    they add up over the groups to the solve's (float error) and recombine as ``relight`` does:
    with ``light`` and ``live`` first ("bounced", (S,T,3,3)), the light arriving less the sources'
    direct light (the renderer's), smooth alone, with lamps ("lampless") less theirs alone
    (``_lampless``); then with ``light`` ("light", (S,T,3,3)), the light arriving
    (``Surface.arriving_light``); then ("smooth", (S,T,3,3)), the reflected light filtered
    (``Surface.filter_light``) and smooth, plus each group's own emission, flat. Light and smooth
    show the direct light at the corners (``point_direct``), each group's own.
    ``surface`` is ``smoothing.Surface.of`` the scene's triangles (or ``triangles``, (T,3) of its
    vertices); ``result`` a per-source solve's SolveResult. Made in float64, given as ``dtype``
    (float32: half the memory, as they are written; their sum then the whole's to float32
    rounding). ``deadline``: the direct light's retries within it (``point_direct``). ``display``:
    a callable giving (the surface, its CornerDirect) of the display's finer cells, called once
    the filters and the live parts, which read neither, are made on ``surface`` (on one thread
    where its ``beside`` says the display's are traced beside them meanwhile, ``threads.beside``)
    and carried to its cells (``Surface.interpolated``); else ``direct``, or the groups' own made here."""
    per_source = result.per_source
    if per_source is None:
        raise ValueError("the solve has no per-source results: solve with per_source=True")
    triangles = scene.triangles if triangles is None else triangles
    drawn = per_source.direct_irradiance  # (S,P,3) or None (known: the solve's noise is in the rest alone, direct_means)
    rho = scene.reflectivity
    slack = light_slack(result) if light else None  # (each shown mean within its slack)
    early = []  # (the live parts, on ``surface``)
    with beside(getattr(display, "beside", False)):
        if light and live and drawn is None:  # (the lamps', suns', emitters' and world's direct light left to the renderer)
            drawn = live_sources.live_means(scene, seed=result.seed, light=result.irradiance,
                                            light_group=per_source.light_group, patch_group=per_source.patch_group,
                                            groups=per_source.count, deadline=deadline)
        made = _filtered(surface, result, drawn, rho, light)
        if light and live:  # (what the live outputs read: the light less what Cycles draws, and less what EEVEE does)
            early = _live_parts(surface, scene, result, made["rest"], made["rest_parts"], drawn, dtype, deadline, slack)
    if display is not None:
        surface, direct = display()
    elif direct is None:  # (else the display's own: its finer cells')
        direct = group_direct(surface, scene, result, triangles, deadline)
    while early:
        name, corners = early.pop(0)
        yield name, surface.interpolated(corners)
        del corners
    filtered, noise = made["filtered"], made["noise"]
    held = 0.0 if per_source.direct_irradiance is None else per_source.direct_irradiance * rho
    whole = _summed(direct)
    if light:
        rest, rest_parts = made.pop("rest"), made.pop("rest_parts")
        arriving, parts = (rest, rest_parts) if drawn is None else (rest + drawn.sum(axis=0), rest_parts + drawn)
        yield "light", point_direct.shown(surface, arriving, whole, parts, direct, dtype, slack)[1]
    del slack
    _, smooth = point_direct.shown(surface, filtered, whole and point_direct.scaled(surface, whole, rho),
                                   noise(per_source.irradiance * rho - held) + held,
                                   direct and point_direct.scaled(surface, direct, rho), dtype, reflected_slack(result, rho))
    emitting = per_source_emission(scene, per_source)
    for s in range(per_source.count):  # (a part at a time: no (S,T,3) copy)
        smooth[s] += emitting[s, surface.triangle_patch][:, None, :]
    yield "smooth", smooth


def _filtered(surface, result, drawn, rho, light):
    """{"filtered", "noise"}: the reflected light filtered (``Surface.filter_light``, the groups' known
    direct part held) and the filter's map of the groups' parts; with ``light`` also {"rest",
    "rest_parts"}: the light arriving less the groups' ``drawn`` (S,P,3) filtered and its map of
    the groups' parts. The noise filters first, as the pipeline's (with the direct light's corners
    held, the peak), the two on the local threads."""
    per_source, made = result.per_source, {}

    def arriving_filter():
        held = 0.0 if drawn is None else drawn
        rest, rest_fill = surface.arriving_light(result.irradiance - _whole(held), result.irradiance_variance, rho,
                                                 return_filter=True)
        made["rest"], made["rest_parts"] = rest, rest_fill(per_source.irradiance - held)

    def reflected_filter():
        held = 0.0 if per_source.direct_irradiance is None else per_source.direct_irradiance * rho
        made["filtered"], made["noise"] = surface.filter_light(result.reflected - _whole(held), result.reflected_variance,
                                                               return_filter=True)
        made["filtered"] += _whole(held)

    surface.neighbours()  # (made once, before the two filters read it on the local threads)
    filters = ([arriving_filter] if light else []) + [reflected_filter]  # (a bad input's error as before: the first's)
    each_on_threads(len(filters), lambda k: filters[k]())
    return made


def _live_parts(surface, scene, result, rest, rest_parts, drawn, dtype, deadline, slack=None):
    """[("bounced", (S,T,3,3))]: each group's light arriving less its live sources' ``drawn`` (the
    rest: ``rest`` (P,3), ``rest_parts`` (S,P,3)), smooth alone (its means within ``slack``); and
    where there are lamps ("lampless", ``_lampless``)."""
    bounced = point_direct.shown(surface, rest, None, rest_parts, None, dtype, slack)[1]
    if not live_sources.draws_highlights(scene):
        return [("bounced", bounced)]
    return [("bounced", bounced), ("lampless", _lampless(surface, scene, result, bounced, drawn, dtype, deadline))]


def _lampless(surface, scene, result, bounced, drawn, dtype, deadline):
    """(S,T,3,3) each group's light arriving less its lamps' and suns' (``live_sources.lamp_part``),
    smooth alone: its ``bounced`` corners (the light less every live source's ``drawn``, (S,P,3))
    plus the corners of the emitters' and the world's part of ``drawn``, made by the map of their
    sum (whose patch means are its own)."""
    ps = result.per_source
    unlit = drawn - live_sources.lamp_part(scene, drawn, ps.light_group, ps.patch_group, ps.count, result.seed,
                                           result.irradiance, deadline)
    out = bounced.copy()
    rows = np.flatnonzero(unlit.any(axis=(1, 2)))  # (a lamp's group: its bounced light as it is)
    if rows.size:
        whole, apply = surface.corner_values(unlit[rows].sum(axis=0), return_filter=True)
        out[rows] += point_direct.parts_corners(whole, apply, unlit[rows], dtype)
    return out


def group_direct(surface, scene, result, triangles, deadline=None):
    """The per-source ``result``'s CornerDirect, each group's (G,T,3,3), at the corners of ``triangles``."""
    per_source = result.per_source
    return point_direct.corner_direct(surface, scene, triangles, seed=result.seed, light_group=per_source.light_group,
                                      patch_group=per_source.patch_group, groups=per_source.count, deadline=deadline,
                                      light=result.irradiance)


def _whole(parts):
    """The groups' (S,P,3) ``parts`` summed (0 stays 0)."""
    return parts if np.ndim(parts) == 0 else parts.sum(axis=0)


def _summed(direct):
    """The whole's CornerDirect of a per-group one (None stays None)."""
    return None if direct is None else point_direct.CornerDirect(direct.corners.sum(axis=0), direct.means.sum(axis=0))


def per_source_emission(scene, per_source):
    """(S,P,3) each group's own emitting patches' E (0 elsewhere)."""
    if per_source.patch_group is None:
        raise ValueError("the per-source results do not say which group each emitting patch is in (patch_group)")
    emission = np.zeros((per_source.count, scene.patch_count, 3))
    group = per_source.patch_group
    for s in range(per_source.count):
        emission[s] = np.where((group == s)[:, None], scene.emission, 0.0)
    return emission


