"""Where adaptive patches split after a solve (:mod:`.adaptive` splits them): neighbours on one
surface whose solved light differs by more than their measured noise and by a visible share.

A refined object's patches (a conforming mesh: no T-junction, so patches that touch share whole
edges) are neighbours where they share an edge and their normals are within the smooth colours'
crease angle (a wall and the ceiling meeting at a corner are not one surface). A pair's solved
arriving light H (channel mean) differs visibly when the difference passes the Detail's share of
their local light (or of ``floor`` times the mean where the light is dim, as the direct-light
refinement's rule) and ``NOISE_Z`` standard errors of the difference (the solve's batch-means
variances of both patches, an upper bound of the channel mean's); both patches of such a pair
split, within the Detail's smallest size and patch budget, the largest differences first.
"""
from __future__ import annotations

import numpy as np

from .adaptive import balanced, edge_keys, split
from .adaptive_light import NOISE_Z, SMALLEST_SIDE
from ..mesh.faces import ranks_in_runs, starts_of
from ..display.smoothing import CREASE_ANGLE

COS_CREASE = float(np.cos(np.radians(CREASE_ANGLE)))


def patch_normals(mesh):
    """(P,3) unit normal of each patch of ``mesh`` (its triangles' area-weighted)."""
    points = np.asarray(mesh.points, np.float64)
    triangles = np.asarray(mesh.triangles, np.int64)
    first = points[triangles[:, 0]]
    cross = np.cross(points[triangles[:, 1]] - first, points[triangles[:, 2]] - first)
    tp = np.asarray(mesh.triangle_patch, np.int64)
    normal = np.stack([np.bincount(tp, weights=cross[:, k], minlength=mesh.patch_count) for k in range(3)], axis=1)
    length = np.linalg.norm(normal, axis=1, keepdims=True)
    return np.divide(normal, length, out=np.zeros_like(normal), where=length > 0)


def neighbours(mesh):
    """(a, b): the pairs of patches of a conforming PatchMesh that share an edge (polygon corners
    by index), their normals within the crease angle; each pair once, a < b."""
    sizes = np.asarray(mesh.face_sizes, np.int64)
    verts = np.asarray(mesh.corner_verts, np.int64)
    starts = np.repeat(starts_of(sizes), sizes)
    rank = ranks_in_runs(sizes)
    following = verts[starts + (rank + 1) % np.repeat(sizes, sizes)]
    key = edge_keys(verts, following)
    patch = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    order = np.argsort(key, kind="stable")
    key, patch = key[order], patch[order]
    same = np.flatnonzero((key[1:] == key[:-1]) & (patch[1:] != patch[:-1]))
    a, b = np.minimum(patch[same], patch[same + 1]), np.maximum(patch[same], patch[same + 1])
    normal = patch_normals(mesh)
    smooth = np.einsum("ij,ij->i", normal[a], normal[b]) >= COS_CREASE
    pairs = np.unique(a[smooth] * (np.int64(1) << 32) + b[smooth])
    return pairs >> 32, pairs & ((np.int64(1) << 32) - 1)


def solve_scores(mesh, light, variance, detail, mean_light):
    """(P,) each patch's largest difference to a neighbour over what it must pass to split
    (above 1: split): ``light`` (P,3) the solve's H of this object's patches, ``variance`` (P,3)
    its batch-means variance (NaN, below two batches: no split)."""
    value = np.asarray(light, np.float64).mean(axis=1)
    noise = np.asarray(variance, np.float64).mean(axis=1)  # (>= Var of the channel mean)
    noise = np.where(np.isfinite(noise), noise, np.inf)
    a, b = neighbours(mesh)
    score = np.zeros(len(value))
    if not a.size:
        return score
    visible = detail.contrast * np.maximum(0.5 * (value[a] + value[b]), detail.floor * mean_light)
    ratio = np.abs(value[a] - value[b]) / np.maximum(visible, NOISE_Z * np.sqrt(noise[a] + noise[b]))
    ratio = np.where(np.isfinite(ratio), ratio, 0.0)
    np.maximum.at(score, a, ratio)
    np.maximum.at(score, b, ratio)
    return score


def refine_by_solve(cells, meshes, light, variance, detail, diagonal, first_count, receives=None, keep_whole=None):
    """One step: split the cells whose solved light differs from a neighbour's (see the module's
    docstring). ``cells``/``meshes`` per object (the conforming meshes of those cells, in cell
    order), ``light``/``variance`` (P,3) of all their patches in that order, ``diagonal`` the
    scene's, ``first_count`` the patches before any refinement (the budget is the Detail's
    share of it), ``keep_whole`` (P,) bool patches that must not split (partly buried ones).
    Returns (the cells per object, {"candidates", "split", "patches"})."""
    receives = [True] * len(cells) if receives is None else list(receives)
    offsets = np.cumsum([0] + [m.patch_count for m in meshes])
    area = np.concatenate([np.asarray(m.patch_area, np.float64) for m in meshes])
    value = np.asarray(light, np.float64).mean(axis=1)
    mine = np.concatenate([np.full(m.patch_count, bool(r)) for m, r in zip(meshes, receives)])
    mean_light = float((value * area)[mine].sum() / max(area[mine].sum(), 1e-300))
    smallest = (SMALLEST_SIDE * diagonal) ** 2 * 4  # (a cell's area: its children's four)
    scores, owner = [], []
    for k, (c, m) in enumerate(zip(cells, meshes)):
        rows = slice(offsets[k], offsets[k + 1])
        s = solve_scores(m, light[rows], variance[rows], detail, mean_light) if receives[k] else np.zeros(c.count)
        s[(c.level >= detail.levels) | c.frozen | (np.asarray(m.patch_area) < smallest)] = 0.0
        if keep_whole is not None:
            s[np.asarray(keep_whole[rows], bool)] = 0.0
        scores.append(s)
        owner.append(np.full(c.count, k))
    score, owner = np.concatenate(scores), np.concatenate(owner)
    chosen = np.flatnonzero(score > 1)
    chosen = chosen[np.argsort(-score[chosen], kind="stable")]  # the largest differences first
    marks = _within_budget(cells, offsets, owner, chosen, int(detail.budget * first_count) - int(offsets[-1]))
    out = list(cells)
    for k, marked in enumerate(marks):
        if marked.any():
            out[k], _ = split(cells[k], marked)
    chosen = chosen[:int(sum(m.sum() for m in marks))]
    return out, {"candidates": int((score > 0).sum()), "split": int(chosen.size), "patches": int(sum(c.count for c in out))}


def _within_budget(cells, offsets, owner, ranked, room):
    """Per object, (L,) bool: the first of the ``ranked`` patches whose splits, with what balance
    adds, make at most ``room`` more patches (each split three more)."""
    def marks(n):
        out = [np.zeros(c.count, bool) for c in cells]
        for k in range(len(cells)):
            mine = ranked[:n][owner[ranked[:n]] == k]
            out[k][mine - offsets[k]] = True
        return out

    def added(n):
        return 3 * sum(int(balanced(c, m).sum()) for c, m in zip(cells, marks(n)) if m.any())

    if added(len(ranked)) <= room:
        return marks(len(ranked))
    low, high = 0, min(len(ranked), max(0, room) // 3)  # (n splits add 3n at least; added(low) fits)
    while low < high:  # the most that fit (what balance adds only grows with n)
        middle = (low + high + 1) // 2
        low, high = (middle, high) if added(middle) <= room else (low, middle - 1)
    return marks(low)
