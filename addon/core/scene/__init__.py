"""The patch scene and its ray tracing: PatchScene, Embree, regions, rays, buried and coincident faces."""
