"""The patch scene: validated arrays of geometry and materials, with the paper's grey quantities.

Notation follows Sbert & Brusi: a patch i has area A_i, reflectivity R_i and emittance
(emitted power per unit area) E_i. An emitting patch emits E_i from its front and from its
back, as Cycles' emission leaves both sides of a face: its power is Phi_i = s_i E_i A_i with
s_i = 2 sides (``emitting_sides``), or 1 where its back has nothing to light (no vertex behind
it, as behind a closed room's lit wall, or closed in, as in a lamp box: ``back_emits``), and
Phi_T = sum_i Phi_i (beside the lights'). Its radiosity B_i is its front's.
Colours are carried as three channels; the grey quantities the paper's formulas use are
channel means (R_bar_i, E_bar_i), so that a grey scene is exactly the paper's.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from .geometry_build import build_geometry
from .rays import meets_front
from .visibility import PROBES, VOTES, buried_at, tangents
from ..lights.sampling import patch_point_rows
from ..materials.glossy import GlossyLobe
from ..lights.lights import Lights
from ..mesh.validation import (
    PatchError,
    material_rows,
    validate_light_numbers,
    validate_lights,
    validate_materials,
    validate_power_scale,
)

SAME = object()  # with_materials: keep the scene's own
# The most sides an emitting patch emits E from (Cycles' emission closure: |cos| of either side).
EMITTING_SIDES = 2
# A vertex this share of the diagonal behind an emitting patch's plane is behind it; planes
# within PLANE_GRAIN (normal, depth over the diagonal) of each other are tested as one.
BEHIND_TOLERANCE = 1e-4
PLANE_GRAIN = 1e-6


class PatchScene:
    """Patches (groups of coplanar triangles) with their reflectivity and emittance.

    Parameters
    ----------
    vertices : (V,3) float
    triangles : (T,3) int, indices into ``vertices``; the normal follows the right-hand rule
        and radiosity leaves the front side.
    triangle_patch : (T,) int in [0, P): the patch each triangle belongs to.
    reflectivity : (P,3) RGB or (P,) grey, each in [0, 1).
    emission : (P,3) or (P,), the emittance E (power per unit area), >= 0, from the front
        and the back of the patch (``emitting_sides``).
    lights : light sources beside the emissive patches (``lights``: point, spot, area, sun, world).
    aim : (centre, radius) of the sphere sun and world light is aimed at (the part of the scene
        whose light matters); default the bounding sphere of every patch.
    glossy : (share (P,3), alpha (P,)) or a GlossyLobe: the share of each patch's reflectivity
        that its first reflection of a source's light sends along a GGX lobe (``glossy``);
        default none (every reflection Lambertian).
    hidden : (P,) bool, the patches a near surface covers (a ceiling over a panel hung just under
        it): the error a solve measures and stops on leaves them out (``area_share``).

    Degenerate triangles are dropped with a warning; everything else that is wrong raises
    ``ValueError`` naming the problem and the offending indices.
    """

    def __init__(self, vertices, triangles, triangle_patch, reflectivity, emission, lights=(), aim=None, *, glossy=None,
                 hidden=None, _geometry=None):
        reflectivity_arr = np.asarray(reflectivity)
        if reflectivity_arr.ndim not in (1, 2) or reflectivity_arr.shape[0] == 0:
            raise ValueError(f"reflectivity must have shape (P,) or (P, 3) with P > 0; got {reflectivity_arr.shape}")
        patch_count = material_rows(reflectivity_arr, emission, triangle_patch)
        lights = tuple(lights.lights if isinstance(lights, Lights) else lights)
        self.reflectivity, self.emission = validate_materials(reflectivity, emission, patch_count, require_emitter=not lights)
        if isinstance(glossy, GlossyLobe):
            glossy = (glossy.share, glossy.alpha)
        self.glossy = None if glossy is None else GlossyLobe.checked(*glossy, self.reflectivity)
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.triangles = np.asarray(triangles)
        self.triangle_patch = np.asarray(triangle_patch)
        self.geometry = _geometry if _geometry is not None else build_geometry(
            vertices, triangles, triangle_patch, patch_count
        )
        with np.errstate(over="ignore", invalid="ignore"):
            power = EMITTING_SIDES * self.patch_area[:, None] * self.emission
            finite = np.isfinite(power.sum())
        if not finite:
            raise PatchError(
                "emission times area overflows: the emitted power is not a finite number "
                f"(largest emission {self.emission.max():.3g}); use smaller units of power",
                np.flatnonzero(~np.isfinite(power).all(axis=1) | (power.max(axis=1) > 1e300)),
            )
        g = self.geometry
        if aim is None:
            aim = (g.centre, 0.5 * g.diagonal)
        # Sun and world rays start beyond the whole scene, seen from the aim's centre.
        reach = float(np.linalg.norm(np.asarray(aim[0], np.float64) - g.centre)) + g.diagonal
        validate_light_numbers(lights)
        self.lights = Lights(lights, aim, reach)
        validate_lights(self.lights)
        if lights and not (self.source_power > 0).any():
            raise ValueError("the scene has no source: every emission is zero and no light gives power")
        validate_power_scale(self.total_power, self.patch_area)
        self.hidden = _hidden(hidden, self.patch_count)

    # --- materials -------------------------------------------------------------------------
    def with_materials(self, reflectivity, emission, lights=None, glossy=SAME):
        """A scene on the same patches with other materials (and the same lights and glossy
        lobe unless given; the lobe's share held to the new reflectivity), sharing geometry and
        ray tracer."""
        return PatchScene(
            self.vertices, self.triangles, self.triangle_patch, reflectivity, emission,
            self.lights if lights is None else lights, self.lights.aim,
            glossy=self.glossy if glossy is SAME else glossy, hidden=self.hidden, _geometry=self.geometry,
        )

    # --- sizes -----------------------------------------------------------------------------
    @property
    def patch_count(self):
        return self.geometry.patch_count

    @property
    def triangle_count(self):
        return self.geometry.triangle_count

    @property
    def patch_area(self):
        return self.geometry.patch_area

    @property
    def area_share(self):
        """(P,) each patch's share of the surfaces the error is measured over: its area over the
        scene's, the ``hidden`` patches left out (under a near cover: seen only through the gap,
        their light counted where it comes out)."""
        if self.hidden is None:
            return self.patch_area / self.total_area
        return np.where(self.hidden, 0.0, self.patch_area) / self.seen_area

    @property
    def seen_area(self):
        """The area the error is measured over: A_T less the ``hidden`` patches'."""
        return self.total_area if self.hidden is None else float(self.patch_area[~self.hidden].sum())

    @property
    def patch_normal(self):
        return self.geometry.patch_normal.astype(np.float64)

    @cached_property
    def total_area(self):
        """A_T."""
        return float(self.patch_area.sum())

    # --- grey quantities of the paper ------------------------------------------------------
    @cached_property
    def grey_reflectivity(self):
        """R_bar_i: the channel mean of each patch's reflectivity (the survival probability);
        exactly R_i where the three channels are equal (a float mean of three equal numbers
        may differ from them in the last bit)."""
        R = self.reflectivity
        mean = R.mean(axis=1)
        grey = (R == R[:, :1]).all(axis=1)
        mean[grey] = R[grey, 0]
        return mean

    @cached_property
    def is_grey(self):
        same = lambda a: bool((a == a[:, :1]).all())  # noqa: E731
        return same(self.reflectivity) and same(self.emission) and same(self.lights.power)

    @cached_property
    def back_emits(self):
        """(P,) bool: the emitting patches whose back has something to light: some vertex of
        the scene lies behind their plane, and the space behind them is not closed in
        (:func:`closed_behind`). The others emit from their front alone: what their back emits
        would all escape (a closed room's lit wall) or stay inside the solid it bounds (a lamp
        box's face), where it lights no visible surface."""
        back = np.zeros(self.patch_count, dtype=bool)
        emitting = np.flatnonzero(self.emission.any(axis=1))
        if not emitting.size:
            return back
        g = self.geometry
        normal = g.patch_normal[emitting].astype(np.float64)
        depth = np.einsum("ij,ij->i", normal, g.to_world(g.corners[g.patch_first_triangle[emitting]][:, 0, :], emitting))
        # Coplanar emitters (a lamp's patches) share one test: their planes, to within PLANE_GRAIN.
        key = np.round(np.column_stack([normal, depth / g.diagonal]) / PLANE_GRAIN)
        planes, first, plane_of = np.unique(key, axis=0, return_index=True, return_inverse=True)
        level = depth[first] - BEHIND_TOLERANCE * g.diagonal  # a vertex below it is behind the plane
        low, high = self.vertices.min(axis=0), self.vertices.max(axis=0)
        behind = np.einsum("ij,ij->i", normal[first], np.where(normal[first] > 0, low, high)) < level  # (the box's)
        candidates = np.flatnonzero(behind)
        step = max(1, (1 << 16) // max(candidates.size, 1))  # (vertices a block: small temporaries)
        lowest = np.full(candidates.size, np.inf)
        for start in range(0, len(self.vertices) if candidates.size else 0, step):
            np.minimum(lowest, (self.vertices[start:start + step] @ normal[first[candidates]].T).min(axis=0), out=lowest)
        behind[candidates] = lowest < level[candidates]
        open_behind = emitting[behind[plane_of.ravel()]]
        if open_behind.size:
            back[open_behind[~closed_behind(g, open_behind)]] = True
        return back

    @property
    def emitting_sides(self):
        """(P,) s_i: 2 where the patch's back emits too (``back_emits``), else 1."""
        return 1.0 + self.back_emits

    @cached_property
    def patch_power(self):
        """Phi_i = s_i A_i E_bar_i, the channel-mean power of each patch (its sides')."""
        return self.emitting_sides * self.patch_area * self.emission.mean(axis=1)

    @cached_property
    def source_power(self):
        """(S,3) the power of every source: the patches' s_i A_i E_i (their sides'), then the
        lights' emitters."""
        return np.vstack([(self.emitting_sides * self.patch_area)[:, None] * self.emission, self.lights.power])

    @cached_property
    def total_power(self):
        """Phi_T: the patches' and the lights' (channel mean)."""
        if not len(self.lights):
            return float(self.patch_power.sum())
        return float(self.patch_power.sum() + self.lights.power.mean(axis=1).sum())

    @cached_property
    def average_reflectivity(self):
        """R_ave: the area-weighted average reflectivity (channel mean)."""
        return float((self.patch_area * self.grey_reflectivity).sum() / self.total_area)

    @property
    def tracer(self):
        """The ray tracer over this geometry (shared with scenes made by with_materials)."""
        return self.geometry.tracer

    def __repr__(self):
        return (
            f"PatchScene({self.patch_count} patches, {self.triangle_count} triangles, "
            f"A_T={self.total_area:.6g}, Phi_T={self.total_power:.6g}, R_ave={self.average_reflectivity:.4g}"
            + (f", {len(self.lights)} lights)" if len(self.lights) else ")")
        )


def closed_behind(g, patch):
    """(n,) bool: whether the space just behind a middle point of each of ``patch`` is closed in:
    inside more solids than it enters (``visibility.buried_at``, probing about -n), or along
    VOTES of the probes a back side is met first (the inside of a closed object in a room of
    inward faces, whose windings the room's walls take back to 0)."""
    third = np.full(patch.size, 1 / 3, np.float32)  # (a triangle's centroid; inside a parallelogram)
    points = patch_point_rows(g, patch, third + np.float32(1 / 6), third.copy(), third.copy()).astype(np.float64)
    normal = -g.patch_normal_rows.take(patch, axis=1).astype(np.float64)
    # A quarter of the ray offset behind the surface: inside a body as thin as that (a sliver).
    points += normal * (1.25 * g.ray_offsets(patch, np.float64))
    closed = buried_at(g, points, patch, side=-1.0)
    tangent, bitangent = tangents(normal)
    origins, backs = np.ascontiguousarray(points.T, dtype=np.float32), np.zeros(patch.size, np.int64)
    for theta, phi in PROBES:
        theta, phi = np.radians(theta), np.radians(phi)
        d = np.cos(theta) * normal + np.sin(theta) * (np.cos(phi) * tangent + np.sin(phi) * bitangent)
        d32 = np.ascontiguousarray(d.T, dtype=np.float32)
        hit, _, _, _, hit_normal = g.surface_tracer.first_hit_barycentric(origins, d32, g.region_of(patch))
        backs += (hit >= 0) & ~meets_front(d32.T, hit_normal)
    return closed | (backs >= VOTES)


def _hidden(hidden, patch_count):
    """(P,) bool of the patches the error measure leaves out, or None where it counts every one
    (none given, none hidden, or all of them: a measure needs a surface)."""
    if hidden is None:
        return None
    hidden = np.asarray(hidden, dtype=bool).ravel()
    if hidden.shape != (patch_count,):
        raise ValueError(f"hidden must have one flag a patch ({patch_count}); got {hidden.shape[0]}")
    return hidden if hidden.any() and not hidden.all() else None
