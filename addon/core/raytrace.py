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

    def first_hit(self, origins, directions):
        """Index of the first triangle each ray hits, -1 where it hits nothing. (n,) int32."""
        return self._scene.run(origins, directions)

    def first_hit_barycentric(self, origins, directions):
        """(triangle index, u, v, t, Ng) of each ray's first hit: the hit point is
        corner0 + u (corner1 - corner0) + v (corner2 - corner0), and origin + t direction
        (t is inf for a miss); Ng (n,3) is the hit triangle's unnormalised geometric normal,
        oriented like (corner1 - corner0) x (corner2 - corner0) (Embree computes it anyway;
        its sign is all the walk needs)."""
        out = self._scene.run(origins, directions, output=1)
        return out["primID"], out["u"], out["v"], out["tfar"], out["Ng"]
