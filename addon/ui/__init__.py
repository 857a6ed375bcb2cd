"""The user interface in Blender: the settings (properties), the operators, the sidebar panel
and the live view (bpy)."""
