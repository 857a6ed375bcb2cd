"""Which corners of a surface's shading triangles may share a value (``smoothing.Surface``): the
points whose corners all lie within half the crease angle of their mean normal, and at the other
points, the pairs of corners whose normals are within the angle (and on one side of a cover's
outline). No bpy.
"""
import numpy as np

from ..mesh.welding import run_starts


def crease_pairs(point, triangle_patch, patch_normal, cos_crease, covered=None):
    """(smooth point flags (n,), compatible (corner, other) pairs at the other points); a
    corner's normal is its patch's, and its side of a cover's outline its patch's ``covered``."""
    p = point.ravel()
    cp = np.repeat(triangle_patch, 3)
    n = int(p.max()) + 1 if len(p) else 0
    mean = np.stack([np.bincount(p, weights=patch_normal[cp, k], minlength=n) for k in range(3)], axis=1)
    length = np.linalg.norm(mean, axis=1, keepdims=True)
    mean = np.divide(mean, length, out=np.zeros_like(mean), where=length > 0)
    dot = np.zeros(len(p))
    for k in range(3):  # over axes, not elements
        dot += patch_normal[cp, k] * mean[p, k]
    half = np.cos(0.5 * np.arccos(np.clip(cos_crease, -1.0, 1.0)))
    lowest = np.full(n, np.inf)
    np.minimum.at(lowest, p, dot)
    del dot
    smooth = (lowest >= half) & (length[:, 0] > 0)
    if covered is not None:  # (a point both sides meet at is a crease point: some of its corners covered, not all)
        smooth &= np.bincount(p, weights=covered[cp], minlength=n) % np.maximum(np.bincount(p, minlength=n), 1) == 0
    corners = np.flatnonzero(~smooth[p])
    if len(corners) == 0:
        return smooth, (np.zeros(0, np.int64), np.zeros(0, np.int64))
    corners = corners[np.argsort(p[corners], kind="stable")]
    starts = run_starts(p[corners])
    sizes = np.diff(np.r_[starts, len(corners)])
    square = sizes * sizes
    first = np.repeat(starts, square)
    size = np.repeat(sizes, square)
    rank = np.arange(len(first)) - np.repeat(np.cumsum(square) - square, square)
    c, o = corners[first + rank // size], corners[first + rank % size]
    keep = np.einsum("ij,ij->i", patch_normal[cp[c]], patch_normal[cp[o]]) >= cos_crease
    keep &= True if covered is None else covered[cp[c]] == covered[cp[o]]
    return smooth, (c[keep], o[keep])
