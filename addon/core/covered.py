"""Patches no camera sees: buried whole inside another object, or covered by a surface lying
against them.

The smooth colours join, at each corner, the patches that meet there. A patch that gets no light
because something lies against it (the ceiling behind a light panel hung 1 cm under it, the floor
under a box or a rug) would pull its visible neighbours' corners towards black: a dark rim around
the panel and, as each neighbour keeps its mean, ripples beyond it. Such patches are left out of
their neighbours' corners (``smoothing.Surface``'s ``hidden``); their own values stay as solved.

A patch is covered when the ray from its middle along its normal meets the back of a surface
within COVER_SHARE of the patch's side (a panel facing away from it, a rug's underside; a table
top a patch's width above the floor is not). A patch whose ray meets a back side farther off is
hidden when the near-grazing probes of ``visibility`` meet back sides first too (the floor under
a box with no bottom, whose patches nothing crosses; under a one-sided table top they escape),
or buried whole as ``visibility`` found it.
"""
from __future__ import annotations

import numpy as np

from .rays import meets_front
from .sampling import patch_point_rows
from .visibility import PROBES, _tangents

COVER_SHARE = 1.0  # of the patch's side


def hidden_patches(geometry):
    """(P,) bool: the patches buried whole or covered (the module's docstring)."""
    g = geometry
    P = len(g.patch_area)
    hidden = np.zeros(P, bool)
    if g.buried is not None:
        hidden[g.buried.whole] = True
    patch = np.arange(P, dtype=np.int64)
    half = np.full(P, 0.5, np.float32)
    origins = patch_point_rows(g, patch, half.astype(np.float64), half, half.copy())  # (pushed off its patch)
    normal = g.patch_normal_rows.astype(np.float64)
    back, t = _meets_back(g, origins, normal, patch)
    near = COVER_SHARE * np.sqrt(g.patch_area) / g.diagonal  # (unit space)
    hidden |= back & (t < near)
    rows = np.flatnonzero(back & ~hidden)
    tangent, bitangent = _tangents(normal[:, rows])
    for theta, phi in PROBES[1:]:
        if not rows.size:
            break
        s, c = np.sin(np.radians(theta)), np.cos(np.radians(theta))
        d = c * normal[:, rows] + s * (np.cos(np.radians(phi)) * tangent + np.sin(np.radians(phi)) * bitangent)
        keep = _meets_back(g, origins[:, rows], d, rows)[0]
        rows, tangent, bitangent = rows[keep], tangent[:, keep], bitangent[:, keep]
    hidden[rows] = True
    return hidden


def _meets_back(g, origins, directions, patch):
    """((n,) bool: the first surface met is seen from behind, (n,) its distance, unit space) for
    rays (3,n) from points of ``patch``."""
    d = np.ascontiguousarray(directions.T, np.float32)
    hit, _, _, t, hit_normal = g.surface_tracer.first_hit_barycentric(np.ascontiguousarray(origins.T, np.float32), d,
                                                                      g.region_of(patch))
    return (hit >= 0) & ~meets_front(d.T, hit_normal), t
