"""Ray casting with Embree (through embreex).

embreex's ``EmbreeScene.run`` takes float32 (n,3) origins and directions, returns the id of the
first triangle hit (-1 for a miss), always starts rays at t=0 and releases the GIL while it
traces, so several threads can trace on one committed scene at once.
"""
from __future__ import annotations

import numpy as np


class RayTracer:
    """First-hit queries against a fixed set of triangles (in the order given)."""

    def __init__(self, triangle_corners):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        corners = np.ascontiguousarray(triangle_corners, dtype=np.float32)
        self._scene = rtcore_scene.EmbreeScene()
        self._mesh = TriangleMesh(self._scene, corners)
        # embreex commits the scene on its first query; do that here, on one thread, so that
        # later concurrent queries never race to commit.
        self._scene.run(np.zeros((1, 3), np.float32), np.array([[0.0, 0.0, 1.0]], np.float32))
        self.triangle_count = corners.shape[0]

    def first_hit(self, origins, directions, region=None):
        """Index of the first triangle each ray hits, -1 where it hits nothing. (n,) int32.
        (``region``: see :class:`RegionTracer`; one frame here.)"""
        return self._scene.run(origins, directions)

    def first_hit_barycentric(self, origins, directions, region=None):
        """(triangle index, u, v, t, Ng) of each ray's first hit: the hit point is
        corner0 + u (corner1 - corner0) + v (corner2 - corner0), and origin + t direction
        (t is inf for a miss); Ng (n,3) is the hit triangle's unnormalised geometric normal,
        oriented like (corner1 - corner0) x (corner2 - corner0) (Embree computes it anyway;
        its sign is all the walk needs)."""
        out = self._scene.run(origins, directions, output=1)
        return out["primID"], out["u"], out["v"], out["tfar"], out["Ng"]


class RegionTracer:
    """First-hit queries against triangles whose corners are given in their regions' frames
    (:mod:`.regions`): one Embree scene per region. A ray's origin is in the frame of the region
    ``region`` given for it. Where it starts inside that region's box it is traced there as it
    is; in every other region whose box its line enters before its nearest hit so far (and in
    its own, where it starts outside it: a sun's ray from beyond the scene) it is traced from
    where it enters the box, carried there in float64 and rounded in that region's frame (as
    fine as the region is small: a float32 origin far from the triangles it meets would put
    Embree's hit a rounding of the whole distance off)."""

    def __init__(self, triangle_corners, triangle_region, regions):
        self.regions = regions
        self.triangle_count = triangle_corners.shape[0]
        self._index = [np.flatnonzero(triangle_region == k).astype(np.int32) for k in range(regions.count)]
        self._tracers = [RayTracer(triangle_corners[index]) if index.size else None for index in self._index]
        # Each region's box in its own frame (float32, for the cheap test of a start inside it),
        # and how far apart any two boxes are (a ray from inside one that meets something
        # nearer than that never reaches the other).
        self._home_lower = (regions.lower - regions.centre).astype(np.float32)
        self._home_upper = (regions.upper - regions.centre).astype(np.float32)
        apart = np.maximum(0.0, np.maximum(regions.lower[:, None] - regions.upper[None], regions.lower[None] - regions.upper[:, None]))
        self._apart = np.sqrt(np.einsum("abi,abi->ab", apart, apart))

    def first_hit(self, origins, directions, region):
        return self.first_hit_barycentric(origins, directions, region)[0]

    def first_hit_barycentric(self, origins, directions, region):
        """As :meth:`RayTracer.first_hit_barycentric`, for rays from ``region`` (n,) frames
        (t from the origin given)."""
        if region is None:
            raise ValueError("rays in a scene of several regions need the region of each origin")
        n = origins.shape[0]
        hit = np.full(n, -1, np.int32)
        u, v = np.zeros(n, np.float32), np.zeros(n, np.float32)
        t = np.full(n, np.inf, np.float32)
        normal = np.zeros((n, 3), np.float32)
        inside = np.zeros(n, bool)  # started inside its own region's box: traced there as it is
        for k, tracer in enumerate(self._tracers):
            home = region == k
            whole = bool(home.all())  # (a walk's rays mostly: no gathers, no scatters)
            o = origins if whole else origins[home]
            within = ((o >= self._home_lower[k]) & (o <= self._home_upper[k])).all(axis=1)
            if whole and within.all():
                inside[:] = True
                hit, u, v, t, normal = tracer.first_hit_barycentric(origins, directions)
                hit = np.where(hit >= 0, self._index[k].take(hit, mode="wrap"), -1).astype(np.int32)
                break
            rows = np.flatnonzero(home)[within]
            if rows.size == 0:
                continue
            inside[rows] = True
            triangle, uk, vk, tk, nk = tracer.first_hit_barycentric(np.ascontiguousarray(origins[rows]), np.ascontiguousarray(directions[rows]))
            hit[rows] = np.where(triangle >= 0, self._index[k].take(triangle, mode="wrap"), -1)
            u[rows], v[rows], t[rows], normal[rows] = uk, vk, tk, nk
        for k, tracer in enumerate(self._tracers):  # then every other box the ray may reach first
            if tracer is None:
                continue
            rows = np.flatnonzero(t > np.where(inside, self._apart[region, k], 0.0))
            rows = rows[~(inside[rows] & (region[rows] == k))]
            if rows.size == 0:
                continue
            unit_origins = origins[rows].astype(np.float64) + self.regions.centre[region[rows]]
            d64 = directions[rows].astype(np.float64)
            entry = self.regions.entry(k, unit_origins, d64)
            keep = entry < t[rows]
            rows, entry = rows[keep], entry[keep]
            if rows.size == 0:
                continue
            o = (unit_origins[keep] + entry[:, None] * d64[keep] - self.regions.centre[k]).astype(np.float32)
            triangle, uk, vk, tk, nk = tracer.first_hit_barycentric(o, np.ascontiguousarray(directions[rows]))
            tk = tk + entry  # (float64: from the origin given)
            nearer = (triangle >= 0) & (tk < t[rows])
            at = rows[nearer]
            hit[at] = self._index[k][triangle[nearer]]
            u[at], v[at], t[at], normal[at] = uk[nearer], vk[nearer], tk[nearer], nk[nearer]
        return hit, u, v, t, normal
