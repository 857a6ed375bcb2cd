"""Shared pure-numpy meshing helpers for the sample scenes.

Every patch is an axis-aligned square (or, for a few thin slabs, rectangle) made of two
triangles with the same winding. A patch spanned by edge vectors ``u`` and ``v`` from corner
``p`` has corners ``p, p+u, p+u+v, p+v`` and triangles ``(0,1,2), (0,2,3)``, so its normal is
``u x v`` (right-hand rule) and radiosity leaves that side.

Coordinates are Blender's: metres, Z up.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

AXES = {"x": 0, "y": 1, "z": 2}
_UNIT = np.eye(3)


def _face_frame(face):
    """Edge directions (u_axis, v_axis) whose cross product is the OUTWARD normal of a box face.

    ``face`` is one of 'x-', 'x+', 'y-', 'y+', 'z-', 'z+'.
    """
    return {
        "x+": (1, 2),  # y x z = +x
        "x-": (2, 1),  # z x y = -x
        "y+": (2, 0),  # z x x = +y
        "y-": (0, 2),  # x x z = -y
        "z+": (0, 1),  # x x y = +z
        "z-": (1, 0),  # y x x = -z
    }[face]


ALL_FACES = ("x-", "x+", "y-", "y+", "z-", "z+")


def divisions(length, patch_size, what="length"):
    """Number of patches of ``patch_size`` along ``length``; the length must be a whole multiple."""
    n = int(round(length / patch_size))
    if n < 1 or abs(n * patch_size - length) > 1e-9 * max(1.0, length):
        raise ValueError(f"{what} {length} is not a whole multiple of the patch size {patch_size}")
    return n


@dataclass
class MeshBuilder:
    """Accumulates square patches, each tagged with a named part and its materials."""

    vertices: list = field(default_factory=list)
    triangles: list = field(default_factory=list)
    triangle_patch: list = field(default_factory=list)
    reflectivity: list = field(default_factory=list)
    emission: list = field(default_factory=list)
    patch_part: list = field(default_factory=list)
    part_names: list = field(default_factory=list)
    boxes: list = field(default_factory=list)  # (part, lo, hi, inward, first, end patch) per add_box
    patch_count: int = 0
    _vertex_count: int = 0

    def part_index(self, name):
        if name not in self.part_names:
            self.part_names.append(name)
        return self.part_names.index(name)

    def add_grid(self, origin, u, v, nu, nv, part, reflectivity, emission=0.0):
        """Add an ``nu`` x ``nv`` grid of patches spanning ``origin + s*u + t*v``, s,t in [0,1].

        Patch normals are ``u x v``. Returns the indices of the new patches.
        """
        origin = np.asarray(origin, dtype=np.float64)
        du = np.asarray(u, dtype=np.float64) / nu
        dv = np.asarray(v, dtype=np.float64) / nv
        a, b = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
        a = a.ravel()
        b = b.ravel()
        p0 = origin + a[:, None] * du + b[:, None] * dv
        corners = np.stack([p0, p0 + du, p0 + du + dv, p0 + dv], axis=1)  # (n,4,3)
        n = corners.shape[0]
        base = self._vertex_count + 4 * np.arange(n)
        tris = np.concatenate(
            [np.stack([base, base + 1, base + 2], axis=1), np.stack([base, base + 2, base + 3], axis=1)],
            axis=1,
        ).reshape(-1, 3)
        patches = self.patch_count + np.arange(n)
        self.vertices.append(corners.reshape(-1, 3))
        self.triangles.append(tris)
        self.triangle_patch.append(np.repeat(patches, 2))
        self.reflectivity.append(np.broadcast_to(np.asarray(reflectivity, dtype=np.float64), (n, 3)).copy())
        self.emission.append(np.broadcast_to(np.asarray(emission, dtype=np.float64), (n, 3)).copy())
        self.patch_part.append(np.full(n, self.part_index(part), dtype=np.int32))
        self._vertex_count += 4 * n
        self.patch_count += n
        return patches

    def add_box(self, lo, hi, patch_size, part, reflectivity, emission=0.0, faces=ALL_FACES,
                inward=False, divisions_override=None):
        """Add the faces of the axis-aligned box [lo, hi], meshed into squares of ``patch_size``.

        Normals point out of the box, or into it with ``inward=True`` (an enclosure).
        ``divisions_override`` maps a face name to (nu, nv) for thin slabs whose sides are
        thinner than one patch (those patches are then rectangles).
        """
        lo = np.asarray(lo, dtype=np.float64)
        hi = np.asarray(hi, dtype=np.float64)
        size = hi - lo
        first = self.patch_count
        out = []
        for face in faces:
            axis = AXES[face[0]]
            ua, va = _face_frame(face)
            if inward:
                ua, va = va, ua
            origin = lo.copy()
            if face[1] == "+":
                origin[axis] = hi[axis]
            u = _UNIT[ua] * size[ua]
            v = _UNIT[va] * size[va]
            if divisions_override and face in divisions_override:
                nu, nv = divisions_override[face]
            else:
                nu = divisions(size[ua], patch_size, f"{part} box edge")
                nv = divisions(size[va], patch_size, f"{part} box edge")
            out.append(self.add_grid(origin, u, v, nu, nv, part, reflectivity, emission))
        self.boxes.append((part, tuple(lo), tuple(hi), bool(inward), first, self.patch_count))
        return np.concatenate(out)

    def finish(self, name, description, **metadata):
        from . import SampleScene

        return SampleScene(
            name=name,
            description=description,
            vertices=np.concatenate(self.vertices),
            triangles=np.concatenate(self.triangles).astype(np.int64),
            triangle_patch=np.concatenate(self.triangle_patch).astype(np.int64),
            reflectivity=np.concatenate(self.reflectivity),
            emission=np.concatenate(self.emission),
            patch_part=np.concatenate(self.patch_part),
            part_names=list(self.part_names),
            metadata={**metadata, "boxes": list(self.boxes)},
        )


def box_patch_count(nx, ny, nz, faces=ALL_FACES):
    """Patches of a box of nx x ny x nz patch units over the given faces."""
    per_face = {"x-": ny * nz, "x+": ny * nz, "y-": nx * nz, "y+": nx * nz, "z-": nx * ny, "z+": nx * ny}
    return sum(per_face[f] for f in faces)


def solve_for_reflectivity(sample_areas, sample_reflectivity, free_mask, target):
    """The single reflectivity for the patches in ``free_mask`` that makes the area-weighted
    mean reflectivity (over all patches, channel mean) equal ``target``."""
    grey = sample_reflectivity.mean(axis=1)
    fixed = np.sum(sample_areas[~free_mask] * grey[~free_mask])
    free_area = np.sum(sample_areas[free_mask])
    value = (target * sample_areas.sum() - fixed) / free_area
    if not 0 <= value < 1:
        raise ValueError(f"cannot reach R_ave={target}: the free patches would need reflectivity {value:.3f}")
    return value


def _inside(points, lo, hi, tol=0.0):
    return np.all((points > np.asarray(lo) + tol) & (points < np.asarray(hi) - tol), axis=1)


def _on_surface(points, lo, hi, tol=1e-9):
    lo, hi = np.asarray(lo), np.asarray(hi)
    within = np.all((points >= lo - tol) & (points <= hi + tol), axis=1)
    return within & np.any(np.isclose(points, lo, atol=tol, rtol=0) | np.isclose(points, hi, atol=tol, rtol=0), axis=1)


def orientation_report(sample, eps=1e-4):
    """Check every patch faces free space, from the boxes recorded while building.

    Returns (wrong, covered): indices of patches whose front side is solid (inside an outward
    box or outside the enclosure) without touching that box -- a winding error -- and of patches
    that are covered by a box resting on them (floor under a bed: no light can reach them, the
    paper's meshes have them too). Also checks that the back of every box face is solid.
    """
    c, n = sample.patch_centroid, sample.patch_normal
    front, back = c + eps * n, c - eps * n
    wrong = np.zeros(len(c), bool)
    covered = np.zeros(len(c), bool)
    for part, lo, hi, inward, first, end in sample.metadata["boxes"]:
        if inward:
            wrong |= ~_inside(front, lo, hi)
        else:
            blocked = _inside(front, lo, hi)
            touching = _on_surface(c, lo, hi)
            own = np.zeros(len(c), bool)
            own[first:end] = True
            covered |= blocked & touching & ~own
            wrong |= blocked & ~touching
        idx = np.arange(first, end)
        behind = _inside(back[idx], lo, hi)
        wrong[idx[behind == inward]] = True
    return np.flatnonzero(wrong), np.flatnonzero(covered & ~wrong)
