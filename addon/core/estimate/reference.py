"""Exact and near-exact references for the random walks, to test them against.

Form factors, the direct solve of the discrete radiosity system B = E + R F B, and the exact
per-path variances of table 1. Emitting patches emit from their backs too (``PatchScene``):
then B = E + R F B + R F_back E, F_back[i, j] the form factor from i to the back of j (the
backs emit but reflect nothing: surfaces are one-sided), ``back_form_factors``.

Form factors between axis-aligned rectangles come in closed form from the contour integral
(Stokes' theorem applied to the form factor's double area integral)

    A_i F_ij = 1/(2 pi) * sum over edge pairs of  integral integral ln r  dx_i . dx_j

where only parallel edges contribute, each pair by a closed-form double primitive of ln r.
It holds for rectangles that see each other whole (the inside of a convex enclosure, say).
For general scenes, :func:`form_factors_raycast` estimates F by casting many rays.
"""
from __future__ import annotations

import numpy as np

from ..lights.sampling import cosine_directions, points_on_patches


# --- closed-form form factors of axis-aligned rectangles ------------------------------------

def _ln_double_primitive(u, d):
    """G(u) with G'' = ln sqrt(u^2 + d^2): 1/2 [ (u^2 - d^2)/2 ln(u^2 + d^2) - 3/2 u^2 + 2 d u atan(u/d) ]."""
    r2 = u * u + d * d
    with np.errstate(divide="ignore", invalid="ignore"):
        log_term = np.where(r2 > 0, 0.5 * (u * u - d * d) * np.log(np.where(r2 > 0, r2, 1.0)), 0.0)
        atan_term = np.where(d > 0, 2.0 * d * u * np.arctan(u / np.where(d > 0, d, 1.0)), 0.0)
    return 0.5 * (log_term - 1.5 * u * u + atan_term)


def _rectangle_edges(origin, edge_u, edge_v):
    """The four edges of each rectangle o, o+u, o+u+v, o+v (counter-clockwise about u x v).

    Returns start points (n,4,3), axis index (n,4), signed length along that axis (n,4).
    """
    corners = np.stack([origin, origin + edge_u, origin + edge_u + edge_v, origin + edge_v], axis=1)
    vectors = np.roll(corners, -1, axis=1) - corners
    axis = np.argmax(np.abs(vectors), axis=2)
    length = np.take_along_axis(vectors, axis[..., None], axis=2)[..., 0]
    off_axis = np.abs(vectors).sum(axis=2) - np.abs(length)
    if np.any(off_axis > 1e-9 * np.abs(length).max()):
        raise ValueError("rectangle_form_factors needs rectangles whose edges are parallel to the axes")
    return corners, axis, length


def rectangle_form_factors(origin, edge_u, edge_v, block=256):
    """Form factors F_ij between axis-aligned rectangles i (rows) and j (columns).

    Rectangle k has corners o_k, o_k + u_k, o_k + u_k + v_k, o_k + v_k and normal u_k x v_k.
    Pairs that are coplanar, or where either lies behind the other, get F = 0; otherwise the
    rectangles are assumed to see each other whole.
    """
    origin, edge_u, edge_v = (np.asarray(a, dtype=np.float64) for a in (origin, edge_u, edge_v))
    n = origin.shape[0]
    corners, axis, length = _rectangle_edges(origin, edge_u, edge_v)
    normal = np.cross(edge_u, edge_v)
    area = np.linalg.norm(normal, axis=1)
    normal /= area[:, None]
    centre = origin + 0.5 * (edge_u + edge_v)
    F = np.zeros((n, n))
    for i0 in range(0, n, block):
        i = slice(i0, min(n, i0 + block))
        # Edge pairs (i rows, 4) x (j cols, 4) broadcast as (bi,4,1,1) against (1,1,n,4).
        start_i = corners[i][:, :, None, None, :]
        start_j = corners[None, None, :, :, :]
        axis_i = axis[i][:, :, None, None]
        axis_j = axis[None, None, :, :]
        same = axis_i == axis_j
        delta = start_i - start_j                      # (bi,4,n,4,3)
        along = np.take_along_axis(delta, np.broadcast_to(axis_i, delta.shape[:-1])[..., None], axis=-1)[..., 0]
        d = np.sqrt(np.maximum((delta**2).sum(axis=-1) - along**2, 0.0))
        len_i = length[i][:, :, None, None]
        len_j = length[None, None, :, :]
        # Positions along the shared axis, relative to edge j's start: edge i spans
        # [along, along + len_i], edge j spans [0, len_j]; each integrates in its own direction.
        a1, a2 = along, along + len_i
        b1, b2 = 0.0, len_j
        integral = (
            _ln_double_primitive(a2 - b1, d)
            - _ln_double_primitive(a1 - b1, d)
            - _ln_double_primitive(a2 - b2, d)
            + _ln_double_primitive(a1 - b2, d)
        )
        F[i] = np.where(same, integral, 0.0).sum(axis=(1, 3)) / (2.0 * np.pi * area[i][:, None])
    # Zero the pairs that cannot exchange light: coplanar, or one behind the other.
    to_j = centre[None, :, :] - centre[:, None, :]
    j_in_front_of_i = np.einsum("ik,ijk->ij", normal, to_j) > 1e-12
    i_in_front_of_j = np.einsum("jk,ijk->ij", normal, -to_j) > 1e-12
    return np.where(j_in_front_of_i & i_in_front_of_j, F, 0.0)


def back_form_factors(origin, edge_u, edge_v):
    """F_back[i, j]: the form factor from axis-aligned rectangle i (its front) to the back of
    rectangle j, each seen whole (:func:`rectangle_form_factors` of j turned over)."""
    origin, edge_u, edge_v = (np.asarray(a, dtype=np.float64) for a in (origin, edge_u, edge_v))
    n = origin.shape[0]
    both = rectangle_form_factors(np.vstack([origin, origin]), np.vstack([edge_u, edge_v]), np.vstack([edge_v, edge_u]))
    return both[:n, n:]


# --- form factors by ray casting -------------------------------------------------------------

def form_factors_raycast(scene, rays_per_patch=100_000, seed=0, block_rays=1 << 20, backs=False):
    """Estimate F_ij by casting ``rays_per_patch`` cosine-distributed rays from uniform points
    on every patch i and counting front hits on j. Dense (P,P); meant for small scenes. With
    ``backs``, (F, F_back): F_back[i, j] counts the same rays' hits on the back of j.

    Each row is a multinomial estimate: F_ij has standard error sqrt(F_ij (1 - F_ij) / rays).
    """
    g = scene.geometry
    P = scene.patch_count
    if P > 8000:
        raise ValueError(f"form_factors_raycast is dense (P x P); {P} patches is too many")
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence(seed, spawn_key=(0xF0F0,))))
    counts, back_counts = np.zeros(P * P), np.zeros(P * P)
    patches_per_block = max(1, block_rays // rays_per_patch)
    for p0 in range(0, P, patches_per_block):
        rows = np.arange(p0, min(P, p0 + patches_per_block))
        patch = np.repeat(rows, rays_per_patch)
        u = rng.random((5, patch.size), dtype=np.float32)
        origins = points_on_patches(g, patch, u[0], u[1], u[2])
        directions = cosine_directions(g, patch, u[3], u[4])
        hit = scene.tracer.first_hit(origins, directions, g.region_of(patch))
        ok = hit >= 0
        hit_safe = np.where(ok, hit, 0)
        front = ok & (np.einsum("ij,ij->i", directions, g.triangle_normal[hit_safe]) < 0)
        target = g.triangle_patch[hit_safe[front]]
        counts += np.bincount(patch[front] * P + target, minlength=P * P)
        back = ok & ~front
        back_counts += np.bincount(patch[back] * P + g.triangle_patch[hit_safe[back]], minlength=P * P)
    F = counts.reshape(P, P) / rays_per_patch
    return (F, back_counts.reshape(P, P) / rays_per_patch) if backs else F


# --- the discrete radiosity system and table 1 -------------------------------------------------

def _channels(values, P):
    a = np.asarray(values, dtype=np.float64)
    return np.repeat(a[:, None], 3, axis=1) if a.ndim == 1 else a


def solve_radiosity_system(F, reflectivity, emission, F_back=None):
    """B = E + R F B (+ R F_back E: the emitters' backs' light, given their form factors)
    solved directly, per channel. (P,3) for (P,3) or (P,) inputs."""
    P = F.shape[0]
    R = _channels(reflectivity, P)
    E = _channels(emission, P)
    identity = np.eye(P)
    source = E if F_back is None else E + R * (F_back @ E)
    return np.stack([np.linalg.solve(identity - R[:, c, None] * F, source[:, c]) for c in range(3)], axis=1)


def self_return(F, reflectivity):
    """xi_i of table 2: power received by patch i per unit power it emits, counting every
    later bounce (grey): diag(F (I - R F)^-1)."""
    R = np.asarray(reflectivity, dtype=np.float64)
    P = F.shape[0]
    H = F @ np.linalg.inv(np.eye(P) - R[:, None] * F)
    return np.diag(H).copy()


def path_variances(F, reflectivity, emission, area, F_back=None, sides=1.0):
    """Exact per-path variances of table 1 for a grey scene: (finite, infinite), each (P,).

        finite:   R_i b_i Phi_T / A_i (1 + 2 R_i xi_i) - b_i^2
        infinite: beta_i Phi_T / A_i (1 + 2 R_i xi_i) - b_i^2
    with beta the reflected radiosity when every reflectivity is replaced by its square, Phi_T
    the sources' sum of ``sides`` E_i A_i (``PatchScene.emitting_sides``), their backs' light
    through ``F_back`` where given.
    """
    R = np.asarray(reflectivity, dtype=np.float64)
    E = np.asarray(emission, dtype=np.float64)
    A = np.asarray(area, dtype=np.float64)
    Phi_T = float((np.asarray(sides) * E * A).sum())
    b = solve_radiosity_system(F, R, E, F_back)[:, 0] - E
    beta = solve_radiosity_system(F, R**2, E, F_back)[:, 0] - E
    xi = self_return(F, R)
    finite = R * b * Phi_T / A * (1 + 2 * R * xi) - b**2
    infinite = beta * Phi_T / A * (1 + 2 * R * xi) - b**2
    return finite, infinite


def area_weighted_mse(estimate, exact, area):
    """MSE as the product defines it: area-weighted mean over patches, averaged over channels."""
    err = np.asarray(estimate, dtype=np.float64) - np.asarray(exact, dtype=np.float64)
    sq = err**2 if err.ndim == 1 else (err**2).mean(axis=1)
    return float((sq * area).sum() / np.sum(area))
