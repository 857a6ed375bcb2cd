"""Stochastic Jacobi iteration with incremental shooting: the light shot generation by generation.

Beyond the paper. A chunk of n "paths" starts as the walk does: n first rays from the
sources, drawn in proportion to power, each carrying the relative weight 1 (Phi_T / n of power).
The power incident on each patch in one generation is scored, and the part the patches reflect,
U_j = R_j I_j, is the next generation's unshot power. It is shot again from the patches as a
whole: about sum(U) rays (the same quantum, weight 1, as a first ray), allotted to patches in
proportion to U by systematic sampling and leaving each patch from Halton points (bases 2, 3 for
the point, 5, 7 for the cosine direction), shifted by one random vector a generation
(Cranley-Patterson). A patch then sheds what it reflects in floor or ceil of its share of rays,
from evenly spread points and directions, where a walk's survivors leave it in a random number
of rays from random ones: the same expectation, less noise.

    shoot       the generation's rays: from the sources (generation 0) or from the patches,
                in proportion to their unshot power
    intersect   the ray tracer: what each ray meets first (rays.cast)
    score       the power arriving at each front side hit: the generation's incident power
    reflect     U_j = R_j I_j, the next generation's unshot power; below one ray's weight in
                all, Russian roulette: one ray of weight 1 with probability sum(U), else the end

Each generation's rays are, given the previous generation, an unbiased estimate of the light it
transports (E[count_j] times the ray weight is U_j), so the chunk's total is unbiased; chunks
are independent, and the solve's batch means measure the error. The power accounts balance
exactly as the walk's do: what arrives at a patch is absorbed there but for what leaves it.

Its plan and its direct light (shot, or gathered by shadow rays) are the gathered walk's
(``methods.walk``): the paper's formulas do not predict its error, which is measured. Small
chunks are traced together, a generation of every chunk in one wavefront, up to
GROUP_PATHS_JACOBI first rays a group.
"""
from __future__ import annotations

import numpy as np

from ..scene import rays
from ..mesh.faces import ranks_in_runs
from ..lights.sampling import HALTON, draw_sources, shifted_float32, systematic_counts
from ..estimate.grouping import with_groups
from ..estimate.tallies import ChunkTally, chunk_counts, chunk_sums
from ..names import JACOBI
from .base import Integrator, check
from .tables import chunk_wide
from .walk import Walk, chunks_per_group

# A group's wavefront is a generation, whose first has a ray a path: chunks go together up to
# this many first rays in a group.
GROUP_PATHS_JACOBI = 1 << 16


class Jacobi(Walk):
    """Shooting stochastic Jacobi iteration."""

    name = JACOBI

    @property
    def predicted(self):
        return False

    def shot(self, tables):
        return ShotJacobi(tables)

    @staticmethod
    def one_chunk(tables, paths, rng, abort):
        return jacobi_one(tables, paths, rng, abort)


class ShotJacobi(Integrator):
    """Stochastic Jacobi iteration from the sources: its tables alone."""

    def group(self, chunk_paths, expected_path_length):
        return chunks_per_group(self.tables, chunk_paths, GROUP_PATHS_JACOBI)

    def run(self, sizes, rng, abort=None):
        sizes = [int(n) for n in sizes]
        tables = chunk_wide(self.tables, sum(sizes))
        with tables.numpy_turn:
            return jacobi_chunks(tables, sizes, rng, lambda: check(abort))


def jacobi_one(tables, paths, rng, abort):
    """One chunk of Jacobi iteration (from the sources ``tables`` has)."""
    return jacobi_chunk(tables, paths, rng, lambda: check(abort))


def shoot_from_patches(tables, unshot, rng, groups=1):
    """A generation's rays from the patches, for a group of G chunks: ``unshot`` (C,G,P)
    relative power (per source, (S C,G,P): each of ``groups`` groups' channels). Each chunk
    with more than one ray's weight of it shoots about that many rays of equal weight; one with
    less plays Russian roulette (one ray of weight 1 with probability its unshot power, else its
    end). Returns (patch, chunk, weights (C,m), leaving (G,C), origins, directions), the rays
    in chunk order, or None once every chunk has ended."""
    C, G, P = unshot.shape
    whole = unshot if groups == 1 else unshot.reshape(groups, C // groups, G, P).sum(axis=0)  # (the groups' sum)
    power = whole[0] if whole.shape[0] == 1 else whole.mean(axis=0)  # (G,P) what a ray's weight counts
    total = power.sum(axis=1)
    roulette, shift, corner = rng.random(G), rng.random(G), rng.random((G, 4))  # drawn alike, always
    rays_of = np.where(total >= 1.0, np.rint(total), (total > 0) & (roulette < total)).astype(np.int64)
    if not rays_of.any():
        return None
    scale = np.where(total >= 1.0, total / np.maximum(rays_of, 1), 1.0)  # each ray's weight
    counts = np.zeros((G, P), dtype=np.int64)
    for g in np.flatnonzero(rays_of):
        counts[g] = systematic_counts(power[g], int(rays_of[g]), shift[g])
    cell = np.repeat(np.arange(G * P, dtype=np.int64), counts.ravel())
    chunk = (cell // P).astype(np.int32)
    patch = (cell - chunk.astype(np.int64) * P).astype(np.int32)
    # Ray k of a chunk: (k + shift) / m chose its patch, Halton point k its point and direction:
    # a 5-D Hammersley set over the chunk's generation (each patch's rays a run of it).
    index = ranks_in_runs(rays_of)
    points = HALTON.rows(int(rays_of.max())).take(index, axis=1)
    points += corner.T.take(chunk, axis=1)
    u = np.empty((tables.uniforms_per_ray, cell.size), dtype=np.float32)
    u[:4] = shifted_float32(points)
    if tables.row_triangle is not None:
        rng.random(dtype=np.float32, out=u[tables.row_triangle])
    origins, directions = rays.leave_random(tables, patch, u)
    weights = scale.take(chunk)[None]
    if C > 1:
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(power > 0, unshot / power, 0.0)  # (C,G,P) U_jc / U_bar_j (a group's)
        weights = ratio.reshape(C, G * P).take(cell, axis=1) * weights
    return patch, chunk, weights, chunk_sums(weights, chunk, G), origins, directions


def jacobi_chunks(tables, sizes, rng, check=None):
    """Chunks of stochastic Jacobi iteration from ``sizes`` first rays each, traced together
    (each generation's rays of every chunk in one wavefront); returns each chunk's ChunkTally
    in the walk's relative weights (times Phi_T / N). ``check()`` is called every generation
    (it raises to stop). Per source, each first ray carries its source's group, and every
    later ray each group's share of what it carries (S C weights: the light passes on linearly)."""
    C, P, G = tables.channels, tables.patch_count, len(sizes)
    S = 1 if tables.groups is None else tables.groups.count
    source, chunk, first = draw_sources(tables.sources, sizes, rng, tables.stratified)
    group, part = _first_groups(tables, source, rng)
    u = rng.random((tables.uniforms_per_ray, source.size), dtype=np.float32)
    if first is not None:
        u[:4] = first
    origins, directions = rays.leave_sources(tables, source, u)
    region = rays.region_of(tables, source)
    chunk = np.zeros(source.size, dtype=np.int32) if chunk is None else chunk
    weights = np.ones((1, source.size)) if C == 1 else tables.start_weight(source, part)
    emitted = chunk_sums(weights, chunk, G)
    incident = np.zeros((S * C, G * P))
    absorbed, escaped, blocked = (np.zeros((G, C)) for _ in range(3))
    ray_count, generations = np.zeros(G, dtype=np.int64), np.zeros(G, dtype=np.int64)
    R = np.tile(tables.reflectivity, (S, 1))[:, None, :]
    while True:
        if check is not None:
            check()
        hits = rays.cast(tables, origins, directions, region)
        traced = chunk_counts(chunk, G)
        ray_count += traced
        generations += traced > 0
        front = np.flatnonzero(hits.front)
        cell = chunk.take(front) * np.int64(P) + hits.patch.take(front)
        arrived = _arrived(weights, front, cell, G * P, group, S)
        group = None  # (from the second generation on, every ray carries every group)
        incident += arrived
        missed = hits.hit < 0
        back = ~missed & ~hits.front
        escaped += _by_channel(chunk_sums(weights.compress(missed, axis=1), chunk.compress(missed), G), C)
        blocked += _by_channel(chunk_sums(weights.compress(back, axis=1), chunk.compress(back), G), C)
        arrived = arrived.reshape(S * C, G, P)
        unshot = arrived * R
        reflected = unshot.sum(axis=2).T  # (G,C)
        absorbed += _by_channel(arrived.sum(axis=2).T - reflected, C)
        shot = shoot_from_patches(tables, unshot, rng, S)
        if shot is None:
            absorbed += _by_channel(reflected, C)  # (the roulette's end: nothing leaves)
            break
        patch, chunk, weights, leaving, origins, directions = shot
        region = tables.geometry.region_of(patch)
        absorbed += _by_channel(reflected - leaving, C)  # what leaves beyond what was reflected: the roulette's, either sign
    return _tallies(sizes, incident.reshape(S, C, G, P), ray_count, emitted, absorbed, escaped, blocked, generations,
                    tables.groups is not None)


def _first_groups(tables, source, rng):
    """(group, part) of each first ray's source (None, None without per-source results)."""
    if tables.groups is None:
        return None, None
    if tables.groups.mix is None:
        return tables.groups.source_group.take(source), None
    return tables.groups.mix.draw(source, rng.random(source.size))


def _arrived(weights, front, cell, cells, group, S):
    """(S C, cells) the weight arriving at each chunk's patches (``cell``) from the rays that
    met a front (``front``): by their ``group`` (the first generation's, per source), else by
    the rows of ``weights`` (C or S C)."""
    every = front.size == weights.shape[1]  # (every ray met a front, as in a closed room: no copies)
    if group is None:
        return np.stack([np.bincount(cell, weights=w if every else w.take(front), minlength=cells) for w in weights])
    key = group.take(front) * np.int64(cells) + cell
    by_group = np.stack([np.bincount(key, weights=w if every else w.take(front), minlength=S * cells) for w in weights])
    return by_group.reshape(len(weights), S, cells).transpose(1, 0, 2).reshape(S * len(weights), cells)


def _by_channel(values, C):
    """(G,C) of (G, S C) per-group accounts: their sum over the groups."""
    return values if values.shape[1] == C else values.reshape(values.shape[0], -1, C).sum(axis=1)


def _tallies(sizes, incident, ray_count, emitted, absorbed, escaped, blocked, generations, grouped):
    """Each chunk's ChunkTally from (S,C,G,P) ``incident`` and the (G,...) accounts."""
    tallies = []
    for g, n in enumerate(sizes):
        tally = ChunkTally(n, int(ray_count[g]), incident[0, :, g].copy(), emitted[g], absorbed[g], escaped[g],
                           blocked[g], np.zeros(incident.shape[1]), {"generations": int(generations[g])})
        tallies.append(with_groups(tally, incident[:, :, g].copy()) if grouped else tally)
    return tallies


def jacobi_chunk(tables, paths, rng, check=None):
    """One chunk of :func:`jacobi_chunks`."""
    return jacobi_chunks(tables, [paths], rng, check)[0]
