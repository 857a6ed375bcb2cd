"""Adaptive patches: cells split where the direct light or a short solve says the light changes."""
