"""Per-source results and relighting: every source group's light from one solve, recombined.

Radiosity is linear in emission, channel by channel: the result for any strengths and colours
of the sources is sum_s w_s B_s, B_s the result of group s alone at the solve's strengths and
w_s (S,3) the new strength and colour over the solved ones. A per-source solve
(``solve(..., per_source=True)``) tallies each group's incident power apart from the same rays
(``grouping``); :class:`GroupBatches` sums them chunk by chunk, with what the error of any
recombination needs, and :func:`relight` recombines without tracing a ray.

The error of a recombination: the chunks are the batches (``batches``), and the groups' batch
means share paths, so the batch variance of sum_s w_s b_s is w^T V w, V the groups' batch
covariance. Its area-weighted mean over patches (the measured MSE) needs only, per channel,
M_st = sum_j W_j (sum_k I_sj^(k) I_tj^(k) / n_k - I_sj I_tj / N), W_j = (R_j Phi_T / A_j)^2 A_j / A_T:
(3,S,S) numbers, kept as the chunks come in. With every w_s = 1 it is the solve's own measured
MSE (to rounding).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..estimate.error_model import mean_reflected_radiosity
from ..display import point_direct
from . import relit_checks
from ..estimate.grouping import SourceGroups, check_per_source, source_groups


class GroupBatches:
    """The groups' incident power summed over chunks (S,C,P), with the cross sums of their batch
    covariance (C,S,S), weighted as the measured MSE weights patches."""

    def __init__(self, scene, tables, groups):
        C, P, S = tables.channels, scene.patch_count, groups.count
        self.groups, self.channels = groups, C
        self.incident = np.zeros((S, C, P))
        self.direct = None  # (S,C,P) of it straight from the sources, where chunks gather it apart
        self.cross = np.zeros((C, S, S))  # sum_k sum_j W_j I_sj^(k) I_tj^(k) / n_k
        self.lit = np.zeros(S, np.int64)  # the batches each group's light reached a reflecting patch in
        score = tables.reflectivity * (scene.total_power / scene.patch_area)  # (C,P)
        self.root_weight = score * np.sqrt(scene.patch_area / scene.total_area)  # sqrt(W_j)

    def add(self, tally):
        """Adds a chunk's ``incident_groups`` (S,C,P) of ``tally.paths`` paths."""
        self.incident += tally.incident_groups
        if tally.direct_groups is not None:
            self.direct = tally.direct_groups.copy() if self.direct is None else \
                np.add(self.direct, tally.direct_groups, out=self.direct)
        lit = np.zeros(self.groups.count, bool)
        for c in range(self.channels):
            x = tally.incident_groups[:, c] * self.root_weight[c]
            lit |= x.any(axis=1)
            # (einsum, not a BLAS product: OpenBLAS's threads would spin beside the walks' threads)
            self.cross[c] += np.einsum("sp,tp->st", x, x) / tally.paths
        self.lit += lit

    def spread(self, paths):
        """(C,S,S) M: the cross sums less those of the means, N (chunks - 1) times the batch
        covariance's area-weighted mean over patches."""
        spread = self.cross.copy()
        for c in range(self.channels):
            x = self.incident[:, c] * self.root_weight[c]
            spread[c] -= np.einsum("sp,tp->st", x, x) / paths
        return spread

    def results(self, scene, total, target_mse, measured_scale=False):
        """The PerSource of the run ``total`` (batches.Batches) made (``measured_scale``: with
        each group's own mean reflected radiosity, which its relit error is then relative to)."""
        S, N = self.groups.count, total.paths
        radiosity = np.empty((S, scene.patch_count, 3))
        irradiance = self.irradiance(scene, self.incident, N)
        patch_group = self.groups.patch_group(scene.patch_count)
        for s in range(S):
            radiosity[s] = scene.reflectivity * irradiance[s]
            radiosity[s] += np.where((patch_group == s)[:, None], scene.emission, 0.0)
        covariance = self.spread(N) / ((total.chunks - 1) * N) if total.chunks > 1 else np.full((self.channels, S, S), math.nan)
        direct = None if self.direct is None else self.irradiance(scene, self.direct, N)
        means = None
        if measured_scale:  # (area-weighted over patches: Batches.mean_reflected's, group by group)
            means = np.einsum("spc,pc,p->sc", irradiance, scene.reflectivity, scene.patch_area / scene.total_area)
        power = group_power(scene, self.groups)
        return PerSource(self.groups.names, radiosity, irradiance, power, covariance, scene_scale(scene), target_mse,
                         patch_group, self.groups.light_group, direct, means, self.lit.copy(),
                         relit_checks.power_share(power))

    def irradiance(self, scene, incident, paths):
        """(S,P,3) the irradiance of incident power (S,C,P) summed over ``paths`` paths."""
        out = np.zeros((incident.shape[0], scene.patch_count, 3))
        if paths:
            for c in range(3):
                out[:, :, c] = incident[:, c if self.channels == 3 else 0] * (scene.total_power / scene.patch_area) / paths
        return out


def group_power(scene, groups):
    """(S,3) the power of each group at the solve's strengths: its patches' A_i E_i and its
    lights' emitters'."""
    power = np.zeros((groups.count, 3))
    source_power = scene.source_power
    emitting = groups.source_group >= 0
    np.add.at(power, groups.source_group[emitting], source_power[emitting])
    return power


def scene_scale(scene):
    """b_ave per unit of Phi_T: what the relative RMS error is relative to, for any power."""
    R_ave = scene.average_reflectivity
    return mean_reflected_radiosity(1.0, scene.total_area, R_ave)


@dataclass
class PerSource:
    """A per-source solve's results: ``names`` (S,) of the groups; ``radiosity`` and
    ``irradiance`` (S,P,3) of each group alone at the solve's strengths (its emitting patches'
    E in its radiosity), summing to the solve's own over groups; ``power`` (S,3) each group's
    power; ``covariance`` (C,S,S) the area-weighted mean over patches of the groups' batch
    covariance of the reflected radiosity (C = 1 for a grey scene, whose channels are alike;
    NaN below 2 chunks); ``scale`` b_ave per unit of power; the solve's ``target_mse`` or None;
    ``patch_group`` (P,) int32 the group of each patch's own emission (-1: none), or None;
    ``light_group`` (L,) int32 the group of each light, or None."""

    names: tuple
    radiosity: np.ndarray
    irradiance: np.ndarray
    power: np.ndarray
    covariance: np.ndarray
    scale: float
    target_mse: float | None = None
    patch_group: np.ndarray | None = None
    light_group: np.ndarray | None = None
    direct_irradiance: np.ndarray | None = None  # (S,P,3) of ``irradiance`` straight from the sources, where gathered apart
    # (S,3) each group's area-weighted mean reflected radiosity, where the solve held its error to
    # its own mean (error_scale "measured"): the relit error is then relative to theirs recombined
    reflected_means: np.ndarray | None = None
    # (S,) the batches each group lit a reflecting patch in; (S,) its share of its solve's samples (relit_checks)
    lit_batches: np.ndarray | None = None
    sampled_share: np.ndarray | None = None

    @property
    def count(self):
        return len(self.names)

    def mse(self, weights):
        """The measured MSE of the reflected radiosity recombined with ``weights`` (S,3)."""
        weights = np.asarray(weights, np.float64)
        C = self.covariance.shape[0]
        return float(np.mean([weights[:, c] @ self.covariance[c if C == 3 else 0] @ weights[:, c] for c in range(3)]))

    def mean_reflected(self, weights):
        """What the relative RMS error is relative to at the powers ``weights`` give: the groups'
        own mean reflected radiosities recombined (``reflected_means``), else b_ave (``paper_mean``)."""
        if self.reflected_means is None:
            return self.paper_mean(weights)
        return float((np.asarray(weights, np.float64) * self.reflected_means).sum(axis=0).mean())

    def paper_mean(self, weights):
        """The paper's b_ave at the powers ``weights`` give (what ``target_mse`` was made relative to)."""
        return self.scale * float((np.asarray(weights, np.float64) * self.power).sum(axis=0).mean())


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
    if per_source.target_mse is not None:
        target = math.sqrt(per_source.target_mse) / per_source.paper_mean(np.ones_like(w))
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


def smooth_sources(surface, scene, result, light=False, dtype=np.float64, triangles=None, live=False, deadline=None):
    """Each source group's smooth colours, made as the solve's own are (the pipeline's smooth
    output) with the whole's noise-filter weights, clips and corner scales held fixed, so that
    they add up over the groups to the solve's (float error) and recombine as ``relight`` does:
    ("light", (S,T,3,3)) first with ``light``, the light arriving (``Surface.arriving_light``);
    then ("smooth", (S,T,3,3)), the reflected light filtered (``Surface.filter_light``) and
    smooth, plus each group's own emission, flat. Both show the direct light at the corners (``point_direct``), each group's own.
    ``surface`` is ``smoothing.Surface.of`` the scene's triangles (or ``triangles``, (T,3) of its
    vertices); ``result`` a per-source solve's SolveResult. Made in float64, given as ``dtype``
    (float32: half the memory, as they are written; their sum then the whole's to float32
    rounding). ``deadline``: the direct light's retries within it (``point_direct``)."""
    per_source = result.per_source
    if per_source is None:
        raise ValueError("the solve has no per-source results: solve with per_source=True")
    triangles = scene.triangles if triangles is None else triangles
    if light:  # (the noise filters first, as the pipeline's: with the direct light's corners held, the peak)
        irradiance, total = per_source.irradiance, result.irradiance
        if live:  # (the lamps', suns', emitters' and world's direct light left to the renderer: point_direct.light_corners)
            drawn = per_source.direct_irradiance  # (the solve's own: point_direct.live_light)
            if drawn is None:
                drawn = point_direct.live_means(scene, seed=result.seed, light=total, light_group=per_source.light_group,
                                                patch_group=per_source.patch_group, groups=per_source.count,
                                                deadline=deadline)
            irradiance, total = irradiance - drawn, total - drawn.sum(axis=0)
        arriving, fill = surface.arriving_light(total, result.irradiance_variance, scene.reflectivity,
                                                return_filter=True)
    filtered, noise = surface.filter_light(result.reflected, result.reflected_variance, return_filter=True)
    direct = point_direct.corner_direct(surface, scene, triangles,
                                        seed=result.seed, light_group=per_source.light_group,
                                        patch_group=per_source.patch_group, groups=per_source.count, deadline=deadline)
    whole = _summed(direct)
    if light:
        shaped, shaped_whole = (None, None) if live else (direct, whole)
        yield "light", point_direct.shown(surface, arriving, shaped_whole, fill(irradiance), shaped, dtype)[1]
    rho = scene.reflectivity
    _, smooth = point_direct.shown(surface, filtered, whole and point_direct.scaled(surface, whole, rho),
                                       noise(per_source.irradiance * rho), direct and point_direct.scaled(surface, direct, rho), dtype)
    emitting = per_source_emission(scene, per_source)
    for s in range(per_source.count):  # (a part at a time: no (S,T,3) copy)
        smooth[s] += emitting[s, surface.triangle_patch][:, None, :]
    yield "smooth", smooth


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


def resolve(scene, per_source, names, **solve_kwargs):
    """``per_source`` with the groups ``names`` re-solved on ``scene`` (a lamp moved, reshaped,
    re-angled or added: the scene as it is now, on the same patches) and the others kept as they
    are: a PerSource of the scene's groups (``solve_kwargs["groups"]``, default
    ``source_groups(scene)``), in their order. The re-solve traces only the named groups' sources
    (every other light and emitting patch left out) with ``solve_kwargs`` (paths or target_mse,
    method, seed, ...; a target applies to the named groups' light alone); it is independent of
    the kept groups' run (give it a seed of its own), so their covariance is 0. A group of the
    solve the scene no longer has (a lamp deleted) is left out. ValueError in one line for a
    name the scene's groups do not have, a group the solve did not have that is not named, or
    other patches (geometry changed: solve again)."""
    from .. import solver  # (the solver's batches use this module)

    groups = solve_kwargs.pop("groups", None)
    groups = source_groups(scene) if groups is None else groups
    check_per_source(scene, groups)
    names = (names,) if isinstance(names, str) else tuple(names)
    unknown = [n for n in names if n not in groups.names]
    if unknown:
        raise ValueError(f"no source group named {', '.join(map(repr, unknown))}; "
                         f"the groups are {', '.join(map(repr, groups.names))}")
    if per_source.radiosity.shape[1] != scene.patch_count:
        raise ValueError(f"the per-source results are of {per_source.radiosity.shape[1]:,} patches, the scene has "
                         f"{scene.patch_count:,}: the geometry changed, solve again")
    missing = [n for n in groups.names if n not in names and n not in per_source.names]
    if missing:
        raise ValueError(f"source groups {', '.join(map(repr, missing))} are new: name them to be solved")
    solve_kwargs.pop("per_source", None)
    new = [groups.names.index(n) for n in dict.fromkeys(names)]
    sub = _named_sources(scene, groups, new)
    if sub is None:  # the named groups give no light now: their results are nothing
        redone = _dark(scene.patch_count, len(new), per_source.covariance.shape[0])
    else:
        sub_scene, sub_groups = sub
        redone = solver.solve(sub_scene, per_source=True, groups=SourceGroups(*sub_groups), **solve_kwargs).per_source
    return _joined(scene, groups, per_source, new, redone)


def _named_sources(scene, groups, new):
    """(a scene of only the groups ``new``'s sources, its SourceGroups' fields), or None where
    they give no power."""
    P = scene.patch_count
    local = np.full(groups.count, -1, np.int32)
    local[new] = np.arange(len(new), dtype=np.int32)
    own = groups.patch_group(P)
    patch_group = np.where(own >= 0, local.take(np.maximum(own, 0)), -1).astype(np.int32)
    emission = np.where((patch_group >= 0)[:, None], scene.emission, 0.0)
    light_group = local.take(groups.light_group) if len(groups.light_group) else np.zeros(0, np.int32)
    lights = [light for light, g in zip(scene.lights.lights, light_group) if g >= 0]
    power = emission.any() or any(np.any(light_power > 0) for light_power, g in
                                  zip(_light_powers(scene), light_group) if g >= 0)
    if not power:
        return None
    sub = scene.with_materials(scene.reflectivity, emission, lights)
    kept = light_group[light_group >= 0]
    light_sources = kept.take(sub.lights.light_of) if len(kept) else np.zeros(0, np.int32)
    source_group = np.concatenate([patch_group, light_sources])
    return sub, (tuple(groups.names[g] for g in new), source_group.astype(np.int32), kept.astype(np.int32))


def _light_powers(scene):
    """(L,3) each light's emitters' power summed."""
    out = np.zeros((len(scene.lights), 3))
    if len(scene.lights):
        np.add.at(out, scene.lights.light_of, scene.lights.power)
    return out


def _dark(P, S, C):
    """A PerSource of S groups that give no light."""
    zeros = np.zeros((S, P, 3))
    return PerSource(("",) * S, zeros, zeros.copy(), np.zeros((S, 3)), np.zeros((C, S, S)), math.nan,
                     lit_batches=np.zeros(S, np.int64), sampled_share=np.zeros(S))


def _joined(scene, groups, per_source, new, redone):
    """The PerSource of ``groups``: the rows ``new`` from ``redone``, the rest from ``per_source``."""
    S, P = groups.count, scene.patch_count
    source = {g: ("new", k) for k, g in enumerate(new)}
    source.update({g: ("old", per_source.names.index(n)) for g, n in enumerate(groups.names) if g not in source})
    C = max(per_source.covariance.shape[0], redone.covariance.shape[0])
    old_cov = np.broadcast_to(per_source.covariance, (C,) + per_source.covariance.shape[1:])
    new_cov = np.broadcast_to(redone.covariance, (C,) + redone.covariance.shape[1:])
    radiosity = np.empty((S, P, 3), per_source.radiosity.dtype)
    irradiance = np.empty((S, P, 3), per_source.irradiance.dtype)
    power = np.empty((S, 3))
    covariance = np.zeros((C, S, S))
    means = None if per_source.reflected_means is None or redone.reflected_means is None else np.empty((S, 3))
    counted = per_source.lit_batches is not None and per_source.sampled_share is not None
    lit, sampled = (np.zeros(S, np.int64), np.zeros(S)) if counted else (None, None)
    for g, (kind, k) in source.items():
        ps = redone if kind == "new" else per_source
        radiosity[g], irradiance[g], power[g] = ps.radiosity[k], ps.irradiance[k], ps.power[k]
        if means is not None:
            means[g] = ps.reflected_means[k]
        if counted:  # (each its own run's: a re-solved group's share is of the re-solve's samples)
            lit[g], sampled[g] = ps.lit_batches[k], ps.sampled_share[k]
        for h, (other, m) in source.items():
            if other == kind:  # (independent runs: no covariance across them)
                covariance[:, g, h] = (new_cov if kind == "new" else old_cov)[:, k, m]
    target, before = per_source.target_mse, per_source.power.mean(axis=1).sum()
    if target is not None and before > 0:  # (the same relative error of the light as it is now: its power moved)
        target *= (power.mean(axis=1).sum() / before) ** 2
    return PerSource(groups.names, radiosity, irradiance, power, covariance, scene_scale(scene), target,
                     groups.patch_group(P).copy(), np.asarray(groups.light_group, np.int32), reflected_means=means,
                     lit_batches=lit, sampled_share=sampled)
