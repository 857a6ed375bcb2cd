"""Sample scenes from Sbert & Brusi, built deterministically in pure numpy.

Each module has a ``build(...)`` function returning a :class:`SampleScene`: the raw arrays a
core :class:`addon.core.PatchScene` takes, the name of the part every patch belongs to, and
metadata (patch counts per part, R_ave, the sizes chosen where the paper is silent).
``sample.scene`` is the :class:`PatchScene` (built on first use; it needs ``addon.core``).

    from sample_scenes import cube_enclosure, room_fig4, room_fig6, cornell_box
    sample = cube_enclosure.build(reflectivity=0.5)
    scene = sample.scene            # addon.core.PatchScene
    sample.part_patch_counts()      # {'enclosure': 384, ...}

See ``sample_scenes/README.md`` for the table of scenes.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

__all__ = ["SampleScene", "SCENES", "build"]


@dataclass
class SampleScene:
    name: str
    description: str
    vertices: np.ndarray        # (V,3) float64, metres, Z up
    triangles: np.ndarray       # (T,3) int64
    triangle_patch: np.ndarray  # (T,) int64
    reflectivity: np.ndarray    # (P,3) float64
    emission: np.ndarray        # (P,3) float64, emittance (power per unit area)
    patch_part: np.ndarray      # (P,) int32 index into part_names
    part_names: list
    metadata: dict = field(default_factory=dict)

    @property
    def patch_count(self):
        return int(self.reflectivity.shape[0])

    @cached_property
    def patch_area(self):
        c = self.vertices[self.triangles]
        area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
        return np.bincount(self.triangle_patch, weights=area, minlength=self.patch_count)

    @cached_property
    def patch_normal(self):
        """Unit normal of each patch (right-hand rule on its first triangle)."""
        first = np.zeros(self.patch_count, dtype=np.int64)
        first[self.triangle_patch[::-1]] = np.arange(len(self.triangle_patch))[::-1]
        c = self.vertices[self.triangles[first]]
        n = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        return n / np.linalg.norm(n, axis=1, keepdims=True)

    @cached_property
    def patch_centroid(self):
        c = self.vertices[self.triangles].mean(axis=1)
        area = self.patch_area
        tri_area = 0.5 * np.linalg.norm(
            np.cross(*(self.vertices[self.triangles][:, k] - self.vertices[self.triangles][:, 0] for k in (1, 2))),
            axis=1,
        )
        out = np.zeros((self.patch_count, 3))
        for k in range(3):
            out[:, k] = np.bincount(self.triangle_patch, weights=c[:, k] * tri_area, minlength=self.patch_count)
        return out / area[:, None]

    @property
    def total_area(self):
        return float(self.patch_area.sum())

    @property
    def r_ave(self):
        """Area-weighted mean reflectivity (channel mean), the paper's R_ave."""
        return float(np.sum(self.patch_area * self.reflectivity.mean(axis=1)) / self.total_area)

    @property
    def total_power(self):
        """Emittance times area, channel mean: the paper's Phi_T of one-sided emitters (the core's
        PatchScene.total_power counts an emitter's back too, where that emits)."""
        return float(np.sum(self.patch_area * self.emission.mean(axis=1)))

    def part_patches(self, name):
        return np.flatnonzero(self.patch_part == self.part_names.index(name))

    def part_patch_counts(self):
        counts = np.bincount(self.patch_part, minlength=len(self.part_names))
        return {n: int(c) for n, c in zip(self.part_names, counts)}

    def part_summary(self):
        """Rows (part, patches, area m^2, reflectivity RGB, emittance RGB) for documentation."""
        rows = []
        for k, name in enumerate(self.part_names):
            idx = np.flatnonzero(self.patch_part == k)
            rows.append((name, idx.size, float(self.patch_area[idx].sum()),
                         tuple(np.round(self.reflectivity[idx[0]], 4)), tuple(np.round(self.emission[idx[0]], 4))))
        return rows

    def grey_reflectivity(self):
        """(P,) reflectivity if the scene is grey, else None."""
        r = self.reflectivity
        return r[:, 0].copy() if np.all(r == r[:, :1]) else None

    def arrays(self, grey=True):
        """(vertices, triangles, triangle_patch, reflectivity, emission); grey scenes as (P,)."""
        refl, emis = self.reflectivity, self.emission
        if grey and np.all(refl == refl[:, :1]) and np.all(emis == emis[:, :1]):
            refl, emis = refl[:, 0].copy(), emis[:, 0].copy()
        return self.vertices, self.triangles, self.triangle_patch, refl, emis

    @cached_property
    def scene(self):
        """The core PatchScene (grey arrays for grey scenes)."""
        from addon.core import PatchScene

        return PatchScene(*self.arrays())

    def summary(self):
        return (f"{self.name}: {self.patch_count} patches, {len(self.triangles)} triangles, "
                f"A_T={self.total_area:.4g} m^2, R_ave={self.r_ave:.4f}, Phi_T={self.total_power:.4g}")


def build(name, **kwargs):
    """Build a sample scene by registry name (see SCENES)."""
    import importlib

    module, defaults = SCENES[name]
    mod = importlib.import_module(f"{__name__}.{module}")
    return mod.build(**{**defaults, **kwargs})


# registry: name -> (module, default keyword arguments)
SCENES = {
    "fig1_r0.2": ("cube_enclosure", {"reflectivity": 0.2}),
    "fig1_r0.5": ("cube_enclosure", {"reflectivity": 0.5}),
    "fig1_r0.8": ("cube_enclosure", {"reflectivity": 0.8}),
    "fig4_room": ("room_fig4", {}),
    "fig6_room": ("room_fig6", {}),
    "cornell_box": ("cornell_box", {}),
}
