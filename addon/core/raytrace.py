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
        unit_origins = np.asarray(origins, np.float64) + self.regions.centre[region]
        d64 = np.asarray(directions, np.float64)
        at_home = np.zeros(n, bool)  # traced in its own region as it is
        for home in (True, False):  # from inside its own region first: the nearest hit, mostly
            for k, tracer in enumerate(self._tracers):
                if tracer is None:
                    continue
                rows = np.flatnonzero((region == k) if home else ~(at_home & (region == k)))
                entry = self.regions.entry(k, unit_origins[rows], d64[rows])
                keep = (entry == 0) if home else (entry < t[rows])
                rows, entry = rows[keep], entry[keep]
                if rows.size == 0:
                    continue
                if home:
                    at_home[rows] = True
                    o = origins[rows]
                else:
                    o = (unit_origins[rows] + entry[:, None] * d64[rows] - self.regions.centre[k]).astype(np.float32)
                triangle, uk, vk, tk, nk = tracer.first_hit_barycentric(np.ascontiguousarray(o), np.ascontiguousarray(directions[rows]))
                tk = tk + entry  # (float64 where carried: from the origin given)
                nearer = (triangle >= 0) & (tk < t[rows])
                at = rows[nearer]
                hit[at] = self._index[k][triangle[nearer]]
                u[at], v[at], t[at], normal[at] = uk[nearer], vk[nearer], tk[nearer], nk[nearer]
        return hit, u, v, t, normal
