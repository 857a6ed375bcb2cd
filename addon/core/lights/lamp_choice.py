"""Which lamp a sample of the display's direct light looks at: each lamp by what it would give
the sample's point unoccluded.

The display's direct light at a point (``point_direct``) sums every lamp's and sun's light
there. Looking at every lamp from every point costs shadow rays that grow with the lamps; here
a point's samples share one budget among them (importance sampling the lamps, as Cycles' light
tree does): sample j chooses lamp k with the chance w_k(x) / sum_k' w_k'(x) and adds lamp k's
estimate divided by that chance, so the sum's expectation is every lamp's light, whatever the
weights, as long as a lamp that can light the point has a weight above 0.

w_k(x) is lamp k's light at x unoccluded where that is cheap and exact (a point lamp or a spot,
and the sun of no angle: I cos / d^2 times the spot's mask, H cos), else a bound of it from the
sphere about the lamp (a sphere lamp's, an area lamp's, the sun's disc): the angles to the
receiver's normal and to the lamp's emitting side widened by the half-angle that sphere subtends,
the distance less its radius. A point standing for a patch (``spread``: the radius of a sphere
about the patch) widens them by that too, so one choice serves all of the patch's samples.
Where no lamp can light a point the choice is by power (its samples then find nothing, as they
must). The bound errs only upwards (wasted samples, never a lamp left out), and a point lamp's
weight is its light itself: among point lamps with nothing in the way, one sample is exact.
"""
from __future__ import annotations

import numpy as np

from .light_directions import cone_directions, direction_to, dot
from .lights import AreaLight, PointLight, SunLight
from .near_choice import patch_centres

TWO_PI = 2.0 * np.pi

POINT, AREA, SUN = range(3)
PAIRS = 1 << 18  # lamps x points weighed at a time (a few arrays of this many float64)
# A lamp's weight takes its distance as at least this share of its (widened) sphere's radius: a
# point inside the sphere is near the lamp, not at it.
NEAR = 0.5
# A lamp with a size (or a point standing for a patch) weighs at least this share of its bound:
# the light from its centre is nearer its light than the bound where it is wholly in view, and
# the bound keeps a weight where only a part of it is (its centre below the horizon).
BOUND_SHARE = 0.1


def _widened(cosine, cos_u, sin_u):
    """cos(max(theta - theta_u, 0)) of the angle theta whose cosine is ``cosine``: the cosine of
    the nearest direction within theta_u of it, at least 0."""
    sine = np.sqrt(np.maximum(1.0 - cosine * cosine, 0.0))
    out = cosine * cos_u + sine * sin_u
    out = np.where(cosine >= cos_u, 1.0, out)
    return np.maximum(out, 0.0)


class LampChoice:
    """The lamps and suns ``lamps`` (core lights, no world; kept in ``_in_space_order``) weighed
    at points (``weights``), chosen for samples (``choose``) and looked at from them
    (``gather``)."""

    def __init__(self, lamps):
        self.lamps = _in_space_order(lamps)
        L = len(self.lamps)
        self.casts_shadow = np.array([getattr(light, "casts_shadow", True) for light in self.lamps], bool)
        self.kind = np.array([SUN if isinstance(light, SunLight) else AREA if isinstance(light, AreaLight) else POINT
                              for light in self.lamps], np.int8)
        self.centre, self.axis = np.zeros((L, 3)), np.zeros((L, 3))  # (the axis: a spot's, an area lamp's normal, to the sun)
        self.radius, self.strength, self.cap = np.zeros(L), np.zeros(L), np.full(L, np.inf)
        self.cos_outer, self.cos_inner = np.full(L, -2.0), np.full(L, -2.0)  # a round spot's mask (-2: none)
        self.colour = np.zeros((L, 3))  # I, M, or the sun's H times its disc's beam factor
        self.half_u, self.half_v, self.ellipse, self.area = np.zeros((L, 3)), np.zeros((L, 3)), np.zeros(L, bool), np.zeros(L)
        self.vectored = np.ones(L, bool)  # looked at all at once (``gather``), else each by its own
        for k, light in enumerate(self.lamps):
            self._describe(k, light)
        power = np.array([np.asarray(light.emitter_powers(None), np.float64).sum(axis=0).mean() for light in self.lamps])
        self.share = power / power.sum() if power.sum() > 0 else np.full(L, 1.0 / max(L, 1))

    def _describe(self, k, light):
        if isinstance(light, SunLight):
            self.axis[k] = -np.asarray(light.direction, np.float64)
            self.radius[k] = 0.5 * light.angle  # (an angle: the sun's disc)
            self.colour[k] = light.gather(np.zeros((3, 1)), self.axis[k][:, None], np.zeros((2, 1), np.float32))[2][:, 0]
            self.strength[k] = self.colour[k].mean()
        elif isinstance(light, AreaLight):
            hu, hv = np.asarray(light.half_u, np.float64), np.asarray(light.half_v, np.float64)
            self.centre[k], self.axis[k], self.half_u[k], self.half_v[k] = light.centre, light.normal, hu, hv
            self.radius[k] = max(np.linalg.norm(hu + hv), np.linalg.norm(hu - hv))
            self.colour[k], self.ellipse[k], self.area[k] = light.exitance, light.ellipse, light.area
            self.strength[k] = np.mean(light.exitance) * light.area / np.pi
            self.cap[k] = np.mean(light.exitance)  # (no surface gets more irradiance than the exitance facing it)
        elif isinstance(light, PointLight):
            self.centre[k], self.radius[k], self.colour[k] = light.position, light.radius, light.intensity
            self.strength[k] = np.mean(light.intensity)
            spot = light.spot
            self.vectored[k] = not (light.soft_falloff and light.radius > 0) and (spot is None or spot.to_local is None)
            if spot is not None:
                self.axis[k] = spot.axis
                if spot.to_local is None:
                    self.cos_outer[k], self.cos_inner[k] = spot.cos_outer, spot.cos_inner
                else:  # (an elliptical cone: its round bounding cone, all or nothing)
                    self.cos_outer[k] = self.cos_inner[k] = spot.bounding_cos()
        else:
            raise TypeError(f"a lamp of an unknown kind: {type(light).__name__}")

    def __len__(self):
        return len(self.lamps)

    def weights(self, x, normal, spread=0.0):
        """(L, n) each lamp's weight at world points ``x`` (n,3) of unit ``normal`` (n,3), each
        standing for a sphere of radius ``spread`` (scalar or (n,)) about it."""
        n = len(x)
        spread = np.broadcast_to(np.asarray(spread, np.float64), (n,))
        out = np.zeros((len(self), n))
        step = max(1, PAIRS // max(len(self), 1))
        placed, suns = np.flatnonzero(self.kind != SUN), np.flatnonzero(self.kind == SUN)
        for start in range(0, n, step):
            rows = slice(start, start + step)
            if placed.size:
                out[placed, rows] = self._placed(placed, x[rows].T, normal[rows].T, spread[rows])
            if suns.size:
                out[suns, rows] = self._suns(suns, normal[rows])
        return out

    def _placed(self, lamps, x, normal, spread):
        """(l, n) the weights of point, spot, sphere or area lamps ``lamps`` at points ``x`` (3,n)
        (float32: a choice needs no more): the light from the lamp's centre, and where the lamp
        or the point has a size, at least BOUND_SHARE of the bound (``_light`` of the widened
        angles)."""
        x, normal = x.astype(np.float32), normal.astype(np.float32)
        centre, axis = self.centre[lamps].astype(np.float32), self.axis[lamps].astype(np.float32)
        d = [centre[:, i, None] - x[i] for i in range(3)]  # (towards the lamp)
        squared = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
        np.maximum(squared, np.float32(1e-30), out=squared)
        distance = np.sqrt(squared)
        cosine = (d[0] * normal[0] + d[1] * normal[1] + d[2] * normal[2]) / distance
        emitted = -(d[0] * axis[:, 0, None] + d[1] * axis[:, 1, None] + d[2] * axis[:, 2, None]) / distance  # (the way out)
        radius = (self.radius[lamps][:, None] + spread[None]).astype(np.float32)
        wide = np.flatnonzero(radius.any(axis=1))
        if not wide.size:
            return self._light(lamps, cosine, emitted, squared)
        near = np.maximum(distance[wide], np.float32(NEAR) * radius[wide])
        squared[wide] = near * near
        weight = self._light(lamps, cosine, emitted, squared)
        sin_u = np.minimum(radius[wide] / distance[wide], np.float32(1.0))
        cos_u = np.sqrt(1.0 - sin_u * sin_u)
        near = np.maximum(distance[wide] - radius[wide], np.float32(NEAR) * radius[wide])
        bound = self._light(lamps[wide], _widened(cosine[wide], cos_u, sin_u), _widened(emitted[wide], cos_u, sin_u),
                            near * near)
        weight[wide] = np.maximum(weight[wide], BOUND_SHARE * bound)
        return weight

    def _light(self, lamps, cosine, emitted, squared):
        """(l, n) ``lamps``' light at points at these cosines to the normal and out of the lamp
        and these squared distances, as from a point (at most an area lamp's exitance)."""
        weight = np.maximum(cosine, np.float32(0.0))
        area = np.flatnonzero(self.kind[lamps] == AREA)
        if area.size:
            weight[area] *= np.maximum(emitted[area], np.float32(0.0))
        spots = np.flatnonzero((self.kind[lamps] != AREA) & (self.cos_outer[lamps] > -2.0))
        if spots.size:
            weight[spots] *= _mask(emitted[spots], self.cos_outer[lamps][spots, None], self.cos_inner[lamps][spots, None])
        weight *= self.strength[lamps].astype(np.float32)[:, None] / squared
        return np.minimum(weight, self.cap[lamps][:, None])

    def _suns(self, lamps, normal):
        """(l, n) the suns' weights at points of ``normal`` (n,3)."""
        cosine = normal @ self.axis[lamps].T  # (n, l)
        half = self.radius[lamps]
        return (_widened(cosine, np.cos(half), np.sin(half)) * self.strength[lamps]).T

    def choose(self, weights, local, u):
        """((m,) the lamp each sample chooses, (m,) the chance of that choice) for samples of
        the points ``local`` (m,) (columns of ``weights`` (L, n)) with uniforms ``u`` (m,) in [0, 1):
        by weight, by power at a point that no lamp can light."""
        L, n = weights.shape
        if L == 1:
            return np.zeros(len(local), np.int64), np.ones(len(local))
        total = weights.sum(axis=0)
        chance = np.where(total > 0, weights / np.where(total > 0, total, 1.0), self.share[:, None])  # (L, n)
        cumulative = np.cumsum(chance.T, axis=1)  # (n, L)
        cumulative[:, -1] = 1.0
        cumulative += np.arange(n)[:, None]
        position = np.searchsorted(cumulative.ravel(), local + np.asarray(u, np.float64), side="right")
        lamp = np.clip(position - local * L, 0, L - 1)
        return lamp, chance[lamp, local]

    def gather(self, lamp, x, normal, u):
        """Each sample's chosen ``lamp`` (m,) looked at from world points ``x`` (3,m) of unit
        ``normal`` (3,m) with uniforms ``u`` (2,m), as its ``gather`` does: (towards (3,m),
        distance (m,), irradiance unoccluded (3,m)); all the point, sphere, round spot, area
        lamps and suns at once, the others (a soft falloff, an elliptical spot) each by its own."""
        if len(self) == 1:  # (one lamp: its own, as it is)
            return self.lamps[0].gather(x, normal, u)
        m = lamp.size
        towards, distance, value = np.empty((3, m)), np.empty(m), np.zeros((3, m))
        kind = np.where(self.vectored[lamp], self.kind[lamp], -1)
        for code, look in ((POINT, self._points_at), (AREA, self._areas_at), (SUN, self._suns_at)):
            at = np.flatnonzero(kind == code)
            if at.size:
                towards[:, at], distance[at], value[:, at] = look(lamp[at], x[:, at], normal[:, at], u[:, at])
        others = np.flatnonzero(kind < 0)
        for k in np.unique(lamp[others]):
            at = others[lamp[others] == k]
            towards[:, at], distance[at], value[:, at] = self.lamps[k].gather(x[:, at], normal[:, at], u[:, at])
        return towards, distance, value

    def _points_at(self, k, x, normal, u):
        """``PointLight.gather`` of point, sphere and round spot lamps ``k`` (one a sample)."""
        position, radius = self.centre[k].T, self.radius[k]
        towards, distance = direction_to(position, x)
        value = 1.0 / distance**2
        sphere = np.flatnonzero(radius > 0)
        if sphere.size:  # (a uniform direction of the cone the sphere subtends)
            r, centre_distance = radius[sphere], distance[sphere]
            cos_alpha = np.sqrt(1.0 - np.minimum((r / centre_distance) ** 2, 1.0))
            cos_theta = 1.0 - u[0, sphere].astype(np.float64) * (1.0 - cos_alpha)
            towards[:, sphere] = cone_directions(towards[:, sphere], cos_theta, u[1, sphere])
            reach = np.sqrt(np.maximum(r**2 - centre_distance**2 * (1.0 - cos_theta**2), 0.0))
            distance[sphere] = centre_distance * cos_theta - reach
            value[sphere] = TWO_PI * (1.0 - cos_alpha) / (np.pi * r**2)
        spot = np.flatnonzero(self.cos_outer[k] > -2.0)
        if spot.size:
            axis = self.axis[k[spot]].T
            value[spot] = value[spot] * _mask(-dot(axis, towards[:, spot]), self.cos_outer[k[spot]], self.cos_inner[k[spot]])
        value = value * np.maximum(dot(normal, towards), 0.0)
        return towards, distance, self.colour[k].T * value

    def _areas_at(self, k, x, normal, u):
        """``AreaLight.gather`` of area lamps ``k``: a uniform point of each."""
        a, b = u[0].astype(np.float64), u[1].astype(np.float64)
        s, t = 2.0 * a - 1.0, 2.0 * b - 1.0
        ellipse = np.flatnonzero(self.ellipse[k])
        if ellipse.size:
            r, phi = np.sqrt(a[ellipse]), TWO_PI * b[ellipse]
            s[ellipse], t[ellipse] = r * np.cos(phi), r * np.sin(phi)
        points = self.centre[k].T + self.half_u[k].T * s + self.half_v[k].T * t
        towards, distance = direction_to(points, x)
        cos_y = np.maximum(-dot(self.axis[k].T, towards), 0.0)
        value = np.maximum(dot(normal, towards), 0.0) * cos_y * (self.area[k] / np.pi) / distance**2
        return towards, distance, self.colour[k].T * value

    def _suns_at(self, k, x, normal, u):
        """``SunLight.gather`` of suns ``k``: a uniform direction of each one's disc."""
        cos_theta = 1.0 - u[0].astype(np.float64) * (1.0 - np.cos(self.radius[k]))
        towards = -cone_directions(-self.axis[k].T, cos_theta, u[1])  # (as the sun draws it)
        return towards, np.full(x.shape[1], np.inf), self.colour[k].T * np.maximum(dot(normal, towards), 0.0)


def _in_space_order(lamps, bits=10):
    """The lamps along a Morton curve through their places (suns last): neighbours in the choice's
    cumulative chances are neighbours in space, so a point's strata of it see alike (``point_direct``
    pairs them to measure its error)."""
    at = np.array([getattr(light, "position", getattr(light, "centre", None)) if not isinstance(light, SunLight)
                   else np.full(3, np.inf) for light in lamps], np.float64).reshape(-1, 3)
    placed = np.isfinite(at).all(axis=1)
    code = np.full(len(lamps), np.iinfo(np.int64).max)
    if placed.any():
        low, high = at[placed].min(axis=0), at[placed].max(axis=0)
        cells = ((at[placed] - low) / np.maximum(high - low, 1e-300) * ((1 << bits) - 1)).astype(np.int64)
        morton = np.zeros(len(cells), np.int64)
        for bit in range(bits):
            for axis in range(3):
                morton |= ((cells[:, axis] >> bit) & 1) << (3 * bit + axis)
        code[placed] = morton
    return tuple(lamps[k] for k in np.argsort(code, kind="stable"))


def _mask(cosine, cos_outer, cos_inner):
    """A round spot's mask (``Spot.mask``) at ``cosine``; all or nothing where the two are equal."""
    width = cos_inner - cos_outer
    t = np.clip((cosine - cos_outer) / np.where(width > 0, width, 1.0), 0.0, 1.0)
    return np.where(width > 0, t * t * (3.0 - 2.0 * t), (cosine > cos_outer).astype(np.float64))


def patch_spheres(scene):
    """((P,3) a world point in the middle of each patch, (P,) the radius of a sphere about it that
    holds the patch's triangles)."""
    centre = patch_centres(scene)
    corners = scene.vertices[scene.triangles]  # (T,3,3)
    reach = np.linalg.norm(corners - centre[scene.triangle_patch][:, None, :], axis=2).max(axis=1)
    radius = np.zeros(scene.patch_count)
    np.maximum.at(radius, scene.triangle_patch, reach)
    return centre, radius
