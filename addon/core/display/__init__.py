"""Estimates in, a display out: smooth corner values, the noise filter, the direct light's shape."""
