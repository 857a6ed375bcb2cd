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
from .sampling import SourceTable, add_sphere_points, channel_sum, source_weights
from .grouping import Mix, with_groups
from .tallies import ChunkTally


class ReflectedPoints:
    """The gathering samples as the walk's light sources (leaving from hit points): sample k,
    at point x_k of patch j, reflects R_j A_j / n_j times the irradiance it found (``power``
    (K,3), in the walk's source table after the patches), in cosine-distributed directions
    about the patch's normal. Their sum over patch j's samples is A_j E'_j. Points and normals
    stay in the walk's unit space, float32 (the points already pushed off the surface)."""

    def __init__(self, gathering, geometry, samples):
        patch, x, value = samples
        factor = gathering.reflectivity * gathering.area_per_sample  # R_j A_j / n_j
        self.power = np.ascontiguousarray((value * factor.take(patch, axis=1)).T)
        self.patch = patch
        self.points = np.asarray(x, dtype=np.float32)
        self.normals = geometry.patch_normal_rows.take(patch, axis=1)

    def unit_rays(self, rows, u, geometry):
        """Rays from samples ``rows`` with uniforms ``u`` (4, n) float32 (directions from u[2:4],
        as a patch's: normal plus a uniform sphere point): (3, n) unit-space origins, directions,
        as :meth:`.lights.Lights.unit_rays` gives them (the points are in unit space already:
        ``geometry`` is not read)."""
        return self.points.take(rows, axis=1), add_sphere_points(self.normals.take(rows, axis=1), u[2], u[3])

    def regions(self, rows, geometry):
        """(n,) the region frame of samples ``rows``' points (their patches'), or None."""
        return geometry.region_of(self.patch.take(rows))


def reflected_sources(tables, gathering, emission, samples, groups=None):
    """The walk's tables with the patches' reflected direct light as its only sources
    (everything else shared): ``emission`` (P,3) E' from uniform points of each patch (random
    exit), or, leaving from hit points, the gathering ``samples`` (gather_direct's) as
    ReflectedPoints. Per source, ``groups`` is (E' of each group (S,3,P), the samples'
    grouping.SampleParts): each source a mix of groups (grouping.Mix)."""
    area = tables.geometry.patch_area
    if tables.exit_random:
        mix = None
        if groups is not None:
            S, P = groups[0].shape[0], area.size
            mix = Mix(0, np.broadcast_to(np.arange(S, dtype=np.int32)[:, None], (S, P)),
                      np.ascontiguousarray((groups[0] * area).transpose(0, 2, 1)))
        return tables.with_sources(SourceTable(source_weights(area, emission)), emission, None, mix)
    points = ReflectedPoints(gathering, tables.geometry, samples)
    none = np.zeros_like(emission)
    mix = None
    if groups is not None:
        mix = groups[1].mix((gathering.reflectivity * gathering.area_per_sample).take(samples[0], axis=1), area.size)
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
        tally = walk(reflected_sources(tables, gathering, np.ascontiguousarray(reflected.T), samples, grouped or None),
                     paths, rng)
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
