"""The two shooting random walk estimators of Sbert & Brusi, advanced as a wavefront.

Every path of a batch ("chunk") advances one bounce per step: the live paths' rays go to the
ray tracer together, and their scores accumulate with ``np.bincount``.

Weights are relative: a path from source i starts with per-channel weight E_ic / E_bar_i (1 in a
grey scene), and the true carried power is that weight times Phi_T / N. What a chunk tallies is
the power *incident* on each patch's front side, I_j; the reflected radiosity is
b_j = R_j I_j (Phi_T / N) / A_j.

- ``finite`` (the paper's Phi_T estimator): the carried power never changes; each hit scores,
  then the path survives with probability R_bar_j (the patch's mean reflectivity). In colour,
  survivors multiply each channel by R_jc / R_bar_j, so every channel stays unbiased.
- ``biased_infinite``: each hit scores, the carried power is multiplied by R_jc, and the path
  goes on until the product of (mean) reflectivities along it falls below the threshold t.
  The power still carried at that moment is "undistributed".

Rays that hit nothing escape; rays that hit a patch's back side are absorbed there ("blocked"):
radiosity leaves only the front side of a patch.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .sampling import SourceTable, cosine_directions, points_at_barycentric, points_on_patches

FINITE = "finite"
BIASED_INFINITE = "biased_infinite"
ESTIMATORS = (FINITE, BIASED_INFINITE)
EXIT_RANDOM = "random"
EXIT_HIT = "hit"
EXIT_POINTS = (EXIT_RANDOM, EXIT_HIT)


class WalkTables:
    """Per-solve tables: materials in the layouts the walk reads, shared by all chunks."""

    def __init__(self, scene, estimator, threshold, exit_point, stratified=False):
        self.geometry = scene.geometry
        self.tracer = scene.tracer
        self.estimator = estimator
        self.threshold = float(threshold)
        self.exit_random = exit_point == EXIT_RANDOM
        self.stratified = bool(stratified)
        self.patch_count = scene.patch_count
        self.sources = SourceTable(scene.patch_area, scene.emission)
        R = scene.reflectivity
        self.mean_reflectivity = scene.mean_reflectivity  # R_bar (P,)
        # Grey scenes carry one channel; colour scenes three.
        self.channels = 1 if scene.is_grey else 3
        self.reflectivity = np.ascontiguousarray(R[:, : self.channels].T)  # (C,P)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(self.mean_reflectivity > 0, R.T / self.mean_reflectivity, 0.0)
            mean_emission = scene.emission.mean(axis=1)
            start = np.where(mean_emission > 0, scene.emission.T / mean_emission, 0.0)
        self.survivor_weight = np.ascontiguousarray(ratio[: self.channels])  # R_jc / R_bar_j (C,P)
        self.start_weight = np.ascontiguousarray(start[: self.channels])      # E_ic / E_bar_i (C,P)
        # float32 uniforms per ray: point (2), direction (2), then a triangle choice unless every
        # patch is a parallelogram. The finite estimator's survival test draws float64 (a float32
        # draw would quantise the survival probability to multiples of 2^-24: a relative bias
        # of up to 2^-24 / (1 - R) in 1 - R, 0.6% at R = 0.99999).
        self.uniforms_per_ray = 4
        self.row_triangle = None
        if not self.geometry.all_parallelograms:
            self.row_triangle = self.uniforms_per_ray
            self.uniforms_per_ray += 1
        # In a grey finite walk every weight stays exactly 1: no weight arrays at all. In a grey
        # biased walk the weight is the product of reflectivities, which is the product of mean
        # reflectivities the threshold test keeps anyway (exactly: R_bar = R in grey): one array.
        self.unit_weights = estimator == FINITE and self.channels == 1
        self.weight_is_accumulated = estimator != FINITE and self.channels == 1


@dataclass
class ChunkTally:
    """What one batch of paths produced, in relative weights (multiply by Phi_T / N)."""

    paths: int
    rays: int
    incident: np.ndarray                 # (C,P) power incident on each patch's front side
    emitted: np.ndarray                  # (C,) total starting weight
    escaped: np.ndarray                  # (C,) carried by rays that hit nothing
    blocked: np.ndarray                  # (C,) carried by rays that hit a back side
    undistributed: np.ndarray            # (C,) left on paths cut by the threshold
    ended: dict = field(default_factory=dict)  # path counts by how they ended


class Aborted(Exception):
    """The walk was asked to stop; its partial chunk is discarded."""


def _weight_sum(weights, mask):
    """Sum of the carried weights of the masked paths, per channel (a product with the
    boolean mask: no copy of the selected columns)."""
    if weights is None:
        return np.array([float(np.count_nonzero(mask))])
    return np.einsum("cn,n->c", weights, mask)


def walk_chunk(tables: WalkTables, paths: int, rng: np.random.Generator, abort=None) -> ChunkTally:
    """Trace ``paths`` random walks from the sources to their end; return their tallies."""
    g = tables.geometry
    C, P = tables.channels, tables.patch_count
    finite = tables.estimator == FINITE
    scored_patches, scored_weights = [], []  # per step; one bincount per chunk at the end
    escaped = np.zeros(C)
    blocked = np.zeros(C)
    undistributed = np.zeros(C)
    ended = {"escaped": 0, "blocked": 0, "absorbed": 0, "threshold": 0}

    first_step = True
    if tables.stratified:
        patch, first_uniforms = tables.sources.stratified(paths, rng)
    else:
        patch = tables.sources.choose(rng.random(paths))
    accumulated = np.ones(paths) if not finite else None  # product of R_bar along the path
    if tables.unit_weights:
        weights = None
    elif tables.weight_is_accumulated:
        weights = accumulated[None]  # a view: (1,n)
    else:
        weights = np.take(tables.start_weight, patch, axis=1)
    emitted = weights.sum(axis=1) if weights is not None else np.array([float(paths)])
    leave_from = None  # hit points, for exit_point="hit"
    rays = 0
    n = paths
    while n:
        if abort is not None and abort.is_set():
            raise Aborted
        u = rng.random((tables.uniforms_per_ray, n), dtype=np.float32)
        u_survive = rng.random(n) if finite else None
        if first_step and tables.stratified:
            u[:4] = first_uniforms  # the first ray: a randomly shifted low-discrepancy set
        first_step = False
        if leave_from is None:
            u_triangle = None if tables.row_triangle is None else u[tables.row_triangle]
            origins = points_on_patches(g, patch, u_triangle, u[0], u[1])
        else:
            origins = leave_from
        directions = cosine_directions(g, patch, u[2], u[3], normalize=False)
        if tables.exit_random:
            hit = tables.tracer.first_hit(origins, directions)
            # A miss (-1) gathers the last triangle's normal: harmless, masked out by ``missed``.
            hit_normal = np.take(g.triangle_normal, hit, axis=0)
        else:
            hit, bary_u, bary_v, hit_normal = tables.tracer.first_hit_barycentric(origins, directions)
        rays += n

        missed = hit < 0
        facing = np.einsum("ij,ij->i", directions, hit_normal) < 0
        front = facing & ~missed
        if not front.all():
            back = ~missed & ~facing
            n_missed, n_back = int(np.count_nonzero(missed)), int(np.count_nonzero(back))
            if n_missed:
                escaped += _weight_sum(weights, missed)
                ended["escaped"] += n_missed
            if n_back:
                blocked += _weight_sum(weights, back)
                ended["blocked"] += n_back
            keep = np.flatnonzero(front)
            hit = hit[keep]
            u_survive = u_survive[keep] if finite else None
            if accumulated is not None:
                accumulated = accumulated[keep]
            if tables.weight_is_accumulated:
                weights = accumulated[None]
            elif weights is not None:
                weights = np.take(weights, keep, axis=1)
            if not tables.exit_random:
                bary_u, bary_v = bary_u[keep], bary_v[keep]
        if hit.size == 0:
            break
        hit_triangle = hit
        patch = g.triangle_patch[hit_triangle]

        # Score: the power arriving at the hit patch.
        scored_patches.append(patch)
        if weights is not None:
            scored_weights.append(weights)

        if finite:
            survive = u_survive < tables.mean_reflectivity[patch]
            ended["absorbed"] += int(survive.size - np.count_nonzero(survive))
            go_on = np.flatnonzero(survive)
            patch = patch[go_on]
            if not tables.exit_random:  # only a hit-point exit needs the triangle again
                hit_triangle = hit_triangle[go_on]
            if weights is not None:
                weights = np.take(weights, go_on, axis=1) * np.take(tables.survivor_weight, patch, axis=1)
        else:
            # New arrays, never in place: the weights just scored may be a view of ``accumulated``.
            accumulated = accumulated * tables.mean_reflectivity[patch]
            if tables.weight_is_accumulated:
                weights = accumulated[None]
            else:
                weights = weights * np.take(tables.reflectivity, patch, axis=1)
            cut = accumulated < tables.threshold
            if cut.any():
                undistributed += _weight_sum(weights, cut)
                ended["threshold"] += int(np.count_nonzero(cut))
                go_on = np.flatnonzero(~cut)
                patch = patch[go_on]
                if not tables.exit_random:
                    hit_triangle = hit_triangle[go_on]
                accumulated = accumulated[go_on]
                weights = accumulated[None] if tables.weight_is_accumulated else np.take(weights, go_on, axis=1)
            else:
                go_on = slice(None)

        if not tables.exit_random:
            # Leave from the hit point, re-made from its barycentric coordinates on the
            # triangle's leaving frame: on the surface (inset, pushed off), whatever the distance.
            if not isinstance(go_on, slice):
                bary_u, bary_v = bary_u[go_on], bary_v[go_on]
            leave_from = points_at_barycentric(g, hit_triangle, bary_u, bary_v)
        n = patch.size

    patches = np.concatenate(scored_patches) if scored_patches else np.zeros(0, np.int32)
    if tables.unit_weights:
        incident = np.bincount(patches, minlength=P)[None].astype(np.float64)
    else:
        w = np.concatenate(scored_weights, axis=1) if scored_weights else np.zeros((C, 0))
        incident = np.stack([np.bincount(patches, weights=w[c], minlength=P) for c in range(C)])
    return ChunkTally(
        paths=paths,
        rays=rays,
        incident=incident,
        emitted=emitted,
        escaped=escaped,
        blocked=blocked,
        undistributed=undistributed,
        ended=ended,
    )
