"""The command line (``python -m addon``): arguments, the run, the progress line, saving, the
preview render and Ctrl-C (bpy, imported where used)."""
