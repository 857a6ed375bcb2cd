"""The glue's middle on arrays, without bpy: patches made from the objects read, the solve on a
worker thread, memory given back between stages. Nothing here imports Blender's modules."""
