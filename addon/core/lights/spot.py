"""A spot light's cone: its mask, solid angle (round or elliptical) and directions drawn within it."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .light_directions import cone_directions, dot, rotate

TWO_PI = 2.0 * np.pi
# An elliptical spot's solid angle: Gauss-Legendre nodes in the angle to the axis (per part), and
# trapezoid steps around it (periodic: both converge fast on the smooth integrand).
ELLIPSE_QUADRATURE = (48, 256)
# Added to the widest angle of an elliptical spot's sampled edge, for the edge between samples.
BOUNDING_MARGIN = 1e-3


@dataclass(frozen=True)
class Spot:
    """A spot light's cone: emission along ``axis`` (unit), the mask of cos(angle to the axis)
    x rising as smoothstep from 0 at cos_outer to 1 at cos_inner (no rise where they are equal).

    A light object scaled unevenly makes the cone elliptical, as Cycles shapes it: ``to_local``
    (3,3) takes a world direction into the light's own frame (the inverse of its matrix, z
    towards the axis), and x is the z of that direction normalised. None: a round cone."""

    axis: np.ndarray
    cos_outer: float
    cos_inner: float
    to_local: np.ndarray | None = None

    def mask(self, x):
        x = np.asarray(x, dtype=np.float64)
        width = self.cos_inner - self.cos_outer
        if width <= 0:
            return (x > self.cos_outer).astype(np.float64)
        t = np.clip((x - self.cos_outer) / width, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)

    def local_cosine(self, directions):
        """x of unit world directions (3, n) leaving the light."""
        if self.to_local is None:
            return dot(np.asarray(self.axis, np.float64)[:, None], directions)
        local = rotate(self.to_local, directions)
        return local[2] / np.sqrt(dot(local, local))

    def solid_angle(self):
        """The integral of the mask over directions. Round: 2 pi times its integral over x in
        [-1, 1]. Elliptical: over the light's own directions l, the mask times the Jacobian
        |det A| / |A l|^3 of l -> A l / |A l| (A the light's matrix), by Gauss-Legendre in the
        angle to the axis (the cap, then the ramp) and the trapezoid rule around it."""
        width = max(self.cos_inner - self.cos_outer, 0.0)
        if self.to_local is None:
            return TWO_PI * ((1.0 - self.cos_inner) + 0.5 * width)  # smoothstep integrates to half
        A = np.linalg.inv(np.asarray(self.to_local, np.float64))
        nodes, weights = np.polynomial.legendre.leggauss(ELLIPSE_QUADRATURE[0])
        phi = TWO_PI * np.arange(ELLIPSE_QUADRATURE[1]) / ELLIPSE_QUADRATURE[1]
        total, theta_inner, theta_outer = 0.0, np.arccos(min(self.cos_inner, 1.0)), np.arccos(self.cos_outer)
        for start, end in ((0.0, theta_inner), (theta_inner, theta_outer)):
            if end <= start:
                continue
            theta = start + (end - start) * 0.5 * (nodes + 1.0)
            l = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                          np.repeat(np.cos(theta)[:, None], phi.size, axis=1)]).reshape(3, -1)
            jacobian = abs(np.linalg.det(A)) / np.sqrt(dot(A @ l, A @ l)) ** 3
            f = (self.mask(l[2]) * jacobian).reshape(theta.size, phi.size) * np.sin(theta)[:, None]
            total += 0.5 * (end - start) * (weights @ f.sum(axis=1)) * (TWO_PI / phi.size)
        return total

    def bounding_cos(self):
        """The cosine of a round cone about the axis that holds every direction of the mask."""
        if self.to_local is None:
            return self.cos_outer
        A = np.linalg.inv(np.asarray(self.to_local, np.float64))
        phi = TWO_PI * np.arange(1024) / 1024
        sin_outer = np.sqrt(max(1.0 - self.cos_outer**2, 0.0))
        edge = A @ np.stack([sin_outer * np.cos(phi), sin_outer * np.sin(phi), np.full(phi.size, self.cos_outer)])
        widest = np.arccos(np.clip(np.min(dot(np.asarray(self.axis, np.float64)[:, None], edge)
                                          / np.sqrt(dot(edge, edge))), -1.0, 1.0))
        return float(np.cos(min(widest + BOUNDING_MARGIN, np.pi)))

    def sample(self, u_cos, u_phi):
        """Directions (3, n) with density proportional to the mask. Round: exactly, by its cosine
        (``sample_cosine``). Elliptical: uniform in the bounding cone, each kept with the chance
        of its mask; the ones left draw again from a generator seeded with their own uniforms
        (reproducible, and independent of other paths)."""
        if self.to_local is None or u_cos.size == 0:
            return cone_directions(self.axis, self.sample_cosine(u_cos), u_phi)
        axis, cos_bound = np.asarray(self.axis, np.float64), self.bounding_cos()
        cos_theta = 1.0 - u_cos.astype(np.float64) * (1.0 - cos_bound)
        directions = cone_directions(axis, cos_theta, u_phi)
        rng = np.random.default_rng(np.frombuffer(np.ascontiguousarray(np.stack([u_cos, u_phi]), np.float32).tobytes(), np.uint32))
        redraw = np.flatnonzero(rng.random(directions.shape[1]) >= self.mask(self.local_cosine(directions)))
        while redraw.size:
            cos_theta = 1.0 - rng.random(redraw.size) * (1.0 - cos_bound)
            directions[:, redraw] = cone_directions(axis, cos_theta, rng.random(redraw.size))
            kept = rng.random(redraw.size) < self.mask(self.local_cosine(directions[:, redraw]))
            redraw = redraw[~kept]
        return directions

    def sample_cosine(self, u):
        """x = cos(angle to the axis) with density proportional to the mask: uniform over the
        full cone above cos_inner, the smoothstep's integral inverted on the ramp (Newton)."""
        u = np.asarray(u, dtype=np.float64)
        width = max(self.cos_inner - self.cos_outer, 0.0)
        full, ramp = 1.0 - self.cos_inner, 0.5 * width
        target = u * (full + ramp)
        x = 1.0 - target  # on the full part: x from 1 down to cos_inner
        on_ramp = target > full
        if width > 0 and on_ramp.any():
            # Mass from x down to cos_outer on the ramp: width (1 - G(t)), G(t) = t^3 - t^4 / 2
            # normalised to 1 at t = 1 (G(1) = 1/2, times 2); solve G(t) = 1 - (target - full) / ramp.
            want = 1.0 - (target[on_ramp] - full) / ramp
            t = np.full(want.shape, 0.5)
            for _ in range(40):
                g = 2.0 * (t**3 - 0.5 * t**4) - want
                dg = 2.0 * (3 * t**2 - 2 * t**3)
                step = np.where(dg > 0, g / np.maximum(dg, 1e-300), 0.0)
                t = np.clip(t - step, 0.0, 1.0)
            x[on_ramp] = self.cos_outer + t * width
        return x
