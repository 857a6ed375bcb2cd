"""Writing results into Blender: the result objects, their colour attributes and material (bpy)."""
