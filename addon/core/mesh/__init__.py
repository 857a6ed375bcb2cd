"""Polygon meshes into patches: faces checked and cut, subdivided, welded; the arrays a scene is made of."""
