"""Light sources beside emissive patches: point, spot, area, sun and world, in the scene's units.

Every quantity is in the units of the radiosity the scene writes (those of an emissive patch's
emittance E, "radiosity units" below, and of B = E + reflected): a light's power is what a patch
of emittance E and area A emits, E A. What each light is given:

- PointLight: radiant intensity I per steradian (power 4 pi I), at a point or spread over a
  sphere of ``radius`` whose surface emits like a Lambertian emitter (same intensity from every
  side), or with ``soft_falloff`` a disc of that radiance facing each receiver (gathered only);
  with a ``spot`` cone, intensity I times the cone's mask of the angle to its axis.
- AreaLight: exitance M of its surface (the E of an emissive patch of the same shape), one side,
  a rectangle or an ellipse, Lambertian (Blender's spread of 180 degrees).
- SunLight: irradiance H on a surface facing it, from a disc of angular diameter ``angle``.
- WorldLight: a uniform background, or an equirectangular image, as the irradiance W it gives an
  unoccluded plane facing any side (a radiance of W / pi).

Each light is a set of one or more emitters (an environment image: one per pixel), each with a
power (3,) and a way to draw rays: ``emit(rows, u)`` gives, for emitter rows and float32 uniforms
u (4, n), origins and directions (3, n) in world space. Sun and world rays start on a disc
perpendicular to their direction that covers the ``aim`` sphere (the part of the scene whose
light matters), placed beyond the whole scene; what misses it escapes.

Each light also answers the gathering question (``first_shot``): ``gather(x, normal, u)`` for
receiving points x (3, n) world with unit normals, and uniforms u (2, n), gives a direction
towards the light, the distance to go (inf: the ray must escape) and the irradiance estimate
(3, n) it makes if nothing is in the way: in expectation, the light's irradiance at x in the
scene's units (B = E + R H).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .spot import Spot  # noqa: F401  (a light kind's part, named here with the lights)
from .light_directions import (
    basis,
    cone_directions,
    cosine_directions_about,
    disc_origins,
    dot,
    equirectangular_pixel,
    pixel_directions,
    pixel_solid_angles,
    rotate,
    sphere_directions,
    direction_to,
)

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class PointLight:
    position: np.ndarray           # (3,) world
    intensity: np.ndarray          # (3,) radiosity units x area per steradian
    radius: float = 0.0
    spot: Spot | None = None
    name: str = "point"
    casts_shadow: bool = True  # False: its direct light passes through objects (gathered only)
    soft_falloff: bool = False  # with a radius: Cycles' disc facing each receiver (gathered only)

    def emitter_powers(self, aim=None):
        solid_angle = 4.0 * np.pi if self.spot is None else self.spot.solid_angle()
        return (np.asarray(self.intensity, np.float64) * solid_angle)[None]

    def emit(self, rows, u, aim, reach):
        n = u.shape[1]
        if self.spot is None:
            direction = sphere_directions(u[2], u[3])
        else:
            direction = self.spot.sample(u[2], u[3])
        origin = np.repeat(np.asarray(self.position, np.float64)[:, None], n, axis=1)
        if self.radius > 0:
            # A point of the sphere seen from the direction: a uniform point of the disc facing
            # it, moved onto the near hemisphere (a Lambertian sphere's rays in one direction).
            a, b = basis(direction)
            r = self.radius * np.sqrt(u[0].astype(np.float64))
            phi = TWO_PI * u[1].astype(np.float64)
            x, y = r * np.cos(phi), r * np.sin(phi)
            z = np.sqrt(np.maximum(self.radius**2 - x * x - y * y, 0.0))
            origin = origin + a * x + b * y + direction * z
        return origin, direction

    def gather(self, x, normal, u):
        position = np.asarray(self.position, np.float64)[:, None]
        if self.radius > 0 and self.soft_falloff:
            # Cycles' soft falloff: a disc of the sphere's radiance I / (pi r^2) facing x; a
            # uniform point y of it gives I cos_y / |x - y|^2 along x -> y.
            axis, _ = direction_to(position, x)
            a, b = basis(axis)
            r, phi = self.radius * np.sqrt(u[0].astype(np.float64)), TWO_PI * u[1].astype(np.float64)
            towards, distance = direction_to(position + a * (r * np.cos(phi)) + b * (r * np.sin(phi)), x)
            value = np.maximum(dot(axis, towards), 0.0) / distance**2
        elif self.radius > 0:
            # A uniform direction of the cone the sphere subtends (solid angle Omega): the sphere
            # (exitance I / r^2, Lambertian) gives (I / r^2) cos_x Omega / pi along it.
            axis, centre_distance = direction_to(position, x)
            sin2 = np.minimum((self.radius / centre_distance) ** 2, 1.0)  # (inside: the whole sphere)
            cos_alpha = np.sqrt(1.0 - sin2)
            cos_theta = 1.0 - u[0].astype(np.float64) * (1.0 - cos_alpha)
            towards = cone_directions(axis, cos_theta, u[1])
            reach = np.sqrt(np.maximum(self.radius**2 - centre_distance**2 * (1.0 - cos_theta**2), 0.0))
            distance = centre_distance * cos_theta - reach  # to the sphere's near side
            value = TWO_PI * (1.0 - cos_alpha) / (np.pi * self.radius**2)
        else:
            towards, distance = direction_to(position, x)
            value = 1.0 / distance**2
        if self.spot is not None:
            value = value * self.spot.mask(self.spot.local_cosine(-towards))
        value = value * np.maximum(dot(normal, towards), 0.0)
        return towards, distance, np.asarray(self.intensity, np.float64)[:, None] * value


@dataclass(frozen=True)
class AreaLight:
    centre: np.ndarray             # (3,) world
    half_u: np.ndarray             # (3,) half of the first side (or semi-axis)
    half_v: np.ndarray             # (3,) half of the second side (or semi-axis)
    normal: np.ndarray             # (3,) unit, the side it emits to
    exitance: np.ndarray           # (3,) radiosity units
    ellipse: bool = False
    name: str = "area"
    casts_shadow: bool = True

    @property
    def area(self):
        full = 4.0 * np.linalg.norm(np.cross(self.half_u, self.half_v))
        return full * np.pi / 4.0 if self.ellipse else full

    def emitter_powers(self, aim=None):
        return (np.asarray(self.exitance, np.float64) * self.area)[None]

    def emit(self, rows, u, aim, reach):
        return self._points(u[0], u[1]), cosine_directions_about(self.normal, u[2], u[3])

    def _points(self, a, b):
        a, b = a.astype(np.float64), b.astype(np.float64)
        if self.ellipse:
            r, phi = np.sqrt(a), TWO_PI * b
            s, t = r * np.cos(phi), r * np.sin(phi)
        else:
            s, t = 2.0 * a - 1.0, 2.0 * b - 1.0
        return np.asarray(self.centre, np.float64)[:, None] + np.outer(self.half_u, s) + np.outer(self.half_v, t)

    def gather(self, x, normal, u):
        # A uniform point y of the light: M cos_x cos_y A / (pi d^2).
        towards, distance = direction_to(self._points(u[0], u[1]), x)
        cos_y = np.maximum(-dot(np.asarray(self.normal, np.float64)[:, None], towards), 0.0)
        value = np.maximum(dot(normal, towards), 0.0) * cos_y * (self.area / np.pi) / distance**2
        return towards, distance, np.asarray(self.exitance, np.float64)[:, None] * value


@dataclass(frozen=True)
class SunLight:
    direction: np.ndarray          # (3,) unit, the way the light travels
    irradiance: np.ndarray         # (3,) on a surface facing the sun
    angle: float = 0.0             # angular diameter of the sun's disc
    name: str = "sun"
    casts_shadow: bool = True

    def _beam_factor(self):
        """Flux through a disc perpendicular to each direction of the sun's cone, over the
        irradiance it gives a surface facing it: solid angle / projected solid angle."""
        half = 0.5 * self.angle
        if half < 1e-6:
            return 1.0
        return 2.0 * (1.0 - np.cos(half)) / np.sin(half) ** 2

    def emitter_powers(self, aim=None):
        radius = 1.0 if aim is None else aim[1]
        return (np.asarray(self.irradiance, np.float64) * np.pi * radius**2 * self._beam_factor())[None]

    def emit(self, rows, u, aim, reach):
        half = 0.5 * self.angle
        cos_theta = 1.0 - u[2].astype(np.float64) * (1.0 - np.cos(half))
        direction = cone_directions(np.asarray(self.direction, np.float64), cos_theta, u[3])
        return disc_origins(direction, u[0], u[1], aim, reach), direction

    def gather(self, x, normal, u):
        # A uniform direction of the sun's cone: its radiance H / (pi sin^2) times cos_x times
        # the cone's solid angle is H cos_x times the beam factor.
        half = 0.5 * self.angle
        cos_theta = 1.0 - u[0].astype(np.float64) * (1.0 - np.cos(half))
        towards = -cone_directions(np.asarray(self.direction, np.float64), cos_theta, u[1])
        value = np.maximum(dot(normal, towards), 0.0) * self._beam_factor()
        return towards, np.full(x.shape[1], np.inf), np.asarray(self.irradiance, np.float64)[:, None] * value


@dataclass(frozen=True)
class WorldLight:
    irradiance: np.ndarray = field(default_factory=lambda: np.zeros(3))  # (3,) uniform background
    image: np.ndarray | None = None  # (H, W, 3) equirectangular, in the same units, or None
    rotation: np.ndarray | None = None  # (3,3) world direction -> image direction
    name: str = "world"

    def emitter_powers(self, aim=None):
        radius = 1.0 if aim is None else aim[1]
        if self.image is None:
            return (np.asarray(self.irradiance, np.float64) * 4.0 * np.pi * radius**2)[None]
        # An image pixel's flux through a disc perpendicular to its directions: (W / pi) pi R^2 Omega.
        return self.image.reshape(-1, 3) * (pixel_solid_angles(self.image.shape[:2]).reshape(-1, 1) * radius**2)

    def emit(self, rows, u, aim, reach):
        if self.image is None:
            towards_sky = sphere_directions(u[2], u[3])
        else:
            towards_sky = pixel_directions(self.image.shape[:2], rows, u[2], u[3])
            if self.rotation is not None:
                towards_sky = rotate(np.asarray(self.rotation, np.float64).T, towards_sky)
        direction = -towards_sky
        return disc_origins(direction, u[0], u[1], aim, reach), direction

    def gather(self, x, normal, u):
        # A cosine-distributed direction about the normal: radiance W / pi over the density
        # cos / pi leaves W (the pixel's W for an image).
        towards = cosine_directions_about(normal, u[0], u[1])
        return towards, np.full(x.shape[1], np.inf), self.radiance_times_pi(towards)

    def radiance_times_pi(self, towards):
        """(3, n) pi times the sky's radiance in each direction (3, n) towards it: W, or its pixel's."""
        if self.image is None:
            return np.repeat(np.asarray(self.irradiance, np.float64)[:, None], towards.shape[1], axis=1)
        sky = towards if self.rotation is None else rotate(self.rotation, towards)
        row, column = equirectangular_pixel(sky, self.image.shape[:2])
        return self.image[row, column].T.astype(np.float64)


class Lights:
    """A scene's lights as one table of emitters (rows), in the order given: (E,3) ``power``,
    the light of each row, and rays from rows. ``aim`` (centre, radius) is the sphere sun and
    world rays cover, ``reach`` how far back from its centre they start (world units)."""

    def __init__(self, lights, aim, reach):
        self.lights = tuple(lights)
        self.aim = (np.asarray(aim[0], np.float64), float(aim[1]))
        self.reach = float(reach)
        powers = [np.asarray(light.emitter_powers(self.aim), np.float64).reshape(-1, 3) for light in self.lights]
        counts = np.array([p.shape[0] for p in powers], dtype=np.int64)
        self.power = np.vstack(powers) if powers else np.zeros((0, 3))
        self.first = np.concatenate(([0], np.cumsum(counts)))
        self.light_of = np.repeat(np.arange(len(self.lights)), counts)

    def __len__(self):
        return len(self.lights)

    @property
    def emitter_count(self):
        return self.power.shape[0]

    def gathered_only(self):
        """(name, why) of each light whose direct light a shooting walk cannot carry: one that
        casts no shadow, or a sphere with Cycles' soft falloff (a disc facing each receiver,
        which no set of rays leaving the light draws)."""
        why = []
        for light in self.lights:
            if not getattr(light, "casts_shadow", True):
                why.append((light.name, "casts no shadow"))
            elif getattr(light, "soft_falloff", False) and light.radius > 0:
                why.append((light.name, "has soft falloff"))
        return why

    def light_power(self):
        """(L,3) the power of each light (the sum of its emitters')."""
        return np.add.reduceat(self.power, self.first[:-1], axis=0) if len(self) else np.zeros((0, 3))

    def emit(self, rows, u):
        """Rays from emitter ``rows`` (n,) with uniforms ``u`` (4, n): world origins and unit
        directions, (3, n) float64 each."""
        origins, directions = np.empty((3, rows.size)), np.empty((3, rows.size))
        light = self.light_of[rows]
        for k in np.unique(light):
            at = np.flatnonzero(light == k)
            o, d = self.lights[k].emit(rows[at] - self.first[k], u[:, at], self.aim, self.reach)
            origins[:, at], directions[:, at] = o, d
        return origins, directions

    def unit_rays(self, rows, u, geometry):
        """:meth:`emit`'s rays in ``geometry``'s unit space, as a walk traces them: origins
        pushed off along their direction like a patch's along its normal ((3, n) each)."""
        origins, directions = self.emit(rows, u)
        origins = (origins - geometry.centre[:, None]) / geometry.diagonal
        if geometry.regions is not None:
            origins -= geometry.regions.shift(self.regions(rows, geometry))
        origins += geometry.light_offsets(origins) * directions
        return origins, directions

    def regions(self, rows, geometry):
        """(n,) the region frame (.regions) of emitter ``rows``' rays in ``geometry``: the region
        nearest its light's position (the first region for the sun and the world, whose rays
        start beyond the scene), or None where the scene is one frame."""
        if geometry.regions is None:
            return None
        at = [getattr(light, "position", getattr(light, "centre", None)) for light in self.lights]
        region = np.zeros(len(self.lights), np.int32)
        placed = [k for k, p in enumerate(at) if p is not None]
        if placed:
            points = (np.array([at[k] for k in placed], np.float64) - geometry.centre) / geometry.diagonal
            region[placed] = geometry.regions.nearest(points.T)
        return region.take(self.light_of.take(rows))
