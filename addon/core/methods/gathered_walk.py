"""The walk from gathered direct light: what the first shot found, reflected, as the walk's sources.

The gathering (:mod:`.first_shot`) gives each patch j its direct irradiance H_j; the walk then
shoots only what that light reflects, E'_j = R_j H_j, and adds every later bounce. Leaving from
uniform points (random exit), patch j is a source of emittance E'_j; leaving from hit points,
each gathering sample is a point source of what it found (:class:`ReflectedPoints`), so that the
first reflection is as uneven over a patch as the light that lands on it.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .first_shot import gather_direct
from ..materials.glossy import reflect
from ..lights.sampling import SourceTable, add_sphere_points, channel_sum, source_weights
from ..estimate.grouping import Mix, with_groups
from ..estimate.tallies import ChunkTally


class ReflectedPoints:
    """The gathering samples as the walk's light sources (leaving from hit points): sample k,
    at point x_k of patch j, reflects R_j A_j / n_j times the irradiance it found (``power``
    (K,3), in the walk's source table after the patches), in cosine-distributed directions
    about the patch's normal. Their sum over patch j's samples is A_j E'_j. Points and normals
    stay in the walk's unit space, float32 (the points already pushed off the surface).

    Where the scene has a glossy lobe (:mod:`.glossy`) and the samples kept their rays' parts
    and directions, the glossy share of each part leaves along its lobe instead: it is taken out
    of sample k's row and becomes a row of its own after the K (``glossy_rows``; the shadow
    rays' parts, then the cosine rays'), only for the parts that have some (their directions
    drawn from a generator of their own, seeded from the chunk's ``rng``). ``count`` is K."""

    def __init__(self, gathering, geometry, samples, rng):
        patch, x, value = samples[:3]
        factor = gathering.reflectivity * gathering.area_per_sample  # R_j A_j / n_j
        self.factor = factor.take(patch, axis=1)  # (3,K) each sample's (its parts' too: _part_power)
        self.shine = None  # (3,K) each sample's glossy share times A / n (where there is a lobe)
        power = value * self.factor
        self.count = patch.size
        self.sample = None  # each row's sample (None: row k is sample k, no glossy rows)
        lobe = samples[3] if len(samples) > 3 else None
        if lobe is not None:
            parts, directions = lobe
            shine = self.shine = self._shine(gathering, patch)
            kept, rows = [], [power]
            self.row_of = np.full((2, self.count), -1)  # each part's glossy row (-1: none)
            for m in range(2):
                glossy = parts[m] * shine
                power -= glossy
                keep = np.flatnonzero(glossy.max(axis=0) > 0)
                self.row_of[m, keep] = self.count + sum(k.size for k in kept) + np.arange(keep.size)
                kept.append(keep)
                rows.append(glossy.take(keep, axis=1))
            np.maximum(power, 0.0, out=power)  # (R value - g parts >= 0 but for rounding)
            self.sample = np.concatenate([np.arange(self.count), *kept])
            self.towards = np.hstack([directions[m].take(k, axis=1) for m, k in enumerate(kept)])
            self.alpha = gathering.glossy.alpha.take(patch.take(self.sample[self.count:]))
            self.rng = np.random.default_rng(rng.integers(1 << 63))
            power = np.hstack(rows)
        self.rows = power  # (3,N) (the two-way iteration reads it so; the walk reads ``power``)
        self._power = None
        self.patch = patch
        self.points = np.asarray(x, dtype=np.float32)
        self.normals = geometry.patch_normal_rows.take(patch, axis=1)

    @property
    def power(self):
        """(N,3) each row's power (the walk's source table reads it so)."""
        if self._power is None:
            self._power = np.ascontiguousarray(self.rows.T)
        return self._power

    @staticmethod
    def _shine(gathering, patch):
        """(3,K) g_j A_j / n_j of each sample: what its parts' glossy share is."""
        return (gathering.glossy.share.T * gathering.area_per_sample).take(patch, axis=1)

    @property
    def glossy_rows(self):
        """(G,) the rows of the glossy shares (none: an empty array)."""
        return np.arange(self.count, self.rows.shape[1])

    def samples_of(self, rows):
        """(n,) the sample each of ``rows`` leaves from."""
        return rows if self.sample is None else self.sample.take(rows)

    def unit_rays(self, rows, u, geometry):
        """Rays from rows ``rows`` with uniforms ``u`` (4, n) float32 (directions from u[2:4],
        as a patch's: normal plus a uniform sphere point; a glossy row's along its lobe about the
        mirror of where its light came from, glossy.reflect, from the rows' own generator):
        (3, n) unit-space origins, directions, as :meth:`.lights.Lights.unit_rays` gives them
        (the points are in unit space already: ``geometry`` is not read)."""
        k = self.samples_of(rows)
        directions = add_sphere_points(self.normals.take(k, axis=1), u[2], u[3])
        if self.sample is not None:
            lobe = np.flatnonzero(rows >= self.count)
            if lobe.size:
                g = rows.take(lobe) - self.count
                directions[:, lobe] = reflect(self.normals.take(k.take(lobe), axis=1), self.towards.take(g, axis=1),
                                              self.alpha.take(g), self.rng)
        return self.points.take(k, axis=1), directions

    def regions(self, rows, geometry):
        """(n,) the region frame of rows ``rows``' points (their patches'), or None."""
        return geometry.region_of(self.patch.take(self.samples_of(rows)))

    def _part_power(self, gathering, parts, channels=3):
        """((2,C,K) each part's diffuse power, (2,C,K) its glossy power or None): a sample's
        shadow and cosine parts (grouping.SampleParts) times R A / n less their glossy share."""
        power = parts.value[:, :channels] * self.factor[:channels]
        if self.sample is None:
            return power, None
        glossy = parts.value[:, :channels] * self.shine[:channels]
        return np.maximum(power - glossy, 0.0), glossy

    def group_power(self, gathering, parts, S, C):
        """(S C,K) each source group's part of every sample's diffuse power (per-source results):
        a sample's shadow and cosine parts each in its group; and (G,) the group of each glossy
        row (its part's; None without a lobe)."""
        diffuse, _ = self._part_power(gathering, parts, C)
        K = self.count
        power = np.empty((S, C, K))
        # (a count a channel by (group, sample), the shadow parts then the cosine parts: the sums
        # of adding them in turn, where indexing by (group, :, sample) took numpy's slow mixed path)
        found = [np.flatnonzero(g >= 0) for g in parts.group]
        key = np.concatenate([parts.group[m].take(f).astype(np.intp) * K + f for m, f in enumerate(found)])
        for c in range(C):
            weights = np.concatenate([diffuse[m, c].take(f) for m, f in enumerate(found)])
            power[:, c] = np.bincount(key, weights=weights, minlength=S * K).reshape(S, K)
        power = power.reshape(S * C, K)
        if self.sample is None:
            return power, None
        group = np.full(self.rows.shape[1] - K, -1, dtype=np.int32)
        for m in range(2):
            there = np.flatnonzero(self.row_of[m] >= 0)
            group[self.row_of[m].take(there) - K] = parts.group[m].take(there)
        return power, group

    def mix(self, gathering, parts, offset):
        """The rows as a walk's sources of ids from ``offset`` on, each a grouping.Mix of its
        shadow and cosine parts (a glossy row: its share of its part alone)."""
        diffuse, glossy = self._part_power(gathering, parts)
        group = np.maximum(parts.group, 0)
        if glossy is None:
            return Mix(offset, group, np.ascontiguousarray(diffuse.transpose(0, 2, 1)))
        G = self.rows.shape[1] - self.count
        lobe_group, lobe = np.zeros((2, G), dtype=group.dtype), np.zeros((2, 3, G))
        for m in range(2):
            at = np.flatnonzero(self.row_of[m] >= 0)
            lobe_group[0, self.row_of[m, at] - self.count] = group[m, at]
            lobe[0][:, self.row_of[m, at] - self.count] = glossy[m][:, at]
        return Mix(offset, np.hstack([group, lobe_group]),
                   np.ascontiguousarray(np.concatenate([diffuse, lobe], axis=2).transpose(0, 2, 1)))


def reflected_sources(tables, gathering, emission, samples, rng, groups=None):
    """The walk's tables with the patches' reflected direct light as its only sources
    (everything else shared): ``emission`` (P,3) E' from uniform points of each patch (random
    exit), or, leaving from hit points, the gathering ``samples`` (gather_direct's) as
    ReflectedPoints (``rng`` seeds their glossy rows' directions). Per source, ``groups`` is (E'
    of each group (S,3,P), the samples' grouping.SampleParts): each source a mix of groups
    (grouping.Mix)."""
    area = tables.geometry.patch_area
    if tables.exit_random:
        mix = None
        if groups is not None:
            S, P = groups[0].shape[0], area.size
            mix = Mix(0, np.broadcast_to(np.arange(S, dtype=np.int32)[:, None], (S, P)),
                      np.ascontiguousarray((groups[0] * area).transpose(0, 2, 1)))
        return tables.with_sources(SourceTable(source_weights(area, emission)), emission, None, mix)
    points = ReflectedPoints(gathering, tables.geometry, samples, rng)
    none = np.zeros_like(emission)
    mix = None if groups is None else points.mix(gathering, groups[1], area.size)
    return tables.with_sources(SourceTable(source_weights(area, none, points.power)), none, points, mix)


def split_lost(gathering, lost):
    """(escaped, blocked) (C,) each: ``lost`` (C,), the direct light the gathering found on no
    patch's front, split by the solve's ``gathering.fate_shares``."""
    escaped, blocked = gathering.fate_shares
    return lost * escaped, lost * blocked


def gathered_chunk(tables, gathering, paths, rng, walk):
    """One chunk of the gathered estimate: the direct light of every patch, then ``paths``
    walks from its reflection (``walk(tables, paths, rng)`` gives their ChunkTally). Returns
    a ChunkTally in the solve's relative weights (times Phi_T / N)."""
    grouped = tables.groups is not None
    gathered = gather_direct(tables, gathering, rng, grouped)
    H, gather_rays, samples = gathered[:3]
    C = tables.channels
    direct = H * gathering.patch_area  # (3,P) power incident on each patch's front
    reflected = gathering.reflectivity * H  # (3,P) E'
    walk_power = float((gathering.patch_area * channel_sum(reflected.T)).sum() / 3)
    scale = paths / gathering.total_power  # relative weight per unit of power
    incident = direct[:C] * scale
    absorbed = ((1.0 - gathering.reflectivity) * direct).sum(axis=1)[:C] * scale
    emitted = gathering.channel_power[:C] * scale
    walked = np.zeros(C)  # what the walk started with
    blocked, undistributed, walk_absorbed, walk_escaped = (np.zeros(C) for _ in range(4))
    rays, ended = gather_rays, {}
    if grouped:  # (each group's direct light, and its reflection as the walk's sources)
        H_groups = gathered[3].irradiance(tables.groups.count, tables.patch_count, gathering.samples)
        incident_groups = H_groups[:, :C] * (gathering.patch_area * scale)
        direct_groups = incident_groups if tables.direct_apart else None
        grouped = (gathering.reflectivity * H_groups, gathered[3])
    if walk_power > 0:
        sources = reflected_sources(tables, gathering, np.ascontiguousarray(reflected.T), samples, rng, grouped or None)
        tally = walk(sources, paths, rng)
        w = walk_power / gathering.total_power
        incident = incident + tally.incident * w
        walked, walk_absorbed, walk_escaped = tally.emitted * w, tally.absorbed * w, tally.escaped * w
        blocked, undistributed = tally.blocked * w, tally.undistributed * w
        rays += tally.rays
        ended = tally.ended
        if grouped:
            incident_groups = incident_groups + tally.incident_groups * w
    # What the direct light brought no patch (in expectation, what escaped or met a back side
    # on its first flight), so that the accounts balance exactly; below zero where a light that
    # casts no shadow reaches, through objects, more than it emits.
    lost_escaped, lost_blocked = split_lost(gathering, emitted - absorbed - walked)
    tally = ChunkTally(paths, rays, incident, emitted, absorbed + walk_absorbed, lost_escaped + walk_escaped,
                       blocked + lost_blocked, undistributed, ended,
                       direct=direct[:C] * scale if tables.direct_apart and not grouped else None)
    return replace(with_groups(tally, incident_groups), direct_groups=direct_groups) if grouped else tally
