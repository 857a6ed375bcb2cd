"""Welding by position: vertices within a small distance of each other on every axis are one
point, whatever mesh or object they come from (shifted grids of cells, joined transitively).
"""
from __future__ import annotations

import numpy as np


def run_starts(sorted_keys):
    """Start of each run of equal values in a sorted 1-D array."""
    return np.flatnonzero(np.r_[True, sorted_keys[1:] != sorted_keys[:-1]])


def _cells(points, cell, shift):
    """Cell number (V,) of every point in a grid of ``cell`` shifted by ``shift`` cells per axis."""
    q = np.floor(points / cell + shift).astype(np.int64)
    order = np.lexsort(q.T[::-1])
    qs = q[order]
    new = np.r_[True, (qs[1:] != qs[:-1]).any(axis=1)]
    del qs
    cells = np.empty(len(points), index_type(len(points)))
    cells[order] = np.cumsum(new) - 1
    return cells


def weld_points(points, weld):
    """Point label (V,) of every vertex: equal for vertices within ``weld`` of each other on every
    axis (transitively), labels 0..n-1."""
    points = np.asarray(points, np.float64)
    V = len(points)
    if V == 0:
        return np.zeros(0, np.int64)
    shifts = [(a, b, c) for a in (0, 0.5) for b in (0, 0.5) for c in (0, 0.5)]
    grids = []
    for s in shifts:
        cells = _cells(points, 2.0 * weld, np.asarray(s))
        if np.bincount(cells).max() > 1:  # a grid joining nothing adds nothing
            order = np.argsort(cells, kind="stable").astype(cells.dtype)
            grids.append((cells, order, run_starts(cells[order]).astype(cells.dtype)))
    labels = np.arange(V, dtype=index_type(V))
    while grids:
        before = labels
        for cells, order, starts in grids:
            labels = np.minimum(labels, np.minimum.reduceat(labels[order], starts)[cells])
        labels = labels[labels]  # pointer jumping: chains shorten geometrically
        if np.array_equal(labels, before):
            break
    return np.unique(labels, return_inverse=True)[1].astype(index_type(V))


def index_type(n):
    """The smallest of int32 and int64 that numbers n things: half the memory of index arrays."""
    return np.int32 if n < 2 ** 31 - 1 else np.int64
