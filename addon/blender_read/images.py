"""Reading a Blender image's pixels as linear RGB (bpy glue, one reader for materials and the world)."""

from __future__ import annotations

import numpy as np


def srgb_to_linear(c):
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_pixels(image, dtype=np.float32):
    """(H, W, 3) linear pixels of an image, row 0 at the bottom (Blender's order), or None if
    it has none (a missing file). Byte images hold their colour space's values; float images
    are scene linear."""
    try:
        width, height = image.size[:]
        channels = image.channels
        if width * height == 0 or channels < 1:
            return None
        pixels = np.empty(width * height * channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    except Exception:  # noqa: BLE001 - unreadable image: the caller falls back and says so
        return None
    pixels = pixels.reshape(height, width, channels).astype(np.float64)
    rgb = pixels[..., :3] if channels >= 3 else np.repeat(pixels[..., :1], 3, axis=2)
    if not image.is_float and image.colorspace_settings.name == "sRGB":
        rgb = srgb_to_linear(rgb)
    return np.ascontiguousarray(rgb, dtype=dtype)


def image_average(image):
    """Average linear RGB of an image's pixels, or None if it has none (missing file)."""
    pixels = linear_pixels(image, np.float64)
    return None if pixels is None else pixels.reshape(-1, 3).mean(axis=0)
